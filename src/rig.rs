//! A robot and a force sensor against an ideal spring, sharing one position through an `Rc<Cell>`:
//! neither allocates, locks nor makes a system call, so the control loop's own cost (and the
//! recorder's) can be measured and its allocations counted — the recorder's allocation test and its
//! benchmark use it. The robot follows each command exactly; the sensor reads `k·(x − x_c)` in contact.

use std::cell::Cell;
use std::rc::Rc;
use std::time::Duration;

use hal::{Correction, Cycle, ErrorKind, ForceSensor, Pose, RobotLink, Sample, Vector3, Wrench};

/// The spring and the shared position.
#[derive(Clone, Debug)]
pub struct Spring {
    x: Rc<Cell<f64>>,
    /// Stiffness, N/m.
    pub k: f64,
    /// Surface position, m (contact when `x > x_c`).
    pub x_c: f64,
    /// Sign the sensor reports a compressive force with (the loop's `force_sign`).
    pub sign: f64,
}

impl Spring {
    /// A spring of stiffness `k` at `x_c`, the tool at `x0`.
    pub fn new(k: f64, x_c: f64, x0: f64, sign: f64) -> Self {
        Self {
            x: Rc::new(Cell::new(x0)),
            k,
            x_c,
            sign,
        }
    }

    /// The robot and the sensor on this spring, `period` s a cycle.
    pub fn devices(&self, period: f64) -> (SpringRobot, SpringSensor) {
        (
            SpringRobot {
                spring: self.clone(),
                seq: 0,
                period,
            },
            SpringSensor {
                spring: self.clone(),
                seq: 0,
            },
        )
    }
}

/// The robot half: reports the shared position, moves to each command.
#[derive(Debug)]
pub struct SpringRobot {
    spring: Spring,
    seq: u64,
    period: f64,
}

impl RobotLink for SpringRobot {
    type Error = ErrorKind;

    fn next_cycle(&mut self) -> Result<Cycle, ErrorKind> {
        self.seq += 1;
        Ok(Cycle {
            seq: self.seq,
            t: self.seq as f64 * self.period,
            period: self.period,
            actual: Pose::from_position(Vector3::new(0.0, 0.0, self.spring.x.get())),
            programmed: Pose::identity(),
            late_replies: 0,
            missed: 0,
            replied_late: 0,
            new_session: false,
            process: None,
        })
    }

    fn reply(&mut self, c: &Correction) -> Result<(), ErrorKind> {
        self.spring.x.set(c.translation.z);
        Ok(())
    }
}

/// The sensor half: the spring's force at the shared position.
#[derive(Debug)]
pub struct SpringSensor {
    spring: Spring,
    seq: u64,
}

impl ForceSensor for SpringSensor {
    type Error = ErrorKind;

    fn read(&mut self) -> Result<Sample, ErrorKind> {
        self.seq += 1;
        let s = &self.spring;
        let f = (s.k * (s.x.get() - s.x_c)).max(0.0);
        Ok(Sample {
            wrench: Wrench::from_array([0.0, 0.0, s.sign * f, 0.0, 0.0, 0.0]),
            seq: self.seq,
            age: Duration::ZERO,
        })
    }
}
