//! Property tests of the stream codec: any byte stream yields only frames whose 16 bytes are in the input
//! with a good CRC, and the decoder resynchronises within one frame length after garbage.

use proptest::prelude::*;
use robotiq::codec::{Counts, Event, FRAME_LEN, StreamDecoder, crc16, decode_frame, encode_frame};

fn counts() -> impl Strategy<Value = Counts> {
    proptest::array::uniform6(any::<i16>()).prop_map(Counts)
}

/// Every frame the decoder emits for `bytes`, with the index of its last byte.
fn decode_all(bytes: &[u8]) -> Vec<(usize, Counts)> {
    let mut d = StreamDecoder::new();
    let mut out = Vec::new();
    for (i, &b) in bytes.iter().enumerate() {
        if let Some(Event::Frame(c)) = d.push(b) {
            out.push((i, c));
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn frames_round_trip(c in counts()) {
        let f = encode_frame(c);
        prop_assert_eq!(decode_frame(&f), Ok(c));
        prop_assert_eq!(crc16(&f[..14]).to_le_bytes(), [f[14], f[15]]);
        prop_assert_eq!(robotiq::Counts::from_wrench(&c.to_wrench()), Ok(c));
    }

    /// Never a sample from a bad CRC: whatever comes in, each emitted frame is exactly the 16 input
    /// bytes that end where it was emitted, and those bytes carry a good header and CRC.
    #[test]
    fn any_stream_yields_only_checked_frames(
        bytes in proptest::collection::vec(
            prop_oneof![any::<u8>(), Just(0x20u8), Just(0x4Eu8), Just(0xFFu8)], 0..600),
        frames in proptest::collection::vec((counts(), 0usize..600), 0..8),
    ) {
        // Sprinkle whole frames into the noise so that good and broken candidates interleave.
        let mut bytes = bytes;
        for (c, at) in frames {
            let at = at.min(bytes.len());
            bytes.splice(at..at, encode_frame(c));
        }
        for (end, c) in decode_all(&bytes) {
            prop_assert!(end + 1 >= FRAME_LEN);
            let window: [u8; FRAME_LEN] = bytes[end + 1 - FRAME_LEN..=end].try_into().unwrap();
            prop_assert_eq!(window, encode_frame(c));
            prop_assert_eq!(decode_frame(&window), Ok(c));
        }
    }

    /// After any garbage, at most the first frame is lost: every later frame is decoded, in order.
    /// (The first one too, unless a false candidate in the garbage happens to pass its CRC.)
    #[test]
    fn resync_after_garbage_within_one_frame(
        garbage in proptest::collection::vec(
            prop_oneof![any::<u8>(), Just(0x20u8), Just(0x4Eu8)], 0..200),
        sent in proptest::collection::vec(counts(), 2..6),
    ) {
        let mut bytes = garbage.clone();
        for c in &sent {
            bytes.extend_from_slice(&encode_frame(*c));
        }
        let decoded: Vec<(usize, Counts)> = decode_all(&bytes)
            .into_iter()
            .filter(|(end, _)| *end >= garbage.len())
            .collect();
        let got: Vec<Counts> = decoded.iter().map(|(_, c)| *c).collect();
        prop_assert!(got.ends_with(&sent[1..]), "sent {:?}, got {:?}", sent, got);
        // Before them: the first frame, or a false candidate that began in the garbage, passed its CRC
        // and swallowed the first frame's bytes, or both (the candidate ended before the frame began
        // to be read), never more.
        let before = &decoded[..decoded.len() - (sent.len() - 1)];
        prop_assert!(before.len() <= 2, "sent {:?}, got {:?}", sent, got);
        let first_end = garbage.len() + FRAME_LEN - 1;
        for (end, c) in before {
            if (*end, *c) != (first_end, sent[0]) {
                // A false candidate: 16 bytes of the input with a good header and CRC, ending before
                // the first frame does.
                prop_assert!(*end < first_end, "{end} {c:?}");
                let window: [u8; FRAME_LEN] = bytes[end + 1 - FRAME_LEN..=*end].try_into().unwrap();
                prop_assert_eq!(decode_frame(&window), Ok(*c));
            }
        }
    }

    /// A frame with any single bit flipped never becomes a sample; its neighbours still do.
    #[test]
    fn a_corrupted_frame_is_dropped_and_its_neighbours_kept(
        a in counts(), b in counts(), c in counts(), bit in 0usize..(8 * FRAME_LEN),
    ) {
        let mut bad = encode_frame(b);
        bad[bit / 8] ^= 1 << (bit % 8);
        let mut bytes = encode_frame(a).to_vec();
        bytes.extend_from_slice(&bad);
        bytes.extend_from_slice(&encode_frame(c));
        let got: Vec<Counts> = decode_all(&bytes).into_iter().map(|(_, c)| c).collect();
        prop_assert_eq!(got.first(), Some(&a));
        prop_assert_eq!(got.last(), Some(&c));
        // Bytes of the broken frame never produce a frame (no second valid CRC hides in 16 bytes
        // formed from one frame and a flipped bit except by a 2^-16 coincidence, which would still
        // be a checked frame: the previous property covers that).
        prop_assert!(got.len() <= 3);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// `feed` (whole reads, aligned frames checked in place) gives exactly the events and counters of
    /// pushing the same bytes one by one, however the stream is cut into reads.
    #[test]
    fn feeding_reads_equals_pushing_bytes(
        noise in proptest::collection::vec(
            prop_oneof![any::<u8>(), Just(0x20u8), Just(0x4Eu8)], 0..300),
        frames in proptest::collection::vec((counts(), 0usize..300, any::<bool>()), 0..10),
        cuts in proptest::collection::vec(1usize..40, 1..30),
    ) {
        let mut bytes = noise;
        for (c, at, corrupt) in frames {
            let at = at.min(bytes.len());
            let mut f = encode_frame(c);
            if corrupt {
                f[3] ^= 0x08;
            }
            bytes.splice(at..at, f);
        }
        let mut one = StreamDecoder::new();
        let mut by_byte = Vec::new();
        for &b in &bytes {
            by_byte.extend(one.push(b));
        }
        let mut fed = StreamDecoder::new();
        let mut by_read = Vec::new();
        let mut rest = &bytes[..];
        let mut k = 0;
        while !rest.is_empty() {
            let n = cuts[k % cuts.len()].min(rest.len());
            fed.feed(&rest[..n], |e| by_read.push(e));
            rest = &rest[n..];
            k += 1;
        }
        prop_assert_eq!(by_read, by_byte);
        prop_assert_eq!(fed.counters(), one.counters());
    }
}
