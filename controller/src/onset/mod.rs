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

mod fit;
mod sums;
#[cfg(test)]
mod tests;

use sums::Sums;

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
    /// The slowest surface speed that counts as motion, m/s.
    slowest: f64,
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
                let suf = suffix.centred()[sums::SUF];
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

    /// The spring force the fit so far gives at position `x` (m), N, and the standard deviation of a
    /// new sample's force about it (the fit's own uncertainty at `x`, and its residuals' or the noise
    /// variance `noise_var` (N²), whichever is larger), N; `None` while the fit is undetermined. A
    /// force below zero puts `x` behind the surface: a sample there is on the hinge's flat part, not
    /// on the line (chosen by the position, not the force, so noise does not bias what is kept).
    pub fn line_at(&self, x: f64, noise_var: f64) -> Option<(f64, f64)> {
        self.fit(0.0).map(|f| {
            let u = (x - self.x0) / self.scale;
            let var =
                f.var_a + u * u * f.var_b + 2.0 * u * f.cov_ab + f.residual_var.max(noise_var);
            (f.a + f.b * u, var.max(0.0).sqrt())
        })
    }

    /// Count `dt` s of the window without a sample (one behind the surface, [`line_at`](Self::line_at)).
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
}

impl Default for OnsetFit {
    fn default() -> Self {
        Self::new()
    }
}
