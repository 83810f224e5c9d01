//! Fuzz the ATI NETCANOEM decoders with arbitrary frames: they must never panic, and every frame they
//! accept must encode back to itself.
#![no_main]

use ati_can::{Answer, Base, Frame, Request};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    // [flags, base, id_hi, id_lo (or 4 id bytes when extended), data…]
    let Some((&flags, rest)) = input.split_first() else { return };
    let Some((&base, rest)) = rest.split_first() else { return };
    let base = Base::new(base & 0x7F).unwrap_or_default();
    let extended = flags & 1 != 0;
    let remote = flags & 2 != 0;
    let id_len = if extended { 4 } else { 2 };
    if rest.len() < id_len {
        return;
    }
    let (id_bytes, data) = rest.split_at(id_len);
    let id = id_bytes.iter().fold(0u32, |a, b| (a << 8) | u32::from(*b));
    let data = &data[..data.len().min(8)];
    let frame = match (extended, remote) {
        (_, true) => Frame::remote(id & 0x1FFF_FFFF, extended, data.len() as u8),
        (true, false) => Frame::extended(id & 0x1FFF_FFFF, data),
        (false, false) => Frame::standard((id & 0x7FF) as u16, data),
    };
    let Some(frame) = frame else { return };
    if let Ok(a) = Answer::decode(&frame, base) {
        assert_eq!(a.encode(base).ok(), Some(frame));
    }
    if let Ok(r) = Request::decode(&frame, base) {
        assert_eq!(r.encode(base).ok(), Some(frame));
    }
});
