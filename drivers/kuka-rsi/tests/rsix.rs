//! The signal-flow context `rsi-config` writes, read back with an XML parser the project did not
//! write (`roxmltree`): well-formed, every wire ends at an object and an ETHERNET port the Ethernet
//! config declares, the correction's limits and frame are the template's, and the KRL loads it by
//! name.

use std::collections::HashMap;
use std::net::Ipv4Addr;

use kuka_rsi::config::{EthernetConfig, Indx};
use kuka_rsi::krl::{ProcessSetup, RobotSetup};
use kuka_rsi::limits::PoscorrLimits;
use kuka_rsi::link::CorrectionMode;
use kuka_rsi::process::ProcessChannels;

fn setup(process: bool) -> RobotSetup {
    let mut ethernet = EthernetConfig::forcecell(Ipv4Addr::new(10, 0, 0, 2), 49152, false);
    if process {
        ethernet = ethernet.with_process(ProcessChannels::default());
    }
    RobotSetup {
        ethernet,
        mode: CorrectionMode::Absolute,
        ipo_fast: true,
        timeout: 100,
        precision: 4,
        poscorr: PoscorrLimits {
            translation: 0.0055,
            rotation: 2f64.to_radians(),
        },
        poscorrmon: PoscorrLimits {
            translation: 0.006,
            rotation: 3f64.to_radians(),
        },
        name: "cell7".into(),
        process: process.then(ProcessSetup::default_polish),
    }
}

/// `(type, inputs (InIdx, from, OutIdx), parameters name → value)` by object id.
type Objects = HashMap<String, (String, Vec<(usize, String, usize)>, HashMap<String, String>)>;

fn objects(text: &str) -> Objects {
    let doc = roxmltree::Document::parse(text).expect("well-formed XML");
    let root = doc.root_element();
    assert_eq!(root.tag_name().name(), "RsiContext");
    let mut out = Objects::new();
    for o in root
        .descendants()
        .filter(|n| n.tag_name().name() == "RsiObject")
    {
        let id = o.attribute("ObjId").expect("ObjId").to_string();
        let num = |n: roxmltree::Node, a: &str| -> usize {
            n.attribute(a)
                .unwrap_or_else(|| panic!("{id}: no {a}"))
                .parse()
                .unwrap_or_else(|_| panic!("{id}: {a} is not a number"))
        };
        let inputs = o
            .descendants()
            .filter(|n| n.tag_name().name() == "Input")
            .map(|n| {
                (
                    num(n, "InIdx"),
                    n.attribute("OutObjId").unwrap().to_string(),
                    num(n, "OutIdx"),
                )
            })
            .collect();
        let params = o
            .descendants()
            .filter(|n| n.tag_name().name() == "Parameter")
            .map(|n| {
                num(n, "ParamId");
                (
                    n.attribute("Name").unwrap().to_string(),
                    n.attribute("ParamValue").unwrap().to_string(),
                )
            })
            .collect();
        let ty = o.attribute("ObjType").unwrap().to_string();
        num(o, "ObjTypeId");
        assert!(
            out.insert(id.clone(), (ty, inputs, params)).is_none(),
            "{id} twice"
        );
    }
    out
}

/// The 0-based port of `tag` among `elements`' channels.
fn port(elements: &[kuka_rsi::config::ConfigElement], tag: &str) -> usize {
    elements
        .iter()
        .find_map(|e| match e.indx {
            Indx::Channel(i) if e.tag == tag => Some(usize::from(i) - 1),
            _ => None,
        })
        .unwrap_or_else(|| panic!("{tag} is not a channel"))
}

#[test]
fn the_context_wires_the_correction_stop_and_process_channels_to_the_ethernet_config() {
    let s = setup(true);
    let files = s.files();
    let (name, text) = files
        .iter()
        .find(|(n, _)| n.ends_with(".rsix"))
        .expect("rsi-config writes the context");
    assert_eq!(name, "cell7.rsix");
    let krl = &files.iter().find(|(n, _)| n.ends_with(".src")).unwrap().1;
    assert!(krl.contains("RSI_CREATE(\"cell7.rsix\""), "{krl}");

    let objs = objects(text);
    let e = &s.ethernet;
    let (ty, eth_in, eth) = &objs["ETHERNET1"];
    assert_eq!(ty, "Ethernet");
    assert_eq!(eth["ConfigFile"], "cell7.xml");
    assert_eq!(eth["Timeout"], "100");
    assert_eq!(eth["Precision"], "4");

    // Every wire starts at an object that exists; an ETHERNET output is a RECEIVE channel.
    let channels = |list: &[kuka_rsi::config::ConfigElement]| {
        list.iter()
            .filter(|c| matches!(c.indx, Indx::Channel(_)))
            .count()
    };
    for (id, (_, inputs, _)) in &objs {
        for (_, from, out) in inputs {
            assert!(objs.contains_key(from), "{id} is wired to {from}");
            if from == "ETHERNET1" {
                assert!(*out < channels(&e.receive), "{id}: ETHERNET port {out}");
            }
        }
    }

    let (ty, corr_in, corr) = &objs["POSCORR1"];
    assert_eq!(ty, "PosCorr");
    for (i, c) in ["X", "Y", "Z", "A", "B", "C"].iter().enumerate() {
        let want = (
            i,
            "ETHERNET1".to_string(),
            port(&e.receive, &format!("RKorr.{c}")),
        );
        assert!(corr_in.contains(&want), "RKorr.{c}: {corr_in:?}");
    }
    assert_eq!(corr["UpperLimZ"], "5.500");
    assert_eq!(corr["LowerLimX"], "-5.500");
    assert_eq!(corr["MaxRotAngle"], "2.000");
    assert_eq!(corr["RefCorrSys"], "3", "the tool frame");
    let (_, _, mon) = &objs["POSCORRMON1"];
    assert_eq!(
        (mon["MaxTrans"].as_str(), mon["MaxRotAngle"].as_str()),
        ("6.000", "3.000")
    );

    let (_, stop_in, stop) = &objs["STOP1"];
    assert_eq!(
        stop_in,
        &[(0, "ETHERNET1".to_string(), port(&e.receive, "Stop"))]
    );
    assert_eq!(stop["Mode"], "4", "ExitMoveCorr ends RSI_MOVECORR");

    // The process channels: FcCmd from $SEN_PINT/$SEN_PREA into the ETHERNET inputs, FcState out.
    let io = s.process.as_ref().unwrap().io;
    for (tag, id, ty, index) in [
        ("FcCmd.Mode", "FCCMD_MODE", "Sen_PInt", io.mode_pint),
        ("FcCmd.F", "FCCMD_F", "Sen_PRea", io.force_prea),
        ("FcCmd.Ramp", "FCCMD_RAMP", "Sen_PRea", io.ramp_prea),
        ("FcCmd.Seg", "FCCMD_SEG", "Sen_PInt", io.seg_pint),
    ] {
        let (t, _, p) = &objs[id];
        assert_eq!((t.as_str(), p["Index"].clone()), (ty, index.to_string()));
        assert!(
            eth_in.contains(&(port(&e.send, tag), id.to_string(), 0)),
            "{tag}"
        );
    }
    for (tag, id, ty, index) in [
        (
            "FcState.State",
            "FCSTATE_STATE",
            "Map2Sen_PInt",
            io.state_pint,
        ),
        ("FcState.F", "FCSTATE_F", "Map2Sen_PRea", io.measured_prea),
        (
            "FcState.Fault",
            "FCSTATE_FAULT",
            "Map2Sen_PInt",
            io.fault_pint,
        ),
    ] {
        let (t, inputs, p) = &objs[id];
        assert_eq!((t.as_str(), p["Index"].clone()), (ty, index.to_string()));
        assert_eq!(
            inputs,
            &[(0, "ETHERNET1".to_string(), port(&e.receive, tag))]
        );
    }
}

#[test]
fn without_process_channels_the_context_has_only_the_correction_and_stop() {
    let s = setup(false);
    let objs = objects(&s.rsix());
    let mut ids: Vec<&str> = objs.keys().map(String::as_str).collect();
    ids.sort_unstable();
    assert_eq!(ids, ["ETHERNET1", "POSCORR1", "POSCORRMON1", "STOP1"]);
    assert!(objs["ETHERNET1"].1.is_empty(), "no inputs into ETHERNET");
}
