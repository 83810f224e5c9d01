//! The response in contact: the proportional path `κ·(f_r − f̃)/k̂_c` anchored on the measured position
//! (weighted down inside the sensor's noise), the conditional integral, and the set-point's slew.

use serde::{Deserialize, Serialize};

use super::{at_least, non_negative, positive};

/// Largest magnitude of the integral term, m: a guard against wind-up, no tuning. It was the parameter
/// `response.integral_limit` (0.3 mm); at half of it no B, pass or range figure changed, nor at 1 m
/// (the clamp binds in none of them: the integral acts only within `integration_band` of the set-point
/// and its gain falls with the noise), so it left the tuning (docs/robust-law.md, "Fewer parameters").
pub const INTEGRAL_LIMIT: f64 = 3e-4;

/// How the law responds in contact.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResponseParams {
    /// Fraction `κ` of the force error, converted to a position by `k̂_c`, corrected per command. In
    /// (0, 1]; the loop stays stable while `κ·k_c/k̂_c < 2`.
    pub kappa: f64,
    /// Integral gain `k_i`, 1/s (0: none).
    pub integral: f64,
    /// Sensor noise, relative to the set-point, at which the integral's gain is halved (advanced): the
    /// gain is `integral / (1 + (σ / (integral_noise·f_r))²)`. The integral pulls in what the
    /// proportional path leaves standing (a servo that stops short of its command); inside the noise
    /// gate it would random-walk on the noise instead, and the weighted-down proportional path lets
    /// the force follow that walk.
    #[serde(default = "default_integral_noise")]
    pub integral_noise: f64,
    /// Natural frequency of the surface observer the estimator's motion test and the reported `x̂_c`
    /// use, Hz.
    pub surface_bandwidth: f64,
    /// Spectral density of the surface's jerk in the surface predictor's model, m²/s⁵. With the
    /// measured sensor noise it sets the predictor's bandwidth (see [`crate::predictor`]).
    pub surface_jerk: f64,
    /// Largest acceleration of the surface along the tool axis the predictor extrapolates, m/s²
    /// (advanced). A pass at feed `v` over a curve of radius `R` shows `v²/R`: 50 mm/s over 50 mm is
    /// 0.05 m/s², B5b's 1 mm at 1 Hz 0.039 m/s². A surface that starts to move at its full speed looks
    /// like a far larger acceleration to the predictor's model (0.2 m/s² at 3 mm/s), whose
    /// extrapolation over the lead time commands the tool past the surface's path.
    #[serde(default = "default_surface_acceleration")]
    pub surface_acceleration: f64,
    /// Floor of the force noise the predictor assumes, N (quantisation, model error).
    pub noise_floor: f64,
    /// Dead-band of the fallback feed-forward per newton of sensor noise, (m/s)/N. While no real
    /// surface motion is established (see [`crate::estimator::surface_moving`]) the law feeds the
    /// conditioned observer's velocity forward over the loop's lead time instead of the prediction;
    /// inside `σ·feedforward_deadband` that velocity is taken for differentiated noise (and inside
    /// the noise's velocity scale on the observer, see `observer.deadband_significance`).
    pub feedforward_deadband: f64,
    /// Largest rate of change of the set-point when it is changed, N/s (bumpless changes).
    pub set_point_rate: f64,
    /// Noise gate: the proportional correction is weighted by `e²/(e² + (noise_gate·σ)²)`, with `e` the
    /// conditioned force error and `σ` the sensor noise the law measures online. 0 switches it off.
    pub noise_gate: f64,
    /// Relative force error within which the integral acts (advanced): near the set-point what is left
    /// is a ramp's lag; a transient's error is the proportional path's business.
    #[serde(default = "default_integration_band")]
    pub integration_band: f64,
    /// While a rise of the force under a steady contact that a stiffness up to this factor higher
    /// explains is not resolved by the re-fit (a surface step or a stiffer surface), the correction
    /// takes the stiffness as risen with the force; a larger rise is a surface step (advanced; 1: off).
    #[serde(default = "default_jump_caution")]
    pub jump_caution: f64,
}

fn default_jump_caution() -> f64 {
    2.0
}

fn default_surface_acceleration() -> f64 {
    0.05
}

fn default_integral_noise() -> f64 {
    0.1
}

fn default_integration_band() -> f64 {
    0.3
}

impl ResponseParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("response.kappa", self.kappa)?;
        if self.kappa > 1.0 {
            return Err(format!("response.kappa must be <= 1, got {}", self.kappa));
        }
        non_negative("response.integral", self.integral)?;
        positive("response.integral_noise", self.integral_noise)?;
        positive("response.surface_bandwidth", self.surface_bandwidth)?;
        positive("response.surface_jerk", self.surface_jerk)?;
        positive("response.surface_acceleration", self.surface_acceleration)?;
        positive("response.noise_floor", self.noise_floor)?;
        non_negative("response.feedforward_deadband", self.feedforward_deadband)?;
        positive("response.set_point_rate", self.set_point_rate)?;
        non_negative("response.noise_gate", self.noise_gate)?;
        positive("response.integration_band", self.integration_band)?;
        at_least("response.jump_caution", self.jump_caution, 1.0)
    }
}

/// The response's state: the active set-point and the integral.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Response {
    p: ResponseParams,
    f_r: f64,
    integ: f64,
    /// Rate of the active set-point over the last step, N/s.
    rate: f64,
}

impl Response {
    /// At rest at set-point `f_r`.
    pub fn new(p: ResponseParams, f_r: f64) -> Self {
        Self {
            p,
            f_r,
            integ: 0.0,
            rate: 0.0,
        }
    }

    /// Take new parameters, keeping the state.
    pub fn set_params(&mut self, p: ResponseParams) {
        self.p = p;
    }

    /// At rest at set-point `f_r`.
    pub fn reset(&mut self, f_r: f64) {
        self.f_r = f_r;
        self.integ = 0.0;
        self.rate = 0.0;
    }

    /// A new contact: the integral starts over.
    pub fn begin_contact(&mut self) {
        self.integ = 0.0;
    }

    /// The active set-point, N.
    pub fn set_point(&self) -> f64 {
        self.f_r
    }

    /// Slew the active set-point towards `target` for a step of `dt`; returns it, N.
    pub fn slew(&mut self, target: f64, dt: f64) -> f64 {
        let df = self.p.set_point_rate * dt;
        let step = (target - self.f_r).clamp(-df, df);
        self.f_r += step;
        self.rate = step / dt;
        self.f_r
    }

    /// How fast the active set-point moved over the last step, N/s (0 once it stands).
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// The proportional correction and the integral (updated) for conditioned force `ff`, stiffness `k`
    /// and noise variance `noise_var`; `force_scale` is the set-point, at least the contact force, N.
    /// Returns `(proportional, integral)`, m.
    pub fn correction(
        &mut self,
        ff: f64,
        k: f64,
        noise_var: f64,
        force_scale: f64,
        dt: f64,
    ) -> (f64, f64) {
        let r = self.p;
        let e = self.f_r - ff;
        let n = r.noise_gate * r.noise_gate * noise_var;
        let weight = if n > 0.0 { e * e / (e * e + n) } else { 1.0 };
        let delta = e / k;
        // While the set-point moves, the error is the ramp's lag, which the set-point feed-forward
        // answers: integrating it would wind up and overshoot the ramp's end.
        if e.abs() <= r.integration_band * force_scale && self.rate == 0.0 {
            let lim = INTEGRAL_LIMIT;
            let gain = r.integral / (1.0 + noise_var / (r.integral_noise * force_scale).powi(2));
            self.integ = (self.integ + dt * gain * delta).clamp(-lim, lim);
        }
        (weight * r.kappa * delta, self.integ)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: ResponseParams = ResponseParams {
        kappa: 0.8,
        integral: 1.5,
        integral_noise: 0.1,
        surface_bandwidth: 8.0,
        surface_jerk: 0.001,
        surface_acceleration: 0.05,
        noise_floor: 0.02,
        feedforward_deadband: 0.0006,
        set_point_rate: 50.0,
        noise_gate: 1.0,
        integration_band: 0.3,
        jump_caution: 2.0,
    };

    #[test]
    fn the_set_point_slews_and_the_integral_acts_near_it_only() {
        let mut r = Response::new(P, 5.0);
        assert_eq!(r.slew(10.0, 1e-3), 5.05);
        r.reset(5.0);
        // Far from the set-point: proportional only.
        let (p, i) = r.correction(0.0, 50_000.0, 0.0, 5.0, 1e-3);
        assert!((p - 0.8 * 5.0 / 50_000.0).abs() < 1e-15 && i == 0.0);
        // Near it: the integral builds up, within its limit.
        for _ in 0..100_000 {
            r.correction(4.5, 50_000.0, 0.0, 5.0, 1e-3);
        }
        assert_eq!(r.correction(4.5, 50_000.0, 0.0, 5.0, 1e-3).1, 0.0003);
        // Inside the noise the proportional correction is weighted down.
        let (p, _) = r.correction(4.9, 50_000.0, 0.25, 5.0, 1e-3);
        assert!(p < 0.1 * 0.8 * 0.1 / 50_000.0, "{p}");
        r.begin_contact();
        assert_eq!(r.correction(0.0, 50_000.0, 0.0, 5.0, 1e-3).1, 0.0);
    }

    /// The integral's gain halves where the noise is `integral_noise` of the set-point, and falls with
    /// its square beyond: it pulls in a standing error, not the noise.
    #[test]
    fn the_integral_slows_down_in_noise() {
        let first_step = |noise_var: f64| {
            let mut r = Response::new(P, 5.0);
            r.correction(4.9, 50_000.0, noise_var, 5.0, 1e-3).1
        };
        let quiet = first_step(0.0);
        assert!(
            (quiet - 1e-3 * 1.5 * 0.1 / 50_000.0).abs() < 1e-18,
            "{quiet}"
        );
        assert!((first_step(0.25) - quiet / 2.0).abs() < 1e-18);
        assert!((first_step(1.0) - quiet / 5.0).abs() < 1e-18);
        let p = ResponseParams {
            integral_noise: 0.0,
            ..P
        };
        assert!(p.validate().unwrap_err().contains("integral_noise"));
    }

    #[test]
    fn validation_names_the_field() {
        let p = ResponseParams { kappa: 1.5, ..P };
        assert!(p.validate().unwrap_err().contains("kappa"));
        for jump_caution in [0.5, f64::NAN, f64::INFINITY] {
            let p = ResponseParams { jump_caution, ..P };
            assert!(p.validate().unwrap_err().contains("jump_caution"));
        }
        assert!(
            ResponseParams {
                jump_caution: 1.0,
                ..P
            }
            .validate()
            .is_ok()
        );
    }
}
