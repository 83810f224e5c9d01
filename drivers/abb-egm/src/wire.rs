//! The one place where SI meets the EGM wire: metres ↔ millimetres, unit quaternions ↔
//! `EgmQuaternion` (`u0` the scalar part), durations ↔ whole milliseconds, and forcecell's tool frame
//! ↔ the frame a path correction is written in.
//!
//! # The frame of a path correction
//! `EgmPathCorr.pos` is a translation in mm expressed in the **sensor frame** that the RAPID program
//! gives `EGMActMove` (`\SensorFrame`, a pose relative to the tool); the controller applies it in path
//! coordinates, which follow the direction of motion (ABB's RAPID reference describes them under
//! `CorrConn`). forcecell's [`hal::Correction`] is in the tool frame. This module converts with the
//! sensor frame's orientation relative to the tool ([`SensorFrame`]; identity when the program passes
//! the tool itself, as the RAPID module forcecell will write does). With the tool's z normal to the
//! surface and the motion along the surface, path z and tool z coincide: the normal correction, the one
//! a 1-DOF force law makes, is the same in both. **Not verified on a controller**: how the controller
//! turns the tangential axes (x, y) into path coordinates when the tool is tilted against the path.
//!
//! A path correction carries **translation only**: a correction's rotation cannot be sent (the session
//! drops it and counts it).

use core::time::Duration;

use hal::{Pose, UnitQuaternion, Vector3};

use crate::msg::{EgmCartesian, EgmQuaternion};

/// Millimetres per metre.
pub const MM_PER_M: f64 = 1000.0;

/// How far from unit length a received quaternion may be (the controller's rounding) before it is
/// refused as malformed rather than normalised.
pub const QUATERNION_TOLERANCE: f64 = 1e-3;

/// The sensor frame's orientation relative to the tool: what `EGMActMove \SensorFrame` is set to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorFrame(pub UnitQuaternion<f64>);

impl Default for SensorFrame {
    /// The tool itself.
    fn default() -> Self {
        Self(UnitQuaternion::identity())
    }
}

/// Why a pose on the wire is unusable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseError {
    /// A coordinate is missing (`pos` or `orient` incomplete).
    Missing,
    /// A value is NaN or infinite.
    NonFinite,
    /// The quaternion is further than [`QUATERNION_TOLERANCE`] from unit length.
    NotUnit,
}

/// `EgmCartesian` (mm) and `EgmQuaternion` → a pose in m.
pub fn pose_from_wire(
    pos: Option<&EgmCartesian>,
    orient: Option<&EgmQuaternion>,
) -> Result<Pose, PoseError> {
    let (Some(p), Some(q)) = (pos, orient) else {
        return Err(PoseError::Missing);
    };
    let (Some(x), Some(y), Some(z)) = (p.x, p.y, p.z) else {
        return Err(PoseError::Missing);
    };
    let (Some(w), Some(i), Some(j), Some(k)) = (q.u0, q.u1, q.u2, q.u3) else {
        return Err(PoseError::Missing);
    };
    let v = [x, y, z, w, i, j, k];
    if !v.iter().all(|v| v.is_finite()) {
        return Err(PoseError::NonFinite);
    }
    let q = nalgebra::Quaternion::new(w, i, j, k);
    let n = q.norm();
    if (n - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(PoseError::NotUnit);
    }
    Ok(Pose {
        position: Vector3::new(x, y, z) / MM_PER_M,
        orientation: UnitQuaternion::new_normalize(q),
    })
}

/// A pose in m → `EgmCartesian` (mm) and `EgmQuaternion` (for the robot side).
pub fn pose_to_wire(p: &Pose) -> (EgmCartesian, EgmQuaternion) {
    let x = p.position * MM_PER_M;
    let q = p.orientation.quaternion();
    (
        EgmCartesian {
            x: Some(x.x),
            y: Some(x.y),
            z: Some(x.z),
        },
        EgmQuaternion {
            u0: Some(q.w),
            u1: Some(q.i),
            u2: Some(q.j),
            u3: Some(q.k),
        },
    )
}

/// A correction's translation in m, tool frame → `EgmPathCorr.pos` in mm, sensor frame.
pub fn correction_to_wire(translation: &Vector3<f64>, frame: &SensorFrame) -> EgmCartesian {
    let v = frame.0.inverse_transform_vector(translation) * MM_PER_M;
    EgmCartesian {
        x: Some(v.x),
        y: Some(v.y),
        z: Some(v.z),
    }
}

/// `EgmPathCorr.pos` (mm, sensor frame) → m in the tool frame (for the robot side). Missing or
/// non-finite coordinates give `None`.
pub fn correction_from_wire(c: &EgmCartesian, frame: &SensorFrame) -> Option<Vector3<f64>> {
    let (Some(x), Some(y), Some(z)) = (c.x, c.y, c.z) else {
        return None;
    };
    let v = Vector3::new(x, y, z);
    v.iter()
        .all(|v| v.is_finite())
        .then(|| frame.0.transform_vector(&v) / MM_PER_M)
}

/// A duration → whole milliseconds, rounded to the nearest, saturating (`EgmPathCorr.age`,
/// `EgmHeader.tm`).
pub fn ms_to_wire(d: Duration) -> u32 {
    u32::try_from((d.as_micros() + 500) / 1000).unwrap_or(u32::MAX)
}

/// Milliseconds on the wire → seconds.
pub fn ms_from_wire(ms: u64) -> f64 {
    ms as f64 / 1000.0
}

/// Metres → millimetres (limits stated in SI, compared at the wire).
pub fn m_to_mm(m: f64) -> f64 {
    m * MM_PER_M
}

/// Millimetres → metres.
pub fn mm_to_m(mm: f64) -> f64 {
    mm / MM_PER_M
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_round_trip_in_mm_with_u0_the_scalar() {
        let p = Pose {
            position: Vector3::new(0.4455, -0.0125, 0.89025),
            orientation: UnitQuaternion::from_euler_angles(0.3, -0.2, 2.9),
        };
        let (c, q) = pose_to_wire(&p);
        assert!((c.z.unwrap() - 890.25).abs() < 1e-9);
        assert!((q.u0.unwrap() - p.orientation.w).abs() < 1e-15);
        let back = pose_from_wire(Some(&c), Some(&q)).unwrap();
        assert!((back.position - p.position).norm() < 1e-12);
        assert!(back.orientation.angle_to(&p.orientation) < 1e-12);
        // The identity is u0 = 1.
        let id = pose_from_wire(
            Some(&c),
            Some(&EgmQuaternion {
                u0: Some(1.0),
                u1: Some(0.0),
                u2: Some(0.0),
                u3: Some(0.0),
            }),
        )
        .unwrap();
        assert_eq!(id.orientation, UnitQuaternion::identity());
    }

    #[test]
    fn bad_poses_are_refused_never_repaired() {
        let (c, q) = pose_to_wire(&Pose::identity());
        assert_eq!(pose_from_wire(None, Some(&q)), Err(PoseError::Missing));
        let mut part = c;
        part.y = None;
        assert_eq!(
            pose_from_wire(Some(&part), Some(&q)),
            Err(PoseError::Missing)
        );
        let mut nan = c;
        nan.x = Some(f64::NAN);
        assert_eq!(
            pose_from_wire(Some(&nan), Some(&q)),
            Err(PoseError::NonFinite)
        );
        let mut long = q;
        long.u0 = Some(1.01);
        assert_eq!(
            pose_from_wire(Some(&c), Some(&long)),
            Err(PoseError::NotUnit)
        );
        let mut zero = q;
        zero.u0 = Some(0.0);
        assert_eq!(
            pose_from_wire(Some(&c), Some(&zero)),
            Err(PoseError::NotUnit)
        );
    }

    #[test]
    fn correction_goes_to_mm_in_the_sensor_frame_and_back() {
        let t = Vector3::new(0.0, 0.0, 0.0015);
        let c = correction_to_wire(&t, &SensorFrame::default());
        assert_eq!((c.x, c.y, c.z), (Some(0.0), Some(0.0), Some(1.5)));
        // A sensor frame turned +90° about the tool's x: its y axis is the tool's z.
        let f = SensorFrame(UnitQuaternion::from_euler_angles(
            core::f64::consts::FRAC_PI_2,
            0.0,
            0.0,
        ));
        let c = correction_to_wire(&t, &f);
        assert!(
            (c.y.unwrap() - 1.5).abs() < 1e-12 && c.z.unwrap().abs() < 1e-12,
            "{c:?}"
        );
        let back = correction_from_wire(&c, &f).unwrap();
        assert!((back - t).norm() < 1e-15);
    }

    #[test]
    fn milliseconds_round_to_nearest_and_saturate() {
        assert_eq!(ms_to_wire(Duration::from_micros(1499)), 1);
        assert_eq!(ms_to_wire(Duration::from_micros(1500)), 2);
        assert_eq!(ms_to_wire(Duration::from_secs(u64::MAX / 2)), u32::MAX);
    }
}
