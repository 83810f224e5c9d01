//! Identification's parameters, and what the law tells it of each contact step.

use serde::{Deserialize, Serialize};

use super::super::{at_least, non_negative, positive};
use crate::onset::MAX_MEMORY;

/// Identification's advanced parameters (the defaults suit any cell).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IdentifyParams {
    /// How long the onset fit remembers of the approach before contact is declared, s: the force's
    /// rise the conditioning delays the detection by, and the free air before it (at most
    /// [`MAX_MEMORY`]; a cycle faster than [`FASTEST_CYCLE`](crate::onset::FASTEST_CYCLE) remembers less).
    pub approach_memory: f64,
    /// How long after contact is declared the contact transient is fitted, s.
    pub onset_window: f64,
    /// How long after `onset_window` the onset fit may wait for more samples while its slope is not
    /// significant yet, s (a small set-point on a soft surface under noise; 0: never).
    pub onset_patience: f64,
    /// How long the transient after a jump in a steady contact on a still surface (a stiffness
    /// change, a surface step) is fitted to re-identify `k̂_c`, s.
    pub refit_window: f64,
    /// Largest factor by which a re-fit may move `k̂_c`, widened by three of `k̂_c`'s relative
    /// deviations: a fit further off is not taken. A surface moving slowly under a steady contact
    /// (below `max_surface_speed`) looks to a re-fit like a stiffness change of any size — with the tool
    /// following it, the samples lie on a line of slope `k_c·(1 − v_surface/v_tool)` through the
    /// surface before — and a `k̂_c` three times too low fed the surface predictor a motion that ran
    /// the command away (268 N at f_r 20 N on 500 kN/m, `moving_surfaces`). The changes the law is
    /// built for are ×0.5 to ×2.
    pub max_refit_change: f64,
    /// Significance, in standard deviations of the residual, at which a re-fit's line through the
    /// surface before the jump (a stiffness change alone) gives way to a free line (the surface moved),
    /// that a fitted slope must have to be taken (onset and re-fit: a fit of noise is not), and that a
    /// fit's surface damping needs to be taken.
    pub pivot_gate: f64,
    /// Forgetting time of the steady-contact estimator, s.
    pub steady_memory: f64,
    /// How long the steady-contact estimator must have run before it is used, s.
    pub steady_min_age: f64,
    /// Relative standard deviation below which the steady-contact estimate is used.
    pub steady_confidence: f64,
    /// Relative standard deviation at which the steady-contact estimator stops learning.
    pub steady_done: f64,
    /// Largest relative rate at which the steady-contact estimate moves `k̂_c`, 1/s.
    pub steady_rate: f64,
}

impl Default for IdentifyParams {
    fn default() -> Self {
        Self {
            approach_memory: 0.2,
            onset_window: 0.1,
            onset_patience: 0.5,
            refit_window: 0.3,
            max_refit_change: 2.5,
            pivot_gate: 3.0,
            steady_memory: 3600.0,
            steady_min_age: 1.0,
            steady_confidence: 0.1,
            steady_done: 0.02,
            steady_rate: 0.02,
        }
    }
}

impl IdentifyParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("identify.approach_memory", self.approach_memory)?;
        if self.approach_memory > MAX_MEMORY {
            return Err(format!(
                "identify.approach_memory {} s is more than the {MAX_MEMORY} s remembered at most",
                self.approach_memory
            ));
        }
        positive("identify.onset_window", self.onset_window)?;
        non_negative("identify.onset_patience", self.onset_patience)?;
        positive("identify.refit_window", self.refit_window)?;
        at_least("identify.max_refit_change", self.max_refit_change, 1.0)?;
        positive("identify.pivot_gate", self.pivot_gate)?;
        positive("identify.steady_memory", self.steady_memory)?;
        positive("identify.steady_min_age", self.steady_min_age)?;
        positive("identify.steady_confidence", self.steady_confidence)?;
        positive("identify.steady_done", self.steady_done)?;
        positive("identify.steady_rate", self.steady_rate)?;
        if self.steady_done > self.steady_confidence {
            return Err(format!(
                "identify.steady_done {} must not be above identify.steady_confidence {}",
                self.steady_done, self.steady_confidence
            ));
        }
        Ok(())
    }
}

/// What the law knows of a contact step besides its sample (see
/// [`Identifier::in_contact`](super::Identifier::in_contact)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepState {
    /// The surface moves: no stiffness to learn (a re-fit is judged by its own consistency instead,
    /// as the apparent motion of the stale `k̂_c` makes it look moving).
    pub moving: bool,
    /// The observed surface went further than a still one can appear to: the recursion waits, the
    /// rest goes on (the touch-down's fit before it has `k̂_c` sees the surface move by the whole
    /// force over the tuning's guess).
    pub drifted: bool,
    /// Contact was declared this step.
    pub first: bool,
    /// The raw force is below the lift force: off the surface, not yet a lift-off.
    pub lifted: bool,
    /// Something moved or jumped lately.
    pub disturbed: bool,
    /// The raw force left its band in a calm contact this step (beyond what its noise reaches): a
    /// jump's first sample, which the conditioned force the band test reads shows only later.
    pub jumped: bool,
    /// The force comes through a sensor's own filter (`[law.cell] sensor_delay` above zero): a
    /// spring's window fits a line only to the filter's shape, not to the noise.
    pub filtered: bool,
}
