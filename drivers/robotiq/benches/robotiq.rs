//! Per-frame cost of the stream codec (`cargo bench -p forcecell-robotiq`). The achieved stream rate and
//! the sample age over a real pseudo-terminal are measured in `sim/benches/ft300_stream.rs`.

use core::time::Duration;

use divan::black_box;
use robotiq::codec::{Counts, Event, StreamDecoder, decode_frame, encode_frame};
use robotiq::{LinkConfig, LinkState};

fn main() {
    divan::main();
}

fn golden() -> [u8; 16] {
    encode_frame(Counts([1234, -567, -9810, 123, -45, 6]))
}

/// One frame through the resynchronising decoder as the driver feeds it (a whole read), and to SI.
#[divan::bench]
fn stream_decode_one_frame(b: divan::Bencher) {
    let f = golden();
    let mut d = StreamDecoder::new();
    b.bench_local(|| {
        let mut out = None;
        d.feed(black_box(&f), |e| {
            if let Event::Frame(c) = e {
                out = Some(c.to_wrench());
            }
        });
        out
    });
}

/// The same frame pushed one byte at a time (the worst case: one byte per read).
#[divan::bench]
fn stream_decode_one_frame_bytewise(b: divan::Bencher) {
    let f = golden();
    let mut d = StreamDecoder::new();
    b.bench_local(|| {
        let mut out = None;
        for &byte in black_box(&f) {
            if let Some(Event::Frame(c)) = d.push(byte) {
                out = Some(c.to_wrench());
            }
        }
        out
    });
}

/// Header and CRC check of an aligned frame only.
#[divan::bench]
fn decode_aligned_frame(b: divan::Bencher) {
    let f = golden();
    b.bench(|| decode_frame(black_box(&f)));
}

/// A frame through the link state (decoder, window, latest sample) and the sample handed out.
#[divan::bench]
fn link_state_one_frame_and_sample(b: divan::Bencher) {
    let f = golden();
    let mut s = LinkState::new(LinkConfig::default(), Duration::ZERO);
    let mut t = Duration::ZERO;
    b.bench_local(|| {
        t += Duration::from_millis(10);
        s.on_bytes(black_box(&f), t);
        s.sample_at(t).is_ok()
    });
}
