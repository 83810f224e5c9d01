//! Gravity and bias compensation of a wrist force/torque sensor: pure math on HAL types, no I/O.
//!
//! Static model in the sensor frame S, with `g_S = R_WSᵀ·[0, 0, −9.81]`:
//! `f = m'·g_S + f_b`, `τ = (m'c) × g_S + τ_b`, where `m' = ±m` absorbs the sensor's sign convention
//! (fitted, never assumed), `c` is the tool's centre of gravity and `f_b`, `τ_b` the sensor bias.
//!
//! [`GravityModel::identify`] fits `x = [m', m'c, f_b, τ_b]` by least squares over static poses; each pose
//! contributes `[f; τ] = [[g_S, 0, I, 0], [0, −[g_S]×, 0, I]]·x`. At least three poses whose `g_S` span
//! R³ are needed (two leave the system at rank 9): otherwise it refuses and says why.
//! [`Compensator`] removes the modelled tool weight and bias at run time and refuses when the robot's
//! orientation is missing or stale. The tool model (m, c) and the bias stay separate, so the bias can be
//! re-taken in any free-air pose ([`GravityModel::rebias`]); nothing is ever biased silently.

use core::fmt;

use hal::{UnitQuaternion, Vector3, Wrench};
use nalgebra::{DMatrix, DVector, Matrix3};

/// Standard gravity, m/s².
pub const G: f64 = 9.81;

/// Why identification or compensation refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GravityError {
    /// Fewer than three poses.
    TooFewPoses {
        /// Poses given.
        poses: usize,
    },
    /// The poses' gravity directions do not span R³.
    RankDeficient {
        /// Numerical rank of the 10-column system.
        rank: usize,
    },
    /// A pose or a measurement is not finite.
    NonFinite,
    /// No orientation of the robot is available.
    OrientationMissing,
    /// The orientation is older than allowed.
    OrientationStale {
        /// Its age, s.
        age: f64,
        /// The limit, s.
        max_age: f64,
    },
}

impl fmt::Display for GravityError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TooFewPoses { poses } => write!(
                f,
                "gravity calibration needs at least 3 static poses, got {poses}"
            ),
            Self::RankDeficient { rank } => write!(
                f,
                "gravity calibration is rank {rank} of 10: the poses' gravity directions do not span 3-D space; add a pose tilted about another axis"
            ),
            Self::NonFinite => {
                f.write_str("gravity calibration: a pose or measurement is not finite")
            }
            Self::OrientationMissing => {
                f.write_str("gravity compensation: no robot orientation, output invalid")
            }
            Self::OrientationStale { age, max_age } => write!(
                f,
                "gravity compensation: robot orientation is {age:.3} s old (limit {max_age:.3} s), output invalid"
            ),
        }
    }
}

impl std::error::Error for GravityError {}

/// Gravity in the sensor frame for a sensor oriented `r_ws` (sensor frame in the world, z up).
pub fn gravity_in_sensor(r_ws: &UnitQuaternion<f64>) -> Vector3<f64> {
    r_ws.inverse_transform_vector(&Vector3::new(0.0, 0.0, -G))
}

/// The identified tool and bias.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GravityModel {
    /// Signed mass `m'`, kg (the sign is the sensor's convention).
    pub signed_mass: f64,
    /// `m'·c`, kg·m, sensor frame.
    pub mass_moment: Vector3<f64>,
    /// Force bias, N.
    pub force_bias: Vector3<f64>,
    /// Torque bias, N·m.
    pub torque_bias: Vector3<f64>,
}

/// Relative singular-value threshold of the rank check.
const RANK_TOLERANCE: f64 = 1e-7;

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

impl GravityModel {
    /// Least-squares fit over static poses: `(R_WS, measured wrench)` pairs.
    pub fn identify(poses: &[(UnitQuaternion<f64>, Wrench)]) -> Result<Self, GravityError> {
        if poses.len() < 3 {
            return Err(GravityError::TooFewPoses { poses: poses.len() });
        }
        let rows = 6 * poses.len();
        let mut a = DMatrix::<f64>::zeros(rows, 10);
        let mut b = DVector::<f64>::zeros(rows);
        for (i, (r, w)) in poses.iter().enumerate() {
            if !(w.is_finite() && r.coords.iter().all(|v| v.is_finite())) {
                return Err(GravityError::NonFinite);
            }
            let g = gravity_in_sensor(r);
            let k = 6 * i;
            a.view_mut((k, 0), (3, 1)).copy_from(&g);
            a.view_mut((k, 4), (3, 3)).fill_with_identity();
            a.view_mut((k + 3, 1), (3, 3)).copy_from(&(-skew(&g)));
            a.view_mut((k + 3, 7), (3, 3)).fill_with_identity();
            b.rows_mut(k, 6).copy_from_slice(&w.to_array());
        }
        let svd = a.svd(true, true);
        let max = svd.singular_values.max();
        let rank = svd
            .singular_values
            .iter()
            .filter(|s| **s > RANK_TOLERANCE * max)
            .count();
        if rank < 10 {
            return Err(GravityError::RankDeficient { rank });
        }
        let x = svd
            .solve(&b, RANK_TOLERANCE * max)
            .map_err(|_| GravityError::RankDeficient { rank })?;
        Ok(Self {
            signed_mass: x[0],
            mass_moment: Vector3::new(x[1], x[2], x[3]),
            force_bias: Vector3::new(x[4], x[5], x[6]),
            torque_bias: Vector3::new(x[7], x[8], x[9]),
        })
    }

    /// Tool mass, kg.
    pub fn mass(&self) -> f64 {
        self.signed_mass.abs()
    }

    /// Centre of gravity, m, sensor frame (zero for a massless tool).
    pub fn centre_of_gravity(&self) -> Vector3<f64> {
        if self.signed_mass == 0.0 {
            Vector3::zeros()
        } else {
            self.mass_moment / self.signed_mass
        }
    }

    /// The tool's weight as the sensor reads it at orientation `r_ws`, without bias.
    pub fn tool_wrench(&self, r_ws: &UnitQuaternion<f64>) -> Wrench {
        let g = gravity_in_sensor(r_ws);
        Wrench {
            force: g * self.signed_mass,
            torque: self.mass_moment.cross(&g),
        }
    }

    /// The contact wrench: measured minus tool weight minus bias.
    pub fn compensate(&self, measured: &Wrench, r_ws: &UnitQuaternion<f64>) -> Wrench {
        let tool = self.tool_wrench(r_ws);
        Wrench {
            force: measured.force - tool.force - self.force_bias,
            torque: measured.torque - tool.torque - self.torque_bias,
        }
    }

    /// Take the bias again from a free-air measurement at `r_ws`, keeping the tool model.
    pub fn rebias(&mut self, free_air: &Wrench, r_ws: &UnitQuaternion<f64>) {
        let tool = self.tool_wrench(r_ws);
        self.force_bias = free_air.force - tool.force;
        self.torque_bias = free_air.torque - tool.torque;
    }
}

/// An orientation from the robot with its age.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orientation {
    /// Flange (or tool) orientation in the world, as the robot reports it.
    pub rotation: UnitQuaternion<f64>,
    /// How old it is, s.
    pub age: f64,
}

/// Run-time compensation: model, sensor mounting, staleness limit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Compensator {
    /// The identified model.
    pub model: GravityModel,
    /// The sensor frame in the flange frame (`R_FS`).
    pub mount: UnitQuaternion<f64>,
    /// Oldest usable orientation, s.
    pub max_age: f64,
}

impl Compensator {
    /// The contact wrench, or why it cannot be computed. A missing or stale orientation, or a
    /// non-finite one, makes the output invalid.
    pub fn compensate(
        &self,
        measured: &Wrench,
        orientation: Option<Orientation>,
    ) -> Result<Wrench, GravityError> {
        let o = orientation.ok_or(GravityError::OrientationMissing)?;
        if !(o.age.is_finite() && o.rotation.coords.iter().all(|v| v.is_finite())) {
            return Err(GravityError::NonFinite);
        }
        if o.age > self.max_age {
            return Err(GravityError::OrientationStale {
                age: o.age,
                max_age: self.max_age,
            });
        }
        Ok(self.model.compensate(measured, &(o.rotation * self.mount)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::FRAC_PI_2;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    fn truth() -> GravityModel {
        let m = 2.0;
        GravityModel {
            signed_mass: m,
            mass_moment: Vector3::new(0.01, -0.02, 0.08) * m,
            force_bias: Vector3::new(1.5, -2.0, 3.0),
            torque_bias: Vector3::new(0.1, 0.05, -0.08),
        }
    }

    fn measure(model: &GravityModel, r: &UnitQuaternion<f64>) -> Wrench {
        let t = model.tool_wrench(r);
        Wrench {
            force: t.force + model.force_bias,
            torque: t.torque + model.torque_bias,
        }
    }

    fn rot(rx: f64, ry: f64, rz: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(rx, ry, rz)
    }

    /// Six-axis noise like a small ATI sensor: σ 0.05 N and 2 mN·m.
    struct Noise {
        rng: ChaCha8Rng,
        f: Normal<f64>,
        t: Normal<f64>,
    }

    impl Noise {
        fn new(seed: u64) -> Self {
            Self {
                rng: ChaCha8Rng::seed_from_u64(seed),
                f: Normal::new(0.0, 0.05).unwrap(),
                t: Normal::new(0.0, 0.002).unwrap(),
            }
        }
        fn add(&mut self, w: &Wrench) -> Wrench {
            let mut v = w.to_array();
            for (i, x) in v.iter_mut().enumerate() {
                *x += if i < 3 { &self.f } else { &self.t }.sample(&mut self.rng);
            }
            Wrench::from_array(v)
        }
        /// A static pose measured as the mean of `n` samples.
        fn mean(&mut self, w: &Wrench, n: usize) -> Wrench {
            let mut acc = [0.0; 6];
            for _ in 0..n {
                for (a, v) in acc.iter_mut().zip(self.add(w).to_array()) {
                    *a += v / n as f64;
                }
            }
            Wrench::from_array(acc)
        }
    }

    #[test]
    fn exact_data_is_identified_exactly() {
        let t = truth();
        let poses: Vec<_> = [
            rot(0.0, 0.0, 0.0),
            rot(FRAC_PI_2, 0.0, 0.0),
            rot(0.0, FRAC_PI_2, 0.0),
        ]
        .iter()
        .map(|r| (*r, measure(&t, r)))
        .collect();
        let m = GravityModel::identify(&poses).unwrap();
        assert!((m.mass() - 2.0).abs() < 1e-9);
        assert!((m.centre_of_gravity() - Vector3::new(0.01, -0.02, 0.08)).norm() < 1e-9);
        assert!((m.force_bias - t.force_bias).norm() < 1e-9);
        assert!((m.torque_bias - t.torque_bias).norm() < 1e-9);
    }

    #[test]
    fn the_sign_convention_is_fitted_not_assumed() {
        let mut t = truth();
        t.signed_mass = -2.0;
        t.mass_moment = -t.mass_moment;
        let poses: Vec<_> = [rot(0.3, 0.0, 0.0), rot(0.0, 1.2, 0.0), rot(-1.0, 0.4, 0.5)]
            .iter()
            .map(|r| (*r, measure(&t, r)))
            .collect();
        let m = GravityModel::identify(&poses).unwrap();
        assert!((m.signed_mass + 2.0).abs() < 1e-9 && (m.mass() - 2.0).abs() < 1e-9);
        assert!((m.centre_of_gravity() - Vector3::new(0.01, -0.02, 0.08)).norm() < 1e-9);
    }

    #[test]
    fn two_orientations_are_refused_with_rank_nine() {
        let t = truth();
        // Three poses but only two distinct gravity directions (a rotation about gravity adds none).
        let poses: Vec<_> = [
            rot(0.0, 0.0, 0.0),
            rot(0.0, 0.0, 1.0),
            rot(FRAC_PI_2, 0.0, 0.0),
        ]
        .iter()
        .map(|r| (*r, measure(&t, r)))
        .collect();
        let e = GravityModel::identify(&poses).unwrap_err();
        assert_eq!(e, GravityError::RankDeficient { rank: 9 });
        assert!(e.to_string().contains("another axis"));
        assert_eq!(
            GravityModel::identify(&poses[..2]),
            Err(GravityError::TooFewPoses { poses: 2 })
        );
        let mut bad = poses.clone();
        bad[0].1.force.x = f64::NAN;
        assert_eq!(GravityModel::identify(&bad), Err(GravityError::NonFinite));
    }

    /// Scenario B10: a 2 kg tool reoriented 0–90° out of contact leaves ≤ 0.3 N after a least-squares
    /// calibration from ≤ 8 static poses, with sensor noise.
    #[test]
    fn b10_two_kilogram_tool_reoriented_leaves_under_0_3_newton() {
        let t = truth();
        let mut noise = Noise::new(10);
        let calibration_poses = [
            rot(0.0, 0.0, 0.0),
            rot(FRAC_PI_2, 0.0, 0.0),
            rot(-FRAC_PI_2, 0.0, 0.0),
            rot(0.0, FRAC_PI_2, 0.0),
            rot(0.0, -FRAC_PI_2, 0.0),
            rot(core::f64::consts::PI, 0.0, 0.0),
            rot(0.8, 0.8, 0.0),
            rot(-0.6, 0.3, 1.0),
        ];
        // Each static pose: the mean of 100 samples (0.1 s at 1 kHz).
        let poses: Vec<_> = calibration_poses
            .iter()
            .map(|r| (*r, noise.mean(&measure(&t, r), 100)))
            .collect();
        assert!(poses.len() <= 8);
        let m = GravityModel::identify(&poses).unwrap();
        assert!((m.mass() - 2.0).abs() < 0.01, "{}", m.mass());

        let comp = Compensator {
            model: m,
            mount: UnitQuaternion::identity(),
            max_age: 0.01,
        };
        let mut worst: f64 = 0.0;
        let mut worst_model: f64 = 0.0;
        for axis in 0..2 {
            for deg in 0..=90 {
                let a = f64::from(deg).to_radians();
                let r = if axis == 0 {
                    rot(a, 0.0, 0.0)
                } else {
                    rot(0.0, a, 0.3 * a)
                };
                let clean = measure(&t, &r);
                let o = Some(Orientation {
                    rotation: r,
                    age: 0.004,
                });
                // Model error alone, and what a single noisy sample shows.
                worst_model = worst_model.max(comp.compensate(&clean, o).unwrap().force.norm());
                worst = worst.max(comp.compensate(&noise.add(&clean), o).unwrap().force.norm());
            }
        }
        assert!(worst_model < 0.05, "model residual {worst_model} N");
        assert!(worst <= 0.3, "residual with noise {worst} N");
        // Without compensation the tool weight alone moves the reading by ~2·9.81·√2 N.
        let raw =
            measure(&t, &rot(FRAC_PI_2, 0.0, 0.0)).force - measure(&t, &rot(0.0, 0.0, 0.0)).force;
        assert!(raw.norm() > 20.0);
    }

    #[test]
    fn missing_or_stale_orientation_invalidates_the_output() {
        let comp = Compensator {
            model: truth(),
            mount: UnitQuaternion::identity(),
            max_age: 0.012,
        };
        let w = Wrench::default();
        assert_eq!(
            comp.compensate(&w, None),
            Err(GravityError::OrientationMissing)
        );
        let stale = Orientation {
            rotation: UnitQuaternion::identity(),
            age: 0.1,
        };
        assert!(matches!(
            comp.compensate(&w, Some(stale)),
            Err(GravityError::OrientationStale { .. })
        ));
        let nan = Orientation {
            rotation: UnitQuaternion::identity(),
            age: f64::NAN,
        };
        assert_eq!(comp.compensate(&w, Some(nan)), Err(GravityError::NonFinite));
    }

    #[test]
    fn the_mount_rotation_is_applied() {
        let t = truth();
        // Sensor mounted rotated 90° about the flange z; flange tilted 90° about x.
        let mount = rot(0.0, 0.0, FRAC_PI_2);
        let flange = rot(FRAC_PI_2, 0.0, 0.0);
        let measured = measure(&t, &(flange * mount));
        let comp = Compensator {
            model: t,
            mount,
            max_age: 1.0,
        };
        let c = comp
            .compensate(
                &measured,
                Some(Orientation {
                    rotation: flange,
                    age: 0.0,
                }),
            )
            .unwrap();
        assert!(c.force.norm() < 1e-9 && c.torque.norm() < 1e-9);
    }

    #[test]
    fn rebias_keeps_the_tool_model() {
        let t = truth();
        let mut m = t;
        m.force_bias = Vector3::zeros();
        m.torque_bias = Vector3::zeros();
        let r = rot(0.4, -0.2, 0.0);
        m.rebias(&measure(&t, &r), &r);
        assert!((m.force_bias - t.force_bias).norm() < 1e-12);
        assert!((m.torque_bias - t.torque_bias).norm() < 1e-12);
        assert_eq!(m.signed_mass, t.signed_mass);
        // Contact force shows through after compensation.
        let r2 = rot(1.0, 0.5, 0.0);
        let mut pressed = measure(&t, &r2);
        pressed.force.z += 5.0;
        assert!((m.compensate(&pressed, &r2).force.z - 5.0).abs() < 1e-9);
    }
}
