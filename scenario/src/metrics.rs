//! Metrics of a run, computed from the true contact force of the trace over a time window.
//!
//! Definitions (window `[from, until]`, band ±2 % of `f_r`):
//! * `first_contact` — first time the true force is above zero (whole run), s;
//! * `peak_force` — largest true force in the window, N;
//! * `overshoot_pct` — `(peak − f_r)/f_r·100`, at least 0, counted from first contact;
//! * `settle_time` — from the later of window start and first contact to the last exit from the band
//!   (infinite when the last sample is outside), s;
//! * `ss_error` — steady-state error `|mean(f − f_r)|` over the last 0.1 s of the window, N;
//! * `ss_ripple` — largest `|f − f_r|` over the same 0.1 s (what is left of a transient), N;
//! * `rms_error`, `max_error` — over the window from first contact on, N;
//! * `contact_losses` — drops of the true force to zero after first contact; `contact_loss_time` — the
//!   longest of them, s;
//! * `true_force_std` — standard deviation of the true force in the window, N;
//! * `force_std_detrended` — the same about the least-squares line through it, N: the fluctuation a
//!   controller causes, without the slow trend a drifting sensor bias imposes (unobservable in a steady
//!   contact);
//! * `kc_hat`, `xc_hat` — estimates at the window's end; `kc_rel_error` — `|k̂_c − k_c|/k_c` there.
//!
//! Of a pass the robot program commands (rows with a process phase, see docs/wire-rsi.md):
//! * `pressing_time` — time reported `PRESSING`, s;
//! * `pressing_in_band_pct` — share of that time with the force within ±5 % of the program's `F`, %;
//! * `press_overshoot_pct` — the largest overshoot of the force past the program's `F` while
//!   approaching, ramping or pressing, in % of `F`, in the direction of the change that led there
//!   (above `F` after an entry or a rise, below it after a fall);
//! * `release_excess` — largest force above `F` while releasing, N (≤ 0: no force above `F`);
//! * `final_correction` — `|x_cmd|` of the window's last row, m;
//! * `press_contact_losses` — drops of the force to zero while ramping or pressing.
//!
//! Of a pass on a curved part (rows with `tilt_error`, see docs/curved-parts.md; `f_true` is then
//! the force normal to the surface):
//! * `tilt_error_max` — largest angle between the tool axis and the surface normal, less the
//!   program's tilt, while `PRESSING`, rad (NaN without a curved part or without pressing);
//! * `tilt_error_settled` — the same from [`TILT_SETTLE`] after each entry into `PRESSING` on, rad;
//! * `max_rotation` — largest magnitude of the correction's rotation in the window, rad;
//! * `final_rotation` — its magnitude in the window's last row, rad;
//! * `max_correction` — largest `|x_cmd|` in the window, m.
//!
//! Per pass ([`pass_force_errors`]): a pass is a maximal stretch of rows reported `PRESSING`; its
//! mean force error is `mean(f − f_r)` over it, N (`f` the true force where the trace has it), signed:
//! a sensor bias that reads high makes it negative.

use crate::record::Row;

/// Names accepted by [`Metrics::get`] and by scenario targets.
pub const METRIC_NAMES: &[&str] = &[
    "first_contact",
    "peak_force",
    "overshoot_pct",
    "settle_time",
    "ss_error",
    "ss_ripple",
    "rms_error",
    "max_error",
    "contact_losses",
    "contact_loss_time",
    "true_force_std",
    "force_std_detrended",
    "kc_hat",
    "xc_hat",
    "kc_rel_error",
    "faults",
    "pressing_time",
    "pressing_in_band_pct",
    "press_overshoot_pct",
    "release_excess",
    "final_correction",
    "press_contact_losses",
    "tilt_error_max",
    "tilt_error_settled",
    "max_rotation",
    "final_rotation",
    "max_correction",
];

/// How long after entering `PRESSING` the tilt has to settle before `tilt_error_settled` counts, s.
pub const TILT_SETTLE: f64 = 0.3;

/// The process phase codes of a row (`FcState.State`).
mod phase {
    pub const APPROACH: u8 = 1;
    pub const RAMP: u8 = 2;
    pub const PRESSING: u8 = 3;
    pub const RELEASE: u8 = 4;
}

/// Metrics over one window `[from, until)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metrics {
    /// s, NaN when never in contact.
    pub first_contact: f64,
    /// N.
    pub peak_force: f64,
    /// %.
    pub overshoot_pct: f64,
    /// s (infinite: never settled).
    pub settle_time: f64,
    /// N.
    pub ss_error: f64,
    /// N.
    pub ss_ripple: f64,
    /// N.
    pub rms_error: f64,
    /// N.
    pub max_error: f64,
    /// Count.
    pub contact_losses: f64,
    /// s.
    pub contact_loss_time: f64,
    /// N.
    pub true_force_std: f64,
    /// N.
    pub force_std_detrended: f64,
    /// N/m.
    pub kc_hat: f64,
    /// m.
    pub xc_hat: f64,
    /// Relative.
    pub kc_rel_error: f64,
    /// Steps with a condition (`Row::condition` not 0: a sensor error, a non-finite input, a limited
    /// command); the metric keeps its name, scenario targets use it.
    pub faults: f64,
    /// s.
    pub pressing_time: f64,
    /// %.
    pub pressing_in_band_pct: f64,
    /// %.
    pub press_overshoot_pct: f64,
    /// N.
    pub release_excess: f64,
    /// m.
    pub final_correction: f64,
    /// Count.
    pub press_contact_losses: f64,
    /// rad.
    pub tilt_error_max: f64,
    /// rad.
    pub tilt_error_settled: f64,
    /// rad.
    pub max_rotation: f64,
    /// rad.
    pub final_rotation: f64,
    /// m.
    pub max_correction: f64,
}

impl Metrics {
    /// Compute over `[from, until]` (`until = ∞` for the end). Uses `f_true` when the trace has it,
    /// else the measured force.
    pub fn compute(rows: &[Row], from: f64, until: f64) -> Self {
        let force = |r: &Row| if r.f_true.is_finite() { r.f_true } else { r.f };
        let first_contact = rows
            .iter()
            .find(|r| force(r) > 0.0)
            .map_or(f64::NAN, |r| r.t);
        let win: Vec<&Row> = rows.iter().filter(|r| r.t >= from && r.t < until).collect();
        let mut m = Metrics {
            first_contact,
            peak_force: f64::NAN,
            overshoot_pct: f64::NAN,
            settle_time: f64::NAN,
            ss_error: f64::NAN,
            ss_ripple: f64::NAN,
            rms_error: f64::NAN,
            max_error: f64::NAN,
            contact_losses: 0.0,
            contact_loss_time: 0.0,
            true_force_std: f64::NAN,
            force_std_detrended: f64::NAN,
            kc_hat: f64::NAN,
            xc_hat: f64::NAN,
            kc_rel_error: f64::NAN,
            faults: win.iter().filter(|r| r.condition != 0).count() as f64,
            pressing_time: 0.0,
            pressing_in_band_pct: f64::NAN,
            press_overshoot_pct: f64::NAN,
            release_excess: f64::NAN,
            final_correction: f64::NAN,
            press_contact_losses: 0.0,
            tilt_error_max: f64::NAN,
            tilt_error_settled: f64::NAN,
            max_rotation: f64::NAN,
            final_rotation: f64::NAN,
            max_correction: f64::NAN,
        };
        let Some(last) = win.last() else {
            return m;
        };
        m.final_correction = last.x_cmd.abs();
        m.final_rotation = last.rotation;
        m.max_rotation = win.iter().map(|r| r.rotation).fold(f64::NAN, f64::max);
        m.max_correction = win.iter().map(|r| r.x_cmd.abs()).fold(f64::NAN, f64::max);
        m.tilt(&win);
        m.pass(&win, force);
        m.kc_hat = last.kc_hat;
        m.xc_hat = last.xc_hat;
        m.kc_rel_error = ((last.kc_hat - last.k_c) / last.k_c).abs();
        let n = win.len() as f64;
        let mean = win.iter().map(|r| force(r)).sum::<f64>() / n;
        m.true_force_std = (win.iter().map(|r| (force(r) - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mean_t = win.iter().map(|r| r.t).sum::<f64>() / n;
        let stt = win.iter().map(|r| (r.t - mean_t).powi(2)).sum::<f64>();
        let slope = if stt > 0.0 {
            win.iter()
                .map(|r| (r.t - mean_t) * (force(r) - mean))
                .sum::<f64>()
                / stt
        } else {
            0.0
        };
        m.force_std_detrended = (win
            .iter()
            .map(|r| (force(r) - mean - slope * (r.t - mean_t)).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        m.peak_force = win
            .iter()
            .map(|r| force(r))
            .fold(f64::NEG_INFINITY, f64::max);
        let f_r = last.f_r;
        let t_end = last.t;
        let tail: Vec<f64> = win
            .iter()
            .filter(|r| r.t > t_end - 0.1 + 1e-9)
            .map(|r| force(r) - r.f_r)
            .collect();
        m.ss_error = (tail.iter().sum::<f64>() / tail.len() as f64).abs();
        m.ss_ripple = tail.iter().map(|e| e.abs()).fold(0.0, f64::max);
        if first_contact.is_nan() {
            m.overshoot_pct = 0.0;
            m.settle_time = f64::INFINITY;
            return m;
        }
        let contact: Vec<&Row> = win
            .iter()
            .copied()
            .filter(|r| r.t >= first_contact)
            .collect();
        if contact.is_empty() {
            return m;
        }
        let t0 = contact[0].t;
        let peak = contact
            .iter()
            .map(|r| force(r))
            .fold(f64::NEG_INFINITY, f64::max);
        m.overshoot_pct = ((peak - f_r) / f_r * 100.0).max(0.0);
        let errs: Vec<f64> = contact.iter().map(|r| force(r) - r.f_r).collect();
        m.rms_error = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        m.max_error = errs.iter().map(|e| e.abs()).fold(0.0, f64::max);
        let band = 0.02 * f_r.abs();
        m.settle_time = match contact
            .iter()
            .rposition(|r| (force(r) - r.f_r).abs() > band)
        {
            None => 0.0,
            Some(i) if i + 1 == contact.len() => f64::INFINITY,
            Some(i) => contact[i + 1].t - t0,
        };
        let mut loss_start: Option<f64> = None;
        for r in &contact {
            let touching = force(r) > 0.0;
            match (touching, loss_start) {
                (false, None) => {
                    loss_start = Some(r.t);
                    m.contact_losses += 1.0;
                }
                (true, Some(s)) => {
                    m.contact_loss_time = m.contact_loss_time.max(r.t - s);
                    loss_start = None;
                }
                _ => {}
            }
        }
        if let Some(s) = loss_start {
            m.contact_loss_time = m.contact_loss_time.max(t_end - s);
        }
        m
    }

    /// The metrics of a commanded pass (see the module's list).
    fn pass(&mut self, win: &[&Row], force: impl Fn(&Row) -> f64) {
        let (mut pressing, mut in_band) = (0usize, 0usize);
        let (mut over, mut excess) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        // An episode: one commanded force while pressing; its overshoot is measured in the direction
        // of the change that began it (up from the last force, or from nothing at entry).
        let (mut episode_f, mut direction) = (f64::NAN, 1.0);
        let mut touching = true;
        let mut dt_sum = 0.0;
        for w in win.windows(2) {
            let (r, next) = (w[0], w[1]);
            let f = force(r);
            let phase = r.phase.unwrap_or(0);
            match phase {
                phase::PRESSING => {
                    pressing += 1;
                    dt_sum += next.t - r.t;
                    in_band += usize::from((f - r.f_cmd).abs() <= 0.05 * r.f_cmd);
                }
                phase::RELEASE => excess = excess.max(f - r.f_cmd),
                _ => {}
            }
            if matches!(phase, phase::APPROACH | phase::RAMP | phase::PRESSING) {
                if r.f_cmd != episode_f {
                    direction = if episode_f.is_nan() || r.f_cmd > episode_f {
                        1.0
                    } else {
                        -1.0
                    };
                    episode_f = r.f_cmd;
                }
                over = over.max(direction * (f - r.f_cmd) / r.f_cmd * 100.0);
            } else {
                episode_f = f64::NAN;
            }
            if matches!(phase, phase::RAMP | phase::PRESSING) {
                if touching && f <= 0.0 {
                    self.press_contact_losses += 1.0;
                }
                touching = f > 0.0;
            } else {
                touching = true;
            }
        }
        self.pressing_time = dt_sum;
        if pressing > 0 {
            self.pressing_in_band_pct = in_band as f64 / pressing as f64 * 100.0;
        }
        if over.is_finite() {
            self.press_overshoot_pct = over.max(0.0);
        }
        if excess.is_finite() {
            self.release_excess = excess;
        }
    }

    /// The tilt metrics of a pass on a curved part (see the module's list).
    fn tilt(&mut self, win: &[&Row]) {
        let (mut max, mut settled) = (f64::NAN, f64::NAN);
        let mut entered: Option<f64> = None;
        for r in win {
            if r.phase != Some(phase::PRESSING) {
                entered = None;
                continue;
            }
            let t0 = *entered.get_or_insert(r.t);
            if r.tilt_error.is_nan() {
                continue;
            }
            max = max.max(r.tilt_error);
            if r.t >= t0 + TILT_SETTLE {
                settled = settled.max(r.tilt_error);
            }
        }
        self.tilt_error_max = max;
        self.tilt_error_settled = settled;
    }

    /// A metric by name (see [`METRIC_NAMES`]).
    pub fn get(&self, name: &str) -> Option<f64> {
        Some(match name {
            "first_contact" => self.first_contact,
            "peak_force" => self.peak_force,
            "overshoot_pct" => self.overshoot_pct,
            "settle_time" => self.settle_time,
            "ss_error" => self.ss_error,
            "ss_ripple" => self.ss_ripple,
            "rms_error" => self.rms_error,
            "max_error" => self.max_error,
            "contact_losses" => self.contact_losses,
            "contact_loss_time" => self.contact_loss_time,
            "true_force_std" => self.true_force_std,
            "force_std_detrended" => self.force_std_detrended,
            "kc_hat" => self.kc_hat,
            "xc_hat" => self.xc_hat,
            "kc_rel_error" => self.kc_rel_error,
            "faults" => self.faults,
            "pressing_time" => self.pressing_time,
            "pressing_in_band_pct" => self.pressing_in_band_pct,
            "press_overshoot_pct" => self.press_overshoot_pct,
            "release_excess" => self.release_excess,
            "final_correction" => self.final_correction,
            "press_contact_losses" => self.press_contact_losses,
            "tilt_error_max" => self.tilt_error_max,
            "tilt_error_settled" => self.tilt_error_settled,
            "max_rotation" => self.max_rotation,
            "final_rotation" => self.final_rotation,
            "max_correction" => self.max_correction,
            _ => return None,
        })
    }
}

/// One pass of a trace: a maximal stretch of rows reported `PRESSING`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassError {
    /// Its first row's time, s.
    pub start: f64,
    /// Its last row's time, s.
    pub end: f64,
    /// `mean(f − f_r)` over it, N (the true force where the trace has it).
    pub mean_error: f64,
}

/// Every pass of `rows` with its mean force error, in order (see the module's definitions).
pub fn pass_force_errors(rows: &[Row]) -> Vec<PassError> {
    let force = |r: &Row| if r.f_true.is_finite() { r.f_true } else { r.f };
    let mut out = Vec::new();
    let mut run: Option<(f64, f64, f64, f64)> = None; // start, end, sum, n
    for r in rows {
        let e = force(r) - r.f_r;
        if r.phase == Some(phase::PRESSING) && e.is_finite() {
            let (start, _, sum, n) = run.unwrap_or((r.t, r.t, 0.0, 0.0));
            run = Some((start, r.t, sum + e, n + 1.0));
        } else if r.phase != Some(phase::PRESSING)
            && let Some((start, end, sum, n)) = run.take()
        {
            out.push(PassError {
                start,
                end,
                mean_error: sum / n,
            });
        }
    }
    if let Some((start, end, sum, n)) = run {
        out.push(PassError {
            start,
            end,
            mean_error: sum / n,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(forces: &[f64]) -> Vec<Row> {
        forces
            .iter()
            .enumerate()
            .map(|(k, &f)| Row {
                t: k as f64 * 0.01,
                f,
                f_true: f,
                f_r: 5.0,
                k_c: 70_000.0,
                kc_hat: 63_000.0,
                ..Row::default()
            })
            .collect()
    }

    #[test]
    fn settle_overshoot_losses() {
        let m = Metrics::compute(
            &trace(&[0.0, 0.0, 8.0, 4.0, 0.0, 0.0, 5.2, 5.01, 5.0, 5.0]),
            0.0,
            f64::INFINITY,
        );
        assert_eq!(m.first_contact, 0.02);
        assert_eq!(m.peak_force, 8.0);
        assert!((m.overshoot_pct - 60.0).abs() < 1e-9);
        // Last sample outside ±0.1 N is 5.2 at t = 0.06; settled from t = 0.07, 0.05 s after contact.
        assert!((m.settle_time - 0.05).abs() < 1e-9, "{}", m.settle_time);
        assert_eq!(m.contact_losses, 1.0);
        assert!((m.contact_loss_time - 0.02).abs() < 1e-9);
        assert!((m.kc_rel_error - 0.1).abs() < 1e-9);
        // From t = 0.07 the window holds 5.01, 5.0, 5.0.
        let tail = Metrics::compute(
            &trace(&[0.0, 0.0, 8.0, 4.0, 0.0, 0.0, 5.2, 5.01, 5.0, 5.0]),
            0.07,
            f64::INFINITY,
        );
        assert!(
            (tail.ss_error - 0.01 / 3.0).abs() < 1e-9,
            "{}",
            tail.ss_error
        );
        assert!((tail.ss_ripple - 0.01).abs() < 1e-9);
    }

    #[test]
    fn unsettled_and_no_contact() {
        let m = Metrics::compute(&trace(&[0.0, 6.0, 4.0, 6.0]), 0.0, f64::INFINITY);
        assert!(m.settle_time.is_infinite());
        let m = Metrics::compute(&trace(&[0.0, 0.0]), 0.0, f64::INFINITY);
        assert!(m.first_contact.is_nan());
        assert!(m.settle_time.is_infinite());
    }

    #[test]
    fn detrended_std_removes_a_drift_and_keeps_the_ripple() {
        let ramp: Vec<f64> = (0..100).map(|k| 5.0 - 0.01 * k as f64).collect();
        let m = Metrics::compute(&trace(&ramp), 0.0, f64::INFINITY);
        assert!(m.true_force_std > 0.2, "{}", m.true_force_std);
        assert!(m.force_std_detrended < 1e-9, "{}", m.force_std_detrended);
        let ripple: Vec<f64> = (0..100)
            .map(|k| 5.0 - 0.01 * k as f64 + if k % 2 == 0 { 0.1 } else { -0.1 })
            .collect();
        let m = Metrics::compute(&trace(&ripple), 0.0, f64::INFINITY);
        assert!(
            (m.force_std_detrended - 0.1).abs() < 0.01,
            "{}",
            m.force_std_detrended
        );
    }

    #[test]
    fn passes_are_the_pressing_stretches_with_their_mean_error() {
        let row = |t: f64, f: f64, phase: u8| Row {
            t,
            f,
            f_r: 10.0,
            phase: Some(phase),
            ..Row::unknown()
        };
        let rows = vec![
            row(0.0, 0.0, 1),
            row(0.1, 9.0, 3),
            row(0.2, 11.0, 3),
            row(0.3, 8.0, 3),
            row(0.4, 2.0, 4),
            row(0.5, 0.0, 0),
            row(0.6, 12.0, 3),
        ];
        let p = pass_force_errors(&rows);
        assert_eq!(p.len(), 2, "{p:?}");
        assert_eq!((p[0].start, p[0].end), (0.1, 0.3));
        assert!((p[0].mean_error - (-2.0 / 3.0)).abs() < 1e-12);
        assert!((p[1].mean_error - 2.0).abs() < 1e-12);
        assert!(pass_force_errors(&rows[..1]).is_empty());
    }

    #[test]
    fn every_name_resolves() {
        let m = Metrics::compute(&trace(&[1.0]), 0.0, 1.0);
        for n in METRIC_NAMES {
            assert!(m.get(n).is_some(), "{n}");
        }
        assert!(m.get("nope").is_none());
    }

    #[test]
    fn tilt_metrics_count_pressing_and_settle_after_entry() {
        let rows: Vec<Row> = (0..100)
            .map(|k| {
                let t = k as f64 * 0.01;
                Row {
                    t,
                    phase: Some(if (10..90).contains(&k) { 3 } else { 4 }),
                    // 2° at entry, decaying to 0.5° after 0.2 s; 3° while releasing.
                    tilt_error: if (10..90).contains(&k) {
                        if k < 30 { 0.035 } else { 0.009 }
                    } else {
                        0.05
                    },
                    rotation: if k == 99 { 0.0 } else { 0.02 },
                    x_cmd: -0.001 * (k % 3) as f64,
                    ..Row::default()
                }
            })
            .collect();
        let m = Metrics::compute(&rows, 0.0, f64::INFINITY);
        assert_eq!(m.tilt_error_max, 0.035);
        assert_eq!(m.tilt_error_settled, 0.009);
        assert_eq!((m.max_rotation, m.final_rotation), (0.02, 0.0));
        assert_eq!(m.max_correction, 0.002);
    }
}
