//! The paper's position-based impedance law with online estimation of the environment
//! (Wang et al., "Adaptive Control Strategy of Robot Polishing Force Based on Position Impedance", eqs. 7–23),
//! and the same impedance filter with a fixed reference for comparison.
//!
//! # 1-DOF model (along the tool's normal axis; `x` grows into the workpiece; SI units)
//! * impedance filter (eqs. 7–8): `m_d·ë + b_d·ė + k_d·e = f_r − f`, `e = x_cmd − x_r`, `x_cmd = x_r + e`;
//! * estimator (eqs. 15–22) on `f = [x, −1]·[k_c, K_c]`, `K_c = k_c·x_c`:
//!   `f̂ = k̂_c·x − K̂_c`, `dk̂_c/dt = −r1·x·(f̂ − f)`, `dK̂_c/dt = r2·(f̂ − f)`;
//! * reference (eq. 23): `x̂_c = K̂_c/k̂_c`, `x_r = x̂_c + f_r/k̂_c`.
//!
//! # Discretisation (fixed here, the paper is continuous-time)
//! One call of [`ImpedanceLaw::step`] with the measured `x_k`, `f_k` and the step `dt`:
//! 1. estimator, forward Euler with the values held at the start of the step:
//!    `ε = k̂·x_k − K̂ − f_k`, `k̂ ← k̂ − dt·r1·x_k·ε`, `K̂ ← K̂ + dt·r2·ε`;
//! 2. reference from the updated estimates: `x_r = K̂/k̂ + f_r/k̂`;
//! 3. impedance filter, semi-implicit (symplectic) Euler — velocity first, then position with the new
//!    velocity, which keeps the lightly damped filter from gaining energy:
//!    `ė ← ė + dt·(f_r − f_k − b_d·ė − k_d·e)/m_d`, `e ← e + dt·ė`;
//! 4. `x_cmd = x_r + e`.
//!
//! The step is a handful of multiplications on `f64`s held in the struct: no allocation, no I/O, no clock.

use hal::{Correction, Cycle, Wrench};
use serde::{Deserialize, Serialize};

/// Impedance filter parameters and the force set-point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImpedanceParams {
    /// Force set-point `f_r`, N (compressive, positive).
    pub f_r: f64,
    /// Target inertia `m_d`, kg.
    pub m_d: f64,
    /// Target damping `b_d`, N·s/m.
    pub b_d: f64,
    /// Target stiffness `k_d`, N/m.
    pub k_d: f64,
}

impl ImpedanceParams {
    /// Table I of the paper: `f_r` 5 N, `m_d` 8 kg, `b_d` 80 N·s/m, `k_d` 50 000 N/m.
    pub const PAPER: Self = Self {
        f_r: 5.0,
        m_d: 8.0,
        b_d: 80.0,
        k_d: 50_000.0,
    };

    /// Checks that every value is finite and physically meaningful.
    pub fn validate(&self) -> Result<(), String> {
        check_positive("m_d", self.m_d)?;
        check_positive("k_d", self.k_d)?;
        check_non_negative("b_d", self.b_d)?;
        check_non_negative("f_r", self.f_r)?;
        Ok(())
    }
}

/// Where the impedance filter's reference `x_r` comes from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Reference {
    /// A fixed reference (plain impedance control, eq. 9 predicts its steady-state error).
    Fixed {
        /// The reference position `x_r`, m.
        x_r: f64,
    },
    /// The paper's adaptive law (eq. 23).
    PaperAdaptive(AdaptiveParams),
}

/// Gains and initial estimates of the paper's estimator.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdaptiveParams {
    /// Gain of the stiffness channel `r1`.
    pub r1: f64,
    /// Gain of the `K_c = k_c·x_c` channel `r2`.
    pub r2: f64,
    /// Initial stiffness estimate `k̂_c(0)`, N/m.
    pub kc0: f64,
    /// Initial surface position estimate `x̂_c(0)`, m.
    pub xc0: f64,
}

impl AdaptiveParams {
    /// Table I of the paper: `r1` 5, `r2` 10, `k̂_c(0)` 50 000 N/m, `x̂_c(0)` 9 mm.
    pub const PAPER: Self = Self {
        r1: 5.0,
        r2: 10.0,
        kc0: 50_000.0,
        xc0: 0.009,
    };

    /// Checks that every value is finite and the initial stiffness positive.
    pub fn validate(&self) -> Result<(), String> {
        check_non_negative("r1", self.r1)?;
        check_non_negative("r2", self.r2)?;
        check_positive("kc0", self.kc0)?;
        check_finite("xc0", self.xc0)?;
        Ok(())
    }
}

fn check_finite(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(format!("{name} must be a finite number, got {v}"))
    }
}

fn check_positive(name: &str, v: f64) -> Result<(), String> {
    check_finite(name, v)?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be > 0, got {v}"))
    }
}

fn check_non_negative(name: &str, v: f64) -> Result<(), String> {
    check_finite(name, v)?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be >= 0, got {v}"))
    }
}

/// What a law computed in one step. Positions in m along the tool normal, stiffness in N/m.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Output {
    /// Position command for the robot's inner position loop, `x_cmd = x_r + e`.
    pub x_cmd: f64,
    /// The impedance filter's reference `x_r`.
    pub x_r: f64,
    /// Stiffness estimate `k̂_c` (the fixed-reference law reports NaN: it estimates nothing).
    pub kc_hat: f64,
    /// Surface position estimate `x̂_c` (NaN for the fixed-reference law).
    pub xc_hat: f64,
    /// Contact state, for laws that run a contact state machine (`None` for the paper's law).
    pub state: Option<ContactState>,
    /// What happened in this step (state changes, limits that acted).
    pub events: Events,
}

/// Where a law with a contact state machine is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ContactState {
    /// Moving towards an unknown surface at the bounded approach speed.
    Approach,
    /// In contact, regulating the force.
    Contact,
    /// Contact was lost: moving back towards the surface, fast first, then at approach speed.
    Reacquire,
    /// The force limit was exceeded: moving away before approaching again.
    Retract,
}

impl ContactState {
    /// A small code for recordings: 0 approach, 1 contact, 2 re-acquire, 3 retract.
    pub fn code(self) -> u8 {
        match self {
            Self::Approach => 0,
            Self::Contact => 1,
            Self::Reacquire => 2,
            Self::Retract => 3,
        }
    }
}

/// Events of one step. A limit that acted is always an event: nothing is clamped silently.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Events {
    /// Contact was detected (approach or re-acquire ended).
    pub contact: bool,
    /// Contact was lost.
    pub lift_off: bool,
    /// The conditioned force exceeded the maximum force: the law retracts.
    pub force_limit: bool,
    /// The command's velocity was limited.
    pub velocity_limit: bool,
    /// The command's acceleration was limited.
    pub acceleration_limit: bool,
    /// The command would have left the allowed deviation from the programmed path.
    pub deviation_limit: bool,
    /// The stiffness estimate was projected back into its bounds.
    pub estimator_bound: bool,
    /// A non-finite input or step reached the law; it held its command.
    pub bad_input: bool,
    /// Orientation following: the rotation's rate was limited.
    pub orientation_rate: bool,
    /// Orientation following: the rotation was held at the robot's POSCORR rotation limit.
    pub orientation_limit: bool,
    /// Orientation following: the moment was not usable (saturated, out of range, not finite);
    /// the rotation held.
    pub orientation_hold: bool,
    /// Orientation following: the rotation would have reached its envelope (a fault: the loop
    /// backs off).
    pub orientation_envelope: bool,
}

impl Events {
    /// True when any limit acted (not counting contact and lift-off, which are state changes).
    pub fn any_limit(&self) -> bool {
        self.force_limit
            || self.velocity_limit
            || self.acceleration_limit
            || self.deviation_limit
            || self.estimator_bound
            || self.bad_input
            || self.orientation_rate
            || self.orientation_limit
            || self.orientation_hold
            || self.orientation_envelope
    }
}

/// Counters of [`Events`] since the law started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct EventCounts {
    /// Contacts detected.
    pub contacts: u64,
    /// Contacts lost.
    pub lift_offs: u64,
    /// Force-limit retractions.
    pub force_limits: u64,
    /// Steps with the velocity limited.
    pub velocity_limits: u64,
    /// Steps with the acceleration limited.
    pub acceleration_limits: u64,
    /// Steps with the deviation from the path limited.
    pub deviation_limits: u64,
    /// Steps with the stiffness estimate projected.
    pub estimator_bounds: u64,
    /// Steps with non-finite input held.
    pub bad_inputs: u64,
    /// Steps with the rotation's rate limited.
    pub orientation_rates: u64,
    /// Steps with the rotation held at POSCORR.
    pub orientation_limits: u64,
    /// Steps with the rotation held on an unusable moment.
    pub orientation_holds: u64,
    /// Steps where the rotation reached its envelope.
    pub orientation_envelopes: u64,
}

impl EventCounts {
    /// Count one step's events.
    pub fn add(&mut self, e: &Events) {
        self.contacts += u64::from(e.contact);
        self.lift_offs += u64::from(e.lift_off);
        self.force_limits += u64::from(e.force_limit);
        self.velocity_limits += u64::from(e.velocity_limit);
        self.acceleration_limits += u64::from(e.acceleration_limit);
        self.deviation_limits += u64::from(e.deviation_limit);
        self.estimator_bounds += u64::from(e.estimator_bound);
        self.bad_inputs += u64::from(e.bad_input);
        self.orientation_rates += u64::from(e.orientation_rate);
        self.orientation_limits += u64::from(e.orientation_limit);
        self.orientation_holds += u64::from(e.orientation_hold);
        self.orientation_envelopes += u64::from(e.orientation_envelope);
    }
}

/// A 1-DOF force control law: what the control loop runs every cycle.
///
/// Contract: `step` is called with finite inputs only (the loop gates bad samples) and a positive `dt`;
/// it must not allocate, block or read a clock. `start` (re)initialises the law at rest at the measured
/// position, so the first command equals the position the robot already has (bumpless start).
pub trait ForceLaw {
    /// Initialise at rest at measured position `x`, m.
    fn start(&mut self, x: f64);
    /// One control step with measured position `x` (m), measured normal force `f` (N) and step `dt` (s).
    fn step(&mut self, x: f64, f: f64, dt: f64) -> Output;
    /// The force set-point, N.
    fn set_point(&self) -> f64;
    /// Change the force set-point while running, without a bump (a law may approach the new value at
    /// its own rate). An invalid value is refused and changes nothing.
    fn set_set_point(&mut self, f_r: f64) -> Result<(), String>;
    /// Events counted since `start` (laws without limits or a state machine count nothing).
    fn counters(&self) -> EventCounts {
        EventCounts::default()
    }
}

impl<L: ForceLaw + ?Sized> ForceLaw for Box<L> {
    fn start(&mut self, x: f64) {
        (**self).start(x)
    }
    fn step(&mut self, x: f64, f: f64, dt: f64) -> Output {
        (**self).step(x, f, dt)
    }
    fn set_point(&self) -> f64 {
        (**self).set_point()
    }
    fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        (**self).set_set_point(f_r)
    }
    fn counters(&self) -> EventCounts {
        (**self).counters()
    }
}

/// What a [`CellLaw`] returns for one cycle: the correction it wants (translation and rotation, tool
/// frame, absolute from the programmed path) and what it computed, for the record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawStep {
    /// The correction the law wants; the loop limits it before it is sent. Its `stop` and `process`
    /// fields are the loop's and are ignored.
    pub correction: Correction,
    /// The law's output (along the tool normal for a 1-DOF law).
    pub out: Output,
}

/// A force control law over what the cell gives and what the robot takes: the robot's cycle (poses,
/// time, process command) and the wrench in, a [`Correction`] out.
///
/// Contract: `step` is called with a finite cycle and wrench only (the loop gates bad input) and a
/// positive `dt`; it must not allocate, block or read a clock. `start` (re)initialises the law at rest
/// with the correction standing at `at`, so the first command is what the robot already has (bumpless).
pub trait CellLaw {
    /// Initialise at rest for `cycle`, with the correction standing at `at`.
    fn start(&mut self, cycle: &Cycle, at: &Correction);
    /// One control step on `cycle` with the (compensated) `wrench` over `dt` s.
    fn step(&mut self, cycle: &Cycle, wrench: &Wrench, dt: f64) -> LawStep;
    /// The force set-point, N (along the tool normal, compressive).
    fn set_point(&self) -> f64;
    /// Change the force set-point while running, without a bump; an invalid value is refused and
    /// changes nothing.
    fn set_set_point(&mut self, f_r: f64) -> Result<(), String>;
    /// Events counted since `start`.
    fn counters(&self) -> EventCounts;
}

/// The one adapter from a 1-DOF [`ForceLaw`] to a [`CellLaw`]: the law acts along the tool's normal
/// (z) axis, on the tool's offset from the programmed path along it ([`Cycle::tool_offset`]) and on the
/// compressive normal force `force_sign · F_z`; its command is a correction along z only.
#[derive(Clone, Debug)]
pub struct AlongNormal<L> {
    law: L,
    force_sign: f64,
}

impl<L> AlongNormal<L> {
    /// `law` along the tool normal; `force_sign` turns the sensor's `F_z` into a compressive force
    /// (`+1` when pressing reads positive).
    pub fn new(law: L, force_sign: f64) -> Self {
        Self { law, force_sign }
    }

    /// The 1-DOF law.
    pub fn inner(&self) -> &L {
        &self.law
    }
}

impl<L: ForceLaw> CellLaw for AlongNormal<L> {
    fn start(&mut self, _: &Cycle, at: &Correction) {
        self.law.start(at.translation.z);
    }

    fn step(&mut self, cycle: &Cycle, wrench: &Wrench, dt: f64) -> LawStep {
        let x = cycle.tool_offset().z;
        let f = self.force_sign * wrench.force.z;
        let out = self.law.step(x, f, dt);
        LawStep {
            correction: Correction::along_z(out.x_cmd),
            out,
        }
    }

    fn set_point(&self) -> f64 {
        self.law.set_point()
    }

    fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        self.law.set_set_point(f_r)
    }

    fn counters(&self) -> EventCounts {
        self.law.counters()
    }
}

/// The impedance filter with either a fixed reference or the paper's adaptive reference.
#[derive(Clone, Debug, PartialEq)]
pub struct ImpedanceLaw {
    imp: ImpedanceParams,
    reference: Reference,
    /// `e = x_cmd − x_r`, m.
    e: f64,
    /// `ė`, m/s.
    e_dot: f64,
    /// `k̂_c`, N/m.
    kc: f64,
    /// `K̂_c = k̂_c·x̂_c`, N.
    big_kc: f64,
}

impl ImpedanceLaw {
    /// A law with the given parameters, at rest with `e = 0`. Parameters are validated.
    pub fn new(imp: ImpedanceParams, reference: Reference) -> Result<Self, String> {
        imp.validate()?;
        let (kc, big_kc) = match reference {
            Reference::Fixed { x_r } => {
                check_finite("x_r", x_r)?;
                (f64::NAN, f64::NAN)
            }
            Reference::PaperAdaptive(a) => {
                a.validate()?;
                (a.kc0, a.kc0 * a.xc0)
            }
        };
        Ok(Self {
            imp,
            reference,
            e: 0.0,
            e_dot: 0.0,
            kc,
            big_kc,
        })
    }

    /// The paper's law with every value of Table I.
    pub fn paper() -> Self {
        Self::new(
            ImpedanceParams::PAPER,
            Reference::PaperAdaptive(AdaptiveParams::PAPER),
        )
        .expect("Table I is valid")
    }

    /// The impedance parameters.
    pub fn params(&self) -> &ImpedanceParams {
        &self.imp
    }

    /// The reference `x_r` the current estimates give.
    pub fn reference_position(&self) -> f64 {
        match self.reference {
            Reference::Fixed { x_r } => x_r,
            Reference::PaperAdaptive(_) => (self.big_kc + self.imp.f_r) / self.kc,
        }
    }

    fn output(&self) -> Output {
        let x_r = self.reference_position();
        Output {
            x_cmd: x_r + self.e,
            x_r,
            kc_hat: self.kc,
            xc_hat: self.big_kc / self.kc,
            ..Output::default()
        }
    }
}

impl ForceLaw for ImpedanceLaw {
    fn start(&mut self, x: f64) {
        if let Reference::PaperAdaptive(a) = self.reference {
            self.kc = a.kc0;
            self.big_kc = a.kc0 * a.xc0;
        }
        self.e = x - self.reference_position();
        self.e_dot = 0.0;
    }

    fn step(&mut self, x: f64, f: f64, dt: f64) -> Output {
        if let Reference::PaperAdaptive(a) = self.reference {
            let eps = self.kc * x - self.big_kc - f;
            let kc = self.kc - dt * a.r1 * x * eps;
            self.big_kc += dt * a.r2 * eps;
            self.kc = kc;
        }
        let p = &self.imp;
        let acc = (p.f_r - f - p.b_d * self.e_dot - p.k_d * self.e) / p.m_d;
        self.e_dot += dt * acc;
        self.e += dt * self.e_dot;
        self.output()
    }

    fn set_point(&self) -> f64 {
        self.imp.f_r
    }

    fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        check_non_negative("f_r", f_r)?;
        self.imp.f_r = f_r;
        Ok(())
    }
}

/// Steady-state force error `f_r − f` of the fixed-reference impedance law against a spring (eq. 9):
/// `k_d/(k_d+k_c)·[f_r + k_c(x_c − x_r)]`. Valid while the tool stays in contact.
pub fn fixed_reference_steady_state_error(
    p: &ImpedanceParams,
    k_c: f64,
    x_c: f64,
    x_r: f64,
) -> f64 {
    p.k_d / (p.k_d + k_c) * (p.f_r + k_c * (x_c - x_r))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed loop against a pure spring with the ideal plant P0 (x_{k+1} = x_cmd_k), no wire.
    fn run_p0(law: &mut ImpedanceLaw, k_c: f64, x_c: f64, x0: f64, steps: usize) -> (f64, f64) {
        let dt = 1e-3;
        let mut x = x0;
        law.start(x);
        let mut f = 0.0;
        for _ in 0..steps {
            f = (k_c * (x - x_c)).max(0.0);
            x = law.step(x, f, dt).x_cmd;
        }
        (x, f)
    }

    #[test]
    fn start_is_bumpless() {
        let mut law = ImpedanceLaw::paper();
        law.start(0.0123);
        assert!((law.output().x_cmd - 0.0123).abs() < 1e-15);
    }

    #[test]
    fn fixed_reference_keeps_the_eq9_error() {
        let p = ImpedanceParams::PAPER;
        let (k_c, x_c, x_r) = (70_000.0, 0.01, 0.0101);
        let mut law = ImpedanceLaw::new(p, Reference::Fixed { x_r }).unwrap();
        let (_, f) = run_p0(&mut law, k_c, x_c, x_r, 4000);
        let predicted = fixed_reference_steady_state_error(&p, k_c, x_c, x_r);
        let got = p.f_r - f;
        assert!(
            (got - predicted).abs() <= 0.01 * predicted.abs(),
            "error {got} N, eq. 9 predicts {predicted} N"
        );
    }

    #[test]
    fn adaptive_law_removes_the_steady_state_error() {
        let mut law = ImpedanceLaw::paper();
        let (_, f) = run_p0(&mut law, 70_000.0, 0.01, 0.0091, 4000);
        assert!((f - 5.0).abs() < 0.05, "force {f} N");
    }

    #[test]
    fn bad_parameters_are_refused_with_the_name() {
        let mut p = ImpedanceParams::PAPER;
        p.m_d = 0.0;
        let err = ImpedanceLaw::new(p, Reference::Fixed { x_r: 0.0 }).unwrap_err();
        assert!(err.contains("m_d"), "{err}");
        let mut a = AdaptiveParams::PAPER;
        a.kc0 = f64::NAN;
        let err =
            ImpedanceLaw::new(ImpedanceParams::PAPER, Reference::PaperAdaptive(a)).unwrap_err();
        assert!(err.contains("kc0"), "{err}");
    }
}
