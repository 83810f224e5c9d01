//! The telemetry schema: the one definition of what a control cycle records, and of every code in it.
//!
//! * [`Record`] is one control cycle as recorded; [`Row`] is its trace part (the CSV's columns).
//! * Every code a recording carries knows its number and its name through [`Coded`]: the contact
//!   state (`Option<ContactState>`), the cycle's input [`Condition`], the process mode, phase and
//!   fault (`hal`'s own codes and names). The law's event flags are [`EVENTS`].
//! * The fields are a declarative table ([`Field`], grouped into [`MessageType`]s, sent on the
//!   [`CHANNELS`]): name, protobuf field number, type, unit and description, and how each is read from
//!   (and written back into) a [`Record`]. Generated from it: the protobuf schema
//!   ([`file_descriptor_set`]), the messages ([`encode`], [`decode`]), the CSV header and columns
//!   ([`CSV_COLUMNS`], [`CSV_HEADER`]) and the legends of plots and documents ([`Coded::legend`],
//!   [`describe`]).
//!
//! Words: a **condition** is what the control loop met in one cycle (a sensor error, a non-finite
//! input, a limited step; [`Condition`]); a **fault** is only ever the force process's latched fault
//! ([`hal::ProcessFault`], the number the robot program reads in `FcState.Fault`).

use controller::{ContactState, CycleReport, Events, RezeroOutcome};
use hal::{ProcessFault, ProcessMode, ProcessPhase};

use crate::record::Row;

// ------------------------------------------------------------------------------------------------
// Codes
// ------------------------------------------------------------------------------------------------

/// A value recorded as a small number with a name.
pub trait Coded: Copy + Sized + 'static {
    /// The number written in recordings and CSV files.
    fn code(self) -> i64;
    /// A short name, for the operator, legends and recordings.
    fn name(self) -> &'static str;
    /// Every value, in the order of its codes.
    fn all() -> Vec<Self>;

    /// The value of a code, if one has it.
    fn from_code(code: i64) -> Option<Self> {
        Self::all().into_iter().find(|v| v.code() == code)
    }

    /// The name of a code (`unknown` for a code no value has).
    fn name_of(code: i64) -> &'static str {
        Self::from_code(code).map_or("unknown", Self::name)
    }

    /// Every code with its name, for a legend: `0 none, 1 sensor error, …`.
    fn legend() -> String {
        Self::all()
            .into_iter()
            .map(|v| format!("{} {}", v.code(), v.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// What the control loop met in one cycle (the loop's `controller::Fault`, which does not end the
/// run): its input, or the limit that shaped its command.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Condition {
    /// Nothing: the law stepped on a usable sample and pose.
    #[default]
    None = 0,
    /// The sensor returned an error; the loop held its last command.
    SensorError = 1,
    /// The sensor returned a non-finite sample; held.
    NonFiniteSample = 2,
    /// The robot reported a non-finite pose; held.
    NonFinitePose = 3,
    /// The law produced a non-finite command; held.
    NonFiniteCommand = 4,
    /// The command moved more than `max_step` in one cycle and was limited.
    StepLimited = 5,
    /// The command left `±max_offset` and was limited.
    EnvelopeLimited = 6,
    /// The loop is backing off after a fault that ends the run.
    BackingOff = 7,
}

impl Condition {
    const ALL: [Self; 8] = [
        Self::None,
        Self::SensorError,
        Self::NonFiniteSample,
        Self::NonFinitePose,
        Self::NonFiniteCommand,
        Self::StepLimited,
        Self::EnvelopeLimited,
        Self::BackingOff,
    ];

    /// The condition of a cycle the loop reported with `fault`.
    pub fn of(fault: Option<controller::Fault>) -> Self {
        use controller::Fault as F;
        match fault {
            None => Self::None,
            Some(F::Sensor(_)) => Self::SensorError,
            Some(F::NonFiniteSample) => Self::NonFiniteSample,
            Some(F::NonFinitePose) => Self::NonFinitePose,
            Some(F::NonFiniteCommand) => Self::NonFiniteCommand,
            Some(F::StepLimited) => Self::StepLimited,
            Some(F::EnvelopeLimited) => Self::EnvelopeLimited,
            Some(F::Retracting) => Self::BackingOff,
        }
    }
}

impl Coded for Condition {
    fn code(self) -> i64 {
        self as i64
    }
    fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::SensorError => "sensor error",
            Self::NonFiniteSample => "non-finite sample",
            Self::NonFinitePose => "non-finite pose",
            Self::NonFiniteCommand => "non-finite command",
            Self::StepLimited => "step limited",
            Self::EnvelopeLimited => "envelope limited",
            Self::BackingOff => "backing off",
        }
    }
    fn all() -> Vec<Self> {
        Self::ALL.to_vec()
    }
}

/// The state code of a law without a contact state machine.
pub const NO_STATE: u8 = 255;

/// The contact state (`None`: a law without a contact state machine), coded by
/// [`ContactState::code`].
impl Coded for Option<ContactState> {
    fn code(self) -> i64 {
        i64::from(self.map_or(NO_STATE, ContactState::code))
    }
    fn name(self) -> &'static str {
        match self {
            Some(ContactState::Approach) => "approach",
            Some(ContactState::Contact) => "contact",
            Some(ContactState::Reacquire) => "reacquire",
            Some(ContactState::Retract) => "retract",
            None => "none",
        }
    }
    fn all() -> Vec<Self> {
        let mut all: Vec<Self> = [
            ContactState::Approach,
            ContactState::Contact,
            ContactState::Reacquire,
            ContactState::Retract,
        ]
        .into_iter()
        .map(Some)
        .chain([None])
        .collect();
        all.sort_by_key(|s| s.code());
        all
    }
}

/// The process mode the robot program commands (`hal`'s codes and names; a number the contract does
/// not define is recorded as sent and named `unknown`).
impl Coded for ProcessMode {
    fn code(self) -> i64 {
        ProcessMode::code(self)
    }
    fn name(self) -> &'static str {
        ProcessMode::name(self)
    }
    fn all() -> Vec<Self> {
        (0..)
            .map(ProcessMode::from_code)
            .take_while(|m| !matches!(m, ProcessMode::Unknown(_)))
            .collect()
    }
}

/// The force process's phase as reported to the robot (`hal`'s codes and names).
impl Coded for ProcessPhase {
    fn code(self) -> i64 {
        ProcessPhase::code(self)
    }
    fn name(self) -> &'static str {
        ProcessPhase::name(self)
    }
    fn all() -> Vec<Self> {
        (0..=i64::from(u8::MAX))
            .filter_map(ProcessPhase::from_code)
            .collect()
    }
    fn from_code(code: i64) -> Option<Self> {
        ProcessPhase::from_code(code)
    }
}

/// The force process's latched fault (`hal`'s codes and names).
impl Coded for ProcessFault {
    fn code(self) -> i64 {
        ProcessFault::code(self)
    }
    fn name(self) -> &'static str {
        ProcessFault::name(self)
    }
    fn all() -> Vec<Self> {
        (0..=i64::from(u8::MAX))
            .filter_map(ProcessFault::from_code)
            .collect()
    }
    fn from_code(code: i64) -> Option<Self> {
        ProcessFault::from_code(code)
    }
}

/// What a re-zero check of the sensor decided (the control loop's own codes and names).
impl Coded for RezeroOutcome {
    fn code(self) -> i64 {
        RezeroOutcome::code(self)
    }
    fn name(self) -> &'static str {
        RezeroOutcome::name(self)
    }
    fn all() -> Vec<Self> {
        RezeroOutcome::ALL.to_vec()
    }
}

/// One of the law's event flags.
#[derive(Clone, Copy, Debug)]
pub struct EventFlag {
    /// Its name (a field of the `Events` message, an item of a legend).
    pub name: &'static str,
    /// What it says.
    pub description: &'static str,
    /// Its value in a step's events.
    pub get: fn(&Events) -> bool,
}

/// The law's event flags; [`Record::events`] holds them as bits, the first the lowest.
pub const EVENTS: [EventFlag; 12] = [
    EventFlag {
        name: "contact",
        description: "contact was detected (approach or re-acquire ended)",
        get: |e| e.contact,
    },
    EventFlag {
        name: "lift_off",
        description: "contact was lost",
        get: |e| e.lift_off,
    },
    EventFlag {
        name: "force_limit",
        description: "the force exceeded the maximum: the law retracts",
        get: |e| e.force_limit,
    },
    EventFlag {
        name: "velocity_limit",
        description: "the command's velocity was limited",
        get: |e| e.velocity_limit,
    },
    EventFlag {
        name: "acceleration_limit",
        description: "the command's acceleration was limited",
        get: |e| e.acceleration_limit,
    },
    EventFlag {
        name: "deviation_limit",
        description: "the command would have left the allowed deviation from the path",
        get: |e| e.deviation_limit,
    },
    EventFlag {
        name: "estimator_bound",
        description: "the stiffness estimate was projected back into its bounds",
        get: |e| e.estimator_bound,
    },
    EventFlag {
        name: "bad_input",
        description: "a non-finite input or step reached the law; it held its command",
        get: |e| e.bad_input,
    },
    EventFlag {
        name: "orientation_rate",
        description: "orientation following: the rotation's rate was limited",
        get: |e| e.orientation_rate,
    },
    EventFlag {
        name: "orientation_limit",
        description: "orientation following: the rotation was held at the robot's POSCORR rotation limit",
        get: |e| e.orientation_limit,
    },
    EventFlag {
        name: "orientation_hold",
        description: "orientation following: the moment was not usable (saturated, out of range, not finite); the rotation held",
        get: |e| e.orientation_hold,
    },
    EventFlag {
        name: "orientation_envelope",
        description: "orientation following: the rotation would have reached its envelope (a fault: the loop backs off)",
        get: |e| e.orientation_envelope,
    },
];

/// A step's events as bits, [`EVENTS`] order.
pub fn event_bits(e: &Events) -> u16 {
    EVENTS
        .iter()
        .enumerate()
        .fold(0, |acc, (i, f)| acc | (u16::from((f.get)(e)) << i))
}

/// The names of the events set in `bits`.
pub fn event_names(bits: u16) -> impl Iterator<Item = &'static str> {
    EVENTS
        .iter()
        .enumerate()
        .filter(move |(i, _)| bits & (1 << i) != 0)
        .map(|(_, f)| f.name)
}

// ------------------------------------------------------------------------------------------------
// The record
// ------------------------------------------------------------------------------------------------

/// One control cycle as recorded. SI units (s, N, N·m, m, N/m); NaN where a value is unknown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// The trace row (force, positions, estimates, condition, process; truth columns NaN).
    pub row: Row,
    /// The wrench the loop read (gravity-compensated on a cell that compensates), sensor frame:
    /// `[Fx, Fy, Fz, Tx, Ty, Tz]`.
    pub wrench: [f64; 6],
    /// The sensor's wrench before compensation (NaN where no compensation runs).
    pub wrench_raw: [f64; 6],
    /// The sensor driver's measurement counter (0 when no sample).
    pub sensor_seq: u64,
    /// Age of the sample when read, s (NaN when no sample).
    pub sensor_age: f64,
    /// The robot cycle's sequence number (RSI IPOC on a KUKA).
    pub robot_seq: u64,
    /// The robot cycle's period, s.
    pub period: f64,
    /// Replies the robot reported late so far.
    pub late_replies: u64,
    /// Robot cycles lost so far (gaps in the robot's cycle stamps).
    pub missed: u64,
    /// Replies sent later than the link's late bound after the robot's datagram arrived (the kernel's
    /// receive stamp), so far (to the reply before this cycle's).
    pub replied_late: u64,
    /// The robot's measured tool pose (RSI `RIst`), base frame: position x, y, z (m) and orientation as
    /// a rotation vector (rad); NaN where unknown.
    pub pose: [f64; 6],
    /// The correction sent, tool frame: translation x, y, z (m) and rotation vector (rad); NaN where
    /// unknown.
    pub correction: [f64; 6],
    /// Contact state code ([`Coded`] for `Option<ContactState>`; [`NO_STATE`] for laws without a
    /// state machine).
    pub state: u8,
    /// The law's events of this step, one bit each in [`EVENTS`] order.
    pub events: u16,
    /// A re-zero of the sensor in this cycle, or a refusal to: its [`RezeroOutcome`] code (`None`:
    /// no decision this cycle).
    pub rezero: Option<u8>,
    /// That re-zero's offset removed (a refusal: the window's mean over the old zero), sensor frame,
    /// `[Fx, Fy, Fz, Tx, Ty, Tz]` in N and N·m; NaN without one.
    pub rezero_offset: [f64; 6],
}

const NAN6: [f64; 6] = [f64::NAN; 6];

/// A pose as position (m) and rotation vector (rad).
fn pose6(p: &hal::Pose) -> [f64; 6] {
    let r = p.orientation.scaled_axis();
    [p.position.x, p.position.y, p.position.z, r.x, r.y, r.z]
}

impl Record {
    /// The record of an answered cycle with set-point `f_r`; the process segment, command and state
    /// come from the cycle and the correction sent ([`Row::from_report`]).
    pub fn from_report(r: &CycleReport, f_r: f64) -> Self {
        let (raw, sensor_seq, sensor_age) = match r.sample {
            Some(s) => (s.wrench.to_array(), s.seq, s.age.as_secs_f64()),
            None => (NAN6, 0, f64::NAN),
        };
        // Where the loop compensates gravity, the wrench it used and the raw one beside it.
        let (wrench, wrench_raw) = if r.compensated {
            (r.wrench.map_or(NAN6, |w| w.to_array()), raw)
        } else {
            (raw, NAN6)
        };
        Self {
            row: Row::from_report(r, f_r),
            wrench,
            wrench_raw,
            sensor_seq,
            sensor_age,
            robot_seq: r.cycle.seq,
            period: r.cycle.period,
            late_replies: u64::from(r.cycle.late_replies),
            missed: r.cycle.missed,
            replied_late: r.cycle.replied_late,
            pose: pose6(&r.cycle.actual),
            correction: [
                r.command.translation.x,
                r.command.translation.y,
                r.command.translation.z,
                r.command.rotation.x,
                r.command.rotation.y,
                r.command.rotation.z,
            ],
            state: r.out.state.map_or(NO_STATE, ContactState::code),
            events: event_bits(&r.out.events),
            rezero: r.rezero.map(|e| e.outcome.code() as u8),
            rezero_offset: r.rezero.map_or(NAN6, |e| e.offset.to_array()),
        }
    }

    /// A record holding only a trace row (the other fields unknown).
    pub fn from_row(row: Row) -> Self {
        Self {
            row,
            wrench: NAN6,
            wrench_raw: NAN6,
            sensor_seq: 0,
            sensor_age: f64::NAN,
            robot_seq: 0,
            period: f64::NAN,
            late_replies: 0,
            missed: 0,
            replied_late: 0,
            pose: NAN6,
            correction: NAN6,
            state: NO_STATE,
            events: 0,
            rezero: None,
            rezero_offset: NAN6,
        }
    }

    /// A record with every value unknown (what [`decode`] fills in).
    pub fn unknown() -> Self {
        Self::from_row(Row::unknown())
    }
}

// ------------------------------------------------------------------------------------------------
// The field table
// ------------------------------------------------------------------------------------------------

/// A field's value, as read from or written into a [`Record`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// Not there: an optional field without a value, a sub-message not sent.
    Absent,
    /// A real number (`double`, `float`).
    F64(f64),
    /// A signed integer (`sint64`, an enum's code).
    I64(i64),
    /// An unsigned integer (`uint64`).
    U64(u64),
    /// A flag (`bool`; for a sub-message, whether it is sent).
    Bool(bool),
}

/// A field's protobuf type.
#[derive(Clone, Copy, Debug)]
pub enum Type {
    /// `double`: 64-bit, exact.
    Double,
    /// `float`: 32-bit (24-bit mantissa), for values no exact copy of which is kept elsewhere and
    /// whose resolution is far coarser (a sensor's wrench).
    Float,
    /// `sint64`.
    Sint64,
    /// `uint64`.
    Uint64,
    /// `bool`.
    Bool,
    /// An enum, with the names of its codes. Its wire type is `int32`: a code outside that range is
    /// not written (a companion field carries it).
    Enum(&'static EnumType),
    /// A sub-message.
    Message(&'static MessageType),
}

/// An enum of the schema: the codes and names of a [`Coded`] type.
#[derive(Clone, Copy, Debug)]
pub struct EnumType {
    /// Its name (a message of that name holds it as `Code`: each enum's value names have a scope of
    /// their own, so two enums may both have `NONE`).
    pub name: &'static str,
    /// Every code with its name.
    pub values: fn() -> Vec<(i64, &'static str)>,
    /// What it codes.
    pub description: &'static str,
}

fn values_of<T: Coded>() -> Vec<(i64, &'static str)> {
    T::all().into_iter().map(|v| (v.code(), v.name())).collect()
}

/// A message of the schema.
#[derive(Clone, Copy, Debug)]
pub struct MessageType {
    /// Its name in the `forcecell` package.
    pub name: &'static str,
    /// What it holds.
    pub description: &'static str,
    /// Its fields, in the order they are written.
    pub fields: &'static [Field],
}

/// One field of the schema.
#[derive(Clone, Copy, Debug)]
pub struct Field {
    /// Its name (a message field, a CSV column).
    pub name: &'static str,
    /// Its protobuf field number (never reused: a number once given keeps its meaning).
    pub number: u32,
    /// Its type.
    pub ty: Type,
    /// Whether it may be absent (protobuf `optional`: an unknown integer, no process command).
    pub optional: bool,
    /// Its unit (empty for counts, codes and flags).
    pub unit: &'static str,
    /// What it is.
    pub description: &'static str,
    /// A legend for plots.
    pub label: &'static str,
    /// Its value in a record (for a sub-message: `Bool(true)` when it is sent).
    pub get: fn(&Record) -> Value,
    /// Set it in a record ([`Value::Absent`] for an optional field not sent).
    pub set: fn(&mut Record, Value),
}

impl Value {
    fn f64(self) -> f64 {
        match self {
            Value::F64(v) => v,
            Value::I64(v) => v as f64,
            Value::U64(v) => v as f64,
            Value::Bool(b) => f64::from(u8::from(b)),
            Value::Absent => f64::NAN,
        }
    }
    fn i64(self) -> Option<i64> {
        match self {
            Value::I64(v) => Some(v),
            Value::U64(v) => i64::try_from(v).ok(),
            Value::Bool(b) => Some(i64::from(b)),
            Value::F64(_) | Value::Absent => None,
        }
    }
    fn u64(self) -> u64 {
        match self {
            Value::U64(v) => v,
            Value::I64(v) => u64::try_from(v).unwrap_or(0),
            Value::Bool(b) => u64::from(b),
            Value::F64(_) | Value::Absent => 0,
        }
    }
    fn code_u8(self) -> Option<u8> {
        self.i64().and_then(|c| u8::try_from(c).ok())
    }
    /// The value as a plot's number (NaN when absent).
    pub fn as_f64(self) -> f64 {
        self.f64()
    }
}

fn no_set(_: &mut Record, _: Value) {}

macro_rules! double {
    ($name:literal, $n:literal, $unit:literal, $desc:literal, $label:literal, |$r:ident| $get:expr) => {
        Field {
            name: $name,
            number: $n,
            ty: Type::Double,
            optional: false,
            unit: $unit,
            description: $desc,
            label: $label,
            get: |$r| Value::F64($get),
            set: |$r, v| $get = v.f64(),
        }
    };
}

macro_rules! float {
    ($name:literal, $n:literal, $unit:literal, $desc:literal, |$r:ident| $get:expr) => {
        Field {
            name: $name,
            number: $n,
            ty: Type::Float,
            optional: false,
            unit: $unit,
            description: $desc,
            label: $name,
            get: |$r| Value::F64($get),
            set: |$r, v| $get = v.f64(),
        }
    };
}

macro_rules! message {
    ($name:literal, $n:literal, $ty:expr, $desc:literal, |$r:ident| $sent:expr) => {
        Field {
            name: $name,
            number: $n,
            ty: Type::Message($ty),
            optional: true,
            unit: "",
            description: $desc,
            label: $name,
            get: |$r| Value::Bool($sent),
            set: no_set,
        }
    };
}

// Force ------------------------------------------------------------------------------------------

/// Cycle time, s (robot time on a cell, simulated time in `sim`).
pub const T: Field = double!("t", 1, "s", "cycle time", "t", |r| r.row.t);
/// Measured normal force.
pub const F: Field = double!(
    "f",
    1,
    "N",
    "measured normal force (NaN: no usable sample)",
    "f measured",
    |r| r.row.f
);
/// Set-point.
pub const F_R: Field = double!("f_r", 2, "N", "set-point", "f_r set-point", |r| r.row.f_r);
/// Force error (a plotting aid: `f - f_r` from the exact values above).
pub const ERROR: Field = Field {
    name: "error",
    number: 3,
    ty: Type::Float,
    optional: false,
    unit: "N",
    description: "f - f_r",
    label: "error",
    get: |r| Value::F64(r.row.f - r.row.f_r),
    set: no_set,
};

/// `forcecell.Force`.
pub const FORCE: MessageType = MessageType {
    name: "Force",
    description: "the normal force against its set-point",
    fields: &[F, F_R, ERROR],
};

// Wrench -----------------------------------------------------------------------------------------

macro_rules! vector3 {
    ($name:literal, $desc:literal, $unit:literal, $arr:ident, $i:literal) => {
        MessageType {
            name: $name,
            description: $desc,
            fields: &[
                float!("x", 1, $unit, "x component", |r| r.$arr[$i]),
                float!("y", 2, $unit, "y component", |r| r.$arr[$i + 1]),
                float!("z", 3, $unit, "z component", |r| r.$arr[$i + 2]),
            ],
        }
    };
}

const WRENCH_FORCE: MessageType = vector3!("WrenchForce", "force, sensor frame", "N", wrench, 0);
const WRENCH_TORQUE: MessageType =
    vector3!("WrenchTorque", "torque, sensor frame", "N·m", wrench, 3);
const RAW_FORCE: MessageType = vector3!("RawForce", "force, sensor frame", "N", wrench_raw, 0);
const RAW_TORQUE: MessageType = vector3!("RawTorque", "torque, sensor frame", "N·m", wrench_raw, 3);

/// `forcecell.Wrench`: the wrench the loop read.
pub const WRENCH: MessageType = MessageType {
    name: "Wrench",
    description: "the wrench the loop read (gravity-compensated where the cell compensates), sensor frame",
    fields: &[
        message!("force", 1, &WRENCH_FORCE, "force", |_r| true),
        message!("torque", 2, &WRENCH_TORQUE, "torque", |_r| true),
    ],
};

/// `forcecell.WrenchRaw`: the sensor's wrench before compensation.
pub const WRENCH_RAW: MessageType = MessageType {
    name: "WrenchRaw",
    description: "the sensor's wrench before gravity compensation, sensor frame",
    fields: &[
        message!("force", 1, &RAW_FORCE, "force", |_r| true),
        message!("torque", 2, &RAW_TORQUE, "torque", |_r| true),
    ],
};

// Position, estimates ----------------------------------------------------------------------------

/// Measured position along the normal.
pub const X: Field = double!(
    "x",
    1,
    "m",
    "measured position along the normal",
    "x measured",
    |r| r.row.x
);
/// Commanded position.
pub const X_CMD: Field = double!("x_cmd", 2, "m", "commanded position", "x_cmd", |r| r
    .row
    .x_cmd);
/// Impedance reference.
pub const X_R: Field = double!("x_r", 3, "m", "impedance reference", "x_r reference", |r| r
    .row
    .x_r);

/// `forcecell.Position`.
pub const POSITION: MessageType = MessageType {
    name: "Position",
    description: "positions along the tool normal",
    fields: &[X, X_CMD, X_R],
};

/// Stiffness estimate.
pub const KC_HAT: Field = double!(
    "kc_hat",
    1,
    "N/m",
    "stiffness estimate",
    "k̂_c estimate",
    |r| r.row.kc_hat
);
/// Surface estimate.
pub const XC_HAT: Field = double!(
    "xc_hat",
    2,
    "m",
    "surface estimate",
    "x̂_c estimate",
    |r| r.row.xc_hat
);

/// `forcecell.Estimates`.
pub const ESTIMATES: MessageType = MessageType {
    name: "Estimates",
    description: "the law's estimates of the contact",
    fields: &[KC_HAT, XC_HAT],
};

// State ------------------------------------------------------------------------------------------

/// `forcecell.ContactState.Code`.
pub const CONTACT_STATE: EnumType = EnumType {
    name: "ContactState",
    values: values_of::<Option<ContactState>>,
    description: "the law's contact state",
};
/// `forcecell.Condition.Code`.
pub const CONDITION_CODES: EnumType = EnumType {
    name: "Condition",
    values: values_of::<Condition>,
    description: "what the control loop met in the cycle",
};

/// Contact state.
pub const STATE: Field = Field {
    name: "state",
    number: 1,
    ty: Type::Enum(&CONTACT_STATE),
    optional: false,
    unit: "",
    description: "the law's contact state",
    label: "contact state",
    get: |r| Value::I64(i64::from(r.state)),
    set: |r, v| r.state = v.code_u8().unwrap_or(NO_STATE),
};
/// The cycle's condition.
pub const CONDITION: Field = Field {
    name: "condition",
    number: 2,
    ty: Type::Enum(&CONDITION_CODES),
    optional: false,
    unit: "",
    description: "what the control loop met in the cycle",
    label: "condition",
    get: |r| Value::I64(i64::from(r.row.condition)),
    set: |r, v| r.row.condition = v.code_u8().unwrap_or(0),
};

macro_rules! event {
    ($i:literal) => {
        Field {
            name: EVENTS[$i].name,
            number: $i + 1,
            ty: Type::Bool,
            optional: false,
            unit: "",
            description: EVENTS[$i].description,
            label: EVENTS[$i].name,
            get: |r| Value::Bool(r.events & (1 << $i) != 0),
            set: |r, v| {
                if v == Value::Bool(true) {
                    r.events |= 1 << $i
                } else {
                    r.events &= !(1 << $i)
                }
            },
        }
    };
}

/// `forcecell.Events`: the law's event flags ([`EVENTS`]).
pub const EVENT_FLAGS: MessageType = MessageType {
    name: "Events",
    description: "the law's events of the step",
    fields: &[
        event!(0),
        event!(1),
        event!(2),
        event!(3),
        event!(4),
        event!(5),
        event!(6),
        event!(7),
        event!(8),
        event!(9),
        event!(10),
        event!(11),
    ],
};

/// `forcecell.State`.
pub const STATE_MSG: MessageType = MessageType {
    name: "State",
    description: "the law's contact state, the cycle's condition and the law's events",
    fields: &[
        STATE,
        CONDITION,
        message!("events", 3, &EVENT_FLAGS, "the law's events", |_r| true),
    ],
};

// Robot, sensor ----------------------------------------------------------------------------------

/// `forcecell.Robot`.
pub const ROBOT: MessageType = MessageType {
    name: "Robot",
    description: "the robot's cycle",
    fields: &[
        Field {
            name: "seq",
            number: 1,
            ty: Type::Uint64,
            optional: false,
            unit: "",
            description: "cycle sequence (RSI IPOC)",
            label: "robot seq",
            get: |r| Value::U64(r.robot_seq),
            set: |r, v| r.robot_seq = v.u64(),
        },
        float!("period", 2, "s", "the cycle's period", |r| r.period),
        Field {
            name: "late_replies",
            number: 3,
            ty: Type::Uint64,
            optional: false,
            unit: "",
            description: "replies the robot reported late so far",
            label: "late replies",
            get: |r| Value::U64(r.late_replies),
            set: |r, v| r.late_replies = v.u64(),
        },
        Field {
            name: "missed",
            number: 4,
            ty: Type::Uint64,
            optional: false,
            unit: "",
            description: "robot cycles lost so far (gaps in the robot's cycle stamps)",
            label: "missed cycles",
            get: |r| Value::U64(r.missed),
            set: |r, v| r.missed = v.u64(),
        },
        message!(
            "pose",
            5,
            &POSE,
            "the measured tool pose (absent: unknown)",
            |r| r.pose.iter().all(|v| v.is_finite())
        ),
        Field {
            name: "replied_late",
            number: 6,
            ty: Type::Uint64,
            optional: false,
            unit: "",
            description: "replies sent later than the link's late bound (RSI: late_after, 2 ms) after \
                          the robot's datagram arrived, from the kernel's receive stamp, so far",
            label: "replied late",
            get: |r| Value::U64(r.replied_late),
            set: |r, v| r.replied_late = v.u64(),
        },
    ],
};

/// `forcecell.Pose`: the robot's measured tool pose, base frame.
pub const POSE: MessageType = MessageType {
    name: "Pose",
    description: "the robot's measured tool pose (RSI RIst), base frame: position and rotation vector",
    fields: &[
        float!("x", 1, "m", "position x", |r| r.pose[0]),
        float!("y", 2, "m", "position y", |r| r.pose[1]),
        float!("z", 3, "m", "position z", |r| r.pose[2]),
        float!("rx", 4, "rad", "rotation vector x", |r| r.pose[3]),
        float!("ry", 5, "rad", "rotation vector y", |r| r.pose[4]),
        float!("rz", 6, "rad", "rotation vector z", |r| r.pose[5]),
    ],
};

/// `forcecell.Correction`: the correction sent, tool frame.
pub const CORRECTION: MessageType = MessageType {
    name: "Correction",
    description: "the correction sent to the robot, tool frame: translation and rotation vector",
    fields: &[
        float!("x", 1, "m", "translation x", |r| r.correction[0]),
        float!("y", 2, "m", "translation y", |r| r.correction[1]),
        float!("z", 3, "m", "translation z (along the tool normal)", |r| r
            .correction[2]),
        float!("rx", 4, "rad", "rotation about tool x", |r| r.correction[3]),
        float!("ry", 5, "rad", "rotation about tool y", |r| r.correction[4]),
        float!("rz", 6, "rad", "rotation about tool z", |r| r.correction[5]),
    ],
};

/// `forcecell.Sensor`.
pub const SENSOR: MessageType = MessageType {
    name: "Sensor",
    description: "the force sensor's sample",
    fields: &[
        Field {
            name: "ok",
            number: 1,
            ty: Type::Bool,
            optional: false,
            unit: "",
            description: "a finite wrench was read",
            label: "sample ok",
            get: |r| Value::Bool(r.wrench.iter().all(|v| v.is_finite())),
            set: no_set,
        },
        Field {
            name: "seq",
            number: 2,
            ty: Type::Uint64,
            optional: false,
            unit: "",
            description: "the driver's measurement counter (0: no sample)",
            label: "sensor seq",
            get: |r| Value::U64(r.sensor_seq),
            set: |r, v| r.sensor_seq = v.u64(),
        },
        float!(
            "age",
            3,
            "s",
            "age of the sample when read (NaN: no sample)",
            |r| r.sensor_age
        ),
    ],
};

// Process ----------------------------------------------------------------------------------------

/// `forcecell.ProcessMode.Code`.
pub const MODE_CODES: EnumType = EnumType {
    name: "ProcessMode",
    values: values_of::<ProcessMode>,
    description: "the process mode the robot program commands",
};
/// `forcecell.ProcessPhase.Code`.
pub const PHASE_CODES: EnumType = EnumType {
    name: "ProcessPhase",
    values: values_of::<ProcessPhase>,
    description: "the force process's phase (RSI FcState.State)",
};
/// `forcecell.ProcessFault.Code`.
pub const FAULT_CODES: EnumType = EnumType {
    name: "ProcessFault",
    values: values_of::<ProcessFault>,
    description: "the force process's latched fault (RSI FcState.Fault)",
};

fn opt_i64(v: Option<i64>) -> Value {
    v.map_or(Value::Absent, Value::I64)
}

/// The robot program's path segment.
pub const SEGMENT: Field = Field {
    name: "segment",
    number: 1,
    ty: Type::Sint64,
    optional: true,
    unit: "",
    description: "the robot program's path segment (RSI FcCmd.Seg); absent: no process command",
    label: "segment",
    get: |r| opt_i64(r.row.segment),
    set: |r, v| r.row.segment = v.i64(),
};
/// The commanded process mode.
pub const MODE: Field = Field {
    name: "mode",
    number: 2,
    ty: Type::Enum(&MODE_CODES),
    optional: true,
    unit: "",
    description: "the commanded mode (RSI FcCmd.Mode; other numbers as sent: a bad command); absent: no process command",
    label: "mode",
    get: |r| opt_i64(r.row.mode),
    set: |r, v| r.row.mode = v.i64(),
};
/// A commanded mode outside the enum's range, as sent.
pub const MODE_CODE: Field = Field {
    name: "mode_code",
    number: 6,
    ty: Type::Sint64,
    optional: true,
    unit: "",
    description: "the commanded mode when its number does not fit the mode field (32 bits)",
    label: "mode",
    get: |r| match r.row.mode {
        Some(m) if i32::try_from(m).is_err() => Value::I64(m),
        _ => Value::Absent,
    },
    set: |r, v| {
        if let Some(m) = v.i64() {
            r.row.mode = Some(m);
        }
    },
};
/// The commanded process force.
pub const F_CMD: Field = double!(
    "f_cmd",
    3,
    "N",
    "the commanded force (RSI FcCmd.F; NaN: no process command)",
    "F commanded (FcCmd.F)",
    |r| r.row.f_cmd
);
/// The process phase.
pub const PHASE: Field = Field {
    name: "phase",
    number: 4,
    ty: Type::Enum(&PHASE_CODES),
    optional: true,
    unit: "",
    description: "the phase reported to the robot (RSI FcState.State)",
    label: "process phase",
    get: |r| opt_i64(r.row.phase.map(i64::from)),
    set: |r, v| r.row.phase = v.code_u8(),
};
/// The process fault.
pub const FAULT: Field = Field {
    name: "fault",
    number: 5,
    ty: Type::Enum(&FAULT_CODES),
    optional: true,
    unit: "",
    description: "the process's latched fault (RSI FcState.Fault)",
    label: "process fault",
    get: |r| opt_i64(r.row.fault.map(i64::from)),
    set: |r, v| r.row.fault = v.code_u8(),
};

/// `forcecell.Process`.
pub const PROCESS: MessageType = MessageType {
    name: "Process",
    description: "the robot program's process command and the force process's state",
    fields: &[SEGMENT, MODE, F_CMD, PHASE, FAULT, MODE_CODE],
};

// Re-zero ----------------------------------------------------------------------------------------

/// `forcecell.RezeroOutcome.Code`.
pub const REZERO_CODES: EnumType = EnumType {
    name: "RezeroOutcome",
    values: values_of::<RezeroOutcome>,
    description: "what a re-zero check of the sensor in free air decided",
};

/// The re-zero's outcome.
pub const REZERO_OUTCOME: Field = Field {
    name: "outcome",
    number: 1,
    ty: Type::Enum(&REZERO_CODES),
    optional: true,
    unit: "",
    description: "re-zeroed, or why the re-zero was refused (the old zero kept)",
    label: "re-zero",
    get: |r| opt_i64(r.rezero.map(i64::from)),
    set: |r, v| r.rezero = v.code_u8(),
};

const REZERO_FORCE: MessageType = vector3!(
    "RezeroForce",
    "force offset, sensor frame",
    "N",
    rezero_offset,
    0
);
const REZERO_TORQUE: MessageType = vector3!(
    "RezeroTorque",
    "torque offset, sensor frame",
    "N·m",
    rezero_offset,
    3
);

/// `forcecell.Rezero`: a re-zero of the sensor in free air between passes, or a refusal; its time is
/// the cycle's.
pub const REZERO: MessageType = MessageType {
    name: "Rezero",
    description: "a re-zero of the force sensor between passes (or a refusal): the outcome and the offset removed (a refusal: measured, not removed)",
    fields: &[
        REZERO_OUTCOME,
        message!("force", 2, &REZERO_FORCE, "force offset", |_r| true),
        message!("torque", 3, &REZERO_TORQUE, "torque offset", |_r| true),
    ],
};

// Cycle, truth -----------------------------------------------------------------------------------

/// `forcecell.Cycle`: one control cycle, on [`CYCLE_TOPIC`].
pub const CYCLE: MessageType = MessageType {
    name: "Cycle",
    description: "one control cycle",
    fields: &[
        T,
        message!("force", 2, &FORCE, "the normal force", |_r| true),
        message!("wrench", 3, &WRENCH, "the wrench read", |_r| true),
        message!(
            "wrench_raw",
            4,
            &WRENCH_RAW,
            "the wrench before compensation (absent: none runs)",
            |r| r.wrench_raw.iter().any(|v| v.is_finite())
        ),
        message!("position", 5, &POSITION, "positions", |_r| true),
        message!("estimates", 6, &ESTIMATES, "estimates", |_r| true),
        message!("state", 7, &STATE_MSG, "state, condition, events", |_r| {
            true
        }),
        message!("robot", 8, &ROBOT, "the robot's cycle", |_r| true),
        message!("sensor", 9, &SENSOR, "the sensor's sample", |_r| true),
        message!("process", 10, &PROCESS, "the force process", |_r| true),
        message!(
            "correction",
            11,
            &CORRECTION,
            "the correction sent (absent: unknown)",
            |r| r.correction.iter().all(|v| v.is_finite())
        ),
        message!(
            "rezero",
            12,
            &REZERO,
            "a re-zero of the sensor, or a refusal (absent: no decision this cycle)",
            |r| r.rezero.is_some()
        ),
    ],
};

/// True contact force.
pub const F_TRUE: Field = double!(
    "f_true",
    1,
    "N",
    "true contact force (simulation)",
    "f true",
    |r| r.row.f_true
);
/// True stiffness.
pub const K_C: Field = double!(
    "k_c",
    2,
    "N/m",
    "true stiffness (simulation)",
    "k_c true",
    |r| r.row.k_c
);
/// True surface position.
pub const X_C: Field = double!(
    "x_c",
    3,
    "m",
    "true surface position (simulation)",
    "x_c surface (true)",
    |r| r.row.x_c
);

/// A simulation-only double that is often unknown: written only where it is known (NaN is left
/// out, and read back as NaN).
macro_rules! known_double {
    ($name:literal, $n:literal, $unit:literal, $desc:literal, $label:literal, |$r:ident| $get:expr) => {
        Field {
            name: $name,
            number: $n,
            ty: Type::Double,
            optional: true,
            unit: $unit,
            description: $desc,
            label: $label,
            get: |$r| {
                let v = $get;
                if v.is_nan() {
                    Value::Absent
                } else {
                    Value::F64(v)
                }
            },
            set: |$r, v| $get = v.f64(),
        }
    };
}

/// The tool's true path position (absent without a path).
pub const S_TRUE: Field = known_double!(
    "s",
    4,
    "m",
    "the tool's position along the path (simulation; absent without a path)",
    "path position (true)",
    |r| r.row.s
);
/// The true tilt error on a curved part (absent elsewhere).
pub const TILT_ERROR: Field = known_double!(
    "tilt_error",
    5,
    "rad",
    "angle between the tool axis and the surface normal less the program's tilt (simulation, curved part; absent elsewhere)",
    "tilt error (true)",
    |r| r.row.tilt_error
);

/// `forcecell.Truth`: the simulated world's truth, on [`TRUTH_TOPIC`].
pub const TRUTH: MessageType = MessageType {
    name: "Truth",
    description: "the simulated world's truth (written when the run ends)",
    fields: &[F_TRUE, K_C, X_C, S_TRUE, TILT_ERROR],
};

/// The topic of every control cycle.
pub const CYCLE_TOPIC: &str = "/cycle";
/// The topic of a simulation's truth.
pub const TRUTH_TOPIC: &str = "/truth";

/// A channel of a recording.
#[derive(Clone, Copy, Debug)]
pub struct Channel {
    /// Topic.
    pub topic: &'static str,
    /// Its message.
    pub message: &'static MessageType,
}

impl Channel {
    /// The schema's full name, e.g. `forcecell.Cycle`.
    pub fn schema_name(&self) -> String {
        format!("{PACKAGE}.{}", self.message.name)
    }

    /// Whether `rec` has anything for this channel (the truth only where the world knows it).
    pub fn has(&self, rec: &Record) -> bool {
        self.message.name != TRUTH.name
            || rec.row.f_true.is_finite()
            || rec.row.k_c.is_finite()
            || rec.row.x_c.is_finite()
    }
}

/// Every channel a recording (and the live view) carries, in a fixed order.
pub const CHANNELS: [Channel; 2] = [
    Channel {
        topic: CYCLE_TOPIC,
        message: &CYCLE,
    },
    Channel {
        topic: TRUTH_TOPIC,
        message: &TRUTH,
    },
];

/// The protobuf package of the schema.
pub const PACKAGE: &str = "forcecell";

// ------------------------------------------------------------------------------------------------
// The CSV
// ------------------------------------------------------------------------------------------------

/// The CSV's columns, in order: the trace's fields of the schema.
pub const CSV_COLUMNS: [Field; 17] = [
    T, F, F_TRUE, F_R, X, X_CMD, X_R, KC_HAT, XC_HAT, K_C, X_C, CONDITION, SEGMENT, MODE, F_CMD,
    PHASE, FAULT,
];

const fn header_len(cols: &[Field]) -> usize {
    let mut n = 0;
    let mut i = 0;
    while i < cols.len() {
        n += cols[i].name.len() + if i > 0 { 1 } else { 0 };
        i += 1;
    }
    n
}

const fn header_bytes<const N: usize>(cols: &[Field]) -> [u8; N] {
    let mut out = [0u8; N];
    let mut at = 0;
    let mut i = 0;
    while i < cols.len() {
        if i > 0 {
            out[at] = b',';
            at += 1;
        }
        let name = cols[i].name.as_bytes();
        let mut j = 0;
        while j < name.len() {
            out[at] = name[j];
            at += 1;
            j += 1;
        }
        i += 1;
    }
    out
}

const HEADER_LEN: usize = header_len(&CSV_COLUMNS);
const HEADER_BYTES: [u8; HEADER_LEN] = header_bytes(&CSV_COLUMNS);

/// The CSV header: the names of [`CSV_COLUMNS`].
pub const CSV_HEADER: &str = match std::str::from_utf8(&HEADER_BYTES) {
    Ok(s) => s,
    Err(_) => panic!("field names are UTF-8"),
};

// ------------------------------------------------------------------------------------------------
// Protobuf encoding
// ------------------------------------------------------------------------------------------------

fn varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn key(out: &mut Vec<u8>, number: u32, wire: u8) {
    varint(out, (u64::from(number) << 3) | u64::from(wire));
}

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

/// Append `rec` as a protobuf message of type `msg`. A field at its zero value is left out (protobuf's
/// default; `-0.0` and NaN are written), as is an optional field without a value.
pub fn encode(msg: &MessageType, rec: &Record, out: &mut Vec<u8>) {
    for f in msg.fields {
        let v = (f.get)(rec);
        match (f.ty, v) {
            (_, Value::Absent) => {}
            (Type::Double, v) => {
                let x = v.f64();
                if f.optional || x.to_bits() != 0 {
                    key(out, f.number, 1);
                    out.extend_from_slice(&x.to_le_bytes());
                }
            }
            (Type::Float, v) => {
                let x = v.f64() as f32;
                if f.optional || x.to_bits() != 0 {
                    key(out, f.number, 5);
                    out.extend_from_slice(&x.to_le_bytes());
                }
            }
            (Type::Sint64, v) => {
                let x = v.i64().unwrap_or(0);
                if f.optional || x != 0 {
                    key(out, f.number, 0);
                    varint(out, zigzag(x));
                }
            }
            (Type::Uint64, v) => {
                let x = v.u64();
                if f.optional || x != 0 {
                    key(out, f.number, 0);
                    varint(out, x);
                }
            }
            (Type::Bool, v) => {
                let x = v == Value::Bool(true);
                if f.optional || x {
                    key(out, f.number, 0);
                    varint(out, u64::from(x));
                }
            }
            (Type::Enum(_), v) => {
                // An enum is an int32 on the wire (negative: sign-extended to ten bytes).
                if let Some(x) = v.i64().and_then(|x| i32::try_from(x).ok())
                    && (f.optional || x != 0)
                {
                    key(out, f.number, 0);
                    varint(out, i64::from(x) as u64);
                }
            }
            (Type::Message(m), v) => {
                if v == Value::Bool(true) {
                    key(out, f.number, 2);
                    // One byte of length first (most sub-messages are short), widened if needed.
                    let at = out.len();
                    out.push(0);
                    encode(m, rec, out);
                    let len = out.len() - at - 1;
                    if len < 0x80 {
                        out[at] = len as u8;
                    } else {
                        let mut l = Vec::with_capacity(4);
                        varint(&mut l, len as u64);
                        out.splice(at..at + 1, l);
                    }
                }
            }
        }
    }
}

/// Why a message could not be decoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DecodeError(pub String);

impl std::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for DecodeError {}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn err(&self, what: &str) -> DecodeError {
        DecodeError(format!("{what} at byte {}", self.at))
    }
    fn varint(&mut self) -> Result<u64, DecodeError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let Some(&byte) = self.b.get(self.at) else {
                return Err(self.err("a varint runs past the end"));
            };
            self.at += 1;
            v |= u64::from(byte & 0x7f) << shift;
            if byte < 0x80 {
                return Ok(v);
            }
        }
        Err(self.err("a varint is longer than ten bytes"))
    }
    fn bytes(&mut self, n: usize) -> Result<&[u8], DecodeError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| self.err("a field runs past the end"))?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
}

/// Read a protobuf message of type `msg` into `rec`: every field of the message is set (a field not
/// in the message to its zero value, an optional one to [`Value::Absent`]); a sub-message not in it
/// leaves its fields as they were in `rec`. Fields the table does not know are skipped.
pub fn decode(msg: &MessageType, bytes: &[u8], rec: &mut Record) -> Result<(), DecodeError> {
    for f in msg.fields {
        let zero = match f.ty {
            _ if f.optional => Value::Absent,
            Type::Double | Type::Float => Value::F64(0.0),
            Type::Sint64 | Type::Enum(_) => Value::I64(0),
            Type::Uint64 => Value::U64(0),
            Type::Bool => Value::Bool(false),
            Type::Message(_) => continue,
        };
        (f.set)(rec, zero);
    }
    let mut r = Reader { b: bytes, at: 0 };
    while r.at < bytes.len() {
        let k = r.varint()?;
        let (number, wire) = (k >> 3, (k & 7) as u8);
        let field = msg.fields.iter().find(|f| u64::from(f.number) == number);
        let value = match wire {
            0 => Value::U64(r.varint()?),
            1 => Value::F64(f64::from_le_bytes(r.bytes(8)?.try_into().expect("8 bytes"))),
            5 => Value::F64(f64::from(f32::from_le_bytes(
                r.bytes(4)?.try_into().expect("4 bytes"),
            ))),
            2 => {
                let n = usize::try_from(r.varint()?).map_err(|_| r.err("a length too long"))?;
                let body = r.bytes(n)?;
                if let Some(Field {
                    ty: Type::Message(m),
                    ..
                }) = field
                {
                    decode(m, body, rec)?;
                }
                continue;
            }
            _ => return Err(r.err(&format!("wire type {wire}"))),
        };
        let Some(f) = field else { continue };
        let value = match (f.ty, value) {
            (Type::Sint64, Value::U64(x)) => Value::I64(unzigzag(x)),
            (Type::Enum(_), Value::U64(x)) => Value::I64(i64::from(x as i32)),
            (Type::Bool, Value::U64(x)) => Value::Bool(x != 0),
            (Type::Double | Type::Float, Value::F64(x)) => Value::F64(x),
            (Type::Uint64, Value::U64(x)) => Value::U64(x),
            _ => {
                return Err(DecodeError(format!(
                    "{}.{}: wire type {wire} does not fit its type",
                    msg.name, f.name
                )));
            }
        };
        (f.set)(rec, value);
    }
    Ok(())
}

// ------------------------------------------------------------------------------------------------
// The protobuf schema
// ------------------------------------------------------------------------------------------------

/// Every message type reachable from `msg` (itself first), and every enum type, each once.
fn reachable(
    msg: &'static MessageType,
    msgs: &mut Vec<&'static MessageType>,
    enums: &mut Vec<&'static EnumType>,
) {
    if msgs.iter().any(|m| m.name == msg.name) {
        return;
    }
    msgs.push(msg);
    for f in msg.fields {
        match f.ty {
            Type::Message(m) => reachable(m, msgs, enums),
            Type::Enum(e) if !enums.iter().any(|x| x.name == e.name) => enums.push(e),
            _ => {}
        }
    }
}

/// A code's name as a protobuf enum value: `non-finite sample` → `NON_FINITE_SAMPLE`.
pub fn enum_value_name(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_uppercase()
            } else {
                '_'
            }
        })
        .collect()
}

/// A field's comment in the schema: its description and unit.
pub fn field_doc(f: &Field) -> String {
    let codes = match f.ty {
        Type::Enum(e) => format!(
            ": {}",
            (e.values)()
                .iter()
                .map(|(c, n)| format!("{c} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        _ => String::new(),
    };
    if f.unit.is_empty() {
        format!("{}{codes}", f.description)
    } else {
        format!("{}, {}{codes}", f.description, f.unit)
    }
}

/// The schema of `channel` as a protobuf `FileDescriptorSet` (what MCAP's `protobuf` schema encoding
/// and the Foxglove WebSocket protocol carry), with every field's description and unit as its comment.
pub fn file_descriptor_set(channel: &Channel) -> Vec<u8> {
    use prost::Message as _;
    use prost_types::field_descriptor_proto::{Label, Type as Pt};
    use prost_types::source_code_info::Location;
    use prost_types::{
        DescriptorProto, EnumDescriptorProto, EnumValueDescriptorProto, FieldDescriptorProto,
        FileDescriptorProto, FileDescriptorSet, OneofDescriptorProto, SourceCodeInfo,
    };

    let (mut msgs, mut enums) = (Vec::new(), Vec::new());
    reachable(channel.message, &mut msgs, &mut enums);
    let mut locations = Vec::new();
    let comment = |path: Vec<i32>, text: String| Location {
        path,
        span: vec![0, 0, 0],
        leading_comments: Some(format!(" {text}\n")),
        ..Location::default()
    };
    let mut message_type = Vec::new();
    for (mi, m) in msgs.iter().enumerate() {
        let mi = mi as i32;
        locations.push(comment(vec![4, mi], m.description.to_string()));
        let mut d = DescriptorProto {
            name: Some(m.name.to_string()),
            ..DescriptorProto::default()
        };
        for (fi, f) in m.fields.iter().enumerate() {
            locations.push(comment(vec![4, mi, 2, fi as i32], field_doc(f)));
            let (ty, type_name) = match f.ty {
                Type::Double => (Pt::Double, None),
                Type::Float => (Pt::Float, None),
                Type::Sint64 => (Pt::Sint64, None),
                Type::Uint64 => (Pt::Uint64, None),
                Type::Bool => (Pt::Bool, None),
                Type::Enum(e) => (Pt::Enum, Some(format!(".{PACKAGE}.{}.Code", e.name))),
                Type::Message(m) => (Pt::Message, Some(format!(".{PACKAGE}.{}", m.name))),
            };
            // An optional scalar is proto3's `optional`: a synthetic one-field oneof.
            let synthetic = f.optional && !matches!(f.ty, Type::Message(_));
            let oneof_index = synthetic.then(|| {
                d.oneof_decl.push(OneofDescriptorProto {
                    name: Some(format!("_{}", f.name)),
                    ..OneofDescriptorProto::default()
                });
                d.oneof_decl.len() as i32 - 1
            });
            d.field.push(FieldDescriptorProto {
                name: Some(f.name.to_string()),
                number: Some(f.number as i32),
                label: Some(Label::Optional as i32),
                r#type: Some(ty as i32),
                type_name,
                json_name: Some(f.name.to_string()),
                oneof_index,
                proto3_optional: synthetic.then_some(true),
                ..FieldDescriptorProto::default()
            });
        }
        message_type.push(d);
    }
    // Each enum as `Code` inside a message of the enum's name: its value names get a scope of their own.
    for (ei, e) in enums.iter().enumerate() {
        let mi = (msgs.len() + ei) as i32;
        locations.push(comment(vec![4, mi], e.description.to_string()));
        let mut values = (e.values)();
        values.sort_by_key(|(c, _)| *c);
        message_type.push(DescriptorProto {
            name: Some(e.name.to_string()),
            enum_type: vec![EnumDescriptorProto {
                name: Some("Code".into()),
                value: values
                    .iter()
                    .map(|(c, n)| EnumValueDescriptorProto {
                        name: Some(enum_value_name(n)),
                        number: Some(*c as i32),
                        ..EnumValueDescriptorProto::default()
                    })
                    .collect(),
                ..EnumDescriptorProto::default()
            }],
            ..DescriptorProto::default()
        });
    }
    let file = FileDescriptorProto {
        name: Some(format!("{PACKAGE}/{}.proto", channel.message.name)),
        package: Some(PACKAGE.into()),
        message_type,
        source_code_info: Some(SourceCodeInfo {
            location: locations,
        }),
        syntax: Some("proto3".into()),
        ..FileDescriptorProto::default()
    };
    FileDescriptorSet { file: vec![file] }.encode_to_vec()
}

// ------------------------------------------------------------------------------------------------
// Documents
// ------------------------------------------------------------------------------------------------

/// The code tables as a Markdown table: every code of the contact state, the condition, the process
/// mode, phase and fault, and the event flags.
pub fn code_table() -> String {
    let mut out = String::from("| field | code | name |\n| --- | --- | --- |\n");
    let mut table = |field: &str, rows: Vec<(i64, &str)>| {
        for (c, n) in rows {
            out.push_str(&format!("| {field} | {c} | {n} |\n"));
        }
    };
    table(
        "`state` (contact state)",
        values_of::<Option<ContactState>>(),
    );
    table("`condition` (the cycle's input)", values_of::<Condition>());
    table("`mode` (commanded, FcCmd.Mode)", values_of::<ProcessMode>());
    table("`phase` (FcState.State)", values_of::<ProcessPhase>());
    table(
        "`fault` (process fault, FcState.Fault)",
        values_of::<ProcessFault>(),
    );
    table(
        "`events` (bit)",
        EVENTS
            .iter()
            .enumerate()
            .map(|(i, e)| (1 << i, e.name))
            .collect(),
    );
    out
}

/// How many cycles of `rows` met each condition, by name (`none` when every cycle was clean): the
/// line a run's summary prints, e.g. `12 sensor error, 3 step limited`.
pub fn condition_counts(rows: &[Row]) -> String {
    let mut counts = [0usize; Condition::ALL.len()];
    let mut unknown = 0;
    for r in rows {
        match counts.get_mut(usize::from(r.condition)) {
            Some(n) => *n += 1,
            None => unknown += 1,
        }
    }
    let mut parts: Vec<String> = Condition::ALL
        .iter()
        .zip(counts)
        .filter(|(c, n)| **c != Condition::None && *n > 0)
        .map(|(c, n)| format!("{n} {}", c.name()))
        .collect();
    if unknown > 0 {
        parts.push(format!("{unknown} unknown"));
    }
    if parts.is_empty() {
        "none".into()
    } else {
        parts.join(", ")
    }
}

/// Every channel's fields as a Markdown table: path, protobuf type, unit, description.
pub fn describe() -> String {
    fn walk(prefix: &str, m: &MessageType, out: &mut String) {
        for f in m.fields {
            let path = format!("{prefix}.{}", f.name);
            let ty = match f.ty {
                Type::Double => "double".to_string(),
                Type::Float => "float".to_string(),
                Type::Sint64 => "sint64".to_string(),
                Type::Uint64 => "uint64".to_string(),
                Type::Bool => "bool".to_string(),
                Type::Enum(e) => format!("{}.Code", e.name),
                Type::Message(sub) => {
                    walk(&path, sub, out);
                    continue;
                }
            };
            let opt = if f.optional { "optional " } else { "" };
            out.push_str(&format!(
                "| `{path}` | {opt}{ty} | {} | {} |\n",
                f.unit, f.description
            ));
        }
    }
    let mut out =
        String::from("| field | type | unit | description |\n| --- | --- | --- | --- |\n");
    for c in CHANNELS {
        walk(c.topic, c.message, &mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Record {
        let mut rec = Record::from_row(Row {
            t: 1.234,
            f: 5.000_000_1,
            f_true: f64::NAN,
            f_r: 5.0,
            x: -0.0,
            x_cmd: 0.010_2,
            x_r: 0.0,
            kc_hat: 50_000.5,
            xc_hat: 0.009,
            k_c: f64::NAN,
            x_c: f64::NAN,
            condition: 5,
            segment: Some(-3),
            mode: Some(1 << 40),
            f_cmd: 12.5,
            phase: Some(9),
            fault: Some(4),
            s: f64::NAN,
            tilt_error: f64::NAN,
            rotation: f64::NAN,
            moment: [f64::NAN; 2],
        });
        rec.wrench = [0.5, -0.25, 5.0, 0.0, 0.125, f64::NAN];
        rec.sensor_seq = 300;
        rec.sensor_age = 0.001;
        rec.robot_seq = u64::MAX;
        rec.period = 0.004;
        rec.late_replies = 2;
        rec.state = 2;
        rec.events = 0b1000_0101;
        rec.rezero = Some(RezeroOutcome::Moving.code() as u8);
        rec.rezero_offset = [0.5, -0.25, 1.5, 0.0, 0.125, -0.0625];
        rec
    }

    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn a_cycle_round_trips_through_its_message() {
        let rec = sample();
        let mut buf = Vec::new();
        encode(&CYCLE, &rec, &mut buf);
        let mut back = Record::unknown();
        decode(&CYCLE, &buf, &mut back).unwrap();
        let (a, b) = (&back.row, &rec.row);
        for (x, y) in [
            (a.t, b.t),
            (a.f, b.f),
            (a.f_r, b.f_r),
            (a.x, b.x),
            (a.x_cmd, b.x_cmd),
            (a.x_r, b.x_r),
            (a.kc_hat, b.kc_hat),
            (a.xc_hat, b.xc_hat),
            (a.f_cmd, b.f_cmd),
        ] {
            assert!(same(x, y), "{x} vs {y}");
        }
        assert_eq!(
            (a.condition, a.segment, a.mode, a.phase, a.fault),
            (b.condition, b.segment, b.mode, b.phase, b.fault)
        );
        assert!(a.f_true.is_nan(), "the truth is another channel's");
        for (x, y) in back.wrench.iter().zip(rec.wrench) {
            assert!(same(*x, y), "wrench {x} vs {y}");
        }
        assert!(back.wrench_raw.iter().all(|v| v.is_nan()), "none sent");
        assert_eq!(
            (
                back.sensor_seq,
                back.robot_seq,
                back.late_replies,
                back.state,
                back.events
            ),
            (300, u64::MAX, 2, 2, 0b1000_0101)
        );
        assert!(same(back.period, f64::from(0.004f32)));
        assert_eq!(back.rezero, Some(RezeroOutcome::Moving.code() as u8));
        for (x, y) in back.rezero_offset.iter().zip(rec.rezero_offset) {
            assert!(same(*x, y), "re-zero offset {x} vs {y}");
        }
        // A cycle without a re-zero sends none, and reads back without one.
        let mut none = rec;
        none.rezero = None;
        let mut buf = Vec::new();
        encode(&CYCLE, &none, &mut buf);
        let mut back = Record::unknown();
        decode(&CYCLE, &buf, &mut back).unwrap();
        assert_eq!(back.rezero, None);
        assert!(back.rezero_offset.iter().all(|v| v.is_nan()));
        // A mode beyond 32 bits travels in its own field; one within, in the enum.
        let mut small = rec;
        small.row.mode = Some(-7);
        let mut buf = Vec::new();
        encode(&CYCLE, &small, &mut buf);
        let mut back = Record::unknown();
        decode(&CYCLE, &buf, &mut back).unwrap();
        assert_eq!(back.row.mode, Some(-7));
        // No process command: the optional fields are absent, not zero.
        let mut none = rec;
        none.row = none.row.no_process();
        let mut buf = Vec::new();
        encode(&CYCLE, &none, &mut buf);
        let mut back = sample();
        decode(&CYCLE, &buf, &mut back).unwrap();
        assert_eq!(
            (
                back.row.segment,
                back.row.mode,
                back.row.phase,
                back.row.fault
            ),
            (None, None, None, None)
        );
        // Truncated: an error, not a panic.
        assert!(decode(&CYCLE, &buf[..buf.len() - 3], &mut back).is_err());
    }

    #[test]
    fn the_pose_the_correction_and_the_missed_cycles_round_trip() {
        let mut rec = sample();
        rec.missed = 7;
        rec.replied_late = 11;
        rec.pose = [0.5, -0.125, 0.3, std::f64::consts::PI, 0.0, 0.0];
        rec.correction = [0.0, 0.0, 0.001, 0.0, -0.01, 0.0];
        let mut buf = Vec::new();
        encode(&CYCLE, &rec, &mut buf);
        let mut back = Record::unknown();
        decode(&CYCLE, &buf, &mut back).unwrap();
        assert_eq!((back.missed, back.replied_late), (7, 11));
        for (x, y) in back.pose.iter().zip(rec.pose) {
            assert!(same(*x, f64::from(y as f32)), "pose {x} vs {y}");
        }
        for (x, y) in back.correction.iter().zip(rec.correction) {
            assert!(same(*x, f64::from(y as f32)), "correction {x} vs {y}");
        }
        // Unknown poses and corrections are left out, and read back unknown (as in older files).
        let mut buf = Vec::new();
        encode(&CYCLE, &sample(), &mut buf);
        let mut back = Record::unknown();
        decode(&CYCLE, &buf, &mut back).unwrap();
        assert!(back.pose.iter().chain(&back.correction).all(|v| v.is_nan()));
    }

    #[test]
    fn codes_and_names_come_from_one_table() {
        assert_eq!(
            Condition::legend(),
            "0 none, 1 sensor error, 2 non-finite sample, 3 non-finite pose, 4 non-finite command, \
             5 step limited, 6 envelope limited, 7 backing off"
        );
        assert_eq!(
            <ProcessFault as Coded>::legend(),
            hal::ProcessFault::legend(),
            "the fault's legend is hal's"
        );
        assert_eq!(
            <ProcessPhase as Coded>::legend(),
            "0 off, 1 approach, 2 ramp, 3 pressing, 4 release, 9 fault"
        );
        assert_eq!(
            <ProcessMode as Coded>::legend(),
            "0 off, 1 press, 2 release"
        );
        assert_eq!(
            <Option<ContactState>>::legend(),
            "0 approach, 1 contact, 2 reacquire, 3 retract, 255 none"
        );
        assert_eq!(Condition::name_of(8), "unknown");
        assert_eq!(ProcessFault::name_of(2), "force limit");
        assert_eq!(ProcessPhase::name_of(5), "unknown");
        // Every controller fault has its condition, and the codes are distinct.
        let codes: Vec<i64> = Condition::all().into_iter().map(Coded::code).collect();
        assert_eq!(codes, (0..8).collect::<Vec<_>>());
        assert_eq!(
            Condition::of(Some(controller::Fault::Retracting)),
            Condition::BackingOff
        );
        let all = Events {
            contact: true,
            bad_input: true,
            ..Events::default()
        };
        assert_eq!(event_bits(&all), 0b1000_0001);
        assert_eq!(
            event_names(0b1000_0001).collect::<Vec<_>>(),
            ["contact", "bad_input"]
        );
    }

    #[test]
    fn a_summary_counts_conditions_by_name() {
        let row = |condition| Row {
            condition,
            ..Row::default()
        };
        assert_eq!(condition_counts(&[row(0), row(0)]), "none");
        assert_eq!(
            condition_counts(&[row(1), row(5), row(1), row(0), row(9)]),
            "2 sensor error, 1 step limited, 1 unknown"
        );
    }

    #[test]
    fn the_csv_header_is_the_fields_names() {
        assert_eq!(
            CSV_HEADER,
            "t,f,f_true,f_r,x,x_cmd,x_r,kc_hat,xc_hat,k_c,x_c,condition,segment,mode,f_cmd,phase,fault"
        );
    }

    #[test]
    fn field_numbers_are_unique_within_each_message() {
        let (mut msgs, mut enums) = (Vec::new(), Vec::new());
        for c in CHANNELS {
            reachable(c.message, &mut msgs, &mut enums);
        }
        for m in msgs {
            let mut numbers: Vec<u32> = m.fields.iter().map(|f| f.number).collect();
            numbers.sort_unstable();
            numbers.dedup();
            assert_eq!(numbers.len(), m.fields.len(), "{}", m.name);
            let mut names: Vec<&str> = m.fields.iter().map(|f| f.name).collect();
            names.sort_unstable();
            names.dedup();
            assert_eq!(names.len(), m.fields.len(), "{}", m.name);
        }
        for e in enums {
            let values = (e.values)();
            assert!(
                values.iter().any(|(c, _)| *c == 0),
                "{}: proto3 needs a 0",
                e.name
            );
        }
    }

    #[test]
    fn the_descriptor_names_every_field_and_code() {
        use prost::Message as _;
        let set =
            prost_types::FileDescriptorSet::decode(&file_descriptor_set(&CHANNELS[0])[..]).unwrap();
        let file = &set.file[0];
        assert_eq!(file.syntax(), "proto3");
        let cycle = file
            .message_type
            .iter()
            .find(|m| m.name() == "Cycle")
            .unwrap();
        assert_eq!(cycle.field.len(), CYCLE.fields.len());
        let process = file
            .message_type
            .iter()
            .find(|m| m.name() == "Process")
            .unwrap();
        let seg = process
            .field
            .iter()
            .find(|f| f.name() == "segment")
            .unwrap();
        assert!(seg.proto3_optional());
        let cond = file
            .message_type
            .iter()
            .find(|m| m.name() == "Condition")
            .unwrap();
        let names: Vec<&str> = cond.enum_type[0].value.iter().map(|v| v.name()).collect();
        assert_eq!(names[2], "NON_FINITE_SAMPLE");
        let fault = file
            .message_type
            .iter()
            .find(|m| m.name() == "ProcessFault")
            .unwrap();
        assert_eq!(fault.enum_type[0].value[2].name(), "FORCE_LIMIT");
        assert_eq!(fault.enum_type[0].value[2].number(), 2);
        let docs = &file.source_code_info.as_ref().unwrap().location;
        assert!(docs.iter().any(|l| {
            l.leading_comments()
                .contains("measured normal force (NaN: no usable sample), N")
        }));
    }
}
