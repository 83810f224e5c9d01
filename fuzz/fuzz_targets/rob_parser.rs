//! Fuzz the `<Rob>` parser (the bytes a network peer controls) and, when it accepts, check that
//! writing what it parsed and parsing that again gives the same frame.
#![no_main]

use kuka_rsi::{ConfigElement, EthernetConfig, Frame, ValueType};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false);
    cfg.send
        .push(ConfigElement::channel("User.V", ValueType::Double, 1, None));
    cfg.send
        .push(ConfigElement::channel("Txt", ValueType::String, 2, None));
    let schema = cfg.rob_schema(4).expect("valid schema");
    let mut frame = Frame::new();
    if schema.parse(data, &mut frame).is_ok() {
        let mut buf = vec![0u8; 65536];
        if let Ok(n) = schema.write(&frame, &mut buf) {
            let mut again = Frame::new();
            schema
                .parse(&buf[..n], &mut again)
                .expect("the writer's output must parse");
            assert_eq!(again.ipoc(), frame.ipoc());
        }
    }
});
