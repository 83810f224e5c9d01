//! What the cell can stop: how far the tool goes into a surface after it touches it at speed `v`.
//!
//! A contact just after a sample is seen one cycle later; the commands already sent still move the
//! tool for the delay; then the tool's lag behind its command has to be taken back, and the command
//! reverses no faster than the limiter's acceleration and velocity allow. The law's model of the
//! inner loop ([`CellParams`]: commands held over a cycle, the delay in whole cycles, the first-order
//! lag) is run through that hardest stop; the travel is tabulated over speed and re-tabulated when
//! the cycle (measured: by more than 1 %), the cell or the limits change.
//!
//! The delay and one cycle alone (`v·(T_d + T_c)`, the floor) leave the lag out: measured on
//! a 1 mm retreat re-contacted on 500 kN/m at 1 kHz (P1) the tool stops after 6.2–7.9 ms of its
//! speed against 5 (the re-contact tripped the force limit); on a 4 ms cycle the command reverses
//! within a cycle and the lag costs about one more millisecond.

use super::guards::{DISTANCE_GUARD, SPEED_GUARD, STIFFNESS_GUARD};
use super::{CellParams, LimitParams};

/// What a table is keyed on: cycle, lag, the robot's and the sensor's delays, acceleration, velocity.
const KEY_LEN: usize = 6;

/// The relative change of the measured cycle that re-tabulates: 1 %, a choice that keeps a measured
/// cycle's small wander from re-tabulating (each re-tabulation simulates [`POINTS`] stops in one
/// control step) while a real change of the cycle does.
const CYCLE_TOLERANCE: f64 = 0.01;

/// How far below a whole number of cycles the delay is still counted as that many cycles, in cycles:
/// a delay configured as `3 × 4 ms` is 3 cycles of a measured 4 ms cycle, not 4, whatever rounding
/// the division leaves.
const WHOLE_CYCLE_TOLERANCE: f64 = 1e-6;

/// Speeds tabulated: `top·2^−i`, `i` = 0…`POINTS`−1 (top the limiter's velocity), so the slow
/// approach is resolved as well as the fast search.
const POINTS: usize = 12;

/// Steps of the stop simulated at most, so that a re-tabulation (12 of them, in a control step) stays
/// short: a real cell stops within tens of cycles (P1: the delay's 4 and about 10 of braking). Past
/// it (a lag of seconds on a fast cycle) the travel is bounded by the farthest command, which the
/// lagging tool never passes and which the braking reaches within `v/(a·T)` steps.
const MAX_STEPS: usize = 4096;

/// The travel after contact as a function of speed, for one cell and one set of limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stopping {
    /// What the table was made for: cycle, lag, the robot's and the sensor's delays, acceleration,
    /// velocity (NaN: nothing yet).
    key: [f64; KEY_LEN],
    /// `speed[i]` (m/s, falling) and the travel into the surface at that speed, m.
    speed: [f64; POINTS],
    travel: [f64; POINTS],
}

impl Default for Stopping {
    fn default() -> Self {
        Self::new()
    }
}

impl Stopping {
    /// Nothing tabulated yet.
    pub fn new() -> Self {
        Self {
            key: [f64::NAN; KEY_LEN],
            speed: [0.0; POINTS],
            travel: [0.0; POINTS],
        }
    }

    /// Tabulate for this cell, measured `cycle` (s) and limits, unless the table is already for them.
    pub fn update(&mut self, cell: &CellParams, cycle: f64, limits: &LimitParams) {
        let key = [
            cycle,
            cell.lag,
            cell.delay,
            cell.sensor_delay,
            limits.max_acceleration,
            limits.max_velocity,
        ];
        let same = (key[0] - self.key[0]).abs() <= CYCLE_TOLERANCE * self.key[0]
            && key[1..] == self.key[1..];
        if same {
            return;
        }
        self.key = key;
        for i in 0..POINTS {
            let v = limits.max_velocity / 2f64.powi(i as i32);
            self.speed[i] = v;
            self.travel[i] = travel(cell, cycle, limits, v);
        }
    }

    /// The travel into a surface touched at `v` (m/s), m: interpolated between the tabulated speeds
    /// (linear in speed: the travel grows faster than the speed, so this is never short).
    pub fn travel(&self, v: f64) -> f64 {
        let (s, d) = (&self.speed, &self.travel);
        if v >= s[0] {
            return d[0] * v / s[0];
        }
        for i in 1..POINTS {
            if v >= s[i] {
                let w = (v - s[i]) / (s[i - 1] - s[i]);
                return d[i] + w * (d[i - 1] - d[i]);
            }
        }
        d[POINTS - 1] * v / s[POINTS - 1]
    }

    /// The stopping time at `v`: the travel over the speed, s.
    pub fn time(&self, v: f64) -> f64 {
        self.travel(v) / v.max(SPEED_GUARD)
    }

    /// The largest speed (at most `cap`, m/s, and the limiter's velocity) whose travel into
    /// stiffness `k` (N/m) stays within `force` (N).
    pub fn speed_within(&self, force: f64, k: f64, cap: f64) -> f64 {
        let room = force.max(0.0) / k.max(STIFFNESS_GUARD);
        let (s, d) = (&self.speed, &self.travel);
        let v = if room >= d[0] {
            s[0]
        } else if let Some(i) = (1..POINTS).find(|&i| room >= d[i]) {
            s[i] + (room - d[i]) / (d[i - 1] - d[i]).max(DISTANCE_GUARD) * (s[i - 1] - s[i])
        } else {
            s[POINTS - 1] * room / d[POINTS - 1].max(DISTANCE_GUARD)
        };
        v.min(cap)
    }
}

/// The travel into a surface touched at `v` (m/s) just after a sample, m: one cycle to the next
/// sample, the sensor's delay until the force shows it, the delay's commands, then the stop at the
/// limiter's hardest reversal through the lag. Without a measured cycle, the delays alone.
pub fn travel(cell: &CellParams, cycle: f64, limits: &LimitParams, v: f64) -> f64 {
    if cycle.is_nan() || cycle <= 0.0 || v.is_nan() || v <= 0.0 {
        return v.max(0.0) * cell.loop_delay();
    }
    let t = cycle;
    let alpha = if cell.lag > 0.0 {
        1.0 - (-t / cell.lag).exp()
    } else {
        1.0
    };
    let delay_cycles = (cell.delay / t - WHOLE_CYCLE_TOLERANCE).ceil().max(0.0);
    // At the sample that sees the contact, the tool has gone up to one cycle in, and the commands of
    // the delay still move it on at `v`; then the first braked command arrives. At steady speed the
    // tool is `v·t/α` behind the command it follows. The last command sent is the origin.
    let before = v * t * (1.0 + delay_cycles) + v * cell.sensor_delay;
    let (a, top) = (limits.max_acceleration, limits.max_velocity);
    let mut y = v * t * (1.0 - 1.0 / alpha);
    let start = y;
    let (mut u, mut vel, mut far) = (0.0f64, v, 0.0f64);
    for _ in 0..MAX_STEPS {
        vel = (vel - a * t).max(-top);
        u += vel * t;
        far = far.max(u);
        let next = y + alpha * (u - y);
        if next <= y {
            return before + (y - start);
        }
        y = next;
    }
    before + (far - start)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    const LIMITS: LimitParams = LimitParams {
        max_force: 60.0,
        max_velocity: 0.1,
        max_acceleration: 20.0,
        max_deviation: 0.05,
    };

    /// A cell of `cycle` and `delay` (s), 10 ms lag, the shipped limits, and its table.
    pub(crate) fn cell(cycle: f64, delay: f64) -> (CellParams, Stopping) {
        let c = CellParams {
            cycle,
            lag: 0.010,
            delay,
            sensor_delay: 0.0,
        };
        let mut s = Stopping::new();
        s.update(&c, cycle, &LIMITS);
        (c, s)
    }

    #[test]
    fn the_tool_stops_after_the_delay_one_cycle_and_the_lag() {
        // The measured stops (`stopping_times` in the range tests): P1 6.2–7.9 ms, P2 14.5–15.5 ms
        // at a sample's phase; the model is the worst phase.
        let (_, p1) = cell(0.001, 0.004);
        let (_, p2) = cell(0.004, 0.012);
        for v in [0.01, 0.025, 0.05] {
            assert!(
                (0.0062..0.0095).contains(&p1.time(v)),
                "P1 {v}: {}",
                p1.time(v)
            );
            assert!(
                (0.016..0.0185).contains(&p2.time(v)),
                "P2 {v}: {}",
                p2.time(v)
            );
        }
        assert!(p1.time(0.05) > p1.time(0.01), "the lag costs more at speed");
    }

    /// A sensor whose force is 2.25 ms old (its own 100 Hz filter) shows a contact that much later:
    /// the tool goes on `v·2.25 ms` further, not a whole cycle of the robot's delay line more.
    #[test]
    fn a_sensor_s_delay_adds_its_own_travel() {
        for (cycle, delay) in [(0.001, 0.004), (0.004, 0.012)] {
            let (c, _) = cell(cycle, delay);
            let late = CellParams {
                sensor_delay: 0.00225,
                ..c
            };
            for v in [0.01, 0.05] {
                let more = travel(&late, cycle, &LIMITS, v) - travel(&c, cycle, &LIMITS, v);
                assert!((more - v * 0.00225).abs() < 1e-12, "{more} m");
            }
        }
    }

    #[test]
    fn the_speed_within_a_force_is_the_tables_inverse_and_never_over() {
        let (c, s) = cell(0.001, 0.004);
        for k in [10e3, 70e3, 500e3] {
            for force in [2.0, 10.0, 57.0] {
                let v = s.speed_within(force, k, 1.0);
                let exact = travel(&c, 0.001, &LIMITS, v);
                assert!(
                    k * exact <= force * (1.0 + 1e-9),
                    "{k} {force}: {}",
                    k * exact
                );
                assert!(
                    v == LIMITS.max_velocity || k * exact >= 0.9 * force,
                    "{k} {force}: {} is too slow",
                    k * exact
                );
            }
        }
        assert_eq!(s.speed_within(1e9, 1e3, 0.05), 0.05);
        assert_eq!(
            s.speed_within(1e9, 1e3, 1.0),
            0.1,
            "never above the limiter's velocity"
        );
        assert_eq!(s.speed_within(-1.0, 1e3, 0.05), 0.0);
    }

    #[test]
    fn a_lag_of_seconds_on_a_fast_cycle_is_bounded_by_the_farthest_command() {
        let c = CellParams {
            sensor_delay: 0.0,
            cycle: 1e-4,
            lag: 10.0,
            delay: 0.004,
        };
        let d = travel(&c, 1e-4, &LIMITS, 0.05);
        // At most the ramp to the first braked command, the command's lead over the tool at that
        // speed (`v·τ`, half a metre here) and the braking's own travel, `v²/2a`.
        let most = 0.05 * (0.004 + 1e-4) + 0.05 * 10.0 + 0.05 * 0.05 / 40.0;
        assert!(
            d.is_finite() && d > 0.05 * (0.004 + 1e-4) && d <= most + 1e-9,
            "{d}"
        );
    }

    #[test]
    fn a_new_cycle_retabulates_and_a_jitter_does_not() {
        let (c, mut s) = cell(0.004, 0.012);
        let before = s;
        s.update(&c, 0.00401, &LIMITS);
        assert_eq!(s, before, "0.25 % of jitter");
        s.update(&c, 0.012, &LIMITS);
        assert!(s.time(0.01) > 0.012 + 0.012, "{}", s.time(0.01));
        let untimed = travel(&c, 0.0, &LIMITS, 0.01);
        assert!(
            (untimed - 0.01 * 0.012).abs() < 1e-15,
            "no cycle yet: the delay alone"
        );
    }
}
