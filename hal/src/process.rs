//! The force process's contract between a robot program and forcecell, robot-independent: what the
//! program asks ([`ProcessCommand`]: off, press at a force, release), where the process is
//! ([`ProcessPhase`]) and why it faulted ([`ProcessFault`]), each with its number. The numbers are
//! forcecell's, the same on every robot family and in every recording; a robot driver carries them in
//! its own wire format (KUKA RSI: the `FcCmd` and `FcState` elements, see the `forcecell-kuka-rsi`
//! driver).

/// What the robot program asks of the force process (KUKA RSI: `<FcCmd Mode=…>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProcessMode {
    /// No force control: the correction returns to zero and stays there.
    Off,
    /// Approach until contact, ramp to the commanded force, hold it.
    Press,
    /// Ramp the force down, lift off, bring the correction back to zero, then report [`ProcessPhase::Off`].
    Release,
    /// A mode number the contract does not define; the process faults with [`ProcessFault::BadCommand`].
    Unknown(i64),
}

impl ProcessMode {
    /// The mode for a wire number (0 OFF, 1 PRESS, 2 RELEASE, anything else [`ProcessMode::Unknown`]).
    pub fn from_code(code: i64) -> Self {
        match code {
            0 => Self::Off,
            1 => Self::Press,
            2 => Self::Release,
            other => Self::Unknown(other),
        }
    }

    /// The wire number.
    pub fn code(self) -> i64 {
        match self {
            Self::Off => 0,
            Self::Press => 1,
            Self::Release => 2,
            Self::Unknown(c) => c,
        }
    }

    /// A short name, for the operator and recordings (`unknown` for a number the contract does not
    /// define).
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Press => "press",
            Self::Release => "release",
            Self::Unknown(_) => "unknown",
        }
    }

    /// Every defined wire number with its name, for a legend: `0 off, 1 press, 2 release`.
    pub fn legend() -> String {
        (0..)
            .map(Self::from_code)
            .take_while(|m| !matches!(m, Self::Unknown(_)))
            .map(|m| format!("{} {}", m.code(), m.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The robot program's process command, carried by one cycle. SI units: the driver converts at the wire.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProcessCommand {
    /// What to do.
    pub mode: ProcessMode,
    /// Force set-point while pressing, N (compressive, along the tool's +z).
    pub force: f64,
    /// How long a change of set-point takes, s; 0 means the tuning's own rate.
    pub ramp: f64,
    /// The program's path segment number (recorded with every row).
    pub segment: i64,
}

/// Where the force process is, as reported to the robot program (RSI: `<FcState State=…>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum ProcessPhase {
    /// No force control; the correction is (back) at zero.
    #[default]
    Off,
    /// Pressing was asked; moving towards the surface.
    Approach,
    /// In contact, the set-point ramps towards the commanded force.
    Ramp,
    /// Holding the commanded force within the tuning's tolerance.
    Pressing,
    /// Releasing: force ramps down, the tool lifts off, the correction returns to zero.
    Release,
    /// A latched fault; re-armed only by [`ProcessMode::Off`].
    Fault,
}

impl ProcessPhase {
    /// The wire number (0 OFF · 1 APPROACH · 2 RAMP · 3 PRESSING · 4 RELEASE · 9 FAULT).
    pub fn code(self) -> i64 {
        match self {
            Self::Off => 0,
            Self::Approach => 1,
            Self::Ramp => 2,
            Self::Pressing => 3,
            Self::Release => 4,
            Self::Fault => 9,
        }
    }

    /// The phase for a wire number, if the contract defines it.
    pub fn from_code(code: i64) -> Option<Self> {
        Some(match code {
            0 => Self::Off,
            1 => Self::Approach,
            2 => Self::Ramp,
            3 => Self::Pressing,
            4 => Self::Release,
            9 => Self::Fault,
            _ => return None,
        })
    }

    /// A short name, for the operator and recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Approach => "approach",
            Self::Ramp => "ramp",
            Self::Pressing => "pressing",
            Self::Release => "release",
            Self::Fault => "fault",
        }
    }

    /// Every wire number with its name, for a legend: `0 off, 1 approach, …, 9 fault`.
    pub fn legend() -> String {
        (0..=u8::MAX)
            .filter_map(|c| Self::from_code(i64::from(c)))
            .map(|p| format!("{} {}", p.code(), p.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Why the force process faulted (RSI: `FcState.Fault`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum ProcessFault {
    /// No fault.
    #[default]
    None,
    /// The sensor was lost, or gave nothing usable for too long.
    SensorLost,
    /// The measured force exceeded the tuning's limit.
    ForceLimit,
    /// The correction reached its envelope.
    CorrectionLimit,
    /// The program sent a command the contract does not allow.
    BadCommand,
    /// Contact was lost for too long while pressing.
    ContactLost,
    /// The last command was held too long without a usable input.
    HoldTimeout,
}

impl ProcessFault {
    /// The wire number (0 none · 1 sensor · 2 force limit · 3 correction limit · 4 bad command ·
    /// 5 contact lost · 6 hold timeout).
    pub fn code(self) -> i64 {
        match self {
            Self::None => 0,
            Self::SensorLost => 1,
            Self::ForceLimit => 2,
            Self::CorrectionLimit => 3,
            Self::BadCommand => 4,
            Self::ContactLost => 5,
            Self::HoldTimeout => 6,
        }
    }

    /// A short name, for the operator and recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::SensorLost => "sensor lost",
            Self::ForceLimit => "force limit",
            Self::CorrectionLimit => "correction limit",
            Self::BadCommand => "bad command",
            Self::ContactLost => "contact lost",
            Self::HoldTimeout => "hold timeout",
        }
    }

    /// Every wire number with its name, for a legend: `0 none, 1 sensor lost, …, 6 hold timeout`.
    pub fn legend() -> String {
        (0..)
            .map_while(Self::from_code)
            .map(|f| format!("{} {}", f.code(), f.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The fault for a wire number, if the contract defines it.
    pub fn from_code(code: i64) -> Option<Self> {
        Some(match code {
            0 => Self::None,
            1 => Self::SensorLost,
            2 => Self::ForceLimit,
            3 => Self::CorrectionLimit,
            4 => Self::BadCommand,
            5 => Self::ContactLost,
            6 => Self::HoldTimeout,
            _ => return None,
        })
    }
}

/// The force process's state, sent with a reply.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ProcessState {
    /// Where the process is.
    pub phase: ProcessPhase,
    /// Measured compensated normal force, N (0 when none is known).
    pub force: f64,
    /// The latched fault, [`ProcessFault::None`] unless `phase` is [`ProcessPhase::Fault`].
    pub fault: ProcessFault,
}
