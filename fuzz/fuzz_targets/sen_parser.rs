//! Fuzz the `<Sen>` parser (what the simulated KUKA controller reads from the PC, the opposite direction
//! of `rob_parser`): it must never panic, and what it accepts must write and parse back the same. Two
//! configs: without and with the process channels (`FcState`, whose decoding may refuse but not panic).
#![no_main]

use kuka_rsi::{EthernetConfig, Frame, ProcessChannels, Schema, StateSlots};
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

fn schemas() -> &'static [(Schema, Option<StateSlots>); 2] {
    static S: OnceLock<[(Schema, Option<StateSlots>); 2]> = OnceLock::new();
    S.get_or_init(|| {
        let plain = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false);
        let process = plain.clone().with_process(ProcessChannels::default());
        [plain, process].map(|c| {
            let mut s = c.sen_schema(4).expect("valid schema");
            let slots = StateSlots::find(&mut s).expect("valid process channels");
            (s, slots)
        })
    })
}

fuzz_target!(|data: &[u8]| {
    for (schema, slots) in schemas() {
        let mut frame = Frame::new();
        if schema.parse(data, &mut frame).is_ok() {
            if let Some(slots) = slots {
                let _ = slots.decode(&frame);
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
});
