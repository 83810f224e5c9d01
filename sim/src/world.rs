//! One simulated cell: contact plant + inner position loop + sensor model on one clock, and the
//! in-process backends that implement the HAL traits on it (no wire).
//!
//! The wire peers (simulated robot controller, simulated sensor nodes) share a [`World`] through
//! [`SharedWorld`] the same way.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use hal::{
    Correction, Cycle, ErrorKind, ForceSensor, Pose, ProcessCommand, ProcessState, RobotLink,
    Sample, UnitQuaternion, Vector3, Wrench,
};

use crate::geometry::{Contact, ContactState, Geometry};
use crate::inner::{InnerLoop, InnerLoopModel};
use crate::plant::ContactPlant;
use crate::program::{Program, ProgramRunner, SurfaceForm};
use crate::sensor_model::{SensorModel, SensorParams};

/// The simulated cell's state. Time advances only through [`World::advance`].
#[derive(Clone, Debug)]
pub struct World {
    plant: ContactPlant,
    inner: InnerLoop,
    sensor: SensorModel,
    programmed: Pose,
    k: u64,
    last_command: f64,
    measurements: u64,
    truth: Vec<Truth>,
    form: SurfaceForm,
    program: Option<ProgramRunner>,
    /// Path position when no program moves the tool, m.
    s: f64,
    /// A curved part's geometry, pad and tool rotation (`None`: the 1-DOF plant, as ever), and the
    /// torque's sensor model.
    curved: Option<(Contact, SensorModel)>,
    /// World time at which the program was first done, s.
    program_done_at: Option<f64>,
}

/// The true state of the cell at one cycle, logged by [`World::advance`] for recording and metrics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truth {
    /// Time, s.
    pub t: f64,
    /// Tool position along the normal, m.
    pub x: f64,
    /// Contact force, N.
    pub f: f64,
    /// Stiffness, N/m.
    pub k_c: f64,
    /// Surface position, m.
    pub x_c: f64,
    /// Path position along the workpiece, m.
    pub s: f64,
    /// On a curved part ([`World::with_geometry`]): the angle between the tool axis and the surface
    /// normal, less the program's tilt (the norm of their difference as rotations), rad; NaN on the
    /// 1-DOF plant.
    pub tilt_error: f64,
}

/// A world shared between the peers of one simulation.
pub type SharedWorld = Arc<Mutex<World>>;

/// Lock a shared world; a poisoned lock (a peer panicked) still yields the state.
pub fn lock(w: &SharedWorld) -> MutexGuard<'_, World> {
    w.lock().unwrap_or_else(|p| p.into_inner())
}

impl World {
    /// A cell at rest with the tool at normal position `x0` (m).
    pub fn new(plant: ContactPlant, model: InnerLoopModel, sensor: SensorParams, x0: f64) -> Self {
        Self {
            plant,
            inner: InnerLoop::new(model, x0),
            sensor: SensorModel::new(sensor),
            programmed: Self::default_programmed_pose(),
            k: 0,
            last_command: x0,
            measurements: 0,
            truth: Vec::new(),
            form: SurfaceForm::default(),
            program: None,
            s: 0.0,
            curved: None,
            program_done_at: None,
        }
    }

    /// A curved part (`docs/curved-parts.md`): the surface normal varies along the path, the pad
    /// presses with a moment when tilted, friction drags against the feed, the tool turns by the
    /// correction's rotation through the inner loop, and the sensor reads all six axes (the torque
    /// through its own model: the force's filter, noise, bias and drift scaled by
    /// [`crate::geometry::TORQUE_ARM`]).
    pub fn with_geometry(mut self, geometry: Geometry) -> Self {
        let contact = Contact::new(geometry, *self.inner.model());
        let torque = SensorModel::new(crate::geometry::torque_params(self.sensor.params()));
        self.curved = Some((contact, torque));
        self
    }

    /// The curved part's contact now, if the world has one.
    pub fn contact_state(&self) -> Option<ContactState> {
        let (c, _) = self.curved.as_ref()?;
        let t = self.time();
        let s = self.path_position();
        Some(c.state(
            self.plant.k_c.at(t).max(0.0),
            self.plant.c_e,
            self.inner.position(),
            self.inner.velocity(),
            s,
            c.feed(),
            self.plant.x_c.at(t) + self.form.height(s),
        ))
    }

    /// The workpiece's form along the path.
    pub fn with_form(mut self, form: SurfaceForm) -> Self {
        self.form = form;
        self
    }

    /// A robot program: each cycle carries its process command, and it moves the tool along the path.
    pub fn with_program(mut self, program: Program) -> Self {
        self.program = Some(ProgramRunner::new(program));
        self
    }

    /// The running program, if any.
    pub fn program(&self) -> Option<&ProgramRunner> {
        self.program.as_ref()
    }

    /// The program's command for this cycle, if a program runs.
    pub fn process_command(&self) -> Option<ProcessCommand> {
        self.program.as_ref().map(ProgramRunner::command)
    }

    /// The process state the PC replied to this cycle.
    pub fn process_reply(&mut self, state: ProcessState) {
        if let Some(p) = &mut self.program {
            p.observe(state);
        }
    }

    /// Path position, m.
    pub fn path_position(&self) -> f64 {
        self.program
            .as_ref()
            .map_or(self.s, ProgramRunner::path_position)
    }

    /// Where the programmed path is on the part now, base frame, m: a line runs along base x (x = the
    /// path position, y = 0); a raster's passes lie `step_over` apart along base y.
    pub fn path_xy(&self) -> (f64, f64) {
        self.program
            .as_ref()
            .map_or((self.s, 0.0), ProgramRunner::path_xy)
    }

    /// The programmed (uncorrected) tool pose now: the start pose moved along the path by
    /// [`World::path_xy`] in the base frame (the tool's normal is base −z, so the move is across it).
    pub fn programmed_pose(&self) -> Pose {
        let (x, y) = self.path_xy();
        Pose {
            position: self.programmed.position + Vector3::new(x, y, 0.0),
            orientation: self.programmed.orientation,
        }
    }

    /// The programmed (uncorrected) tool pose at the start of the path: 0.5 m out, 0.3 m up, tool z
    /// pointing down onto the workpiece, so the normal axis is base −z.
    pub fn default_programmed_pose() -> Pose {
        Pose {
            position: Vector3::new(0.5, 0.0, 0.3),
            orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
        }
    }

    /// Share it.
    pub fn shared(self) -> SharedWorld {
        Arc::new(Mutex::new(self))
    }

    /// Simulated time, s.
    pub fn time(&self) -> f64 {
        self.k as f64 * self.inner.model().period
    }

    /// Cycle index.
    pub fn cycle_index(&self) -> u64 {
        self.k
    }

    /// Control period, s.
    pub fn period(&self) -> f64 {
        self.inner.model().period
    }

    /// The plant.
    pub fn plant(&self) -> &ContactPlant {
        &self.plant
    }

    /// The sensor model.
    pub fn sensor_model(&self) -> &SensorModel {
        &self.sensor
    }

    /// True tool position along the normal, m.
    pub fn position(&self) -> f64 {
        self.inner.position()
    }

    /// The last command applied, m.
    pub fn last_command(&self) -> f64 {
        self.last_command
    }

    /// True contact force now, N.
    pub fn true_force(&self) -> f64 {
        if let Some(st) = self.contact_state() {
            return st.normal;
        }
        // The form shifts the surface: the same as the tool standing back by its height.
        let (x, y) = self.path_xy();
        let h = self.form.height_at(x, y);
        self.plant.force(
            self.time(),
            self.inner.position() - h,
            self.inner.velocity(),
        )
    }

    /// True surface position now, m (the plant's, plus the form under the tool).
    pub fn surface(&self) -> f64 {
        let (x, y) = self.path_xy();
        self.plant.x_c.at(self.time()) + self.form.height_at(x, y)
    }

    /// True stiffness now, N/m.
    pub fn stiffness(&self) -> f64 {
        self.plant.k_c.at(self.time())
    }

    /// True wrench in the sensor (= tool) frame. Convention of the simulated sensor: a compressive contact
    /// force reads **positive** `F_z`.
    pub fn true_wrench(&self) -> Wrench {
        if let Some(st) = self.contact_state() {
            return Wrench {
                force: st.force,
                torque: st.torque,
            };
        }
        Wrench::from_array([0.0, 0.0, self.true_force(), 0.0, 0.0, 0.0])
    }

    /// Measure through the sensor model: `None` in a dropout.
    pub fn measure(&mut self) -> Option<Wrench> {
        let t = self.time();
        if self.curved.is_some() {
            let w = self.true_wrench();
            let (_, torque_model) = self.curved.as_mut()?;
            // The torque's model filters on through a force dropout as the force's does.
            let tq = torque_model.measure(t, w.torque.into());
            let f = self.sensor.measure(t, w.force.into()).ok()?;
            self.measurements += 1;
            return Some(Wrench {
                force: Vector3::from(f),
                torque: Vector3::from(tq.ok()?),
            });
        }
        let f = self
            .sensor
            .measure(t, self.true_wrench().force.into())
            .ok()?;
        self.measurements += 1;
        Some(Wrench {
            force: Vector3::from(f),
            torque: Vector3::zeros(),
        })
    }

    /// Number of successful measurements so far.
    pub fn measurements(&self) -> u64 {
        self.measurements
    }

    /// The measured state as the robot reports it for the current cycle.
    pub fn cycle(&self) -> Cycle {
        let mut p = self.programmed_pose();
        let mut turned = p.orientation;
        if let Some((c, _)) = &self.curved {
            // The program's tilt is the programmed pose's; the correction's rotation the actual's.
            p.orientation *= c.geometry().programmed();
            turned = p.orientation * UnitQuaternion::from_scaled_axis(c.rotation());
        }
        let actual = Pose {
            position: p.position + p.orientation * Vector3::new(0.0, 0.0, self.inner.position()),
            orientation: turned,
        };
        Cycle {
            seq: self.k,
            t: self.time(),
            period: self.period(),
            actual,
            programmed: p,
            late_replies: 0,
            missed: 0,
            replied_late: 0,
            new_session: false,
            process: self.process_command(),
        }
    }

    /// The true state now.
    pub fn truth(&self) -> Truth {
        Truth {
            t: self.time(),
            x: self.position(),
            f: self.true_force(),
            k_c: self.stiffness(),
            x_c: self.surface(),
            s: self.path_position(),
            tilt_error: self.curved.as_ref().map_or(f64::NAN, |(c, _)| {
                let want = Vector3::new(0.0, c.geometry().program_tilt, 0.0);
                self.contact_state()
                    .map_or(f64::NAN, |st| (st.tilt - want).norm())
            }),
        }
    }

    /// Take the truth logged since the last call (the log starts empty again): a long run hands it
    /// on as it goes instead of keeping every cycle in memory.
    pub fn drain_truth(&mut self) -> Vec<Truth> {
        std::mem::take(&mut self.truth)
    }

    /// The true state at every cycle so far (index = cycle index), followed by the state now.
    pub fn truth_log(&self) -> Vec<Truth> {
        let mut v = self.truth.clone();
        v.push(self.truth());
        v
    }

    /// Apply the normal component of `correction` (absolute offset, m) — or hold the last one when
    /// `None` or non-finite — and advance the physics one period.
    pub fn advance(&mut self, correction: Option<&Correction>) {
        if let Some(c) = correction
            && c.translation.z.is_finite()
        {
            self.last_command = c.translation.z;
        }
        self.truth.push(self.truth());
        self.inner.advance(self.last_command);
        let s0 = self.path_position();
        if let Some(p) = &mut self.program {
            p.advance(self.inner.model().period);
        }
        if self.curved.is_some() {
            let feed = (self.path_position() - s0) / self.period();
            let rotation = correction.map(|c| c.rotation);
            if let Some((c, _)) = &mut self.curved {
                c.advance(rotation, feed);
            }
        }
        self.k += 1;
        if self.program_done_at.is_none() && self.program.as_ref().is_some_and(|p| p.done()) {
            self.program_done_at = Some(self.time());
        }
    }

    /// World time at which the program was first done, s (`None`: not done, or no program). A peer
    /// that answers cycles on another thread compares it with the time of the cycle it answered last:
    /// the world may already have advanced past that cycle.
    pub fn program_done_at(&self) -> Option<f64> {
        self.program_done_at
    }
}

/// The robot side of a world, in process: every `next_cycle` is the world's next period.
pub struct InProcRobot {
    world: SharedWorld,
    started: bool,
    answered: bool,
}

impl InProcRobot {
    /// A robot on `world`.
    pub fn new(world: SharedWorld) -> Self {
        Self {
            world,
            started: false,
            answered: false,
        }
    }
}

impl RobotLink for InProcRobot {
    type Error = ErrorKind;

    fn next_cycle(&mut self) -> Result<Cycle, ErrorKind> {
        let mut w = lock(&self.world);
        if self.started && !self.answered {
            // Nobody answered: the robot holds the last correction (HOLDON = 1) and moves on.
            w.advance(None);
        }
        self.started = true;
        self.answered = false;
        Ok(w.cycle())
    }

    fn reply(&mut self, correction: &Correction) -> Result<(), ErrorKind> {
        if !self.started || self.answered {
            return Err(ErrorKind::Other);
        }
        self.answered = true;
        let mut w = lock(&self.world);
        w.process_reply(correction.process);
        w.advance(Some(correction));
        Ok(())
    }
}

/// The sensor side of a world, in process: every `read` measures the world now.
pub struct InProcSensor {
    world: SharedWorld,
    seq: u64,
}

impl InProcSensor {
    /// A sensor on `world`.
    pub fn new(world: SharedWorld) -> Self {
        Self { world, seq: 0 }
    }
}

impl ForceSensor for InProcSensor {
    type Error = ErrorKind;

    fn read(&mut self) -> Result<Sample, ErrorKind> {
        let w = lock(&self.world).measure().ok_or(ErrorKind::Timeout)?;
        self.seq += 1;
        Ok(Sample {
            wrench: w,
            seq: self.seq,
            age: Duration::ZERO,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_cycle_reports_the_normal_offset_and_applies_the_reply() {
        let world = World::new(
            ContactPlant::spring(70_000.0, 0.01),
            InnerLoopModel::P0,
            SensorParams::default(),
            0.002,
        )
        .shared();
        let mut robot = InProcRobot::new(world.clone());
        let c = robot.next_cycle().unwrap();
        assert!((c.tool_offset().z - 0.002).abs() < 1e-12);
        assert_eq!(robot.reply(&Correction::along_z(0.0101)), Ok(()));
        assert_eq!(
            robot.reply(&Correction::along_z(0.0101)),
            Err(ErrorKind::Other),
            "one reply per cycle"
        );
        let c = robot.next_cycle().unwrap();
        assert!((c.tool_offset().z - 0.0101).abs() < 1e-12);
        let mut sensor = InProcSensor::new(world);
        let s = sensor.read().unwrap();
        assert!((s.wrench.force.z - 7.0).abs() < 1e-6, "{:?}", s.wrench);
    }

    #[test]
    fn the_programmed_pose_follows_the_path_and_the_offset_stays_along_the_normal() {
        use crate::program::{Segment, SegmentMode};
        let program = Program {
            segments: vec![Segment {
                mode: SegmentMode::Off,
                force: 0.0,
                ramp: 0.0,
                segment: 1,
                feed: 0.05,
                length: 0.01,
                dwell: 0.0,
            }],
            wait_timeout: 1.0,
            passes: 1,
            step_over: 0.0,
            transfer_feed: 0.1,
        };
        let world = World::new(
            ContactPlant::spring(70_000.0, 0.01),
            InnerLoopModel::P0,
            SensorParams::default(),
            0.002,
        )
        .with_program(program)
        .shared();
        let mut robot = InProcRobot::new(world.clone());
        let start = robot.next_cycle().unwrap();
        let mut last = start;
        // 10 mm at 50 mm/s is 0.2 s: run 0.4 s whatever the period.
        let n = (0.4 / lock(&world).period()).round() as usize;
        for _ in 0..n {
            robot.reply(&Correction::along_z(0.002)).unwrap();
            last = robot.next_cycle().unwrap();
        }
        let s = lock(&world).path_position();
        assert!((s - 0.01).abs() < 1e-12, "the move ran to its end: {s}");
        let moved = last.programmed.position - start.programmed.position;
        assert!(
            (moved.x - s).abs() < 1e-12 && moved.y == 0.0 && moved.z == 0.0,
            "{moved:?}"
        );
        assert!((last.actual.position.x - (0.5 + s)).abs() < 1e-12);
        assert!((last.tool_offset().z - 0.002).abs() < 1e-12);
        assert!(last.tool_offset().x.abs() < 1e-12);
    }

    #[test]
    fn the_program_end_is_stamped_with_the_world_time_it_happened() {
        use crate::program::{Program, Segment, SegmentMode};
        // A PRESS that never sees PRESSING: the program aborts after its wait (20 ms).
        let program = Program {
            segments: vec![Segment {
                mode: SegmentMode::Press,
                force: 10.0,
                ramp: 0.2,
                segment: 1,
                feed: 0.01,
                length: 0.01,
                dwell: 0.0,
            }],
            wait_timeout: 0.02,
            passes: 1,
            step_over: 0.0,
            transfer_feed: 0.1,
        };
        let mut w = World::new(
            ContactPlant::spring(70_000.0, 0.01),
            InnerLoopModel::P0,
            SensorParams::default(),
            0.0,
        )
        .with_program(program);
        let mut at = None;
        for _ in 0..100 {
            assert_eq!(w.program_done_at(), at, "stamped once, when it ends");
            w.advance(None);
            if at.is_none() && w.program().is_some_and(|p| p.done()) {
                at = Some(w.time());
            }
        }
        let at = at.expect("the program ended");
        assert!(at >= 0.02, "not before its wait: {at}");
        assert_eq!(w.program_done_at(), Some(at));
    }

    #[test]
    fn unanswered_cycle_holds_and_time_moves_on() {
        let world = World::new(
            ContactPlant::spring(70_000.0, 0.01),
            InnerLoopModel::P0,
            SensorParams::default(),
            0.0,
        )
        .shared();
        let mut robot = InProcRobot::new(world.clone());
        robot.next_cycle().unwrap();
        robot.reply(&Correction::along_z(0.001)).unwrap();
        robot.next_cycle().unwrap();
        let c = robot.next_cycle().unwrap();
        assert_eq!(c.seq, 2);
        assert!((c.tool_offset().z - 0.001).abs() < 1e-12);
    }

    #[test]
    fn a_curved_world_reports_the_rotation_the_full_wrench_and_the_tilt() {
        use crate::geometry::{Geometry, Shape};
        let g = Geometry {
            shape: Shape::Flat,
            misplace_x: 0.05,
            misplace_y: 0.0,
            pad_radius: 0.02,
            friction: 0.0,
            tool_length: 0.1,
            program_tilt: 0.0,
        };
        let world = World::new(
            ContactPlant::spring(10_000.0, 0.001),
            InnerLoopModel::P0,
            SensorParams::default(),
            0.003,
        )
        .with_geometry(g)
        .shared();
        let mut robot = InProcRobot::new(world.clone());
        let mut sensor = InProcSensor::new(world.clone());
        let c = robot.next_cycle().unwrap();
        assert_eq!(c.actual.orientation, c.programmed.orientation);
        let w = sensor.read().unwrap().wrench;
        // Tilted: a moment about x and a lateral force, all six axes on the sample.
        assert!(w.torque.x.abs() > 1e-3 && w.force.y.abs() > 0.1, "{w:?}");
        assert!((lock(&world).truth().tilt_error - 0.05).abs() < 1e-9);
        let turn = Correction {
            rotation: Vector3::new(0.05, 0.0, 0.0),
            ..Correction::along_z(0.003)
        };
        robot.reply(&turn).unwrap();
        let c = robot.next_cycle().unwrap();
        let rel = c.programmed.orientation.inverse() * c.actual.orientation;
        assert!(
            (rel.scaled_axis() - turn.rotation).norm() < 1e-12,
            "the actual pose turned"
        );
        let w = sensor.read().unwrap().wrench;
        assert!(w.torque.norm() < 1e-9 && w.force.y.abs() < 1e-9, "{w:?}");
        assert!(lock(&world).truth().tilt_error < 1e-9);
    }

    #[test]
    fn a_flat_square_geometry_gives_the_one_dof_force() {
        let mk = |geo: bool| {
            let w = World::new(
                ContactPlant::spring(10_000.0, 0.001),
                InnerLoopModel::P1,
                SensorParams::default(),
                0.0,
            );
            let w = if geo {
                w.with_geometry(crate::geometry::Geometry {
                    shape: crate::geometry::Shape::Flat,
                    misplace_x: 0.0,
                    misplace_y: 0.0,
                    pad_radius: 0.02,
                    friction: 0.0,
                    tool_length: 0.1,
                    program_tilt: 0.0,
                })
            } else {
                w
            };
            w.shared()
        };
        let (a, b) = (mk(false), mk(true));
        for k in 0..200 {
            let z = 0.003 * (k as f64 / 100.0).min(1.0);
            for w in [&a, &b] {
                lock(w).advance(Some(&Correction::along_z(z)));
            }
            let (fa, fb) = (lock(&a).true_force(), lock(&b).true_force());
            assert!((fa - fb).abs() < 1e-9, "{k}: {fa} {fb}");
        }
        assert!(lock(&a).truth().tilt_error.is_nan());
    }
}
