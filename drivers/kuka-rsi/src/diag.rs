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
    /// Replies sent more than the configured `late_after` after their datagram arrived: measured from
    /// the kernel's receive stamp (`SO_TIMESTAMPNS`), so a datagram that waited in the socket while
    /// the loop was busy counts; from the receive call's return where the kernel gave no stamp
    /// (those replies are also counted in [`unstamped`](Self::unstamped)).
    pub late: u64,
    /// Replies whose lateness was measured from the receive call's return, the kernel having given no
    /// arrival stamp for their datagram.
    pub unstamped: u64,
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
    /// Arrival→send time of every reply sent: from the kernel's receive stamp of the datagram (where
    /// there is none, its receipt) to the return of the send call; what [`Counters::late`] judges.
    pub from_arrival: Latency,
    /// The part of [`latency`](Self::latency) before the send call: parsing, the application's cycle
    /// and the reply's encoding, all in user space. The rest is the send call itself, which on
    /// loopback also delivers the datagram to the peer and wakes it (an idle peer on another CPU of
    /// a virtual machine costs tens of µs there), and which includes any time the woken peer
    /// preempts the sender on a shared CPU.
    pub before_send: Latency,
    /// What the first cycles of the session showed of the robot's data ([`Measured`]).
    pub measured: Measured,
}

/// Cycles of a session the detectors watch before they judge.
pub const PROBE_CYCLES: u32 = 50;

/// What the first [`PROBE_CYCLES`] cycles of the latest session showed, for [`Diagnostics::advisories`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measured {
    /// The finest decimal step seen in `RIst` X, Y, Z, m (1e-4 mm written with 4 decimals: 1e-7 m);
    /// `None` until the positions changed in [`PROBE_CYCLES`] cycles.
    pub position_resolution: Option<f64>,
    /// The smallest IPOC step between consecutive datagrams over the first cycles.
    pub ipoc_step: Option<u64>,
    /// Seconds per IPOC count in use: the configured `ipoc_unit`, or `period / ipoc_step` when the
    /// step disagrees with the period (adopted; see `docs/wire-rsi.md`).
    pub ipoc_unit: Option<f64>,
}

/// The decimals a wire value (mm) was written with, 0..=6 (6: six or more).
pub fn decimals_of(mm: f64) -> u8 {
    let mut scale = 1.0;
    for d in 0..6u8 {
        let x = mm * scale;
        if (x - x.round()).abs() < 1e-6 * scale.max(1.0) {
            return d;
        }
        scale *= 10.0;
    }
    6
}

impl Diagnostics {
    /// Warnings about what degrades control, from [`Measured`]: positions too coarse for the force
    /// control at contact stiffness `stiffness` (N/m), an IPOC step that disagreed with `period`
    /// (s). Each is one line with the consequence and the fix.
    pub fn advisories(&self, period: f64, stiffness: f64) -> Vec<String> {
        let mut out = Vec::new();
        let m = &self.measured;
        if let Some(q) = m.position_resolution {
            let err = stiffness * q / 2.0;
            if err >= 0.1 {
                out.push(format!(
                    "warning: the robot sends positions at {:.4} mm resolution: at {:.0} kN/m contact stiffness that is a steady force error of up to k*q/2 = {err:.2} N; raise the ETHERNET object's Precision in the RSI context to 4 decimals",
                    q * 1e3,
                    stiffness * 1e-3
                ));
            }
        }
        if let (Some(step), Some(unit)) = (m.ipoc_step, m.ipoc_unit) {
            let expected = (period * 1e3).round();
            if (unit * step as f64 - period).abs() < 1e-9 && step as f64 != expected {
                out.push(format!(
                    "warning: the robot's IPOC steps by {step} per cycle, not {expected} (1 per ms at a {:.0} ms cycle): robot time was taken as {step} counts per {:.0} ms cycle; a real KUKA controller counts milliseconds, so check the robot side (a simulator?) or cycle_ms",
                    period * 1e3,
                    period * 1e3
                ));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimals_are_read_from_the_values() {
        assert_eq!(decimals_of(450.0), 0);
        assert_eq!(decimals_of(801.2), 1);
        assert_eq!(decimals_of(-12.25), 2);
        assert_eq!(decimals_of(801.2501), 4);
    }

    #[test]
    fn coarse_positions_and_a_foreign_ipoc_step_are_warned_with_their_cost() {
        let mut d = Diagnostics::default();
        assert!(d.advisories(0.004, 70e3).is_empty());
        // 0.1 mm at 70 kN/m: up to 3.5 N.
        d.measured.position_resolution = Some(1e-4);
        let a = d.advisories(0.004, 70e3);
        assert_eq!(a.len(), 1);
        assert!(
            a[0].contains("0.1000 mm") && a[0].contains("3.50 N"),
            "{}",
            a[0]
        );
        // 1e-4 mm (4 decimals) costs 0.0035 N: no warning.
        d.measured.position_resolution = Some(1e-7);
        assert!(d.advisories(0.004, 70e3).is_empty());
        // IPOC stepping 1 per 4 ms cycle, the unit adopted from the period.
        d.measured.ipoc_step = Some(1);
        d.measured.ipoc_unit = Some(0.004);
        let a = d.advisories(0.004, 70e3);
        assert!(a[0].contains("steps by 1 per cycle, not 4"), "{a:?}");
        // Stepping 4 at 1 ms per count: as it should be.
        d.measured.ipoc_step = Some(4);
        d.measured.ipoc_unit = Some(0.001);
        assert!(d.advisories(0.004, 70e3).is_empty());
    }
}
