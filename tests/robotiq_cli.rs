//! The `forcecell` binary's Robotiq commands: `sim-sensor robotiq` serves a simulated FT 300 on a
//! pseudo-terminal and prints its path, `sensor robotiq --port PATH info|read|zero` talks to it from
//! another process, and `sim --sensor robotiq` runs a scenario through the driver over a pty.

mod common;

use common::run;

#[test]
fn sensor_commands_talk_to_the_simulated_ft300_in_another_process() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ft300");
    let _sensor = common::ft300(&link, "12.5");
    let port = link.to_str().unwrap();

    let (out, info) = run(&["sensor", "robotiq", "--port", port, "info"]);
    assert!(out.status.success(), "{info}");
    assert!(info.contains("firmware         FTS-3.1.0"), "{info}");
    assert!(info.contains("serial           FTS-875704368"), "{info}");
    assert!(info.contains("production year  2021"), "{info}");
    assert!(info.contains("Fz 12.50 N"), "{info}");

    let (out, read) = run(&["sensor", "robotiq", "--port", port, "read", "--count", "3"]);
    assert!(out.status.success(), "{read}");
    assert!(read.contains("12.500"), "{read}");
    assert!(read.contains("0 CRC errors"), "{read}");

    let (out, zero) = run(&["sensor", "robotiq", "--port", port, "zero"]);
    assert!(out.status.success(), "{zero}");
    assert!(zero.contains("Fz 12.500"), "{zero}");

    let (out, text) = run(&["sensor", "robotiq", "--port", "/dev/forcecell-none", "info"]);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("/dev/forcecell-none"), "{text}");
}

#[test]
fn sim_runs_b1_on_p2_through_the_ft300_driver() {
    let dir = tempfile::tempdir().unwrap();
    let (out, text) = run(&[
        "sim",
        "-s",
        "b01-approach",
        "--plant",
        "p2",
        "--tuning",
        "robust-100hz",
        "--sensor",
        "robotiq",
        "--check",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("Robotiq FT 300 driver"), "{text}");
    // Every cycle read a good sample: a sensor error would be counted on the summary's
    // `conditions` line as "N sensor error".
    assert!(text.contains("conditions"), "{text}");
    assert!(!text.contains("sensor error"), "{text}");
    assert!(!text.contains("FAIL"), "{text}");
}
