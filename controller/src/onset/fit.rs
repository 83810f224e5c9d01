//! The window's fits: the free line (with damping where it is determined), the line through a
//! known surface, and the known spring on a surface moving at a constant speed.

use super::sums::{COLLINEAR, MIN_SAMPLES, SFF, SUF, Sums};

/// Degrees of freedom a plane fit `f = a + b·u + c·w` uses: three parameters.
const PLANE_DOF: f64 = 3.0;
use super::{LineFit, Moving, OnsetFit};

impl OnsetFit {
    /// The fit so far, with residual variance at least `noise_var` (N²); `None` while undetermined.
    pub fn fit(&self, noise_var: f64) -> Option<LineFit> {
        let s = &self.sums;
        if s.n < MIN_SAMPLES || s.centred()[SUF] <= 0.0 {
            return None;
        }
        let m = s.solve()?;
        if m.b <= 0.0 {
            return None;
        }
        let (ub, wb) = (s.u / s.n, s.w / s.n);
        let a = s.f / s.n - m.b * ub - m.c * wb;
        let dof = if m.c > 0.0 { PLANE_DOF } else { 2.0 };
        let residual_var = m.sse / (s.n - dof);
        let var = residual_var.max(noise_var);
        let var_b = var * m.i_uu;
        // a = f̄ − b·ū − c·w̄: its variance from the centred inverse and the mean's own.
        let var_a =
            var / s.n + var * (ub * ub * m.i_uu + 2.0 * ub * wb * m.i_uw + wb * wb * m.i_ww);
        let fit = LineFit {
            a,
            b: m.b,
            var_a,
            var_b,
            cov_ab: -var * (ub * m.i_uu + wb * m.i_uw),
            c: m.c,
            c_unit_var: m.i_ww,
            residual_var,
            sse: m.sse,
            force_var: s.centred()[SFF] / (s.n - 1.0),
        };
        [fit.a, fit.b, fit.var_a, fit.var_b, fit.cov_ab, fit.c]
            .iter()
            .all(|v| v.is_finite())
            .then_some(fit)
    }

    /// The fit through the surface `x_c` (m) left where it was: `f = b·(x − x_c)/s + c·w`, no
    /// intercept of its own (a change of stiffness alone pivots the spring line about the surface). The
    /// intercept at `x₀` follows the slope; variances from the residuals, at least `noise_var` (N²).
    /// With it, the slope variance the surface's own uncertainty adds per m² of its variance, to first
    /// order, N²/m².
    pub fn fit_through(&self, x_c: f64, noise_var: f64) -> Option<(LineFit, f64)> {
        let s = &self.sums;
        let d = (self.x0 - x_c) / self.scale;
        if s.n < MIN_SAMPLES || !d.is_finite() {
            return None;
        }
        // Moments about the pivot, u_p = u + d, uncentred.
        let pp = s.uu + 2.0 * d * s.u + s.n * d * d;
        let pw = s.uw + d * s.w;
        let pf = s.uf + d * s.f;
        let (ww, wf, ff) = (s.ww, s.wf, s.ff);
        if pp <= 0.0 {
            return None;
        }
        let det = pp * ww - pw * pw;
        let (mut b, mut c, mut i_pp, mut i_cc) = (pf / pp, 0.0, 1.0 / pp, 0.0);
        let mut sse = ff - pf * pf / pp;
        if det > COLLINEAR * pp * ww {
            let (bb, cc) = ((ww * pf - pw * wf) / det, (pp * wf - pw * pf) / det);
            if cc >= 0.0 {
                (b, c, i_pp, i_cc) = (bb, cc, ww / det, pp / det);
                sse = ff - b * pf - c * wf;
            }
        }
        let sse = sse.max(0.0);
        let dof = if c > 0.0 { 2.0 } else { 1.0 };
        let residual_var = sse / (s.n - dof);
        // ∂b/∂d = −b·Σu_p/Σu_p² for samples on the line.
        let db = b * (s.u + s.n * d) / pp;
        let var_b = residual_var.max(noise_var) * i_pp;
        let per_surface_var = db * db / (self.scale * self.scale);
        let fit = LineFit {
            a: b * d,
            b,
            var_a: d * d * var_b,
            var_b,
            cov_ab: d * var_b,
            c,
            c_unit_var: i_cc,
            residual_var,
            sse,
            force_var: s.centred()[SFF] / (s.n - 1.0),
        };
        (b > 0.0
            && [fit.a, fit.b, fit.var_b, fit.c]
                .iter()
                .all(|v| v.is_finite()))
        .then_some((fit, per_surface_var))
    }

    /// Fit the window's samples from now on also as the known spring on a surface moving at a
    /// constant speed: `f = b·u + c_e·v + a − r·t`, with the slope `b` (N per unit of `u`) and the
    /// damping `c_e` (N·s/m) known, only the surface's start and speed free — the alternative to a
    /// changed stiffness when the force leaves its band on a surface that may have started to move
    /// (see [`moving_sse`](Self::moving_sse)). The damping is not fitted again: a loop settling
    /// exponentially moves the tool along its own velocity, and a free damping would fit a changed
    /// stiffness as well. A surface slower than `slowest` (m/s) is no moving surface: with the tool
    /// advancing steadily through the window, time and position are nearly collinear, and a crawl of
    /// the surface tilts the known spring's line into almost any slope — under noise it explained a
    /// halving on the 12 ms cell better than the halving did, at 0.09 mm/s (f_r 4.8 N, 74.6 kN/m,
    /// σ 0.47 N: `k̂_c` kept, 89 % off).
    pub fn also_moving(&mut self, b: f64, c_e: f64, slowest: f64) {
        self.moving = Some(Moving {
            b,
            c_e,
            slowest,
            sums: Sums::default(),
            t: 0.0,
        });
    }

    /// The residual sum of squares of that fit, N² (`None` unless asked for, undetermined, or the
    /// surface's speed it fits is below the slowest motion).
    pub fn moving_sse(&self) -> Option<f64> {
        let m = self.moving?;
        let fit = m.sums.solve()?;
        // The fit's time slope over the spring's stiffness (N/m) is the surface's speed.
        let speed = fit.b / (m.b / self.scale);
        (speed.abs() >= m.slowest).then_some(fit.sse)
    }
}
