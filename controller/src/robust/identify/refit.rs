//! The re-fit after a jump in a steady contact on a still surface: its choice of model, and its
//! judgement.
//!
//! A stiffness change leaves the surface where it was: the new spring line goes through it, and a fit
//! through that pivot has one unknown less than a free line — under sensor noise it is many times
//! more precise, as every sample's distance from the surface carries the slope, not only the
//! transient's spread. A surface step moves the pivot: the line through the old surface then leaves
//! significantly more residual than the free line, and the free line is taken.
//!
//! The fit is judged by its own consistency (the stale `k̂_c` makes the still surface look moving
//! meanwhile): once the loop has answered the jump, every step until it is conclusive, and at the
//! window's end for the last time. Waiting out the window with a stale `k̂_c` costs the contact on a
//! soft surface at a small set-point (a doubled stiffness under the stale gain rings).

use super::Identifier;
use crate::onset::{LineFit, OnsetFit};

/// The fit of the window in `onset`: through the surface `pivot` (m) unless that costs more than
/// `gate` standard deviations of residual over the free line's; none when the free line's slope is not
/// `gate` deviations above zero. `noise_var` (N²) the measured noise, `r` (N²) the same with its floor.
pub(super) fn choose(
    onset: &OnsetFit,
    pivot: f64,
    noise_var: f64,
    r: f64,
    gate: f64,
) -> Option<LineFit> {
    let free = onset.fit(noise_var);
    let through = if pivot.is_finite() {
        onset.fit_through(pivot, noise_var)
    } else {
        None
    };
    // Without a spring transient of its own (the free slope within `gate` deviations of none: noise
    // in a hold) the window says nothing the pivot did not.
    let free = free.filter(|f| f.b > gate * f.var_b.sqrt())?;
    match through {
        Some(through) if through.sse - free.sse <= gate * gate * free.residual_var.max(r) => {
            Some(through)
        }
        _ => Some(free),
    }
}

impl Identifier {
    /// The re-fit's fit if it is conclusive now: significant, different from `k̂_c`, and one still
    /// spring — what the plane leaves beyond the noise is at most `steady_confidence` of the
    /// transient's variance (a surface that started to move leaves the force unexplained by the
    /// position). The re-fit ends when taken or at the window's end.
    pub(super) fn judge_refit(&mut self, noise_var: f64, noise_floor: f64) -> Option<LineFit> {
        let (x0, f0, pivot) = self.refit_from?;
        let open = self.onset.active();
        if open && self.refit_age < self.refit_early {
            return None;
        }
        let (scale, rel) = (self.est.scale(), self.p.steady_confidence);
        // Early, only a fit as precise as a learnt one (`steady_done`): what the rest of the window
        // would add is then not worth the wait.
        let precision = if open { self.p.steady_done } else { rel };
        let r = noise_var.max(noise_floor * noise_floor);
        let fit = choose(&self.onset, pivot, noise_var, r, self.p.pivot_gate).filter(|fit| {
            fit.b > 0.0
                && fit.var_b.sqrt() <= precision * fit.b
                && (fit.b / scale - self.est.kc()).abs() > rel * self.est.kc()
                && fit.residual_var - r <= rel * fit.force_var
        });
        if fit.is_some() || !open {
            self.refit_from = None;
            self.onset.stop();
        }
        if fit.is_some() {
            self.est.begin_contact(x0, f0);
        }
        fit
    }
}
