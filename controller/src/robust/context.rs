//! What one step knows once its inputs are measured, computed once at the top of the step and read by
//! every stage after it: the cycle, the active set-point, the sensor's noise and what the conditioning
//! does to it, and the loop's lead time. The stages take it as their input; none of them reads another
//! stage's state for these values.

use super::cell::CellParams;
use super::noise::NoiseEstimate;

/// The band a steady contact's force keeps about the set-point, as a share of the force scale
/// ([`Context::force_scale`]): a fifth: a design choice, not the result of a sweep (a stiffness
/// that changes by more than a fifth moves the force out of it under the stale gain).
const BAND_SHARE: f64 = 0.2;

/// The band's floor in noise deviations: Gaussian noise leaves a band of 5σ with a probability of
/// 5.7·10⁻⁷ per sample (about once in 29 min at 1 kHz), where one of [`super::contact::SIGNIFICANCE`]
/// (4σ, 6.3·10⁻⁵) would be left about every 16 s: a band the noise alone leaves opens re-fits on noise.
const BAND_DEVIATIONS: f64 = 5.0;

/// How far ahead of the robot the approach may command, in multiples of the loop's lead time (the
/// lag, the delay and the conditioning's delay): the commands in flight when a contact is seen.
const ANCHOR_LEADS: f64 = 4.0;

/// The least anchor time, s: on a cell with a negligible lead the approach may still command 50 ms
/// of travel ahead (at 10 mm/s, half a millimetre).
const ANCHOR_MIN_TIME: f64 = 0.05;

/// One step's context. SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Context {
    /// The step, s (a held cycle lengthens it).
    pub dt: f64,
    /// The interface cycle, s ([`super::CycleMeter`]).
    pub cycle: f64,
    /// The active set-point (slewed towards the configured one), N.
    pub set_point: f64,
    /// The force a jump or a band is measured against: the set-point, at least the contact force, N.
    pub force_scale: f64,
    /// The raw force's noise, measured ([`super::NoiseMeter`]).
    pub noise: NoiseEstimate,
    /// The share of the noise's deviation that passes the conditioning.
    pub noise_gain: f64,
    /// How long a step takes to pass the conditioning, s.
    pub step_time: f64,
    /// The conditioning's low-frequency group delay, s.
    pub filter_delay: f64,
    /// The robot's first-order lag, s ([`CellParams::lag`]).
    pub lag: f64,
    /// The robot's pure delay, command to motion, s ([`CellParams::loop_delay`]).
    pub loop_delay: f64,
    /// The loop's whole lead time: lag, delay and conditioning, s.
    pub lead: f64,
}

impl Context {
    /// The context of a step of `dt` at `cycle`, with the active `set_point` and the least
    /// `contact_force` (N), the `noise` measured, the conditioning's `noise_gain`, `step_time` and
    /// `filter_delay`, on `cell`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dt: f64,
        cycle: f64,
        set_point: f64,
        contact_force: f64,
        noise: NoiseEstimate,
        noise_gain: f64,
        step_time: f64,
        filter_delay: f64,
        cell: &CellParams,
    ) -> Self {
        let loop_delay = cell.loop_delay();
        Self {
            dt,
            cycle,
            set_point,
            force_scale: set_point.max(contact_force),
            noise,
            noise_gain,
            step_time,
            filter_delay,
            lag: cell.lag,
            loop_delay,
            lead: cell.lag + loop_delay + filter_delay,
        }
    }

    /// The conditioned force's noise deviation, N.
    pub fn sigma_filtered(&self) -> f64 {
        self.noise.std * self.noise_gain
    }

    /// The band a force of noise deviation `sigma` (N) keeps about the set-point in a steady contact:
    /// a fifth of the set-point, at least five deviations, N. Leaving it opens a re-fit (the
    /// conditioned force) or holds the recursion for the step (the raw force).
    pub fn band(&self, sigma: f64) -> f64 {
        (BAND_SHARE * self.force_scale).max(BAND_DEVIATIONS * sigma)
    }

    /// How far ahead of the robot the approach may command, in time at approach speed, s.
    pub fn anchor_time(&self) -> f64 {
        (ANCHOR_LEADS * self.lead).max(ANCHOR_MIN_TIME)
    }
}
