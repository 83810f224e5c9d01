//! Fuzz the `<Rob>` parser (the bytes a network peer controls) and, when it accepts, check that
//! writing what it parsed and parsing that again gives the same frame. Two configs: without and with
//! the process channels (`FcCmd`), whose decoding must never panic either. And a layout learnt from a
//! well-formed message reads the bytes as the strict parser does (the same error, or the same values).
#![no_main]

use kuka_rsi::{
    CommandSlots, ConfigElement, EthernetConfig, Frame, Layout, ProcessChannels, Schema, ValueType,
};
use libfuzzer_sys::fuzz_target;

fn check(schema: &Schema, data: &[u8]) {
    let mut learnt = vec![0u8; 65536];
    let n = schema
        .write(&Frame::new(), &mut learnt)
        .expect("an all-zero frame writes");
    let mut layout = Layout::new(65536);
    layout
        .parse(schema, &learnt[..n], &mut Frame::new())
        .expect("the writer's output must parse");
    // A layout that converts only slot 0 (the others checked) accepts and refuses alike.
    let mut reading = Layout::reading(65536, 1);
    reading
        .parse(schema, &learnt[..n], &mut Frame::new())
        .expect("the writer's output must parse");
    let (mut strict, mut fast, mut some) = (Frame::new(), Frame::new(), Frame::new());
    let result = schema.parse(data, &mut strict);
    assert_eq!(result, layout.parse(schema, data, &mut fast));
    assert_eq!(result, reading.parse(schema, data, &mut some));
    if result.is_ok() && strict.is_present(0) {
        assert_eq!(strict.get(0).to_bits(), some.get(0).to_bits());
    }
    if result.is_ok() {
        assert_eq!(strict.ipoc(), fast.ipoc());
        for slot in 0..schema.slots() {
            assert_eq!(strict.is_present(slot), fast.is_present(slot));
            if strict.is_present(slot) {
                assert_eq!(strict.get(slot).to_bits(), fast.get(slot).to_bits());
            }
        }
    }
    let mut frame = Frame::new();
    if schema.parse(data, &mut frame).is_ok() {
        if let Some(slots) = CommandSlots::find(schema).expect("valid process channels") {
            let c = slots.decode(&frame);
            assert!(c.force.is_finite() && c.ramp.is_finite());
        }
        let mut buf = vec![0u8; 65536];
        if let Ok(n) = schema.write(&frame, &mut buf) {
            let mut again = Frame::new();
            schema
                .parse(&buf[..n], &mut again)
                .expect("the writer's output must parse");
            assert_eq!(again.ipoc(), frame.ipoc());
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let mut cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false);
    cfg.send
        .push(ConfigElement::channel("User.V", ValueType::Double, 1, None));
    cfg.send
        .push(ConfigElement::channel("Txt", ValueType::String, 2, None));
    check(&cfg.rob_schema(4).expect("valid schema"), data);
    let cfg = cfg.with_process(ProcessChannels {
        cmd: [3, 4, 5, 6],
        state: [8, 9, 10],
    });
    check(&cfg.rob_schema(4).expect("valid schema"), data);
});
