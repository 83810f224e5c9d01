//! Real surface motion, told from the apparent motion of a stale `k̂_c` (which is tied to the robot's):
//! * the motion test ([`surface_moving`]) on the predictor's velocity and the robot's raw velocity,
//!   passed without a break for `motion_confirm` (a stale `k̂_c` passes it briefly where the robot turns);
//! * a run of surface velocity that keeps its sign while the robot has moved both with it and against
//!   it for `opposed_confirm` each (a stale `k̂_c`'s turns when the robot turns).
//!
//! Either holds the feed-forward on for `motion_hold` (a curved surface passes through zero velocity
//! at every turn) and makes the surface a moving one (no re-fit opens on it); the second also holds
//! the estimator off the moving surface. Both count a surface as still below `max_surface_speed`.
//!
//! The first test runs a second time down to `observer.feedforward_speed` (never within the noise),
//! confirmed over the loop's lead time: that one holds the feed-forward alone. A slow surface on a
//! stiff material is fed forward as a fast one is (0.2 mm at 0.5 Hz, 0.63 mm/s, on 500 kN/m at f_r
//! 20 N swung 15–25 N without it). The identification takes it for a still one (a re-fit may open
//! on it), except that the recursion waits on it as on a fast one once it began after a calm contact
//! ([`Motion::after_calm`]).

use super::observer::ObserverParams;
use crate::estimator::surface_moving;

/// The fewest samples a surface motion is confirmed on, whatever the cycle.
const MIN_SAMPLES: f64 = 2.0;

/// [`MIN_SAMPLES`] as a time in steps: half a step less, a margin for the rounding of the sum of the
/// steps' `dt`.
const CONFIRM_STEPS: f64 = MIN_SAMPLES - 0.5;

/// The motion tests' state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    /// Time left during which the surface counts as moving (feed-forward on), s.
    hold: f64,
    /// How long the predictor has seen surface motion without a break, s.
    time: f64,
    /// Sign of the current run of surface velocity (0: none), and how long within it the robot moved
    /// with it and against it, s.
    run_sign: f64,
    run_with: f64,
    run_against: f64,
    /// Time left during which the estimator takes the surface for a moving one, s.
    est_hold: f64,
    /// The feed-forward's own test, down to `observer.feedforward_speed`: how long it has seen motion
    /// without a break, and the time left during which it holds the feed-forward on, s.
    slow_time: f64,
    slow_hold: f64,
    /// How long no motion (the feed-forward's slow one included) has been held since the last
    /// restart, s.
    calm: f64,
    /// Whether the motion held now began after `motion_hold` of that calm.
    after_calm: bool,
}

impl Motion {
    /// Forget everything.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// A new contact or a new `k̂_c`: the runs start over, the holds run on.
    pub fn restart(&mut self) {
        self.time = 0.0;
        self.slow_time = 0.0;
        self.run_sign = 0.0;
        self.calm = 0.0;
    }

    /// Whether motion is held that began after a calm of `motion_hold` under the same contact and
    /// `k̂_c`: a surface that started to move under a `k̂_c` the calm confirmed, not the apparent
    /// motion of a fresh, perhaps wrong one (after a touch-down the stale estimate's ringing looks
    /// moving, and the recursion must learn from it). The feed-forward's slow motion counts: it ends
    /// the calm and begins such a motion (a surface receding at 0.31 mm/s from a 50 N contact on
    /// 500 kN/m on the 12 ms cell, at a third of the speed of the tool's answer to it, took `k̂_c`
    /// 38 % down).
    pub fn after_calm(&self) -> bool {
        self.after_calm && !self.quiet()
    }

    /// Whether no motion at all is held, the feed-forward's slow one included.
    fn quiet(&self) -> bool {
        self.still() && self.slow_hold <= 0.0
    }

    /// Whether no motion is established.
    pub fn still(&self) -> bool {
        self.hold <= 0.0 && self.est_hold <= 0.0
    }

    /// Whether the feed-forward may act.
    pub fn established(&self) -> bool {
        self.hold > 0.0 || self.slow_hold > 0.0
    }

    /// Run the holds for a step; `seen`: the conditioned motion test passed in contact. Returns
    /// whether the estimator is to take the surface for a moving one.
    pub fn hold(&mut self, p: &ObserverParams, seen: bool, dt: f64) -> bool {
        self.hold = if seen {
            p.motion_hold
        } else {
            (self.hold - dt).max(0.0)
        };
        self.est_hold = (self.est_hold - dt).max(0.0);
        self.slow_hold = (self.slow_hold - dt).max(0.0);
        if self.quiet() {
            self.calm += dt;
            self.after_calm = false;
        } else if self.calm > 0.0 {
            self.after_calm = self.calm >= p.motion_hold;
            self.calm = 0.0;
        }
        self.est_hold > 0.0
    }

    /// Test the predictor's surface velocity `v` against the robot's raw velocity `v_raw` (m/s), with
    /// `thr` the speed below which a surface counts as still, `thr_ff` (at most `thr`) the speed
    /// above which its motion is fed forward, and `lead` the loop's lead time (s).
    pub fn observe(
        &mut self,
        p: &ObserverParams,
        v: f64,
        v_raw: f64,
        thr: [f64; 2],
        lead: f64,
        dt: f64,
    ) {
        let [thr, thr_ff] = thr;
        // Confirmed over `motion_confirm`, and never on fewer than `MIN_SAMPLES` samples: on a slow
        // cycle one noisy sample would otherwise be a motion (half a cycle of margin for the sum's
        // rounding).
        let confirm = p.motion_confirm.max(CONFIRM_STEPS * dt);
        if confirmed(&mut self.time, surface_moving(v, v_raw, thr), confirm, dt) {
            self.hold = p.motion_hold;
        }
        // A surface slower than `thr` is fed forward too (the identification takes it for a still
        // one but for the recursion's wait after a calm contact). Its motion must last the loop's
        // lead time: the loop's own ringing under a stale `k̂_c` shows an apparent motion that turns
        // within it (a noisy doubling at f_r 2.5 N on the 12 ms cell, fed forward, rang into three
        // lost contacts).
        let slow = surface_moving(v, v_raw, thr_ff);
        if confirmed(&mut self.slow_time, slow, confirm.max(lead), dt) {
            self.slow_hold = p.motion_hold;
        }
        if v.abs() > thr {
            if v.signum() != self.run_sign {
                self.run_sign = v.signum();
                self.run_with = 0.0;
                self.run_against = 0.0;
            }
            if v_raw.abs() > thr {
                if v_raw * v > 0.0 {
                    self.run_with += dt;
                } else {
                    self.run_against += dt;
                }
            }
            let opposed = p.opposed_confirm.max(CONFIRM_STEPS * dt);
            if self.run_with >= opposed && self.run_against >= opposed {
                self.est_hold = p.motion_hold;
                self.hold = p.motion_hold;
            }
        } else {
            self.run_sign = 0.0;
        }
    }
}

/// Count a test's passes without a break in `time` (s); whether they lasted `confirm` (s).
fn confirmed(time: &mut f64, passed: bool, confirm: f64, dt: f64) -> bool {
    *time = if passed { *time + dt } else { 0.0 };
    passed && *time >= confirm
}

/// The speed above which the surface counts as moving, m/s: `max_surface_speed`, and never within
/// `motion_significance` standard deviations `v_std` (m/s) of what the sensor's noise makes of a still
/// surface's velocity (on a slow cell on a soft surface the noise alone shows a millimetre a second).
pub fn threshold(max_surface_speed: f64, p: &ObserverParams, v_std: f64) -> f64 {
    max_surface_speed.max(p.motion_significance * v_std)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motion_with_the_robot_at_rest_is_real_and_held() {
        let p = ObserverParams::default();
        let mut m = Motion::default();
        for _ in 0..20 {
            m.observe(&p, 0.005, 0.0, [0.001; 2], 0.03, 1e-3);
        }
        assert!(m.established() && !m.still());
        // Held through a turn, then released.
        for _ in 0..400 {
            m.hold(&p, false, 1e-3);
        }
        assert!(m.established());
        for _ in 0..200 {
            m.hold(&p, false, 1e-3);
        }
        assert!(m.still());
    }

    #[test]
    fn a_slow_surface_is_fed_forward_and_still_identified_on() {
        let p = ObserverParams::default();
        let thr = [0.001, 0.0001];
        let run = |v: f64, steps: usize| {
            let mut m = Motion::default();
            for _ in 0..steps {
                m.observe(&p, v, v, thr, 0.03, 1e-3);
                m.hold(&p, false, 1e-3);
            }
            m
        };
        // 0.5 mm/s with the robot following, under the 1 mm/s of a moving surface and over the
        // feed-forward's 0.1 mm/s, for longer than the 30 ms lead: fed forward, and still to the
        // identification.
        let m = run(0.0005, 40);
        assert!(m.established(), "fed forward");
        assert!(m.still(), "still to the identification");
        // Shorter than the lead (a loop's own ringing turns within it), or slower: nothing.
        for m in [run(0.0005, 25), run(0.00005, 40)] {
            assert!(!m.established() && m.still());
        }
    }

    /// Motion that the conditioned test sees right after a contact begins is the ringing of a fresh
    /// `k̂_c` as often as a surface's: the recursion must learn from it (a touch-down under σ 1 N on
    /// 500 kN/m on P2 whose onset fit said 272 kN/m kept it for the whole contact when that motion
    /// held the recursion off). The same motion after a calm contact of `motion_hold` is a surface
    /// that started to move.
    #[test]
    fn motion_after_a_calm_contact_is_a_moving_surface_and_right_after_a_contact_is_not() {
        let p = ObserverParams::default();
        let dt = 1e-3;
        let seen = |m: &mut Motion, steps: usize, moving: bool| {
            for _ in 0..steps {
                m.hold(&p, moving, dt);
            }
        };
        let mut m = Motion::default();
        m.restart();
        seen(&mut m, 20, true);
        assert!(
            !m.still() && !m.after_calm(),
            "motion right after the contact began"
        );
        // The hold runs out after 0.5 s, then 0.5 s of calm.
        seen(&mut m, 1001, false);
        assert!(m.still());
        seen(&mut m, 1, true);
        assert!(m.after_calm(), "motion after a calm of motion_hold");
        // A new `k̂_c` (a re-fit) needs its own calm.
        seen(&mut m, 1001, false);
        m.restart();
        seen(&mut m, 100, false);
        seen(&mut m, 1, true);
        assert!(
            !m.still() && !m.after_calm(),
            "motion 0.1 s after a new k̂_c"
        );
    }

    /// A surface slower than `max_surface_speed` that starts to move under a calm contact is fed
    /// forward (the slow test) and counts as still for the motion test; it is a moving surface to the
    /// recursion all the same (a slow sine read as a softer surface, `ranges.rs`
    /// `a_slow_surface_that_starts_to_move_is_no_softer_surface`). The calm it needs counts no slow
    /// motion either.
    #[test]
    fn slow_motion_after_a_calm_contact_is_a_moving_surface() {
        let p = ObserverParams::default();
        // 0.3 mm/s with the robot still: slow motion, under the motion test's 1 mm/s.
        let (slow, fast) = (Some(0.3e-3), Some(2e-3));
        let mut m = Motion::default();
        m.restart();
        cycles(&mut m, &p, 600, None);
        cycles(&mut m, &p, 40, slow);
        assert!(
            m.still() && m.established(),
            "fed forward, still to the motion test"
        );
        assert!(m.after_calm(), "a moving surface to the recursion");
        // Slow motion from a contact's start for 0.6 s, then fast: no calm to count.
        let mut m = Motion::default();
        m.restart();
        cycles(&mut m, &p, 600, slow);
        cycles(&mut m, &p, 10, fast);
        assert!(
            !m.still() && !m.after_calm(),
            "no calm while the slow motion was held"
        );
    }

    /// `n` cycles of 1 ms with the robot still, the surface seen at `v` (m/s; `None`: no surface
    /// velocity), under the thresholds of a 1 mm/s moving surface, 0.1 mm/s fed forward and a 30 ms
    /// lead; the holds run every cycle.
    fn cycles(m: &mut Motion, p: &ObserverParams, n: usize, v: Option<f64>) {
        for _ in 0..n {
            if let Some(v) = v {
                m.observe(p, v, 0.0, [1e-3, 1e-4], 0.03, 1e-3);
            }
            m.hold(p, false, 1e-3);
        }
    }

    #[test]
    fn velocity_that_keeps_its_sign_while_the_robot_turns_holds_the_estimator_off() {
        let p = ObserverParams::default();
        let mut m = Motion::default();
        // The robot moves with the surface, then against it: the surface's own motion.
        for i in 0..40 {
            let v_raw = if i < 20 { 0.01 } else { -0.01 };
            m.observe(&p, 0.003, v_raw, [0.001; 2], 0.03, 1e-3);
        }
        assert!(m.hold(&p, false, 1e-3), "the estimator is held off");
        m.reset();
        assert!(m.still());
    }
}
