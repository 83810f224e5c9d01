//! The re-fit's choice of model after a jump in a steady contact on a still surface.
//!
//! A stiffness change leaves the surface where it was: the new spring line goes through it, and a fit
//! through that pivot has one unknown less than a free line — under sensor noise it is many times
//! more precise, as every sample's distance from the surface carries the slope, not only the
//! transient's spread. A surface step moves the pivot: the line through the old surface then leaves
//! significantly more residual than the free line, and the free line is taken.

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
