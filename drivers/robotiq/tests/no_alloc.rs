//! The per-frame hot path — push 16 bytes through the resynchronising decoder, check header and CRC,
//! update the link state, convert to SI — allocates nothing (counted by `stats_alloc`).

use std::alloc::System;
use std::time::Duration;

use robotiq::codec::{Counts, Event, StreamDecoder, encode_frame};
use robotiq::{LinkConfig, LinkState};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn decoding_frames_does_not_allocate() {
    let frame = encode_frame(Counts([1234, -567, -9810, 123, -45, 6]));
    let mut broken = frame;
    broken[9] ^= 0x10;
    let mut decoder = StreamDecoder::new();
    let mut state = LinkState::new(LinkConfig::default(), Duration::ZERO);
    let mut fz = 0.0;
    let region = Region::new(GLOBAL);
    for i in 0..1000u64 {
        for &b in &frame {
            if let Some(Event::Frame(c)) = decoder.push(b) {
                fz += c.to_wrench().force.z;
            }
        }
        let now = Duration::from_millis(10 * i);
        state.on_bytes(&broken, now);
        state.on_bytes(&frame, now);
        // Every other frame fails: the link is corrupt, and saying so allocates nothing either.
        std::hint::black_box(state.sample_at(now).is_ok());
    }
    let change = region.change();
    assert_eq!(change.allocations + change.reallocations, 0, "{change:?}");
    assert!((fz + 98_100.0).abs() < 1e-6, "{fz}");
    assert_eq!(decoder.counters().frames, 1000);
    assert_eq!(state.counters().crc_errors, 1000);
}
