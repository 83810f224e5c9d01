//! The process channels (contract: `docs/wire-rsi.md`): the robot program's command
//! `<FcCmd Mode=".." F=".." Ramp=".." Seg=".."/>` in `<Rob>` and forcecell's state
//! `<FcState State=".." F=".." Fault=".."/>` in `<Sen>`.
//!
//! They are ordinary attribute-style user channels (like `RKorr X=..`): the Ethernet config declares
//! `FcCmd.Mode` (LONG), `FcCmd.F` (DOUBLE), `FcCmd.Ramp` (DOUBLE), `FcCmd.Seg` (LONG) in SEND and
//! `FcState.State` (LONG), `FcState.F` (DOUBLE), `FcState.Fault` (LONG) in RECEIVE, and the generic
//! codec carries them. This module finds their slots in a [`Schema`] and maps slot values to the HAL's
//! [`ProcessCommand`] / [`ProcessState`] and back, for both sides (the driver and the simulated robot).
//!
//! * A config declares all four `FcCmd` attributes or none; all three `FcState` attributes or none;
//!   with the contract's types. Anything else is a configuration error, never a half-used channel.
//! * A datagram that lacks a declared value, or carries a non-numeric or fractional LONG, is rejected
//!   by the codec as malformed (`ParseError::MissingElement` / `BadNumber`) — never read as a default.
//! * A `Mode` outside 0/1/2 is delivered as [`ProcessMode::Unknown`] (the process faults with
//!   "bad command"); a `State` or `Fault` code outside the contract is a [`ProcessError`].
//! * `FcState.F` is written with 2 decimals; a non-finite force is written as `0.00`
//!   ([`crate::wire::force_to_wire`]).

use core::fmt;

use hal::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};

use crate::codec::{Frame, Schema, ValueType};
use crate::config::{ConfigElement, EthernetConfig};
use crate::wire;

/// Tag of the robot program's command in `<Rob>`.
pub const FC_CMD: &str = "FcCmd";
/// Tag of forcecell's state in `<Sen>`.
pub const FC_STATE: &str = "FcState";
/// `FcCmd` attributes and their types, in wire order.
pub const FC_CMD_FIELDS: [(&str, ValueType); 4] = [
    ("Mode", ValueType::Long),
    ("F", ValueType::Double),
    ("Ramp", ValueType::Double),
    ("Seg", ValueType::Long),
];
/// `FcState` attributes and their types, in wire order.
pub const FC_STATE_FIELDS: [(&str, ValueType); 3] = [
    ("State", ValueType::Long),
    ("F", ValueType::Double),
    ("Fault", ValueType::Long),
];
/// Decimals of `FcState.F`.
pub const FC_STATE_F_DECIMALS: u8 = 2;

/// An `FcState` that does not follow the contract (seen by the robot side).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProcessError {
    /// `State` is not one of 0 1 2 3 4 9.
    BadState(i64),
    /// `Fault` is not one of 0..=6.
    BadFault(i64),
}

impl fmt::Display for ProcessError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadState(c) => {
                write!(f, "FcState State={c} is not a process phase (0 1 2 3 4 9)")
            }
            Self::BadFault(c) => write!(f, "FcState Fault={c} is not a fault code (0..6)"),
        }
    }
}

impl std::error::Error for ProcessError {}

impl hal::Error for ProcessError {
    fn kind(&self) -> hal::ErrorKind {
        hal::ErrorKind::Malformed
    }
}

/// Slots of one element's attributes, `None` when the schema has none of them.
fn find<const N: usize>(
    schema: &Schema,
    tag: &str,
    fields: [(&str, ValueType); N],
) -> Result<Option<[usize; N]>, String> {
    let Some(element) = schema.elements().iter().find(|e| e.tag == tag) else {
        return Ok(None);
    };
    let mut out = [0; N];
    for (o, (name, ty)) in out.iter_mut().zip(fields) {
        let f = element
            .fields()
            .iter()
            .find(|f| f.name == name)
            .ok_or_else(|| {
                format!(
                    "{tag}.{name} is missing: the process channels need all of {}",
                    fields.map(|(n, _)| format!("{tag}.{n}")).join(", ")
                )
            })?;
        if f.ty != ty {
            return Err(format!(
                "{tag}.{name} must be TYPE=\"{}\", not {}",
                ty.as_config(),
                f.ty.as_config()
            ));
        }
        *o = f
            .slot
            .ok_or_else(|| format!("{tag}.{name} has no value slot"))?;
    }
    Ok(Some(out))
}

/// Where `FcCmd` lives in a `<Rob>` frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandSlots {
    mode: usize,
    force: usize,
    ramp: usize,
    seg: usize,
}

impl CommandSlots {
    /// The four slots as a mask (bit `slot` set).
    pub(crate) fn mask(&self) -> u128 {
        [self.mode, self.force, self.ramp, self.seg]
            .iter()
            .fold(0, |m, &s| m | 1u128 << s)
    }

    /// The slots in `rob` (the `<Rob>` schema); `Ok(None)` when the config declares no `FcCmd`.
    pub fn find(rob: &Schema) -> Result<Option<Self>, String> {
        Ok(
            find(rob, FC_CMD, FC_CMD_FIELDS)?.map(|[mode, force, ramp, seg]| Self {
                mode,
                force,
                ramp,
                seg,
            }),
        )
    }

    /// The command of a parsed frame (SI: N, s). The codec guarantees the values are present,
    /// finite, and integral for the LONGs.
    pub fn decode(&self, f: &Frame) -> ProcessCommand {
        ProcessCommand {
            mode: ProcessMode::from_code(f.get(self.mode) as i64),
            force: wire::force_from_wire(f.get(self.force)),
            ramp: wire::seconds_from_wire(f.get(self.ramp)),
            segment: f.get(self.seg) as i64,
        }
    }

    /// Put a command into a frame (the robot side). Non-finite values are written as 0.
    pub fn encode(&self, c: &ProcessCommand, f: &mut Frame) {
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        f.set(self.mode, c.mode.code() as f64);
        f.set(self.force, finite(c.force));
        f.set(self.ramp, finite(c.ramp));
        f.set(self.seg, c.segment as f64);
    }
}

/// Where `FcState` lives in a `<Sen>` frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StateSlots {
    state: usize,
    force: usize,
    fault: usize,
}

impl StateSlots {
    /// The slots in `sen` (the `<Sen>` schema), whose `FcState.F` is then written with 2 decimals;
    /// `Ok(None)` when the config declares no `FcState`.
    pub fn find(sen: &mut Schema) -> Result<Option<Self>, String> {
        let Some([state, force, fault]) = find(sen, FC_STATE, FC_STATE_FIELDS)? else {
            return Ok(None);
        };
        sen.set_decimals(FC_STATE, "F", FC_STATE_F_DECIMALS)?;
        Ok(Some(Self {
            state,
            force,
            fault,
        }))
    }

    /// Put a state into a frame (the PC side). The force is always finite on the wire.
    pub fn encode(&self, s: &ProcessState, f: &mut Frame) {
        f.set(self.state, s.phase.code() as f64);
        f.set(self.force, wire::force_to_wire(s.force));
        f.set(self.fault, s.fault.code() as f64);
    }

    /// The state of a parsed frame (the robot side).
    pub fn decode(&self, f: &Frame) -> Result<ProcessState, ProcessError> {
        let state = f.get(self.state) as i64;
        let fault = f.get(self.fault) as i64;
        Ok(ProcessState {
            phase: ProcessPhase::from_code(state).ok_or(ProcessError::BadState(state))?,
            force: wire::force_from_wire(f.get(self.force)),
            fault: ProcessFault::from_code(fault).ok_or(ProcessError::BadFault(fault))?,
        })
    }
}

/// The `INDX` channels of the process elements in the Ethernet config (the ETHERNET object's ports).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProcessChannels {
    /// SEND `FcCmd.Mode`, `FcCmd.F`, `FcCmd.Ramp`, `FcCmd.Seg`.
    pub cmd: [u8; 4],
    /// RECEIVE `FcState.State`, `FcState.F`, `FcState.Fault`.
    pub state: [u8; 3],
}

impl Default for ProcessChannels {
    /// SEND 1–4; RECEIVE 8–10 (after `RKorr` 1–6 and `Stop` 7 of [`EthernetConfig::forcecell`]).
    fn default() -> Self {
        Self {
            cmd: [1, 2, 3, 4],
            state: [8, 9, 10],
        }
    }
}

impl EthernetConfig {
    /// This config with the process channels added: `FcCmd.*` at the end of SEND, `FcState.*` at
    /// the end of RECEIVE (HOLDON 1: on a late reply the robot keeps the last state instead of
    /// reading 0 = OFF, which a `WAIT FOR` on OFF would take for the end of a release).
    pub fn with_process(mut self, ch: ProcessChannels) -> Self {
        for ((name, ty), indx) in FC_CMD_FIELDS.into_iter().zip(ch.cmd) {
            self.send.push(ConfigElement::channel(
                &format!("{FC_CMD}.{name}"),
                ty,
                indx,
                None,
            ));
        }
        for ((name, ty), indx) in FC_STATE_FIELDS.into_iter().zip(ch.state) {
            self.receive.push(ConfigElement::channel(
                &format!("{FC_STATE}.{name}"),
                ty,
                indx,
                Some(true),
            ));
        }
        self
    }

    /// True when SEND declares `FcCmd`.
    pub fn has_process_command(&self) -> bool {
        self.send.iter().any(|e| e.tag.starts_with("FcCmd."))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::Ipoc;

    fn schemas() -> (Schema, Schema, CommandSlots, StateSlots) {
        let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false)
            .with_process(ProcessChannels::default());
        cfg.validate().unwrap();
        let rob = cfg.rob_schema(4).unwrap();
        let mut sen = cfg.sen_schema(4).unwrap();
        let c = CommandSlots::find(&rob).unwrap().unwrap();
        let s = StateSlots::find(&mut sen).unwrap().unwrap();
        (rob, sen, c, s)
    }

    #[test]
    fn absent_channels_are_none() {
        let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
        assert_eq!(CommandSlots::find(&cfg.rob_schema(4).unwrap()), Ok(None));
        assert_eq!(StateSlots::find(&mut cfg.sen_schema(4).unwrap()), Ok(None));
        assert!(!cfg.has_process_command());
    }

    #[test]
    fn half_declared_or_mistyped_channels_are_config_errors() {
        let mut cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false)
            .with_process(ProcessChannels::default());
        cfg.send.retain(|e| e.tag != "FcCmd.Ramp");
        let e = CommandSlots::find(&cfg.rob_schema(4).unwrap()).unwrap_err();
        assert!(e.contains("FcCmd.Ramp is missing"), "{e}");
        let mut cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false)
            .with_process(ProcessChannels::default());
        for e in &mut cfg.receive {
            if e.tag == "FcState.State" {
                e.ty = ValueType::Double;
            }
        }
        let e = StateSlots::find(&mut cfg.sen_schema(4).unwrap()).unwrap_err();
        assert!(e.contains("must be TYPE=\"LONG\""), "{e}");
    }

    #[test]
    fn fc_state_golden_and_non_finite_force() {
        let (_, sen, _, s) = schemas();
        let mut f = Frame::new();
        f.set_ipoc(Ipoc::new(42));
        s.encode(
            &ProcessState {
                phase: ProcessPhase::Pressing,
                force: 19.976,
                fault: ProcessFault::None,
            },
            &mut f,
        );
        let mut buf = [0u8; 512];
        let n = sen.write(&f, &mut buf).unwrap();
        let text = core::str::from_utf8(&buf[..n]).unwrap();
        assert!(
            text.contains("<FcState State=\"3\" F=\"19.98\" Fault=\"0\"/>"),
            "{text}"
        );
        s.encode(
            &ProcessState {
                phase: ProcessPhase::Fault,
                force: f64::NAN,
                fault: ProcessFault::SensorLost,
            },
            &mut f,
        );
        let n = sen.write(&f, &mut buf).unwrap();
        let text = core::str::from_utf8(&buf[..n]).unwrap();
        assert!(
            text.contains("<FcState State=\"9\" F=\"0.00\" Fault=\"1\"/>"),
            "{text}"
        );
    }

    #[test]
    fn fc_cmd_decodes_and_unknown_mode_is_kept() {
        let (rob, _, c, _) = schemas();
        let mut f = Frame::new();
        for (mode, expect) in [
            ("1", ProcessMode::Press),
            ("0", ProcessMode::Off),
            ("2", ProcessMode::Release),
            ("7", ProcessMode::Unknown(7)),
            ("-1", ProcessMode::Unknown(-1)),
        ] {
            let msg = format!(
                "<Rob Type=\"KUKA\"><RIst X=\"0\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/><RSol X=\"0\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/><AIPos A1=\"0\" A2=\"0\" A3=\"0\" A4=\"0\" A5=\"0\" A6=\"0\"/><ASPos A1=\"0\" A2=\"0\" A3=\"0\" A4=\"0\" A5=\"0\" A6=\"0\"/><Delay D=\"0\"/><FcCmd Mode=\"{mode}\" F=\"20.00\" Ramp=\"0.50\" Seg=\"3\"/><IPOC>7</IPOC></Rob>"
            );
            rob.parse(msg.as_bytes(), &mut f).unwrap();
            assert_eq!(
                c.decode(&f),
                ProcessCommand {
                    mode: expect,
                    force: 20.0,
                    ramp: 0.5,
                    segment: 3
                }
            );
        }
    }

    #[test]
    fn fc_state_codes_outside_the_contract_are_errors() {
        let (_, _, _, s) = schemas();
        let mut f = Frame::new();
        s.encode(&ProcessState::default(), &mut f);
        assert_eq!(
            s.decode(&f),
            Ok(ProcessState {
                phase: ProcessPhase::Off,
                force: 0.0,
                fault: ProcessFault::None
            })
        );
        f.set(s.state, 5.0);
        assert_eq!(s.decode(&f), Err(ProcessError::BadState(5)));
        f.set(s.state, 9.0);
        f.set(s.fault, 7.0);
        assert_eq!(s.decode(&f), Err(ProcessError::BadFault(7)));
    }
}
