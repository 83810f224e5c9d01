//! Division guards: the least magnitude a quantity is taken at where the law divides by it, so that a
//! zero (an unmeasured noise, a stiffness not identified, a speed of zero) gives a large finite number
//! instead of a NaN or an infinity. Each is many orders of magnitude below any value the quantity
//! takes on a real cell, so it changes no result where the quantity is physical.

/// The least force the law divides by, N (a force sensor resolves 10⁻³ N at best).
pub const FORCE_GUARD: f64 = 1e-9;

/// The least noise standard deviation the law divides by, N.
pub const NOISE_GUARD: f64 = 1e-12;

/// The least stiffness the law divides by, N/m (surfaces are 10³–10⁶ N/m).
pub const STIFFNESS_GUARD: f64 = 1e-12;

/// The least speed the law divides by, m/s.
pub const SPEED_GUARD: f64 = 1e-12;

/// The least distance the law divides by, m.
pub const DISTANCE_GUARD: f64 = 1e-18;

/// The least variance (of a velocity, m²/s², or an acceleration, m²/s⁴) the law divides by.
pub const VARIANCE_GUARD: f64 = 1e-30;
