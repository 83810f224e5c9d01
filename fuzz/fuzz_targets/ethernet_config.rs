//! Fuzz the robot's Ethernet config XML parser (`ethernet_config` in a cell file): any text gives a
//! config or an error, never a panic; an accepted config either validates or says why not, and its
//! schemas build or fail cleanly.
#![no_main]

use kuka_rsi::EthernetConfig;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(cfg) = EthernetConfig::parse(text) {
        let _ = cfg.validate();
        let _ = cfg.rob_schema(4);
        let _ = cfg.sen_schema(4);
    }
});
