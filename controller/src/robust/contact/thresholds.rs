//! The contact detector's thresholds, scaled to the set-point and the measured noise.

use super::ContactMachine;
use crate::robust::guards::{FORCE_GUARD, NOISE_GUARD};

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
    /// In a steady contact (held at the set-point for longer than a bounce), the raw force below
    /// which a sample counts towards a lift-off, N: `lift` raised by [`LIFT_NOISE`] deviations of
    /// the raw noise (a lost contact's samples are noise about zero), up to a quarter of the
    /// set-point and no nearer it than [`SIGNIFICANCE`] deviations (a hold at a small set-point under
    /// noise keeps `lift`: its own noise reaches down there).
    pub lift_off: f64,
    /// Consecutive samples below `lift_off` a steady contact's lift-off needs, as `samples`.
    pub off_samples: u32,
    /// The raw force's measured noise, standard deviation, N: how far a mean of raw samples must
    /// stand out to show a contact.
    pub noise: f64,
}

/// Standard deviations of a signal's noise that a contact must stand out by.
pub const SIGNIFICANCE: f64 = 4.0;

/// Deviations of the raw noise by which a steady contact's lift-off threshold stands above `lift`
/// (within a quarter of the set-point, and [`SIGNIFICANCE`] deviations below it): a lost contact's
/// sample, noise about zero, is below it 98 % of the time. Below `lift` alone, under σ 0.9 N with
/// `lift` 0.3 N, a lost contact needed six samples in a row below 0.3 N, each as likely as not: on
/// P1 80 samples passed without them while the law, still in contact, chased the retreated surface
/// at the loop's speed into 112 N at f_r 39 N; on the 12 ms cell such a chase tripped the force
/// limit.
pub const LIFT_NOISE: f64 = 2.0;

/// The contact threshold's share of a small set-point: below twice `contact_force` the contact is
/// declared at half the set-point, so that a small set-point's contact is still seen.
pub const CONTACT_SHARE: f64 = 0.5;

/// The steady contact's lift-off threshold's ceiling as a share of the set-point: a quarter. A hold
/// at the set-point stays three quarters of it away, so [`LIFT_NOISE`] never raises the threshold into
/// the contact's own force.
pub const LIFT_OFF_SHARE: f64 = 0.25;

/// The most consecutive samples a lift-off needs, however noisy: 64 ms at 1 kHz, 0.77 s on a 12 ms
/// cycle. A bound on the count, which grows without one as the set-point nears the noise.
pub const MAX_LIFT_SAMPLES: f64 = 64.0;

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
    /// hold's own noise lifted off, and the fast search pressed 15–21 N into the surface still there);
    /// a steady contact's lift-off counts samples below `lift_off` instead, as many in a row alike.
    pub fn thresholds(&self, f_r: f64, sigma: f64, sigma_ff: f64) -> Thresholds {
        let c = &self.p;
        let contact = c
            .contact_force
            .min(CONTACT_SHARE * f_r)
            .max(SIGNIFICANCE * sigma_ff);
        let lift = c.lift_force * contact / c.contact_force;
        let lift_off = (lift + LIFT_NOISE * sigma)
            .min(LIFT_OFF_SHARE * f_r)
            .min(f_r - SIGNIFICANCE * sigma)
            .max(lift);
        // Two samples, one more per `below` of raw noise; and, as a hold at the set-point puts a raw
        // sample below `below` with a probability of at most `½·exp(−a²/2)`, `a` the gap in noise
        // deviations, at least as many in a row as bring that down to a [`SIGNIFICANCE`] event,
        // `exp(−SIGNIFICANCE²/2)`.
        let in_a_row = |below: f64| {
            let extra = (sigma / below.max(FORCE_GUARD)).ceil();
            let a = (f_r - below).max(0.0) / sigma.max(NOISE_GUARD);
            let run = SIGNIFICANCE * SIGNIFICANCE / 2.0 / (a * a / 2.0 + core::f64::consts::LN_2);
            (2.0 + extra).max(run.ceil()).min(MAX_LIFT_SAMPLES) as u32
        };
        Thresholds {
            contact,
            strong: c.strong_contact * contact.max(SIGNIFICANCE * sigma),
            lift,
            samples: in_a_row(lift),
            lift_off,
            off_samples: in_a_row(lift_off),
            noise: sigma,
        }
    }
}
