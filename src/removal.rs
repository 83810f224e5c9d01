//! `forcecell removal REC.mcap`: what a recorded pass did to the part. The computation is
//! [`scenario::removal::analyse`] (shared with the tests and `sim`); this module reads the recording,
//! finds the `[removal]` table, writes `NAME-removal.mcap` (the `/removal` channels) and
//! `NAME-removal.png` beside the input (or in `--out`), and prints the figures. The input is only read.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use scenario::removal::{PathSample, Removal, RemovalConfig, analyse};

/// The removal of one recording and where it was written.
#[derive(Debug)]
pub struct RemovalOutput {
    /// The figures and the maps.
    pub removal: Removal,
    /// Which force made the pressure.
    pub force_source: &'static str,
    /// The MCAP with the `/removal` channels.
    pub mcap: PathBuf,
    /// The heat map.
    pub png: PathBuf,
}

/// The `[removal]` table of `spec`: a built-in scenario's name, or a scenario or cell TOML file.
pub fn load_config(spec: &str) -> Result<RemovalConfig> {
    let path = Path::new(spec);
    let is_file = spec.ends_with(".toml") || spec.contains('/');
    let cfg = if is_file {
        let text = crate::input::read_text(path, "removal config", crate::input::MAX_CONFIG)?;
        let v: toml::Table = toml::from_str(&text)
            .map_err(|e| anyhow!("{spec}: {}", crate::scenario::one_line(&e.to_string())))?;
        let Some(t) = v.get("removal") else {
            bail!(
                "{spec} has no [removal] table (pad, tool speed, Preston's coefficient: docs/removal.md)"
            );
        };
        t.clone().try_into::<RemovalConfig>().map_err(|e| {
            anyhow!(
                "{spec}: [removal]: {}",
                crate::scenario::one_line(&e.to_string())
            )
        })?
    } else {
        crate::scenario::Scenario::load(spec)?
            .removal
            .ok_or_else(|| anyhow!("scenario {spec} has no [removal] table (docs/removal.md)"))?
    };
    cfg.validate().map_err(|e| anyhow!("{spec}: {e}"))?;
    Ok(cfg)
}

/// The samples of a recording: the measured pose's x and y, the true contact force where the file
/// has it (a simulation), else the measured force; the set-point in effect.
pub fn samples(path: &Path) -> Result<(Vec<PathSample>, &'static str)> {
    let bytes = crate::input::read(path, "recording", crate::input::MAX_TRACE)?;
    if !bytes.starts_with(mcap::MAGIC) {
        bail!(
            "{}: not an MCAP recording (a CSV trace carries no robot poses)",
            path.display()
        );
    }
    let back = crate::recorder::read_mcap(&bytes).with_context(|| format!("{}", path.display()))?;
    if let Some(why) = &back.truncated {
        eprintln!(
            "note: {} ends early ({why}): mapped up to its last complete record",
            path.display()
        );
    }
    let truth = back.rows.iter().any(|r| r.f_true.is_finite());
    let v = back
        .rows
        .iter()
        .zip(&back.poses)
        .map(|(r, p)| PathSample {
            t: r.t,
            x: p[0],
            y: p[1],
            force: if truth { r.f_true } else { r.f },
            setpoint: r.f_r,
        })
        .collect();
    Ok((
        v,
        if truth {
            "true contact force (simulation)"
        } else {
            "measured force (sensor)"
        },
    ))
}

/// The output paths for `input` in `out` (default: beside the input).
pub fn output_paths(input: &Path, out: Option<&Path>) -> (PathBuf, PathBuf) {
    let stem = input
        .file_stem()
        .map_or("recording".into(), |s| s.to_string_lossy().into_owned());
    let dir = out.map(Path::to_path_buf).unwrap_or_else(|| {
        input
            .parent()
            .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
    });
    (
        dir.join(format!("{stem}-removal.mcap")),
        dir.join(format!("{stem}-removal.png")),
    )
}

/// Compute and write the removal of `input` with `cfg`.
pub fn run(input: &Path, cfg: &RemovalConfig, out: Option<&Path>) -> Result<RemovalOutput> {
    let (mcap_path, png) = output_paths(input, out);
    crate::output::require_extension(&mcap_path, &["mcap"], "a removal recording")?;
    crate::output::refuse_input(&mcap_path, input)?;
    crate::output::refuse_input(&png, input)?;
    let (samples, force_source) = samples(input)?;
    let removal = analyse(cfg, &samples).map_err(|e| anyhow!("{}: {e}", input.display()))?;
    let title = format!(
        "{} — removal",
        input
            .file_stem()
            .map_or("recording".into(), |s| s.to_string_lossy().into_owned())
    );
    if let Some(dir) = mcap_path.parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    crate::output::replace(&mcap_path, |tmp| write_mcap(tmp, &removal))?;
    crate::plot::write_removal_png(&png, &[(title.as_str(), &removal)])?;
    Ok(RemovalOutput {
        removal,
        force_source,
        mcap: mcap_path,
        png,
    })
}

/// The report's lines.
pub fn report(o: &RemovalOutput) -> String {
    let r = &o.removal;
    let s = &r.stats;
    let t = r.target;
    let um = |m: f64| m * 1e6;
    let mut text = format!(
        "removal from the {}; part frame from the first pose at ({:.4}, {:.4}) m base\n",
        o.force_source, r.origin.0, r.origin.1
    );
    text += &format!(
        "  target area        x {:.1}…{:.1} mm, y {:.1}…{:.1} mm\n",
        t[0] * 1e3,
        t[1] * 1e3,
        t[2] * 1e3,
        t[3] * 1e3
    );
    text += &format!("  mean removal       {:.4} µm\n", um(s.mean));
    text += &format!("  coverage           {:.1} %\n", s.coverage * 100.0);
    text += &format!(
        "  uniformity         {:.4} (σ/mean), min/max {:.4}/{:.4} µm\n",
        s.uniformity(),
        um(s.min),
        um(s.max)
    );
    text += &format!(
        "  under/over-polished {:.1} % / {:.1} % of the target (±{:.0} % of the set-point's removal)\n",
        r.under * 100.0,
        r.over * 100.0,
        r.band * 100.0
    );
    let path_len = r.along.len() as f64 * r.map.cell;
    let mut contact: Vec<f64> = r
        .along
        .iter()
        .map(|a| a.dwell)
        .filter(|d| *d > 0.0)
        .collect();
    contact.sort_by(f64::total_cmp);
    if let Some(median) = contact.get(contact.len() / 2) {
        let max = contact.last().copied().unwrap_or(0.0);
        text += &format!(
            "  dwell              {:.2} s/m median in contact (max {:.1} s/m) over {:.1} mm of path\n",
            median,
            max,
            path_len * 1e3
        );
    }
    if r.skipped > 0 {
        text += &format!("  skipped            {} cycles without a pose\n", r.skipped);
    }
    text += &format!(
        "wrote {} (/removal, /removal/map, /removal/stats) and {}",
        o.mcap.display(),
        o.png.display()
    );
    text
}

const SAMPLE_SCHEMA: &str = r#"{"title":"forcecell.RemovalAlongPath","description":"removal along the path, one bin per map cell of travel","type":"object","properties":{"s":{"type":"number","description":"distance along the path to the bin, m"},"x":{"type":"number","description":"part-frame x, m"},"y":{"type":"number","description":"part-frame y, m"},"depth":{"type":"number","description":"removal depth under the path, m"},"dwell":{"type":"number","description":"contact time per unit path length, s/m"}}}"#;
const MAP_SCHEMA: &str = r#"{"title":"forcecell.RemovalMap","description":"removal depth and dwell over the part, row-major (y outer)","type":"object","properties":{"x0":{"type":"number","description":"first cell centre x, m"},"y0":{"type":"number","description":"first cell centre y, m"},"cell":{"type":"number","description":"cell size, m"},"nx":{"type":"integer"},"ny":{"type":"integer"},"depth":{"type":"array","items":{"type":"number"},"description":"m"},"dwell":{"type":"array","items":{"type":"number"},"description":"contact time, s"}}}"#;
const STATS_SCHEMA: &str = r#"{"title":"forcecell.RemovalStats","description":"figures over the target area","type":"object","properties":{"target":{"type":"array","items":{"type":"number"},"description":"x_min, x_max, y_min, y_max, m"},"mean":{"type":"number","description":"m"},"std":{"type":"number","description":"m"},"min":{"type":"number","description":"m"},"max":{"type":"number","description":"m"},"coverage":{"type":"number","description":"share of cells with removal"},"uniformity":{"type":"number","description":"std/mean"},"under":{"type":"number","description":"share under-polished"},"over":{"type":"number","description":"share over-polished"}}}"#;

fn write_mcap(path: &Path, r: &Removal) -> Result<()> {
    let file = File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .profile("")
        .library(concat!("forcecell ", env!("CARGO_PKG_VERSION")))
        .create(BufWriter::new(file))?;
    let mut channel = |name: &str, topic: &str, schema: &str| -> Result<u16> {
        let s = w.add_schema(name, "jsonschema", schema.as_bytes())?;
        Ok(w.add_channel(s, topic, "json", &BTreeMap::new())?)
    };
    let along = channel("forcecell.RemovalAlongPath", "/removal", SAMPLE_SCHEMA)?;
    let map = channel("forcecell.RemovalMap", "/removal/map", MAP_SCHEMA)?;
    let stats = channel("forcecell.RemovalStats", "/removal/stats", STATS_SCHEMA)?;
    let ns = |t: f64| crate::recorder::nanos(t);
    for a in &r.along {
        let v =
            serde_json::json!({"s": a.s, "x": a.x, "y": a.y, "depth": a.depth, "dwell": a.dwell});
        let header = mcap::records::MessageHeader {
            channel_id: along,
            sequence: 0,
            log_time: ns(a.t),
            publish_time: ns(a.t),
        };
        w.write_to_known_channel(&header, &serde_json::to_vec(&v)?)?;
    }
    let end = r.along.last().map_or(0, |a| ns(a.t));
    let m = &r.map;
    let v = serde_json::json!({"x0": m.x0, "y0": m.y0, "cell": m.cell, "nx": m.nx, "ny": m.ny,
        "depth": m.depth, "dwell": m.dwell});
    let header = |channel_id| mcap::records::MessageHeader {
        channel_id,
        sequence: 0,
        log_time: end,
        publish_time: end,
    };
    w.write_to_known_channel(&header(map), &serde_json::to_vec(&v)?)?;
    let s = &r.stats;
    let v = serde_json::json!({"target": r.target, "mean": s.mean, "std": s.std, "min": s.min,
        "max": s.max, "coverage": s.coverage, "uniformity": s.uniformity(), "under": r.under,
        "over": r.over});
    w.write_to_known_channel(&header(stats), &serde_json::to_vec(&v)?)?;
    w.finish()?;
    Ok(())
}

/// A recording's label: its file name without `.mcap`.
pub fn label(path: &Path) -> String {
    path.file_stem()
        .map_or("recording".into(), |s| s.to_string_lossy().into_owned())
}

/// A Markdown table of the figures, one row per labelled removal.
pub fn table(rows: &[(String, RemovalOutput)]) -> String {
    let mut t = String::from(
        "| case | mean removal (µm) | uniformity σ/mean | min / max (µm) | coverage | under-polished | over-polished |\n|---|---|---|---|---|---|---|\n",
    );
    for (label, o) in rows {
        let r = &o.removal;
        let s = &r.stats;
        t += &format!(
            "| {label} | {:.4} | {:.4} | {:.4} / {:.4} | {:.1} % | {:.1} % | {:.1} % |\n",
            s.mean * 1e6,
            s.uniformity(),
            s.min * 1e6,
            s.max * 1e6,
            s.coverage * 100.0,
            r.under * 100.0,
            r.over * 100.0
        );
    }
    t
}
