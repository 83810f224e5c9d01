//! Hard limits on the command: deviation from the programmed path, velocity and acceleration (with a
//! braking distance). Every one that acts is an event of the step.

use serde::{Deserialize, Serialize};

use super::positive;
use crate::law::Events;

/// The relative excess over the acceleration limit's velocity step that counts as the limit acting:
/// the braking's square root and the clamp round in the last digits, which is not a limit event.
const ACCELERATION_TOLERANCE: f64 = 1e-9;

/// Hard limits. Each one that acts is reported.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitParams {
    /// Conditioned force above which the law retracts, N.
    pub max_force: f64,
    /// Largest command velocity, m/s.
    pub max_velocity: f64,
    /// Largest command acceleration, m/s².
    pub max_acceleration: f64,
    /// Largest magnitude of the command, i.e. deviation from the programmed path along the normal, m.
    pub max_deviation: f64,
}

impl LimitParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("limits.max_force", self.max_force)?;
        positive("limits.max_velocity", self.max_velocity)?;
        positive("limits.max_acceleration", self.max_acceleration)?;
        positive("limits.max_deviation", self.max_deviation)
    }
}

/// The limited command and its velocity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limiter {
    p: LimitParams,
    /// Last command, m, and its velocity, m/s.
    u: f64,
    v: f64,
}

impl Limiter {
    /// At rest at 0.
    pub fn new(p: LimitParams) -> Self {
        Self { p, u: 0.0, v: 0.0 }
    }

    /// Take new limits, keeping the command.
    pub fn set_params(&mut self, p: LimitParams) {
        self.p = p;
    }

    /// At rest at `x` (0 when not finite).
    pub fn reset(&mut self, x: f64) {
        self.u = if x.is_finite() { x } else { 0.0 };
        self.v = 0.0;
    }

    /// The last command, m.
    pub fn command(&self) -> f64 {
        self.u
    }

    /// Hold the command this step; it moves off from rest afterwards.
    pub fn hold(&mut self) -> f64 {
        self.v = 0.0;
        self.u
    }

    /// Move towards `want` within the limits, flagging each one that acts.
    pub fn step(&mut self, want: f64, dt: f64, ev: &mut Events) -> f64 {
        let l = self.p;
        let mut target = want;
        if target.abs() > l.max_deviation {
            target = target.clamp(-l.max_deviation, l.max_deviation);
            ev.deviation_limit = true;
        }
        let dist = target - self.u;
        let mut v = dist / dt;
        if v.abs() > l.max_velocity {
            v = v.clamp(-l.max_velocity, l.max_velocity);
            ev.velocity_limit = true;
        }
        // Braking: never faster than what can still stop at the target (not a limit event: it is how
        // an acceleration-limited command reaches a target without overshoot). Discrete time: the
        // largest speed from which steps of at most `a·dt` velocity change still stop within `dist`.
        let half = l.max_acceleration * dt / 2.0;
        let v_brake = (half * half + 2.0 * l.max_acceleration * dist.abs()).sqrt() - half;
        v = v.clamp(-v_brake, v_brake);
        let dv = l.max_acceleration * dt;
        if (v - self.v).abs() > dv * (1.0 + ACCELERATION_TOLERANCE) {
            v = v.clamp(self.v - dv, self.v + dv);
            ev.acceleration_limit = true;
        }
        let mut u = self.u + v * dt;
        if u.abs() > l.max_deviation {
            u = u.clamp(-l.max_deviation, l.max_deviation);
            v = (u - self.u) / dt;
            ev.deviation_limit = true;
        }
        self.v = v;
        self.u = u;
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const L: LimitParams = LimitParams {
        max_force: 60.0,
        max_velocity: 0.1,
        max_acceleration: 20.0,
        max_deviation: 0.05,
    };

    #[test]
    fn velocity_acceleration_and_deviation_are_limited_and_reported() {
        let mut l = Limiter::new(L);
        l.reset(0.0);
        let mut ev = Events::default();
        let u = l.step(1.0, 1e-3, &mut ev);
        assert!(ev.deviation_limit && ev.velocity_limit && ev.acceleration_limit);
        assert!((u - 20.0 * 1e-6).abs() < 1e-15, "{u}");
        let mut v_prev = 0.02;
        let mut u_prev = u;
        for _ in 0..2000 {
            let u = l.step(0.01, 1e-3, &mut Events::default());
            let v = (u - u_prev) / 1e-3;
            assert!(v <= 0.1 + 1e-12 && (v - v_prev).abs() <= 0.02 + 1e-9);
            (u_prev, v_prev) = (u, v);
        }
        assert!(
            (u_prev - 0.01).abs() < 1e-12,
            "reaches the target without overshoot"
        );
        assert_eq!(l.hold(), u_prev);
    }
}
