//! Fuzz the `<Sen>` parser (what the simulated KUKA controller reads from the PC, the opposite direction
//! of `rob_parser`): it must never panic, and what it accepts must write and parse back the same.
#![no_main]

use kuka_rsi::{EthernetConfig, Frame, Schema};
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

fn schema() -> &'static Schema {
    static S: OnceLock<Schema> = OnceLock::new();
    S.get_or_init(|| {
        EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false)
            .sen_schema(4)
            .expect("valid schema")
    })
}

fuzz_target!(|data: &[u8]| {
    let schema = schema();
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
