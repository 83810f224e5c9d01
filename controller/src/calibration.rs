//! Gravity calibration on the cell: the robot's own program moves the tool through static orientations in
//! free air while forcecell answers every cycle with a zero correction; each time the tool has stood still
//! long enough in an orientation far enough from the ones already taken, the mean wrench over that still
//! window becomes one pose of the least-squares fit ([`GravityModel::identify`]).
//!
//! Time comes from the robot's cycles (`Cycle::t`), never from a clock.

use core::fmt;

use hal::{Correction, Error as HalError, ForceSensor, RobotLink, UnitQuaternion, Vector3, Wrench};

use crate::control_loop::CycleReport;
use crate::law::Output;
use crate::run::{Cycler, End, RunLimits, Sink, run};

use crate::gravity::{GravityError, GravityModel};

/// When a pose counts as static and new.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollectorConfig {
    /// How long the orientation must stay within `still_tolerance`, s.
    pub still_time: f64,
    /// Largest rotation from the start of a still window, rad.
    pub still_tolerance: f64,
    /// Smallest rotation between two recorded poses, rad.
    pub min_separation: f64,
}

impl Default for CollectorConfig {
    /// 0.5 s still within 0.2°, poses at least 10° apart.
    fn default() -> Self {
        Self {
            still_time: 0.5,
            still_tolerance: 0.2f64.to_radians(),
            min_separation: 10f64.to_radians(),
        }
    }
}

/// Turns a stream of (time, sensor orientation, wrench) into static poses.
#[derive(Clone, Debug)]
pub struct PoseCollector {
    cfg: CollectorConfig,
    start: Option<(f64, UnitQuaternion<f64>)>,
    sum: [f64; 6],
    n: u32,
    taken: bool,
    poses: Vec<(UnitQuaternion<f64>, Wrench)>,
}

impl PoseCollector {
    /// An empty collector.
    pub fn new(cfg: CollectorConfig) -> Self {
        Self {
            cfg,
            start: None,
            sum: [0.0; 6],
            n: 0,
            taken: false,
            poses: Vec::new(),
        }
    }

    /// The poses recorded so far.
    pub fn poses(&self) -> &[(UnitQuaternion<f64>, Wrench)] {
        &self.poses
    }

    fn restart(&mut self, t: f64, q: UnitQuaternion<f64>) {
        self.start = Some((t, q));
        self.sum = [0.0; 6];
        self.n = 0;
        self.taken = false;
    }

    /// One sample. Returns `true` when it completed a new pose. Non-finite samples restart the window.
    pub fn push(&mut self, t: f64, q: UnitQuaternion<f64>, w: &Wrench) -> bool {
        let finite = t.is_finite() && w.is_finite() && q.coords.iter().all(|v| v.is_finite());
        if !finite {
            self.start = None;
            return false;
        }
        match self.start {
            Some((_, q0)) if q0.angle_to(&q) <= self.cfg.still_tolerance => {}
            _ => self.restart(t, q),
        }
        let Some((t0, q0)) = self.start else {
            return false;
        };
        for (s, v) in self.sum.iter_mut().zip(w.to_array()) {
            *s += v;
        }
        self.n += 1;
        if self.taken || t - t0 < self.cfg.still_time {
            return false;
        }
        self.taken = true;
        let new = self
            .poses
            .iter()
            .all(|(p, _)| p.angle_to(&q0) >= self.cfg.min_separation);
        if new {
            let n = f64::from(self.n);
            self.poses
                .push((q0, Wrench::from_array(self.sum.map(|s| s / n))));
        }
        new
    }
}

/// Why a calibration failed.
#[derive(Debug)]
pub enum CalibrationError<E> {
    /// The robot link ended before enough poses were seen.
    Robot {
        /// The link's error.
        error: E,
        /// Poses recorded until then.
        poses: usize,
    },
    /// The fit refused the poses.
    Fit(GravityError),
    /// The operator stopped the calibration before enough poses were seen.
    Stopped {
        /// Poses recorded until then.
        poses: usize,
    },
}

impl<E: fmt::Display> fmt::Display for CalibrationError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Robot { error, poses } => write!(
                f,
                "the robot link ended after {poses} static poses: {error}"
            ),
            Self::Stopped { poses } => {
                write!(f, "stopped by the operator after {poses} static poses")
            }
            Self::Fit(e) => write!(
                f,
                "{e} (hold the tool still in orientations rotated about at least two different axes)"
            ),
        }
    }
}

impl<E: fmt::Debug + fmt::Display> std::error::Error for CalibrationError<E> {}

/// The result of a calibration.
#[derive(Clone, Debug)]
pub struct Calibration {
    /// The fitted tool model and bias.
    pub model: GravityModel,
    /// The poses it was fitted to (sensor orientation, mean wrench).
    pub poses: Vec<(UnitQuaternion<f64>, Wrench)>,
    /// Largest force residual over the poses, N.
    pub worst_force_residual: f64,
}

/// The calibration's cycle for the [run loop](crate::run): answer each robot cycle with a zero
/// correction, then read the sensor and feed the collector (sensor orientation = the robot's measured
/// orientation · `mount`). Sensor errors skip the sample. Done once `wanted` poses are in.
pub struct Collecting<'a, R, S> {
    robot: R,
    sensor: S,
    mount: UnitQuaternion<f64>,
    wanted: usize,
    collector: PoseCollector,
    on_pose: &'a mut dyn FnMut(usize),
    cycles: u64,
}

impl<'a, R: RobotLink, S: ForceSensor> Collecting<'a, R, S> {
    /// Collect `wanted` poses; `on_pose` is told the count after each new pose.
    pub fn new(
        robot: R,
        sensor: S,
        mount: UnitQuaternion<f64>,
        wanted: usize,
        cfg: CollectorConfig,
        on_pose: &'a mut dyn FnMut(usize),
    ) -> Self {
        Self {
            robot,
            sensor,
            mount,
            wanted,
            collector: PoseCollector::new(cfg),
            on_pose,
            cycles: 0,
        }
    }

    /// The poses collected so far.
    pub fn poses(&self) -> &[(UnitQuaternion<f64>, Wrench)] {
        self.collector.poses()
    }

    fn next(&mut self) -> Result<hal::Cycle, R::Error> {
        loop {
            match self.robot.next_cycle() {
                Ok(c) => return Ok(c),
                Err(e) if e.kind().is_transient() => continue,
                Err(e) => return Err(e),
            }
        }
    }
}

impl<R: RobotLink, S: ForceSensor> Cycler for Collecting<'_, R, S> {
    type Error = R::Error;

    fn cycle(&mut self) -> Result<CycleReport, R::Error> {
        let cycle = self.next()?;
        let command = Correction::default();
        self.robot.reply(&command)?;
        self.cycles += 1;
        let sample = self.sensor.read().ok();
        if let Some(s) = sample
            && self
                .collector
                .push(cycle.t, cycle.actual.orientation * self.mount, &s.wrench)
        {
            (self.on_pose)(self.collector.poses().len());
        }
        Ok(CycleReport {
            cycle,
            x: cycle.tool_offset().z,
            f: sample.map(|s| s.wrench.force.z),
            sample,
            wrench: sample.map(|s| s.wrench),
            compensated: false,
            out: Output {
                x_cmd: 0.0,
                x_r: f64::NAN,
                kc_hat: f64::NAN,
                xc_hat: f64::NAN,
                ..Output::default()
            },
            command,
            set_point: 0.0,
            fault: None,
            rezero: None,
        })
    }

    fn stop(&mut self) -> Result<(), R::Error> {
        self.next()?;
        self.robot.reply(&Correction {
            stop: true,
            ..Correction::default()
        })?;
        self.cycles += 1;
        Ok(())
    }

    fn robot_gone(_: &R::Error) -> bool {
        // Transient errors are skipped in `next`: what reaches the runner is the link's end.
        true
    }

    fn cycles(&self) -> u64 {
        self.cycles
    }

    fn done(&self) -> bool {
        self.collector.poses().len() >= self.wanted
    }
}

/// Run `collecting` (answer the robot's cycles with a zero correction until it has its static poses),
/// end the correction motion with `Stop`, and fit; every cycle goes to `sink`. Runs through the one [run loop](crate::run::run), with `limits` (the operator's stop).
pub fn calibrate<R: RobotLink, S: ForceSensor>(
    mut collecting: Collecting<'_, R, S>,
    limits: RunLimits<'_>,
    sink: &mut dyn Sink,
) -> Result<Calibration, CalibrationError<R::Error>> {
    let outcome = run(&mut collecting, limits, sink);
    let poses = collecting.poses().len();
    let failed = |error| CalibrationError::Robot { error, poses };
    match outcome.end {
        End::Done => {}
        End::LinkLost(e) | End::RobotEnded(e) | End::Fault(e) | End::Stopped(Some(e)) => {
            return Err(failed(e));
        }
        End::Stopped(None) | End::Program(_) => return Err(CalibrationError::Stopped { poses }),
    }
    if let Some(Err(e)) = outcome.stop {
        return Err(failed(e));
    }
    let collector = collecting.collector;
    let poses = collector.poses().to_vec();
    let model = GravityModel::identify(&poses).map_err(CalibrationError::Fit)?;
    let worst_force_residual = poses
        .iter()
        .map(|(q, w)| {
            let r: Vector3<f64> = model.compensate(w, q).force;
            r.norm()
        })
        .fold(0.0, f64::max);
    Ok(Calibration {
        model,
        poses,
        worst_force_residual,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::FRAC_PI_2;
    use hal::{Cycle, ErrorKind, Pose, Sample};
    use std::time::Duration;

    fn tool() -> GravityModel {
        GravityModel {
            signed_mass: 2.0,
            mass_moment: Vector3::new(0.0, 0.01, 0.16),
            force_bias: Vector3::new(1.0, -0.5, 2.0),
            torque_bias: Vector3::new(0.02, 0.0, -0.01),
        }
    }

    /// A robot program: hold each orientation 0.8 s, sweeping between them, 4 ms cycles; then silence.
    struct Program {
        k: u64,
        stops: u32,
        holds: Vec<UnitQuaternion<f64>>,
    }

    impl Program {
        fn orientation(&self, t: f64) -> Option<UnitQuaternion<f64>> {
            let seg = (t / 1.0) as usize;
            let into = t - seg as f64;
            let a = *self.holds.get(seg)?;
            if into < 0.8 {
                return Some(a);
            }
            let b = *self.holds.get(seg + 1).unwrap_or(&a);
            Some(a.slerp(&b, (into - 0.8) / 0.2))
        }
    }

    impl RobotLink for Program {
        type Error = ErrorKind;
        fn next_cycle(&mut self) -> Result<Cycle, ErrorKind> {
            let t = self.k as f64 * 0.004;
            let q = self.orientation(t).ok_or(ErrorKind::LinkLost)?;
            Ok(Cycle {
                seq: self.k,
                t,
                period: 0.004,
                actual: Pose {
                    position: Vector3::zeros(),
                    orientation: q,
                },
                programmed: Pose::identity(),
                late_replies: 0,
                missed: 0,
                replied_late: 0,
                new_session: self.k == 0,
                process: None,
            })
        }
        fn reply(&mut self, c: &Correction) -> Result<(), ErrorKind> {
            assert_eq!(
                c.translation,
                Vector3::zeros(),
                "calibration never moves the robot"
            );
            self.stops += u32::from(c.stop);
            self.k += 1;
            Ok(())
        }
    }

    /// The tool hanging on the sensor, with a ±0.05 N dither: its own copy of the program, read once per
    /// cycle (the loop reads the sensor once per answered cycle).
    struct Hanging {
        program: Program,
    }

    impl Hanging {
        fn new(program: &Program) -> Self {
            Self {
                program: Program {
                    k: 0,
                    stops: 0,
                    holds: program.holds.clone(),
                },
            }
        }
    }

    impl ForceSensor for Hanging {
        type Error = ErrorKind;
        fn read(&mut self) -> Result<Sample, ErrorKind> {
            let k = self.program.k;
            self.program.k += 1;
            let q = self
                .program
                .orientation(k as f64 * 0.004)
                .ok_or(ErrorKind::LinkLost)?;
            let m = tool();
            let mut w = m.tool_wrench(&q);
            w.force += m.force_bias;
            w.torque += m.torque_bias;
            w.force.x += if k.is_multiple_of(2) { 0.05 } else { -0.05 };
            Ok(Sample {
                wrench: w,
                seq: k,
                age: Duration::ZERO,
            })
        }
    }

    fn poses(n: usize) -> Vec<UnitQuaternion<f64>> {
        (0..n)
            .map(|i| {
                let a = FRAC_PI_2 * i as f64 / (n - 1) as f64;
                if i % 2 == 0 {
                    UnitQuaternion::from_euler_angles(a, 0.0, 0.0)
                } else {
                    UnitQuaternion::from_euler_angles(0.0, a, 0.3)
                }
            })
            .collect()
    }

    #[test]
    fn a_program_of_static_poses_calibrates_the_tool() {
        let mut program = Program {
            k: 0,
            stops: 0,
            holds: poses(8),
        };
        let mut sensor = Hanging::new(&program);
        let mut seen = Vec::new();
        let result = calibrate(
            Collecting::new(
                &mut program,
                &mut sensor,
                UnitQuaternion::identity(),
                8,
                CollectorConfig::default(),
                &mut |n| seen.push(n),
            ),
            RunLimits::default(),
            &mut (),
        )
        .unwrap();
        assert_eq!(seen, (1..=8).collect::<Vec<_>>());
        assert_eq!(program.stops, 1, "Stop sent once, after the last pose");
        let m = result.model;
        assert!((m.mass() - 2.0).abs() < 0.01, "mass {}", m.mass());
        assert!((m.force_bias - tool().force_bias).norm() < 0.05);
        assert!(
            result.worst_force_residual < 0.1,
            "{}",
            result.worst_force_residual
        );
    }

    #[test]
    fn too_few_poses_before_the_robot_stops_is_an_error_that_says_how_many() {
        let mut program = Program {
            k: 0,
            stops: 0,
            holds: poses(2),
        };
        let mut sensor = Hanging::new(&program);
        let e = calibrate(
            Collecting::new(
                &mut program,
                &mut sensor,
                UnitQuaternion::identity(),
                8,
                CollectorConfig::default(),
                &mut |_| {},
            ),
            RunLimits::default(),
            &mut (),
        )
        .unwrap_err();
        assert!(matches!(e, CalibrationError::Robot { poses: 2, .. }), "{e}");
        assert!(e.to_string().contains("2 static poses"), "{e}");
    }

    #[test]
    fn moving_samples_and_repeated_orientations_are_not_poses() {
        let mut c = PoseCollector::new(CollectorConfig::default());
        let w = Wrench::default();
        // Turning continuously: never still.
        for k in 0..500 {
            let q = UnitQuaternion::from_euler_angles(k as f64 * 0.01, 0.0, 0.0);
            assert!(!c.push(k as f64 * 0.004, q, &w));
        }
        // Still for 0.6 s: one pose; the same orientation again later: no new pose.
        let q = UnitQuaternion::identity();
        let got: usize = (0..150)
            .map(|k| usize::from(c.push(10.0 + k as f64 * 0.004, q, &w)))
            .sum();
        assert_eq!(got, 1);
        let q2 = UnitQuaternion::from_euler_angles(0.5, 0.0, 0.0);
        for k in 0..10 {
            c.push(20.0 + k as f64 * 0.004, q2, &w);
        }
        let again: usize = (0..150)
            .map(|k| usize::from(c.push(30.0 + k as f64 * 0.004, q, &w)))
            .sum();
        assert_eq!(again, 0);
        assert_eq!(c.poses().len(), 1);
        // NaN restarts the window and is never averaged in.
        let bad = Wrench::from_array([f64::NAN; 6]);
        assert!(!c.push(40.0, q2, &bad));
    }
}
