//! `forcecell removal` and the map `sim` writes at the end of a programmed pass: the numbers are the
//! model's own (`scenario::removal`), the path comes from the recorded poses, a recording without poses
//! is refused with one error, and the input is never touched.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::run;

fn stats_of(mcap_path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(mcap_path).unwrap();
    let mut topics = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        *topics.entry(m.channel.topic.clone()).or_insert(0) += 1;
        if m.channel.topic == "/removal/stats" {
            return serde_json::from_slice(&m.data).unwrap();
        }
    }
    panic!("no /removal/stats in {}: {topics:?}", mcap_path.display());
}

#[test]
fn a_sim_pass_maps_what_the_model_computes_and_leaves_the_recording_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    // The default wires: the RSI driver against the simulated KRC, the ATI driver against its node.
    let (o, text) = run(&["sim", "--scenario", "pass-flat-20n", "--out", out]);
    assert!(o.status.success(), "{text}");
    let rec = dir.path().join("pass-flat-20n.mcap");
    for f in ["pass-flat-20n-removal.mcap", "pass-flat-20n-removal.png"] {
        assert!(
            dir.path().join(f).metadata().unwrap().len() > 1000,
            "sim wrote {f}: {text}"
        );
    }
    let before = std::fs::read(&rec).unwrap();
    let again = dir.path().join("again");
    let (o, text) = run(&[
        "removal",
        rec.to_str().unwrap(),
        "--config",
        "pass-flat-20n",
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{text}");
    assert_eq!(
        std::fs::read(&rec).unwrap(),
        before,
        "the input is untouched"
    );
    assert!(text.contains("mean removal"), "{text}");

    // The recorded poses move along the path: 100 mm along base x, none across.
    let back = forcecell::recorder::read_mcap(&before).unwrap();
    let xs: Vec<f64> = back
        .poses
        .iter()
        .map(|p| p[0])
        .filter(|x| x.is_finite())
        .collect();
    let span = xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - xs.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!((span - 0.1).abs() < 1e-3, "the path spans {span} m");

    // The CLI's figures are the model's own computation on the same samples.
    let cfg = forcecell::removal::load_config("pass-flat-20n").unwrap();
    let (samples, source) = forcecell::removal::samples(&rec).unwrap();
    assert!(source.contains("true"), "{source}");
    let r = scenario::removal::analyse(&cfg, &samples).unwrap();
    let stats = stats_of(&again.join("pass-flat-20n-removal.mcap"));
    let mean = stats["mean"].as_f64().unwrap();
    assert!(
        (mean - r.stats.mean).abs() <= 1e-12 * r.stats.mean,
        "{mean} vs {}",
        r.stats.mean
    );
    assert_eq!(stats["coverage"].as_f64().unwrap(), 1.0);

    // And the model's by hand: on the centreline of a uniform pad dragged at u, a point lies under
    // the patch for 2R/u, so depth = k_p · F/(πR²) · (v_disc + u) · 2R/u (20 N, R = 10 mm, u = 50 mm/s,
    // 3000 rpm at 20 mm). The force holds 20 N within the pass's band, so within 2 %.
    let (f, radius, u) = (20.0, 0.01, 0.05);
    let v = 3000.0 * std::f64::consts::TAU / 60.0 * 0.02 + u;
    let hand = cfg.preston * f / (std::f64::consts::PI * radius * radius) * v * 2.0 * radius / u;
    assert!(
        (mean - hand).abs() < 0.02 * hand,
        "mean {mean} m against {hand} m by hand"
    );
    assert!(stats["uniformity"].as_f64().unwrap() < 0.01, "{stats}");
    assert_eq!(stats["under"].as_f64().unwrap(), 0.0, "{stats}");
}

/// A recording from before poses were recorded: one channel per group of fields, no `robot.pose`.
fn recording_without_poses() -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut w = mcap::Writer::new(&mut buf).unwrap();
    let schema = w
        .add_schema("forcecell.Force", "jsonschema", br#"{"type":"object"}"#)
        .unwrap();
    let ch = w
        .add_channel(schema, "/force", "json", &BTreeMap::new())
        .unwrap();
    for k in 0..50u32 {
        let t = u64::from(k + 1) * 4_000_000;
        let msg = format!(
            r#"{{"t":{},"f":20.0,"f_r":20.0,"error":0.0}}"#,
            t as f64 * 1e-9
        );
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: k,
            log_time: t,
            publish_time: t,
        };
        w.write_to_known_channel(&header, msg.as_bytes()).unwrap();
    }
    w.finish().unwrap();
    drop(w);
    buf.into_inner()
}

#[test]
fn a_recording_without_poses_is_refused_with_one_error_and_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("old.mcap");
    std::fs::write(&rec, recording_without_poses()).unwrap();
    let before = std::fs::read(&rec).unwrap();
    let (o, text) = run(&[
        "removal",
        rec.to_str().unwrap(),
        "--config",
        "pass-flat-20n",
    ]);
    assert!(!o.status.success(), "{text}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error:")).count(),
        1,
        "{err}"
    );
    assert!(err.contains("robot.pose"), "{err}");
    assert_eq!(std::fs::read(&rec).unwrap(), before);
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        left,
        vec![std::ffi::OsString::from("old.mcap")],
        "nothing written"
    );
}

#[test]
fn a_config_without_a_removal_table_or_with_a_bad_value_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("old.mcap");
    std::fs::write(&rec, recording_without_poses()).unwrap();
    let (o, text) = run(&["removal", rec.to_str().unwrap(), "--config", "b01-approach"]);
    assert!(!o.status.success());
    assert!(text.contains("no [removal] table"), "{text}");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[removal]\npreston = -1e-12\npad_radius = 0.01\n").unwrap();
    let (o, text) = run(&[
        "removal",
        rec.to_str().unwrap(),
        "--config",
        bad.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(text.contains("removal.preston"), "{text}");
}

#[test]
fn a_raster_from_sim_is_mapped_over_the_part_and_compared_side_by_side() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let (o, text) = run(&["sim", "--scenario", "raster-step", "--out", out]);
    assert!(o.status.success(), "{text}");
    assert!(text.contains("coverage           100.0 %"), "{text}");
    let rec = dir.path().join("raster-step.mcap");
    // The recorded poses are the raster: 11 passes 10 mm apart along base y.
    let back = forcecell::recorder::read_mcap(&std::fs::read(&rec).unwrap()).unwrap();
    let ys: Vec<f64> = back
        .poses
        .iter()
        .map(|p| p[1])
        .filter(|y| y.is_finite())
        .collect();
    let span = ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - ys.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(
        (span - 0.1).abs() < 1e-3,
        "the raster spans {span} m across"
    );
    let copy = dir.path().join("again.mcap");
    std::fs::copy(&rec, &copy).unwrap();
    let png = dir.path().join("both.png");
    let (o, text) = run(&[
        "removal",
        rec.to_str().unwrap(),
        copy.to_str().unwrap(),
        "--config",
        "raster-step",
        "--out",
        dir.path().join("maps").to_str().unwrap(),
        "--compare",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{text}");
    let rows: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("| raster-step") || l.starts_with("| again"))
        .collect();
    assert_eq!(rows.len(), 2, "{text}");
    // The same recording twice: the same figures.
    assert_eq!(
        rows[0]
            .split_once('|')
            .unwrap()
            .1
            .split_once('|')
            .unwrap()
            .1,
        rows[1]
            .split_once('|')
            .unwrap()
            .1
            .split_once('|')
            .unwrap()
            .1
    );
    assert!(png.metadata().unwrap().len() > 10_000);
}
