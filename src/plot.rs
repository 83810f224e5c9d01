//! PNG plots of a trace: force against set-point, positions, estimates. Pure Rust (plotters' bitmap
//! backend with an embedded DejaVu Sans font): no system font, no C library.

use std::path::Path;
use std::sync::Once;

use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use ::scenario::telemetry as tm;

use crate::record::Row;

/// The backend reports an unwritable path as a nested Debug dump, only after drawing: find it first.
fn check_writable(path: &Path) -> Result<()> {
    std::fs::File::create(path).map_err(|e| {
        let t = e.to_string();
        let t = t.split(" (os error").next().unwrap_or_default();
        anyhow!("cannot write {}: {t}", path.display())
    })?;
    Ok(())
}

fn fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid TrueType; a failure would only mean text is not drawn.
        let _ = register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
        let _ = register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
    });
}

/// One line of a panel.
struct Line<'a> {
    label: &'a str,
    color: RGBColor,
    width: u32,
    value: fn(&Row) -> f64,
}

fn range(rows: &[Row], lines: &[Line]) -> (f64, f64) {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for r in rows {
        for l in lines {
            let v = (l.value)(r);
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.06).max(1e-9 + hi.abs() * 1e-3);
    (lo - pad, hi + pad)
}

/// The x axis of a panel: its label and its value.
type Axis = (&'static str, fn(&Row) -> f64);

/// Time, s.
const TIME: Axis = ("t [s]", |r| r.t);

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    rows: &[Row],
    caption: &str,
    y_label: &str,
    lines: &[Line],
) -> Result<()> {
    panel_over(area, rows, TIME, caption, y_label, lines)
}

fn panel_over(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    rows: &[Row],
    (x_desc, xv): Axis,
    caption: &str,
    y_label: &str,
    lines: &[Line],
) -> Result<()> {
    let (x_lo, x_hi) = rows
        .iter()
        .map(xv)
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (x_lo, x_hi) = if x_lo.is_finite() && x_hi > x_lo {
        (x_lo.min(0.0), x_hi)
    } else {
        (0.0, 1.0)
    };
    let (lo, hi) = range(rows, lines);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 20).into_font())
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .build_cartesian_2d(x_lo..x_hi, lo..hi)
        .map_err(|e| anyhow!("plot: {e}"))?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_label)
        .label_style(("sans-serif", 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(|e| anyhow!("plot: {e}"))?;
    // Keep the PNG light: at most ~4000 points a line.
    let stride = (rows.len() / 4000).max(1);
    for l in lines {
        let color = l.color;
        let pts = rows
            .iter()
            .step_by(stride)
            .map(|r| (xv(r), (l.value)(r)))
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        chart
            .draw_series(LineSeries::new(pts, color.stroke_width(l.width)))
            .map_err(|e| anyhow!("plot: {e}"))?
            .label(l.label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], color.stroke_width(3)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(|e| anyhow!("plot: {e}"))?;
    Ok(())
}

const BLUE_: RGBColor = RGBColor(31, 119, 180);
const ORANGE_: RGBColor = RGBColor(255, 127, 14);
const GREEN_: RGBColor = RGBColor(44, 160, 44);
const RED_: RGBColor = RGBColor(214, 39, 40);
const GREY_: RGBColor = RGBColor(150, 150, 150);
const PURPLE_: RGBColor = RGBColor(148, 103, 189);

/// Write a three-panel PNG: force, positions (mm), stiffness estimate (kN/m). The file is drawn under
/// a temporary name and renamed over `path` when complete ([`crate::output::replace`]).
pub fn write_png(path: &Path, title: &str, rows: &[Row]) -> Result<()> {
    crate::output::require_extension(path, &["png"], "a plot")?;
    crate::output::replace(path, |tmp| draw_png(tmp, title, rows))
}

fn draw_png(path: &Path, title: &str, rows: &[Row]) -> Result<()> {
    fonts();
    check_writable(path)?;
    let root = BitMapBackend::new(path, (1200, 1050)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
    let root = root
        .titled(title, ("sans-serif", 24).into_font())
        .map_err(|e| anyhow!("plot: {e}"))?;
    let panels = root.split_evenly((3, 1));
    panel(
        &panels[0],
        rows,
        "contact force",
        "force [N]",
        &[
            Line {
                label: tm::F.label,
                color: GREY_,
                width: 1,
                value: |r| r.f,
            },
            Line {
                label: tm::F_TRUE.label,
                color: BLUE_,
                width: 2,
                value: |r| r.f_true,
            },
            Line {
                label: tm::F_R.label,
                color: RED_,
                width: 2,
                value: |r| r.f_r,
            },
        ],
    )?;
    panel(
        &panels[1],
        rows,
        "positions along the tool normal",
        "x [mm]",
        &[
            Line {
                label: tm::X.label,
                color: BLUE_,
                width: 2,
                value: |r| r.x * 1e3,
            },
            Line {
                label: tm::X_CMD.label,
                color: ORANGE_,
                width: 1,
                value: |r| r.x_cmd * 1e3,
            },
            Line {
                label: tm::X_R.label,
                color: GREEN_,
                width: 1,
                value: |r| r.x_r * 1e3,
            },
            Line {
                label: tm::X_C.label,
                color: BLACK,
                width: 1,
                value: |r| r.x_c * 1e3,
            },
            Line {
                label: tm::XC_HAT.label,
                color: PURPLE_,
                width: 2,
                value: |r| r.xc_hat * 1e3,
            },
        ],
    )?;
    panel(
        &panels[2],
        rows,
        "environment stiffness",
        "k [kN/m]",
        &[
            Line {
                label: tm::K_C.label,
                color: BLACK,
                width: 1,
                value: |r| r.k_c * 1e-3,
            },
            Line {
                label: tm::KC_HAT.label,
                color: PURPLE_,
                width: 2,
                value: |r| r.kc_hat * 1e-3,
            },
        ],
    )?;
    root.present()
        .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?;
    Ok(())
}

/// Write the plot of a programmed pass: force against the program's `F` and the set-point in effect,
/// the process state the program saw, its segment and the tool's position along the path, over time;
/// on a curved part or with orientation following also the tilt error, the rotation sent and the
/// moments. Written like [`write_png`].
pub fn write_pass_png(path: &Path, title: &str, rows: &[Row]) -> Result<()> {
    crate::output::require_extension(path, &["png"], "a plot")?;
    crate::output::replace(path, |tmp| draw_pass_png(tmp, title, rows))
}

fn draw_pass_png(path: &Path, title: &str, rows: &[Row]) -> Result<()> {
    fonts();
    check_writable(path)?;
    let rows: Vec<Row> = rows
        .iter()
        .filter(|r| r.segment.is_some())
        .cloned()
        .collect();
    // A pass that turns the tool (orientation following) or runs over a simulated curved part gets
    // two more panels: the tilt and the rotation sent, and the moments the tilt makes.
    let turned = rows
        .iter()
        .any(|r| r.tilt_error.is_finite() || r.rotation > 0.0);
    let extra = if turned { 2 } else { 0 };
    let root = BitMapBackend::new(path, (1200, 1100 + 220 * extra)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
    let root = root
        .titled(title, ("sans-serif", 24).into_font())
        .map_err(|e| anyhow!("plot: {e}"))?;
    let (top, bottom) = root.split_vertically(440);
    let all = bottom.split_evenly((3 + extra as usize, 1));
    let (turn, lower) = all.split_at(extra as usize);
    if turned {
        panel(
            &turn[0],
            &rows,
            "orientation: tilt error (true, simulation) and the rotation sent",
            "angle [°]",
            &[
                Line {
                    label: tm::TILT_ERROR.label,
                    color: RED_,
                    width: 2,
                    value: |r| r.tilt_error.to_degrees(),
                },
                Line {
                    label: "rotation sent (magnitude)",
                    color: BLACK,
                    width: 1,
                    value: |r| r.rotation.to_degrees(),
                },
            ],
        )?;
        panel(
            &turn[1],
            &rows,
            "moments the loop read (sensor frame, after compensation)",
            "torque [N·m]",
            &[
                Line {
                    label: "about x",
                    color: BLUE_,
                    width: 2,
                    value: |r| r.moment[0],
                },
                Line {
                    label: "about y",
                    color: GREEN_,
                    width: 2,
                    value: |r| r.moment[1],
                },
            ],
        )?;
    }
    panel(
        &top,
        &rows,
        "contact force",
        "force [N]",
        &[
            Line {
                label: tm::F_TRUE.label,
                color: BLUE_,
                width: 2,
                value: |r| r.f_true,
            },
            Line {
                label: tm::F_CMD.label,
                color: BLACK,
                width: 1,
                value: |r| r.f_cmd,
            },
            Line {
                label: "set-point in effect",
                color: RED_,
                width: 2,
                value: |r| r.f_r,
            },
        ],
    )?;
    panel(
        &lower[0],
        &rows,
        &format!(
            "process phase (FcState.State: {})",
            hal::ProcessPhase::legend().to_uppercase()
        ),
        "phase",
        &[Line {
            label: tm::PHASE.label,
            color: ORANGE_,
            width: 2,
            value: |r| r.phase.map_or(f64::NAN, f64::from),
        }],
    )?;
    panel(
        &lower[1],
        &rows,
        "program segment (FcCmd.Seg)",
        "segment",
        &[Line {
            label: tm::SEGMENT.label,
            color: GREEN_,
            width: 2,
            value: |r| r.segment.map_or(f64::NAN, |s| s as f64),
        }],
    )?;
    panel(
        &lower[2],
        &rows,
        "tool along the path",
        "s [mm]",
        &[Line {
            label: "path position",
            color: PURPLE_,
            width: 2,
            value: |r| r.s * 1e3,
        }],
    )?;
    root.present().map_err(|e| anyhow!("plot: {e}"))?;
    Ok(())
}

/// A colour for `v` in `0..=1` (black-body-like: dark blue, purple, orange, yellow).
fn heat(v: f64) -> RGBColor {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [13.0, 8.0, 135.0]),
        (0.25, [126.0, 3.0, 168.0]),
        (0.5, [204.0, 71.0, 120.0]),
        (0.75, [248.0, 149.0, 64.0]),
        (1.0, [240.0, 249.0, 33.0]),
    ];
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let k = STOPS
        .iter()
        .rposition(|(at, _)| *at <= v)
        .unwrap_or(0)
        .min(3);
    let (a, ca) = STOPS[k];
    let (b, cb) = STOPS[k + 1];
    let f = (v - a) / (b - a);
    let c = |i: usize| (ca[i] + (cb[i] - ca[i]) * f).round() as u8;
    RGBColor(c(0), c(1), c(2))
}

/// Write removal maps side by side, one panel each on one extent (a heat map in µm on one colour scale
/// shared by the panels, up to 1.25 × the deepest cell within a target area; the path overlaid in white, the
/// target area in a green box). Written like [`write_png`].
pub fn write_removal_png(path: &Path, maps: &[(&str, &scenario::removal::Removal)]) -> Result<()> {
    crate::output::require_extension(path, &["png"], "a plot")?;
    if maps.is_empty() {
        return Err(anyhow!("no removal map to draw"));
    }
    crate::output::replace(path, |tmp| draw_removal_png(tmp, maps))
}

fn draw_removal_png(path: &Path, maps: &[(&str, &scenario::removal::Removal)]) -> Result<()> {
    fonts();
    check_writable(path)?;
    let e = |e: DrawingAreaErrorKind<_>| anyhow!("plot: {e}");
    let panel_w = 560u32;
    let bar_w = 110u32;
    let w = panel_w * maps.len() as u32 + bar_w;
    let root = BitMapBackend::new(path, (w, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    // One colour scale: up to 1.25 × the deepest cell within any target area (a fault's dwell outside it
    // would wash out the rest); deeper cells take the top colour. One extent: the union of the maps'.
    let in_target = |r: &scenario::removal::Removal| {
        let m = &r.map;
        let t = r.target;
        let mut deepest = 0.0_f64;
        for j in 0..m.ny {
            for i in 0..m.nx {
                let (x, y) = m.centre(i, j);
                if x >= t[0] && x <= t[1] && y >= t[2] && y <= t[3] {
                    deepest = deepest.max(m.depth_at(i, j));
                }
            }
        }
        deepest
    };
    let mut vmax = maps
        .iter()
        .map(|(_, r)| in_target(r))
        .fold(0.0_f64, f64::max);
    if vmax <= 0.0 {
        vmax = maps
            .iter()
            .flat_map(|(_, r)| r.map.depth.iter().copied())
            .fold(0.0_f64, f64::max);
    }
    // A quarter of headroom: the deepest cells of the target stay distinguishable.
    let vmax = (1.25 * vmax).max(1e-12);
    let mm = |v: f64| v * 1e3;
    let extent = maps.iter().fold(
        [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ],
        |e, (_, r)| {
            let m = &r.map;
            [
                e[0].min(mm(m.x0 - m.cell / 2.0)),
                e[1].max(mm(m.x0 + (m.nx as f64 - 0.5) * m.cell)),
                e[2].min(mm(m.y0 - m.cell / 2.0)),
                e[3].max(mm(m.y0 + (m.ny as f64 - 0.5) * m.cell)),
            ]
        },
    );
    let (panels, bar) = root.split_horizontally(panel_w * maps.len() as u32);
    for (area, (title, r)) in panels.split_evenly((1, maps.len())).iter().zip(maps) {
        let m = &r.map;
        let [x0, x1, y0, y1] = extent;
        let mut chart = ChartBuilder::on(area)
            .caption(*title, ("sans-serif", 18))
            .margin(10)
            .margin_bottom(30)
            .x_label_area_size(55)
            .y_label_area_size(55)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .label_style(("sans-serif", 13))
            .x_desc("x [mm]")
            .y_desc("y [mm]")
            .draw()
            .map_err(e)?;
        // Where this map has no cell nothing was removed.
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(x0, y0), (x1, y1)],
                heat(0.0).filled(),
            )))
            .map_err(e)?;
        let c = mm(m.cell);
        chart
            .draw_series((0..m.ny).flat_map(|j| {
                (0..m.nx).map(move |i| {
                    let (cx, cy) = m.centre(i, j);
                    let (cx, cy) = (mm(cx), mm(cy));
                    Rectangle::new(
                        [(cx - c / 2.0, cy - c / 2.0), (cx + c / 2.0, cy + c / 2.0)],
                        heat(m.depth_at(i, j) / vmax).filled(),
                    )
                })
            }))
            .map_err(e)?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                r.path
                    .iter()
                    .map(|(x, y)| (mm(*x), mm(*y)))
                    .collect::<Vec<_>>(),
                WHITE.stroke_width(1),
            )))
            .map_err(e)?;
        let t = r.target;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(mm(t[0]), mm(t[2])), (mm(t[1]), mm(t[3]))],
                GREEN_.stroke_width(2),
            )))
            .map_err(e)?;
        let s = &r.stats;
        area.draw(&Text::new(
            format!(
                "mean {:.3} µm · σ/mean {:.3} · under {:.0} % · over {:.0} %",
                s.mean * 1e6,
                s.uniformity(),
                r.under * 100.0,
                r.over * 100.0
            ),
            (60, 580),
            ("sans-serif", 14).into_font(),
        ))
        .map_err(e)?;
    }
    // The colour scale, µm.
    let vmax_um = vmax * 1e6;
    let mut scale = ChartBuilder::on(&bar)
        .caption("µm", ("sans-serif", 16))
        .margin(10)
        .margin_bottom(50)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..1.0, 0.0..vmax_um)
        .map_err(e)?;
    scale
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_label_style(("sans-serif", 14))
        .draw()
        .map_err(e)?;
    let n = 100;
    scale
        .draw_series((0..n).map(|k| {
            let a = vmax_um * k as f64 / n as f64;
            let b = vmax_um * (k + 1) as f64 / n as f64;
            Rectangle::new(
                [(0.0, a), (1.0, b)],
                heat((k as f64 + 0.5) / n as f64).filled(),
            )
        }))
        .map_err(e)?;
    root.present().map_err(e)?;
    Ok(())
}
