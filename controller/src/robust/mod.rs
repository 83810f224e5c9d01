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
//! predicted `T_d` ahead through the inverted lag, less `x̃_c` (`T_d`, `τ` and the cycle are the cell's,
//! [`CellParams`], not the step's `dt`, which a held cycle lengthens):
//! `FF = w·(x̂_c(t + T_d) + [x̂_c(t + T_d + dt) − x̂_c(t + T_d)]/α − x̃_c)`, `α = 1 − e^{−dt/τ}`.
//! With a perfect prediction the loop's characteristic equation is the one above, so the feed-forward
//! does not change stability; what it changes is what a *wrong* `k̂_c` does: then `x − f/k̂_c` moves
//! with the robot (`(1 − k_c/k̂_c)·ẋ`) and a predictor would feed that back. So the weight `w` is 0
//! until the estimator's motion test ([`crate::estimator::surface_moving`]: observed motion that leads
//! or exceeds the robot's, on the conditioned pair, or on the raw pair for 8 ms without a break) has
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
//! # Stages
//! The law is a pipeline of small stages, each owning its parameters, its state, its `reset()` and its
//! tests; [`RobustLaw::step`] composes them:
//! [`signals`] (conditioning of force and position) → [`noise`] (sensor noise, measured) →
//! [`contact`] (the state machine) → [`identify`] (`k̂_c`: onset fit, recursion, steady-contact fit) →
//! [`observer`] (surface observer, predictor, feed-forward; [`motion`]: real motion or a stale `k̂_c`) and [`response`] (proportional, integral,
//! set-point) → [`limiter`] (deviation, velocity, acceleration). [`cell`] is the inner loop's model,
//! [`stopping`] how far it carries the tool into a surface after a contact is seen.
//! Every limit that acts is an [`Events`] flag of the step and a counter ([`ForceLaw::counters`]).

use crate::law::{ContactState, EventCounts, Events, ForceLaw, Output};

pub mod cell;
mod compose;
pub mod contact;
pub mod context;
pub mod guards;
pub mod identify;
pub mod limiter;
pub mod motion;
pub mod noise;
pub mod observer;
mod params;
pub mod response;
pub mod signals;
pub mod stopping;
#[cfg(test)]
mod tests;

pub use cell::{CellParams, CycleMeter};
pub use contact::{ContactMachine, ContactParams, Transition};
pub use context::Context;
pub use identify::{Estimate, Identifier, IdentifyParams};
pub use limiter::{LimitParams, Limiter};
pub use noise::{NoiseEstimate, NoiseMeter, NoiseParams};
pub use observer::{ObserverParams, SurfaceObserver, SurfaceStatus};
pub use params::RobustParams;
pub(crate) use params::{at_least, non_negative, positive};
pub use response::{Response, ResponseParams};
pub use signals::{Conditioner, Signals};
pub use stopping::Stopping;

/// The robust law. See the module documentation.
#[derive(Clone, Debug, PartialEq)]
pub struct RobustLaw {
    p: RobustParams,
    cycle: CycleMeter,
    signals: Conditioner,
    noise: NoiseMeter,
    contact: ContactMachine,
    identify: Identifier,
    observer: SurfaceObserver,
    response: Response,
    limiter: Limiter,
    stopping: Stopping,
    counts: EventCounts,
    /// The contact state the last step ended in (its [`Output::state`]): the next step's input.
    last_state: ContactState,
}

impl RobustLaw {
    /// A law with validated parameters, at rest at 0.
    pub fn new(p: RobustParams) -> Result<Self, String> {
        p.validate()?;
        Ok(Self {
            cycle: CycleMeter::new(&p.cell),
            signals: Conditioner::new(p.conditioning),
            noise: NoiseMeter::new(p.noise),
            contact: ContactMachine::new(p.contact),
            identify: Identifier::new(p.identify, p.estimator, p.response.noise_floor, p.scale()),
            observer: SurfaceObserver::new(p.observer),
            response: Response::new(p.response, p.f_r),
            limiter: Limiter::new(p.limits),
            stopping: Stopping::new(),
            counts: EventCounts::default(),
            last_state: ContactState::Approach,
            p,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &RobustParams {
        &self.p
    }

    /// The contact state.
    pub fn state(&self) -> ContactState {
        self.contact.state()
    }

    /// The set-point in force now (it slews towards a new one), N.
    pub fn active_set_point(&self) -> f64 {
        self.response.set_point()
    }

    /// Change the parameters while running, without a bump: the estimates, filters, contact state and
    /// command are kept, a new set-point is approached at `set_point_rate`, and the velocity and
    /// acceleration limits keep acting on the command.
    pub fn set_params(&mut self, p: RobustParams) -> Result<(), String> {
        p.validate()?;
        self.cycle.set_params(&p.cell);
        self.signals.set_params(p.conditioning);
        self.noise.set_params(p.noise);
        self.contact.set_params(p.contact);
        self.identify
            .set_params(p.identify, p.estimator, p.response.noise_floor);
        self.observer.set_params(p.observer);
        self.response.set_params(p.response);
        self.limiter.set_params(p.limits);
        self.p = p;
        Ok(())
    }

    /// Change the force set-point only (bumpless, see [`set_params`](Self::set_params)).
    pub fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        let mut p = self.p;
        p.f_r = f_r;
        self.set_params(p)
    }

    fn output(&mut self, events: Events) -> Output {
        self.last_state = self.contact.state();
        let k = self.identify.kc();
        let zc = self.observer.surface();
        Output {
            x_cmd: self.limiter.command(),
            x_r: zc + self.response.set_point() / k,
            kc_hat: k,
            xc_hat: zc,
            state: Some(self.contact.state()),
            events,
        }
    }
}

impl ForceLaw for RobustLaw {
    fn start(&mut self, x: f64) {
        self.cycle.reset();
        self.signals.reset();
        self.noise.reset();
        self.contact.reset();
        self.identify.reset();
        self.observer.reset();
        self.response.reset(self.p.f_r);
        self.limiter.reset(x);
        self.counts = EventCounts::default();
        self.last_state = ContactState::Approach;
    }

    fn step(&mut self, x: f64, f: f64, dt: f64) -> Output {
        let mut ev = Events::default();
        if !(x.is_finite() && f.is_finite() && dt.is_finite() && dt > 0.0) {
            ev.bad_input = true;
            self.limiter.hold();
            self.counts.add(&ev);
            return self.output(ev);
        }
        let cycle = self.cycle.step(dt);
        let set_point = self.response.slew(self.p.f_r, dt);
        let s = self.signals.step(x, f, dt, self.p.cell.sensor_delay);
        let noise = self.noise.step(f, dt);
        let ctx = self.context(dt, cycle, set_point, noise);
        if matches!(
            self.last_state,
            ContactState::Approach | ContactState::Reacquire
        ) {
            self.identify.remember(x, f, s.v_raw, cycle);
        }
        let receding = self.observer.receding();
        let th = self.thresholds(&ctx);
        let c = self
            .contact
            .step(&s, &th, self.p.limits.max_force, receding, dt);
        match c.transition {
            Transition::None => {}
            Transition::ForceLimit => ev.force_limit = true,
            Transition::Contact { from_approach } => {
                self.begin_contact(&s, from_approach, &c.search);
                ev.contact = true;
            }
            Transition::LiftOff => {
                // Back in the approach: a touch-down taken back, nothing was learnt of a surface.
                self.identify.lift_off(c.state == ContactState::Approach);
                self.signals.reset_force(f);
                ev.lift_off = true;
            }
        }
        let in_contact = c.state == ContactState::Contact;
        let surface = self
            .observer
            .hold(s.v_x, self.p.estimator.max_surface_speed, in_contact, dt);
        let identified =
            in_contact && self.identify_in_contact(&s, &ctx, th.lift, c.steady, &surface, &mut ev);
        let est = self.identify.estimate();
        let want = self.command(x, &s, &th, &ctx, &est, identified);
        if want.is_finite() {
            self.limiter.step(want, dt, &mut ev);
        } else {
            ev.bad_input = true;
            self.limiter.hold();
        }
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
