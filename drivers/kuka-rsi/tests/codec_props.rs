//! Property tests: round trips through the codec in both directions, and a parser that never panics.

use kuka_rsi::{ConfigElement, EthernetConfig, Frame, Ipoc, ValueType};
use proptest::prelude::*;

fn cfg() -> EthernetConfig {
    let mut c = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false);
    c.send
        .push(ConfigElement::internal("DEF_ESPos", ValueType::Double));
    c.send.push(ConfigElement::channel(
        "Force.Fz",
        ValueType::Double,
        1,
        None,
    ));
    c.send
        .push(ConfigElement::channel("Count", ValueType::Long, 2, None));
    c
}

fn golden_rob() -> Vec<u8> {
    let s = cfg().rob_schema(4).unwrap();
    let mut f = Frame::new();
    for slot in 0..s.slots() {
        f.set(slot, slot as f64 * 1.25 - 7.0);
    }
    f.set_ipoc(Ipoc::new(123_645_634_563));
    let mut buf = vec![0u8; 4096];
    let n = s.write(&f, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn rob_round_trip(
        values in proptest::collection::vec(-1.0e6f64..1.0e6, 40),
        ipoc in any::<u64>(),
        precision in 0u8..=6,
    ) {
        let s = cfg().rob_schema(precision).unwrap();
        let mut f = Frame::new();
        for slot in 0..s.slots() {
            let v = values[slot % values.len()];
            let is_long = s.field_of(slot).unwrap().ty == ValueType::Long;
            f.set(slot, if is_long { v.round() } else { v });
        }
        f.set_ipoc(Ipoc::new(ipoc));
        let mut buf = [0u8; 4096];
        let n = s.write(&f, &mut buf).unwrap();
        let mut back = Frame::new();
        s.parse(&buf[..n], &mut back).unwrap();
        prop_assert_eq!(back.ipoc(), f.ipoc());
        let tol = 0.5 * 10f64.powi(-i32::from(precision)) * (1.0 + 1e-9) + 1e-9;
        for slot in 0..s.slots() {
            prop_assert!((back.get(slot) - f.get(slot)).abs() <= tol,
                "slot {}: {} -> {}", slot, f.get(slot), back.get(slot));
        }
        // Writing what was parsed gives the same bytes: the wire form is a fixed point.
        let mut again = [0u8; 4096];
        let m = s.write(&back, &mut again).unwrap();
        prop_assert_eq!(&buf[..n], &again[..m]);
    }

    #[test]
    fn sen_round_trip(
        korr in proptest::array::uniform6(-5.0f64..5.0),
        stop in any::<bool>(),
        ipoc_text in "[0-9]{1,19}",
    ) {
        let s = cfg().sen_schema(4).unwrap();
        let mut f = Frame::new();
        f.set6(s.six("RKorr", ["X", "Y", "Z", "A", "B", "C"]).unwrap(), korr);
        f.set(s.slot("Stop", "").unwrap(), f64::from(u8::from(stop)));
        f.set_ipoc(Ipoc::parse(ipoc_text.as_bytes()).unwrap());
        let mut buf = [0u8; 1024];
        let n = s.write(&f, &mut buf).unwrap();
        let mut back = Frame::new();
        s.parse(&buf[..n], &mut back).unwrap();
        prop_assert_eq!(back.ipoc().digits(), ipoc_text.as_bytes(), "echoed verbatim");
        prop_assert_eq!(back.get(s.slot("Stop", "").unwrap()) != 0.0, stop);
        for (i, slot) in s.six("RKorr", ["X", "Y", "Z", "A", "B", "C"]).unwrap().into_iter().enumerate() {
            prop_assert!((back.get(slot) - korr[i]).abs() <= 0.5e-4 + 1e-12);
        }
    }

    #[test]
    fn parser_never_panics_on_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let s = cfg().rob_schema(4).unwrap();
        let mut f = Frame::new();
        let _ = s.parse(&bytes, &mut f);
    }

    #[test]
    fn parser_never_panics_on_mutated_golden(
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<prop::sample::Index>(),
    ) {
        let s = cfg().rob_schema(4).unwrap();
        let mut bytes = golden_rob();
        for (at, b) in edits {
            let i = at.index(bytes.len());
            bytes[i] = b;
        }
        let cut = cut.index(bytes.len() + 1);
        let mut f = Frame::new();
        let full = s.parse(&bytes, &mut f);
        let truncated = s.parse(&bytes[..cut], &mut f);
        if cut < bytes.len() && full.is_ok() {
            // A strict prefix of a good document is never a good document.
            prop_assert!(truncated.is_err());
        }
    }

    #[test]
    fn config_round_trip(
        channels in proptest::collection::btree_map("[A-Z][a-z]{0,6}", (0usize..4, any::<bool>()), 1..20),
        onlysend in any::<bool>(),
    ) {
        let mut c = EthernetConfig::forcecell([10, 0, 0, 2].into(), 6008, true);
        c.onlysend = onlysend;
        let types = [ValueType::Bool, ValueType::Long, ValueType::Double, ValueType::String];
        for (i, (tag, (ty, holdon))) in channels.into_iter().enumerate() {
            let tag = format!("U{tag}");
            c.send.push(ConfigElement::channel(&tag, types[ty], i as u8 + 1, None));
            c.receive.push(ConfigElement::channel(&format!("{tag}.v"), types[ty], i as u8 + 8, Some(holdon)));
        }
        let back = EthernetConfig::parse(&c.to_xml()).unwrap();
        prop_assert_eq!(back, c);
    }
}
