//! A contact's start: the approach's samples kept, the onset fit at a touch-down, and its patience
//! under noise.
//!
//! The fit sets `k̂_c` once its slope is significant. On a soft surface at a small set-point under
//! sensor noise the window's samples may not make it significant in `onset_window` (f_r 2 N on
//! 10 kN/m under σ 1 N: the whole rise is 0.2 mm, and the slope's deviation is `σ/√Σ(x − x̄)²`):
//! the window then stays open, one step at a time, for at most `onset_patience` more while the
//! contact holds on a still surface, instead of leaving `k̂_c` at the tuning's guess (five times
//! too stiff there: a loop five times too slow, whose integral cannot remove its error in seconds).
//! Once the fit is significant the window closes on the next step.

use super::Identifier;
use crate::onset::{LineFit, OnsetFit};

impl Identifier {
    /// Contact is declared (`begin_contact`); on a re-contact the search that
    /// ended in it is judged (`recontact`). Returns `k̂_c` as the touch-down left
    /// it, before that judgement (where the observers restart).
    pub fn touch_down(&mut self, t: &TouchDown<'_>) -> f64 {
        self.begin_contact(t.x, t.f, t.from_approach);
        let kc = self.kc();
        if !t.from_approach {
            self.recontact(t.x, t.f, t.search, t.f_r, t.max_surface_speed, t.hold);
        }
        kc
    }

    /// Contact is lost (`lost`); `back_to_approach`: the touch-down is taken back and
    /// what it identified forgotten (`forget_touch_down`).
    pub fn lift_off(&mut self, back_to_approach: bool) {
        self.lost();
        if back_to_approach {
            self.forget_touch_down();
        }
    }

    /// Keep a raw sample `(x, f)` of the approach, at velocity `v` (m/s), for the onset fit: the last
    /// `approach_memory` at control cycle `cycle` (s).
    pub fn remember(&mut self, x: f64, f: f64, v: f64, cycle: f64) {
        let keep = OnsetFit::samples(self.p.approach_memory, cycle);
        self.onset.remember(x, f, v, keep);
    }

    /// Contact is declared at `(x, f)`; `from_approach`: on a still surface, so the transient is fitted.
    pub(super) fn begin_contact(&mut self, x: f64, f: f64, from_approach: bool) {
        self.before_touch_down = from_approach.then(|| (self.est.clone(), self.c_e));
        self.est.begin_contact(x, f);
        self.onset_seeded = false;
        self.onset_age = 0.0;
        if from_approach {
            // A touch-down ends the wait after a moved surface (it runs on through a bounce).
            self.recontact_hold = 0.0;
            self.onset.begin(x, self.est.scale(), self.p.onset_window);
        } else {
            self.onset.clear();
            self.keep_confidence();
        }
        self.steady.stop();
        self.steady_var0 = f64::INFINITY;
    }

    /// The touch-down was no contact (declared on noise, taken back): what it identified is forgotten,
    /// the estimate is the one before it (a fit of the noise a contact was declared on is no
    /// stiffness: f_r 5 N on 50 kN/m on the 12 ms cell under σ 1 N kept 10 kN/m from one, and the
    /// next touch-down, its fit not significant, rang with it).
    pub(super) fn forget_touch_down(&mut self) {
        if let Some((est, c_e)) = self.before_touch_down.take() {
            self.est = est;
            self.c_e = c_e;
        }
        self.onset.clear();
        self.refit = None;
        self.steady.stop();
        self.steady_var0 = f64::INFINITY;
    }

    /// The onset fit after a step of `dt` in the window, if its slope is significant (`pivot_gate`
    /// deviations above zero; a contact declared on noise has no force rising with the position).
    pub(super) fn onset_fit(&mut self, noise_var: f64, dt: f64) -> Option<LineFit> {
        let gate = self.p.pivot_gate;
        let fit = self
            .onset
            .fit(noise_var)
            .filter(|f| f.b > gate * f.var_b.sqrt());
        if fit.is_some() {
            self.onset_seeded = true;
        } else if !self.onset_seeded
            && !self.onset.active()
            && self.onset_age < self.p.onset_window + self.p.onset_patience
        {
            self.onset.extend(dt);
        }
        fit
    }
}

/// A declared contact ([`Identifier::touch_down`]).
#[derive(Clone, Copy, Debug)]
pub struct TouchDown<'a> {
    /// The raw position, m.
    pub x: f64,
    /// The raw force, N.
    pub f: f64,
    /// From the approach (a still surface: the transient is fitted), or a re-contact.
    pub from_approach: bool,
    /// The search that ended in a re-contact.
    pub search: &'a crate::robust::contact::Search,
    /// The set-point, N.
    pub f_r: f64,
    /// The fastest surface the law follows, m/s.
    pub max_surface_speed: f64,
    /// How long the recursion waits after a surface found moved, s.
    pub hold: f64,
}
