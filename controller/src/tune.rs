//! Tuning aids: analyse impedance parameters against a stiffness range and the robot's loop (damping
//! ratio, crossover, phase and delay margins), propose safe ones, and say plainly when given parameters are
//! unsafe. Also states the robust law's stability condition for a tuning.
//!
//! # Model
//! Position-based impedance in contact with a spring `k_c`, the robot's inner loop a first-order lag `τ`
//! plus a pure delay: the open loop from force error to force is
//! `L(s) = k_c·e^{−s·T_e}/((τs + 1)·(m_d s² + b_d s + k_d))`, with the effective delay
//! `T_e = T_d + 1.5·T` (the delay, one period until a command acts, half a period of hold).
//! Without lag and delay the closed loop is `m_d s² + b_d s + (k_d + k_c)`: damping ratio
//! `ζ = b_d/(2·√(m_d·(k_d + k_c)))`, worst at the stiffest surface. The crossovers of `|L(jω)| = 1` up to
//! the Nyquist frequency give the phase margin; the delay margin is the extra delay it absorbs,
//! `PM/ω_c`.

use core::f64::consts::PI;
use core::fmt;

use crate::law::ImpedanceParams;
use crate::robust::RobustParams;

/// The robot's inner loop as the tuning sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopModel {
    /// Control period, s.
    pub period: f64,
    /// First-order lag of the position loop, s.
    pub lag: f64,
    /// Pure delay, s.
    pub delay: f64,
}

impl LoopModel {
    /// Effective delay `T_d + 1.5·T`, s.
    pub fn effective_delay(&self) -> f64 {
        self.delay + 1.5 * self.period
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.period.is_finite() && (MIN_PERIOD..=MAX_PERIOD).contains(&self.period)) {
            return Err(format!(
                "period must be in [{MIN_PERIOD}, {MAX_PERIOD}] s (robot position loops run at 1 Hz to 10 kHz), got {}",
                self.period
            ));
        }
        for (n, v) in [("lag", self.lag), ("delay", self.delay)] {
            if !(v.is_finite() && (0.0..=MAX_LAG).contains(&v)) {
                return Err(format!(
                    "{n} must be in [0, {MAX_LAG}] s (a robot loop answering seconds late cannot be force-controlled), got {v}"
                ));
            }
        }
        Ok(())
    }
}

/// The shortest control period analysed, s (10 kHz: faster than any robot's position interface).
pub const MIN_PERIOD: f64 = 1e-4;
/// The longest control period analysed, s (1 Hz: slower than any force loop can hold contact).
pub const MAX_PERIOD: f64 = 1.0;
/// The longest lag or delay analysed, s.
pub const MAX_LAG: f64 = 1.0;

/// Required margins: what "safe" means here.
pub const MIN_DAMPING: f64 = 0.7;
/// The delay margin must be at least this multiple of the loop's effective delay.
pub const MIN_DELAY_MARGIN_FACTOR: f64 = 2.0;

/// The impedance loop at one stiffness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactAnalysis {
    /// Stiffness, N/m.
    pub k_c: f64,
    /// Damping ratio of the ideal closed loop.
    pub zeta: f64,
    /// Natural frequency of the ideal closed loop, rad/s.
    pub omega_n: f64,
    /// Crossover with the smallest phase margin, rad/s (NaN: |L| < 1 everywhere).
    pub crossover: f64,
    /// Smallest phase margin, degrees (∞ without a crossover).
    pub phase_margin: f64,
    /// Extra delay the loop absorbs before it goes unstable, s (∞ without a crossover; ≤ 0: unstable).
    pub delay_margin: f64,
    /// Settling time (2 %) of the ideal closed loop (no lag, no delay), s: a lower bound.
    pub settle: f64,
}

/// The verdict on impedance parameters over a stiffness range.
#[derive(Clone, Debug, PartialEq)]
pub struct ImpedanceReport {
    /// The parameters judged.
    pub params: ImpedanceParams,
    /// The loop.
    pub model: LoopModel,
    /// Analyses across the range, softest first.
    pub contacts: Vec<ContactAnalysis>,
    /// Why the parameters are unsafe; empty when they are safe.
    pub problems: Vec<String>,
}

impl ImpedanceReport {
    /// True when every stiffness in the range has `ζ ≥ 0.7` and a delay margin of at least twice the
    /// loop's effective delay.
    pub fn is_safe(&self) -> bool {
        self.problems.is_empty()
    }
}

fn open_loop(p: &ImpedanceParams, m: &LoopModel, k_c: f64, w: f64) -> (f64, f64) {
    let re = p.k_d - p.m_d * w * w;
    let im = p.b_d * w;
    let mag = k_c / ((re * re + im * im).sqrt() * (1.0 + (w * m.lag).powi(2)).sqrt());
    let phase = -w * m.effective_delay() - (w * m.lag).atan() - im.atan2(re);
    (mag, phase)
}

/// Analyse impedance parameters at one stiffness.
pub fn analyse_contact(p: &ImpedanceParams, m: &LoopModel, k_c: f64) -> ContactAnalysis {
    let k = p.k_d + k_c;
    let omega_n = (k / p.m_d).sqrt();
    let zeta = p.b_d / (2.0 * (p.m_d * k).sqrt());
    let slowest = if zeta < 1.0 {
        zeta * omega_n
    } else {
        omega_n * (zeta - (zeta * zeta - 1.0).sqrt())
    };
    let settle = 4.0 / slowest;
    // Scan log-spaced frequencies up to Nyquist for crossings of |L| = 1.
    let w_max = PI / m.period;
    let n = 4000;
    let w_min: f64 = 1e-2;
    let ratio = (w_max / w_min).powf(1.0 / n as f64);
    let mut worst = (f64::NAN, f64::INFINITY, f64::INFINITY);
    let mut w = w_min;
    let (mut prev_mag, _) = open_loop(p, m, k_c, w);
    for _ in 0..n {
        let w_next = w * ratio;
        let (mag, _) = open_loop(p, m, k_c, w_next);
        if (prev_mag - 1.0) * (mag - 1.0) <= 0.0 && prev_mag != mag {
            // Refine by bisection on log ω.
            let (mut lo, mut hi) = (w, w_next);
            for _ in 0..60 {
                let mid = (lo * hi).sqrt();
                let (mm, _) = open_loop(p, m, k_c, mid);
                if (open_loop(p, m, k_c, lo).0 - 1.0) * (mm - 1.0) <= 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            let wc = (lo * hi).sqrt();
            let (_, ph) = open_loop(p, m, k_c, wc);
            // Phase margin: distance of the phase from −180°, wrapped to (−180°, 180°].
            // (One remainder, not a loop: a phase of 1e8 rad wraps at once.)
            let mut pm = (ph + PI).rem_euclid(2.0 * PI);
            if pm > PI {
                pm -= 2.0 * PI;
            }
            let dm = pm / wc;
            if dm < worst.2 {
                worst = (wc, pm.to_degrees(), dm);
            }
        }
        prev_mag = mag;
        w = w_next;
    }
    ContactAnalysis {
        k_c,
        zeta,
        omega_n,
        crossover: worst.0,
        phase_margin: worst.1,
        delay_margin: worst.2,
        settle,
    }
}

fn stiffness_grid(k_min: f64, k_max: f64) -> Vec<f64> {
    let n = 7;
    let mut v: Vec<f64> = (0..n)
        .map(|i| k_min * (k_max / k_min).powf(i as f64 / (n - 1) as f64))
        .collect();
    v.dedup();
    v
}

/// Judge impedance parameters over the stiffness range `[k_min, k_max]` (N/m) on loop `m`.
pub fn analyse_impedance(
    p: &ImpedanceParams,
    m: &LoopModel,
    k_min: f64,
    k_max: f64,
) -> Result<ImpedanceReport, String> {
    p.validate()?;
    m.validate()?;
    check_range(k_min, k_max)?;
    let contacts: Vec<ContactAnalysis> = stiffness_grid(k_min, k_max)
        .into_iter()
        .map(|k| analyse_contact(p, m, k))
        .collect();
    let mut problems = Vec::new();
    let need = MIN_DELAY_MARGIN_FACTOR * m.effective_delay();
    for c in &contacts {
        if c.zeta < MIN_DAMPING {
            problems.push(format!(
                "damping ratio {:.3} at k_c = {:.0} N/m is below {MIN_DAMPING}: it rings at {:.1} Hz",
                c.zeta,
                c.k_c,
                c.omega_n / (2.0 * PI)
            ));
        }
        if c.delay_margin <= 0.0 {
            problems.push(format!(
                "UNSTABLE at k_c = {:.0} N/m: phase margin {:.1}° at {:.1} Hz with {:.1} ms of effective delay",
                c.k_c,
                c.phase_margin,
                c.crossover / (2.0 * PI),
                m.effective_delay() * 1e3
            ));
        } else if c.delay_margin < need {
            problems.push(format!(
                "delay margin {:.1} ms at k_c = {:.0} N/m is below {MIN_DELAY_MARGIN_FACTOR}× the effective delay ({:.1} ms)",
                c.delay_margin * 1e3,
                c.k_c,
                need * 1e3
            ));
        }
    }
    Ok(ImpedanceReport {
        params: *p,
        model: *m,
        contacts,
        problems,
    })
}

fn check_range(k_min: f64, k_max: f64) -> Result<(), String> {
    if !(k_min.is_finite() && k_min > 0.0 && k_max.is_finite() && k_max >= k_min) {
        return Err(format!(
            "the stiffness range must satisfy 0 < k_min <= k_max, got [{k_min}, {k_max}] N/m"
        ));
    }
    Ok(())
}

/// Propose impedance parameters for set-point `f_r` (N), stiffness range `[k_min, k_max]` (N/m) and loop
/// `m`: the fastest (shortest settling at `k_min`) among a grid of target masses and dampings that is
/// safe over the whole range, keeping the paper's ratio of `k_d` to the range's geometric mean. `Err` when
/// nothing on the grid is safe (the delay is too long for the range).
pub fn propose_impedance(
    f_r: f64,
    m: &LoopModel,
    k_min: f64,
    k_max: f64,
) -> Result<ImpedanceReport, String> {
    m.validate()?;
    check_range(k_min, k_max)?;
    // Table I pairs k_d 50 kN/m with k_c 70 kN/m.
    let k_d = (k_min * k_max).sqrt() * 50.0 / 70.0;
    let mut best: Option<(f64, ImpedanceReport)> = None;
    for i in 0..60 {
        let m_d = 0.1 * 10f64.powf(i as f64 / 12.0); // 0.1 kg … 10 t
        for zeta in [0.7, 0.8, 1.0, 1.3, 1.7, 2.2, 3.0, 4.0] {
            let b_d = 2.0 * zeta * (m_d * (k_d + k_max)).sqrt();
            let p = ImpedanceParams { f_r, m_d, b_d, k_d };
            let r = analyse_impedance(&p, m, k_min, k_max)?;
            if !r.is_safe() {
                continue;
            }
            let slowest = r.contacts.iter().map(|c| c.settle).fold(0.0, f64::max);
            if best.as_ref().is_none_or(|(s, _)| slowest < *s) {
                best = Some((slowest, r));
            }
        }
    }
    best.map(|(_, r)| r).ok_or_else(|| {
        format!(
            "no impedance on the grid is safe for k_c in [{k_min:.0}, {k_max:.0}] N/m with {:.1} ms of effective delay",
            m.effective_delay() * 1e3
        )
    })
}

/// What the robust law's structure guarantees for a tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobustReport {
    /// The loop gain `κ·k_c/k̂_c` at the softest surface with the initial estimate.
    pub gain_min: f64,
    /// The same at the stiffest surface.
    pub gain_max: f64,
    /// Stiffness up to which the law is stable for any delay before the estimator has learnt
    /// anything (`2·k̂_c(0)/κ`), N/m.
    pub delay_independent_up_to: f64,
    /// The stiffest surface considered, N/m.
    pub k_max: f64,
}

/// The robust law's stability condition for a tuning over `[k_min, k_max]`: with `g = κ·k_c/k̂_c` the
/// loop is stable for **any** delay and lag while `0 < g < 2` (see `controller::robust`).
pub fn analyse_robust(p: &RobustParams, k_min: f64, k_max: f64) -> Result<RobustReport, String> {
    p.validate()?;
    check_range(k_min, k_max)?;
    let k0 = p.estimator.kc0;
    Ok(RobustReport {
        gain_min: p.response.kappa * k_min / k0,
        gain_max: p.response.kappa * k_max / k0,
        delay_independent_up_to: 2.0 * k0 / p.response.kappa,
        k_max,
    })
}

impl fmt::Display for ImpedanceReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = &self.params;
        writeln!(
            f,
            "impedance m_d {:.3} kg, b_d {:.1} N·s/m, k_d {:.0} N/m on a loop of {:.1} ms period, {:.1} ms lag, {:.1} ms delay (effective {:.1} ms)",
            p.m_d,
            p.b_d,
            p.k_d,
            self.model.period * 1e3,
            self.model.lag * 1e3,
            self.model.delay * 1e3,
            self.model.effective_delay() * 1e3
        )?;
        writeln!(
            f,
            "  {:>10}  {:>7}  {:>9}  {:>12}  {:>12}  {:>15}  {:>14}",
            "k_c N/m",
            "ζ",
            "f_n Hz",
            "crossover Hz",
            "phase margin",
            "delay margin ms",
            "ideal settle s"
        )?;
        for c in &self.contacts {
            writeln!(
                f,
                "  {:>10.0}  {:>7.3}  {:>9.2}  {:>12.2}  {:>11.1}°  {:>15.2}  {:>14.3}",
                c.k_c,
                c.zeta,
                c.omega_n / (2.0 * PI),
                c.crossover / (2.0 * PI),
                c.phase_margin,
                c.delay_margin * 1e3,
                c.settle
            )?;
        }
        if self.is_safe() {
            write!(
                f,
                "SAFE: ζ ≥ {MIN_DAMPING} and delay margin ≥ {MIN_DELAY_MARGIN_FACTOR}× the effective delay over the whole range"
            )
        } else {
            writeln!(f, "UNSAFE:")?;
            for (i, pr) in self.problems.iter().enumerate() {
                if i > 0 {
                    writeln!(f)?;
                }
                write!(f, "  - {pr}")?;
            }
            Ok(())
        }
    }
}

impl fmt::Display for RobustReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "robust law: loop gain κ·k_c/k̂_c(0) from {:.2} to {:.2}; stable for any delay and lag while it stays below 2",
            self.gain_min, self.gain_max
        )?;
        if self.k_max < self.delay_independent_up_to {
            write!(
                f,
                "  the whole range is covered before the estimator has learnt anything (up to {:.0} N/m)",
                self.delay_independent_up_to
            )
        } else {
            write!(
                f,
                "  up to {:.0} N/m without the estimator; stiffer surfaces rely on it learning k_c at first contact",
                self.delay_independent_up_to
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P1: LoopModel = LoopModel {
        period: 0.001,
        lag: 0.010,
        delay: 0.004,
    };
    const P2: LoopModel = LoopModel {
        period: 0.004,
        lag: 0.010,
        delay: 0.012,
    };

    #[test]
    fn the_papers_tuning_is_reported_unsafe_with_its_damping() {
        let r = analyse_impedance(&ImpedanceParams::PAPER, &P2, 70_000.0, 70_000.0).unwrap();
        assert!(!r.is_safe());
        let c = r.contacts[0];
        // ζ = 80/(2·√(8·120 000)) ≈ 0.041.
        assert!((c.zeta - 0.0408).abs() < 1e-3, "ζ {}", c.zeta);
        let text = r.to_string();
        assert!(
            text.contains("UNSAFE") && text.contains("damping ratio 0.041"),
            "{text}"
        );
        assert!(
            r.problems.iter().any(|p| p.contains("UNSTABLE")),
            "with 18 ms of effective delay the paper's loop has no phase margin: {text}"
        );
    }

    #[test]
    fn a_proposal_is_safe_and_says_so() {
        for m in [P1, P2] {
            let r = propose_impedance(5.0, &m, 10_000.0, 500_000.0).unwrap();
            assert!(r.is_safe(), "{r}");
            assert!(r.contacts.iter().all(|c| c.zeta >= MIN_DAMPING));
            assert!(
                r.contacts
                    .iter()
                    .all(|c| c.delay_margin >= 2.0 * m.effective_delay())
            );
            assert!(r.to_string().contains("SAFE"));
        }
    }

    #[test]
    fn delay_margin_matches_a_pure_integrator() {
        // m_d → 0, k_d → 0: L = k_c e^{-sT}/(b s); crossover k_c/b, phase margin 90° − ω_c·T.
        let p = ImpedanceParams {
            f_r: 5.0,
            m_d: 1e-9,
            b_d: 7000.0,
            k_d: 1e-9,
        };
        let m = LoopModel {
            period: 1e-4,
            lag: 0.0,
            delay: 0.01,
        };
        let c = analyse_contact(&p, &m, 70_000.0);
        assert!((c.crossover - 10.0).abs() < 0.01, "{}", c.crossover);
        let t = m.effective_delay();
        let expect = (PI / 2.0 - 10.0 * t) / 10.0;
        assert!(
            (c.delay_margin - expect).abs() < 1e-4,
            "{} vs {expect}",
            c.delay_margin
        );
    }

    #[test]
    fn bad_ranges_are_refused() {
        assert!(propose_impedance(5.0, &P1, 0.0, 1.0).is_err());
        assert!(analyse_impedance(&ImpedanceParams::PAPER, &P1, 2.0, 1.0).is_err());
    }
}
