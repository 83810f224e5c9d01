//! Property tests: round trips through the codec in both directions, and a parser that never panics.

use kuka_rsi::{ConfigElement, EthernetConfig, Frame, Ipoc, Layout, ValueType};
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

/// A frame of `s` with `values` in its slots (repeated as needed; integers rounded) and `ipoc`.
fn frame_of(s: &kuka_rsi::Schema, values: &[f64], ipoc: u64) -> Frame {
    let mut f = Frame::new();
    for slot in 0..s.slots() {
        let v = values[slot % values.len()];
        let is_long = s.field_of(slot).unwrap().ty == ValueType::Long;
        f.set(slot, if is_long { v.round() } else { v });
    }
    f.set_ipoc(Ipoc::new(ipoc));
    f
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
        let f = frame_of(&s, &values, ipoc);
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
    fn process_channels_round_trip(
        mode in -3i64..6,
        force in -1.0e5f64..1.0e5,
        ramp in 0.0f64..100.0,
        seg in any::<i32>(),
        phase in proptest::sample::select(vec![0i64, 1, 2, 3, 4, 9]),
        fault in 0i64..=6,
        measured in proptest::num::f64::ANY,
    ) {
        use hal::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};
        use kuka_rsi::{CommandSlots, ProcessChannels, StateSlots};
        let c = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false)
            .with_process(ProcessChannels::default());
        // Robot -> PC.
        let rob = c.rob_schema(4).unwrap();
        let cs = CommandSlots::find(&rob).unwrap().unwrap();
        let mut f = Frame::new();
        for slot in 0..rob.slots() {
            f.set(slot, 0.0);
        }
        let cmd = ProcessCommand { mode: ProcessMode::from_code(mode), force, ramp, segment: i64::from(seg) };
        cs.encode(&cmd, &mut f);
        f.set_ipoc(Ipoc::new(1));
        let mut buf = [0u8; 2048];
        let n = rob.write(&f, &mut buf).unwrap();
        let mut back = Frame::new();
        rob.parse(&buf[..n], &mut back).unwrap();
        let got = cs.decode(&back);
        prop_assert_eq!(got.mode, cmd.mode);
        prop_assert_eq!(got.segment, cmd.segment);
        prop_assert!((got.force - force).abs() <= 0.5e-4 + 1e-9);
        prop_assert!((got.ramp - ramp).abs() <= 0.5e-4 + 1e-9);
        // PC -> robot: any force, even NaN or inf, is written as a plain number with 2 decimals.
        let mut sen = c.sen_schema(4).unwrap();
        let ss = StateSlots::find(&mut sen).unwrap().unwrap();
        let mut f = Frame::new();
        for slot in 0..sen.slots() {
            f.set(slot, 0.0);
        }
        let st = ProcessState {
            phase: ProcessPhase::from_code(phase).unwrap(),
            force: measured,
            fault: ProcessFault::from_code(fault).unwrap(),
        };
        ss.encode(&st, &mut f);
        f.set_ipoc(Ipoc::new(1));
        let n = sen.write(&f, &mut buf).unwrap();
        let mut back = Frame::new();
        sen.parse(&buf[..n], &mut back).unwrap();
        let got = ss.decode(&back).unwrap();
        prop_assert_eq!(got.phase, st.phase);
        prop_assert_eq!(got.fault, st.fault);
        let expect = kuka_rsi::wire::force_to_wire(measured);
        prop_assert!((got.force - expect).abs() <= 0.5e-2 + 1e-9, "{} -> {}", measured, got.force);
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

    /// A learnt layout reads every message as the strict parser does — the same error, or the same
    /// IPOC and values — whatever was learnt before: messages with new values (other lengths), and
    /// mutated, truncated or stretched ones.
    #[test]
    fn the_learnt_layout_reads_as_the_strict_parser_does(
        values in proptest::collection::vec(-1.0e6f64..1.0e6, 1..40),
        ipoc in any::<u64>(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 0..4),
        cut in any::<prop::sample::Index>(),
    ) {
        let s = cfg().rob_schema(4).unwrap();
        let mut layout = Layout::new(4096);
        let f = frame_of(&s, &values, ipoc);
        let mut buf = [0u8; 4096];
        let n = s.write(&f, &mut buf).unwrap();
        let mut mutated = buf[..n].to_vec();
        for (at, b, op) in edits {
            let i = at.index(mutated.len());
            match op {
                0 => mutated[i] = b,
                1 => mutated.insert(i, b),
                _ => { mutated.remove(i); }
            }
        }
        let cut = cut.index(mutated.len() + 1).max(mutated.len() / 2);
        mutated.truncate(cut);
        let golden = golden_rob();
        for msg in [&golden, &buf[..n].to_vec(), &mutated, &golden, &mutated] {
            let (mut a, mut b) = (Frame::new(), Frame::new());
            let strict = s.parse(msg, &mut a);
            let learnt = layout.parse(&s, msg, &mut b);
            prop_assert_eq!(strict, learnt);
            if strict.is_ok() {
                prop_assert_eq!(a.ipoc(), b.ipoc());
                for slot in 0..s.slots() {
                    prop_assert_eq!(a.is_present(slot), b.is_present(slot));
                    if a.is_present(slot) {
                        prop_assert_eq!(a.get(slot).to_bits(), b.get(slot).to_bits(), "slot {}", slot);
                    }
                }
            }
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
