//! Whether the force has shown a declared contact: the evidence a touch-down's landing waits for, and
//! without which its loss is no contact.

use super::{SIGNIFICANCE, Thresholds};

/// What the force has shown since a contact was declared.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Evidence {
    /// How long the conditioned force has shown contact without a break, s.
    touched: f64,
    /// The force has shown the contact.
    shown: bool,
    /// The raw force summed over the samples, N, and their number.
    sum_f: f64,
    n_f: u32,
}

impl Evidence {
    /// A contact declared: nothing shown yet.
    pub(super) fn reset(&mut self) {
        *self = Self::default();
    }

    /// Whether the force has shown the contact.
    pub(super) fn shown(&self) -> bool {
        self.shown
    }

    /// A raw force sample `f` (N) in contact: the contact shows in the raw mean since it was declared
    /// once that mean has two samples or more and stands above the lift force and [`SIGNIFICANCE`]
    /// standard errors of the raw noise. At a small set-point under noise the conditioned force's
    /// threshold (`SIGNIFICANCE` of its deviations) can lie beyond the set-point itself (f_r 2 N under
    /// σ 1 N on the 12 ms cell): a held contact shows in the mean within a few samples, a contact
    /// declared on a noise spike in free air does not.
    pub(super) fn raw(&mut self, f: f64, th: &Thresholds) {
        if self.shown || !f.is_finite() {
            return;
        }
        self.sum_f += f;
        self.n_f += 1;
        let n = f64::from(self.n_f);
        self.shown =
            self.n_f >= 2 && self.sum_f / n >= th.lift.max(SIGNIFICANCE * th.noise / n.sqrt());
    }

    /// The conditioned force `ff` (N) for a step of `dt` (s): the contact shows once it has stayed
    /// above the contact threshold for `confirm` s without a break (as long as a step takes to pass
    /// the conditioning), or reached the strong threshold no noise spike reaches. Returns whether it
    /// is above the contact threshold now.
    pub(super) fn conditioned(&mut self, ff: f64, th: &Thresholds, confirm: f64, dt: f64) -> bool {
        let touching = ff >= th.contact;
        self.touched = if touching { self.touched + dt } else { 0.0 };
        self.shown |= self.touched >= confirm || ff >= th.strong;
        touching
    }
}
