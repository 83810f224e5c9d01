//! Orientation following: a law stage ([`Oriented`]) around a [`CellLaw`] along the tool normal that
//! turns the tool (the correction's rotation about tool `x` and `y`) until the contact moment about
//! the pad's centre vanishes — the tool square to the surface — or holds a configured tilt towards
//! the feed (a disc polisher). Model and formulas: `docs/curved-parts.md`.
//!
//! # The step (opt-in: without [`OrientationParams`] the stage passes everything through untouched)
//! 1. The moment about the TCP from the sensor's wrench (compressive convention, tool frame, the
//!    sensor `L` behind the TCP): `M = T − (L·ẑ) × F`, i.e. `Mx = Tx + L·Fy`, `My = Ty − L·Fx`
//!    (friction at the pad face has no moment about `x`/`y` there).
//! 2. The tilt it means, for a pad of radius `r` and the configured stiffness `k` in full contact:
//!    `‖M‖ = K·sin φ·cos φ` with `K = k·r²/4`,
//!    so `φ̂ = ½·asin(min(1, 2‖M‖/K))` about the direction `−M/‖M‖`: the rotation `ψ̂` from the tool
//!    axis to the surface normal.
//! 3. The inner law gets the force along the estimated normal `n̂ = R(ψ̂)·ẑ`, `F·n̂` (friction is
//!    tangent to the surface and drops out).
//! 4. The rotation follows: `θ ← θ + dt·ω`, `ω = gain·(ψ̂ − ψ_d)` with `ψ_d = (0, tilt)`, `‖ω‖`
//!    within `max_rate` (event `orientation_rate`), each axis of `θ` within the robot's POSCORR
//!    rotation limit (event `orientation_limit`); a `θ` that would reach `max_angle` is not taken
//!    and raises `orientation_envelope`, which the loop's guard turns into a correction-limit fault
//!    (it backs off as for any fault).
//! 5. A moment that is not finite or beyond `max_moment` (a saturated or misread gauge) holds `θ` and
//!    the last `ψ̂` (event `orientation_hold`); so does a force below `min_force` (no contact yet:
//!    no event) and, with a configured tilt, below 1.1·`k·r·sin|tilt|` (the pad on its edge). A stale sample never reaches the law: the loop holds the whole correction.
//!
//! The step allocates nothing and reads no clock.

use hal::{Correction, Cycle, Vector3, Wrench};
use serde::{Deserialize, Serialize};

use crate::law::{CellLaw, EventCounts, LawStep};

/// The orientation stage's parameters (the tuning's `[orientation]` table). Angles in rad.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrientationParams {
    /// Distance from the sensor's origin to the pad face (the TCP) along the tool axis, m.
    pub tool_length: f64,
    /// Pad radius, m.
    pub pad_radius: f64,
    /// Tilt to hold towards the feed, about tool `y`, rad (0: square to the surface).
    #[serde(default)]
    pub tilt: f64,
    /// Rotation rate per rad of tilt error, 1/s.
    pub gain: f64,
    /// Largest angular rate of the rotation command, rad/s.
    pub max_rate: f64,
    /// The rotation's envelope: a command that would reach it faults, rad.
    pub max_angle: f64,
    /// The robot's POSCORR rotation limit on each axis, rad.
    pub poscorr: f64,
    /// A moment about the TCP beyond this is not believed (saturated, misread), N·m.
    pub max_moment: f64,
    /// Below this normal force the tool is not in contact: the rotation holds, N.
    pub min_force: f64,
    /// The pad's stiffness, N/m: with the pad radius it makes the moment a tilt (a configured tilt
    /// is held to the accuracy of this value; square to the surface, only the gain depends on it).
    pub stiffness: f64,
}

impl OrientationParams {
    /// Checks every value.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |n: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("orientation.{n} must be > 0, got {v}"))
            }
        };
        if !(self.tool_length.is_finite() && (0.0..=1.0).contains(&self.tool_length)) {
            return Err(format!(
                "orientation.tool_length must be in [0, 1] m, got {}",
                self.tool_length
            ));
        }
        pos("pad_radius", self.pad_radius)?;
        pos("gain", self.gain)?;
        pos("max_rate", self.max_rate)?;
        pos("max_angle", self.max_angle)?;
        pos("poscorr", self.poscorr)?;
        pos("max_moment", self.max_moment)?;
        pos("min_force", self.min_force)?;
        pos("stiffness", self.stiffness)?;
        // Past 30° a pad is on its edge and the full-contact moment model means nothing.
        let most = core::f64::consts::FRAC_PI_6;
        if self.max_angle > most || self.poscorr > most {
            return Err(format!(
                "orientation.max_angle {} and poscorr {} must be at most π/6 rad (30°)",
                self.max_angle, self.poscorr
            ));
        }
        if !(self.tilt.is_finite() && self.tilt.abs() < self.max_angle) {
            return Err(format!(
                "orientation.tilt must lie within ±max_angle ({} rad), got {}",
                self.max_angle, self.tilt
            ));
        }
        Ok(())
    }
}

/// A [`CellLaw`] with orientation following around it (see the module's step). Without parameters
/// it is the inner law, step for step.
#[derive(Clone, Debug)]
pub struct Oriented<L> {
    inner: L,
    params: Option<OrientationParams>,
    force_sign: f64,
    /// The commanded rotation about tool x and y, rad.
    theta: [f64; 2],
    /// The last believed tilt estimate ψ̂, rad.
    psi: [f64; 2],
    counts: OrientationCounts,
}

/// Counters of the stage's events since the law started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct OrientationCounts {
    rates: u64,
    limits: u64,
    holds: u64,
    envelopes: u64,
}

impl<L> Oriented<L> {
    /// `inner` with orientation following by `params` (`None`: off); `force_sign` turns the sensor's
    /// wrench into the compressive convention (the loop's).
    pub fn new(inner: L, params: Option<OrientationParams>, force_sign: f64) -> Self {
        Self {
            inner,
            params,
            force_sign,
            theta: [0.0; 2],
            psi: [0.0; 2],
            counts: OrientationCounts::default(),
        }
    }

    /// The inner law.
    pub fn inner(&self) -> &L {
        &self.inner
    }

    /// The parameters, when orientation following is on.
    pub fn params(&self) -> Option<&OrientationParams> {
        self.params.as_ref()
    }

    /// The rotation command, rad (tool x, y).
    pub fn rotation(&self) -> [f64; 2] {
        self.theta
    }
}

impl<L> Oriented<L> {
    /// The least normal force at which the rotation follows: `min_force`, and with a configured tilt
    /// 10 % above the force that keeps the whole pad in contact at that tilt, `k·r·sin|tilt|` (on its
    /// edge the pad's moment is not the full-contact moment the tilt is read from).
    fn follow_force(&self, p: &OrientationParams) -> f64 {
        p.min_force
            .max(1.1 * p.stiffness * p.pad_radius * p.tilt.abs().sin())
    }
}

impl<L: CellLaw> CellLaw for Oriented<L> {
    fn start(&mut self, cycle: &Cycle, at: &Correction) {
        self.inner.start(cycle, at);
        // Bumpless: from the rotation the robot has now (the standing correction's when the poses
        // say nothing usable).
        let rel = (cycle.programmed.orientation.inverse() * cycle.actual.orientation).scaled_axis();
        let r = if rel.iter().all(|v| v.is_finite()) {
            rel
        } else {
            at.rotation
        };
        self.theta = [r.x, r.y];
        self.psi = [0.0; 2];
        self.counts = OrientationCounts::default();
    }

    fn step(&mut self, cycle: &Cycle, wrench: &Wrench, dt: f64) -> LawStep {
        let Some(p) = self.params else {
            return self.inner.step(cycle, wrench, dt);
        };
        let s = self.force_sign;
        let (f, t) = (wrench.force * s, wrench.torque * s);
        let m = [t.x + p.tool_length * f.y, t.y - p.tool_length * f.x];
        let m_norm = (m[0] * m[0] + m[1] * m[1]).sqrt();
        let believed = m_norm.is_finite() && m_norm <= p.max_moment;
        if believed {
            let big_k = p.stiffness * p.pad_radius * p.pad_radius / 4.0;
            let phi = 0.5 * (2.0 * m_norm / big_k).min(1.0).asin();
            self.psi = if m_norm > 0.0 {
                [-m[0] / m_norm * phi, -m[1] / m_norm * phi]
            } else {
                [0.0; 2]
            };
        }
        // The force along the estimated normal n̂ = R(ψ̂)·ẑ.
        let phi = (self.psi[0] * self.psi[0] + self.psi[1] * self.psi[1]).sqrt();
        let sinc = if phi > 1e-9 { phi.sin() / phi } else { 1.0 };
        let n = Vector3::new(self.psi[1] * sinc, -self.psi[0] * sinc, phi.cos());
        let f_n = f.dot(&n);
        let along = Wrench {
            force: Vector3::new(wrench.force.x, wrench.force.y, s * f_n),
            torque: wrench.torque,
        };
        let mut step = self.inner.step(cycle, &along, dt);
        let ev = &mut step.out.events;
        if !believed {
            ev.orientation_hold = true;
        } else if f_n >= self.follow_force(&p) && dt > 0.0 {
            let e = [self.psi[0], self.psi[1] - p.tilt];
            let mut w = [p.gain * e[0], p.gain * e[1]];
            let w_norm = (w[0] * w[0] + w[1] * w[1]).sqrt();
            if w_norm > p.max_rate {
                let k = p.max_rate / w_norm;
                w = [w[0] * k, w[1] * k];
                ev.orientation_rate = true;
            }
            let mut next = [self.theta[0] + dt * w[0], self.theta[1] + dt * w[1]];
            for v in &mut next {
                if v.abs() > p.poscorr {
                    *v = v.clamp(-p.poscorr, p.poscorr);
                    ev.orientation_limit = true;
                }
            }
            if (next[0] * next[0] + next[1] * next[1]).sqrt() >= p.max_angle {
                ev.orientation_envelope = true;
            } else {
                self.theta = next;
            }
        }
        self.counts.rates += u64::from(ev.orientation_rate);
        self.counts.limits += u64::from(ev.orientation_limit);
        self.counts.holds += u64::from(ev.orientation_hold);
        self.counts.envelopes += u64::from(ev.orientation_envelope);
        step.correction.rotation = Vector3::new(self.theta[0], self.theta[1], 0.0);
        step
    }

    fn set_point(&self) -> f64 {
        self.inner.set_point()
    }

    fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        self.inner.set_set_point(f_r)
    }

    fn counters(&self) -> EventCounts {
        let mut c = self.inner.counters();
        c.orientation_rates = self.counts.rates;
        c.orientation_limits = self.counts.limits;
        c.orientation_holds = self.counts.holds;
        c.orientation_envelopes = self.counts.envelopes;
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::{AlongNormal, ImpedanceLaw, ImpedanceParams, Reference};
    use hal::{Pose, UnitQuaternion};

    fn params() -> OrientationParams {
        OrientationParams {
            tool_length: 0.1,
            pad_radius: 0.02,
            tilt: 0.0,
            gain: 20.0,
            max_rate: 0.5,
            max_angle: 0.2,
            poscorr: 0.15,
            max_moment: 5.0,
            min_force: 2.0,
            stiffness: 10_000.0,
        }
    }

    fn law(p: Option<OrientationParams>) -> Oriented<AlongNormal<ImpedanceLaw>> {
        let inner =
            ImpedanceLaw::new(ImpedanceParams::PAPER, Reference::Fixed { x_r: 0.001 }).unwrap();
        let mut l = Oriented::new(AlongNormal::new(inner, 1.0), p, 1.0);
        l.start(&cycle(), &Correction::default());
        l
    }

    fn cycle() -> Cycle {
        Cycle {
            seq: 0,
            t: 0.0,
            period: 0.004,
            actual: Pose::identity(),
            programmed: Pose::identity(),
            late_replies: 0,
            missed: 0,
            replied_late: 0,
            new_session: false,
            process: None,
        }
    }

    /// The wrench of a flat pad tilted by `psi` (rotation from tool axis to normal) at 20 N, with
    /// the lever of a sensor 0.1 m behind the TCP and friction `fx` along the feed.
    fn tilted(psi: [f64; 2], fx: f64) -> Wrench {
        let r: f64 = 0.02;
        let big_k = 10_000.0 * r * r / 4.0;
        let phi = (psi[0] * psi[0] + psi[1] * psi[1]).sqrt();
        let scale = if phi > 0.0 {
            phi.sin() * phi.cos() / phi
        } else {
            0.0
        };
        let m = [-big_k * psi[0] * scale, -big_k * psi[1] * scale];
        let f = Vector3::new(psi[1] * 20.0 + fx, -psi[0] * 20.0, 20.0);
        // T = M_tcp + (L·ẑ) × F.
        Wrench {
            force: f,
            torque: Vector3::new(m[0] - 0.1 * f.y, m[1] + 0.1 * f.x, 0.0),
        }
    }

    #[test]
    fn off_it_is_the_inner_law_step_for_step() {
        let (mut on, mut off) = (law(None), law(None));
        let mut bare = AlongNormal::new(
            ImpedanceLaw::new(ImpedanceParams::PAPER, Reference::Fixed { x_r: 0.001 }).unwrap(),
            1.0,
        );
        bare.start(&cycle(), &Correction::default());
        for _ in 0..10 {
            let w = tilted([0.05, 0.0], 3.0);
            let a = on.step(&cycle(), &w, 0.004);
            let _ = off.step(&cycle(), &w, 0.004);
            let b = bare.step(&cycle(), &w, 0.004);
            // (NaN estimates of the fixed-reference law compare unequal: compare what is sent.)
            assert_eq!(
                (a.correction, a.out.x_cmd, a.out.events),
                (b.correction, b.out.x_cmd, b.out.events)
            );
            assert_eq!(a.correction.rotation, Vector3::zeros());
        }
    }

    #[test]
    fn it_turns_towards_the_normal_at_its_rate_and_the_friction_lever_does_not_fool_it() {
        let mut l = law(Some(params()));
        let s = l.step(&cycle(), &tilted([0.05, -0.02], 6.0), 0.004);
        let r = s.correction.rotation;
        // ω = gain·ψ = (1.0, −0.4) rad/s, limited to 0.5 rad/s: the same direction.
        assert!(s.out.events.orientation_rate);
        assert!((r.norm() - 0.5 * 0.004).abs() < 1e-6, "{r:?}");
        assert!((r.x / r.y + 2.5).abs() < 0.05, "{r:?}");
        // Square to the surface: no moment, no turn.
        let mut l = law(Some(params()));
        let s = l.step(&cycle(), &tilted([0.0, 0.0], 6.0), 0.004);
        assert_eq!(s.correction.rotation, Vector3::zeros());
        assert!(!s.out.events.orientation_rate);
    }

    #[test]
    fn a_configured_tilt_is_where_it_stops() {
        let mut p = params();
        // 20 N keeps the whole pad in contact at 0.05 rad (k·r·sin = 10 N), not at 0.15 (30 N).
        p.tilt = 0.05;
        let mut l = law(Some(p));
        let s = l.step(&cycle(), &tilted([0.0, 0.05], 0.0), 0.004);
        assert!(
            s.correction.rotation.norm() < 1e-9,
            "{:?}",
            s.correction.rotation
        );
        let s = l.step(&cycle(), &tilted([0.0, 0.02], 0.0), 0.004);
        assert!(s.correction.rotation.y < 0.0, "turns towards more tilt");
        p.tilt = 0.15;
        let mut l = law(Some(p));
        let s = l.step(&cycle(), &tilted([0.0, 0.02], 0.0), 0.004);
        assert_eq!(
            s.correction.rotation,
            Vector3::zeros(),
            "the pad would be on its edge: holds"
        );
    }

    #[test]
    fn a_saturated_or_non_finite_moment_holds_the_rotation_and_says_so() {
        let mut l = law(Some(params()));
        let first = l
            .step(&cycle(), &tilted([0.05, 0.0], 0.0), 0.004)
            .correction
            .rotation;
        for bad in [
            Wrench::from_array([0.0, 0.0, 20.0, 9.0, 0.0, 0.0]),
            Wrench::from_array([0.0, 0.0, 20.0, f64::NAN, 0.0, 0.0]),
            Wrench::from_array([0.0, 0.0, 20.0, f64::INFINITY, 0.0, 0.0]),
        ] {
            let s = l.step(&cycle(), &bad, 0.004);
            assert!(s.out.events.orientation_hold, "{bad:?}");
            assert_eq!(s.correction.rotation, first, "held");
            assert!(s.correction.rotation.iter().all(|v| v.is_finite()));
        }
        assert_eq!(l.counters().orientation_holds, 3);
    }

    #[test]
    fn poscorr_clamps_and_the_envelope_faults_without_moving() {
        let mut p = params();
        p.poscorr = 0.01;
        p.max_rate = 10.0;
        let mut l = law(Some(p));
        let mut s = l.step(&cycle(), &tilted([0.2, 0.0], 0.0), 0.004);
        for _ in 0..20 {
            s = l.step(&cycle(), &tilted([0.2, 0.0], 0.0), 0.004);
        }
        assert!(s.out.events.orientation_limit);
        assert_eq!(s.correction.rotation.x, 0.01);
        assert!(l.counters().orientation_limits > 0);

        let mut p = params();
        p.max_angle = 0.011;
        p.poscorr = 0.1;
        p.max_rate = 10.0;
        let mut l = law(Some(p));
        let mut s = l.step(&cycle(), &tilted([0.2, 0.0], 0.0), 0.004);
        while !s.out.events.orientation_envelope {
            s = l.step(&cycle(), &tilted([0.2, 0.0], 0.0), 0.004);
        }
        assert!(
            s.correction.rotation.norm() < 0.011,
            "{:?}",
            s.correction.rotation
        );
        assert_eq!(l.counters().orientation_envelopes, 1);
    }

    #[test]
    fn out_of_contact_it_holds_and_it_starts_from_the_rotation_the_robot_has() {
        let mut l = law(Some(params()));
        let mut w = tilted([0.05, 0.0], 0.0);
        w.force.z = 1.0;
        let s = l.step(&cycle(), &w, 0.004);
        assert_eq!(s.correction.rotation, Vector3::zeros());
        assert!(!s.out.events.orientation_hold);
        let mut c = cycle();
        c.actual.orientation = UnitQuaternion::from_scaled_axis(Vector3::new(0.03, -0.01, 0.0));
        l.start(&c, &Correction::default());
        assert!((l.rotation()[0] - 0.03).abs() < 1e-12 && (l.rotation()[1] + 0.01).abs() < 1e-12);
    }

    #[test]
    fn parameters_are_checked() {
        let mut p = params();
        assert!(p.validate().is_ok());
        p.gain = f64::NAN;
        assert!(p.validate().unwrap_err().contains("gain"));
        let mut p = params();
        p.tilt = 0.3;
        assert!(p.validate().unwrap_err().contains("tilt"));
    }
}
