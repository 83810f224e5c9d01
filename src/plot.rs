//! PNG plots of a trace: force against set-point, positions, estimates. Pure Rust (plotters' bitmap
//! backend with an embedded DejaVu Sans font): no system font, no C library.

use std::path::Path;
use std::sync::Once;

use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use crate::record::Row;

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

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    rows: &[Row],
    caption: &str,
    y_label: &str,
    lines: &[Line],
) -> Result<()> {
    let t_end = rows.last().map_or(1.0, |r| r.t.max(1e-3));
    let (lo, hi) = range(rows, lines);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 20).into_font())
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..t_end, lo..hi)
        .map_err(|e| anyhow!("plot: {e}"))?;
    chart
        .configure_mesh()
        .x_desc("t [s]")
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
            .map(|r| (r.t, (l.value)(r)))
            .filter(|p| p.1.is_finite());
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

/// Write a three-panel PNG: force, positions (mm), stiffness estimate (kN/m).
pub fn write_png(path: &Path, title: &str, rows: &[Row]) -> Result<()> {
    fonts();
    // The backend reports an unwritable path as a nested Debug dump, only after drawing: find it first.
    std::fs::File::create(path).map_err(|e| {
        let t = e.to_string();
        let t = t.split(" (os error").next().unwrap_or_default();
        anyhow!("cannot write {}: {t}", path.display())
    })?;
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
                label: "f measured",
                color: GREY_,
                width: 1,
                value: |r| r.f,
            },
            Line {
                label: "f true",
                color: BLUE_,
                width: 2,
                value: |r| r.f_true,
            },
            Line {
                label: "f_r set-point",
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
                label: "x measured",
                color: BLUE_,
                width: 2,
                value: |r| r.x * 1e3,
            },
            Line {
                label: "x_cmd",
                color: ORANGE_,
                width: 1,
                value: |r| r.x_cmd * 1e3,
            },
            Line {
                label: "x_r reference",
                color: GREEN_,
                width: 1,
                value: |r| r.x_r * 1e3,
            },
            Line {
                label: "x_c surface (true)",
                color: BLACK,
                width: 1,
                value: |r| r.x_c * 1e3,
            },
            Line {
                label: "x̂_c estimate",
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
                label: "k_c true",
                color: BLACK,
                width: 1,
                value: |r| r.k_c * 1e-3,
            },
            Line {
                label: "k̂_c estimate",
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
