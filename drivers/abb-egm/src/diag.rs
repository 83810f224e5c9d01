//! What the link counts and measures, readable by the application at any time.

pub use hal::Latency;

use crate::session::Malformed;

/// Event counters of one link, since it was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Datagrams read from the socket (all of them, good or bad).
    pub received: u64,
    /// Path corrections sent.
    pub answered: u64,
    /// Replies sent more than the configured `late_after` after their datagram arrived (the kernel's
    /// receive stamp, `SO_TIMESTAMPNS`); from the receive call's return where the kernel gave no stamp
    /// (those are also counted in [`unstamped`](Self::unstamped)).
    pub late: u64,
    /// Replies whose lateness was measured from the receive call's return, the kernel having given no
    /// arrival stamp for their datagram.
    pub unstamped: u64,
    /// Good `EgmRobot` datagrams superseded by a newer one in the socket backlog and never answered.
    pub skipped: u64,
    /// Datagrams from a source other than the robot: dropped, never answered.
    pub foreign: u64,
    /// Datagrams that are not a usable `EgmRobot`: dropped, not answered.
    pub malformed: u64,
    /// Datagrams above the configured maximum size: dropped, not answered.
    pub oversized: u64,
    /// Duplicated or reordered (older) sequence numbers: dropped, not answered.
    pub stale: u64,
    /// Cycles the application never replied to before asking for the next one.
    pub unanswered: u64,
    /// Replies where a non-finite command was replaced by the last one sent.
    pub nonfinite_held: u64,
    /// Replies limited by the envelope (or with an axis the link does not carry zeroed).
    pub envelope_limited: u64,
    /// Replies limited by the per-cycle rate limit.
    pub rate_limited: u64,
    /// Replies whose correction asked for a rotation, which a path correction cannot carry (dropped).
    pub rotation_dropped: u64,
    /// Robot sessions seen (first contact and every sequence restart).
    pub sessions: u64,
    /// Socket errors while sending.
    pub send_errors: u64,
    /// Poses that jumped further than the robot can move since the last plausible one: delivered as
    /// unusable (NaN), answered with the last command.
    pub implausible: u64,
    /// Cycles in which the robot reported its motors off.
    pub motors_off: u64,
    /// Cycles in which the robot reported its RAPID program stopped.
    pub rapid_stopped: u64,
    /// Process states published to the RAPID program (on change).
    pub states_published: u64,
    /// Process states the state channel failed to publish (retried next cycle).
    pub state_errors: u64,
}

/// The robot's own state from its last good message.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RobotStatus {
    /// `motorState` (`MOTORS_*` number), when sent.
    pub motors: Option<i32>,
    /// `rapidExecState` (`RAPID_*` number), when sent.
    pub rapid: Option<i32>,
    /// `mciState` (`MCI_*` number), when sent.
    pub mci: Option<i32>,
    /// `moveIndex`, when sent.
    pub move_index: Option<u32>,
}

/// Everything the link reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Diagnostics {
    /// Event counters.
    pub counters: Counters,
    /// The robot's state from its last good message.
    pub robot: RobotStatus,
    /// The reason the last malformed datagram was dropped.
    pub last_malformed: Option<Malformed>,
    /// Receive→send turnaround of every reply sent.
    pub latency: Latency,
    /// Arrival→send time of every reply sent: from the kernel's receive stamp (where there is none,
    /// the receipt) to the return of the send call; what [`Counters::late`] judges.
    pub from_arrival: Latency,
}
