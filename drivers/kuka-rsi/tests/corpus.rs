//! Every file of `tests/rsi-corpus/` (configurations and datagrams reproducing what published RSI
//! configurations and captures contain; see its README) read as forcecell must read it.

use std::path::{Path, PathBuf};

use kuka_rsi::{EthernetConfig, Frame, Layout, MAX_ATTRIBUTES, ParseError, Schema};

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/rsi-corpus")
}

/// What `run` must do with each configuration: `None` accept it, `Some(words)` refuse it with one
/// line containing `words`.
const CONFIGS: &[(&str, Option<&str>)] = &[
    ("internal-receive.xml", None),
    ("bom-comments-crlf.xml", None),
    ("full-tech60.xml", None),
    ("tech-c1-c4.xml", None),
    (
        "axis-only.xml",
        Some("no Cartesian correction RKorr.X, RKorr.Y, RKorr.Z"),
    ),
    ("no-stop.xml", Some("no Stop channel")),
    ("onlysend.xml", Some("ONLYSEND is TRUE")),
];

fn files(dir: &str) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(corpus().join(dir))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn config(name: &str) -> EthernetConfig {
    let text = std::fs::read_to_string(corpus().join("configs").join(name)).unwrap();
    EthernetConfig::parse(&text).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn every_configuration_parses_and_run_accepts_or_refuses_it_as_listed() {
    let on_disk = files("configs");
    let listed: Vec<String> = CONFIGS.iter().map(|(n, _)| n.to_string()).collect();
    let mut sorted = listed.clone();
    sorted.sort();
    assert_eq!(
        on_disk, sorted,
        "every corpus configuration has an expectation here"
    );
    for (name, expect) in CONFIGS {
        let cfg = config(name);
        // Both schemas derive (what the driver reads, what it writes).
        cfg.rob_schema(4).unwrap_or_else(|e| panic!("{name}: {e}"));
        cfg.sen_schema(4).unwrap_or_else(|e| panic!("{name}: {e}"));
        match (cfg.check_for_control(false), expect) {
            (Ok(()), None) => {}
            (Err(e), Some(words)) => {
                let line = e.to_string();
                assert!(line.contains(words), "{name}: {line}");
                assert!(!line.contains('\n'), "{name}: one line: {line}");
            }
            (r, _) => panic!("{name}: expected {expect:?}, got {r:?}"),
        }
    }
}

#[test]
fn internal_receive_values_are_written_back_as_the_robot_expects() {
    let cfg = config("internal-receive.xml");
    let sen = cfg.sen_schema(4).unwrap();
    let mut out = vec![0u8; 4096];
    let n = sen.write(&Frame::new(), &mut out).unwrap();
    let text = core::str::from_utf8(&out[..n]).unwrap();
    // DEF_EStr: an empty message; DEF_Tech.T2: ten zeros T21..T210.
    assert!(text.contains("<EStr></EStr>"), "{text}");
    assert!(text.contains("<Tech T21=\"0.0000\""), "{text}");
    assert!(text.contains("T210=\"0.0000\"/>"), "{text}");
    // And the robot side (the simulated controller) reads that reply back.
    let mut f = Frame::new();
    sen.parse(&out[..n], &mut f).unwrap();
}

#[test]
fn the_process_channels_are_required_when_process_is_on() {
    let e = config("internal-receive.xml")
        .check_for_control(true)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("SEND has no FcCmd and RECEIVE no FcState"),
        "{e}"
    );
}

/// `<config stem>[--variant].rob.xml` is a `<Rob>` for that configuration.
#[test]
fn every_datagram_is_read_by_the_strict_parser_and_the_layout() {
    let names = files("datagrams");
    assert!(!names.is_empty());
    for name in names {
        let stem = name
            .strip_suffix(".rob.xml")
            .expect("datagrams are *.rob.xml");
        let cfg_name = format!("{}.xml", stem.split("--").next().unwrap());
        let rob: Schema = config(&cfg_name).rob_schema(4).unwrap();
        let bytes = std::fs::read(corpus().join("datagrams").join(&name)).unwrap();
        let mut strict = Frame::new();
        rob.parse(&bytes, &mut strict)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_ne!(strict.ipoc().value(), 0, "{name}");
        for slot in 0..rob.slots() {
            assert!(strict.is_present(slot), "{name}: slot {slot}");
        }
        // The fast path reads it the same way, twice (learn, then read through the layout).
        let mut layout = Layout::new(8192);
        for _ in 0..2 {
            let mut f = Frame::new();
            layout.parse(&rob, &bytes, &mut f).unwrap();
            assert_eq!(f, strict, "{name}");
        }
    }
}

#[test]
fn a_tech_element_with_sixty_attributes_is_read() {
    let rob = config("full-tech60.xml").rob_schema(4).unwrap();
    let bytes = std::fs::read(corpus().join("datagrams/full-tech60.rob.xml")).unwrap();
    let text = String::from_utf8(bytes.clone()).unwrap();
    let tech = text.lines().find(|l| l.starts_with("<Tech ")).unwrap();
    assert_eq!(tech.matches('=').count(), 60);
    let mut f = Frame::new();
    rob.parse(&bytes, &mut f).unwrap();
    let c610 = rob.slot("Tech", "C610").unwrap();
    assert!(f.is_present(c610));
    assert_eq!(f.ipoc().value(), 4_294_967_301);
}

/// RSI's bound, not the scanner's: up to [`MAX_ATTRIBUTES`] attributes on one element pass, one
/// more is malformed (bounded: the scanner tracks them on the stack).
#[test]
fn the_attribute_bound_is_rsis_not_thirty_two() {
    let cfg = config("internal-receive.xml");
    let rob = cfg.rob_schema(4).unwrap();
    let msg = |extra: usize| {
        let attrs: String = (0..extra).map(|k| format!(" x{k}=\"1\"")).collect();
        format!(
            "<Rob Type=\"KUKA\"><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><RSol X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><Delay D=\"0\"/><Tech{}{attrs}/><DiL>0</DiL><IPOC>5</IPOC></Rob>",
            (1..=10)
                .map(|k| format!(" C1{k}=\"0\""))
                .collect::<String>()
        )
    };
    let mut f = Frame::new();
    assert_eq!(
        rob.parse(msg(23).as_bytes(), &mut f),
        Ok(()),
        "33 attributes"
    );
    let at_bound = MAX_ATTRIBUTES - 10;
    assert_eq!(rob.parse(msg(at_bound).as_bytes(), &mut f), Ok(()));
    assert!(matches!(
        rob.parse(msg(at_bound + 1).as_bytes(), &mut f),
        Err(ParseError::TooManyAttributes { .. })
    ));
}
