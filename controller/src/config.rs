//! Tunings: which law, with which parameters, and the loop's limits — the part of a cell configuration
//! that belongs to the controller. Deserialised from TOML (`tunings/*.toml`, or a user's file).

use serde::{Deserialize, Serialize};

use crate::control_loop::LoopConfig;
use crate::law::{AdaptiveParams, AlongNormal, ForceLaw, ImpedanceLaw, ImpedanceParams, Reference};
use crate::orientation::{OrientationParams, Oriented};
use crate::robust::{RobustLaw, RobustParams};

/// Which law runs, with its parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum LawConfig {
    /// The paper's adaptive impedance law, exactly (eqs. 8 and 23).
    Paper {
        /// Impedance filter.
        impedance: ImpedanceParams,
        /// Estimator gains and initial estimates.
        adaptive: AdaptiveParams,
    },
    /// The impedance filter with a fixed reference `x_r` (no estimation).
    Impedance {
        /// Impedance filter.
        impedance: ImpedanceParams,
        /// Reference position, m. Scenarios usually set it.
        #[serde(default)]
        x_r: f64,
    },
    /// forcecell's robust law (`controller::robust`): estimator, observer, state machine, limits.
    Robust(Box<RobustParams>),
}

/// A named tuning: a law and the loop's limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tuning {
    /// Short name (`paper`, `robust`, …).
    pub name: String,
    /// One line for humans.
    #[serde(default)]
    pub description: String,
    /// The law.
    pub law: LawConfig,
    /// Limits of the loop.
    #[serde(default, rename = "loop")]
    pub loop_cfg: LoopConfig,
    /// Orientation following on curved parts (`docs/curved-parts.md`); absent: off, the law acts
    /// along the tool normal only.
    #[serde(default)]
    pub orientation: Option<OrientationParams>,
}

/// The law a tuning runs over a cell: the 1-DOF law along the tool normal, with orientation
/// following around it where the tuning turns it on.
pub type TunedLaw = Oriented<AlongNormal<Box<dyn ForceLaw + Send>>>;

impl Tuning {
    /// The loop's configuration, with the process's force limit and set-point rate taken from the
    /// law where it has them (never above what the tuning's `[loop.process]` says): a ramp the
    /// program asks for never outruns the law's own set-point rate, and a PRESS never asks for a
    /// force at or above the law's limit.
    pub fn loop_config(&self) -> LoopConfig {
        let mut c = self.loop_cfg;
        if let LawConfig::Robust(p) = &self.law {
            c.process.max_force = c.process.max_force.min(p.limits.max_force);
            c.process.default_rate = c.process.default_rate.min(p.response.set_point_rate);
        }
        c
    }
}

/// Values a scenario may override in any tuning.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Overrides {
    /// Force set-point, N.
    pub f_r: Option<f64>,
    /// Fixed reference of the `impedance` law, m.
    pub x_r: Option<f64>,
}

impl LawConfig {
    /// The impedance filter's parameters, for the laws that have one (the robust law has none).
    pub fn impedance(&self) -> Option<&ImpedanceParams> {
        match self {
            Self::Paper { impedance, .. } | Self::Impedance { impedance, .. } => Some(impedance),
            Self::Robust(_) => None,
        }
    }

    /// The force set-point, N.
    pub fn set_point(&self) -> f64 {
        match self {
            Self::Paper { impedance, .. } | Self::Impedance { impedance, .. } => impedance.f_r,
            Self::Robust(p) => p.f_r,
        }
    }

    /// Apply scenario overrides.
    pub fn apply(&mut self, o: &Overrides) {
        match self {
            Self::Paper { impedance, .. } => {
                if let Some(f) = o.f_r {
                    impedance.f_r = f;
                }
            }
            Self::Impedance { impedance, x_r } => {
                if let Some(f) = o.f_r {
                    impedance.f_r = f;
                }
                if let Some(x) = o.x_r {
                    *x_r = x;
                }
            }
            // The robust law has no fixed reference: `x_r` does not apply to it.
            Self::Robust(p) => {
                if let Some(f) = o.f_r {
                    p.f_r = f;
                }
            }
        }
    }

    /// Give a robust law the cell's inner-loop model (the other laws have none).
    pub fn set_cell(&mut self, cell: crate::robust::CellParams) {
        if let Self::Robust(p) = self {
            p.cell = cell;
        }
    }

    /// Build the law, validating every parameter.
    pub fn build(&self) -> Result<Box<dyn ForceLaw + Send>, String> {
        Ok(match *self {
            Self::Paper {
                impedance,
                adaptive,
            } => Box::new(ImpedanceLaw::new(
                impedance,
                Reference::PaperAdaptive(adaptive),
            )?),
            Self::Impedance { impedance, x_r } => {
                Box::new(ImpedanceLaw::new(impedance, Reference::Fixed { x_r })?)
            }
            Self::Robust(ref p) => Box::new(RobustLaw::new(**p)?),
        })
    }
}

impl Tuning {
    /// The law this tuning runs over a cell (built and validated), with the loop's force sign.
    pub fn cell_law(&self) -> Result<TunedLaw, String> {
        if let Some(o) = &self.orientation {
            o.validate()?;
        }
        let law = self.law.build()?;
        let sign = self.loop_cfg.force_sign;
        Ok(Oriented::new(
            AlongNormal::new(law, sign),
            self.orientation,
            sign,
        ))
    }

    /// Validate the law's parameters and the loop's limits.
    pub fn validate(&self) -> Result<(), String> {
        self.loop_cfg.validate()?;
        if let Some(o) = &self.orientation {
            o.validate()?;
        }
        self.law.build().map(|_| ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_tuning_parses_from_toml() {
        let t: Tuning = toml::from_str(
            r#"
            name = "paper"
            [law]
            kind = "paper"
            impedance = { f_r = 5.0, m_d = 8.0, b_d = 80.0, k_d = 50000.0 }
            adaptive = { r1 = 5.0, r2 = 10.0, kc0 = 50000.0, xc0 = 0.009 }
            "#,
        )
        .unwrap();
        assert_eq!(
            t.law,
            LawConfig::Paper {
                impedance: ImpedanceParams::PAPER,
                adaptive: AdaptiveParams::PAPER
            }
        );
        assert_eq!(t.loop_cfg, LoopConfig::default());
        t.validate().unwrap();
    }

    #[test]
    fn unknown_fields_and_bad_values_are_refused() {
        let e = toml::from_str::<Tuning>(
            r#"
            name = "x"
            [law]
            kind = "paper"
            impedance = { f_r = 5.0, m_d = 8.0, b_d = 80.0, k_d = 50000.0, typo = 1 }
            adaptive = { r1 = 5.0, r2 = 10.0, kc0 = 50000.0, xc0 = 0.009 }
            "#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("typo"), "{e}");
        let mut t = Tuning {
            name: "x".into(),
            description: String::new(),
            law: LawConfig::Impedance {
                impedance: ImpedanceParams::PAPER,
                x_r: 0.0,
            },
            loop_cfg: LoopConfig::default(),
            orientation: None,
        };
        t.law.apply(&Overrides {
            f_r: Some(-1.0),
            x_r: None,
        });
        assert!(t.validate().unwrap_err().contains("f_r"));
    }
}
