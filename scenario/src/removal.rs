//! Material removal by Preston's law: a pad model (contact patch and pressure from the normal force), the
//! relative speed of the abrasive, Preston's coefficient, and a 2-D removal map accumulated along a path.
//!
//! Everything is SI: metres, newtons, pascals, seconds; Preston's coefficient in m²/N (so that
//! `k_p · p · v` is a removal rate in m/s). The assumptions are stated in `docs/removal.md`.

use std::f64::consts::PI;

/// How the normal force spreads over the contact patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PadModel {
    /// A flat, rigid-backed pad of `radius` (m) in full contact: uniform pressure `F / (π R²)` over the disc.
    Uniform {
        /// Pad radius, m.
        radius: f64,
    },
    /// A compliant spherical pad of curvature `radius` (m) and effective contact modulus `modulus` (Pa)
    /// on a flat part: Hertz contact, patch radius `a = (3 F R / (4 E*))^(1/3)`, pressure
    /// `p(r) = p0 · sqrt(1 − r²/a²)` with `p0 = 3 F / (2 π a²)`.
    Hertz {
        /// Pad radius of curvature, m.
        radius: f64,
        /// Effective contact modulus E* of pad against part, Pa.
        modulus: f64,
    },
}

impl PadModel {
    /// Contact patch radius (m) at normal force `force` (N); 0 for no contact (`force <= 0`).
    pub fn patch_radius(&self, force: f64) -> f64 {
        if force.is_nan() || force <= 0.0 {
            return 0.0;
        }
        match *self {
            PadModel::Uniform { radius } => radius,
            PadModel::Hertz { radius, modulus } => (3.0 * force * radius / (4.0 * modulus)).cbrt(),
        }
    }

    /// Contact pressure (Pa) at distance `r` (m) from the patch centre under normal force `force` (N).
    /// Zero outside the patch and for no contact.
    pub fn pressure(&self, force: f64, r: f64) -> f64 {
        let a = self.patch_radius(force);
        if a <= 0.0 || r.abs() > a {
            return 0.0;
        }
        match *self {
            PadModel::Uniform { .. } => force / (PI * a * a),
            PadModel::Hertz { .. } => {
                let p0 = 3.0 * force / (2.0 * PI * a * a);
                p0 * (1.0 - (r * r) / (a * a)).max(0.0).sqrt()
            }
        }
    }
}

/// The abrasive's own motion, independent of the feed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ToolMotion {
    /// No own motion (a pad only dragged along the path): the relative speed is the feed alone.
    Still,
    /// A rotating disc at `rpm` (rev/min), its speed taken at `effective_radius` (m): `v = 2π·rpm/60 · r_eff`.
    Disc {
        /// Spindle speed, rev/min.
        rpm: f64,
        /// Radius at which the disc's surface speed is taken, m.
        effective_radius: f64,
    },
    /// A belt at surface speed `speed` (m/s).
    Belt {
        /// Belt surface speed, m/s.
        speed: f64,
    },
}

impl ToolMotion {
    /// The tool's own surface speed, m/s.
    pub fn speed(&self) -> f64 {
        match *self {
            ToolMotion::Still => 0.0,
            ToolMotion::Disc {
                rpm,
                effective_radius,
            } => rpm * 2.0 * PI / 60.0 * effective_radius,
            ToolMotion::Belt { speed } => speed,
        }
    }
}

/// The whole removal model: pad, tool motion and Preston's coefficient.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RemovalModel {
    /// How force becomes pressure.
    pub pad: PadModel,
    /// The tool's own motion.
    pub tool: ToolMotion,
    /// Preston's coefficient k_p, m²/N (a property of part material, abrasive and slurry).
    pub preston: f64,
}

impl RemovalModel {
    /// Relative speed of the abrasive (m/s): the tool's own speed plus the feed speed `feed` (m/s).
    /// Assumption: the two add as magnitudes (the tool speed dominates, or the two are aligned).
    pub fn relative_speed(&self, feed: f64) -> f64 {
        self.tool.speed() + feed.abs()
    }

    /// Removal rate (m/s) at distance `r` (m) from the patch centre: `k_p · p(r) · v`.
    pub fn rate(&self, force: f64, feed: f64, r: f64) -> f64 {
        self.preston * self.pad.pressure(force, r) * self.relative_speed(feed)
    }
}

/// A removal depth map over a rectangle of the part, on a regular grid of square cells.
#[derive(Debug, Clone, PartialEq)]
pub struct RemovalMap {
    /// x of the first cell's centre, m.
    pub x0: f64,
    /// y of the first cell's centre, m.
    pub y0: f64,
    /// Cell size, m.
    pub cell: f64,
    /// Cells along x.
    pub nx: usize,
    /// Cells along y.
    pub ny: usize,
    /// Removal depth per cell (row-major, y outer), m.
    pub depth: Vec<f64>,
    /// Contact time per cell (time the cell lay inside the patch), s.
    pub dwell: Vec<f64>,
}

impl RemovalMap {
    /// An empty map covering `[x_min, x_max] × [y_min, y_max]` (m) with cells of `cell` (m).
    pub fn new(x_min: f64, x_max: f64, y_min: f64, y_max: f64, cell: f64) -> Self {
        assert!(
            cell > 0.0 && x_max >= x_min && y_max >= y_min,
            "invalid map extent"
        );
        let nx = ((x_max - x_min) / cell).ceil().max(1.0) as usize;
        let ny = ((y_max - y_min) / cell).ceil().max(1.0) as usize;
        RemovalMap {
            x0: x_min + cell / 2.0,
            y0: y_min + cell / 2.0,
            cell,
            nx,
            ny,
            depth: vec![0.0; nx * ny],
            dwell: vec![0.0; nx * ny],
        }
    }

    /// Centre (x, y) of cell (i, j), m.
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.x0 + i as f64 * self.cell,
            self.y0 + j as f64 * self.cell,
        )
    }

    /// The cell holding point (x, y), if it lies in the map.
    pub fn cell_at(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let i = ((x - self.x0) / self.cell + 0.5).floor();
        let j = ((y - self.y0) / self.cell + 0.5).floor();
        if i < 0.0 || j < 0.0 || i as usize >= self.nx || j as usize >= self.ny {
            return None;
        }
        Some((i as usize, j as usize))
    }

    /// Depth at cell (i, j), m.
    pub fn depth_at(&self, i: usize, j: usize) -> f64 {
        self.depth[j * self.nx + i]
    }

    /// Adds one sample: the patch centred at (x, y) (m) under normal force `force` (N), moving at feed
    /// speed `feed` (m/s), for `dt` (s). Each cell whose centre lies in the patch gets `k_p · p(r) · v · dt`.
    pub fn add(&mut self, model: &RemovalModel, x: f64, y: f64, force: f64, feed: f64, dt: f64) {
        let a = model.pad.patch_radius(force);
        if a <= 0.0 || dt <= 0.0 {
            return;
        }
        let span = (a / self.cell).ceil() as i64 + 1;
        let ci = ((x - self.x0) / self.cell).round() as i64;
        let cj = ((y - self.y0) / self.cell).round() as i64;
        for j in (cj - span)..=(cj + span) {
            for i in (ci - span)..=(ci + span) {
                if i < 0 || j < 0 || i as usize >= self.nx || j as usize >= self.ny {
                    continue;
                }
                let (cx, cy) = self.centre(i as usize, j as usize);
                let r = ((cx - x).powi(2) + (cy - y).powi(2)).sqrt();
                if r > a {
                    continue;
                }
                let k = j as usize * self.nx + i as usize;
                self.depth[k] += model.rate(force, feed, r) * dt;
                self.dwell[k] += dt;
            }
        }
    }

    /// Adds a recorded path: samples `(t, x, y, force)` (s, m, m, N) in time order. Each interval between two
    /// samples is one step at the earlier sample's position and force, its feed the distance to the next
    /// sample over the time between them. A step back in time or a non-finite value skips that interval.
    pub fn add_path(&mut self, model: &RemovalModel, samples: &[(f64, f64, f64, f64)]) {
        for w in samples.windows(2) {
            let ((t0, x0, y0, f0), (t1, x1, y1, _)) = (w[0], w[1]);
            let dt = t1 - t0;
            if !(dt.is_finite()
                && dt > 0.0
                && x0.is_finite()
                && y0.is_finite()
                && x1.is_finite()
                && y1.is_finite())
            {
                continue;
            }
            let feed = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt() / dt;
            self.add(model, x0, y0, f0, feed, dt);
        }
    }

    /// Mean, standard deviation, min and max of the depth over the cells whose centres lie in
    /// `[x_min, x_max] × [y_min, y_max]` (m), and the share of those cells with any removal (coverage).
    pub fn stats(&self, x_min: f64, x_max: f64, y_min: f64, y_max: f64) -> Option<MapStats> {
        let mut v = Vec::new();
        for j in 0..self.ny {
            for i in 0..self.nx {
                let (cx, cy) = self.centre(i, j);
                if cx >= x_min && cx <= x_max && cy >= y_min && cy <= y_max {
                    v.push(self.depth_at(i, j));
                }
            }
        }
        if v.is_empty() {
            return None;
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n).sqrt();
        Some(MapStats {
            mean,
            std,
            min: v.iter().cloned().fold(f64::INFINITY, f64::min),
            max: v.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            coverage: v.iter().filter(|d| **d > 0.0).count() as f64 / n,
        })
    }
}

/// Removal statistics over a target area.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapStats {
    /// Mean depth, m.
    pub mean: f64,
    /// Standard deviation of depth, m.
    pub std: f64,
    /// Least depth, m.
    pub min: f64,
    /// Greatest depth, m.
    pub max: f64,
    /// Share of cells with any removal, 0..=1.
    pub coverage: f64,
}

impl MapStats {
    /// Uniformity as standard deviation over mean (dimensionless); infinite when nothing was removed.
    pub fn uniformity(&self) -> f64 {
        if self.mean > 0.0 {
            self.std / self.mean
        } else {
            f64::INFINITY
        }
    }
}

/// Which pad model a `[removal]` table names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PadKind {
    /// [`PadModel::Uniform`].
    #[default]
    Uniform,
    /// [`PadModel::Hertz`].
    Hertz,
}

/// Which tool motion a `[removal]` table names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ToolKind {
    /// [`ToolMotion::Still`].
    #[default]
    Still,
    /// [`ToolMotion::Disc`].
    Disc,
    /// [`ToolMotion::Belt`].
    Belt,
}

/// The `[removal]` table of a scenario or cell file: the one place the pad, the tool's speed and
/// Preston's coefficient are given, with their units in the names' docs (SI).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RemovalConfig {
    /// Preston's coefficient k_p, m²/N.
    pub preston: f64,
    /// Pad model: `uniform` or `hertz`.
    #[serde(default)]
    pub pad: PadKind,
    /// Pad radius (uniform) or radius of curvature (hertz), m.
    pub pad_radius: f64,
    /// Effective contact modulus E* (hertz only), Pa.
    #[serde(default)]
    pub pad_modulus: Option<f64>,
    /// The tool's own motion: `still`, `disc` or `belt`.
    #[serde(default)]
    pub tool: ToolKind,
    /// Disc speed, rev/min (disc only).
    #[serde(default)]
    pub rpm: Option<f64>,
    /// Radius at which the disc's speed is taken, m (disc only).
    #[serde(default)]
    pub effective_radius: Option<f64>,
    /// Belt surface speed, m/s (belt only).
    #[serde(default)]
    pub belt_speed: Option<f64>,
    /// Map cell size, m.
    #[serde(default = "default_cell")]
    pub cell: f64,
    /// Target area `[x_min, x_max, y_min, y_max]` in the part frame (m: base-frame x and y from the
    /// first recorded pose); default: the path in contact, inset by the patch radius.
    #[serde(default)]
    pub target: Option<[f64; 4]>,
    /// A cell is under- or over-polished when its depth is below `(1 − band)` or above `(1 + band)`
    /// times the nominal depth (what the set-point in effect would have removed on the same path); a
    /// target cell the set-point's path never reached is under-polished when nothing was removed
    /// there, over-polished otherwise.
    #[serde(default = "default_band")]
    pub band: f64,
}

fn default_cell() -> f64 {
    0.5e-3
}

fn default_band() -> f64 {
    0.1
}

/// The largest pad considered, m (a 1 m polishing pad is no pad).
pub const MAX_PAD_RADIUS: f64 = 0.5;
/// The fastest tool surface speed accepted, m/s (grinding wheels run at up to ~100 m/s).
pub const MAX_TOOL_SPEED: f64 = 150.0;
/// The most cells a map may have (a 1 m × 1 m part at 0.5 mm).
pub const MAX_CELLS: usize = 4_000_000;

impl RemovalConfig {
    /// Checks every value against what it can physically be; one message naming the key.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |name: &str, v: f64, max: f64, unit: &str| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(format!(
                    "removal.{name} must be > 0 and ≤ {max} {unit}, got {v}"
                ))
            }
        };
        // Preston coefficients of polishing lie around 1e-15 … 1e-11 m²/N; 1e-9 leaves room.
        pos("preston", self.preston, 1e-9, "m²/N")?;
        pos("pad_radius", self.pad_radius, MAX_PAD_RADIUS, "m")?;
        // A map cell must resolve the patch: at most a fifth of the pad.
        pos(
            "cell",
            self.cell,
            self.pad_radius / 5.0,
            "m (a fifth of pad_radius)",
        )?;
        if !(self.band.is_finite() && self.band > 0.0 && self.band < 1.0) {
            return Err(format!(
                "removal.band is a fraction in (0, 1), got {}",
                self.band
            ));
        }
        match (self.pad, self.pad_modulus) {
            (PadKind::Hertz, Some(e)) => pos("pad_modulus", e, 1e12, "Pa")?,
            (PadKind::Hertz, None) => {
                return Err("removal.pad = \"hertz\" needs pad_modulus (Pa)".into());
            }
            (PadKind::Uniform, Some(_)) => {
                return Err("removal.pad_modulus applies to pad = \"hertz\" only".into());
            }
            (PadKind::Uniform, None) => {}
        }
        match self.tool {
            ToolKind::Still => {
                if self.rpm.is_some()
                    || self.effective_radius.is_some()
                    || self.belt_speed.is_some()
                {
                    return Err(
                        "removal.tool = \"still\" takes no rpm, effective_radius or belt_speed"
                            .into(),
                    );
                }
            }
            ToolKind::Disc => {
                let (Some(rpm), Some(r)) = (self.rpm, self.effective_radius) else {
                    return Err(
                        "removal.tool = \"disc\" needs rpm (rev/min) and effective_radius (m)"
                            .into(),
                    );
                };
                pos("rpm", rpm, 60_000.0, "rev/min")?;
                pos("effective_radius", r, MAX_PAD_RADIUS, "m")?;
                let v = ToolMotion::Disc {
                    rpm,
                    effective_radius: r,
                }
                .speed();
                if v > MAX_TOOL_SPEED {
                    return Err(format!(
                        "removal: the disc's surface speed {v:.1} m/s exceeds {MAX_TOOL_SPEED} m/s"
                    ));
                }
            }
            ToolKind::Belt => {
                let Some(v) = self.belt_speed else {
                    return Err("removal.tool = \"belt\" needs belt_speed (m/s)".into());
                };
                pos("belt_speed", v, MAX_TOOL_SPEED, "m/s")?;
            }
        }
        if let Some([x0, x1, y0, y1]) = self.target
            && !([x0, x1, y0, y1]
                .iter()
                .all(|v| v.is_finite() && v.abs() <= 10.0)
                && x1 > x0
                && y1 >= y0)
        {
            return Err(format!(
                "removal.target is [x_min, x_max, y_min, y_max] in m (x_max > x_min, y_max ≥ y_min, within ±10 m), got {:?}",
                self.target.unwrap_or_default()
            ));
        }
        Ok(())
    }

    /// The model it describes (call [`RemovalConfig::validate`] first).
    pub fn model(&self) -> RemovalModel {
        RemovalModel {
            pad: match self.pad {
                PadKind::Uniform => PadModel::Uniform {
                    radius: self.pad_radius,
                },
                PadKind::Hertz => PadModel::Hertz {
                    radius: self.pad_radius,
                    modulus: self.pad_modulus.unwrap_or(f64::NAN),
                },
            },
            tool: match self.tool {
                ToolKind::Still => ToolMotion::Still,
                ToolKind::Disc => ToolMotion::Disc {
                    rpm: self.rpm.unwrap_or(0.0),
                    effective_radius: self.effective_radius.unwrap_or(0.0),
                },
                ToolKind::Belt => ToolMotion::Belt {
                    speed: self.belt_speed.unwrap_or(0.0),
                },
            },
            preston: self.preston,
        }
    }
}

/// One recorded cycle as the removal needs it: time (s), tool position in the base frame (m), the
/// normal force pressing the pad (N) and the set-point in effect (N, NaN when unknown).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathSample {
    /// Time, s.
    pub t: f64,
    /// Base-frame x, m.
    pub x: f64,
    /// Base-frame y, m.
    pub y: f64,
    /// Normal force, N.
    pub force: f64,
    /// Set-point in effect, N.
    pub setpoint: f64,
}

/// One bin of the path (length = the map's cell): where it is, the depth removed under it and the
/// contact time per unit length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlongPath {
    /// Time the tool entered the bin, s.
    pub t: f64,
    /// Distance along the path to the bin's start, m.
    pub s: f64,
    /// Part-frame position of the bin's first sample, m.
    pub x: f64,
    /// Part-frame position of the bin's first sample, m.
    pub y: f64,
    /// Removal depth at that point, m.
    pub depth: f64,
    /// Contact time per unit path length in the bin, s/m.
    pub dwell: f64,
}

/// What a pass did to the part: the map, the nominal map (the set-point in effect on the same path),
/// the path, the target area and the figures over it.
#[derive(Debug, Clone, PartialEq)]
pub struct Removal {
    /// Depth and dwell over the part (part frame).
    pub map: RemovalMap,
    /// What the set-point in effect would have removed on the same path.
    pub nominal: RemovalMap,
    /// The path in the part frame, (x, y) m, the samples with a pose.
    pub path: Vec<(f64, f64)>,
    /// Along the path, one bin per cell length.
    pub along: Vec<AlongPath>,
    /// Target area `[x_min, x_max, y_min, y_max]`, part frame, m.
    pub target: [f64; 4],
    /// The part frame's origin in the base frame (the first recorded pose), m.
    pub origin: (f64, f64),
    /// Statistics over the target area.
    pub stats: MapStats,
    /// Share of target cells below `(1 − band)` times their nominal depth.
    pub under: f64,
    /// Share of target cells above `(1 + band)` times their nominal depth.
    pub over: f64,
    /// Samples without a usable pose, skipped.
    pub skipped: usize,
    /// The band of [`Removal::under`] and [`Removal::over`] (fraction of the nominal depth).
    pub band: f64,
}

/// Compute the removal of a recorded path. Refuses a path with no pose at all, no contact, or a part
/// too large to map.
pub fn analyse(cfg: &RemovalConfig, samples: &[PathSample]) -> Result<Removal, String> {
    cfg.validate()?;
    let model = cfg.model();
    let posed: Vec<PathSample> = samples
        .iter()
        .filter(|s| s.x.is_finite() && s.y.is_finite() && s.t.is_finite())
        .copied()
        .collect();
    let skipped = samples.len() - posed.len();
    let Some(first) = posed.first() else {
        return Err("the recording has no robot poses (robot.pose): it was written before poses were recorded, or by a link that reports none; a removal map needs the path".into());
    };
    let origin = (first.x, first.y);
    let part: Vec<PathSample> = posed
        .iter()
        .map(|s| PathSample {
            x: s.x - origin.0,
            y: s.y - origin.1,
            ..*s
        })
        .collect();
    let contact: Vec<&PathSample> = part.iter().filter(|s| s.force > 0.0).collect();
    if contact.is_empty() {
        return Err(
            "no cycle with a pose was in contact (force > 0 N): nothing was removed".into(),
        );
    }
    let bbox = |v: &[&PathSample]| {
        v.iter().fold(
            [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ],
            |b, s| [b[0].min(s.x), b[1].max(s.x), b[2].min(s.y), b[3].max(s.y)],
        )
    };
    let all: Vec<&PathSample> = part.iter().collect();
    let b = bbox(&all);
    let mut forces: Vec<f64> = contact.iter().map(|s| s.force).collect();
    forces.sort_by(f64::total_cmp);
    let patch = model
        .pad
        .patch_radius(forces[forces.len() / 2])
        .max(model.pad.patch_radius(forces[forces.len() - 1]));
    let c = cfg.cell;
    let margin = patch + 2.0 * c;
    // Cell centres on multiples of the cell size: the path's line y = 0 is a row of centres.
    let lo = |v: f64| ((v - margin) / c).floor() * c - c / 2.0;
    let hi = |v: f64| ((v + margin) / c).ceil() * c + c / 2.0;
    let (x0, x1, y0, y1) = (lo(b[0]), hi(b[1]), lo(b[2]), hi(b[3]));
    let cells = ((x1 - x0) / c).ceil() * ((y1 - y0) / c).ceil();
    if !(cells.is_finite() && cells <= MAX_CELLS as f64) {
        return Err(format!(
            "the path spans {:.3} m × {:.3} m: more than {MAX_CELLS} cells of {} mm (raise removal.cell)",
            b[1] - b[0],
            b[3] - b[2],
            c * 1e3
        ));
    }
    let mut map = RemovalMap::new(x0, x1, y0, y1, c);
    let mut nominal = map.clone();
    let tuples: Vec<(f64, f64, f64, f64)> = part.iter().map(|s| (s.t, s.x, s.y, s.force)).collect();
    map.add_path(&model, &tuples);
    let nom: Vec<(f64, f64, f64, f64)> = part
        .iter()
        .map(|s| {
            (
                s.t,
                s.x,
                s.y,
                if s.setpoint.is_finite() {
                    s.setpoint
                } else {
                    0.0
                },
            )
        })
        .collect();
    nominal.add_path(&model, &nom);
    let target = cfg.target.unwrap_or_else(|| {
        let cb = bbox(&contact);
        let inset = |a: f64, z: f64| {
            if z - a > 2.0 * patch + c {
                (a + patch, z - patch)
            } else {
                let m = ((a + z) / 2.0 / c).round() * c;
                (m - c / 2.0, m + c / 2.0)
            }
        };
        let (tx0, tx1) = inset(cb[0], cb[1]);
        let (ty0, ty1) = inset(cb[2], cb[3]);
        [tx0, tx1, ty0, ty1]
    });
    let stats = map
        .stats(target[0], target[1], target[2], target[3])
        .ok_or_else(|| format!("the target area {target:?} m holds no cell of the map"))?;
    let (mut n, mut under, mut over) = (0usize, 0usize, 0usize);
    for j in 0..map.ny {
        for i in 0..map.nx {
            let (cx, cy) = map.centre(i, j);
            if cx < target[0] || cx > target[1] || cy < target[2] || cy > target[3] {
                continue;
            }
            n += 1;
            let (d, w) = (map.depth_at(i, j), nominal.depth_at(i, j));
            if w <= 0.0 {
                // The set-point's pass never reached this target cell (a program that ended early):
                // nothing removed is under-polished, anything removed is more than asked.
                if d <= 0.0 {
                    under += 1;
                } else {
                    over += 1;
                }
            } else if d < (1.0 - cfg.band) * w {
                under += 1;
            } else if d > (1.0 + cfg.band) * w {
                over += 1;
            }
        }
    }
    // Along the path: bins of one cell length of travelled distance.
    let mut along: Vec<AlongPath> = Vec::new();
    let mut s = 0.0;
    for w in part.windows(2) {
        let (a, z) = (w[0], w[1]);
        let ds = ((z.x - a.x).powi(2) + (z.y - a.y).powi(2)).sqrt();
        let dt = z.t - a.t;
        let k = (s / c).floor() as usize;
        while along.len() <= k {
            let depth = map
                .cell_at(a.x, a.y)
                .map_or(0.0, |(i, j)| map.depth_at(i, j));
            along.push(AlongPath {
                t: a.t,
                s: along.len() as f64 * c,
                x: a.x,
                y: a.y,
                depth,
                dwell: 0.0,
            });
        }
        if dt > 0.0 && dt.is_finite() && model.pad.patch_radius(a.force) > 0.0 {
            along[k].dwell += dt / c;
        }
        if ds.is_finite() {
            s += ds;
        }
    }
    let path = part.iter().map(|s| (s.x, s.y)).collect();
    let frac = |k: usize| if n == 0 { 0.0 } else { k as f64 / n as f64 };
    Ok(Removal {
        map,
        nominal,
        path,
        along,
        target,
        origin,
        stats,
        under: frac(under),
        over: frac(over),
        skipped,
        band: cfg.band,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * b.abs()
    }

    #[test]
    fn hertz_patch_and_pressure_by_hand() {
        // F = 20 N, R = 0.05 m, E* = 1 MPa: a³ = 3·20·0.05/(4·1e6) = 7.5e-7 m³, a = 9.0856e-3 m.
        let pad = PadModel::Hertz {
            radius: 0.05,
            modulus: 1.0e6,
        };
        let a = pad.patch_radius(20.0);
        assert!(close(a, 9.0856e-3, 1e-4), "a = {a}");
        // p0 = 3F/(2πa²) = 60/(2π·8.2548e-5) = 1.1568e5 Pa.
        assert!(close(pad.pressure(20.0, 0.0), 1.1568e5, 1e-3));
        assert_eq!(pad.pressure(20.0, a * 1.01), 0.0);
        assert_eq!(pad.patch_radius(0.0), 0.0);
        assert_eq!(pad.patch_radius(-3.0), 0.0);
        // The pressure integrates back to the force: ∫ p 2πr dr = F.
        let n = 20_000;
        let f: f64 = (0..n)
            .map(|k| {
                let r = (k as f64 + 0.5) * a / n as f64;
                pad.pressure(20.0, r) * 2.0 * PI * r * a / n as f64
            })
            .sum();
        assert!(close(f, 20.0, 1e-3), "integrated force {f}");
    }

    #[test]
    fn disc_speed_by_hand() {
        // 3000 rpm at 0.02 m: 3000·2π/60·0.02 = 6.2832 m/s; plus 0.01 m/s feed.
        let m = RemovalModel {
            pad: PadModel::Uniform { radius: 0.01 },
            tool: ToolMotion::Disc {
                rpm: 3000.0,
                effective_radius: 0.02,
            },
            preston: 1e-13,
        };
        assert!(close(m.relative_speed(0.01), 6.2932, 1e-4));
        assert!(close(m.relative_speed(-0.01), 6.2932, 1e-4));
    }

    #[test]
    fn dwell_depth_is_kp_p_v_t() {
        // Uniform pad R = 10 mm, F = 10 N: p = 10/(π·1e-4) = 31831 Pa. Belt 5 m/s, k_p = 1e-13 m²/N,
        // 2 s still: depth = 1e-13 · 31831 · 5 · 2 = 3.1831e-8 m (31.8 nm) everywhere under the pad.
        let m = RemovalModel {
            pad: PadModel::Uniform { radius: 0.01 },
            tool: ToolMotion::Belt { speed: 5.0 },
            preston: 1e-13,
        };
        let mut map = RemovalMap::new(-0.02, 0.02, -0.02, 0.02, 0.001);
        for _ in 0..500 {
            map.add(&m, 0.0005, 0.0005, 10.0, 0.0, 0.004);
        }
        let (i, j) = map.cell_at(0.0005, 0.0005).unwrap();
        assert!(
            close(map.depth_at(i, j), 3.1831e-8, 1e-4),
            "{}",
            map.depth_at(i, j)
        );
        assert!(close(map.dwell[j * map.nx + i], 2.0, 1e-9));
        // Outside the pad nothing.
        let (i, j) = map.cell_at(0.0185, 0.0005).unwrap();
        assert_eq!(map.depth_at(i, j), 0.0);
    }

    #[test]
    fn straight_pass_depth_on_centreline() {
        // Uniform pad R = 10 mm at 10 N, feed u = 10 mm/s, pad dragged (no own motion): v = u, and a
        // point on the centreline lies under the patch for 2R/u = 2 s, so depth = k_p · p · u · 2R/u
        // = 1e-13 · 31831 · 0.01 · 2 = 6.3662e-11 m.
        let m = RemovalModel {
            pad: PadModel::Uniform { radius: 0.01 },
            tool: ToolMotion::Still,
            preston: 1e-13,
        };
        let mut map = RemovalMap::new(-0.05, 0.05, -0.02, 0.02, 0.0005);
        let dt = 0.001;
        let u = 0.01;
        let mut x = -0.045;
        while x < 0.045 {
            map.add(&m, x, 0.00025, 10.0, u, dt);
            x += u * dt;
        }
        let (i, j) = map.cell_at(0.0, 0.00025).unwrap();
        assert!(
            close(map.depth_at(i, j), 6.3662e-11, 2e-3),
            "{}",
            map.depth_at(i, j)
        );
        // Beside the path, at 8 mm off the line, the chord is shorter: 2·sqrt(R² − y²) = 12 mm → 1.2 s.
        let (i8, j8) = map.cell_at(0.0, 0.00825).unwrap();
        let (_, cy) = map.centre(i8, j8);
        let chord = 2.0 * (0.01f64.powi(2) - (cy - 0.00025).powi(2)).sqrt();
        let expect = 1e-13 * 10.0 / (PI * 1e-4) * u * chord / u;
        assert!(
            close(map.depth_at(i8, j8), expect, 2e-2),
            "{} vs {expect}",
            map.depth_at(i8, j8)
        );
        let s = map.stats(-0.01, 0.01, -0.001, 0.001).unwrap();
        assert!(
            s.uniformity() < 0.01,
            "along the middle of the pass the depth is even: {s:?}"
        );
        assert_eq!(s.coverage, 1.0);
    }
    #[test]
    fn recorded_path_matches_the_stepped_pass() {
        // The same straight pass as above given as recorded samples: the feed comes from the positions.
        let m = RemovalModel {
            pad: PadModel::Uniform { radius: 0.01 },
            tool: ToolMotion::Still,
            preston: 1e-13,
        };
        let samples: Vec<_> = (0..=9000)
            .map(|k| {
                let t = k as f64 * 0.001;
                (t, -0.045 + 0.01 * t, 0.00025, 10.0)
            })
            .collect();
        let mut map = RemovalMap::new(-0.05, 0.05, -0.02, 0.02, 0.0005);
        map.add_path(&m, &samples);
        let (i, j) = map.cell_at(0.0, 0.00025).unwrap();
        assert!(
            close(map.depth_at(i, j), 6.3662e-11, 2e-3),
            "{}",
            map.depth_at(i, j)
        );
        // A sample with a NaN position removes nothing for its interval; time going back neither.
        let mut bad = RemovalMap::new(-0.05, 0.05, -0.02, 0.02, 0.0005);
        bad.add_path(
            &m,
            &[
                (0.0, f64::NAN, 0.0, 10.0),
                (1.0, 0.0, 0.0, 10.0),
                (0.5, 0.0, 0.0, 10.0),
            ],
        );
        assert!(bad.depth.iter().all(|d| *d == 0.0));
    }

    fn config() -> RemovalConfig {
        RemovalConfig {
            preston: 1e-12,
            pad: PadKind::Uniform,
            pad_radius: 0.01,
            pad_modulus: None,
            tool: ToolKind::Belt,
            rpm: None,
            effective_radius: None,
            belt_speed: Some(5.0),
            cell: 0.0005,
            target: None,
            band: 0.1,
        }
    }

    #[test]
    fn a_removal_table_is_refused_where_it_cannot_be() {
        assert!(config().validate().is_ok());
        let bad = |c: RemovalConfig| c.validate().unwrap_err();
        assert!(
            bad(RemovalConfig {
                preston: 0.0,
                ..config()
            })
            .contains("removal.preston")
        );
        assert!(
            bad(RemovalConfig {
                pad_radius: f64::NAN,
                ..config()
            })
            .contains("pad_radius")
        );
        assert!(
            bad(RemovalConfig {
                cell: 0.005,
                ..config()
            })
            .contains("removal.cell")
        );
        assert!(
            bad(RemovalConfig {
                pad: PadKind::Hertz,
                ..config()
            })
            .contains("pad_modulus")
        );
        assert!(
            bad(RemovalConfig {
                belt_speed: None,
                ..config()
            })
            .contains("belt_speed")
        );
        assert!(
            bad(RemovalConfig {
                belt_speed: Some(500.0),
                ..config()
            })
            .contains("belt_speed")
        );
        assert!(
            bad(RemovalConfig {
                band: 1.0,
                ..config()
            })
            .contains("band")
        );
        assert!(
            bad(RemovalConfig {
                target: Some([0.1, 0.0, 0.0, 0.1]),
                ..config()
            })
            .contains("target")
        );
    }

    #[test]
    fn analyse_maps_a_straight_pass_by_hand_and_refuses_a_path_without_poses() {
        // 100 mm along x at 10 mm/s, 15 N, from base (0.4, 0.2): the part frame starts there.
        let dt = 0.004;
        let samples: Vec<PathSample> = (0..=2500)
            .map(|k| PathSample {
                t: k as f64 * dt,
                x: 0.4 + 0.01 * k as f64 * dt,
                y: 0.2,
                force: 15.0,
                setpoint: 15.0,
            })
            .collect();
        let r = analyse(&config(), &samples).unwrap();
        assert_eq!(r.origin, (0.4, 0.2));
        let hand = 1e-12 * 15.0 / (PI * 1e-4) * (5.0 + 0.01) * 0.02 / 0.01;
        assert!(
            close(r.stats.mean, hand, 0.01),
            "{} vs {hand}",
            r.stats.mean
        );
        assert!(r.stats.uniformity() < 0.01);
        assert_eq!((r.under, r.over), (0.0, 0.0));
        // Dwell along the path: 1/u = 100 s/m in the middle (a bin holds 12 or 13 samples of 0.04 mm:
        // the mean over 20 bins).
        let n = r.along.len() / 2;
        let mid = r.along[n..n + 20].iter().map(|a| a.dwell).sum::<f64>() / 20.0;
        assert!(close(mid, 100.0, 0.01), "{mid}");
        // Half the force everywhere: every target cell is under-polished against the set-point.
        let half: Vec<PathSample> = samples
            .iter()
            .map(|s| PathSample { force: 7.5, ..*s })
            .collect();
        assert_eq!(analyse(&config(), &half).unwrap().under, 1.0);
        let blind: Vec<PathSample> = samples
            .iter()
            .map(|s| PathSample { x: f64::NAN, ..*s })
            .collect();
        assert!(
            analyse(&config(), &blind)
                .unwrap_err()
                .contains("robot.pose")
        );
        let air: Vec<PathSample> = samples
            .iter()
            .map(|s| PathSample { force: 0.0, ..*s })
            .collect();
        assert!(analyse(&config(), &air).unwrap_err().contains("contact"));
    }
}
