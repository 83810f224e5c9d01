//! A robot program for the simulated controller: segments that command the force process over RSI's
//! process channels (`FcCmd`) and move the tool along the workpiece at feed speed, and the workpiece's
//! form along that path. Contract: `docs/wire-rsi.md`.
//!
//! The surface under the tool is the plant's surface (a function of time) plus [`SurfaceForm::height`]
//! at the path position, so at feed speed `v` a waviness of wavelength `λ` is a disturbance of `v/λ` Hz.

use core::f64::consts::TAU;

use hal::{ProcessCommand, ProcessMode, ProcessPhase, ProcessState};
use serde::{Deserialize, Serialize};

/// Where the surface is beyond the part's edge: far out of reach along the normal, m.
pub const NO_SURFACE: f64 = 1.0;

/// A direction on the part: base x (along a line program's path) or base y (across it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Along base x.
    #[default]
    X,
    /// Along base y.
    Y,
}

impl Axis {
    fn of(self, x: f64, y: f64) -> f64 {
        match self {
            Axis::X => x,
            Axis::Y => y,
        }
    }
}

/// One sinusoidal waviness of the surface along the path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wave {
    /// Amplitude along the normal, m.
    pub amplitude: f64,
    /// Wavelength along the path, m.
    pub wavelength: f64,
    /// The direction it varies in (default x, along a line program's path).
    #[serde(default)]
    pub along: Axis,
}

/// A step of the surface at a path position.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormStep {
    /// Path position, m.
    pub at: f64,
    /// Height along the normal (positive: the surface recedes from the tool), m.
    pub height: f64,
    /// The direction it is crossed in: a step at x = `at` (default), or at y = `at`.
    #[serde(default)]
    pub along: Axis,
}

/// The largest height a height map may give, m: a form, not a fixture (RSI corrects by millimetres).
pub const MAX_MAP_HEIGHT: f64 = 0.05;
/// The largest grid a height map may hold (points): 2000 × 2000.
pub const MAX_MAP_POINTS: usize = 4_000_000;

/// A height map of the part from a file: a CSV grid of heights, one line per y (from y = 0 up), one
/// value per x (from x = 0 on), `spacing` apart; each value times `scale` is metres along the normal
/// (positive: the surface recedes from the tool). Between points the height is interpolated
/// bilinearly; beyond the grid it is the nearest edge's.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeightMap {
    /// The CSV file, relative to the scenario file.
    pub file: String,
    /// Grid spacing in x and y, m.
    pub spacing: f64,
    /// Metres per unit of the file's values (1e-6: the file is in µm).
    pub scale: f64,
    /// The heights, m, row by row (filled when the scenario file is loaded).
    #[serde(skip)]
    pub grid: Vec<f64>,
    /// Points per row.
    #[serde(skip)]
    pub nx: usize,
}

impl HeightMap {
    /// Read the grid from the CSV `text` (commas or whitespace between values; `#` lines skipped).
    pub fn load(&mut self, text: &str) -> Result<(), String> {
        let (mut grid, mut nx) = (Vec::new(), 0);
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let before = grid.len();
            for v in line.split(|c: char| c == ',' || c.is_whitespace()) {
                if v.is_empty() {
                    continue;
                }
                let h: f64 = v.parse().map_err(|_| {
                    format!(
                        "height map {}: line {}: {v:?} is no number",
                        self.file,
                        i + 1
                    )
                })?;
                let m = h * self.scale;
                if !(m.is_finite() && m.abs() <= MAX_MAP_HEIGHT) {
                    return Err(format!(
                        "height map {}: line {}: {h} × scale {} is {m} m, beyond ±{MAX_MAP_HEIGHT} m",
                        self.file,
                        i + 1,
                        self.scale
                    ));
                }
                grid.push(m);
                if grid.len() > MAX_MAP_POINTS {
                    return Err(format!(
                        "height map {}: more than {MAX_MAP_POINTS} points",
                        self.file
                    ));
                }
            }
            let n = grid.len() - before;
            if nx == 0 {
                nx = n;
            } else if n != nx {
                return Err(format!(
                    "height map {}: line {} has {n} values, the first line {nx}",
                    self.file,
                    i + 1
                ));
            }
        }
        if nx < 2 || grid.len() / nx < 2 {
            return Err(format!(
                "height map {}: needs at least 2 × 2 values",
                self.file
            ));
        }
        self.grid = grid;
        self.nx = nx;
        Ok(())
    }

    /// The height at (x, y), m.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let ny = self.grid.len() / self.nx;
        let at = |v: f64, n: usize| {
            let u = (v / self.spacing).clamp(0.0, (n - 1) as f64);
            let i = (u.floor() as usize).min(n - 2);
            (i, u - i as f64)
        };
        let ((i, fx), (j, fy)) = (at(x, self.nx), at(y, ny));
        let g = |i: usize, j: usize| self.grid[j * self.nx + i];
        let lo = g(i, j) + fx * (g(i + 1, j) - g(i, j));
        let hi = g(i, j + 1) + fx * (g(i + 1, j + 1) - g(i, j + 1));
        lo + fy * (hi - lo)
    }

    fn validate(&self) -> Result<(), String> {
        if !(self.spacing.is_finite() && self.spacing > 0.0 && self.spacing <= 1.0) {
            return Err(format!(
                "form.height_map.spacing must be in (0, 1] m, got {}",
                self.spacing
            ));
        }
        if !(self.scale.is_finite() && self.scale > 0.0 && self.scale <= 1.0) {
            return Err(format!(
                "form.height_map.scale must be in (0, 1] m per unit, got {}",
                self.scale
            ));
        }
        if self.nx < 2 {
            return Err(format!(
                "form.height_map: {} was not read (a height map needs a scenario file beside it)",
                self.file
            ));
        }
        Ok(())
    }
}

/// The workpiece's form along the path: the surface's offset along the tool normal at path position
/// `s` (positive: farther from the programmed path).
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceForm {
    /// Slope along the path (base x), m per m of path.
    pub tilt: f64,
    /// Slope across the path (base y), m per m.
    pub tilt_y: f64,
    /// Waviness.
    pub waves: Vec<Wave>,
    /// Steps.
    pub steps: Vec<FormStep>,
    /// The part ends at this path position; beyond it there is no surface (`None`: it goes on).
    pub edge: Option<f64>,
    /// A height map from a file, added to the rest.
    pub height_map: Option<HeightMap>,
}

impl SurfaceForm {
    /// The surface's offset at path position `s` of a line program (x = s, y = 0), m.
    pub fn height(&self, s: f64) -> f64 {
        self.height_at(s, 0.0)
    }

    /// The surface's offset at (x, y) on the part (base frame from the path's start), m
    /// ([`NO_SURFACE`] beyond the edge, at x > edge).
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        if self.edge.is_some_and(|e| x > e) {
            return NO_SURFACE;
        }
        let waves: f64 = self
            .waves
            .iter()
            .map(|w| w.amplitude * (TAU * w.along.of(x, y) / w.wavelength).sin())
            .sum();
        let steps: f64 = self
            .steps
            .iter()
            .filter(|st| st.along.of(x, y) >= st.at)
            .map(|st| st.height)
            .sum();
        let map = self.height_map.as_ref().map_or(0.0, |m| m.height(x, y));
        self.tilt * x + self.tilt_y * y + waves + steps + map
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        let fin = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("form.{name} must be finite, got {v}"))
            }
        };
        fin("tilt", self.tilt)?;
        fin("tilt_y", self.tilt_y)?;
        for (name, t) in [("tilt", self.tilt), ("tilt_y", self.tilt_y)] {
            if t.abs() > 1.0 {
                return Err(format!("form.{name} is a slope of at most 1 m/m, got {t}"));
            }
        }
        for w in &self.waves {
            fin("waves.amplitude", w.amplitude)?;
            if !(w.wavelength.is_finite() && w.wavelength > 0.0) {
                return Err(format!(
                    "form.waves.wavelength must be > 0 m, got {}",
                    w.wavelength
                ));
            }
        }
        for st in &self.steps {
            fin("steps.at", st.at)?;
            fin("steps.height", st.height)?;
        }
        if let Some(e) = self.edge {
            fin("edge", e)?;
        }
        if let Some(m) = &self.height_map {
            m.validate()?;
        }
        Ok(())
    }
}

/// What a segment asks of the force process.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SegmentMode {
    /// No force control.
    Off,
    /// Press with the segment's force.
    Press,
    /// Release.
    Release,
}

/// One segment of the program.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// What the segment asks of the force process.
    pub mode: SegmentMode,
    /// Force set-point, N (PRESS; a RELEASE keeps the last PRESS's force on the wire).
    #[serde(default)]
    pub force: f64,
    /// Ramp time, s (0: the tuning's rate).
    #[serde(default)]
    pub ramp: f64,
    /// Segment number sent as `Seg`.
    #[serde(default)]
    pub segment: i64,
    /// Feed speed along the path, m/s.
    #[serde(default)]
    pub feed: f64,
    /// Path length of the segment, m (0: the segment only commands and waits).
    #[serde(default)]
    pub length: f64,
    /// Time to stay after the move, s.
    #[serde(default)]
    pub dwell: f64,
}

/// A robot program: segments run in order. A PRESS entered from OFF waits for `PRESSING` before it
/// moves (the KRL template's `WAIT FOR`), a RELEASE waits for OFF; either wait ends the program after
/// `wait_timeout`, as does a FAULT.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Program {
    /// The segments.
    pub segments: Vec<Segment>,
    /// Longest wait for a state, s.
    #[serde(default = "default_wait")]
    pub wait_timeout: f64,
    /// Parallel passes (a raster): the segments run once per pass, each pass `step_over` further
    /// along base y; between passes the robot moves in free air (process OFF) back to the start of the
    /// next pass at `transfer_feed`.
    #[serde(default = "default_passes")]
    pub passes: u32,
    /// Distance between passes, base y, m.
    #[serde(default)]
    pub step_over: f64,
    /// Speed of the free-air move between passes, m/s.
    #[serde(default = "default_transfer")]
    pub transfer_feed: f64,
}

fn default_wait() -> f64 {
    5.0
}

fn default_passes() -> u32 {
    1
}

fn default_transfer() -> f64 {
    0.1
}

/// The most passes of a raster.
pub const MAX_PASSES: u32 = 1000;
/// The widest raster, m (the farthest pass from the first).
pub const MAX_RASTER_WIDTH: f64 = 1.0;
/// The fastest free-air move between passes, m/s.
pub const MAX_TRANSFER_FEED: f64 = 2.0;

impl Program {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        if self.segments.is_empty() {
            return Err("program has no segments".into());
        }
        if !(self.wait_timeout.is_finite() && self.wait_timeout > 0.0) {
            return Err(format!(
                "program.wait_timeout must be > 0 s, got {}",
                self.wait_timeout
            ));
        }
        if !(1..=MAX_PASSES).contains(&self.passes) {
            return Err(format!(
                "program.passes must be 1 … {MAX_PASSES}, got {}",
                self.passes
            ));
        }
        if self.passes > 1
            && !(self.step_over.is_finite()
                && self.step_over > 0.0
                && self.step_over * f64::from(self.passes - 1) <= MAX_RASTER_WIDTH)
        {
            return Err(format!(
                "program.step_over must be > 0 m with {} passes, and the raster at most {MAX_RASTER_WIDTH} m wide, got {} m",
                self.passes, self.step_over
            ));
        }
        if !(self.step_over.is_finite() && self.step_over >= 0.0) {
            return Err(format!(
                "program.step_over must be ≥ 0 m, got {}",
                self.step_over
            ));
        }
        if !(self.transfer_feed.is_finite()
            && self.transfer_feed > 0.0
            && self.transfer_feed <= MAX_TRANSFER_FEED)
        {
            return Err(format!(
                "program.transfer_feed must be > 0 and ≤ {MAX_TRANSFER_FEED} m/s, got {}",
                self.transfer_feed
            ));
        }
        for (i, s) in self.segments.iter().enumerate() {
            let ok = |v: f64| v.is_finite() && v >= 0.0;
            if !(ok(s.force) && ok(s.ramp) && ok(s.feed) && ok(s.length) && ok(s.dwell)) {
                return Err(format!(
                    "program segment {i}: force, ramp, feed, length and dwell must be finite and ≥ 0"
                ));
            }
            if s.mode == SegmentMode::Press && s.force <= 0.0 {
                return Err(format!("program segment {i}: PRESS needs force > 0 N"));
            }
            if s.length > 0.0 && s.feed <= 0.0 {
                return Err(format!(
                    "program segment {i}: a move of {} m needs feed > 0",
                    s.length
                ));
            }
        }
        Ok(())
    }

    /// The longest the program can take, s: its moves, dwells and every wait at its timeout.
    pub fn max_duration(&self) -> f64 {
        let length: f64 = self.segments.iter().map(|s| s.length).sum();
        let transfer = (length + self.step_over) / self.transfer_feed;
        let pass: f64 = self
            .segments
            .iter()
            .map(|s| {
                let mv = if s.length > 0.0 {
                    s.length / s.feed
                } else {
                    0.0
                };
                mv + s.dwell + self.wait_timeout
            })
            .sum();
        f64::from(self.passes) * pass + f64::from(self.passes - 1) * transfer
    }
}

/// Where a running program is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    /// Waiting for the process state the segment needs, s waited.
    Wait(f64),
    /// Moving, m travelled.
    Move(f64),
    /// Dwelling, s.
    Dwell(f64),
    /// Moving in free air to the start of the next pass, m travelled.
    Transfer(f64),
}

/// A program running on the simulated controller, one cycle at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramRunner {
    program: Program,
    i: usize,
    stage: Stage,
    s: f64,
    pass: u32,
    transfer_from: (f64, f64),
    state: ProcessState,
    cmd: ProcessCommand,
    last_force: f64,
    done: bool,
    aborted: Option<String>,
}

impl ProgramRunner {
    /// At the start of `program`, at path position 0.
    pub fn new(program: Program) -> Self {
        let mut r = Self {
            program,
            i: 0,
            stage: Stage::Wait(0.0),
            s: 0.0,
            pass: 0,
            transfer_from: (0.0, 0.0),
            state: ProcessState::default(),
            cmd: ProcessCommand {
                mode: ProcessMode::Off,
                force: 0.0,
                ramp: 0.0,
                segment: 0,
            },
            last_force: 0.0,
            done: false,
            aborted: None,
        };
        r.enter(false);
        r
    }

    fn enter(&mut self, was_pressing: bool) {
        let Some(seg) = self.program.segments.get(self.i).copied() else {
            if self.pass + 1 < self.program.passes {
                // Free air to the start of the next pass, process OFF.
                self.transfer_from = self.path_xy();
                self.cmd = ProcessCommand {
                    mode: ProcessMode::Off,
                    force: 0.0,
                    ramp: 0.0,
                    segment: 0,
                };
                self.stage = Stage::Transfer(0.0);
            } else {
                self.done = true;
            }
            return;
        };
        if seg.mode == SegmentMode::Press {
            self.last_force = seg.force;
        }
        self.cmd = ProcessCommand {
            mode: match seg.mode {
                SegmentMode::Off => ProcessMode::Off,
                SegmentMode::Press => ProcessMode::Press,
                SegmentMode::Release => ProcessMode::Release,
            },
            force: if seg.mode == SegmentMode::Off {
                0.0
            } else {
                self.last_force
            },
            ramp: seg.ramp,
            segment: seg.segment,
        };
        let waits = match seg.mode {
            SegmentMode::Press => !was_pressing,
            SegmentMode::Release => true,
            SegmentMode::Off => false,
        };
        self.stage = if waits {
            Stage::Wait(0.0)
        } else {
            Stage::Move(0.0)
        };
    }

    /// The command for the next cycle.
    pub fn command(&self) -> ProcessCommand {
        self.cmd
    }

    /// The process state the PC replied.
    pub fn observe(&mut self, state: ProcessState) {
        self.state = state;
    }

    /// Path position along the current pass, m.
    pub fn path_position(&self) -> f64 {
        self.s
    }

    /// The pass under way (0 first).
    pub fn pass(&self) -> u32 {
        self.pass
    }

    /// Where the tool is on the part, base frame from the path's start, m: x along the pass (or on
    /// the free-air move between passes), y the pass's offset.
    pub fn path_xy(&self) -> (f64, f64) {
        if let Stage::Transfer(m) = self.stage {
            let (x0, y0) = self.transfer_from;
            let (x1, y1) = (0.0, f64::from(self.pass + 1) * self.program.step_over);
            let d = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
            let f = if d > 0.0 { (m / d).min(1.0) } else { 1.0 };
            return (x0 + (x1 - x0) * f, y0 + (y1 - y0) * f);
        }
        (self.s, f64::from(self.pass) * self.program.step_over)
    }

    /// True once the last segment ended (or the program was aborted).
    pub fn done(&self) -> bool {
        self.done
    }

    /// Why the program ended early, if it did.
    pub fn aborted(&self) -> Option<&str> {
        self.aborted.as_deref()
    }

    fn abort(&mut self, why: String) {
        self.aborted = Some(why);
        self.cmd.mode = ProcessMode::Off;
        self.done = true;
    }

    /// Advance one cycle of `dt` seconds.
    pub fn advance(&mut self, dt: f64) {
        if self.done {
            return;
        }
        if let Stage::Transfer(m) = self.stage {
            let (x0, y0) = self.transfer_from;
            let y1 = f64::from(self.pass + 1) * self.program.step_over;
            let d = (x0.powi(2) + (y1 - y0).powi(2)).sqrt();
            let m = m + self.program.transfer_feed * dt;
            if m >= d {
                self.pass += 1;
                self.s = 0.0;
                self.i = 0;
                self.enter(false);
            } else {
                self.stage = Stage::Transfer(m);
            }
            return;
        }
        let seg = self.program.segments[self.i];
        if self.state.phase == ProcessPhase::Fault && seg.mode != SegmentMode::Off {
            let why = format!(
                "the PC reported FAULT {} in segment {}",
                self.state.fault.code(),
                seg.segment
            );
            self.abort(why);
            return;
        }
        match self.stage {
            Stage::Wait(w) => {
                let want = match seg.mode {
                    SegmentMode::Press => ProcessPhase::Pressing,
                    _ => ProcessPhase::Off,
                };
                if self.state.phase == want {
                    self.stage = Stage::Move(0.0);
                } else if w + dt > self.program.wait_timeout {
                    let why = format!(
                        "segment {}: no {want:?} within {} s (state {:?})",
                        seg.segment, self.program.wait_timeout, self.state.phase
                    );
                    self.abort(why);
                } else {
                    self.stage = Stage::Wait(w + dt);
                }
            }
            Stage::Move(m) => {
                let step = (seg.feed * dt).min(seg.length - m).max(0.0);
                self.s += step;
                let m = m + step;
                self.stage = if m >= seg.length {
                    Stage::Dwell(0.0)
                } else {
                    Stage::Move(m)
                };
            }
            Stage::Dwell(d) => {
                if d >= seg.dwell {
                    let pressing = seg.mode == SegmentMode::Press;
                    self.i += 1;
                    self.enter(pressing);
                    // A segment that neither waits nor moves nor dwells takes no cycle of its own.
                } else {
                    self.stage = Stage::Dwell(d + dt);
                }
            }
            // Handled above.
            Stage::Transfer(_) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(mode: SegmentMode, force: f64, feed: f64, length: f64, n: i64) -> Segment {
        Segment {
            mode,
            force,
            ramp: 0.2,
            segment: n,
            feed,
            length,
            dwell: 0.0,
        }
    }

    #[test]
    fn form_sums_tilt_waves_steps_and_ends_at_the_edge() {
        let f = SurfaceForm {
            tilt: 0.01,
            tilt_y: 0.0,
            waves: vec![Wave {
                amplitude: 2e-4,
                wavelength: 0.025,
                along: Default::default(),
            }],
            steps: vec![FormStep {
                at: 0.05,
                height: -1e-3,
                along: Default::default(),
            }],
            edge: Some(0.1),
            height_map: None,
        };
        assert!((f.height(0.0)).abs() < 1e-15);
        assert!((f.height(0.025 / 4.0) - (0.01 * 0.025 / 4.0 + 2e-4)).abs() < 1e-12);
        assert!((f.height(0.05) - (0.0005 - 1e-3)).abs() < 1e-9);
        assert_eq!(f.height(0.1001), NO_SURFACE);
        assert!(f.validate().is_ok());
        let bad = SurfaceForm {
            waves: vec![Wave {
                amplitude: 1e-4,
                wavelength: 0.0,
                along: Default::default(),
            }],
            ..SurfaceForm::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn press_waits_for_pressing_moves_at_feed_then_release_waits_for_off() {
        let p = Program {
            segments: vec![
                seg(SegmentMode::Press, 20.0, 0.05, 0.01, 1),
                seg(SegmentMode::Press, 30.0, 0.05, 0.01, 2),
                seg(SegmentMode::Release, 0.0, 0.0, 0.0, 3),
            ],
            wait_timeout: 1.0,
            passes: 1,
            step_over: 0.0,
            transfer_feed: 0.1,
        };
        p.validate().unwrap();
        let mut r = ProgramRunner::new(p);
        let dt = 0.004;
        assert_eq!(r.command().mode, ProcessMode::Press);
        for _ in 0..10 {
            r.advance(dt);
        }
        assert_eq!(r.path_position(), 0.0, "waits for PRESSING before moving");
        r.observe(ProcessState {
            phase: ProcessPhase::Pressing,
            ..ProcessState::default()
        });
        let mut n = 0;
        while r.command().segment == 1 {
            r.advance(dt);
            n += 1;
        }
        assert!((r.path_position() - 0.01).abs() < 1e-12);
        assert!((50..=53).contains(&n), "10 mm at 50 mm/s: {n} cycles");
        assert_eq!(r.command().force, 30.0);
        // No wait on a change of force while pressing: it moves on at once.
        r.advance(dt);
        assert!(r.path_position() > 0.01);
        while r.command().mode != ProcessMode::Release {
            r.advance(dt);
        }
        assert_eq!(r.command().force, 30.0, "RELEASE carries the last force");
        r.advance(dt);
        assert!(!r.done(), "waits for OFF");
        r.observe(ProcessState::default());
        for _ in 0..3 {
            r.advance(dt);
        }
        assert!(r.done());
        assert_eq!(r.aborted(), None);
    }

    #[test]
    fn a_raster_runs_each_pass_a_step_over_further_with_free_air_between() {
        let p = Program {
            segments: vec![
                seg(SegmentMode::Press, 20.0, 0.05, 0.01, 1),
                seg(SegmentMode::Release, 0.0, 0.0, 0.0, 2),
            ],
            wait_timeout: 1.0,
            passes: 3,
            step_over: 0.01,
            transfer_feed: 0.1,
        };
        p.validate().unwrap();
        let mut r = ProgramRunner::new(p.clone());
        let dt = 0.004;
        let pressing = ProcessState {
            phase: ProcessPhase::Pressing,
            ..ProcessState::default()
        };
        let (mut ys, mut off_moves, mut n) = (vec![], 0, 0);
        while !r.done() && n < 10_000 {
            // The PC follows the command at once.
            r.observe(if r.command().mode == ProcessMode::Press {
                pressing
            } else {
                ProcessState::default()
            });
            let before = r.path_xy();
            r.advance(dt);
            let after = r.path_xy();
            if r.command().mode == ProcessMode::Off && before != after && r.command().segment == 0 {
                off_moves += 1;
            }
            if r.command().mode == ProcessMode::Press && !ys.contains(&after.1) {
                ys.push(after.1);
            }
            n += 1;
        }
        assert!(r.done() && r.aborted().is_none(), "{:?}", r.aborted());
        assert_eq!(ys, vec![0.0, 0.01, 0.02], "three passes 10 mm apart");
        // Two free-air moves of √(10² + 10²) mm at 100 mm/s: about 35 cycles each.
        assert!(
            (60..=80).contains(&off_moves),
            "{off_moves} cycles moving with the process OFF"
        );
        assert_eq!(r.pass(), 2);
        let bad = Program {
            step_over: 0.0,
            ..p.clone()
        };
        assert!(bad.validate().unwrap_err().contains("step_over"));
        let bad = Program {
            passes: 0,
            ..p.clone()
        };
        assert!(bad.validate().unwrap_err().contains("passes"));
        let bad = Program {
            transfer_feed: f64::NAN,
            ..p
        };
        assert!(bad.validate().unwrap_err().contains("transfer_feed"));
    }

    #[test]
    fn a_height_map_is_read_interpolated_and_bounded() {
        let mut m = HeightMap {
            file: "part.csv".into(),
            spacing: 0.01,
            scale: 1e-6,
            ..HeightMap::default()
        };
        // Three points in x, two rows in y, in µm; a comment and a blank line.
        m.load("# µm\n0, 10, 20\n\n30 40 50\n").unwrap();
        assert_eq!((m.nx, m.grid.len()), (3, 6));
        let close = |a: f64, b: f64| (a - b).abs() < 1e-15;
        assert!(close(m.height(0.0, 0.0), 0.0));
        assert!(close(m.height(0.005, 0.0), 5e-6), "halfway along x");
        assert!(close(m.height(0.01, 0.005), 25e-6), "halfway along y");
        assert!(
            close(m.height(0.5, 0.5), 50e-6),
            "beyond the grid: its edge"
        );
        assert!(close(m.height(-1.0, 0.0), 0.0));
        let f = SurfaceForm {
            tilt: 0.001,
            height_map: Some(m.clone()),
            ..SurfaceForm::default()
        };
        f.validate().unwrap();
        assert!(
            close(f.height_at(0.02, 0.0), 0.02 * 0.001 + 20e-6),
            "added to the rest"
        );
        // Every bad file is one clear error.
        for (text, why) in [
            ("0, 1\n2\n", "has 1 values"),
            ("0, x\n1, 2\n", "is no number"),
            ("0, 1\n", "2 × 2"),
            ("0, 1e9\n1, 2\n", "beyond"),
            ("0, NaN\n1, 2\n", "beyond"),
        ] {
            let e = m.clone().load(text).unwrap_err();
            assert!(e.contains(why) && e.contains("part.csv"), "{text:?}: {e}");
        }
        // Not read (a scenario given as text, not a file): refused, not a flat part.
        let unread = SurfaceForm {
            height_map: Some(HeightMap {
                grid: Vec::new(),
                nx: 0,
                ..m
            }),
            ..SurfaceForm::default()
        };
        assert!(unread.validate().unwrap_err().contains("was not read"));
    }

    #[test]
    fn a_two_d_form_varies_across_the_path_too() {
        let f = SurfaceForm {
            tilt_y: 0.01,
            waves: vec![Wave {
                amplitude: 1e-4,
                wavelength: 0.04,
                along: Axis::Y,
            }],
            steps: vec![FormStep {
                at: 0.05,
                height: 3e-4,
                along: Axis::X,
            }],
            ..SurfaceForm::default()
        };
        assert!(f.height_at(0.0, 0.0).abs() < 1e-15);
        assert!(
            (f.height_at(0.0, 0.01) - (1e-4 + 1e-4)).abs() < 1e-12,
            "tilt across plus a wave crest"
        );
        assert!(
            (f.height_at(0.06, 0.0) - 3e-4).abs() < 1e-12,
            "the step across the raster"
        );
        assert!(
            SurfaceForm {
                tilt_y: 2.0,
                ..SurfaceForm::default()
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn a_wait_that_times_out_or_a_fault_aborts_with_off() {
        let p = Program {
            segments: vec![seg(SegmentMode::Press, 20.0, 0.05, 0.01, 1)],
            wait_timeout: 0.1,
            passes: 1,
            step_over: 0.0,
            transfer_feed: 0.1,
        };
        let mut r = ProgramRunner::new(p.clone());
        for _ in 0..30 {
            r.advance(0.004);
        }
        assert!(r.done());
        assert!(r.aborted().unwrap().contains("Pressing"));
        assert_eq!(r.command().mode, ProcessMode::Off);

        let mut r = ProgramRunner::new(p);
        r.observe(ProcessState {
            phase: ProcessPhase::Fault,
            force: 0.0,
            fault: hal::ProcessFault::ForceLimit,
        });
        r.advance(0.004);
        assert!(r.aborted().unwrap().contains("FAULT 2"));
    }
}
