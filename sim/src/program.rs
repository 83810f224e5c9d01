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

/// One sinusoidal waviness of the surface along the path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wave {
    /// Amplitude along the normal, m.
    pub amplitude: f64,
    /// Wavelength along the path, m.
    pub wavelength: f64,
}

/// A step of the surface at a path position.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormStep {
    /// Path position, m.
    pub at: f64,
    /// Height along the normal (positive: the surface recedes from the tool), m.
    pub height: f64,
}

/// The workpiece's form along the path: the surface's offset along the tool normal at path position
/// `s` (positive: farther from the programmed path).
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceForm {
    /// Slope along the path, m per m of path.
    pub tilt: f64,
    /// Waviness.
    pub waves: Vec<Wave>,
    /// Steps.
    pub steps: Vec<FormStep>,
    /// The part ends at this path position; beyond it there is no surface (`None`: it goes on).
    pub edge: Option<f64>,
}

impl SurfaceForm {
    /// The surface's offset at path position `s`, m ([`NO_SURFACE`] beyond the edge).
    pub fn height(&self, s: f64) -> f64 {
        if self.edge.is_some_and(|e| s > e) {
            return NO_SURFACE;
        }
        let waves: f64 = self
            .waves
            .iter()
            .map(|w| w.amplitude * (TAU * s / w.wavelength).sin())
            .sum();
        let steps: f64 = self
            .steps
            .iter()
            .filter(|st| s >= st.at)
            .map(|st| st.height)
            .sum();
        self.tilt * s + waves + steps
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
        if self.tilt.abs() > 1.0 {
            return Err(format!(
                "form.tilt is a slope of at most 1 m/m, got {}",
                self.tilt
            ));
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
}

fn default_wait() -> f64 {
    5.0
}

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
        self.segments
            .iter()
            .map(|s| {
                let mv = if s.length > 0.0 {
                    s.length / s.feed
                } else {
                    0.0
                };
                mv + s.dwell + self.wait_timeout
            })
            .sum()
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
}

/// A program running on the simulated controller, one cycle at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramRunner {
    program: Program,
    i: usize,
    stage: Stage,
    s: f64,
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
            self.done = true;
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

    /// Path position, m.
    pub fn path_position(&self) -> f64 {
        self.s
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
            waves: vec![Wave {
                amplitude: 2e-4,
                wavelength: 0.025,
            }],
            steps: vec![FormStep {
                at: 0.05,
                height: -1e-3,
            }],
            edge: Some(0.1),
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
    fn a_wait_that_times_out_or_a_fault_aborts_with_off() {
        let p = Program {
            segments: vec![seg(SegmentMode::Press, 20.0, 0.05, 0.01, 1)],
            wait_timeout: 0.1,
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
