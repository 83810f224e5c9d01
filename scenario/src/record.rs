//! The trace of a run — one row per control step — and its CSV form (header row, SI units).

use std::io::{self, BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};

use crate::telemetry::{self, Coded, Condition, Value};

/// One control step. SI units: s, N, m, N/m.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Row {
    /// Time, s.
    pub t: f64,
    /// Measured normal force, N (NaN when the sensor gave no usable sample).
    pub f: f64,
    /// True contact force from the plant, N (NaN on a real cell).
    pub f_true: f64,
    /// Set-point, N.
    pub f_r: f64,
    /// Measured position along the normal, m.
    pub x: f64,
    /// Commanded position, m.
    pub x_cmd: f64,
    /// Impedance reference, m.
    pub x_r: f64,
    /// Stiffness estimate, N/m.
    pub kc_hat: f64,
    /// Surface estimate, m.
    pub xc_hat: f64,
    /// True stiffness, N/m (NaN on a real cell).
    pub k_c: f64,
    /// True surface position, m (NaN on a real cell).
    pub x_c: f64,
    /// The step's condition code ([`Condition`]: 0 none, a sensor error, a non-finite input, a
    /// limited command).
    pub condition: u8,
    /// The robot program's path segment (RSI `FcCmd`), `None` when the link carries no process
    /// command (or the trace predates process columns).
    pub segment: Option<i64>,
    /// The commanded process mode (`hal::ProcessMode::code`: 0 off, 1 press, 2 release, other
    /// numbers as sent), `None` without a process command.
    pub mode: Option<i64>,
    /// The commanded process force, N (NaN without a process command).
    pub f_cmd: f64,
    /// The force process's phase as reported to the robot (`hal::ProcessPhase::code`), `None` in a
    /// trace that predates process columns.
    pub phase: Option<u8>,
    /// The force process's latched fault (`hal::ProcessFault::code`), `None` in a trace that
    /// predates process columns.
    pub fault: Option<u8>,
    /// Path position along the workpiece, m (simulation only: NaN on a real cell and in files).
    pub s: f64,
    /// On a simulated curved part: the true angle between the tool axis and the surface normal less
    /// the program's tilt, rad (NaN elsewhere and in files; `docs/curved-parts.md`).
    pub tilt_error: f64,
    /// The magnitude of the correction's rotation sent, rad (NaN in files).
    pub rotation: f64,
    /// The torque about the sensor's x and y in the wrench the loop used (after compensation), N·m
    /// (NaN without a usable wrench; in a CSV file NaN, in a recording the `wrench` message's).
    pub moment: [f64; 2],
}

impl Row {
    /// The row of an answered cycle with set-point `f_r`; the truth columns (`f_true`, `k_c`, `x_c`) are
    /// NaN until a simulation fills them in.
    pub fn from_report(r: &controller::CycleReport, f_r: f64) -> Self {
        Self {
            t: r.cycle.t,
            f: r.f.unwrap_or(f64::NAN),
            f_true: f64::NAN,
            f_r,
            x: r.x,
            x_cmd: r.command.translation.z,
            x_r: r.out.x_r,
            kc_hat: r.out.kc_hat,
            xc_hat: r.out.xc_hat,
            k_c: f64::NAN,
            x_c: f64::NAN,
            condition: Condition::of(r.fault).code() as u8,
            segment: r.cycle.process.map(|p| p.segment),
            mode: r.cycle.process.map(|p| p.mode.code()),
            f_cmd: r.cycle.process.map_or(f64::NAN, |p| p.force),
            // Empty where the link carries no process command (docs/recordings.md): a phase "off"
            // and a fault "none" would read as a process that is there.
            phase: r
                .cycle
                .process
                .map(|_| r.command.process.phase.code() as u8),
            fault: r
                .cycle
                .process
                .map(|_| r.command.process.fault.code() as u8),
            s: f64::NAN,
            tilt_error: f64::NAN,
            rotation: r.command.rotation.norm(),
            moment: r.wrench.map_or([f64::NAN; 2], |w| [w.torque.x, w.torque.y]),
        }
    }

    /// The process columns of a row without a process command (phase off, no fault): what a loop
    /// that does not run the process (a calibration, a trace from before process columns) records.
    pub fn no_process(self) -> Self {
        Self {
            segment: None,
            mode: None,
            f_cmd: f64::NAN,
            phase: None,
            fault: None,
            ..self
        }
    }

    /// A row with every value unknown (NaN, `None`; condition 0).
    pub fn unknown() -> Self {
        Self {
            t: f64::NAN,
            f: f64::NAN,
            f_true: f64::NAN,
            f_r: f64::NAN,
            x: f64::NAN,
            x_cmd: f64::NAN,
            x_r: f64::NAN,
            kc_hat: f64::NAN,
            xc_hat: f64::NAN,
            k_c: f64::NAN,
            x_c: f64::NAN,
            condition: 0,
            segment: None,
            mode: None,
            f_cmd: f64::NAN,
            phase: None,
            fault: None,
            s: f64::NAN,
            tilt_error: f64::NAN,
            rotation: f64::NAN,
            moment: [f64::NAN; 2],
        }
    }
}

/// The CSV header, in column order: the names of the schema's trace fields
/// ([`telemetry::CSV_COLUMNS`]). The last five columns are the process command and state (`segment`,
/// commanded `mode` and force `f_cmd`, reported `phase` and `fault`, as their wire numbers; empty where
/// unknown).
pub const HEADER: &str = telemetry::CSV_HEADER;

/// The header of traces written before `fault` was renamed `condition` and `process_fault` `fault`
/// (still read: the same columns in the same order).
pub const HEADER_V2: &str =
    "t,f,f_true,f_r,x,x_cmd,x_r,kc_hat,xc_hat,k_c,x_c,fault,segment,mode,f_cmd,phase,process_fault";

/// The header of traces written before the process columns (still read).
pub const HEADER_V1: &str = "t,f,f_true,f_r,x,x_cmd,x_r,kc_hat,xc_hat,k_c,x_c,fault";

/// Write rows as CSV, one column per field of [`telemetry::CSV_COLUMNS`]. Non-finite values and
/// absent ones are written as empty fields.
pub fn write_csv(w: impl Write, rows: &[Row]) -> io::Result<()> {
    let mut w = BufWriter::new(w);
    writeln!(w, "{HEADER}")?;
    for r in rows {
        let rec = telemetry::Record::from_row(*r);
        for (i, col) in telemetry::CSV_COLUMNS.iter().enumerate() {
            if i > 0 {
                w.write_all(b",")?;
            }
            match (col.get)(&rec) {
                Value::F64(v) if v.is_finite() => write!(w, "{v}")?,
                Value::I64(v) => write!(w, "{v}")?,
                Value::U64(v) => write!(w, "{v}")?,
                Value::Bool(b) => write!(w, "{}", u8::from(b))?,
                Value::F64(_) | Value::Absent => {}
            }
        }
        writeln!(w)?;
    }
    w.flush()
}

/// Write rows to a CSV file.
pub fn write_csv_file(path: &Path, rows: &[Row]) -> Result<()> {
    let f =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    write_csv(f, rows).with_context(|| format!("cannot write {}", path.display()))
}

/// The largest magnitude a trace value may have (stiffness in N/m is the largest column).
pub const MAX_VALUE: f64 = 1e12;
/// The latest time a trace row may have, s (about four months).
pub const MAX_TIME: f64 = 1e7;

/// Read a CSV written by [`write_csv`] (for `replay` and tests). Errors name the line.
pub fn read_csv(text: &str) -> Result<Vec<Row>> {
    let mut lines = text.lines();
    let head = lines.next().unwrap_or_default().trim();
    let ncols = if head == HEADER || head == HEADER_V2 {
        17
    } else if head == HEADER_V1 {
        12
    } else {
        anyhow::bail!(
            "not a forcecell trace: the header must be {HEADER:?} (or, as written before, {HEADER_V2:?} or {HEADER_V1:?})"
        );
    };
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let cols: Vec<&str> = line.split(',').collect();
        if cols.len() != ncols {
            anyhow::bail!(
                "line {}: expected {ncols} columns, got {}",
                n + 2,
                cols.len()
            );
        }
        let mut v = [f64::NAN; 11];
        for (i, c) in cols[..11].iter().enumerate() {
            if !c.is_empty() {
                v[i] = c
                    .parse()
                    .with_context(|| format!("line {}: column {} is not a number", n + 2, i + 1))?;
                if !(v[i].is_finite() && v[i].abs() <= MAX_VALUE) {
                    anyhow::bail!(
                        "line {}: column {} is {c}: every value must be finite and within ±{MAX_VALUE:e} (s, N, m, N/m; an empty field is a missing value)",
                        n + 2,
                        i + 1,
                    );
                }
            }
        }
        if !(0.0..=MAX_TIME).contains(&v[0]) {
            anyhow::bail!(
                "line {}: t must be a time in [0, {MAX_TIME:e}] s, got {}",
                n + 2,
                v[0]
            );
        }
        let condition = cols[11]
            .parse()
            .with_context(|| format!("line {}: bad condition code", n + 2))?;
        let int = |i: usize, what: &str| -> Result<Option<i64>> {
            match cols.get(i) {
                None | Some(&"") => Ok(None),
                Some(c) => c
                    .parse()
                    .map(Some)
                    .with_context(|| format!("line {}: bad {what}", n + 2)),
            }
        };
        let code = |i: usize, what: &str| -> Result<Option<u8>> {
            int(i, what)?
                .map(|c| u8::try_from(c).with_context(|| format!("line {}: bad {what} {c}", n + 2)))
                .transpose()
        };
        let f_cmd = match cols.get(14) {
            None | Some(&"") => f64::NAN,
            Some(c) => {
                let v: f64 = c
                    .parse()
                    .with_context(|| format!("line {}: f_cmd is not a number", n + 2))?;
                if !(v.is_finite() && v.abs() <= MAX_VALUE) {
                    anyhow::bail!(
                        "line {}: f_cmd is {c}: it must be finite and within ±{MAX_VALUE:e} N",
                        n + 2
                    );
                }
                v
            }
        };
        rows.push(Row {
            segment: int(12, "segment")?,
            mode: int(13, "process mode")?,
            f_cmd,
            phase: code(15, "process phase")?,
            fault: code(16, "process fault")?,
            t: v[0],
            f: v[1],
            f_true: v[2],
            f_r: v[3],
            x: v[4],
            x_cmd: v[5],
            x_r: v[6],
            kc_hat: v[7],
            xc_hat: v[8],
            k_c: v[9],
            x_c: v[10],
            condition,
            s: f64::NAN,
            tilt_error: f64::NAN,
            rotation: f64::NAN,
            moment: [f64::NAN; 2],
        });
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trip_keeps_values_and_missing_fields() {
        let rows = vec![
            Row {
                t: 0.001,
                f: f64::NAN,
                f_true: 5.25,
                f_r: 5.0,
                x: 0.0101,
                x_cmd: 0.0102,
                x_r: 0.0103,
                kc_hat: 50_000.0,
                xc_hat: 0.009,
                k_c: 70_000.0,
                x_c: 0.01,
                condition: 1,
                segment: Some(4),
                mode: Some(1),
                f_cmd: 12.5,
                phase: Some(3),
                fault: Some(0),
                s: f64::NAN,
                tilt_error: f64::NAN,
                rotation: f64::NAN,
                moment: [f64::NAN; 2],
            };
            2
        ];
        let mut buf = Vec::new();
        write_csv(&mut buf, &rows).unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert!(text.starts_with("t,f,f_true,f_r,x,x_cmd,x_r,kc_hat,xc_hat"));
        let back = read_csv(&text).unwrap();
        assert_eq!(back.len(), 2);
        assert!(back[0].f.is_nan());
        assert_eq!(back[0].x_cmd, 0.0102);
        assert_eq!(back[1].condition, 1);
        // NaN is not equal to itself: the missing `f` and the simulation-only `s`, `tilt_error` and
        // `rotation` compared as 0.
        let without_f = |r: &Row| Row {
            f: 0.0,
            s: 0.0,
            tilt_error: 0.0,
            rotation: 0.0,
            moment: [0.0; 2],
            ..*r
        };
        assert_eq!(
            back.iter().map(without_f).collect::<Vec<_>>(),
            rows.iter().map(without_f).collect::<Vec<_>>()
        );
        assert_eq!(
            (back[0].segment, back[0].mode, back[0].f_cmd),
            (Some(4), Some(1), 12.5)
        );
        assert_eq!((back[0].phase, back[0].fault), (Some(3), Some(0)));
        assert!(read_csv("a,b\n").is_err());
        let broken = text.replace("0.0102", "zz");
        assert!(
            read_csv(&broken)
                .unwrap_err()
                .to_string()
                .contains("line 2")
        );
    }

    #[test]
    fn rows_without_a_process_command_leave_its_columns_empty_and_old_traces_still_read() {
        let row = Row {
            t: 0.004,
            f: 1.0,
            f_r: 5.0,
            phase: Some(0),
            fault: Some(0),
            ..Row::default()
        }
        .no_process();
        let mut buf = Vec::new();
        write_csv(&mut buf, &[row]).unwrap();
        let text = String::from_utf8(buf).unwrap();
        assert!(text.lines().nth(1).unwrap().ends_with(",0,,,,,"), "{text}");
        let back = read_csv(&text).unwrap();
        assert_eq!(
            (back[0].segment, back[0].mode, back[0].phase, back[0].fault),
            (None, None, None, None)
        );
        assert!(back[0].f_cmd.is_nan());

        // A trace written before the process columns: read, with those columns unknown.
        let old = format!("{HEADER_V1}\n0.004,1,,5,0,0,0,0,0,,,0\n");
        let back = read_csv(&old).unwrap();
        assert_eq!(back.len(), 1);
        assert_eq!(
            (back[0].f, back[0].f_r, back[0].segment, back[0].phase),
            (1.0, 5.0, None, None)
        );
        // A trace written before the renames (`fault` → `condition`, `process_fault` → `fault`): the
        // same columns.
        let v2 = format!("{HEADER_V2}\n0.004,1,,5,0,0,0,0,0,,,2,3,1,5,3,4\n");
        let back = read_csv(&v2).unwrap();
        assert_eq!(
            (
                back[0].condition,
                back[0].segment,
                back[0].phase,
                back[0].fault
            ),
            (2, Some(3), Some(3), Some(4))
        );
        // …but a row must have its header's column count.
        assert!(read_csv(&format!("{HEADER}\n0.004,1,,5,0,0,0,0,0,,,0\n")).is_err());
        assert!(
            read_csv(&format!("{HEADER}\n0.004,1,,5,0,0,0,0,0,,,0,1,1,5,300,0\n"))
                .unwrap_err()
                .to_string()
                .contains("phase")
        );
    }
}
