//! The running least-squares sums the fits are made of, and their solution.

/// Running least-squares sums on `(u, w, f)`: `u` the scaled position, `w` the scaled velocity.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Sums {
    pub(super) n: f64,
    pub(super) u: f64,
    pub(super) w: f64,
    pub(super) f: f64,
    pub(super) uu: f64,
    pub(super) uw: f64,
    pub(super) ww: f64,
    pub(super) uf: f64,
    pub(super) wf: f64,
    pub(super) ff: f64,
}

/// Relative determinant below which the velocity column adds nothing the position column has not
/// (a constant velocity, or one proportional to the position): the fit is then the line alone.
pub(super) const COLLINEAR: f64 = 1e-6;

/// The fewest samples a fit with damping is taken on, and any fit judged: one more than the plane's
/// three parameters (`a`, `b`, `c`), so that a residual is left to judge it by.
pub(super) const MIN_SAMPLES: f64 = 4.0;

/// The number of centred second moments ([`Sums::centred`]).
pub(super) const MOMENTS: usize = 6;
/// Index of `Suf`, the position-force moment, in [`Sums::centred`].
pub(super) const SUF: usize = 3;
/// Index of `Sff`, the force's own moment, in [`Sums::centred`].
pub(super) const SFF: usize = 5;

/// The centred normal equations' solution: slope `b` on `u`, slope `c` on `w` (0: line only), the
/// inverse's entries `(i_uu, i_uw, i_ww)`, and the residual sum of squares.
pub(super) struct Solved {
    pub(super) b: f64,
    pub(super) c: f64,
    pub(super) i_uu: f64,
    pub(super) i_uw: f64,
    pub(super) i_ww: f64,
    pub(super) sse: f64,
}

impl Sums {
    pub(super) fn add(&mut self, u: f64, w: f64, f: f64) {
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
    pub(super) fn centred(&self) -> [f64; MOMENTS] {
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
    pub(super) fn solve(&self) -> Option<Solved> {
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
        if self.n < MIN_SAMPLES || det <= COLLINEAR * suu * sww {
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
    pub(super) fn sse(&self) -> f64 {
        self.solve().map_or(f64::INFINITY, |s| s.sse)
    }
}
