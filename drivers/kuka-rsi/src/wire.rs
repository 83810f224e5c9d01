//! The one place where SI meets the wire: metres ↔ millimetres, radians ↔ degrees, rotation
//! vectors and quaternions ↔ KUKA's `A B C` angles (A about Z, then B about Y, then C about X).

use hal::{Pose, UnitQuaternion, Vector3};

/// Millimetres per metre.
pub const MM_PER_M: f64 = 1000.0;

/// `[X, Y, Z, A, B, C]` in mm and degrees → a pose in m.
pub fn pose_from_wire(v: [f64; 6]) -> Pose {
    pose_from_wire_with(v, &mut Memo::default())
}

/// [`pose_from_wire`], the orientation taken from `memo` when `A B C` are those of its last call
/// (the same result, bit for bit, without the trigonometry).
pub fn pose_from_wire_with(v: [f64; 6], memo: &mut Memo<UnitQuaternion<f64>>) -> Pose {
    Pose {
        position: Vector3::new(v[0], v[1], v[2]) / MM_PER_M,
        orientation: memo.get([v[3], v[4], v[5]], |[a, b, c]| {
            UnitQuaternion::from_euler_angles(c.to_radians(), b.to_radians(), a.to_radians())
        }),
    }
}

/// The last input and output of one orientation conversion. A robot's orientation, and a
/// correction's rotation, is mostly the same from one cycle to the next (on a flat part, always):
/// kept, the same three angles give back the same result without its sines, cosines and arc
/// tangents (six of them a pose). Inputs compare bit for bit, so −0 and 0, or a NaN's payload, are
/// different inputs, and the result is always exactly what the conversion gives.
#[derive(Clone, Copy, Debug, Default)]
pub struct Memo<V> {
    last: Option<([u64; 3], V)>,
}

impl<V: Copy> Memo<V> {
    /// `convert(key)`, or the last result when `key` is the last key.
    #[inline]
    pub fn get(&mut self, key: [f64; 3], convert: impl FnOnce([f64; 3]) -> V) -> V {
        let bits = key.map(f64::to_bits);
        match self.last {
            Some((k, v)) if k == bits => v,
            _ => {
                let v = convert(key);
                self.last = Some((bits, v));
                v
            }
        }
    }
}

/// Translation in m and orientation → `[X, Y, Z, A, B, C]` in mm and degrees (A about Z, B about Y, C about X).
fn to_wire(translation: &Vector3<f64>, orientation: &UnitQuaternion<f64>) -> [f64; 6] {
    let [a, b, c] = abc(orientation);
    let x = translation * MM_PER_M;
    [x.x, x.y, x.z, a, b, c]
}

/// An orientation → KUKA's `A B C`, degrees.
fn abc(orientation: &UnitQuaternion<f64>) -> [f64; 3] {
    let (c, b, a) = orientation.euler_angles();
    [a.to_degrees(), b.to_degrees(), c.to_degrees()]
}

/// A pose in m → `[X, Y, Z, A, B, C]` in mm and degrees.
pub fn pose_to_wire(p: &Pose) -> [f64; 6] {
    to_wire(&p.position, &p.orientation)
}

/// A correction offset (translation m, rotation vector rad) → `[X, Y, Z, A, B, C]` in mm and degrees.
pub fn offset_to_wire(translation: &Vector3<f64>, rotation: &Vector3<f64>) -> [f64; 6] {
    offset_to_wire_with(translation, rotation, &mut Memo::default())
}

/// [`offset_to_wire`], the angles taken from `memo` when `rotation` is that of its last call.
pub fn offset_to_wire_with(
    translation: &Vector3<f64>,
    rotation: &Vector3<f64>,
    memo: &mut Memo<[f64; 3]>,
) -> [f64; 6] {
    let [a, b, c] = memo.get((*rotation).into(), |r| {
        abc(&UnitQuaternion::from_scaled_axis(Vector3::from(r)))
    });
    let x = translation * MM_PER_M;
    [x.x, x.y, x.z, a, b, c]
}

/// `[X, Y, Z, A, B, C]` in mm and degrees → a correction offset (translation m, rotation vector rad).
pub fn offset_from_wire(v: [f64; 6]) -> (Vector3<f64>, Vector3<f64>) {
    let q =
        UnitQuaternion::from_euler_angles(v[5].to_radians(), v[4].to_radians(), v[3].to_radians());
    (Vector3::new(v[0], v[1], v[2]) / MM_PER_M, q.scaled_axis())
}

/// Metres → millimetres (for limits stated in SI and compared at the wire).
pub fn m_to_mm(m: f64) -> f64 {
    m * MM_PER_M
}

/// Millimetres → metres.
pub fn mm_to_m(mm: f64) -> f64 {
    mm / MM_PER_M
}

/// The process channels' force (`FcCmd.F`, `FcState.F`) is in newtons on the wire, as in SI; this is
/// still the one place where it crosses, so a robot program in other units changes only here.
pub fn force_from_wire(n: f64) -> f64 {
    n
}

/// The largest force magnitude written to the wire, N (a plausible sensor never reports more; it keeps
/// every value inside plain fixed-point).
pub const MAX_WIRE_FORCE: f64 = 1.0e6;

/// Newtons → the wire's force (`FcState.F`). Never non-finite: NaN is written as 0 (no force known —
/// the `FcState.State`/`Fault` fields say why), ±inf and anything beyond [`MAX_WIRE_FORCE`] are clamped.
pub fn force_to_wire(n: f64) -> f64 {
    if n.is_nan() {
        0.0
    } else {
        n.clamp(-MAX_WIRE_FORCE, MAX_WIRE_FORCE)
    }
}

/// The process channels' ramp time (`FcCmd.Ramp`) is in seconds on the wire, as in SI.
pub fn seconds_from_wire(s: f64) -> f64 {
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_out_is_always_finite() {
        assert_eq!(force_to_wire(19.98), 19.98);
        assert_eq!(force_to_wire(f64::NAN), 0.0);
        assert_eq!(force_to_wire(f64::INFINITY), MAX_WIRE_FORCE);
        assert_eq!(force_to_wire(f64::NEG_INFINITY), -MAX_WIRE_FORCE);
    }

    #[test]
    fn kuka_abc_is_zyx() {
        // A = 90° about Z turns the tool's x axis onto base y.
        let p = pose_from_wire([445.0, 0.0, 890.0, 90.0, 0.0, 0.0]);
        let x = p.orientation * Vector3::x();
        assert!((x - Vector3::y()).norm() < 1e-12, "{x:?}");
        assert!((p.position - Vector3::new(0.445, 0.0, 0.890)).norm() < 1e-12);
        // C = 180° about X flips z.
        let p = pose_from_wire([0.0, 0.0, 0.0, 0.0, 0.0, 180.0]);
        assert!((p.orientation * Vector3::z() + Vector3::z()).norm() < 1e-12);
    }

    #[test]
    fn pose_round_trip() {
        let v = [445.0, -12.5, 890.25, 30.0, -20.0, 170.0];
        let back = pose_to_wire(&pose_from_wire(v));
        for (a, b) in v.iter().zip(back) {
            assert!((a - b).abs() < 1e-9, "{v:?} vs {back:?}");
        }
    }

    /// The kept conversion gives exactly what the conversion gives, over a sequence that repeats,
    /// changes, and passes through −0, 0 and NaN.
    #[test]
    fn a_kept_conversion_is_the_conversion_bit_for_bit() {
        let abc = [
            [30.0, -20.0, 170.0],
            [30.0, -20.0, 170.0],
            [0.0, 0.0, 180.0],
            [-0.0, 0.0, 180.0],
            [-0.0, 0.0, 180.0],
            [f64::NAN, 0.0, 1.0],
            [f64::NAN, 0.0, 1.0],
            [30.0, -20.0, 170.000_000_000_001],
        ];
        let mut pose_memo = Memo::default();
        let mut offset_memo = Memo::default();
        for [a, b, c] in abc {
            let v = [1.0, 2.0, 3.0, a, b, c];
            let (plain, kept) = (pose_from_wire(v), pose_from_wire_with(v, &mut pose_memo));
            let bits = |p: &Pose| p.orientation.coords.map(f64::to_bits);
            assert_eq!(bits(&plain), bits(&kept), "{v:?}");
            let (t, r) = (Vector3::new(1e-3, 0.0, -2e-3), Vector3::new(a, b, c) * 1e-3);
            let plain = offset_to_wire(&t, &r).map(f64::to_bits);
            let kept = offset_to_wire_with(&t, &r, &mut offset_memo).map(f64::to_bits);
            assert_eq!(plain, kept, "{r:?}");
        }
    }

    #[test]
    fn small_offsets_map_axis_by_axis() {
        let w = offset_to_wire(
            &Vector3::new(0.0, 0.0, 0.000012),
            &Vector3::new(0.0, 0.0, 1f64.to_radians()),
        );
        assert!((w[2] - 0.012).abs() < 1e-12);
        assert!((w[3] - 1.0).abs() < 1e-9, "A is about z: {w:?}");
        let (t, r) = offset_from_wire(w);
        assert!((t.z - 0.000012).abs() < 1e-15);
        assert!((r.z - 1f64.to_radians()).abs() < 1e-12);
    }
}
