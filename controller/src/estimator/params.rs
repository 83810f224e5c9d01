//! The estimator's configuration.

use serde::{Deserialize, Serialize};

/// Estimator configuration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorParams {
    /// Initial stiffness estimate `k̂_c(0)`, N/m.
    pub kc0: f64,
    /// Lower bound of `k̂_c`, N/m.
    pub kc_min: f64,
    /// Upper bound of `k̂_c`, N/m.
    pub kc_max: f64,
    /// Forgetting time constant, s of adapting time.
    pub memory: f64,
    /// Excitation needed to adapt, N: the conditioned force must leave its slow average by this much, and
    /// the position by this much at `kc_max` (`kc_max·|x − x̄|`).
    pub excitation: f64,
    /// Time constant of the slow position average `x̄` the excitation is measured from, s.
    pub excitation_window: f64,
    /// Initial relative uncertainty of `k̂_c` at each contact onset (1 = ±100 %).
    pub initial_uncertainty: f64,
    /// Adapt only while the observed surface moves slower than this, m/s (see
    /// [`surface_moving`](super::surface_moving)): on a moving surface the position follows the surface under a steady force,
    /// and the regression learns the motion instead of the stiffness.
    pub max_surface_speed: f64,
}

impl EstimatorParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |n: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("estimator.{n} must be > 0, got {v}"))
            }
        };
        let nonneg = |n: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(format!("estimator.{n} must be >= 0, got {v}"))
            }
        };
        pos("kc0", self.kc0)?;
        pos("kc_min", self.kc_min)?;
        pos("kc_max", self.kc_max)?;
        pos("memory", self.memory)?;
        pos("excitation_window", self.excitation_window)?;
        pos("initial_uncertainty", self.initial_uncertainty)?;
        pos("max_surface_speed", self.max_surface_speed)?;
        nonneg("excitation", self.excitation)?;
        if self.kc_min > self.kc_max {
            return Err(format!(
                "estimator.kc_min {} N/m is above kc_max {} N/m",
                self.kc_min, self.kc_max
            ));
        }
        if !(self.kc_min..=self.kc_max).contains(&self.kc0) {
            return Err(format!(
                "estimator.kc0 {} N/m is outside [kc_min, kc_max] = [{}, {}] N/m",
                self.kc0, self.kc_min, self.kc_max
            ));
        }
        Ok(())
    }
}
