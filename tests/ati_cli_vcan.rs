//! The `forcecell` binary's ATI commands on a real vcan interface: `sim-sensor ati` serves a simulated
//! node, `sensor ati info|read|tare` talks to it from another process, and `sim --can` runs a scenario
//! through the driver over the interface. Ignored in a plain `cargo test`; `scripts/vcan-tests.sh`
//! runs them natively, inside User-Mode Linux or inside QEMU.

use std::process::{Child, Command, Output, Stdio};

fn iface() -> String {
    std::env::var("FORCECELL_VCAN").unwrap_or_else(|_| "vcan0".into())
}

/// Headroom for slow guests (`FORCECELL_VCAN_TIME_SCALE`, 1 to 100; `scripts/vcan-tests.sh` raises it
/// under QEMU's software emulation): the sensor's turnaround is multiplied by it and the read rate
/// divided by it, so the driver's own check (a poll must fit in one period) still holds.
fn time_scale() -> u32 {
    std::env::var("FORCECELL_VCAN_TIME_SCALE")
        .ok()
        .map(|s| {
            s.parse::<u32>()
                .ok()
                .filter(|k| (1..=100).contains(k))
                .unwrap_or_else(|| panic!("FORCECELL_VCAN_TIME_SCALE must be 1 to 100, not {s:?}"))
        })
        .unwrap_or(1)
}

fn forcecell() -> Command {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
}

struct Kill(Child);

impl Drop for Kill {
    fn drop(&mut self) {
        // Ends only the node process this test started, by its own handle.
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn run(args: &[&str]) -> (Output, String) {
    let out = forcecell().args(args).output().expect("run forcecell");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out, text)
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn sensor_commands_talk_to_the_simulated_node_in_another_process() {
    let can = iface();
    let _node = Kill(
        forcecell()
            .args([
                "sim-sensor",
                "ati",
                "--can",
                &can,
                "--base",
                "0x31",
                "--fz",
                "12.5",
            ])
            .args(["--noise", "0", "--seconds", "120"])
            .stdout(Stdio::null())
            .spawn()
            .expect("start sim-sensor"),
    );
    let turnaround = (20_000 * time_scale()).to_string();
    let rate = (20.0 / f64::from(time_scale())).to_string();
    let common = [
        "sensor",
        "ati",
        "--can",
        &can,
        "--base",
        "0x31",
        "--turnaround-us",
        &turnaround,
    ];

    // The node binds its socket right after starting: retry `info` until it answers.
    let mut info = String::new();
    for _ in 0..20 {
        let (out, text) = run(&[&common[..], &["info"]].concat());
        info = text;
        if out.status.success() {
            break;
        }
    }
    assert!(info.contains("firmware        3.8 build 1"), "{info}");
    assert!(info.contains("serial          FT-SIM01"), "{info}");
    assert!(info.contains("status          0x0000"), "{info}");

    let (out, text) = run(&[&common[..], &["read", "--count", "3", "--rate", &rate]].concat());
    assert!(out.status.success(), "{text}");
    let fz: Vec<f64> = text
        .lines()
        .filter(|l| l.trim_end().ends_with("Ok"))
        .filter_map(|l| l.split_whitespace().nth(3)?.parse().ok())
        .collect();
    assert_eq!(fz.len(), 3, "{text}");
    assert!(fz.iter().all(|f| (f - 12.5).abs() < 0.02), "{fz:?}\n{text}");

    let (out, text) = run(&[
        &common[..],
        &["read", "--count", "2", "--rate", &rate, "--tare"],
    ]
    .concat());
    assert!(out.status.success(), "{text}");
    let after: Vec<f64> = text
        .lines()
        .filter(|l| l.trim_end().ends_with("Ok"))
        .filter_map(|l| l.split_whitespace().nth(3)?.parse().ok())
        .collect();
    assert_eq!(after.len(), 2, "{text}");
    assert!(
        after.iter().all(|f| f.abs() < 0.02),
        "bias removed: {after:?}\n{text}"
    );

    let (out, text) = run(&[&common[..], &["tare"]].concat());
    assert!(
        out.status.success() && text.contains("bias (counts"),
        "{text}"
    );
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn sim_runs_a_scenario_through_the_driver_over_vcan() {
    let dir = std::env::temp_dir().join(format!("forcecell-ati-vcan-{}", std::process::id()));
    let can = iface();
    let (out, text) = run(&[
        "sim",
        "--scenario",
        "paper-fig9",
        "--can",
        &can,
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains(&format!("ATI driver ↔ simulated node on {can}")),
        "{text}"
    );
    assert!(text.contains("ran 2000 steps"), "{text}");
    assert!(dir.join("paper-fig9.csv").exists(), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
