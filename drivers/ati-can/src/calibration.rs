//! From raw gauge counts to SI: the one place where device units are converted.
//!
//! `wrench = diag(u_F/CpF ×3, u_T/CpT ×3) · C · (sg − bias)` where `C` is the board's 6×6 calibration
//! matrix, `CpF`/`CpT` its counts per force/torque unit and `u_F`, `u_T` the SI value of one unit.

use core::fmt;

use hal::{Vector3, Wrench};
use nalgebra::{Matrix6, Vector6};

use crate::codec::Gauges;

/// Counts per unit assumed when firmware older than 3.7 cannot report them.
pub const LEGACY_COUNTS_PER_UNIT: u32 = 1_000_000;

/// Force unit codes of the units answer (0x8).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ForceUnit {
    /// 1: pound-force.
    Lbf,
    /// 2: newton.
    N,
    /// 3: kilo-pound-force.
    Klbf,
    /// 4: kilonewton.
    KN,
    /// 5: kilogram-force.
    Kgf,
    /// 6: gram-force.
    Gf,
}

/// Torque unit codes of the units answer (0x8).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TorqueUnit {
    /// 1: pound-force inch.
    LbfIn,
    /// 2: pound-force foot.
    LbfFt,
    /// 3: newton metre.
    Nm,
    /// 4: newton millimetre.
    Nmm,
    /// 5: kilogram-force centimetre.
    KgfCm,
    /// 6: kilonewton metre.
    KNm,
}

const LBF: f64 = 4.448_221_615_260_5;
const KGF: f64 = 9.806_65;

impl ForceUnit {
    /// From the wire code 1..=6.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => Self::Lbf,
            2 => Self::N,
            3 => Self::Klbf,
            4 => Self::KN,
            5 => Self::Kgf,
            6 => Self::Gf,
            _ => return None,
        })
    }

    /// The wire code.
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    /// Newtons per unit.
    pub fn newtons(self) -> f64 {
        match self {
            Self::Lbf => LBF,
            Self::N => 1.0,
            Self::Klbf => 1000.0 * LBF,
            Self::KN => 1000.0,
            Self::Kgf => KGF,
            Self::Gf => KGF / 1000.0,
        }
    }
}

impl TorqueUnit {
    /// From the wire code 1..=6.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => Self::LbfIn,
            2 => Self::LbfFt,
            3 => Self::Nm,
            4 => Self::Nmm,
            5 => Self::KgfCm,
            6 => Self::KNm,
            _ => return None,
        })
    }

    /// The wire code.
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    /// Newton-metres per unit.
    pub fn newton_metres(self) -> f64 {
        match self {
            Self::LbfIn => LBF * 0.0254,
            Self::LbfFt => LBF * 0.3048,
            Self::Nm => 1.0,
            Self::Nmm => 0.001,
            Self::KgfCm => KGF * 0.01,
            Self::KNm => 1000.0,
        }
    }
}

/// What the board holds in one calibration slot, as read at start-up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Rows Fx Fy Fz Tx Ty Tz, columns gauges sg0..sg5.
    pub matrix: [[f32; 6]; 6],
    /// Counts per force unit.
    pub counts_per_force: u32,
    /// Counts per torque unit.
    pub counts_per_torque: u32,
    /// Force unit.
    pub force_unit: ForceUnit,
    /// Torque unit.
    pub torque_unit: TorqueUnit,
}

/// Why a calibration cannot be used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CalibrationError {
    /// Counts per unit of zero or above [`MAX_COUNTS_PER_UNIT`] (a byte-swapped 1 000 000 reads
    /// 1 078 071 040).
    Counts {
        /// Counts per force unit.
        per_force: u32,
        /// Counts per torque unit.
        per_torque: u32,
    },
    /// A matrix coefficient that is not finite, subnormal or implausibly large (|c| > 1e9): a corrupted
    /// or byte-swapped matrix.
    Coefficient {
        /// Row 0..=5.
        row: usize,
        /// Column 0..=5.
        col: usize,
        /// The value.
        value: f32,
    },
    /// The matrix is singular, so no wrench could be simulated through it (simulated node only).
    Singular,
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Counts {
                per_force,
                per_torque,
            } => write!(
                f,
                "counts per unit {per_force} (force), {per_torque} (torque) outside 1..={MAX_COUNTS_PER_UNIT} (corrupted or byte-swapped?)"
            ),
            Self::Coefficient { row, col, value } => write!(
                f,
                "calibration matrix coefficient [{row}][{col}] = {value:e} is not plausible (corrupted or byte-swapped?)"
            ),
            Self::Singular => f.write_str("calibration matrix is singular"),
        }
    }
}

impl std::error::Error for CalibrationError {}

/// Largest plausible counts per unit (ATI boards report 1 000 000 or thereabouts).
pub const MAX_COUNTS_PER_UNIT: u32 = 100_000_000;

/// Largest plausible calibration coefficient magnitude.
const MAX_COEFFICIENT: f32 = 1e9;

/// True for a coefficient a real calibration can hold: zero or a normal number with |c| ≤ 1e9. A
/// byte-swapped small float is subnormal, a corrupted one often NaN or huge.
pub fn plausible_coefficient(c: f32) -> bool {
    (c == 0.0 || c.is_normal()) && c.abs() <= MAX_COEFFICIENT
}

/// True for counts per unit a board can report: 1..=[`MAX_COUNTS_PER_UNIT`].
pub fn plausible_counts(c: u32) -> bool {
    (1..=MAX_COUNTS_PER_UNIT).contains(&c)
}

/// A checked calibration: counts to SI in one matrix product.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Converter {
    /// SI per count: row `i` gives component `i` (N or N·m) from the six gauges.
    si_per_count: [[f64; 6]; 6],
    /// Its inverse (`None`: singular), computed once: a simulated sensor converts every sample back.
    count_per_si: Option<Matrix6<f64>>,
}

impl Calibration {
    /// Check the values and build the converter.
    pub fn converter(&self) -> Result<Converter, CalibrationError> {
        if !(plausible_counts(self.counts_per_force) && plausible_counts(self.counts_per_torque)) {
            return Err(CalibrationError::Counts {
                per_force: self.counts_per_force,
                per_torque: self.counts_per_torque,
            });
        }
        let f_scale = self.force_unit.newtons() / f64::from(self.counts_per_force);
        let t_scale = self.torque_unit.newton_metres() / f64::from(self.counts_per_torque);
        let mut m = [[0.0; 6]; 6];
        for (row, (out, coeffs)) in m.iter_mut().zip(&self.matrix).enumerate() {
            let scale = if row < 3 { f_scale } else { t_scale };
            for (col, (o, &c)) in out.iter_mut().zip(coeffs).enumerate() {
                if !plausible_coefficient(c) {
                    return Err(CalibrationError::Coefficient { row, col, value: c });
                }
                *o = f64::from(c) * scale;
            }
        }
        let count_per_si = Matrix6::from_fn(|r, c| m[r][c]).try_inverse();
        Ok(Converter {
            si_per_count: m,
            count_per_si,
        })
    }
}

impl Converter {
    /// The wrench (N, N·m, sensor frame) of raw gauges minus a bias in counts.
    pub fn wrench(&self, gauges: &Gauges, bias: &[f64; 6]) -> Wrench {
        let mut d = [0.0; 6];
        for (d, (&g, &b)) in d.iter_mut().zip(gauges.0.iter().zip(bias)) {
            *d = f64::from(g) - b;
        }
        let mut w = [0.0; 6];
        for (w, row) in w.iter_mut().zip(&self.si_per_count) {
            *w = row.iter().zip(&d).map(|(m, d)| m * d).sum();
        }
        Wrench {
            force: Vector3::new(w[0], w[1], w[2]),
            torque: Vector3::new(w[3], w[4], w[5]),
        }
    }

    /// The exact (unrounded) gauge counts that read as `wrench` with no bias: the inverse conversion,
    /// for simulated sensors. Fails on a singular matrix.
    pub fn counts_for(&self, wrench: &Wrench) -> Result<[f64; 6], CalibrationError> {
        let inv = self.count_per_si.ok_or(CalibrationError::Singular)?;
        let g = inv * Vector6::from_column_slice(&wrench.to_array());
        Ok([g[0], g[1], g[2], g[3], g[4], g[5]])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diag(c: f32) -> [[f32; 6]; 6] {
        let mut m = [[0.0; 6]; 6];
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = c;
        }
        m
    }

    #[test]
    fn converts_with_counts_per_unit_and_units() {
        let mut cal = Calibration {
            matrix: diag(1000.0),
            counts_per_force: 1_000_000,
            counts_per_torque: 2_000_000,
            force_unit: ForceUnit::N,
            torque_unit: TorqueUnit::Nmm,
        };
        cal.matrix[0][1] = 500.0;
        let conv = cal.converter().unwrap();
        let w = conv.wrench(&Gauges([100, 200, 0, 0, 0, 4000]), &[0.0; 6]);
        // Fx = (1000·100 + 500·200) / 1e6 N
        assert!((w.force.x - 0.2).abs() < 1e-12);
        assert!((w.force.y - 0.2).abs() < 1e-12);
        // Tz = 1000·4000 / 2e6 N·mm = 2 N·mm = 0.002 N·m
        assert!((w.torque.z - 0.002).abs() < 1e-12);
        // Bias comes off the raw counts.
        let biased = conv.wrench(
            &Gauges([100, 200, 0, 0, 0, 4000]),
            &[100.0, 200.0, 0.0, 0.0, 0.0, 0.0],
        );
        assert!(biased.force.x.abs() < 1e-12 && biased.force.y.abs() < 1e-12);
    }

    #[test]
    fn inverse_round_trips() {
        let mut m = diag(2000.0);
        m[2][0] = -300.0;
        m[4][5] = 150.5;
        let cal = Calibration {
            matrix: m,
            counts_per_force: 1_000_000,
            counts_per_torque: 1_000_000,
            force_unit: ForceUnit::Lbf,
            torque_unit: TorqueUnit::LbfIn,
        };
        let conv = cal.converter().unwrap();
        let w = Wrench::from_array([1.0, -2.0, 30.0, 0.1, -0.2, 0.3]);
        let g = conv.counts_for(&w).unwrap();
        let mut back = [0.0; 6];
        // Through the forward path with a fractional bias that cancels the rounding.
        let rounded = Gauges(g.map(|v| v.round() as i16));
        for i in 0..6 {
            back[i] = f64::from(rounded.0[i]) - g[i];
        }
        let again = conv.wrench(&rounded, &back);
        for (a, b) in again.to_array().iter().zip(w.to_array()) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }

    #[test]
    fn implausible_calibrations_are_refused() {
        let mut cal = Calibration {
            matrix: diag(1.0),
            counts_per_force: 0,
            counts_per_torque: 1,
            force_unit: ForceUnit::N,
            torque_unit: TorqueUnit::Nm,
        };
        assert!(matches!(
            cal.converter(),
            Err(CalibrationError::Counts { .. })
        ));
        cal.counts_per_force = 1_000_000u32.swap_bytes();
        assert!(matches!(
            cal.converter(),
            Err(CalibrationError::Counts { .. })
        ));
        cal.counts_per_force = 1;
        cal.matrix[3][4] = f32::NAN;
        assert!(matches!(
            cal.converter(),
            Err(CalibrationError::Coefficient { row: 3, col: 4, .. })
        ));
        // 1.5 with its bytes swapped is a subnormal number.
        cal.matrix[3][4] = f32::from_bits(1.5f32.to_bits().swap_bytes());
        assert!(cal.converter().is_err());
        cal.matrix[3][4] = 2e9;
        assert!(cal.converter().is_err());
        cal.matrix = [[0.0; 6]; 6];
        let conv = cal.converter().unwrap();
        assert_eq!(
            conv.counts_for(&Wrench::default()),
            Err(CalibrationError::Singular)
        );
    }

    #[test]
    fn unit_codes() {
        for code in 1..=6 {
            assert_eq!(ForceUnit::from_code(code).unwrap().code(), code);
            assert_eq!(TorqueUnit::from_code(code).unwrap().code(), code);
        }
        assert!(ForceUnit::from_code(0).is_none() && TorqueUnit::from_code(7).is_none());
        assert!((ForceUnit::Kgf.newtons() - 9.80665).abs() < 1e-12);
        assert!((TorqueUnit::LbfIn.newton_metres() - 0.112_984_829).abs() < 1e-9);
    }
}
