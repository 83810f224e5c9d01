//! Identification of the contact stiffness from the first contact transient.
//!
//! The approach is the best excitation the law ever gets: the tool moves into a still surface and the
//! force rises from zero along `f = k_c·(x − x_c)`. The conditioned force that confirms contact lags the
//! raw one, so by the time contact is declared most of that rise has passed; it is kept here.
//!
//! Out of contact the last [`CAPACITY`] raw samples `(x, f)` are remembered. When contact is declared,
//! a hinge is fitted to them: samples before the break carry no force (`f ≈ 0`), samples from it on lie
//! on a line `f = a + b·u`, `u = (x − x₀)/s`; the break is the one with the least total squared residual.
//! The samples on the line, and every sample of the window [`OnsetFit::begin`] opens, make an ordinary
//! least-squares fit of `(a, b)` whose uncertainty comes from its own residuals (or the
//! measured sensor noise, whichever is larger). A fixed-size buffer and running sums: no allocation.

/// Samples remembered out of contact.
pub const CAPACITY: usize = 48;

/// Running least-squares sums on `(u, f)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sums {
    n: f64,
    u: f64,
    f: f64,
    uu: f64,
    uf: f64,
    ff: f64,
}

impl Sums {
    fn add(&mut self, u: f64, f: f64) {
        self.n += 1.0;
        self.u += u;
        self.f += f;
        self.uu += u * u;
        self.uf += u * f;
        self.ff += f * f;
    }

    /// Centred second moments `(Suu, Suf, Sff)`.
    fn centred(&self) -> (f64, f64, f64) {
        let n = self.n.max(1.0);
        (
            self.uu - self.u * self.u / n,
            self.uf - self.u * self.f / n,
            self.ff - self.f * self.f / n,
        )
    }

    /// Residual sum of squares of the least-squares line (∞ when the line is undetermined).
    fn sse(&self) -> f64 {
        let (suu, suf, sff) = self.centred();
        if self.n < 2.0 || suu <= 0.0 {
            f64::INFINITY
        } else {
            (sff - suf * suf / suu).max(0.0)
        }
    }
}

/// A line fit `f = a + b·u`, with its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    /// Intercept at `u = 0`, N.
    pub a: f64,
    /// Slope, N per unit of `u`.
    pub b: f64,
    /// Variance of `a`, N².
    pub var_a: f64,
    /// Variance of `b`, N².
    pub var_b: f64,
    /// Covariance of `a` and `b`, N².
    pub cov_ab: f64,
}

/// The onset identifier. See the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct OnsetFit {
    buf: [(f64, f64); CAPACITY],
    len: usize,
    head: usize,
    sums: Sums,
    x0: f64,
    scale: f64,
    /// Time left in the onset window, s (0: not identifying).
    left: f64,
}

impl OnsetFit {
    /// An empty identifier.
    pub fn new() -> Self {
        Self {
            buf: [(0.0, 0.0); CAPACITY],
            len: 0,
            head: 0,
            sums: Sums::default(),
            x0: 0.0,
            scale: 1.0,
            left: 0.0,
        }
    }

    /// Forget everything.
    pub fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
        self.sums = Sums::default();
        self.left = 0.0;
    }

    /// Remember a raw sample out of contact.
    pub fn remember(&mut self, x: f64, f: f64) {
        if !(x.is_finite() && f.is_finite()) {
            return;
        }
        self.buf[self.head] = (x, f);
        self.head = (self.head + 1) % CAPACITY;
        self.len = (self.len + 1).min(CAPACITY);
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
            let (x, f) = at(j);
            suffix.add((x - x0) / scale, f);
            pre_ff -= f * f;
            if suffix.n >= 2.0 {
                let (_, suf, _) = suffix.centred();
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

    /// A sample in contact; returns whether the window is still open.
    pub fn add(&mut self, x: f64, f: f64, dt: f64) -> bool {
        if self.left <= 0.0 {
            return false;
        }
        self.left -= dt;
        if x.is_finite() && f.is_finite() {
            self.sums.add((x - self.x0) / self.scale, f);
        }
        self.left > 0.0
    }

    /// Close the window early.
    pub fn stop(&mut self) {
        self.left = 0.0;
    }

    /// The fit so far, with residual variance at least `noise_var` (N²); `None` while undetermined.
    pub fn fit(&self, noise_var: f64) -> Option<LineFit> {
        let s = &self.sums;
        if s.n < 4.0 {
            return None;
        }
        let (suu, suf, _) = s.centred();
        if !(suu > 0.0 && suf > 0.0) {
            return None;
        }
        let b = suf / suu;
        let ub = s.u / s.n;
        let a = s.f / s.n - b * ub;
        let var = (s.sse() / (s.n - 2.0)).max(noise_var);
        let var_b = var / suu;
        let fit = LineFit {
            a,
            b,
            var_a: var / s.n + ub * ub * var_b,
            var_b,
            cov_ab: -ub * var_b,
        };
        [fit.a, fit.b, fit.var_a, fit.var_b, fit.cov_ab]
            .iter()
            .all(|v| v.is_finite())
            .then_some(fit)
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
            o.remember(x, (k * (x - xc)).max(0.0));
            x += 2e-6;
        }
        o.begin(x, s, 0.1);
        let fit = o.fit(0.0).unwrap();
        assert!((fit.b / s - k).abs() < 1.0, "k {}", fit.b / s);
        assert!((fit.a - k * (x - xc)).abs() < 1e-6);
    }
}
