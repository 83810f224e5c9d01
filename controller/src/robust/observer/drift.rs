//! A surface that moved further than a still one can appear to.
//!
//! The observed surface is `x − f/k̂_c`. On a still surface it moves only by what a wrong `k̂_c` makes
//! of the force's changes, `Δf·|1/k_c − 1/k̂_c|`: under one penetration `f/k̂_c` while `k̂_c` is within
//! a factor of two, whatever the tool does. A surface that really moves carries it further, at any
//! speed — also below `max_surface_speed` and where the tool, following it, moves faster than it, which
//! the velocity test ([`crate::estimator::surface_moving`]) takes for the apparent motion of a `k̂_c`
//! too high. So once the observed surface has left its own average over `motion_hold` by more than
//! `drift_span` penetrations, the recursion takes the surface for a moving one for `motion_hold`.
//!
//! Found on B5a's slow sine (0.5 mm at 0.5 Hz) on 500 kN/m: the tool, catching up with the surface
//! after a turn, backed off faster than it came in, the force fell, and the recursion took that for a
//! softer surface (`k̂_c` 499 → 316 kN/m within 0.1 s on P1; fault 2 on P2).
//!
//! The average restarts with the observer (a new contact, a new `k̂_c`): what the surface seemed to do
//! under another `k̂_c` says nothing (before a touch-down's fit the tuning's guess makes the surface
//! seem to move by the whole force over it).

use super::ObserverParams;

/// The drift test's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drift {
    /// The observed surface's average over `motion_hold`, m (NaN: none yet).
    slow: f64,
    /// Time left during which the surface counts as moving, s.
    hold: f64,
}

impl Default for Drift {
    fn default() -> Self {
        Self {
            slow: f64::NAN,
            hold: 0.0,
        }
    }
}

impl Drift {
    /// Start over at the observed surface `z`, m.
    pub fn restart(&mut self, z: f64) {
        *self = Self { slow: z, hold: 0.0 };
    }

    /// The observed surface moved by `dz` (m) because `k̂_c` did: the average moves with it.
    pub fn shift(&mut self, dz: f64) {
        self.slow += dz;
    }

    /// A step of `dt` with the observed surface at `z` (m), the set-point's penetration `depth` (m).
    pub fn step(&mut self, p: &ObserverParams, z: f64, depth: f64, dt: f64) {
        if !self.slow.is_finite() {
            self.slow = z;
        }
        self.slow += (dt / p.motion_hold).min(1.0) * (z - self.slow);
        self.hold = if (z - self.slow).abs() > p.drift_span * depth {
            p.motion_hold
        } else {
            (self.hold - dt).max(0.0)
        };
    }

    /// Whether the surface counts as moving.
    pub fn moved(&self) -> bool {
        self.hold > 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ramp at 0.5 mm/s, below `max_surface_speed`, on 500 kN/m at 5 N (10 µm of penetration) is
    /// taken for motion within 0.1 s and held 0.5 s after it stops; a still surface whose observed
    /// position wanders by a penetration (a `k̂_c` twice too high) never is.
    #[test]
    fn a_slow_ramp_is_motion_and_a_stale_stiffness_is_not() {
        let p = ObserverParams::default();
        let depth = 5.0 / 500e3;
        let mut d = Drift::default();
        d.restart(0.010);
        let mut z = 0.010;
        let mut first = None;
        for i in 0..200 {
            z += 0.5e-3 * 1e-3;
            d.step(&p, z, depth, 1e-3);
            if d.moved() && first.is_none() {
                first = Some(i);
            }
        }
        let first = first.expect("the ramp is motion");
        assert!(first < 100, "seen after {first} ms");
        for _ in 0..490 {
            d.step(&p, z, depth, 1e-3);
        }
        assert!(d.moved(), "held through a turn");
        for _ in 0..500 {
            d.step(&p, z, depth, 1e-3);
        }
        assert!(!d.moved(), "released");
        d.restart(0.010);
        for i in 0..5000 {
            let wander = depth * (i as f64 * 0.01).sin();
            d.step(&p, 0.010 + wander, depth, 1e-3);
            assert!(!d.moved(), "a wander of one penetration at step {i}");
        }
    }
}
