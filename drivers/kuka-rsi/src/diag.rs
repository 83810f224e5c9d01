//! What the link counts and measures, readable by the application at any time.

use core::time::Duration;

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

/// A receive→send latency distribution: 1 µs buckets up to 4.095 ms, then one overflow bucket.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Latency {
    buckets: Box<[u64; Self::BUCKETS]>,
    count: u64,
    sum_ns: u128,
    max_ns: u64,
}

impl Default for Latency {
    fn default() -> Self {
        Self {
            buckets: Box::new([0; Self::BUCKETS]),
            count: 0,
            sum_ns: 0,
            max_ns: 0,
        }
    }
}

impl Latency {
    const BUCKETS: usize = 4096;

    /// Record one turnaround (no allocation).
    pub fn record(&mut self, d: Duration) {
        let ns = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        let b = ((ns / 1000) as usize).min(Self::BUCKETS - 1);
        self.buckets[b] += 1;
        self.count += 1;
        self.sum_ns += u128::from(ns);
        self.max_ns = self.max_ns.max(ns);
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Largest sample.
    pub fn max(&self) -> Duration {
        Duration::from_nanos(self.max_ns)
    }

    /// Mean.
    pub fn mean(&self) -> Duration {
        if self.count == 0 {
            Duration::ZERO
        } else {
            Duration::from_nanos((self.sum_ns / u128::from(self.count)) as u64)
        }
    }

    /// The `q` quantile (0..=1) as the upper edge of its 1 µs bucket; the maximum for the
    /// overflow bucket; zero without samples.
    pub fn quantile(&self, q: f64) -> Duration {
        if self.count == 0 {
            return Duration::ZERO;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (i, &n) in self.buckets.iter().enumerate() {
            acc += n;
            if acc >= rank {
                return if i == Self::BUCKETS - 1 {
                    self.max()
                } else {
                    Duration::from_micros(i as u64 + 1).min(self.max())
                };
            }
        }
        self.max()
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_of_a_known_distribution() {
        let mut l = Latency::default();
        assert_eq!(l.quantile(0.5), Duration::ZERO);
        for us in 1..=1000u64 {
            l.record(Duration::from_nanos(us * 1000 - 500));
        }
        assert_eq!(l.count(), 1000);
        assert_eq!(l.quantile(0.5), Duration::from_micros(500));
        assert_eq!(l.quantile(0.999), Duration::from_micros(999));
        assert_eq!(l.quantile(1.0), Duration::from_nanos(999_500));
        l.record(Duration::from_secs(1));
        assert_eq!(
            l.quantile(1.0),
            Duration::from_secs(1),
            "overflow reports the max"
        );
    }
}
