//! The contact detector's thresholds, scaled to the set-point and the measured noise.

use super::ContactMachine;

/// The detector's thresholds for one step, scaled to the set-point and the measured noise (see
/// [`ContactMachine::thresholds`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thresholds {
    /// Conditioned force that means contact, N.
    pub contact: f64,
    /// One raw sample at or above this is contact on its own, N.
    pub strong: f64,
    /// Raw force below which a sample counts towards a lift-off, N.
    pub lift: f64,
    /// Consecutive samples below `lift` a lift-off needs (never one: a single bad or zero sample, or
    /// the first sample after a dropout, is not a lift-off; more under noise).
    pub samples: u32,
    /// The raw force's measured noise, standard deviation, N: how far a mean of raw samples must
    /// stand out to show a contact.
    pub noise: f64,
}

/// Standard deviations of a signal's noise that a contact must stand out by.
pub const SIGNIFICANCE: f64 = 4.0;

impl ContactMachine {
    /// The thresholds for set-point `f_r` (N) and the conditioned force's noise `sigma_ff` (N) and the
    /// raw force's `sigma` (N): `contact_force` and `lift_force` as configured for a set-point of at
    /// least twice `contact_force`, scaled down with a smaller set-point (contact at half of it), and
    /// raised to [`SIGNIFICANCE`] standard deviations of the conditioned force's noise; a single raw
    /// sample is contact at `strong_contact` times that, or times as many of the raw force's standard
    /// deviations (the raw noise is wider than the conditioned: over an approach of hundreds of
    /// samples a few noise spikes reach `strong_contact · contact`); a lift-off needs two samples, one
    /// more per `lift_force` of raw noise, and at least as many as make a hold at `f_r` put that many
    /// in a row below `lift` only as a [`SIGNIFICANCE`] event (f_r 2 N under σ 1 N: 7, not 4 — the
    /// hold's own noise lifted off, and the fast search pressed 15–21 N into the surface still there).
    pub fn thresholds(&self, f_r: f64, sigma: f64, sigma_ff: f64) -> Thresholds {
        let c = &self.p;
        let contact = c.contact_force.min(0.5 * f_r).max(SIGNIFICANCE * sigma_ff);
        let lift = c.lift_force * contact / c.contact_force;
        let extra = (sigma / lift.max(1e-9)).ceil();
        // A hold at the set-point puts a raw sample below `lift` with a probability of at most
        // `½·exp(−a²/2)`, `a` the gap in noise deviations: as many samples in a row as bring that
        // down to a [`SIGNIFICANCE`] event, `exp(−SIGNIFICANCE²/2)`.
        let a = (f_r - lift).max(0.0) / sigma.max(1e-12);
        let in_a_row = 0.5 * SIGNIFICANCE * SIGNIFICANCE / (0.5 * a * a + core::f64::consts::LN_2);
        Thresholds {
            contact,
            strong: c.strong_contact * contact.max(SIGNIFICANCE * sigma),
            lift,
            samples: (2.0 + extra).max(in_a_row.ceil()).min(64.0) as u32,
            noise: sigma,
        }
    }
}
