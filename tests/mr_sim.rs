//! forcecell's removal model against an independent implementation, `mr-sim` (PyPI): the same paths,
//! forces, speeds and Preston coefficient, a uniform round pad on a flat part and a belt, on the same
//! grid. Ignored by default: it needs Python with mr-sim. Run it with
//!
//! ```text
//! python3 -m venv target/mrsim/venv && target/mrsim/venv/bin/pip install mr-sim matplotlib
//! MR_SIM_PYTHON=target/mrsim/venv/bin/python cargo test --release --test mr_sim -- --ignored
//! ```
//!
//! (mr-sim imports matplotlib without declaring it.) Agreement asked: the mean depth over the path's
//! area within 0.5 %, and every grid point within 1 % of the deepest point.

use std::process::Command;

use scenario::removal::{PadModel, RemovalMap, RemovalModel, ToolMotion};

const SIZE: f64 = 0.06;
const DX: f64 = 0.0005;
const RADIUS: f64 = 0.008;
const KP: f64 = 1e-12;
const BELT: f64 = 5.0;

/// One straight leg: from (x, y) to (x, y), m, in so many seconds (the same point: a dwell).
type Leg = ((f64, f64), (f64, f64), f64);

/// Samples `(t, x, y, f)` every 4 ms along the legs at a constant force.
fn path(legs: &[Leg], force: f64) -> Vec<(f64, f64, f64, f64)> {
    let dt = 0.004;
    let mut v = vec![];
    let mut t = 0.0;
    for &((x0, y0), (x1, y1), dur) in legs {
        let n = (dur / dt).round() as usize;
        for k in 0..n {
            let f = k as f64 / n as f64;
            v.push((t, x0 + (x1 - x0) * f, y0 + (y1 - y0) * f, force));
            t += dt;
        }
    }
    let last = legs.last().unwrap().1;
    v.push((t, last.0, last.1, force));
    v
}

fn mr_sim(samples: &[(f64, f64, f64, f64)]) -> (Vec<f64>, Vec<f64>, Vec<Vec<f64>>) {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("samples.csv");
    let mut text = String::from("t,x,y,f\n");
    for (t, x, y, f) in samples {
        text += &format!("{t:e},{x:e},{y:e},{f:e}\n");
    }
    std::fs::write(&csv, text).unwrap();
    let python =
        std::env::var("MR_SIM_PYTHON").unwrap_or_else(|_| "target/mrsim/venv/bin/python".into());
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/mr-sim-check.py");
    let out = Command::new(&python)
        .arg(script)
        .arg(&csv)
        .args([SIZE, SIZE, DX, RADIUS, KP, BELT].map(|v| v.to_string()))
        .output()
        .unwrap_or_else(|e| panic!("cannot run {python}: {e} (set MR_SIM_PYTHON)"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let nums = |a: &serde_json::Value| {
        a.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect::<Vec<_>>()
    };
    let depth = v["depth"].as_array().unwrap().iter().map(nums).collect();
    (nums(&v["x"]), nums(&v["y"]), depth)
}

fn compare(name: &str, samples: &[(f64, f64, f64, f64)]) {
    let (xs, ys, theirs) = mr_sim(samples);
    let model = RemovalModel {
        pad: PadModel::Uniform { radius: RADIUS },
        tool: ToolMotion::Belt { speed: BELT },
        preston: KP,
    };
    // Our cells centred on mr-sim's grid points.
    let mut map = RemovalMap::new(
        xs[0] - DX / 2.0,
        xs[xs.len() - 1] + DX / 2.0 - 1e-12,
        ys[0] - DX / 2.0,
        ys[ys.len() - 1] + DX / 2.0 - 1e-12,
        DX,
    );
    assert_eq!(
        (map.nx, map.ny),
        (xs.len(), ys.len()),
        "{name}: the grids match"
    );
    map.add_path(&model, samples);
    let deepest = theirs.iter().flatten().cloned().fold(0.0, f64::max);
    assert!(deepest > 0.0, "{name}: mr-sim removed nothing");
    let (mut ours_sum, mut theirs_sum, mut worst) = (0.0, 0.0, 0.0_f64);
    for (j, row) in theirs.iter().enumerate() {
        for (i, d) in row.iter().enumerate() {
            let o = map.depth_at(i, j);
            ours_sum += o;
            theirs_sum += d;
            worst = worst.max((o - d).abs());
        }
    }
    let rel_mean = (ours_sum - theirs_sum).abs() / theirs_sum;
    eprintln!(
        "{name}: mean differs by {:.4} %, worst point by {:.4} % of the deepest ({:.4} µm)",
        rel_mean * 100.0,
        worst / deepest * 100.0,
        deepest * 1e6
    );
    assert!(
        rel_mean < 0.005,
        "{name}: total removal differs by {:.3} %",
        rel_mean * 100.0
    );
    assert!(
        worst < 0.01 * deepest,
        "{name}: a point differs by {:.3} % of the deepest",
        worst / deepest * 100.0
    );
}

#[test]
#[ignore = "needs Python with mr-sim (PyPI): see this file's header"]
fn a_straight_pass_a_dwell_and_a_raster_agree_with_mr_sim() {
    compare(
        "straight pass",
        &path(&[((-0.02, 0.0), (0.02, 0.0), 4.0)], 15.0),
    );
    // A quarter cell off the grid: a grid point exactly on the patch's rim is in or out by rounding
    // (x² + y² ≤ R² there, √(x² + y²) ≤ R here), and a dwell would weigh that one point fully.
    compare(
        "dwell",
        &path(&[((1.25e-4, 1.25e-4), (1.25e-4, 1.25e-4), 2.0)], 10.0),
    );
    let raster: Vec<_> = (0..3)
        .flat_map(|k| {
            let y = -0.008 + 0.008 * k as f64;
            [
                ((-0.02, y), (0.02, y), 2.0),
                ((0.02, y), (-0.02, y + 0.008), 0.5),
            ]
        })
        .collect();
    compare("raster", &path(&raster, 20.0));
}
