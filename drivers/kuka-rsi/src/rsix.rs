//! The RSI signal-flow context (`.rsix`) that the KRL template loads with `RSI_CREATE`: the objects
//! between the robot program, the ETHERNET object and the motion correction, each named for the
//! integrator.
//!
//! The `.rsix` format is the one RSI 4.1 and later (KR C4 with KSS 8.5 and later, KR C5) load: an
//! `RsiContext` with its `RsiObjects`, each object a type number and name, inputs wired to another
//! object's output by 0-based index, and parameters by name, number and value. The type and
//! parameter numbers are the ones RSI's own object catalogue gives (Ethernet 64, PosCorr 27,
//! PosCorrMon 81, Stop 18, Sen_PInt 57, Sen_PRea 58, Map2Sen_PInt 16, Map2Sen_PRea 17). The file
//! carries no editor layout: RSI Visual (WorkVisual) opens it and saves it with one. RSI 3 (KSS 8.2
//! and 8.3) reads another format; there the template's header lists the same objects to draw.

use core::fmt::Write as _;

use crate::config::{ConfigElement, Indx};
use crate::krl::{ProcessIo, RobotSetup};

/// The ETHERNET object's name in the context.
pub const ETHERNET: &str = "ETHERNET1";
/// The Cartesian correction's name.
pub const POSCORR: &str = "POSCORR1";
/// The correction monitor's name.
pub const POSCORRMON: &str = "POSCORRMON1";
/// The stop object's name.
pub const STOP: &str = "STOP1";

/// `PosCorr`'s `RefCorrSys` for corrections in the tool frame (World 0, Base 1, RobRoot 2, Tool 3,
/// TTS 4).
const REF_TOOL: u8 = 3;
/// `Stop`'s `Mode` that ends `RSI_MOVECORR` (InfoMessage 0, PathNormal 1, Velocity 2, PathFast 3,
/// ExitMoveCorr 4).
const STOP_EXIT_MOVECORR: u8 = 4;

/// One object of the context.
struct Object {
    type_id: u8,
    ty: &'static str,
    id: String,
    /// `(InIdx, OutObjId, OutIdx)`.
    inputs: Vec<(usize, String, usize)>,
    /// `(Name, ParamId, value, runtime)`: parameters that cannot change at runtime say so.
    params: Vec<(&'static str, u8, String, bool)>,
}

/// The 0-based ETHERNET port of `tag` in `elements` (its `INDX` less one).
fn port(elements: &[ConfigElement], tag: &str) -> Option<usize> {
    elements.iter().find_map(|e| match e.indx {
        Indx::Channel(i) if e.tag == tag => Some(usize::from(i) - 1),
        _ => None,
    })
}

impl RobotSetup {
    /// The signal-flow context `<name>.rsix`: ETHERNET (loading `<name>.xml`, with the template's
    /// Timeout and Precision) → POSCORR in the tool frame within the POSCORR limits, POSCORRMON,
    /// STOP on the `Stop` channel, and with the process channels the `$SEN_PINT`/`$SEN_PREA` objects
    /// that carry `FcCmd` in and `FcState` out.
    pub fn rsix(&self) -> String {
        let e = &self.ethernet;
        let mut objects = Vec::new();
        let mut eth = Object {
            type_id: 64,
            ty: "Ethernet",
            id: ETHERNET.into(),
            inputs: Vec::new(),
            params: vec![
                ("ConfigFile", 0, format!("{}.xml", self.name), false),
                ("Timeout", 0, self.timeout.to_string(), true),
                ("Flag", 3, "-1".into(), true),
                ("Precision", 7, self.precision.to_string(), true),
            ],
        };
        if let Some(p) = &self.process {
            let ProcessIo {
                mode_pint,
                seg_pint,
                force_prea,
                ramp_prea,
                state_pint,
                fault_pint,
                measured_prea,
            } = p.io;
            for (tag, pint, index) in [
                ("FcCmd.Mode", true, mode_pint),
                ("FcCmd.F", false, force_prea),
                ("FcCmd.Ramp", false, ramp_prea),
                ("FcCmd.Seg", true, seg_pint),
            ] {
                if let Some(at) = port(&e.send, tag) {
                    let id = tag.replace('.', "_").to_uppercase();
                    eth.inputs.push((at, id.clone(), 0));
                    objects.push(Object {
                        type_id: if pint { 57 } else { 58 },
                        ty: if pint { "Sen_PInt" } else { "Sen_PRea" },
                        id,
                        inputs: Vec::new(),
                        params: vec![("Index", 0, index.to_string(), true)],
                    });
                }
            }
            for (tag, pint, index) in [
                ("FcState.State", true, state_pint),
                ("FcState.F", false, measured_prea),
                ("FcState.Fault", true, fault_pint),
            ] {
                if let Some(at) = port(&e.receive, tag) {
                    objects.push(Object {
                        type_id: if pint { 16 } else { 17 },
                        ty: if pint { "Map2Sen_PInt" } else { "Map2Sen_PRea" },
                        id: tag.replace('.', "_").to_uppercase(),
                        inputs: vec![(0, ETHERNET.into(), at)],
                        params: vec![("Index", 0, index.to_string(), true)],
                    });
                }
            }
        }
        eth.inputs.sort_by_key(|i| i.0);
        let mm = crate::wire::m_to_mm(self.poscorr.translation);
        let corr = ["X", "Y", "Z", "A", "B", "C"];
        let mut params: Vec<(&'static str, u8, String, bool)> = Vec::new();
        for (i, name) in ["LowerLimX", "LowerLimY", "LowerLimZ"]
            .into_iter()
            .enumerate()
        {
            params.push((name, i as u8, format!("{:.3}", -mm), true));
        }
        for (i, name) in ["UpperLimX", "UpperLimY", "UpperLimZ"]
            .into_iter()
            .enumerate()
        {
            params.push((name, 3 + i as u8, format!("{mm:.3}"), true));
        }
        params.push((
            "MaxRotAngle",
            6,
            format!("{:.3}", self.poscorr.rotation.to_degrees()),
            true,
        ));
        params.push(("RefCorrSys", 0, REF_TOOL.to_string(), false));
        objects.push(Object {
            type_id: 27,
            ty: "PosCorr",
            id: POSCORR.into(),
            inputs: corr
                .iter()
                .enumerate()
                .filter_map(|(i, c)| {
                    port(&e.receive, &format!("RKorr.{c}")).map(|at| (i, ETHERNET.into(), at))
                })
                .collect(),
            params,
        });
        objects.push(Object {
            type_id: 81,
            ty: "PosCorrMon",
            id: POSCORRMON.into(),
            inputs: Vec::new(),
            params: vec![
                (
                    "MaxTrans",
                    0,
                    format!("{:.3}", crate::wire::m_to_mm(self.poscorrmon.translation)),
                    false,
                ),
                (
                    "MaxRotAngle",
                    1,
                    format!("{:.3}", self.poscorrmon.rotation.to_degrees()),
                    false,
                ),
            ],
        });
        if let Some(at) = port(&e.receive, "Stop") {
            objects.push(Object {
                type_id: 18,
                ty: "Stop",
                id: STOP.into(),
                inputs: vec![(0, ETHERNET.into(), at)],
                params: vec![
                    ("Mode", 0, STOP_EXIT_MOVECORR.to_string(), true),
                    ("Channel", 1, "0".into(), true),
                ],
            });
        }
        objects.insert(0, eth);

        let mut x = String::new();
        let _ = writeln!(x, r#"<?xml version="1.0" encoding="utf-8"?>"#);
        let _ = writeln!(
            x,
            "<!-- Generated by forcecell rsi-config for {}.src (RSI 4.1 and later). -->",
            self.name
        );
        let _ = writeln!(
            x,
            r#"<RsiContext SchemaVersion="2.0.0" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xmlns="RsiContext">"#
        );
        let _ = writeln!(x, r#"  <RsiObjects xmlns="RsiDriver">"#);
        for o in &objects {
            let _ = writeln!(
                x,
                r#"    <RsiObject ObjTypeId="{}" ObjType="{}" ObjId="{}">"#,
                o.type_id, o.ty, o.id
            );
            if !o.inputs.is_empty() {
                let _ = writeln!(x, "      <Inputs>");
                for (i, from, out) in &o.inputs {
                    let _ = writeln!(
                        x,
                        r#"        <Input InIdx="{i}" OutObjId="{from}" OutIdx="{out}" />"#
                    );
                }
                let _ = writeln!(x, "      </Inputs>");
            }
            let _ = writeln!(x, "      <Parameters>");
            for (name, id, value, runtime) in &o.params {
                let runtime = if *runtime {
                    ""
                } else {
                    r#"IsRuntime="false" "#
                };
                let _ = writeln!(
                    x,
                    r#"        <Parameter {runtime}Name="{name}" ParamId="{id}" ParamValue="{value}" />"#
                );
            }
            let _ = writeln!(x, "      </Parameters>");
            let _ = writeln!(x, "    </RsiObject>");
        }
        let _ = writeln!(x, "  </RsiObjects>");
        let _ = writeln!(x, "</RsiContext>");
        x
    }
}
