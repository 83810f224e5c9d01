//! The trace of a run — one row per control step — and its CSV form (header row, SI units).

use std::io::{self, BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};

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
    /// Fault code of the step (0: none; see [`fault_code`]).
    pub fault: u8,
    /// The force process's phase as reported to the robot program (`FcState.State`: 0 OFF,
    /// 1 APPROACH, 2 RAMP, 3 PRESSING, 4 RELEASE, 9 FAULT), or [`NO_PROCESS`] on a link without
    /// process channels.
    pub phase: u8,
    /// The robot program's segment number (`FcCmd.Seg`; 0 without process channels).
    pub segment: i64,
    /// The robot program's commanded force (`FcCmd.F`), N; NaN without process channels.
    pub f_cmd: f64,
    /// Path position along the workpiece, m (NaN on a real cell).
    pub s: f64,
}

/// [`Row::phase`] of a cycle that carried no process command.
pub const NO_PROCESS: u8 = 255;

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
            fault: fault_code(r.fault),
            phase: r
                .cycle
                .process
                .map_or(NO_PROCESS, |_| r.command.process.phase.code() as u8),
            segment: r.cycle.process.map_or(0, |p| p.segment),
            f_cmd: r.cycle.process.map_or(f64::NAN, |p| p.force),
            s: f64::NAN,
        }
    }
}

/// The CSV header, in column order.
pub const HEADER: &str = "t,f,f_true,f_r,x,x_cmd,x_r,kc_hat,xc_hat,k_c,x_c,fault";

/// A compact code for a cycle's fault, as written in the CSV `fault` column:
/// 0 none, 1 sensor error, 2 non-finite sample, 3 non-finite pose, 4 non-finite command,
/// 5 step limited, 6 envelope limited, 7 backing off after a fault that ends the run.
pub fn fault_code(f: Option<controller::Fault>) -> u8 {
    use controller::Fault::*;
    match f {
        None => 0,
        Some(Sensor(_)) => 1,
        Some(NonFiniteSample) => 2,
        Some(NonFinitePose) => 3,
        Some(NonFiniteCommand) => 4,
        Some(StepLimited) => 5,
        Some(EnvelopeLimited) => 6,
        Some(Retracting) => 7,
    }
}

fn field(w: &mut impl Write, v: f64) -> io::Result<()> {
    if v.is_finite() {
        write!(w, "{v}")
    } else {
        Ok(())
    }
}

/// Write rows as CSV. Non-finite values are written as empty fields.
pub fn write_csv(w: impl Write, rows: &[Row]) -> io::Result<()> {
    let mut w = BufWriter::new(w);
    writeln!(w, "{HEADER}")?;
    for r in rows {
        for (i, v) in [
            r.t, r.f, r.f_true, r.f_r, r.x, r.x_cmd, r.x_r, r.kc_hat, r.xc_hat, r.k_c, r.x_c,
        ]
        .into_iter()
        .enumerate()
        {
            if i > 0 {
                w.write_all(b",")?;
            }
            field(&mut w, v)?;
        }
        writeln!(w, ",{}", r.fault)?;
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
    if head != HEADER {
        anyhow::bail!("not a forcecell trace: the header must be {HEADER:?}");
    }
    let mut rows = Vec::new();
    for (n, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let cols: Vec<&str> = line.split(',').collect();
        if cols.len() != 12 {
            anyhow::bail!("line {}: expected 12 columns, got {}", n + 2, cols.len());
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
        let fault = cols[11]
            .parse()
            .with_context(|| format!("line {}: bad fault code", n + 2))?;
        rows.push(Row {
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
            fault,
            phase: NO_PROCESS,
            segment: 0,
            f_cmd: f64::NAN,
            s: f64::NAN,
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
                fault: 1,
                phase: NO_PROCESS,
                segment: 0,
                f_cmd: f64::NAN,
                s: f64::NAN,
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
        assert_eq!(back[1].fault, 1);
        assert!(read_csv("a,b\n").is_err());
        let broken = text.replace("0.0102", "zz");
        assert!(
            read_csv(&broken)
                .unwrap_err()
                .to_string()
                .contains("line 2")
        );
    }
}
