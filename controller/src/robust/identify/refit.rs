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
//!
//! A surface that started to move slowly (below `max_surface_speed`) opens a re-fit too, and with the
//! tool following it the window's samples lie on a consistent line of `k_c·(1 − v_surface/v_tool)`
//! (0.63 mm/s on 200 kN/m at 20 N on P2: 88 kN/m through the surface before; the predictor then ran
//! the command into a 172 N trip). So the window is fitted as that too: the stale stiffness and
//! identified damping on a surface moving at a constant speed ([`OnsetFit::also_moving`]). A change
//! is taken only where it explains the window better than that. A loop's answer to a real change is
//! no constant speed: the moving fit leaves its curvature as residual. Under noise the two can explain
//! a window almost alike, and the better one is taken: with a margin of `pivot_gate`² noise variances
//! in the stale stiffness's favour, a damped halving at f_r 2 N on the 12 ms cell under σ 0.26 N (the
//! change better by 3.6 variances) kept the stale `k̂_c`, 98 % off. A surface slower than the slowest
//! motion the law acts on (`observer.feedforward_speed`) is no moving surface: with the tool advancing
//! steadily, a crawl tilts the stale line into almost any slope (f_r 3.9 N on the 12 ms cell under σ
//! 0.42 N: a halving explained by 0.07 mm/s, 53 % off; now 12 %).

use super::Identifier;
use crate::onset::{LineFit, OnsetFit};
use crate::robust::contact::SIGNIFICANCE;

/// Relative standard deviations of `k̂_c` by which `max_refit_change` widens: the largest change a
/// re-fit may make is `max_refit_change·(1 + 3·σ_rel)`, three deviations covering what an unsure
/// `k̂_c` may really be off by.
const TRUST_DEVIATIONS: f64 = 3.0;

/// A re-fit while it runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Refit {
    /// Where the transient started, m.
    pub x0: f64,
    /// The force there, N.
    pub f0: f64,
    /// The surface before the jump, m: the pivot of a stiffness change.
    pub pivot: f64,
    /// That surface's variance, m².
    pub pivot_var: f64,
    /// How long the re-fit must run before it may be taken early, s (its age is the window's).
    pub early: f64,
    /// A fit was taken early (see [`Identifier::judge_refit`]): the window runs on and its end
    /// refines it.
    pub refine: bool,
}

/// The fit of the window in `onset`: through the surface `pivot` (m, known to variance `pivot_var`,
/// m²) unless that costs more than `gate` standard deviations of residual over the free line's or the
/// surface's uncertainty makes it less precise than the free line; none when the free line's slope is
/// neither `gate` deviations above zero nor `gate` deviations from the stale slope `stale` (N per
/// unit of `u`). `noise_var` (N²) the measured noise, `r` (N²) the same with its floor.
pub(super) fn choose(
    onset: &OnsetFit,
    pivot: f64,
    pivot_var: f64,
    noise_var: f64,
    r: f64,
    gate: f64,
    stale: f64,
) -> Option<LineFit> {
    let free = onset.fit(noise_var);
    let through = if pivot.is_finite() {
        onset.fit_through(pivot, noise_var)
    } else {
        None
    };
    // What the surface's uncertainty costs the line through it in slope variance (the line keeps its
    // own: a surface known from a fit that is itself in doubt only weighs the choice). A `k̂_c` never
    // fitted has no measured uncertainty, and weighs nothing.
    let pivot_cost = through
        .map(|(_, per)| per * pivot_var)
        .filter(|c| c.is_finite())
        .unwrap_or(0.0);
    let through = through.map(|(t, _)| t);
    // Without a spring transient of its own (the free slope within `gate` deviations of none: noise
    // in a hold) the window says nothing the pivot did not — unless it rejects the stale slope (a
    // damped halving at f_r 2.5 N on P2 under σ 0.47 N: free 28 ± 11 kN/m against a stale 94; kept,
    // `k̂_c` ended 139 % off).
    let free = free.filter(|f| {
        let sd = f.var_b.sqrt();
        f.b > gate * sd || (f.b > 0.0 && (f.b - stale).abs() > gate * sd)
    })?;
    match through {
        Some(through)
            if through.sse - free.sse <= gate * gate * free.residual_var.max(r)
                && pivot_cost <= free.var_b =>
        {
            Some(through)
        }
        _ => Some(free),
    }
}

/// The surface damping of `fit` (in its scaled units) where the fit determines it: `gate` deviations
/// of the residual variance `r` (N²) from none; else none.
pub(super) fn damping(fit: &LineFit, r: f64, gate: f64) -> f64 {
    if fit.c * fit.c > gate * gate * r * fit.c_unit_var {
        fit.c
    } else {
        0.0
    }
}

impl Identifier {
    /// The force jumped in a steady contact on a still surface at `(x, f)`: the environment changed
    /// (a stiffness change, a surface step). Fit the transient that follows, as at a contact onset: the
    /// samples lie on the new spring line whatever moved. The recursion restarts there, agile. The fit
    /// may be taken before the window's end once `early` s have passed (the loop's answer to the jump)
    /// and it is conclusive. `slowest`: the slowest surface speed the law counts as motion, m/s (the
    /// moving surface the window is also fitted as is no slower).
    pub(super) fn refit(&mut self, x: f64, f: f64, early: f64, slowest: f64) {
        self.onset.clear();
        self.onset.begin(x, self.est.scale(), self.p.refit_window);
        self.onset
            .also_moving(self.est.kc() * self.est.scale(), self.c_e, slowest);
        self.onset_age = 0.0;
        self.refit = Some(Refit {
            x0: x,
            f0: f,
            pivot: self.calm_surface,
            pivot_var: self.pivot_variance(x),
            early,
            refine: false,
        });
        self.steady.stop();
        self.steady_var0 = f64::INFINITY;
    }

    /// The re-fit's fit if it is conclusive now: significant, different from `k̂_c`, and one still
    /// spring — what the plane leaves beyond the noise is at most `steady_confidence` of the
    /// transient's variance (a surface that started to move leaves the force unexplained by the
    /// position), and, unless the force comes through a sensor's own filter (`filtered`: a line
    /// misses a filtered transient by the filter's shape), no more than `SIGNIFICANCE²` noise
    /// variances (of 5997 changes the range census takes, none left 2.4; a sine's start on 100 kN/m
    /// on the 12 ms cell, the tool chasing a surface that slowed down, 5500 — fitted as 44 kN/m).
    /// The re-fit ends at the window's end; `(x, f)` is the raw sample now (m, N).
    pub(super) fn judge_refit(
        &mut self,
        x: f64,
        f: f64,
        noise_var: f64,
        noise_floor: f64,
        filtered: bool,
    ) -> Option<LineFit> {
        let mut refit = self.refit?;
        let open = self.onset.active();
        if open && (self.onset_age < refit.early || refit.refine) {
            return None;
        }
        let (scale, rel) = (self.est.scale(), self.p.steady_confidence);
        // Early, a fit as precise as a learnt one (`steady_done`), or one within `steady_confidence`
        // that puts the stale `k̂_c` more than `pivot_gate` of its deviations off: the stale gain
        // rings meanwhile (a doubling at a small set-point), and the fit is the better estimate by
        // far. Taken early, the window runs on, the recursion waiting (fed the transient's tail it
        // wanders from a fit ten times more precise), and its end refines the fit.
        let precision = if open { self.p.steady_done } else { rel };
        let (gate, stale) = (self.p.pivot_gate, self.est.kc() * scale);
        let r = noise_var.max(noise_floor * noise_floor);
        let (pivot, pivot_var) = (refit.pivot, refit.pivot_var);
        // A change beyond `max_refit_change` (widened by what `k̂_c` is unsure of) is no stiffness
        // change the law believes: a surface moving slowly fits such a line too.
        let trust = self.p.max_refit_change * (1.0 + TRUST_DEVIATIONS * self.kc_rel_sd());
        // The stale spring on a surface moving at a constant speed, the other explanation (module
        // docs): a change must explain the window better.
        let moving = self.onset.moving_sse().unwrap_or(f64::INFINITY);
        let fit = choose(&self.onset, pivot, pivot_var, noise_var, r, gate, stale).filter(|fit| {
            let sd = fit.var_b.sqrt();
            let explained = moving <= fit.sse;
            let believed = fit.b <= trust * stale && fit.b * trust >= stale && !explained;
            let conclusive = sd <= precision * fit.b
                || (open && sd <= rel * fit.b && (fit.b - stale).abs() > gate * sd);
            fit.b > 0.0
                && believed
                && conclusive
                && (refit.refine || (fit.b / scale - self.est.kc()).abs() > rel * self.est.kc())
                && fit.residual_var - r <= rel * fit.force_var
                && (filtered || fit.residual_var <= SIGNIFICANCE * SIGNIFICANCE * r)
        });
        if fit.is_some() && open {
            refit.refine = true;
            self.refit = Some(refit);
        } else if fit.is_some() || !open {
            self.refit = None;
            self.onset.stop();
        }
        if fit.is_none() && !open {
            // The window ends with `k̂_c` kept (a surface step leaves the stiffness as it was): the
            // recursion, which waited, starts again here. Its averages and its model are the
            // contact's before the jump, and a surface moved 1.8 mm read as a slope of almost none
            // (on the 12 ms cell `k̂_c` fell from 21.6 to 13.7 kN/m in one step, and the loop rang).
            self.est.begin_contact(x, f);
        }
        if fit.is_some() {
            self.est.begin_contact(refit.x0, refit.f0);
        }
        fit
    }
}

impl Identifier {
    /// Count whether the force is out of its band this step (`calm`: the contact is steady, on a
    /// still surface); true when it has just been out for `persist` s after leaving it in a calm
    /// contact (noise leaves the band for a sample, a changed environment for a transient).
    pub(super) fn excursion(&mut self, off: bool, calm: bool, persist: f64, dt: f64) -> bool {
        let before = self.off_band;
        if off && before == 0.0 {
            self.calm_at_start = calm;
        }
        self.off_band = if off { self.off_band + dt } else { 0.0 };
        self.calm_at_start && before < persist && self.off_band >= persist && !self.fitting()
    }

    /// The raw force at a jump whose re-fit has not concluded yet, N.
    pub fn unresolved_jump(&self) -> Option<f64> {
        self.refit.filter(|r| !r.refine).map(|r| r.f0)
    }

    /// The relative variance of `k̂_c`: its last fit's, or the steady-contact estimator's once used
    /// (infinite before any fit).
    pub fn kc_rel_var(&self) -> f64 {
        let theta = self.est.kc() * self.est.scale();
        let mut rel_var = self.est.seed_variance() / (theta * theta);
        if let Some((_, rel)) = self.steady.estimate()
            && self.steady.age() >= self.p.steady_min_age
        {
            rel_var = rel_var.min(rel * rel);
        }
        rel_var
    }

    /// How well `k̂_c` is known, as a relative standard deviation: [`kc_rel_var`](Self::kc_rel_var),
    /// and before any fit the estimator's initial uncertainty (`k̂_c` is then the tuning's guess).
    pub fn kc_rel_sd(&self) -> f64 {
        let start = self.est.params().initial_uncertainty;
        self.kc_rel_var().sqrt().min(start)
    }

    /// A re-acquired contact: no unknown surface, maybe a moving one. The recursion keeps the
    /// confidence `k̂_c` earned ([`kc_rel_sd`](Self::kc_rel_sd)), at least `steady_confidence`,
    /// instead of the estimator's initial uncertainty (B5b at 200 kN/m on P2: reopened, `k̂_c` went
    /// from 247 to 129 kN/m within 60 ms of a re-contact on the moving surface).
    pub(super) fn keep_confidence(&mut self) {
        let rel = self.kc_rel_sd().max(self.p.steady_confidence);
        self.est.limit_uncertainty(rel);
    }

    /// How well the surface before a jump at `x` (m) is known, m²: its distance from `x` is `f/k̂_c`,
    /// as uncertain as `k̂_c` ([`kc_rel_var`](Self::kc_rel_var)).
    pub(super) fn pivot_variance(&self, x: f64) -> f64 {
        let d = x - self.calm_surface;
        d * d * self.kc_rel_var()
    }
}
