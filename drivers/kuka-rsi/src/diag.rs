//! What the link counts and measures, readable by the application at any time.

pub use hal::Latency;

use crate::xml::ParseError;

/// Event counters of one link, since it was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Datagrams read from the socket (all of them, good or bad).
    pub received: u64,
    /// `<Sen>` replies sent.
    pub answered: u64,
    /// Replies whose receive→send turnaround exceeded the configured `late_after`.
    pub late: u64,
    /// Good `<Rob>` datagrams superseded by a newer one in the socket backlog and never answered.
    pub skipped: u64,
    /// Datagrams from a source other than the robot: dropped, never answered.
    pub foreign: u64,
    /// Datagrams that failed to parse (including truncated and non-ASCII ones): dropped, not answered.
    pub malformed: u64,
    /// Datagrams above the configured maximum size: dropped, not answered.
    pub oversized: u64,
    /// Duplicated or reordered (older) `<Rob>` datagrams: dropped, not answered.
    pub stale: u64,
    /// Robot cycles that never arrived: the IPOC gaps within a session, in whole configured cycles
    /// (a datagram the robot sent and the network lost, or one the robot never sent).
    pub missed: u64,
    /// Cycles the application never replied to before asking for the next one.
    pub unanswered: u64,
    /// Replies where a non-finite command was replaced by the last one sent.
    pub nonfinite_held: u64,
    /// Replies limited by the correction envelope.
    pub envelope_limited: u64,
    /// Replies limited by the per-cycle rate limit.
    pub rate_limited: u64,
    /// Cycles in which the robot reported `Delay` > 0.
    pub delay_alarms: u64,
    /// Robot sessions seen (first contact and every new IPOC base).
    pub sessions: u64,
    /// Replies not sent because the config says `ONLYSEND`.
    pub suppressed: u64,
    /// Socket errors while sending.
    pub send_errors: u64,
    /// `<Rob>` datagrams whose pose jumped further than the robot can move in the time since the last
    /// plausible one (`LinkConfig::max_speed`): answered with the last command, poses not used.
    pub implausible: u64,
}

/// Everything the link reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Diagnostics {
    /// Event counters.
    pub counters: Counters,
    /// The robot's latest `Delay` value.
    pub robot_delay: u32,
    /// The reason the last malformed datagram was dropped.
    pub last_malformed: Option<ParseError>,
    /// Receive→send turnaround of every reply sent: from the datagram's receipt to the return of the
    /// send call.
    pub latency: Latency,
    /// The part of [`latency`](Self::latency) before the send call: parsing, the application's cycle
    /// and the reply's encoding, all in user space. The rest is the send call itself, which on
    /// loopback also delivers the datagram to the peer and wakes it (an idle peer on another CPU of
    /// a virtual machine costs tens of µs there), and which includes any time the woken peer
    /// preempts the sender on a shared CPU.
    pub before_send: Latency,
}
