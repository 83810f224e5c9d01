//! The robust law's parameters: one section per stage, the advanced ones with defaults.

use serde::{Deserialize, Serialize};

use super::{
    CellParams, ContactParams, IdentifyParams, LimitParams, NoiseParams, ObserverParams,
    ResponseParams,
};
use crate::conditioning::ConditioningParams;
use crate::estimator::EstimatorParams;

/// Everything the robust law needs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobustParams {
    /// Force set-point `f_r`, N.
    pub f_r: f64,
    /// The cell's inner loop (cycle, lag, delay).
    #[serde(default)]
    pub cell: CellParams,
    /// Response in contact.
    pub response: ResponseParams,
    /// Force conditioning.
    pub conditioning: ConditioningParams,
    /// Stiffness estimator.
    pub estimator: EstimatorParams,
    /// Contact state machine.
    pub contact: ContactParams,
    /// Limits.
    pub limits: LimitParams,
    /// Sensor noise meter (advanced).
    #[serde(default)]
    pub noise: NoiseParams,
    /// Surface observer and predictor (advanced).
    #[serde(default)]
    pub observer: ObserverParams,
    /// Stiffness identification (advanced).
    #[serde(default)]
    pub identify: IdentifyParams,
}

pub(crate) fn positive(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be > 0, got {v}"))
    }
}

pub(crate) fn non_negative(name: &str, v: f64) -> Result<(), String> {
    at_least(name, v, 0.0)
}

pub(crate) fn at_least(name: &str, v: f64, min: f64) -> Result<(), String> {
    if v.is_finite() && v >= min {
        Ok(())
    } else {
        Err(format!("{name} must be >= {min}, got {v}"))
    }
}

impl RobustParams {
    /// Checks every value and the relations between them.
    pub fn validate(&self) -> Result<(), String> {
        non_negative("f_r", self.f_r)?;
        self.cell.validate()?;
        self.response.validate()?;
        self.conditioning.validate()?;
        self.estimator.validate()?;
        self.contact.validate()?;
        self.limits.validate()?;
        self.noise.validate()?;
        self.observer.validate()?;
        self.identify.validate()?;
        let (c, l) = (&self.contact, &self.limits);
        if l.max_force <= self.f_r.max(c.contact_force) {
            return Err(format!(
                "limits.max_force {} N must be above the set-point {} N and contact.contact_force",
                l.max_force, self.f_r
            ));
        }
        for (n, v) in [
            ("contact.approach_speed", c.approach_speed),
            ("contact.reacquire_speed", c.reacquire_speed),
            (
                "the force limit's retract speed",
                super::contact::RETRACT_SPEED,
            ),
        ] {
            if v > l.max_velocity {
                return Err(format!(
                    "{n} {v} m/s is above limits.max_velocity {} m/s",
                    l.max_velocity
                ));
            }
        }
        Ok(())
    }

    /// Position scale of the estimator's regressor: the penetration the set-point needs at `k̂_c(0)`, m.
    pub(super) fn scale(&self) -> f64 {
        self.f_r.max(1.0) / self.estimator.kc0
    }
}
