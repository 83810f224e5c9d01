//! The composed step's pieces that join several stages: the step's context, the detector's
//! thresholds, the re-identification and the command in contact. Each takes the step's [`Context`]
//! and the typed outputs of the stages before it ([`Signals`], [`SurfaceStatus`], [`Estimate`]).

use super::contact::{LandInput, Search, SearchInput};
use super::identify::{Estimate, InContact, StepState, TouchDown};
use super::noise::NoiseEstimate;
use super::observer::{SurfaceStatus, View};
use super::{Context, RobustLaw, Signals, contact};
use crate::law::Events;

impl RobustLaw {
    /// The step's context: computed once, after the cycle, the set-point and the noise have been
    /// measured for the step.
    pub(super) fn context(
        &self,
        dt: f64,
        cycle: f64,
        set_point: f64,
        noise: NoiseEstimate,
    ) -> Context {
        Context::new(
            dt,
            cycle,
            set_point,
            self.p.contact.contact_force,
            noise,
            self.signals.noise_gain(cycle),
            self.signals.step_time(cycle),
            self.signals.delay(cycle),
            &self.p.cell,
        )
    }

    /// The contact detector's thresholds now: scaled to the active set-point and the measured noise
    /// (the conditioned force's noise from the raw one through the conditioning's noise bandwidth).
    /// Until the noise has been measured for as long as a step takes to pass the conditioning, the
    /// conditioned force is still the first raw sample's, noise and all, and the noise unknown: only
    /// a strong raw sample is contact. So too until the noise has been measured on
    /// `SIGNIFICANCE²` samples: a threshold of that many deviations is only as good as the deviation,
    /// whose estimate from `n` samples is uncertain by about `1/√n` (on the 12 ms cell the step time
    /// is 4 samples: a deviation known to ±50 %, and contacts were declared on noise in free air).
    pub(super) fn thresholds(&self, ctx: &Context) -> contact::Thresholds {
        let mut th = self
            .contact
            .thresholds(ctx.set_point, ctx.noise.std, ctx.sigma_filtered());
        let samples = contact::SIGNIFICANCE * contact::SIGNIFICANCE * ctx.cycle;
        if ctx.noise.age < ctx.step_time.max(samples) {
            th.contact = f64::INFINITY;
        }
        th
    }

    /// The command in contact before limits.
    pub(super) fn in_contact(&mut self, s: &Signals, ctx: &Context, est: &Estimate) -> f64 {
        let (k, dt) = (est.kc, ctx.dt);
        // The surface is `x − f/k̂_c` of the spring's force: the identified damping's share taken out,
        // or a damped surface looks as if it moved with the tool and the feed-forward chases it.
        let view = View::new(s, k, est.damping, ctx);
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
        let rise = match est.unresolved_jump {
            Some(f0) if f0 > scale && f0 - sig <= caution * scale => (f0 / scale).min(caution),
            _ => 1.0,
        };
        let (k_gain, cautious) = (k * rise, rise > 1.0);
        let (proportional, integral) =
            self.response
                .correction(s.ff, k_gain, view.noise_var, view.force_scale, dt);
        let ff = self.observer.feedforward(
            &view,
            ctx,
            &self.p.response,
            self.p.estimator.max_surface_speed,
        );
        // The set-point's own motion, fed forward over the loop's lead time: a ramp is followed, not
        // chased (the force lags the command by the inner loop's lag and delay and the conditioning).
        let ramp = self.response.rate() / k * (ctx.lag + ctx.loop_delay);
        let ff = ff.weight * ff.predicted + (1.0 - ff.weight) * ff.fallback;
        let ff = if cautious { ff.min(0.0) } else { ff };
        s.xf + proportional + ff + integral + ramp
    }

    /// A contact declared at the raw `(s.x, s.f)`: identification begins (a re-contact tells it how
    /// the search went: a surface found moved, or the fast search's momentum, holds the recursion),
    /// the observers restart at the surface `k̂_c` puts there, the integral at zero.
    pub(super) fn begin_contact(&mut self, s: &Signals, from_approach: bool, search: &Search) {
        let kc = self.identify.touch_down(&TouchDown {
            x: s.x,
            f: s.f,
            from_approach,
            search,
            f_r: self.p.f_r,
            max_surface_speed: self.p.estimator.max_surface_speed,
            hold: self.p.observer.motion_hold,
        });
        self.observer.restart(s.xf - s.ff / kc);
        self.response.begin_contact();
    }

    /// In contact: re-identify `k̂_c` when the environment changed under a steady contact, and run the
    /// identifier on the raw sample `(s.x, s.f)`; `surface`: what the observer knows of the surface's
    /// motion this step; `lift`: the raw force below which the tool is off the surface, N.
    pub(super) fn identify_in_contact(
        &mut self,
        s: &Signals,
        ctx: &Context,
        lift: f64,
        steady: bool,
        surface: &SurfaceStatus,
        ev: &mut Events,
    ) -> bool {
        let dt = ctx.dt;
        let before = self.identify.estimate();
        // The environment changed under a steady contact on a still surface: the observed
        // surface jumped, or the force left its band (a stiffness change the observer follows
        // smoothly). Re-identify from the transient that follows.
        let off = (s.ff - ctx.set_point).abs() > ctx.band(ctx.sigma_filtered());
        let calm = steady
            && !surface.moving
            && !before.fitting
            && !before.held
            && !surface.drifted
            && surface.still;
        let jumped = calm && (s.f - ctx.set_point).abs() > ctx.band(ctx.noise.std);
        let id = self.identify.in_contact(&InContact {
            x: s.x,
            f: s.f,
            v: s.v_raw,
            ff: s.ff,
            dt,
            off,
            calm,
            persist: ctx.step_time / 2.0,
            jump_on_still_surface: surface.jump_on_still_surface,
            // The loop answers the jump within its lead time and the conditioning's step time.
            early: ctx.lead + ctx.step_time,
            slowest: self.p.observer.feedforward_speed,
            // The recursion learns nothing while the observer holds the surface for a moving one that
            // started after a calm contact, also on the samples where the predictor's own test does
            // not pass: the tool's answer to the force hides a surface that just started to move on
            // some of them, and learnt in between a sine starting at 3.1 mm/s on 300 kN/m read as a
            // surface 26 % softer. (Right after a touch-down the motion the observer sees is as often
            // a fresh `k̂_c`'s ringing, which the recursion must learn from.)
            state: StepState {
                moving: surface.moving || surface.moving_after_calm,
                drifted: surface.drifted,
                first: ev.contact,
                lifted: s.f < lift,
                disturbed: surface.disturbed,
                jumped,
                filtered: self.p.cell.sensor_delay > 0.0,
            },
            noise_var: ctx.noise.var,
            noise_floor: self.p.response.noise_floor,
        });
        if id.seeded {
            // The observed surface is x − f/k̂_c: a k̂_c that moves would show it moving. While the
            // transient is identified the observers restart on every new k̂_c, at rest.
            self.observer
                .restart(s.xf - s.ff / self.identify.estimate().kc);
        }
        ev.estimator_bound |= id.projected;
        id.seeded
    }

    /// The command before limits: out of contact the state machine's (approach, search, retract), in
    /// contact the law's, held to the approach speed while touching down.
    pub(super) fn command(
        &mut self,
        x: f64,
        s: &Signals,
        th: &contact::Thresholds,
        ctx: &Context,
        est: &Estimate,
        identified: bool,
    ) -> f64 {
        let (anchor, dt) = (ctx.anchor_time(), ctx.dt);
        self.stopping
            .update(&self.p.cell, ctx.cycle, &self.p.limits);
        let speeds = self.contact.speeds(
            est.kc,
            est.kc_rel_sd,
            ctx.set_point,
            self.p.limits.max_force,
            th.strong,
            &self.stopping,
        );
        let u = self.limiter.command();
        let search = self.contact.search_command(&SearchInput {
            x,
            u,
            speeds: &speeds,
            anchor,
            dt,
            identified,
        });
        match search {
            Some(u) => u,
            None => {
                let want = self.in_contact(s, ctx, est);
                self.contact.landing_command(&LandInput {
                    want,
                    u,
                    speeds: &speeds,
                    open: est.onset_open,
                    ff: s.ff,
                    th,
                    confirm: ctx.step_time,
                    dt,
                })
            }
        }
    }
}
