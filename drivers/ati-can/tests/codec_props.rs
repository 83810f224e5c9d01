//! Property tests of the codec: decoding never panics, accepts only what the spec allows, and every
//! accepted frame encodes back to the same bytes.

use ati_can::codec::{interleave, split};
use ati_can::{Answer, Base, CodecError, Frame, Gauges, Request};
use proptest::prelude::*;

fn any_frame() -> impl Strategy<Value = Frame> {
    (
        0u32..0x2000_0000,
        any::<bool>(),
        any::<bool>(),
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(id, ext, rtr, data)| {
            if rtr {
                Frame::remote(if ext { id } else { id & 0x7FF }, ext, data.len() as u8).unwrap()
            } else if ext {
                Frame::extended(id, &data).unwrap()
            } else {
                Frame::standard((id & 0x7FF) as u16, &data).unwrap()
            }
        })
}

proptest! {
    #[test]
    fn decoding_any_frame_is_total_and_strict(frame in any_frame(), base in 0u8..=0x7F) {
        let base = Base::new(base).unwrap();
        match Answer::decode(&frame, base) {
            Ok(a) => {
                prop_assert!(!frame.is_extended() && !frame.is_remote());
                prop_assert_eq!(frame.id() >> 4, u32::from(base.get()));
                // Bit-exact round trip (floats compared through their bits by re-encoding).
                prop_assert_eq!(a.encode(base).unwrap(), frame);
            }
            Err(CodecError::Extended { .. }) => prop_assert!(frame.is_extended()),
            Err(CodecError::Remote { .. }) => prop_assert!(frame.is_remote()),
            Err(CodecError::Foreign { id }) => prop_assert_ne!(id >> 4, u32::from(base.get())),
            Err(_) => {}
        }
        match Request::decode(&frame, base) {
            Ok(r) => prop_assert_eq!(r.encode(base).unwrap(), frame),
            Err(e) => prop_assert!(!e.to_string().is_empty()),
        }
    }

    #[test]
    fn gauges_survive_the_two_frame_split(g in any::<[i16; 6]>(), status in any::<u16>()) {
        let gauges = Gauges(g);
        let (a, b) = split(&gauges);
        let f0 = Answer::PollFirst { status: ati_can::Status(status), gauges: a }.encode(Base::DEFAULT).unwrap();
        let f1 = Answer::PollSecond { gauges: b }.encode(Base::DEFAULT).unwrap();
        let (Ok(Answer::PollFirst { gauges: a2, status: s2 }), Ok(Answer::PollSecond { gauges: b2 })) =
            (Answer::decode(&f0, Base::DEFAULT), Answer::decode(&f1, Base::DEFAULT)) else {
            return Err(TestCaseError::fail("poll frames must decode"));
        };
        prop_assert_eq!(s2.0, status);
        prop_assert_eq!(interleave(a2, b2), gauges);
        prop_assert_eq!(gauges.is_saturated(), g.iter().any(|&v| v == i16::MIN || v == i16::MAX));
    }
}
