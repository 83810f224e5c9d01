//! Re-zeroing the force sensor in free air between passes (`[process] rezero = true`): a stage that
//! owns its parameters ([`RezeroParams`]), its state and the zero it applies, without I/O — cycles and
//! samples in, a [`RezeroEvent`] out when it re-zeroed or refused.
//!
//! A sensor's bias drifts; in a steady contact no controller can tell the drift from the part, but in
//! free air the contact wrench is zero, so whatever the sensor reads there is offset. The stage takes
//! that offset as the new zero only when the check passes, over one window of `window` seconds:
//!
//! * the process is OFF and the program commands OFF (no pass runs: the law is not stepped, and a
//!   PRESS restarts it afterwards as on any new pass);
//! * the tool has been out of contact (normal force within `±entry_force` of the current zero) for at
//!   least `free_air` seconds when the window ends, and was in none of its cycles;
//! * the sensor was healthy in every cycle of the window (a usable, finite, compensable sample);
//! * the tool stood still: the robot's measured pose stayed within `still` (m) and `still_angle`
//!   (rad) of its pose at the window's start;
//! * the force was steady: the standard deviation of each force component over the window is at
//!   most `steady` (N);
//! * the offset to remove is no larger than `max_offset` (N, the force's magnitude): more is not a
//!   drift (a cable pulling, a tool touching something the normal force does not show).
//!
//! Otherwise the old zero stays and the refusal says why ([`RezeroOutcome`]), once per reason per
//! free-air stretch; the stage tries again on the next window. One re-zero per stretch at most.

use hal::{Pose, Wrench};
use serde::{Deserialize, Serialize};

/// The check's parameters. Times in s, forces in N, distances in m, angles in rad.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RezeroParams {
    /// Length of the window the force is averaged and checked over, s.
    pub window: f64,
    /// Largest standard deviation of each force component over the window, N.
    pub steady: f64,
    /// Shortest time out of contact (at OFF) before a window may end in a re-zero, s.
    pub free_air: f64,
    /// Largest excursion of the measured tool position from the window's first pose, m.
    pub still: f64,
    /// Largest rotation of the measured tool pose from the window's first pose, rad.
    pub still_angle: f64,
    /// Largest force offset a re-zero removes, N (magnitude of the force part).
    pub max_offset: f64,
}

impl Default for RezeroParams {
    fn default() -> Self {
        Self {
            window: 0.5,
            steady: 1.0,
            free_air: 1.0,
            still: 1e-4,
            still_angle: 1e-3,
            max_offset: 5.0,
        }
    }
}

impl RezeroParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("window", self.window),
            ("steady", self.steady),
            ("free_air", self.free_air),
            ("still", self.still),
            ("still_angle", self.still_angle),
            ("max_offset", self.max_offset),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!(
                    "process.zeroing.{name} must be a finite number > 0, got {v}"
                ));
            }
        }
        if self.window > 10.0 {
            return Err(format!(
                "process.zeroing.window is at most 10 s, got {}",
                self.window
            ));
        }
        Ok(())
    }
}

/// What a re-zero check decided. The codes and names are the recording's
/// (`forcecell.RezeroOutcome`); [`RezeroOutcome::ALL`] lists them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RezeroOutcome {
    /// The sensor was zeroed: the offset removed is the window's mean wrench.
    Done = 0,
    /// Refused: the tool moved during the window.
    Moving = 1,
    /// Refused: the normal force showed a contact during the window.
    Contact = 2,
    /// Refused: the sensor gave no usable sample in some cycle of the window.
    Unhealthy = 3,
    /// Refused: the force was not steady over the window.
    Unsteady = 4,
    /// Refused: the offset is larger than `max_offset`.
    TooLarge = 5,
    /// Refused: the robot's pose was unknown (not finite) in some cycle of the window.
    NoPose = 6,
}

impl RezeroOutcome {
    /// Every outcome, in the order of its codes.
    pub const ALL: [Self; 7] = [
        Self::Done,
        Self::Moving,
        Self::Contact,
        Self::Unhealthy,
        Self::Unsteady,
        Self::TooLarge,
        Self::NoPose,
    ];

    /// Its code.
    pub fn code(self) -> i64 {
        self as i64
    }

    /// Its name, for the operator and recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Done => "re-zeroed",
            Self::Moving => "tool moving",
            Self::Contact => "in contact",
            Self::Unhealthy => "sensor unhealthy",
            Self::Unsteady => "force not steady",
            Self::TooLarge => "offset too large",
            Self::NoPose => "pose unknown",
        }
    }
}

impl core::fmt::Display for RezeroOutcome {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// A re-zero, or a refusal to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RezeroEvent {
    /// Robot time at the window's end, s.
    pub t: f64,
    /// What was decided.
    pub outcome: RezeroOutcome,
    /// The offset removed (the window's mean wrench over the old zero), N and N·m; for a refusal,
    /// the window's mean where it was measured (NaN where not).
    pub offset: Wrench,
    /// The zero in effect after the decision (the old one on a refusal).
    pub zero: Wrench,
}

/// What the stage sees in one cycle.
#[derive(Clone, Copy, Debug)]
pub struct RezeroInput {
    /// Robot time, s.
    pub t: f64,
    /// True when the process is OFF and the program commands OFF.
    pub off: bool,
    /// The wrench as the loop uses it (compensated, the current zero removed); `None` when the sensor
    /// gave nothing usable this cycle.
    pub wrench: Option<Wrench>,
    /// The compressive normal force of that wrench, N.
    pub f: Option<f64>,
    /// The robot's measured tool pose, `None` when not finite.
    pub pose: Option<Pose>,
    /// A normal force beyond this (either way) is a contact, N (the process's `entry_force`).
    pub contact_force: f64,
}

/// One window's sums.
#[derive(Clone, Copy, Debug)]
struct Window {
    start: f64,
    n: f64,
    sum: [f64; 6],
    sumsq: [f64; 3],
    first: Option<Pose>,
    moved: bool,
    contact: bool,
    unhealthy: bool,
    no_pose: bool,
}

impl Window {
    fn new(start: f64) -> Self {
        Self {
            start,
            n: 0.0,
            sum: [0.0; 6],
            sumsq: [0.0; 3],
            first: None,
            moved: false,
            contact: false,
            unhealthy: false,
            no_pose: false,
        }
    }

    fn mean(&self) -> Wrench {
        if self.n > 0.0 {
            Wrench::from_array(self.sum.map(|s| s / self.n))
        } else {
            Wrench::from_array([f64::NAN; 6])
        }
    }

    fn max_std(&self) -> f64 {
        (0..3)
            .map(|i| {
                let m = self.sum[i] / self.n;
                (self.sumsq[i] / self.n - m * m).max(0.0).sqrt()
            })
            .fold(0.0, f64::max)
    }
}

/// The re-zero stage: its parameters, the free-air stretch it watches and the zero it applies.
#[derive(Clone, Debug)]
pub struct Rezero {
    enabled: bool,
    params: RezeroParams,
    zero: Wrench,
    /// Start of the current free-air time (OFF entered, or the last contact), s.
    free_since: Option<f64>,
    window: Option<Window>,
    /// This stretch has been re-zeroed.
    done: bool,
    /// The last refusal said in this stretch.
    said: Option<RezeroOutcome>,
}

impl Rezero {
    /// A stage with a zero of nothing; when not `enabled` it never re-zeroes.
    pub fn new(enabled: bool, params: RezeroParams) -> Self {
        Self {
            enabled,
            params,
            zero: Wrench::default(),
            free_since: None,
            window: None,
            done: false,
            said: None,
        }
    }

    /// Whether it re-zeroes at all.
    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// The zero in effect.
    pub fn zero(&self) -> Wrench {
        self.zero
    }

    /// `w` with the zero removed.
    pub fn apply(&self, w: &Wrench) -> Wrench {
        Wrench {
            force: w.force - self.zero.force,
            torque: w.torque - self.zero.torque,
        }
    }

    /// Forget the stretch being watched (a new robot session); the zero stays.
    pub fn reset(&mut self) {
        self.free_since = None;
        self.window = None;
        self.done = false;
        self.said = None;
    }

    /// Take one cycle; an event when a window ended in a re-zero or in a refusal not said before in
    /// this stretch.
    pub fn observe(&mut self, inp: &RezeroInput) -> Option<RezeroEvent> {
        if !self.enabled {
            return None;
        }
        if !inp.off {
            self.reset();
            return None;
        }
        if self.done {
            return None;
        }
        let p = self.params;
        let free_since = *self.free_since.get_or_insert(inp.t);
        let w = self.window.get_or_insert_with(|| Window::new(inp.t));
        match (inp.wrench, inp.f) {
            (Some(wr), Some(f)) if wr.is_finite() && f.is_finite() => {
                if f.abs() > inp.contact_force {
                    w.contact = true;
                    self.free_since = Some(inp.t);
                }
                let a = wr.to_array();
                w.n += 1.0;
                for (i, v) in a.iter().enumerate() {
                    w.sum[i] += v;
                    if i < 3 {
                        w.sumsq[i] += v * v;
                    }
                }
            }
            _ => w.unhealthy = true,
        }
        match inp.pose {
            Some(pose)
                if pose.position.iter().all(|v| v.is_finite())
                    && pose.orientation.coords.iter().all(|v| v.is_finite()) =>
            {
                match w.first {
                    None => w.first = Some(pose),
                    Some(first) => {
                        let d = (pose.position - first.position).norm();
                        let a = pose.orientation.angle_to(&first.orientation);
                        if d > p.still || a.is_nan() || a > p.still_angle {
                            w.moved = true;
                        }
                    }
                }
            }
            _ => w.no_pose = true,
        }
        if inp.t - w.start + 1e-9 < p.window {
            return None;
        }
        let w = self.window.take().expect("a window is open");
        let mean = w.mean();
        let outcome = if w.unhealthy {
            Some(RezeroOutcome::Unhealthy)
        } else if w.contact {
            Some(RezeroOutcome::Contact)
        } else if inp.t - free_since + 1e-9 < p.free_air {
            // Not out of contact long enough yet: wait, silently.
            return None;
        } else if w.no_pose {
            Some(RezeroOutcome::NoPose)
        } else if w.moved {
            Some(RezeroOutcome::Moving)
        } else if w.max_std() > p.steady {
            Some(RezeroOutcome::Unsteady)
        } else if mean.force.norm() > p.max_offset {
            Some(RezeroOutcome::TooLarge)
        } else {
            None
        };
        match outcome {
            Some(why) if self.said == Some(why) => None,
            Some(why) => {
                self.said = Some(why);
                Some(RezeroEvent {
                    t: inp.t,
                    outcome: why,
                    offset: mean,
                    zero: self.zero,
                })
            }
            None => {
                self.zero = Wrench {
                    force: self.zero.force + mean.force,
                    torque: self.zero.torque + mean.torque,
                };
                self.done = true;
                Some(RezeroEvent {
                    t: inp.t,
                    outcome: RezeroOutcome::Done,
                    offset: mean,
                    zero: self.zero,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hal::{UnitQuaternion, Vector3};

    const DT: f64 = 0.004;

    fn pose(z: f64) -> Pose {
        Pose {
            position: Vector3::new(0.5, 0.0, 0.3 + z),
            orientation: UnitQuaternion::identity(),
        }
    }

    fn drift(fz: f64) -> Wrench {
        Wrench::from_array([0.2, -0.1, fz, 0.01, 0.0, 0.0])
    }

    /// `n` cycles from `t0` of an OFF process with `wrench(k)` and `pose(k)`; the events.
    fn feed(
        rz: &mut Rezero,
        t0: f64,
        n: usize,
        wrench: impl Fn(usize) -> Option<Wrench>,
        pose: impl Fn(usize) -> Option<Pose>,
    ) -> Vec<RezeroEvent> {
        (0..n)
            .filter_map(|k| {
                let w = wrench(k).map(|w| rz.apply(&w));
                rz.observe(&RezeroInput {
                    t: t0 + k as f64 * DT,
                    off: true,
                    wrench: w,
                    f: w.map(|w| w.force.z),
                    pose: pose(k),
                    contact_force: 2.0,
                })
            })
            .collect()
    }

    fn stage() -> Rezero {
        Rezero::new(true, RezeroParams::default())
    }

    #[test]
    fn in_free_air_still_and_steady_it_zeroes_once_per_stretch() {
        let mut rz = stage();
        // 3 s at OFF, tool still, 1.2 N of offset with a ±0.3 N ripple: one re-zero, after the
        // free-air time, removing the mean.
        let ripple = |k: usize| if k.is_multiple_of(2) { 0.3 } else { -0.3 };
        let ev = feed(
            &mut rz,
            10.0,
            750,
            |k| Some(drift(1.2 + ripple(k))),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev.len(), 1, "{ev:?}");
        let e = ev[0];
        assert_eq!(e.outcome, RezeroOutcome::Done);
        assert!(e.t - 10.0 >= RezeroParams::default().free_air, "{e:?}");
        assert!((e.offset.force.z - 1.2).abs() < 0.01, "{e:?}");
        assert!((e.offset.force.x - 0.2).abs() < 1e-9, "{e:?}");
        assert!((rz.zero().torque.x - 0.01).abs() < 1e-9);
        // The zero applies: the same offset now reads ~0.
        assert!(rz.apply(&drift(1.2)).force.norm() < 0.01);
        // A pass, then free air again with 0.4 N more drift: re-zeroed again, the zero adds up.
        rz.observe(&RezeroInput {
            t: 14.0,
            off: false,
            wrench: None,
            f: None,
            pose: None,
            contact_force: 2.0,
        });
        let ev = feed(
            &mut rz,
            20.0,
            500,
            |_| Some(drift(1.6)),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev.len(), 1);
        assert!((ev[0].offset.force.z - 0.4).abs() < 0.01, "{:?}", ev[0]);
        assert!((rz.zero().force.z - 1.6).abs() < 0.02);
    }

    #[test]
    fn refused_while_moving_keeps_the_old_zero() {
        let mut rz = stage();
        // The tool moves 10 mm/s along the normal the whole stretch.
        let ev = feed(
            &mut rz,
            0.0,
            1000,
            |_| Some(drift(1.0)),
            |k| Some(pose(k as f64 * DT * 0.01)),
        );
        assert_eq!(ev.len(), 1, "said once: {ev:?}");
        assert_eq!(ev[0].outcome, RezeroOutcome::Moving);
        assert_eq!(rz.zero(), Wrench::default());
        // A rotation alone is moving too.
        let mut rz = stage();
        let turn = |k: usize| {
            Some(Pose {
                orientation: UnitQuaternion::from_euler_angles(k as f64 * 1e-4, 0.0, 0.0),
                ..pose(0.0)
            })
        };
        let ev = feed(&mut rz, 0.0, 500, |_| Some(drift(1.0)), turn);
        assert_eq!(ev[0].outcome, RezeroOutcome::Moving);
        assert_eq!(rz.zero(), Wrench::default());
        // The tool stops: the next window re-zeroes.
        let ev = feed(&mut rz, 2.0, 200, |_| Some(drift(1.0)), |_| Some(pose(0.0)));
        assert_eq!(ev.last().unwrap().outcome, RezeroOutcome::Done);
    }

    #[test]
    fn refused_while_in_contact_keeps_the_old_zero() {
        let mut rz = stage();
        // 8 N on the normal at OFF: a contact (the tool rests on the part, a program left it there).
        let ev = feed(
            &mut rz,
            0.0,
            1000,
            |_| Some(drift(8.0)),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert_eq!(ev[0].outcome, RezeroOutcome::Contact);
        assert_eq!(rz.zero(), Wrench::default());
        // A pull reads negative: a contact too.
        let mut rz = stage();
        let ev = feed(
            &mut rz,
            0.0,
            1000,
            |_| Some(drift(-3.0)),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev[0].outcome, RezeroOutcome::Contact);
        // A touch late in the stretch restarts the free-air time: no re-zero right after it.
        let mut rz = stage();
        let ev = feed(
            &mut rz,
            0.0,
            400,
            |k| Some(drift(if k == 200 { 5.0 } else { 0.5 })),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev.len(), 1);
        assert_eq!(ev[0].outcome, RezeroOutcome::Contact);
        let ev = feed(&mut rz, 1.6, 100, |_| Some(drift(0.5)), |_| Some(pose(0.0)));
        assert!(ev.is_empty(), "within free_air of the touch: {ev:?}");
        assert_eq!(rz.zero(), Wrench::default());
    }

    #[test]
    fn refused_while_the_sensor_is_unhealthy_keeps_the_old_zero() {
        let mut rz = stage();
        // Every 50th cycle gives no usable sample (an error, a NaN, a stale wrench).
        let ev = feed(
            &mut rz,
            0.0,
            1000,
            |k| (!k.is_multiple_of(50)).then(|| drift(1.0)),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert_eq!(ev[0].outcome, RezeroOutcome::Unhealthy);
        assert_eq!(rz.zero(), Wrench::default());
        // A non-finite sample is no sample either.
        let mut rz = stage();
        let ev = feed(
            &mut rz,
            0.0,
            260,
            |k| Some(drift(if k == 200 { f64::NAN } else { 1.0 })),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev.len(), 1, "{ev:?}");
        assert_eq!(ev[0].outcome, RezeroOutcome::Unhealthy);
        assert_eq!(rz.zero(), Wrench::default());
    }

    #[test]
    fn refused_when_unsteady_too_large_or_the_pose_is_unknown() {
        let mut rz = stage();
        let ev = feed(
            &mut rz,
            0.0,
            500,
            |k| Some(drift(if k.is_multiple_of(2) { 1.9 } else { -1.9 })),
            |_| Some(pose(0.0)),
        );
        assert_eq!(ev[0].outcome, RezeroOutcome::Unsteady);
        let mut rz = stage();
        let side = |_| Some(Wrench::from_array([6.0, 0.0, 0.5, 0.0, 0.0, 0.0]));
        let ev = feed(&mut rz, 0.0, 500, side, |_| Some(pose(0.0)));
        assert_eq!(ev[0].outcome, RezeroOutcome::TooLarge);
        let mut rz = stage();
        let ev = feed(&mut rz, 0.0, 500, |_| Some(drift(1.0)), |_| None);
        assert_eq!(ev[0].outcome, RezeroOutcome::NoPose);
        assert_eq!(rz.zero(), Wrench::default());
    }

    #[test]
    fn never_while_a_pass_runs_nor_when_disabled() {
        let mut rz = stage();
        for k in 0..2000 {
            let ev = rz.observe(&RezeroInput {
                t: k as f64 * DT,
                off: false,
                wrench: Some(drift(1.0)),
                f: Some(1.0),
                pose: Some(pose(0.0)),
                contact_force: 2.0,
            });
            assert!(ev.is_none());
        }
        let mut off = Rezero::new(false, RezeroParams::default());
        let ev = feed(
            &mut off,
            0.0,
            2000,
            |_| Some(drift(1.0)),
            |_| Some(pose(0.0)),
        );
        assert!(ev.is_empty());
        assert_eq!(off.zero(), Wrench::default());
        assert!(RezeroParams::default().validate().is_ok());
        let bad = RezeroParams {
            window: f64::NAN,
            ..RezeroParams::default()
        };
        assert!(bad.validate().unwrap_err().contains("window"));
    }
}
