//! Identification of the contact stiffness `k̂_c`.
//!
//! * At a contact made from the approach (a still surface, the force rising from zero while the
//!   position moves in), a hinge least-squares fit on the approach's raw samples and the first
//!   `onset_window` of contact sets `k̂_c` once its slope is significant ([`crate::onset`]; a contact
//!   declared on noise has none). A contact re-acquired after a loss is not
//!   fitted: the surface may be the one moving away. The fit has the velocity as a regressor of its own,
//!   so surface damping `c_e·ẋ` is identified beside `k̂_c` instead of biasing it.
//! * A jump under a steady contact on a still surface opens a re-fit over `refit_window`, judged by its
//!   own consistency (the stale `k̂_c` makes the still surface look moving meanwhile), through the calm
//!   surface before the jump unless a surface step shows; taken early once conclusive, and refined by
//!   the rest of its window (`refit.rs`).
//! * Afterwards the recursive estimator ([`StiffnessEstimator`]) goes on from the fitted values, with
//!   its excitation, dead-zone and motion gates, on the force less the identified damping. After a
//!   re-contact that found the surface moved, or that the fast search made, it waits (`moved.rs`).
//! * In a steady contact the slow least-squares fit ([`SteadyEstimator`]) learns from the loop's answer
//!   to sensor noise, and once confident moves `k̂_c` to its estimate at a bounded rate.

mod landing;
mod moved;
mod params;
mod refit;
mod steady;
pub use landing::TouchDown;
pub use params::{IdentifyParams, StepState};
use refit::Refit;

use crate::estimator::{EstimatorParams, SteadyEstimator, StiffnessEstimator};
use crate::onset::OnsetFit;

/// What a contact step of identification did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Identified {
    /// `k̂_c` was set from the contact transient's fit (the surface observers restart on it).
    pub seeded: bool,
    /// An estimate was projected into the configured bounds.
    pub projected: bool,
}

/// A step in contact's input ([`Identifier::in_contact`]).
#[derive(Clone, Copy, Debug)]
pub struct InContact {
    /// The raw position, m.
    pub x: f64,
    /// The raw force, N.
    pub f: f64,
    /// The raw position's velocity, m/s.
    pub v: f64,
    /// The conditioned force, N.
    pub ff: f64,
    /// The step, s.
    pub dt: f64,
    /// The force is out of its band around the set-point.
    pub off: bool,
    /// A steady contact on a still surface, no transient being fitted or held.
    pub calm: bool,
    /// How long an excursion must last to be one, s.
    pub persist: f64,
    /// The observer saw a still surface jump.
    pub jump_on_still_surface: bool,
    /// A re-fit's samples begin this long after its start, s.
    pub early: f64,
    /// The slowest surface motion a re-fit tells from a change of stiffness, m/s.
    pub slowest: f64,
    /// What the law knows of the step.
    pub state: StepState,
    /// The sensor's noise variance, N².
    pub noise_var: f64,
    /// Its floor, N.
    pub noise_floor: f64,
}

/// The identification's output for the rest of a step ([`Identifier::estimate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// `k̂_c`, N/m.
    pub kc: f64,
    /// Relative standard deviation of `k̂_c`.
    pub kc_rel_sd: f64,
    /// Surface damping `ĉ_e`, N·s/m.
    pub damping: f64,
    /// A contact onset's window is open ([`Identifier::onset_open`]).
    pub onset_open: bool,
    /// A transient is being fitted ([`Identifier::fitting`]).
    pub fitting: bool,
    /// The recursion is held after a re-contact ([`Identifier::held`]).
    pub held: bool,
    /// The force a jump under a steady contact rose to, while its re-fit has not resolved it, N.
    pub unresolved_jump: Option<f64>,
}

/// The stiffness identification.
#[derive(Clone, Debug, PartialEq)]
pub struct Identifier {
    p: IdentifyParams,
    est: StiffnessEstimator,
    onset: OnsetFit,
    steady: SteadyEstimator,
    /// The variance the steady-contact estimator starts with, N².
    steady_var0: f64,
    /// How long the force has been out of its band, s, and whether the contact was calm (steady, on a
    /// still surface, nothing being fitted) when it left.
    off_band: f64,
    calm_at_start: bool,
    /// The re-fit of a transient under a steady contact, while it runs.
    refit: Option<Refit>,
    /// The surface `x − f/k̂_c` of the calm steps since `k̂_c` last moved, averaged over `refit_window`, m.
    calm_surface: f64,
    /// Surface damping identified by the last fit, N·s/m.
    c_e: f64,
    /// The onset fit of this contact has been significant (it set `k̂_c`) at least once.
    onset_seeded: bool,
    /// How long the current window (the touch-down's or a re-fit's) has run, s.
    onset_age: f64,
    /// Time left during which the recursion waits after a re-contact that found the surface moved,
    /// or that the fast search made (`moved.rs`), s.
    recontact_hold: f64,
    /// The estimator and the identified damping as they were before the current touch-down, kept
    /// for [`forget_touch_down`](Self::forget_touch_down).
    before_touch_down: Option<(StiffnessEstimator, f64)>,
}

impl Identifier {
    /// Identification from the estimator's initial guess; `scale` is the estimator's position scale, m,
    /// `noise_floor` the least force noise assumed, N.
    pub fn new(p: IdentifyParams, est: EstimatorParams, noise_floor: f64, scale: f64) -> Self {
        Self {
            p,
            est: StiffnessEstimator::new(est, scale, noise_floor),
            onset: OnsetFit::new(),
            steady: SteadyEstimator::new(p.steady_memory),
            steady_var0: f64::INFINITY,
            off_band: 0.0,
            calm_at_start: false,
            refit: None,
            calm_surface: f64::NAN,
            c_e: 0.0,
            onset_seeded: false,
            onset_age: 0.0,
            recontact_hold: 0.0,
            before_touch_down: None,
        }
    }

    /// Take new parameters, keeping the estimates.
    pub fn set_params(&mut self, p: IdentifyParams, est: EstimatorParams, noise_floor: f64) {
        self.est.set_params(est, noise_floor);
        self.p = p;
    }

    /// Back to the initial guess.
    pub fn reset(&mut self) {
        self.est.reset();
        self.onset.clear();
        self.steady.stop();
        self.steady_var0 = f64::INFINITY;
        self.off_band = 0.0;
        self.refit = None;
        self.calm_surface = f64::NAN;
        self.c_e = 0.0;
        self.recontact_hold = 0.0;
        self.before_touch_down = None;
    }

    /// What is identified now.
    pub fn estimate(&self) -> Estimate {
        Estimate {
            kc: self.kc(),
            kc_rel_sd: self.kc_rel_sd(),
            damping: self.damping(),
            onset_open: self.onset_open(),
            fitting: self.fitting(),
            held: self.held(),
            unresolved_jump: self.unresolved_jump(),
        }
    }

    /// `k̂_c`, N/m.
    pub fn kc(&self) -> f64 {
        self.est.kc()
    }

    /// Surface damping `ĉ_e` identified with `k̂_c`, N·s/m (0 until a fit has seen it).
    pub fn damping(&self) -> f64 {
        self.c_e
    }

    /// Whether a contact onset's window is open (stretched by `onset_patience` while its fit is not
    /// significant).
    pub fn onset_open(&self) -> bool {
        self.onset.active() && self.refit.is_none()
    }

    /// Whether a transient is being fitted.
    pub fn fitting(&self) -> bool {
        self.onset.active() || self.refit.is_some()
    }

    /// Contact is lost: the transient is over.
    fn lost(&mut self) {
        self.onset.stop();
    }

    /// One step in contact: a re-fit begins when the environment changed under a steady contact
    /// (`excursion`, or a jump of a still surface), then the recursion's step
    /// (`step`).
    pub fn in_contact(&mut self, i: &InContact) -> Identified {
        let excursion = self.excursion(i.off, i.calm, i.persist, i.dt);
        if excursion || (i.calm && i.jump_on_still_surface) {
            self.refit(i.x, i.f, i.early, i.slowest);
        }
        self.step(
            i.x,
            i.f,
            i.v,
            i.ff,
            i.dt,
            i.state,
            i.noise_var,
            i.noise_floor,
        )
    }

    /// One step in contact with the raw `(x, f)`, the raw position's velocity `v` and conditioned force
    /// `ff`, what the law knows of the step (`state`), and the sensor's noise `noise_var`, N², and its
    /// floor `noise_floor`, N.
    #[allow(clippy::too_many_arguments)]
    fn step(
        &mut self,
        x: f64,
        f: f64,
        v: f64,
        ff: f64,
        dt: f64,
        state: StepState,
        noise_var: f64,
        noise_floor: f64,
    ) -> Identified {
        let StepState {
            moving,
            drifted,
            first,
            lifted,
            disturbed,
            jumped,
            filtered,
        } = state;
        if self.hold_step(dt) {
            return Identified::default();
        }
        // A surface seen moving ends a window, but not a touch-down's before its fit is significant:
        // the surface is seen through `k̂_c`, and the tuning's guess shows the tool's own motion as
        // the surface's (on 12.6 kN/m, four times softer than the guess, three quarters of it).
        if moving && self.refit.is_none() && self.onset_seeded {
            self.onset.stop();
        }
        let onset = self.onset.active();
        if onset && !first {
            // A sample off the surface (a bounce within the window: the force below the lift force,
            // the position behind the surface the fit so far has) lies on the hinge's flat part, not
            // on the spring's line: it counts the window's time only (f_r 2.6 N on 355 kN/m on the
            // 12 ms cell: one bounce sample at 0 N took the fit from 340 to 164 kN/m). So is, in a
            // touch-down, a sample behind that surface beyond the fit's doubt whatever its force: a
            // sensor's own filter still shows a contact that ended between two samples (1.47 N 51 µm
            // behind a 500 kN/m surface through 100 Hz on the 12 ms cell took the fit from 397 to
            // 116 kN/m). Not in a re-fit: a stiffness change's transient can lie behind the line
            // of its first samples (a doubling at f_r 37 N on 21.6 kN/m kept the stale `k̂_c`).
            let touch_down = self.refit.is_none();
            let off = self
                .onset
                .line_at(x, noise_var.max(noise_floor * noise_floor))
                .is_some_and(|(line, sd)| {
                    (lifted && line < 0.0)
                        || (touch_down && line + crate::robust::contact::SIGNIFICANCE * sd < 0.0)
                });
            if off {
                self.onset.pass(dt);
            } else {
                self.onset.add(x, f, v, dt);
            }
            self.onset_age += dt;
        }
        let fit = match self.refit {
            // A contact onset: the fit so far, every step, once its slope is significant (a contact
            // declared on noise has no force rising with the position to fit).
            None if onset => self.onset_fit(noise_var, dt),
            None => None,
            // A re-fit: as soon as it is conclusive, at the latest at the window's end.
            Some(_) => self.judge_refit(x, f, noise_var, noise_floor, filtered),
        };
        match fit {
            Some(fit) => {
                let projected = self.est.seed(&fit, x, ff);
                self.calm_surface = f64::NAN;
                let r = noise_var.max(fit.residual_var);
                let r = r.max(noise_floor * noise_floor);
                self.c_e = refit::damping(&fit, r, self.p.pivot_gate) / self.est.scale();
                self.steady.stop();
                self.steady_var0 = self.est.seed_variance();
                Identified {
                    seeded: true,
                    projected,
                }
            }
            // While a re-fit runs the recursion waits for it: fed the transient with a stale `k̂_c`
            // it jumps, and the observed surface `x − f/k̂_c` jumps with it (taken for motion). So it
            // does on a jump's first sample, before the re-fit opens: no excitation (a damped halving
            // on the 12 ms cell took `k̂_c` 36 % the wrong way in that one step, the re-fit judged
            // against it, and `k̂_c` ended 19 % off).
            None if self.refit.is_some() || jumped => Identified::default(),
            None => {
                // The spring's force: the identified damping's share taken out.
                let f_spring = f - self.c_e * v;
                let up = self
                    .est
                    .update(x, f_spring, ff, noise_var.sqrt(), dt, moving || drifted);
                let r = noise_var.max(noise_floor * noise_floor);
                let calm = !(moving || drifted || up.adapted || disturbed);
                if up.adapted {
                    self.calm_surface = f64::NAN;
                } else if calm {
                    let z = x - f_spring / self.est.kc();
                    let a = (dt / self.p.refit_window).min(1.0);
                    self.calm_surface = if self.calm_surface.is_finite() {
                        self.calm_surface + a * (z - self.calm_surface)
                    } else {
                        z
                    };
                }
                self.steady_step(x, f_spring, dt, !calm, r);
                Identified {
                    seeded: false,
                    projected: up.projected,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
