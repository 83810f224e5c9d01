//! Identification of the contact stiffness from the first contact transient.
//!
//! The approach is the best excitation the law ever gets: the tool moves into a still surface and the
//! force rises from zero along `f = k_c·(x − x_c)`. The conditioned force that confirms contact lags the
//! raw one, so by the time contact is declared most of that rise has passed; it is kept here.
//!
//! Out of contact the raw samples `(x, f)` of the last stretch of the approach are remembered (as many
//! as the caller keeps, at most [`CAPACITY`]). When contact is declared,
//! a hinge is fitted to them: samples before the break carry no force (`f ≈ 0`), samples from it on lie
//! on a line `f = a + b·u`, `u = (x − x₀)/s`; the break is the one with the least total squared residual.
//! The samples on the line, and every sample of the window [`OnsetFit::begin`] opens, make an ordinary
//! least-squares fit of `(a, b)` whose uncertainty comes from its own residuals (or the
//! measured sensor noise, whichever is larger). A fixed-size buffer and running sums: no allocation.

/// The fastest control cycle the buffer is sized for, s (KUKA RSI at 1 kHz).
pub const FASTEST_CYCLE: f64 = 0.001;

/// Samples remembered out of contact at most: [`MAX_MEMORY`] at [`FASTEST_CYCLE`] (a faster cycle
/// remembers a shorter time). A fixed size: remembering never allocates.
pub const CAPACITY: usize = 256;

/// The longest stretch of the approach that can be remembered at [`FASTEST_CYCLE`], s.
pub const MAX_MEMORY: f64 = CAPACITY as f64 * FASTEST_CYCLE;

/// Running least-squares sums on `(u, w, f)`: `u` the scaled position, `w` the scaled velocity.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sums {
    n: f64,
    u: f64,
    w: f64,
    f: f64,
    uu: f64,
    uw: f64,
    ww: f64,
    uf: f64,
    wf: f64,
    ff: f64,
}

/// Relative determinant below which the velocity column adds nothing the position column has not
/// (a constant velocity, or one proportional to the position): the fit is then the line alone.
const COLLINEAR: f64 = 1e-6;

/// The centred normal equations' solution: slope `b` on `u`, slope `c` on `w` (0: line only), the
/// inverse's entries `(i_uu, i_uw, i_ww)`, and the residual sum of squares.
struct Solved {
    b: f64,
    c: f64,
    i_uu: f64,
    i_uw: f64,
    i_ww: f64,
    sse: f64,
}

impl Sums {
    fn add(&mut self, u: f64, w: f64, f: f64) {
        self.n += 1.0;
        self.u += u;
        self.w += w;
        self.f += f;
        self.uu += u * u;
        self.uw += u * w;
        self.ww += w * w;
        self.uf += u * f;
        self.wf += w * f;
        self.ff += f * f;
    }

    /// Centred second moments `[Suu, Suw, Sww, Suf, Swf, Sff]`.
    fn centred(&self) -> [f64; 6] {
        let n = self.n.max(1.0);
        [
            self.uu - self.u * self.u / n,
            self.uw - self.u * self.w / n,
            self.ww - self.w * self.w / n,
            self.uf - self.u * self.f / n,
            self.wf - self.w * self.f / n,
            self.ff - self.f * self.f / n,
        ]
    }

    /// The least-squares plane `f = a + b·u + c·w` (the line `c = 0` when the velocity adds nothing
    /// or asks for a negative damping, which no surface has); `None` when undetermined.
    fn solve(&self) -> Option<Solved> {
        let [suu, suw, sww, suf, swf, sff] = self.centred();
        if self.n < 2.0 || suu <= 0.0 {
            return None;
        }
        let line = Solved {
            b: suf / suu,
            c: 0.0,
            i_uu: 1.0 / suu,
            i_uw: 0.0,
            i_ww: 0.0,
            sse: (sff - suf * suf / suu).max(0.0),
        };
        let det = suu * sww - suw * suw;
        if self.n < 4.0 || det <= COLLINEAR * suu * sww {
            return Some(line);
        }
        let (i_uu, i_uw, i_ww) = (sww / det, -suw / det, suu / det);
        let b = i_uu * suf + i_uw * swf;
        let c = i_uw * suf + i_ww * swf;
        if c < 0.0 {
            return Some(line);
        }
        let sse = (sff - b * suf - c * swf).max(0.0);
        Some(Solved {
            b,
            c,
            i_uu,
            i_uw,
            i_ww,
            sse,
        })
    }

    /// Residual sum of squares of the least-squares fit (∞ when undetermined).
    fn sse(&self) -> f64 {
        self.solve().map_or(f64::INFINITY, |s| s.sse)
    }
}

/// A fit `f = a + b·u + c·w` (`w` the scaled velocity), with its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    /// Intercept at `u = 0`, `w = 0`, N.
    pub a: f64,
    /// Slope, N per unit of `u`.
    pub b: f64,
    /// Variance of `a`, N².
    pub var_a: f64,
    /// Variance of `b`, N².
    pub var_b: f64,
    /// Covariance of `a` and `b`, N².
    pub cov_ab: f64,
    /// Damping, N per unit of `w` (`c_e = c·s` for the position scale `s`).
    pub c: f64,
    /// Variance of `c` per N² of force noise, 1/unit² (0 when the damping is not fitted): with few
    /// samples at a nearly constant velocity the damping trades off against the intercept, and `c`
    /// means nothing.
    pub c_unit_var: f64,
    /// Residual variance per degree of freedom, N².
    pub residual_var: f64,
    /// Residual sum of squares, N².
    pub sse: f64,
    /// Variance of the force about its mean, N².
    pub force_var: f64,
}

/// The onset identifier. See the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct OnsetFit {
    buf: [(f64, f64, f64); CAPACITY],
    len: usize,
    head: usize,
    sums: Sums,
    x0: f64,
    scale: f64,
    /// Time left in the onset window, s (0: not identifying).
    left: f64,
    /// The window's samples as a known spring on a moving surface, once
    /// [`also_moving`](Self::also_moving) asked for it.
    moving: Option<Moving>,
}

/// The window's samples as the spring of slope `b` (N per unit of `u`) and damping `c_e` (N·s/m) on a
/// surface moving at a constant speed.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Moving {
    b: f64,
    c_e: f64,
    /// Sums on `(t, 0, f − b·u − c_e·v)`.
    sums: Sums,
    /// The window's time, s.
    t: f64,
}

impl OnsetFit {
    /// An empty identifier.
    pub fn new() -> Self {
        Self {
            buf: [(0.0, 0.0, 0.0); CAPACITY],
            len: 0,
            head: 0,
            sums: Sums::default(),
            x0: 0.0,
            scale: 1.0,
            left: 0.0,
            moving: None,
        }
    }

    /// Forget everything.
    pub fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
        self.sums = Sums::default();
        self.left = 0.0;
        self.moving = None;
    }

    /// Remember a raw sample out of contact: position `x` (m), force `f` (N), velocity `v` (m/s); the
    /// last `keep` samples (at most [`CAPACITY`]) are kept.
    pub fn remember(&mut self, x: f64, f: f64, v: f64, keep: usize) {
        if !(x.is_finite() && f.is_finite() && v.is_finite()) {
            return;
        }
        self.buf[self.head] = (x, f, v);
        self.head = (self.head + 1) % CAPACITY;
        self.len = (self.len + 1).min(keep.clamp(1, CAPACITY));
    }

    /// How many samples at control cycle `cycle` (s) span `memory` (s): at least two, at most
    /// [`CAPACITY`].
    pub fn samples(memory: f64, cycle: f64) -> usize {
        if cycle > 0.0 && memory.is_finite() {
            ((memory / cycle).round().max(2.0) as usize).min(CAPACITY)
        } else {
            CAPACITY
        }
    }

    /// Whether the onset window is open.
    pub fn active(&self) -> bool {
        self.left > 0.0
    }

    /// Contact is declared at position `x0` (m): fit the hinge to what was remembered and open the
    /// window for `window` s. `scale` is the position unit of `u`, m.
    pub fn begin(&mut self, x0: f64, scale: f64, window: f64) {
        self.x0 = x0;
        self.scale = scale;
        self.sums = Sums::default();
        self.left = window;
        self.moving = None;
        let start = (self.head + CAPACITY - self.len) % CAPACITY;
        let at = |i: usize| self.buf[(start + i) % CAPACITY];
        // Suffix sums from the newest sample back; the prefix carries f² as its residual.
        let mut total_ff = 0.0;
        for i in 0..self.len {
            total_ff += at(i).1 * at(i).1;
        }
        let mut suffix = Sums::default();
        let mut pre_ff = total_ff;
        let mut best = (f64::INFINITY, Sums::default());
        for j in (0..self.len).rev() {
            let (x, f, v) = at(j);
            suffix.add((x - x0) / scale, v / scale, f);
            pre_ff -= f * f;
            if suffix.n >= 2.0 {
                let suf = suffix.centred()[3];
                let cost = pre_ff.max(0.0) + suffix.sse();
                if suf > 0.0 && cost < best.0 {
                    best = (cost, suffix);
                }
            }
        }
        if best.0.is_finite() {
            self.sums = best.1;
        }
        self.len = 0;
        self.head = 0;
    }

    /// A sample in contact at velocity `v` (m/s); returns whether the window is still open.
    pub fn add(&mut self, x: f64, f: f64, v: f64, dt: f64) -> bool {
        if self.left <= 0.0 {
            return false;
        }
        self.left -= dt;
        if x.is_finite() && f.is_finite() && v.is_finite() {
            let (u, w) = ((x - self.x0) / self.scale, v / self.scale);
            self.sums.add(u, w, f);
            if let Some(m) = &mut self.moving {
                m.sums.add(m.t, 0.0, f - m.b * u - m.c_e * v);
            }
        }
        if let Some(m) = &mut self.moving {
            m.t += dt;
        }
        self.left > 0.0
    }

    /// Fit the window's samples from now on also as the known spring on a surface moving at a
    /// constant speed: `f = b·u + c_e·v + a − r·t`, with the slope `b` (N per unit of `u`) and the
    /// damping `c_e` (N·s/m) known, only the surface's start and speed free — the alternative to a
    /// changed stiffness when the force leaves its band on a surface that may have started to move
    /// (see [`moving_sse`](Self::moving_sse)). The damping is not fitted again: a loop settling
    /// exponentially moves the tool along its own velocity, and a free damping would fit a changed
    /// stiffness as well.
    pub fn also_moving(&mut self, b: f64, c_e: f64) {
        self.moving = Some(Moving {
            b,
            c_e,
            sums: Sums::default(),
            t: 0.0,
        });
    }

    /// The residual sum of squares of that fit, N² (`None` unless asked for, or undetermined).
    pub fn moving_sse(&self) -> Option<f64> {
        self.moving.and_then(|m| m.sums.solve()).map(|s| s.sse)
    }

    /// Whether position `x` (m) is behind the surface the fit so far puts its line's zero at (its
    /// spring force `a + b·u` negative): a sample there is on the hinge's flat part, not on the line.
    /// Chosen by the position, not the force, so noise does not bias what is kept. `false` while the
    /// fit is undetermined.
    pub fn behind(&self, x: f64) -> bool {
        self.fit(0.0)
            .is_some_and(|f| f.a + f.b * (x - self.x0) / self.scale < 0.0)
    }

    /// Count `dt` s of the window without a sample (one [`behind`](Self::behind) the surface).
    pub fn pass(&mut self, dt: f64) {
        if self.left > 0.0 {
            self.left -= dt;
            if let Some(m) = &mut self.moving {
                m.t += dt;
            }
        }
    }

    /// Keep the window open for `dt` s more (a fit not conclusive yet waits for more samples).
    pub fn extend(&mut self, dt: f64) {
        self.left = self.left.max(0.0) + dt;
    }

    /// Close the window early.
    pub fn stop(&mut self) {
        self.left = 0.0;
    }

    /// The fit so far, with residual variance at least `noise_var` (N²); `None` while undetermined.
    pub fn fit(&self, noise_var: f64) -> Option<LineFit> {
        let s = &self.sums;
        if s.n < 4.0 || s.centred()[3] <= 0.0 {
            return None;
        }
        let m = s.solve()?;
        if m.b <= 0.0 {
            return None;
        }
        let (ub, wb) = (s.u / s.n, s.w / s.n);
        let a = s.f / s.n - m.b * ub - m.c * wb;
        let dof = if m.c > 0.0 { 3.0 } else { 2.0 };
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
            force_var: s.centred()[5] / (s.n - 1.0),
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
        if s.n < 4.0 || !d.is_finite() {
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
            force_var: s.centred()[5] / (s.n - 1.0),
        };
        (b > 0.0
            && [fit.a, fit.b, fit.var_b, fit.c]
                .iter()
                .all(|v| v.is_finite()))
        .then_some((fit, per_surface_var))
    }
}

impl Default for OnsetFit {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_break_and_the_slope() {
        let (k, xc, s) = (70_000.0, 0.010, 1e-4);
        let mut o = OnsetFit::new();
        let mut x = 0.00996;
        for _ in 0..40 {
            o.remember(x, (k * (x - xc)).max(0.0), 0.002, 48);
            x += 2e-6;
        }
        o.begin(x, s, 0.1);
        let fit = o.fit(0.0).unwrap();
        assert!((fit.b / s - k).abs() < 1.0, "k {}", fit.b / s);
        assert!((fit.a - k * (x - xc)).abs() < 1e-6);
    }

    /// A damped transient: `f = k·(x − x_c) + c_e·ẋ` with the tool settling and a wobble on top.
    fn damped(o: &mut OnsetFit, k: f64, xc: f64, c_e: f64) {
        let dt = 1e-3;
        for i in 0..300 {
            let t = i as f64 * dt;
            let x = 0.0101 - 5e-5 * (-t / 0.02).exp() + 2e-6 * (t * 40.0).sin();
            let v = 5e-5 / 0.02 * (-t / 0.02).exp() + 2e-6 * 40.0 * (t * 40.0).cos();
            o.add(x, k * (x - xc) + c_e * v, v, dt);
        }
    }

    #[test]
    fn the_damping_is_fitted_with_the_stiffness() {
        let (k, xc, c_e, s) = (70_000.0, 0.010, 200.0, 1e-4);
        let mut o = OnsetFit::new();
        o.begin(0.0101, s, 1.0);
        damped(&mut o, k, xc, c_e);
        let fit = o.fit(0.0).unwrap();
        assert!((fit.b / s - k).abs() < 1e-3 * k, "k {}", fit.b / s);
        assert!((fit.c / s - c_e).abs() < 1e-3 * c_e, "c_e {}", fit.c / s);
        let (through, _) = o.fit_through(xc, 0.0).unwrap();
        assert!((through.b / s - k).abs() < 1e-3 * k, "k {}", through.b / s);
        assert!(through.sse < 1e-9, "{}", through.sse);
        // Through a surface 10 µm off the line leaves a residual.
        let off = o.fit_through(xc + 1e-5, 0.0).unwrap().0.sse;
        assert!(off > 1e-3, "{off}");
    }

    /// A window of the tool settling (a loop's answer: not at a constant speed) into a surface of
    /// stiffness `k` at `xc(t)`.
    fn settling(o: &mut OnsetFit, k: f64, xc: impl Fn(f64) -> f64) {
        let dt = 4e-3;
        for i in 0..75 {
            let t = i as f64 * dt;
            let x = 0.0101 + 5e-5 * (1.0 - (-t / 0.05).exp());
            let v = 5e-5 / 0.05 * (-t / 0.05).exp();
            o.add(x, k * (x - xc(t)), v, dt);
        }
    }

    #[test]
    fn a_moving_surface_and_a_changed_stiffness_are_told_apart() {
        let (k, s) = (200_000.0, 1e-4);
        // The stale stiffness on a surface moving at 0.15 mm/s: the moving fit explains the window,
        // the stiffness line does not.
        let mut o = OnsetFit::new();
        o.begin(0.0101, s, 1.0);
        o.also_moving(k * s, 0.0);
        settling(&mut o, k, |t| 0.010 + 1.5e-4 * t);
        let moving = o.moving_sse().unwrap();
        let line = o.fit(0.0).unwrap().sse;
        assert!(moving < 1e-9, "{moving}");
        assert!(line > 1e3 * moving.max(1e-12), "{line}");
        // The stiffness halved on a still surface: the other way round.
        let mut o = OnsetFit::new();
        o.begin(0.0101, s, 1.0);
        o.also_moving(k * s, 0.0);
        settling(&mut o, 0.5 * k, |_| 0.010);
        let moving = o.moving_sse().unwrap();
        let (through, _) = o.fit_through(0.010, 0.0).unwrap();
        assert!(through.sse < 1e-9, "{}", through.sse);
        assert!(moving > 1e-2, "{moving}");
        // Not asked for: none.
        let mut o = OnsetFit::new();
        o.begin(0.0101, s, 1.0);
        settling(&mut o, k, |_| 0.010);
        assert!(o.moving_sse().is_none());
    }

    /// A sample passed (a bounce in the window) still counts the moving surface's time.
    #[test]
    fn a_passed_sample_keeps_the_moving_fit_s_clock() {
        let (k, s, dt) = (200_000.0, 1e-4, 4e-3);
        let mut o = OnsetFit::new();
        o.begin(0.0101, s, 1.0);
        o.also_moving(k * s, 0.0);
        for i in 0..75 {
            let t = i as f64 * dt;
            let x = 0.0101 + 5e-5 * (1.0 - (-t / 0.05).exp());
            if (30..35).contains(&i) {
                o.pass(dt);
            } else {
                o.add(x, k * (x - 0.010 - 1.5e-4 * t), 0.0, dt);
            }
        }
        let moving = o.moving_sse().unwrap();
        assert!(moving < 1e-9, "{moving}");
    }
}
