//! Fuzz the Robotiq FT 300 stream decoder with arbitrary bytes cut into arbitrary reads: it must never
//! panic, every frame it emits must be 16 input bytes with a good header and CRC, and feeding whole
//! reads must give the same events as pushing byte by byte.
#![no_main]

use libfuzzer_sys::fuzz_target;
use robotiq::codec::{Event, FRAME_LEN, StreamDecoder, decode_frame, encode_frame};

fuzz_target!(|input: &[u8]| {
    // [read length, bytes…]
    let Some((&cut, bytes)) = input.split_first() else { return };
    let cut = usize::from(cut).max(1);
    let mut one = StreamDecoder::new();
    let mut by_byte = Vec::new();
    for (i, &b) in bytes.iter().enumerate() {
        if let Some(e) = one.push(b) {
            if let Event::Frame(c) = e {
                let f = encode_frame(c);
                assert!(i + 1 >= FRAME_LEN);
                assert_eq!(&bytes[i + 1 - FRAME_LEN..=i], &f[..]);
                assert_eq!(decode_frame(&f), Ok(c));
            }
            by_byte.push(e);
        }
    }
    let mut fed = StreamDecoder::new();
    let mut by_read = Vec::new();
    for chunk in bytes.chunks(cut) {
        fed.feed(chunk, |e| by_read.push(e));
    }
    assert_eq!(by_read, by_byte);
    assert_eq!(fed.counters(), one.counters());
});
