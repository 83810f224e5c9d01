//! The robust force law: forcecell's own mode beside the paper's.
//!
//! # The law (in contact)
//! With the measured position `x`, the conditioned force `f̃`, the stiffness estimate `k̂_c` and the
//! force set-point `f_r`, the command is
//!
//! `x_cmd = x + κ·(f_r − f̃)/k̂_c + FF + I`, `İ = k_i·(f_r − f̃)/k̂_c` (clamped),
//!
//! i.e. "go to where the spring would give `f_r`", anchored on the position the robot *reports* rather
//! than on an internal integrator. Written as the paper's eq. 23, it is `x_cmd = x̃_c + [κ·f_r +
//! (1 − κ)·f̃]/k̂_c` with the surface observed directly, `x̃_c = x − f̃/k̂_c`, instead of estimated slowly.
//!
//! Why this shape: the robot's inner loop `P(s) = e^{−sT_d}/(τs + 1)` carries the command to the
//! position, so with `g = κ·k_c/k̂_c` the closed loop's characteristic equation is
//! `e^{sT_d}·(τs + 1) = F(s)·(1 − g)` (`F` the conditioning low-pass, applied to position and force
//! alike). For `Re s ≥ 0` the left side has modulus ≥ 1 and the right side < 1 whenever `0 < g < 2`:
//! **the proportional loop is stable for any delay and any lag as long as `k̂_c > κ·k_c/2`**. The
//! estimator only has to be roughly right for stability, and right for speed. (The feed-forward and the
//! small integral below sit outside this argument; the scenario tests B1–B9 and the delay sweep B7 are
//! what covers them.) The proportional correction is also weighted by `e²/(e² + (gate·σ)²)` — `e` the
//! force error, `σ` the sensor noise measured online — which only lowers `g`.
//!
//! Moving surfaces (the feed-forward `FF`): with everything filtered alike, the proportional path
//! stands on the conditioned surface `x̃_c`, which lags the true one by the conditioning, and the robot
//! adds its delay `T_d` and lag `τ`; on a surface moving at `v_c` that costs `k_c·v_c·(lag)` of force
//! (440 N per second of lag at 1 mm, 1 Hz). A Kalman filter on the surface's position, velocity and
//! acceleration ([`crate::predictor`]) is run on the *raw* pseudo-measurement `x − f/k̂_c` (no
//! conditioning lag), with the measured sensor noise as its measurement noise (a clean sensor gives a
//! fast predictor, a noisy one a slow one); `FF` is the command that puts the tool on the surface
//! predicted `T_d` ahead through the inverted lag, less `x̃_c`:
//! `FF = w·(x̂_c(t + T_d) + [x̂_c(t + T_d + dt) − x̂_c(t + T_d)]/α − x̃_c)`, `α = 1 − e^{−dt/τ}`.
//! With a perfect prediction the loop's characteristic equation is the one above, so the feed-forward
//! does not change stability; what it changes is what a *wrong* `k̂_c` does: then `x − f/k̂_c` moves
//! with the robot (`(1 − k_c/k̂_c)·ẋ`) and a predictor would feed that back. So the weight `w` is 0
//! until the estimator's motion test ([`surface_moving`]: observed motion that leads or exceeds the
//! robot's, on the conditioned pair, or on the raw pair for 8 ms without a break) has
//! seen real surface motion within the last 0.5 s (or the predicted surface velocity has kept its sign
//! while the robot moved both with it and against it — which the apparent motion of a stale `k̂_c`,
//! tied to the robot's, never does; that also keeps the estimator off the moving surface, whose
//! transients after a re-contact otherwise drag `k̂_c` down until the loop bounces), and it is then
//! `m²/(m² + 1)` with `m` the estimated velocity and acceleration in units of their own uncertainty
//! (noise is not motion).
//! While `w < 1` the rest of `FF` is the older fallback: the conditioned observer's velocity over the
//! whole lead time, outside a noise dead-band. The small integral `I` removes what a wrong model of the
//! inner loop leaves.
//!
//! # Identification at first contact
//! The approach into a still surface is the one excitation the law can count on: the force rises from
//! zero while the position moves in. Contact is declared on the conditioned force, after most of that
//! rise, so the raw samples of the approach are kept and, at a contact made from `Approach`, a hinge
//! least-squares fit on them and on the first 0.1 s of contact sets `k̂_c`
//! ([`crate::onset`]), combined with the previous estimate at the estimator's initial uncertainty. During
//! that window the recursive estimator is not run and the surface observers restart at rest on every new
//! `k̂_c` (through a changing `k̂_c` a still surface would look as if it moved), so the law is the
//! proportional path and the integral; afterwards the estimator goes on from the fitted values with the
//! covariance of a contact onset. A contact re-acquired after a loss is not fitted: the surface may be
//! the one moving away.
//!
//! In a steady contact a second, slow least-squares fit ([`crate::estimator::SteadyEstimator`]) learns
//! from the only motion there is, the loop's answer to sensor noise (the position measured at an instant
//! does not depend on that instant's noise, so the fit is unbiased; a linearly drifting bias is one of
//! its terms). It starts from the transient's estimate and uncertainty, runs only while nothing moves,
//! jumps or excites the recursive estimator (any of these restarts it), stops learning once its relative
//! standard deviation is 2 %, and, once below 10 %, moves `k̂_c` to its estimate at no more than 2 %/s.
//! Without noise it learns nothing and leaves `k̂_c` alone.
//!
//! # Contact state machine
//! `Approach` (bounded speed, anchored to the measured position) → `Contact` when the conditioned force
//! reaches `contact_force` (or one raw sample three times that) → `Reacquire` when the raw force stays
//! below `lift_force` for `lift_time` (fast for `reacquire_distance`, then at approach speed) →
//! `Contact` … and from anywhere `Retract` when the conditioned force exceeds `max_force`.
//!
//! # Limits
//! Deviation from the programmed path, command velocity and acceleration (with braking distance), the
//! estimator's bounds and the force limit. Every one that acts is an [`Events`] flag of the step and a
//! counter ([`ForceLaw::counters`]).

use serde::{Deserialize, Serialize};

use crate::conditioning::{ConditioningParams, SignalFilter};
use crate::estimator::{EstimatorParams, SteadyEstimator, StiffnessEstimator, surface_moving};
use crate::law::{ContactState, EventCounts, Events, ForceLaw, Output};
use crate::onset::OnsetFit;
use crate::predictor::SurfacePredictor;

/// How the law responds in contact.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResponseParams {
    /// Fraction `κ` of the force error, converted to a position by `k̂_c`, corrected per command. In
    /// (0, 1]; the loop stays stable while `κ·k_c/k̂_c < 2`.
    pub kappa: f64,
    /// First-order lag `τ` of the robot's inner position loop, s (inverted by the feed-forward).
    pub lag: f64,
    /// Pure delay of the inner loop and the interface, s: the surface is predicted this far ahead …
    pub delay: f64,
    /// … plus this many control periods (robot interfaces delay by whole cycles; with the fixed part
    /// one tuning then fits a 1 kHz and a 250 Hz cell), periods.
    #[serde(default)]
    pub delay_cycles: f64,
    /// Integral gain `k_i`, 1/s (0: none).
    pub integral: f64,
    /// Largest magnitude of the integral term, m.
    pub integral_limit: f64,
    /// Natural frequency of the surface observer the estimator's motion test and the reported `x̂_c`
    /// use, Hz.
    pub surface_bandwidth: f64,
    /// Spectral density of the surface's jerk in the surface predictor's model, m²/s⁵. With the
    /// measured sensor noise it sets the predictor's bandwidth (see [`crate::predictor`]).
    pub surface_jerk: f64,
    /// Floor of the force noise the predictor assumes, N (quantisation, model error).
    pub noise_floor: f64,
    /// Dead-band of the fallback feed-forward per newton of sensor noise, (m/s)/N. While no real
    /// surface motion is established (see [`crate::estimator::surface_moving`]) the law feeds the
    /// conditioned observer's velocity forward over the loop's lead time instead of the prediction;
    /// inside `σ·feedforward_deadband` that velocity is taken for differentiated noise.
    pub feedforward_deadband: f64,
    /// Largest rate of change of the set-point when it is changed, N/s (bumpless changes).
    pub set_point_rate: f64,
    /// Noise gate: the proportional correction is weighted by `e²/(e² + (noise_gate·σ)²)`, with `e` the
    /// conditioned force error and `σ` the sensor noise the law measures online. 0 switches it off.
    /// Errors well above the noise get the full gain, errors inside it a small one (the integral keeps
    /// the mean), so noise does not shake the tool.
    pub noise_gate: f64,
}

/// The contact state machine.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactParams {
    /// Speed towards an unknown surface, m/s.
    pub approach_speed: f64,
    /// Conditioned force that means contact, N.
    pub contact_force: f64,
    /// Raw force below which contact is lost, N (< `contact_force`).
    pub lift_force: f64,
    /// How long the force must stay below `lift_force`, s.
    pub lift_time: f64,
    /// Speed after a loss of contact, m/s.
    pub reacquire_speed: f64,
    /// Distance covered at `reacquire_speed` before falling back to `approach_speed`, m.
    pub reacquire_distance: f64,
    /// Speed away from the surface after the force limit, m/s.
    pub retract_speed: f64,
    /// Distance to retract before approaching again, m.
    pub retract_distance: f64,
}

/// Hard limits. Each one that acts is reported.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LimitParams {
    /// Conditioned force above which the law retracts, N.
    pub max_force: f64,
    /// Largest command velocity, m/s.
    pub max_velocity: f64,
    /// Largest command acceleration, m/s².
    pub max_acceleration: f64,
    /// Largest magnitude of the command, i.e. deviation from the programmed path along the normal, m.
    pub max_deviation: f64,
}

/// Everything the robust law needs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobustParams {
    /// Force set-point `f_r`, N.
    pub f_r: f64,
    /// Response in contact.
    pub response: ResponseParams,
    /// Force conditioning.
    pub conditioning: ConditioningParams,
    /// Stiffness estimator.
    pub estimator: EstimatorParams,
    /// Contact state machine.
    pub contact: ContactParams,
    /// Limits.
    pub limits: LimitParams,
}

fn positive(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be > 0, got {v}"))
    }
}

fn non_negative(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be >= 0, got {v}"))
    }
}

impl RobustParams {
    /// Checks every value and the relations between them.
    pub fn validate(&self) -> Result<(), String> {
        non_negative("f_r", self.f_r)?;
        let r = &self.response;
        positive("response.kappa", r.kappa)?;
        if r.kappa > 1.0 {
            return Err(format!("response.kappa must be <= 1, got {}", r.kappa));
        }
        non_negative("response.lag", r.lag)?;
        non_negative("response.delay", r.delay)?;
        non_negative("response.delay_cycles", r.delay_cycles)?;
        non_negative("response.integral", r.integral)?;
        non_negative("response.integral_limit", r.integral_limit)?;
        positive("response.surface_bandwidth", r.surface_bandwidth)?;
        positive("response.surface_jerk", r.surface_jerk)?;
        positive("response.noise_floor", r.noise_floor)?;
        non_negative("response.feedforward_deadband", r.feedforward_deadband)?;
        positive("response.set_point_rate", r.set_point_rate)?;
        non_negative("response.noise_gate", r.noise_gate)?;
        self.conditioning.validate()?;
        self.estimator.validate()?;
        let c = &self.contact;
        positive("contact.approach_speed", c.approach_speed)?;
        positive("contact.contact_force", c.contact_force)?;
        non_negative("contact.lift_force", c.lift_force)?;
        non_negative("contact.lift_time", c.lift_time)?;
        positive("contact.reacquire_speed", c.reacquire_speed)?;
        non_negative("contact.reacquire_distance", c.reacquire_distance)?;
        positive("contact.retract_speed", c.retract_speed)?;
        non_negative("contact.retract_distance", c.retract_distance)?;
        if c.lift_force >= c.contact_force {
            return Err(format!(
                "contact.lift_force {} N must be below contact.contact_force {} N",
                c.lift_force, c.contact_force
            ));
        }
        let l = &self.limits;
        positive("limits.max_force", l.max_force)?;
        positive("limits.max_velocity", l.max_velocity)?;
        positive("limits.max_acceleration", l.max_acceleration)?;
        positive("limits.max_deviation", l.max_deviation)?;
        if l.max_force <= self.f_r.max(c.contact_force) {
            return Err(format!(
                "limits.max_force {} N must be above the set-point {} N and contact.contact_force",
                l.max_force, self.f_r
            ));
        }
        for (n, v) in [
            ("contact.approach_speed", c.approach_speed),
            ("contact.reacquire_speed", c.reacquire_speed),
            ("contact.retract_speed", c.retract_speed),
        ] {
            if v > l.max_velocity {
                return Err(format!(
                    "{n} {v} m/s is above limits.max_velocity {} m/s",
                    l.max_velocity
                ));
            }
        }
        Ok(())
    }

    /// Position scale of the estimator's regressor: the penetration the set-point needs at `k̂_c(0)`, m.
    fn scale(&self) -> f64 {
        self.f_r.max(1.0) / self.estimator.kc0
    }
}

/// Time constant of the sensor-noise estimate, s.
const NOISE_WINDOW: f64 = 1.0;
/// Floor of the clipping level of the noise estimate, N.
const NOISE_FLOOR: f64 = 0.05;

/// A loss of contact sooner than this after contact was detected is a bounce, s.
const BOUNCE_TIME: f64 = 0.5;

/// Innovation of the surface predictor, in its own standard deviations, beyond which (and beyond the
/// jump floor [`STEP_INNOVATION`]) a measurement is a jump.
const JUMP_GATE: f64 = 6.0;

/// Smallest dead-band on the fallback feed-forward velocity, m/s (transients of the observer).
const DEADBAND_FLOOR: f64 = 0.0001;

/// How long the feed-forward stays on after the estimator's motion test last saw real surface motion, s
/// (it passes through zero velocity at every turn of a curved surface).
const MOTION_HOLD: f64 = 0.5;

/// How long the predictor must see surface motion without a break before it is believed, s.
const MOTION_CONFIRM: f64 = 0.008;

/// How long the robot must have moved both with and against one run of surface velocity for that
/// run to count as real motion, s.
const OPPOSED_CONFIRM: f64 = 0.01;

/// Significance, in standard deviations of the predictor's estimate, at which the fed-forward motion
/// gets half its weight.
const MOTION_SIGNIFICANCE: f64 = 3.0;

/// An observed-surface innovation above this fraction of the set-point's penetration `f_r/k̂_c` in one
/// step is a jump, not motion.
const STEP_INNOVATION: f64 = 0.25;

/// How long large innovations count as one jump rather than motion, s (a step needs about this long
/// to pass the force conditioning).
const JUMP_TIME: f64 = 0.03;

/// How long after contact is declared the contact transient is identified by least squares, s.
const ONSET_WINDOW: f64 = 0.1;

/// Forgetting time of the steady-contact estimator, s.
const STEADY_MEMORY: f64 = 3600.0;
/// How long the steady-contact estimator must have run before it is used, s.
const STEADY_MIN_AGE: f64 = 1.0;
/// Relative standard deviation below which the steady-contact estimate is used.
const STEADY_CONFIDENCE: f64 = 0.1;
/// Relative standard deviation at which the steady-contact estimator stops learning.
const STEADY_DONE: f64 = 0.02;
/// Largest relative rate at which the steady-contact estimate moves `k̂_c`, 1/s.
const STEADY_RATE: f64 = 0.02;

/// Relative force error within which the integral acts.
const INTEGRATION_BAND: f64 = 0.3;

/// The robust law. See the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct RobustLaw {
    p: RobustParams,
    state: ContactState,
    /// Active set-point, slewing towards `p.f_r`, N.
    f_r: f64,
    force: SignalFilter,
    position: SignalFilter,
    est: StiffnessEstimator,
    /// Stiffness from the contact transient (see [`crate::onset`]).
    onset: OnsetFit,
    /// Stiffness from a steady contact under sensor noise, and the variance it starts with, N².
    steady: SteadyEstimator,
    steady_var0: f64,
    /// How long the observer's innovation has been a jump, s.
    jump_time: f64,
    /// Observed surface, m, and its velocity, m/s.
    zc: f64,
    vc: f64,
    /// Surface predictor on the raw pseudo-measurement, and how long its innovation has been a jump, s.
    pred: SurfacePredictor,
    pred_jump_time: f64,
    /// Time left during which the surface counts as moving, s.
    motion_hold: f64,
    /// How long the predictor has seen surface motion without a break, s.
    motion_time: f64,
    /// Sign of the predictor's current run of surface velocity (0: none), and how long within it the
    /// robot moved with it and against it, s.
    run_sign: f64,
    run_with: f64,
    run_against: f64,
    /// Time left during which the estimator takes the surface for a moving one, s.
    est_hold: f64,
    integ: f64,
    /// Last command, m, and its velocity, m/s.
    u: f64,
    v: f64,
    /// Time the raw force has been below the lift force, s.
    below: f64,
    /// Distance travelled in the current re-acquire or retract, m.
    travelled: f64,
    /// Time since contact was last detected, s.
    in_contact: f64,
    /// The observed surface velocity away from the tool when contact was last lost, m/s.
    v_lost: f64,
    /// The two previous raw forces, N, and the sensor noise variance measured from them, N².
    f_prev: Option<(f64, f64)>,
    /// Previous conditioned position, m, and its velocity, m/s.
    xf_prev: Option<f64>,
    v_x: f64,
    /// Previous measured position, m, and the velocity from it, m/s.
    x_prev: Option<f64>,
    v_raw: f64,
    noise_var: f64,
    counts: EventCounts,
}

impl RobustLaw {
    /// A law with validated parameters, at rest at 0.
    pub fn new(p: RobustParams) -> Result<Self, String> {
        p.validate()?;
        let position_params = ConditioningParams {
            notch: None,
            ..p.conditioning
        };
        Ok(Self {
            state: ContactState::Approach,
            f_r: p.f_r,
            force: SignalFilter::new(p.conditioning),
            position: SignalFilter::new(position_params),
            est: StiffnessEstimator::new(p.estimator, p.scale()),
            onset: OnsetFit::new(),
            steady: SteadyEstimator::new(STEADY_MEMORY),
            steady_var0: f64::INFINITY,
            jump_time: 0.0,
            zc: f64::NAN,
            vc: 0.0,
            pred: SurfacePredictor::new(),
            pred_jump_time: 0.0,
            motion_hold: 0.0,
            motion_time: 0.0,
            run_sign: 0.0,
            run_with: 0.0,
            run_against: 0.0,
            est_hold: 0.0,
            integ: 0.0,
            u: 0.0,
            v: 0.0,
            below: 0.0,
            travelled: 0.0,
            in_contact: f64::INFINITY,
            v_lost: 0.0,
            f_prev: None,
            xf_prev: None,
            v_x: 0.0,
            x_prev: None,
            v_raw: 0.0,
            noise_var: 0.0,
            counts: EventCounts::default(),
            p,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &RobustParams {
        &self.p
    }

    /// The contact state.
    pub fn state(&self) -> ContactState {
        self.state
    }

    /// The set-point in force now (it slews towards a new one), N.
    pub fn active_set_point(&self) -> f64 {
        self.f_r
    }

    /// Change the parameters while running, without a bump: the estimates, filters, contact state and
    /// command are kept, a new set-point is approached at `set_point_rate`, and the velocity and
    /// acceleration limits keep acting on the command.
    pub fn set_params(&mut self, p: RobustParams) -> Result<(), String> {
        p.validate()?;
        self.force.set_params(p.conditioning);
        self.position.set_params(ConditioningParams {
            notch: None,
            ..p.conditioning
        });
        self.est.set_params(p.estimator);
        self.p = p;
        Ok(())
    }

    /// Change the force set-point only (bumpless, see [`set_params`](Self::set_params)).
    pub fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        let mut p = self.p;
        p.f_r = f_r;
        self.set_params(p)
    }

    fn output(&self, events: Events) -> Output {
        let k = self.est.kc();
        Output {
            x_cmd: self.u,
            x_r: self.zc + self.f_r / k,
            kc_hat: k,
            xc_hat: self.zc,
            state: Some(self.state),
            events,
        }
    }

    fn enter_contact(&mut self, x: f64, f: f64, ff: f64, xf: f64, ev: &mut Events) {
        self.est.begin_contact(x, f);
        // A contact made from the approach is made on a still surface; one re-acquired after a loss
        // of contact may be on a surface that is moving away (the loss says so): the recursion alone
        // learns from that one, behind its motion gate.
        if self.state == ContactState::Approach {
            self.onset.begin(x, self.est.scale(), ONSET_WINDOW);
        } else {
            self.onset.clear();
        }
        self.steady.stop();
        self.steady_var0 = f64::INFINITY;
        self.state = ContactState::Contact;
        self.zc = xf - ff / self.est.kc();
        self.vc = 0.0;
        self.pred.clear();
        self.pred_jump_time = 0.0;
        self.motion_time = 0.0;
        self.run_sign = 0.0;
        self.integ = 0.0;
        self.below = 0.0;
        self.in_contact = 0.0;
        ev.contact = true;
    }

    /// Advance the contact state machine with the raw force `f` and the conditioned force `ff`.
    fn transitions(&mut self, x: f64, f: f64, ff: f64, xf: f64, dt: f64, ev: &mut Events) {
        let c = self.p.contact;
        if ff > self.p.limits.max_force && self.state != ContactState::Retract {
            ev.force_limit = true;
            self.state = ContactState::Retract;
            self.travelled = 0.0;
            return;
        }
        match self.state {
            ContactState::Approach | ContactState::Reacquire => {
                // The conditioned force, confirmed by the raw one (the filter still remembers a
                // contact just lost), or one strong raw sample.
                if (ff >= c.contact_force && f >= c.lift_force) || f >= 3.0 * c.contact_force {
                    self.enter_contact(x, f, ff, xf, ev);
                }
            }
            ContactState::Contact => {
                self.in_contact += dt;
                if f < c.lift_force {
                    self.below += dt;
                    if self.below >= c.lift_time {
                        self.state = ContactState::Reacquire;
                        // The fast search is for a surface that went away. A contact lost while the
                        // tool itself was moving away (the law's own answer to a force jump), or lost
                        // again soon after a re-acquisition (a bounce), is searched for at approach
                        // speed.
                        let retracting = self.v_x < -c.approach_speed;
                        self.travelled = if !retracting && self.in_contact >= BOUNCE_TIME {
                            0.0
                        } else {
                            c.reacquire_distance
                        };
                        ev.lift_off = true;
                        self.onset.stop();
                        self.v_lost = self.vc.max(0.0);
                        // The force is gone: forget the filter's memory of it.
                        self.force.reset_to(f);
                    }
                } else {
                    self.below = 0.0;
                }
            }
            ContactState::Retract => {
                if self.travelled >= c.retract_distance && ff < c.lift_force {
                    self.state = ContactState::Approach;
                }
            }
        }
    }

    /// The command the state wants before limits.
    fn desired(&mut self, x: f64, f: f64, ff: f64, xf: f64, dt: f64) -> f64 {
        let c = self.p.contact;
        let r = self.p.response;
        match self.state {
            ContactState::Approach => {
                // Anchored: never more than a few lead times of approach ahead of the robot.
                let gap = c.approach_speed * self.anchor_time(dt);
                (self.u + c.approach_speed * dt).min(x + gap)
            }
            ContactState::Reacquire => {
                // Fast first; then at approach speed, or faster when the surface was seen receding at
                // lift-off (a receding surface outruns a slow search).
                let speed = if self.travelled < c.reacquire_distance {
                    c.reacquire_speed
                } else {
                    (c.approach_speed + 1.5 * self.v_lost).min(c.reacquire_speed)
                };
                self.travelled += speed * dt;
                let gap = c.reacquire_distance + c.approach_speed * self.anchor_time(dt);
                (self.u + speed * dt).min(x + gap)
            }
            ContactState::Retract => {
                self.travelled += c.retract_speed * dt;
                self.u - c.retract_speed * dt
            }
            ContactState::Contact => {
                let k = self.est.kc();
                // Surface observer: second-order tracker on x̃_c = x̄ − f̃/k̂_c.
                let z = xf - ff / k;
                let w = core::f64::consts::TAU * r.surface_bandwidth;
                let w = w.min(0.5 / dt);
                let e = z - self.zc;
                let jump =
                    e.abs() > STEP_INNOVATION * self.f_r.max(self.p.contact.contact_force) / k;
                self.jump_time = if jump { self.jump_time + dt } else { 0.0 };
                if jump && self.jump_time <= JUMP_TIME {
                    // A jump (a surface step, a stiffness change seen through a stale k̂_c) is not
                    // motion: the observed surface moves there without a velocity kick. What keeps
                    // jumping for longer than the conditioning takes to pass a step is motion.
                    self.zc = z;
                } else {
                    self.vc += dt * w * w * e;
                    self.zc += dt * (self.vc + 2.0 * 0.8 * w * e);
                }
                let e = self.f_r - ff;
                let n = r.noise_gate * r.noise_gate * self.noise_var;
                let weight = if n > 0.0 { e * e / (e * e + n) } else { 1.0 };
                let delta = e / k;
                // Conditional integration: only near the set-point, where what is left is a ramp's lag
                // (a transient's error is the proportional path's business, integrating it overshoots).
                if (self.f_r - ff).abs()
                    <= INTEGRATION_BAND * self.f_r.max(self.p.contact.contact_force)
                {
                    let lim = r.integral_limit;
                    self.integ = (self.integ + dt * r.integral * delta).clamp(-lim, lim);
                }
                // Feed-forward: the predicted surface through the inverted inner loop, less the
                // conditioned surface the proportional path already stands on.
                let floor = r.noise_floor;
                let var = (self.noise_var + floor * floor) / (k * k);
                let jump_floor = STEP_INNOVATION * self.f_r.max(self.p.contact.contact_force) / k;
                let jump_floor = if self.pred_jump_time <= JUMP_TIME {
                    jump_floor
                } else {
                    f64::INFINITY
                };
                let jumped =
                    self.pred
                        .update(x - f / k, var, r.surface_jerk, dt, JUMP_GATE, jump_floor);
                self.pred_jump_time = if jumped {
                    self.pred_jump_time + dt
                } else {
                    0.0
                };
                let delay = r.delay + r.delay_cycles * dt;
                let ahead = self.pred.command(0.0, delay, r.lag, dt, 1.0, 1.0);
                let z_f = xf - ff / k;
                // Only real surface motion (not the apparent one of a stale k̂_c), and only as far as it
                // stands out of the predictor's own uncertainty (not noise).
                let [_, v, a] = self.pred.state();
                // The same test on the unfiltered pair sees motion without the conditioning's lag.
                // It must hold for a while: the apparent motion of a stale k̂_c passes it briefly where
                // the robot turns.
                if jumped {
                    // A jump says nothing about motion either way.
                } else if surface_moving(v, self.v_raw, self.p.estimator.max_surface_speed) {
                    self.motion_time += dt;
                    if self.motion_time >= MOTION_CONFIRM {
                        self.motion_hold = MOTION_HOLD;
                    }
                } else {
                    self.motion_time = 0.0;
                }
                // The apparent motion of a stale k̂_c is tied to the robot's: with it (k̂_c too high)
                // or against it (too low), turning when the robot turns. A surface velocity that keeps
                // its sign while the robot has moved both with it and against it is real motion.
                let thr = self.p.estimator.max_surface_speed;
                if !jumped {
                    if v.abs() > thr {
                        if v.signum() != self.run_sign {
                            self.run_sign = v.signum();
                            self.run_with = 0.0;
                            self.run_against = 0.0;
                        }
                        if self.v_raw.abs() > thr {
                            if self.v_raw * v > 0.0 {
                                self.run_with += dt;
                            } else {
                                self.run_against += dt;
                            }
                        }
                        if self.run_with >= OPPOSED_CONFIRM && self.run_against >= OPPOSED_CONFIRM {
                            self.est_hold = MOTION_HOLD;
                            self.motion_hold = MOTION_HOLD;
                        }
                    } else {
                        self.run_sign = 0.0;
                    }
                }
                let sv = MOTION_SIGNIFICANCE * self.pred.velocity_std();
                let sa = MOTION_SIGNIFICANCE * self.pred.acceleration_std();
                let m2 = v * v / (sv * sv + 1e-30) + a * a / (sa * sa + 1e-30);
                let w_ff = if self.motion_hold > 0.0 {
                    m2 / (m2 + 1.0)
                } else {
                    0.0
                };
                // Fallback: the conditioned observer's velocity over the whole lead time.
                let deadband = (r.feedforward_deadband * self.noise_var.sqrt()).max(DEADBAND_FLOOR);
                let v_ff = self.vc.signum() * (self.vc.abs() - deadband).max(0.0);
                let lead = r.lag + delay + self.conditioning_delay(dt);
                let fallback = lead * v_ff;
                xf + weight * r.kappa * delta
                    + w_ff * (ahead - z_f)
                    + (1.0 - w_ff) * fallback
                    + self.integ
            }
        }
    }

    /// The steady-contact estimator (see [`SteadyEstimator`]): runs while nothing moves, nothing jumps
    /// and the recursive estimator does not adapt, and once confident moves `k̂_c` to its estimate
    /// at a bounded rate.
    fn steady_step(&mut self, x: f64, f: f64, dt: f64, disturbed: bool) {
        let disturbed = disturbed
            || self.motion_hold > 0.0
            || self.est_hold > 0.0
            || self.jump_time > 0.0
            || self.pred_jump_time > 0.0;
        if disturbed {
            self.steady.stop();
            self.steady_var0 = f64::INFINITY;
            return;
        }
        if !self.steady.active() {
            let s = self.est.scale();
            let theta0 = self.est.kc() * s;
            let u = self.p.estimator.initial_uncertainty * theta0;
            let var0 = self.steady_var0.min(u * u);
            self.steady.start(x, self.est.predict(x), theta0, var0, s);
            self.steady_var0 = f64::INFINITY;
            return;
        }
        // Learnt: a steady contact has nothing more to teach, and a sensor bias that has drifted as
        // far as the set-point lifts the tool off unseen (the law holds the measured force), which
        // would teach it wrong.
        let learnt = self
            .steady
            .estimate()
            .is_some_and(|(_, rel)| rel <= STEADY_DONE);
        if !learnt {
            let floor = self.p.response.noise_floor;
            self.steady
                .update(x, f, self.noise_var.max(floor * floor), dt);
        }
        if let Some((k, rel)) = self.steady.estimate()
            && self.steady.age() >= STEADY_MIN_AGE
            && rel <= STEADY_CONFIDENCE
        {
            let now = self.est.kc();
            let step = STEADY_RATE * dt * now;
            self.est.set_kc(now + (k - now).clamp(-step, step), x);
        }
    }

    /// How far ahead of the robot the approach may command, in time at approach speed, s.
    fn anchor_time(&self, dt: f64) -> f64 {
        let r = &self.p.response;
        (4.0 * (r.lag + r.delay + r.delay_cycles * dt + self.conditioning_delay(dt))).max(0.05)
    }

    /// Low-frequency group delay of the force and position conditioning, s.
    fn conditioning_delay(&self, dt: f64) -> f64 {
        core::f64::consts::SQRT_2
            / (core::f64::consts::TAU * self.p.conditioning.cutoff.min(0.45 / dt))
    }

    /// Apply deviation, velocity and acceleration limits to `want`, flagging each one that acts.
    fn limit(&mut self, want: f64, dt: f64, ev: &mut Events) -> f64 {
        let l = self.p.limits;
        let mut target = want;
        if target.abs() > l.max_deviation {
            target = target.clamp(-l.max_deviation, l.max_deviation);
            ev.deviation_limit = true;
        }
        let dist = target - self.u;
        let mut v = dist / dt;
        if v.abs() > l.max_velocity {
            v = v.clamp(-l.max_velocity, l.max_velocity);
            ev.velocity_limit = true;
        }
        // Braking: never faster than what can still stop at the target (not a limit event: it is how
        // an acceleration-limited command reaches a target without overshoot).
        // Discrete time: the largest speed from which steps of at most `a·dt` velocity change still
        // stop within `dist`.
        let half = 0.5 * l.max_acceleration * dt;
        let v_brake = (half * half + 2.0 * l.max_acceleration * dist.abs()).sqrt() - half;
        v = v.clamp(-v_brake, v_brake);
        let dv = l.max_acceleration * dt;
        if (v - self.v).abs() > dv * (1.0 + 1e-9) {
            v = v.clamp(self.v - dv, self.v + dv);
            ev.acceleration_limit = true;
        }
        let mut u = self.u + v * dt;
        if u.abs() > l.max_deviation {
            u = u.clamp(-l.max_deviation, l.max_deviation);
            v = (u - self.u) / dt;
            ev.deviation_limit = true;
        }
        self.v = v;
        u
    }
}

impl ForceLaw for RobustLaw {
    fn start(&mut self, x: f64) {
        self.state = ContactState::Approach;
        self.f_r = self.p.f_r;
        self.force.clear();
        self.position.clear();
        self.est.reset();
        self.onset.clear();
        self.steady.stop();
        self.steady_var0 = f64::INFINITY;
        self.zc = f64::NAN;
        self.jump_time = 0.0;
        self.vc = 0.0;
        self.pred.clear();
        self.pred_jump_time = 0.0;
        self.motion_hold = 0.0;
        self.motion_time = 0.0;
        self.run_sign = 0.0;
        self.est_hold = 0.0;
        self.integ = 0.0;
        self.u = if x.is_finite() { x } else { 0.0 };
        self.v = 0.0;
        self.below = 0.0;
        self.travelled = 0.0;
        self.in_contact = f64::INFINITY;
        self.v_lost = 0.0;
        self.f_prev = None;
        self.xf_prev = None;
        self.v_x = 0.0;
        self.x_prev = None;
        self.v_raw = 0.0;
        self.noise_var = 0.0;
        self.counts = EventCounts::default();
    }

    fn step(&mut self, x: f64, f: f64, dt: f64) -> Output {
        let mut ev = Events::default();
        if !(x.is_finite() && f.is_finite() && dt.is_finite() && dt > 0.0) {
            // Hold: the command stands still this step, and moves off from rest afterwards.
            ev.bad_input = true;
            self.v = 0.0;
            self.counts.add(&ev);
            return self.output(ev);
        }
        let df = self.p.response.set_point_rate * dt;
        self.f_r += (self.p.f_r - self.f_r).clamp(-df, df);
        let ff = self.force.step(f, dt);
        // Sensor noise: the mean square of the raw force's second difference over six (white noise of
        // variance σ² gives σ²; ramps give nothing, smooth motion little), averaged over NOISE_WINDOW.
        // Each difference is clipped at three of its own standard deviations (plus a floor), so impacts
        // and steps — rare, large — cannot pass for noise; true noise still builds the estimate up.
        if let Some((p1, p2)) = self.f_prev {
            let a = (dt / NOISE_WINDOW).min(1.0);
            let clip = 3.0 * (6.0 * self.noise_var).sqrt() + NOISE_FLOOR;
            let d2 = (f - 2.0 * p1 + p2).clamp(-clip, clip);
            self.noise_var += a * (d2 * d2 / 6.0 - self.noise_var);
        }
        self.f_prev = Some((f, self.f_prev.map_or(f, |p| p.0)));
        let xf = self.position.step(x, dt);
        let v_x = self.xf_prev.map_or(0.0, |p| (xf - p) / dt);
        self.xf_prev = Some(xf);
        self.v_x = v_x;
        self.v_raw = self.x_prev.map_or(0.0, |p| (x - p) / dt);
        self.x_prev = Some(x);
        if matches!(self.state, ContactState::Approach | ContactState::Reacquire) {
            self.onset.remember(x, f);
        }
        self.transitions(x, f, ff, xf, dt, &mut ev);
        let moving = surface_moving(self.vc, v_x, self.p.estimator.max_surface_speed);
        self.motion_hold = if moving && self.state == ContactState::Contact {
            MOTION_HOLD
        } else {
            (self.motion_hold - dt).max(0.0)
        };
        self.est_hold = (self.est_hold - dt).max(0.0);
        let moving = moving || self.est_hold > 0.0;
        if self.state == ContactState::Contact {
            // The transient identifies the stiffness on a still surface only.
            if moving {
                self.onset.stop();
            }
            let onset = self.onset.active();
            if onset && !ev.contact {
                self.onset.add(x, f, dt);
            }
            let fit = if onset {
                self.onset.fit(self.noise_var)
            } else {
                None
            };
            let projected = match fit {
                Some(fit) => {
                    let projected = self.est.seed(&fit, x, ff);
                    // The observed surface is x − f/k̂_c: a k̂_c that moves would show it moving.
                    // While the transient is identified the observers restart on every new k̂_c, at
                    // rest; the law is the proportional path and the integral alone.
                    self.zc = xf - ff / self.est.kc();
                    self.vc = 0.0;
                    self.jump_time = 0.0;
                    self.pred.clear();
                    self.pred_jump_time = 0.0;
                    self.motion_time = 0.0;
                    self.run_sign = 0.0;
                    self.steady.stop();
                    self.steady_var0 = self.est.seed_variance();
                    projected
                }
                None => {
                    let up = self.est.update(x, f, ff, dt, moving);
                    self.steady_step(x, f, dt, moving || up.adapted);
                    up.projected
                }
            };
            if projected {
                ev.estimator_bound = true;
            }
        }
        let want = self.desired(x, f, ff, xf, dt);
        let u = if want.is_finite() {
            self.limit(want, dt, &mut ev)
        } else {
            ev.bad_input = true;
            self.v = 0.0;
            self.u
        };
        self.u = u;
        self.counts.add(&ev);
        self.output(ev)
    }

    fn set_point(&self) -> f64 {
        self.p.f_r
    }

    fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        RobustLaw::set_set_point(self, f_r)
    }

    fn counters(&self) -> EventCounts {
        self.counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{LawConfig, Tuning};

    fn params() -> RobustParams {
        let t: Tuning = toml::from_str(include_str!("../../tunings/robust.toml")).unwrap();
        match t.law {
            LawConfig::Robust(p) => *p,
            other => panic!("robust tuning expected, got {other:?}"),
        }
    }

    /// Ideal inner loop against a spring whose surface is `xc(step)`; returns the law and the position.
    fn drive(
        law: &mut RobustLaw,
        x: &mut f64,
        steps: usize,
        k: f64,
        xc: impl Fn(usize) -> f64,
    ) -> Vec<Output> {
        (0..steps)
            .map(|i| {
                let f = (k * (*x - xc(i))).max(0.0);
                let out = law.step(*x, f, 1e-3);
                *x += 0.2 * (out.x_cmd - *x);
                out
            })
            .collect()
    }

    #[test]
    fn start_is_bumpless_and_approach_is_bounded() {
        let p = params();
        let mut law = RobustLaw::new(p).unwrap();
        law.start(0.004);
        let out = law.step(0.004, 0.0, 1e-3);
        assert_eq!(out.state, Some(ContactState::Approach));
        assert!((out.x_cmd - 0.004).abs() <= p.contact.approach_speed * 1e-3 + 1e-15);
    }

    #[test]
    fn state_machine_contact_lift_off_reacquire() {
        let p = params();
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = 0.0095;
        law.start(x);
        let outs = drive(&mut law, &mut x, 6000, 70_000.0, |i| {
            if i < 3000 { 0.010 } else { 0.0115 }
        });
        let first_contact = outs.iter().position(|o| o.events.contact).unwrap();
        assert!(
            outs[..first_contact]
                .iter()
                .all(|o| o.state == Some(ContactState::Approach))
        );
        let lift = outs.iter().position(|o| o.events.lift_off).unwrap();
        assert!(lift >= 3000, "lift-off only after the surface retreats");
        assert_eq!(outs[lift].state, Some(ContactState::Reacquire));
        assert!(outs[lift..].iter().any(|o| o.events.contact));
        assert_eq!(outs.last().unwrap().state, Some(ContactState::Contact));
        let c = law.counters();
        // The fast re-acquisition may bounce once; the search after a bounce is slow and holds.
        assert!(
            (2..=3).contains(&c.contacts) && c.lift_offs == c.contacts - 1,
            "{c:?}"
        );
        let f = 70_000.0 * (x - 0.0115);
        assert!((f - p.f_r).abs() < 0.05, "force {f} N");
    }

    #[test]
    fn force_limit_retracts_and_is_reported() {
        let p = params();
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = 0.0100714;
        law.start(x);
        drive(&mut law, &mut x, 1000, 70_000.0, |_| 0.010);
        // The surface jumps 2 mm towards the tool: 140 N.
        let outs = drive(&mut law, &mut x, 400, 70_000.0, |_| 0.008);
        let hit = outs.iter().position(|o| o.events.force_limit).unwrap();
        assert!(hit < 20, "limit seen after {hit} steps");
        assert_eq!(outs[hit].state, Some(ContactState::Retract));
        assert!(outs[hit + 10].x_cmd < outs[hit].x_cmd, "moving away");
        assert_eq!(law.counters().force_limits, 1);
    }

    #[test]
    fn set_point_change_is_bumpless() {
        let p = params();
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = 0.0100714;
        law.start(x);
        drive(&mut law, &mut x, 1500, 70_000.0, |_| 0.010);
        law.set_set_point(10.0).unwrap();
        let before = x;
        let outs = drive(&mut law, &mut x, 1500, 70_000.0, |_| 0.010);
        // The set-point slews at its rate: the first command moves by no more than rate·dt/k̂ and κ.
        let first_move = (outs[0].x_cmd - before).abs();
        assert!(first_move < 2e-6, "first move {first_move} m");
        assert!(outs.iter().all(|o| !o.events.any_limit()));
        assert!((law.active_set_point() - 10.0).abs() < 1e-12);
        let f = 70_000.0 * (x - 0.010);
        assert!((f - 10.0).abs() < 0.05, "force {f} N");
    }

    #[test]
    fn the_approach_identifies_the_stiffness_whatever_the_guess_and_set_point() {
        for (kc0, f_r) in [(50_000.0, 5.0), (200_000.0, 5.0), (30_000.0, 12.0)] {
            let mut p = params();
            p.estimator.kc0 = kc0;
            let mut law = RobustLaw::new(p).unwrap();
            let mut x = 0.0095;
            law.start(x);
            // A set-point changed before contact must not confuse the fit's position scale.
            law.set_set_point(f_r).unwrap();
            drive(&mut law, &mut x, 2000, 70_000.0, |_| 0.010);
            let k = law.step(x, 70_000.0 * (x - 0.010), 1e-3).kc_hat;
            assert!((k - 70_000.0).abs() < 700.0, "k̂(0) {kc0}, f_r {f_r}: k̂ {k}");
        }
    }

    #[test]
    fn deviation_limit_is_an_event_never_a_silent_clamp() {
        let mut p = params();
        p.limits.max_deviation = 0.0002;
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = 0.0;
        law.start(x);
        // The surface is out of reach (1 mm): the approach runs into the deviation limit.
        let outs = drive(&mut law, &mut x, 2000, 70_000.0, |_| 0.001);
        assert!(outs.iter().all(|o| o.x_cmd.abs() <= 0.0002 + 1e-15));
        assert!(outs.iter().any(|o| o.events.deviation_limit));
        assert!(law.counters().deviation_limits > 0);
    }

    #[test]
    fn validation_names_what_is_wrong() {
        let mut p = params();
        p.contact.lift_force = p.contact.contact_force;
        assert!(RobustLaw::new(p).unwrap_err().contains("lift_force"));
        let mut p = params();
        p.response.kappa = 1.5;
        assert!(RobustLaw::new(p).unwrap_err().contains("kappa"));
        let mut p = params();
        p.estimator.kc0 = 1e7;
        assert!(RobustLaw::new(p).unwrap_err().contains("kc0"));
        let mut p = params();
        p.limits.max_force = 1.0;
        assert!(RobustLaw::new(p).unwrap_err().contains("max_force"));
    }
}
