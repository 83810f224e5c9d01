//! A receive→send latency histogram, shared by the robot drivers (each records its own link's
//! turnaround): fixed 1 µs buckets, no allocation per sample.

use core::time::Duration;

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
