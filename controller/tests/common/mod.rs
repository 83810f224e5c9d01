//! Closed-loop harness for the controller's scenario tests: the simulated cell of `sim` (contact plant,
//! inner loop P0–P2, sensor model) driven through the HAL by a [`ControlLoop`], with the truth recorded
//! from the [`World`] and metrics computed as the application's runner defines them (true force, band
//! ±2 % of `f_r`, settle = last exit from the band).
#![allow(dead_code)]

use controller::{ControlLoop, ForceLaw, LoopConfig, Tuning};
use sim::{ContactPlant, InProcRobot, InProcSensor, InnerLoopModel, Schedule, SensorParams, World};

/// The project's default tuning, as shipped.
pub fn robust() -> Tuning {
    toml::from_str(include_str!("../../../tunings/robust.toml")).expect("robust.toml parses")
}

/// The paper's tuning, as shipped.
pub fn paper() -> Tuning {
    toml::from_str(include_str!("../../../tunings/paper.toml")).expect("paper.toml parses")
}

/// One scenario: the cell and how long to run it.
#[derive(Clone, Debug)]
pub struct Cell {
    pub plant: InnerLoopModel,
    pub k_c: Schedule,
    pub x_c: Schedule,
    pub sensor: SensorParams,
    pub x0: f64,
    pub duration: f64,
}

impl Cell {
    /// k_c 70 kN/m, surface at 10 mm, start 1 mm short, perfect sensor.
    pub fn nominal(plant: InnerLoopModel, duration: f64) -> Self {
        Self {
            plant,
            k_c: Schedule::constant(70_000.0),
            x_c: Schedule::constant(0.010),
            sensor: SensorParams::default(),
            x0: 0.009,
            duration,
        }
    }
}

/// One recorded step (truth at the instant the controller measured).
#[derive(Clone, Copy, Debug, Default)]
pub struct Row {
    pub t: f64,
    /// True contact force, N.
    pub f: f64,
    /// True position, m.
    pub x: f64,
    /// Command sent, m.
    pub u: f64,
    pub kc_hat: f64,
    pub xc_hat: f64,
    pub k_c: f64,
    pub x_c: f64,
    pub f_r: f64,
}

/// A run.
pub struct Trace {
    pub rows: Vec<Row>,
    pub counters: controller::EventCounts,
    pub stats: controller::LoopStats,
    pub period: f64,
}

/// Run a tuning on a cell (the loop limits of the tuning apply).
pub fn run_tuning(t: &Tuning, cell: &Cell) -> Trace {
    let law = t.law.build().expect("tuning builds");
    run(law, t.loop_cfg, cell)
}

/// Run any law on a cell.
pub fn run<L: ForceLaw>(law: L, cfg: LoopConfig, cell: &Cell) -> Trace {
    let plant = ContactPlant {
        k_c: cell.k_c.clone(),
        x_c: cell.x_c.clone(),
        c_e: 0.0,
    };
    let world = World::new(plant, cell.plant, cell.sensor.clone(), cell.x0).shared();
    let f_r = law.set_point();
    let mut lp = ControlLoop::new(
        InProcRobot::new(world.clone()),
        InProcSensor::new(world.clone()),
        law,
        cfg,
    );
    let steps = (cell.duration / cell.plant.period).round() as usize;
    let mut rows = Vec::with_capacity(steps);
    for _ in 0..steps {
        let mut row = {
            let w = sim::world::lock(&world);
            Row {
                t: w.time(),
                f: w.true_force(),
                x: w.position(),
                k_c: w.stiffness(),
                x_c: w.surface(),
                f_r,
                ..Row::default()
            }
        };
        let rep = lp.cycle().expect("the simulated cell never fails");
        row.u = rep.command.translation.z;
        row.kc_hat = rep.out.kc_hat;
        row.xc_hat = rep.out.xc_hat;
        rows.push(row);
    }
    Trace {
        counters: lp.law().counters(),
        stats: lp.stats(),
        rows,
        period: cell.plant.period,
    }
}

impl Trace {
    fn window(&self, from: f64, until: f64) -> impl Iterator<Item = &Row> {
        self.rows
            .iter()
            .filter(move |r| r.t >= from && r.t <= until)
    }

    /// First time the true force is above zero, s.
    pub fn first_contact(&self) -> f64 {
        self.rows
            .iter()
            .find(|r| r.f > 0.0)
            .map_or(f64::NAN, |r| r.t)
    }

    /// Largest true force in the window, N.
    pub fn peak(&self, from: f64, until: f64) -> f64 {
        self.window(from, until).map(|r| r.f).fold(0.0, f64::max)
    }

    /// Time from `from` (or first contact, if later) to the last exit from ±2 % of f_r, s (∞: not settled).
    pub fn settle(&self, from: f64, until: f64) -> f64 {
        let t0 = from.max(self.first_contact());
        let w: Vec<&Row> = self.window(t0, until).collect();
        match w.iter().rposition(|r| (r.f - r.f_r).abs() > 0.02 * r.f_r) {
            None => 0.0,
            Some(i) if i + 1 == w.len() => f64::INFINITY,
            Some(i) => w[i + 1].t - t0,
        }
    }

    /// Largest |f − f_r| in the window, N.
    pub fn max_error(&self, from: f64, until: f64) -> f64 {
        self.window(from, until)
            .map(|r| (r.f - r.f_r).abs())
            .fold(0.0, f64::max)
    }

    /// RMS of f − f_r in the window, N.
    pub fn rms_error(&self, from: f64, until: f64) -> f64 {
        let (s, n) = self.window(from, until).fold((0.0, 0usize), |(s, n), r| {
            (s + (r.f - r.f_r).powi(2), n + 1)
        });
        (s / n as f64).sqrt()
    }

    /// Standard deviation of the true force in the window, N.
    pub fn force_std(&self, from: f64, until: f64) -> f64 {
        let v: Vec<f64> = self.window(from, until).map(|r| r.f).collect();
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|f| (f - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    }

    /// Standard deviation of the true force about its least-squares line in the window, N, and the
    /// line's slope, N/s: what noise does, separated from what a drifting bias does.
    pub fn force_std_detrended(&self, from: f64, until: f64) -> (f64, f64) {
        let w: Vec<(f64, f64)> = self.window(from, until).map(|r| (r.t, r.f)).collect();
        let n = w.len() as f64;
        let mt = w.iter().map(|p| p.0).sum::<f64>() / n;
        let mf = w.iter().map(|p| p.1).sum::<f64>() / n;
        let stt = w.iter().map(|p| (p.0 - mt).powi(2)).sum::<f64>();
        let stf = w.iter().map(|p| (p.0 - mt) * (p.1 - mf)).sum::<f64>();
        let slope = stf / stt;
        let var = w
            .iter()
            .map(|p| (p.1 - mf - slope * (p.0 - mt)).powi(2))
            .sum::<f64>()
            / n;
        (var.sqrt(), slope)
    }

    /// Drops of the true force to zero after first contact in the window, and the longest, s.
    pub fn contact_losses(&self, from: f64, until: f64) -> (usize, f64) {
        let t0 = from.max(self.first_contact());
        let mut n = 0;
        let mut longest: f64 = 0.0;
        let mut start: Option<f64> = None;
        let mut last_t = t0;
        for r in self.window(t0, until) {
            match (r.f > 0.0, start) {
                (false, None) => {
                    start = Some(r.t);
                    n += 1;
                }
                (true, Some(s)) => {
                    longest = longest.max(r.t - s);
                    start = None;
                }
                _ => {}
            }
            last_t = r.t;
        }
        if let Some(s) = start {
            longest = longest.max(last_t - s);
        }
        (n, longest)
    }

    /// The last row at or before `t`.
    pub fn at(&self, t: f64) -> Row {
        *self
            .rows
            .iter()
            .rev()
            .find(|r| r.t <= t + 1e-12)
            .expect("t within the run")
    }

    /// Largest change of the command between two steps, m.
    pub fn max_command_step(&self) -> f64 {
        self.rows
            .windows(2)
            .map(|w| (w[1].u - w[0].u).abs())
            .fold(0.0, f64::max)
    }

    /// Every command finite.
    pub fn commands_finite(&self) -> bool {
        self.rows.iter().all(|r| r.u.is_finite())
    }
}

/// The plants the targets must hold on.
pub const PLANTS: [(&str, InnerLoopModel); 2] =
    [("P1", InnerLoopModel::P1), ("P2", InnerLoopModel::P2)];
