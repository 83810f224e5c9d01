//! The composed step's pieces that read several stages: the detector's thresholds, the approach's
//! anchor, the re-identification and the command in contact.

use super::identify::StepState;
use super::{RobustLaw, Signals, contact, observer};
use crate::law::Events;

/// The band a steady contact's force keeps about the set-point, as a share of the force scale
/// ([`RobustLaw::force_scale`]): a fifth: a design choice, not the result of a sweep (a stiffness
/// that changes by more than a fifth moves the force out of it under the stale gain).
const BAND_SHARE: f64 = 0.2;

/// The band's floor in noise deviations: Gaussian noise leaves a band of 5σ with a probability of
/// 5.7·10⁻⁷ per sample (about once in 29 min at 1 kHz), where one of [`contact::SIGNIFICANCE`] (4σ,
/// 6.3·10⁻⁵) would be left about every 16 s: a band the noise alone leaves opens re-fits on noise.
const BAND_DEVIATIONS: f64 = 5.0;

/// How far ahead of the robot the approach may command, in multiples of the loop's lead time (the
/// lag, the delay and the conditioning's delay): the commands in flight when a contact is seen.
const ANCHOR_LEADS: f64 = 4.0;

/// The least anchor time, s: on a cell with a negligible lead the approach may still command 50 ms
/// of travel ahead (at 10 mm/s, half a millimetre).
const ANCHOR_MIN_TIME: f64 = 0.05;

impl RobustLaw {
    /// The force a jump or a band is measured against: the set-point, at least the contact force, N.
    pub(super) fn force_scale(&self) -> f64 {
        self.response.set_point().max(self.p.contact.contact_force)
    }

    /// The band a force of noise deviation `sigma` (N) keeps about the set-point in a steady contact:
    /// a fifth of the set-point, at least five deviations, N. Leaving it opens a re-fit (the
    /// conditioned force) or holds the recursion for the step (the raw force).
    pub(super) fn band(&self, sigma: f64) -> f64 {
        (BAND_SHARE * self.force_scale()).max(BAND_DEVIATIONS * sigma)
    }

    /// The contact detector's thresholds now: scaled to the active set-point and the measured noise
    /// (the conditioned force's noise from the raw one through the conditioning's noise bandwidth).
    /// Until the noise has been measured for as long as a step takes to pass the conditioning, the
    /// conditioned force is still the first raw sample's, noise and all, and the noise unknown: only
    /// a strong raw sample is contact. So too until the noise has been measured on
    /// `SIGNIFICANCE²` samples: a threshold of that many deviations is only as good as the deviation,
    /// whose estimate from `n` samples is uncertain by about `1/√n` (on the 12 ms cell the step time
    /// is 4 samples: a deviation known to ±50 %, and contacts were declared on noise in free air).
    pub(super) fn thresholds(&self, cycle: f64) -> contact::Thresholds {
        let sigma = self.noise.std();
        let sigma_ff = sigma * self.signals.noise_gain(cycle);
        let mut th = self
            .contact
            .thresholds(self.response.set_point(), sigma, sigma_ff);
        let samples = contact::SIGNIFICANCE * contact::SIGNIFICANCE * cycle;
        if self.noise.age() < self.signals.step_time(cycle).max(samples) {
            th.contact = f64::INFINITY;
        }
        th
    }

    /// How far ahead of the robot the approach may command, in time at approach speed, s.
    pub(super) fn anchor_time(&self, cycle: f64) -> f64 {
        let c = &self.p.cell;
        (ANCHOR_LEADS * (c.lag + c.loop_delay() + self.signals.delay(cycle))).max(ANCHOR_MIN_TIME)
    }

    /// The command in contact before limits.
    pub(super) fn in_contact(&mut self, s: &Signals, cycle: f64, dt: f64) -> f64 {
        let k = self.identify.kc();
        // The surface is `x − f/k̂_c` of the spring's force: the identified damping's share taken out,
        // or a damped surface looks as if it moved with the tool and the feed-forward chases it.
        let c_e = self.identify.damping();
        let view = observer::View {
            x: s.x,
            f: s.f - c_e * s.v_raw,
            xf: s.xf,
            ff: s.ff - c_e * s.v_x,
            v_raw: s.v_raw,
            k,
            force_scale: self.force_scale(),
            noise_var: self.noise.var(),
            noise_gain: self.signals.noise_gain(cycle),
            step_time: self.signals.step_time(cycle),
        };
        self.observer
            .track(&view, self.p.response.surface_bandwidth, dt);
        // A force that rose under a steady contact by what a stiffness up to `jump_caution` times
        // higher explains (within the noise) is a surface that came nearer or a stiffer one, and
        // until the re-fit tells, the correction takes the stiffer: the other retreats too far (a
        // doubling under the stale gain rings into a lost contact). A larger rise is a surface step.
        // Meanwhile only a feed-forward that backs off is kept. A stiffer surface seen through the
        // stale `k̂_c` makes the tool's retreat look like the surface going away (`(1 − k_c/k̂_c)·ẋ`),
        // whose feed-forward would press in; a surface that came nearer and goes on coming is seen
        // approaching, and its feed-forward backs off as the caution does (a slow surface approaching
        // 500 kN/m at 20 N on P2 opened one re-fit after another, each without feed-forward, and the
        // force went to 36 N).
        let (caution, scale) = (self.p.response.jump_caution, view.force_scale);
        let sig = contact::SIGNIFICANCE * view.noise_var.sqrt();
        let rise = match self.identify.unresolved_jump() {
            Some(f0) if f0 > scale && f0 - sig <= caution * scale => (f0 / scale).min(caution),
            _ => 1.0,
        };
        let (k_gain, cautious) = (k * rise, rise > 1.0);
        let (proportional, integral) =
            self.response
                .correction(s.ff, k_gain, view.noise_var, view.force_scale, dt);
        let cell = self.p.cell;
        let lead = cell.lag + cell.loop_delay() + self.signals.delay(cycle);
        let ff = self.observer.feedforward(
            &view,
            &self.p.response,
            self.p.estimator.max_surface_speed,
            cell.lag,
            cell.loop_delay(),
            cycle,
            lead,
            dt,
        );
        // The set-point's own motion, fed forward over the loop's lead time: a ramp is followed, not
        // chased (the force lags the command by the inner loop's lag and delay and the conditioning).
        let ramp = self.response.rate() / k * (cell.lag + cell.loop_delay());
        let ff = ff.weight * ff.predicted + (1.0 - ff.weight) * ff.fallback;
        let ff = if cautious { ff.min(0.0) } else { ff };
        s.xf + proportional + ff + integral + ramp
    }

    /// A contact declared at the raw `(s.x, s.f)`: identification begins (a re-contact tells it how
    /// the search went: a surface found moved, or the fast search's momentum, holds the recursion),
    /// the observers restart at the surface `k̂_c` puts there, the integral at zero.
    pub(super) fn begin_contact(&mut self, s: &Signals, from_approach: bool) {
        let (x, f) = (s.x, s.f);
        self.identify.begin_contact(x, f, from_approach);
        self.observer.restart(s.xf - s.ff / self.identify.kc());
        self.response.begin_contact();
        if !from_approach {
            let (v, hold) = (
                self.p.estimator.max_surface_speed,
                self.p.observer.motion_hold,
            );
            self.identify
                .recontact(x, f, &self.contact.search(), self.p.f_r, v, hold);
        }
    }

    /// In contact: re-identify `k̂_c` when the environment changed under a steady contact, and run the
    /// identifier on the raw sample `(s.x, s.f)`; `moving`: the surface counts as moving; `lift`: the
    /// raw force below which the tool is off the surface, N.
    pub(super) fn identify_in_contact(
        &mut self,
        s: &Signals,
        lift: f64,
        cycle: f64,
        moving: bool,
        ev: &mut Events,
        dt: f64,
    ) {
        // The environment changed under a steady contact on a still surface: the observed
        // surface jumped, or the force left its band (a stiffness change the observer follows
        // smoothly). Re-identify from the transient that follows.
        let sigma = self.noise.std();
        let off = (s.ff - self.response.set_point()).abs()
            > self.band(sigma * self.signals.noise_gain(cycle));
        let persist = self.signals.step_time(cycle) / 2.0;
        let calm = self.contact.steady()
            && !moving
            && !self.identify.fitting()
            && !self.identify.held()
            && !self.observer.drifted()
            && self.observer.still();
        let excursion = self.identify.excursion(off, calm, persist, dt);
        if excursion || (calm && self.observer.jump_on_still_surface()) {
            // The loop answers the jump within its lead time and the conditioning's step time.
            let c = &self.p.cell;
            let early =
                c.lag + c.loop_delay() + self.signals.delay(cycle) + self.signals.step_time(cycle);
            let slowest = self.p.observer.feedforward_speed;
            self.identify.refit(s.x, s.f, early, slowest);
        }
        let disturbed = self.observer.disturbed();
        let jumped = calm && (s.f - self.response.set_point()).abs() > self.band(sigma);
        let id = self.identify.step(
            s.x,
            s.f,
            s.v_raw,
            s.ff,
            dt,
            // The recursion learns nothing while the observer holds the surface for a moving one that
            // started after a calm contact, also on the samples where the predictor's own test does
            // not pass: the tool's answer to the force hides a surface that just started to move on
            // some of them, and learnt in between a sine starting at 3.1 mm/s on 300 kN/m read as a
            // surface 26 % softer. (Right after a touch-down the motion the observer sees is as often
            // a fresh `k̂_c`'s ringing, which the recursion must learn from.)
            StepState {
                moving: moving || self.observer.moving_after_calm(),
                drifted: self.observer.drifted(),
                first: ev.contact,
                lifted: s.f < lift,
                disturbed,
                jumped,
                filtered: self.p.cell.sensor_delay > 0.0,
            },
            self.noise.var(),
            self.p.response.noise_floor,
        );
        if id.seeded {
            // The observed surface is x − f/k̂_c: a k̂_c that moves would show it moving. While the
            // transient is identified the observers restart on every new k̂_c, at rest.
            self.observer.restart(s.xf - s.ff / self.identify.kc());
            self.contact.identified();
        }
        ev.estimator_bound |= id.projected;
    }

    /// The command before limits: out of contact the state machine's (approach, search, retract), in
    /// contact the law's, held to the approach speed while touching down.
    pub(super) fn command(
        &mut self,
        x: f64,
        s: &Signals,
        th: &contact::Thresholds,
        cycle: f64,
        dt: f64,
    ) -> f64 {
        let anchor = self.anchor_time(cycle);
        self.stopping.update(&self.p.cell, cycle, &self.p.limits);
        let speeds = self.contact.speeds(
            self.identify.kc(),
            self.identify.kc_rel_sd(),
            self.response.set_point(),
            self.p.limits.max_force,
            th.strong,
            &self.stopping,
        );
        match self
            .contact
            .command(x, self.limiter.command(), &speeds, anchor, dt)
        {
            Some(u) => u,
            None => {
                let want = self.in_contact(s, cycle, dt);
                let open = self.identify.onset_open();
                let confirm = self.signals.step_time(cycle);
                let touching = self.contact.touch(s.ff, th, confirm, dt);
                self.contact
                    .land(want, self.limiter.command(), &speeds, open, touching, dt)
            }
        }
    }
}
