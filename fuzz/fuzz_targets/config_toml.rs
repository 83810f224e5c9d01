//! Fuzz the TOML loaders a user hands forcecell — scenario, tuning and cell files: any text gives a
//! validated value or an error, never a panic. The first byte picks the loader.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    match which % 3 {
        0 => {
            if let Ok(s) = forcecell::scenario::Scenario::from_toml(text, "fuzz.toml") {
                // A scenario that validates must resolve (or refuse) its plant and tuning cleanly.
                let _ = forcecell::runner::RunSpec::new(s, None, None);
            }
        }
        1 => {
            let _ = forcecell::scenario::tuning_from_toml(text, "fuzz.toml");
        }
        _ => {
            if let Ok(c) = forcecell::cell::CellConfig::from_toml(text, "fuzz.toml")
                && let Ok(t) = forcecell::scenario::load_tuning("robust")
            {
                let _ = c.robot_spec(&t);
                let _ = c.compensator();
            }
        }
    }
});
