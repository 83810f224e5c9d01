//! Curved parts: a surface whose normal varies along the path, a compliant pad on a tool that may be
//! rotated, friction against the feed, and the full wrench this gives at the sensor. Formulas and
//! conventions: `docs/curved-parts.md`.
//!
//! # Frames
//! The **path frame** P: `x` along the feed (tangent to the nominal part at the contact), `y` across
//! the path, `z` into the nominal part (the nominal surface normal). The programmed tool holds the
//! program's tilt `t` about P's `y` (`R_prog = R_y(−t)`: seen from the tool, the nominal normal leans
//! towards the feed by `t`); the tool then turns by the correction's rotation `θ` (tool frame), after
//! the robot's inner loop: `R_tool = R_prog · R(θ)`. The tool's centre point (TCP) is the pad's
//! centre; it stands at path position `s` and at the 1-DOF normal offset `x` along the programmed
//! tool axis.
//!
//! # Surface
//! A height field `z = H(u, v)` in P (`u` along the path from its start, `v` across): the shape
//! (flat, a cylinder with its axis across or along the path, a saddle) plus the part's misplacement,
//! a rotation `r_x` about the path's `x` and `r_y` about its `y`, as the slopes `tan r_x` across
//! and `−tan r_y` along (exact for one rotation; the second rotation's cosine, 0.4 % at 5°, is
//! neglected). The plant's surface position `x_c(t)` and the 1-D form ([`crate::SurfaceForm`]) add
//! to it. The inward normal is `n = (−∂H/∂u, −∂H/∂v, 1)/‖·‖`.
//!
//! # Pad
//! A disc of radius `r`, a bed of springs (Winkler) whose total stiffness is the plant's `k_c`:
//! pressure `p = k_c/(πr²) · max(0, δ₀ + n·ρ)` at the point `ρ` of the pad face, with `δ₀` the
//! centre's penetration along `n`. With `g = sin φ` (φ the angle between the tool axis and `n`) and
//! `ξ` the coordinate along `n`'s part in the pad plane: in full contact (`δ₀ ≥ g·r`)
//! `N = k_c·δ₀` and the pressure's first moment `Q = k_c·g·r²/4`; in partial contact both are the
//! integrals over the chords `2√(r² − ξ²)`, taken numerically. The surface's curvature under the
//! pad is neglected (the pad sees the tangent plane at its centre).
//!
//! # Wrench
//! On the part, at the pressure centre `c = Q/N · ê`: the normal force `N·n` and friction
//! `μ·N·t̂` along the feed direction projected into the tangent plane (while the tool moves along the
//! path; none at rest). The sensor sits `L` (tool length) behind the TCP on the tool axis and reads
//! that force and its moment about its own origin, `(L·a + c) × F`, in its own (the tool's) frame,
//! compressive force positive as the 1-DOF sensor does.

use hal::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::inner::{InnerLoop, InnerLoopModel};

/// The largest rotation of the part, of the program's tilt, accepted, rad (30°).
pub const MAX_ANGLE: f64 = core::f64::consts::FRAC_PI_6;

/// The simulated sensor's torque imperfections are its force's times this arm, m (an F/T sensor's
/// torque noise in N·m is about its force noise in N times a few centimetres).
pub const TORQUE_ARM: f64 = 0.02;

/// The torque's sensor model: the force's filter and dropouts, its noise, bias, drift and resolution
/// scaled by [`TORQUE_ARM`], another seed, and no injected NaN (the force's sample carries those).
pub fn torque_params(force: &crate::SensorParams) -> crate::SensorParams {
    crate::SensorParams {
        noise: force.noise * TORQUE_ARM,
        bias: force.bias * TORQUE_ARM,
        drift_per_min: force.drift_per_min * TORQUE_ARM,
        quantum: force.quantum * TORQUE_ARM,
        dropouts: Vec::new(),
        nan_at: Vec::new(),
        seed: force.seed.wrapping_add(0x7047),
        bandwidth: force.bandwidth,
    }
}

/// How many chords the partial-contact integrals take.
const CHORDS: usize = 256;

/// Which way a cylinder's axis runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Axis {
    /// Across the path (the path runs round the cylinder: the normal turns about the path's `y`).
    Across,
    /// Along the path (the path runs on the crown; the part's curvature is across it).
    Along,
}

/// The nominal shape of the part under the path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Shape {
    /// A plane.
    #[default]
    Flat,
    /// A convex cylinder of `radius` (m) whose crown lies at path position `centre` (m).
    Cylinder {
        /// Radius, m.
        radius: f64,
        /// Which way its axis runs.
        axis: Axis,
        /// The crown's path position, m.
        #[serde(default)]
        centre: f64,
    },
    /// A saddle (hyperbolic paraboloid) `(ξ² − η²)/(2R)` whose principal directions are turned by
    /// `angle` (rad) from the path, centred at path position `centre` (m): along the path its normal
    /// turns about both of the path's axes.
    Saddle {
        /// Principal radius of curvature, m.
        radius: f64,
        /// Angle of the principal directions from the path, rad.
        angle: f64,
        /// The saddle point's path position, m.
        #[serde(default)]
        centre: f64,
    },
}

/// The part's geometry, the pad and the tool (the `[environment.geometry]` table of a scenario).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// The nominal shape.
    #[serde(default)]
    pub shape: Shape,
    /// Misplacement of the part about the path's `x` (the feed direction), rad.
    #[serde(default)]
    pub misplace_x: f64,
    /// Misplacement of the part about the path's `y` (across), rad.
    #[serde(default)]
    pub misplace_y: f64,
    /// Pad radius, m.
    pub pad_radius: f64,
    /// Friction coefficient between pad and part.
    #[serde(default)]
    pub friction: f64,
    /// Distance from the sensor's origin to the pad face (the TCP) along the tool axis, m.
    #[serde(default)]
    pub tool_length: f64,
    /// The tilt the program holds towards the feed (about the tool's `y`) against the nominal
    /// surface, rad; what a disc polisher's process asks for, and the tilt the pass is judged by.
    #[serde(default)]
    pub program_tilt: f64,
}

impl Geometry {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        let fin = |n: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("geometry.{n} must be finite, got {v}"))
            }
        };
        for (n, v) in [
            ("misplace_x", self.misplace_x),
            ("misplace_y", self.misplace_y),
            ("program_tilt", self.program_tilt),
        ] {
            fin(n, v)?;
            if v.abs() > MAX_ANGLE {
                return Err(format!(
                    "geometry.{n} must be within ±{MAX_ANGLE} rad (30°), got {v}"
                ));
            }
        }
        if !(self.pad_radius.is_finite() && self.pad_radius > 0.0 && self.pad_radius <= 0.2) {
            return Err(format!(
                "geometry.pad_radius must be in (0, 0.2] m, got {}",
                self.pad_radius
            ));
        }
        if !(self.friction.is_finite() && (0.0..=2.0).contains(&self.friction)) {
            return Err(format!(
                "geometry.friction must be in [0, 2], got {}",
                self.friction
            ));
        }
        if !(self.tool_length.is_finite() && (0.0..=1.0).contains(&self.tool_length)) {
            return Err(format!(
                "geometry.tool_length must be in [0, 1] m, got {}",
                self.tool_length
            ));
        }
        match self.shape {
            Shape::Flat => {}
            Shape::Cylinder { radius, centre, .. } | Shape::Saddle { radius, centre, .. } => {
                if !(radius.is_finite() && radius >= 0.01) {
                    return Err(format!(
                        "geometry.shape.radius must be at least 0.01 m, got {radius}"
                    ));
                }
                fin("shape.centre", centre)?;
                if radius <= 2.0 * self.pad_radius {
                    return Err(format!(
                        "geometry.shape.radius {radius} m must exceed the pad's diameter {} m (the pad sees the tangent plane)",
                        2.0 * self.pad_radius
                    ));
                }
            }
        }
        if let Shape::Saddle { angle, .. } = self.shape {
            fin("shape.angle", angle)?;
        }
        Ok(())
    }

    /// The part's surface under the path at `s` (m): its height `H` along P's `z` and its slopes
    /// `(∂H/∂u, ∂H/∂v)` at `(u, v) = (s, 0)`; `None` off the part (beyond a cylinder's side).
    pub fn surface(&self, s: f64) -> Option<(f64, f64, f64)> {
        let (h, gu, gv) = match self.shape {
            Shape::Flat => (0.0, 0.0, 0.0),
            Shape::Cylinder {
                radius,
                axis: Axis::Across,
                centre,
            } => {
                let u = s - centre;
                let w = radius * radius - u * u;
                if w <= 0.0 {
                    return None;
                }
                let w = w.sqrt();
                (radius - w, u / w, 0.0)
            }
            // On the crown: no height or slope along the path; the curvature is across it.
            Shape::Cylinder {
                axis: Axis::Along, ..
            } => (0.0, 0.0, 0.0),
            Shape::Saddle {
                radius,
                angle,
                centre,
            } => {
                let u = s - centre;
                let (c2, s2) = ((2.0 * angle).cos(), (2.0 * angle).sin());
                // (ξ² − η²)/2R with ξ, η the principal directions: (c2·(u² − v²) + 2·s2·u·v)/2R.
                (
                    c2 * u * u / (2.0 * radius),
                    c2 * u / radius,
                    s2 * u / radius,
                )
            }
        };
        let (tx, ty) = (self.misplace_x.tan(), self.misplace_y.tan());
        Some((h - ty * s, gu - ty, gv + tx))
    }

    /// The programmed tool orientation in the path frame (the program's tilt).
    pub fn programmed(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_scaled_axis(Vector3::new(0.0, -self.program_tilt, 0.0))
    }
}

/// The pad's contact on the tangent plane: the normal force `N` and the first moment `Q` of the
/// pressure along `ê`, for stiffness `k` (N/m), radius `r`, centre penetration `d` (m) and
/// `g = sin φ`.
pub fn pad_contact(k: f64, r: f64, d: f64, g: f64) -> (f64, f64) {
    if d >= g * r {
        return (k * d, k * g * r * r / 4.0);
    }
    if d + g * r <= 0.0 {
        return (0.0, 0.0);
    }
    // Partial contact: the pressure is zero below ξ₀ = −d/g; midpoint rule over [ξ₀, r].
    let k_a = k / (core::f64::consts::PI * r * r);
    let lo = (-d / g).max(-r);
    let h = (r - lo) / CHORDS as f64;
    let (mut n, mut q) = (0.0, 0.0);
    for i in 0..CHORDS {
        let xi = lo + (i as f64 + 0.5) * h;
        let w = 2.0 * (r * r - xi * xi).max(0.0).sqrt();
        let p = (d + g * xi).max(0.0);
        n += p * w;
        q += p * w * xi;
    }
    (k_a * n * h, k_a * q * h)
}

/// What the contact gives at one instant.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ContactState {
    /// Force normal to the surface, N (≥ 0).
    pub normal: f64,
    /// Force (on the part, compressive `z` positive) in the sensor (= tool) frame, N.
    pub force: Vector3<f64>,
    /// Moment about the sensor's origin, in its frame, N·m.
    pub torque: Vector3<f64>,
    /// The rotation from the tool axis to the surface normal, tool frame, rad (its norm is the
    /// angle between them).
    pub tilt: Vector3<f64>,
}

/// The geometry and the tool's rotation as the robot carries it out.
#[derive(Clone, Debug)]
pub struct Contact {
    geometry: Geometry,
    /// The rotation's inner loops (the correction's rotation about tool `x` and `y`), through the
    /// same lag and delay as the translation.
    turn: [InnerLoop; 2],
    /// The last rotation commanded.
    last: [f64; 2],
    /// The path's speed over the last period, m/s.
    feed: f64,
}

impl Contact {
    /// A contact with the tool turned by nothing.
    pub fn new(geometry: Geometry, model: InnerLoopModel) -> Self {
        Self {
            geometry,
            turn: [InnerLoop::new(model, 0.0), InnerLoop::new(model, 0.0)],
            last: [0.0; 2],
            feed: 0.0,
        }
    }

    /// The path's speed over the last period, m/s (friction acts against it).
    pub fn feed(&self) -> f64 {
        self.feed
    }

    /// The geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    /// The tool's rotation from its programmed orientation now (tool frame; about `z` none), rad.
    pub fn rotation(&self) -> Vector3<f64> {
        Vector3::new(self.turn[0].position(), self.turn[1].position(), 0.0)
    }

    /// Take the correction's rotation about tool `x` and `y` (a non-finite one holds the last) and
    /// advance one period; the path moved at `feed` (m/s) over it.
    pub fn advance(&mut self, rotation: Option<Vector3<f64>>, feed: f64) {
        self.feed = feed;
        if let Some(r) = rotation
            && r.x.is_finite()
            && r.y.is_finite()
        {
            self.last = [r.x, r.y];
        }
        self.turn[0].advance(self.last[0]);
        self.turn[1].advance(self.last[1]);
    }

    /// The contact for a pad of stiffness `k` (N/m) and damping `c` (N·s/m) with the tool at normal
    /// offset `x` (m, velocity `xv`), path position `s` moving at `feed` (m/s), over a surface whose
    /// position along the nominal normal is `surface` (m, the plant's and the 1-D form's).
    #[allow(clippy::too_many_arguments)]
    pub fn state(
        &self,
        k: f64,
        c: f64,
        x: f64,
        xv: f64,
        s: f64,
        feed: f64,
        surface: f64,
    ) -> ContactState {
        let g = &self.geometry;
        let r_tool = g.programmed() * UnitQuaternion::from_scaled_axis(self.rotation());
        let a = r_tool * Vector3::z();
        let a0 = g.programmed() * Vector3::z();
        // Off the part: nothing touches; the tilt is against the nominal normal.
        let Some((h, gu, gv)) = g.surface(s) else {
            return ContactState {
                tilt: tilt_of(&r_tool, &Vector3::z()),
                ..ContactState::default()
            };
        };
        let n = Vector3::new(-gu, -gv, 1.0).normalize();
        let tilt = tilt_of(&r_tool, &n);
        // The TCP's depth along P's z, against the surface under it.
        let depth = x * a0.z - (h + surface);
        let d = n.z * depth;
        let n_perp = n - a * n.dot(&a);
        let sin_phi = n_perp.norm();
        let (mut normal, q) = pad_contact(k, g.pad_radius, d, sin_phi);
        if normal > 0.0 {
            normal = (normal + c * xv * n.dot(&a0)).max(0.0);
        }
        if normal <= 0.0 {
            return ContactState {
                tilt,
                ..ContactState::default()
            };
        }
        let e_hat = if sin_phi > 1e-12 {
            n_perp / sin_phi
        } else {
            Vector3::zeros()
        };
        // Pressure centre, from the pressure's first moment about the pad centre.
        let centre = e_hat * (q / normal);
        let along = Vector3::x() - n * n.x;
        let t_hat = if along.norm() > 1e-12 && feed != 0.0 {
            along.normalize() * feed.signum()
        } else {
            Vector3::zeros()
        };
        let force = n * normal + t_hat * (g.friction * normal);
        let torque = (a * g.tool_length + centre).cross(&force);
        ContactState {
            normal,
            force: r_tool.inverse_transform_vector(&force),
            torque: r_tool.inverse_transform_vector(&torque),
            tilt,
        }
    }
}

/// The rotation (tool frame) that takes the tool axis of `r_tool` onto `n` (path frame).
fn tilt_of(r_tool: &UnitQuaternion<f64>, n: &Vector3<f64>) -> Vector3<f64> {
    let nt = r_tool.inverse_transform_vector(n);
    let axis = Vector3::new(-nt.y, nt.x, 0.0);
    let s = axis.norm();
    if s < 1e-15 {
        return Vector3::zeros();
    }
    axis * (nt.z.clamp(-1.0, 1.0).acos() / s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(r: f64) -> Geometry {
        Geometry {
            shape: Shape::Flat,
            misplace_x: 0.0,
            misplace_y: 0.0,
            pad_radius: r,
            friction: 0.0,
            tool_length: 0.1,
            program_tilt: 0.0,
        }
    }

    #[test]
    fn a_flat_part_square_to_the_tool_is_the_one_dof_spring() {
        let c = Contact::new(flat(0.02), InnerLoopModel::P0);
        let st = c.state(10_000.0, 0.0, 0.003, 0.0, 0.05, 0.05, 0.001);
        assert!((st.normal - 20.0).abs() < 1e-9, "{st:?}");
        assert!((st.force - Vector3::new(0.0, 0.0, 20.0)).norm() < 1e-9);
        assert!(st.torque.norm() < 1e-12 && st.tilt.norm() < 1e-12);
        // Out of touch: nothing.
        let st = c.state(10_000.0, 0.0, 0.0005, 0.0, 0.05, 0.05, 0.001);
        assert_eq!(st.normal, 0.0);
    }

    #[test]
    fn full_contact_moment_is_k_r2_sin_phi_over_4_and_partial_contact_joins_it() {
        let (k, r) = (10_000.0, 0.02);
        let g = 0.05;
        let (n, q) = pad_contact(k, r, 0.002, g);
        assert_eq!(n, 20.0);
        assert!((q - k * g * r * r / 4.0).abs() < 1e-15);
        // Just below full contact the integral agrees with the closed form.
        let (n2, q2) = pad_contact(k, r, g * r * 0.999_999, g);
        let (n3, q3) = pad_contact(k, r, g * r, g);
        assert!((n2 - n3).abs() < 1e-3 * n3, "{n2} {n3}");
        assert!((q2 - q3).abs() < 1e-3 * q3, "{q2} {q3}");
        // On the edge only: less force than a full pad at that depth, and the centre towards the edge.
        let (n4, q4) = pad_contact(k, r, 0.0, g);
        assert!(n4 > 0.0 && q4 / n4 > r / 2.0, "{n4} {q4}");
        assert_eq!(pad_contact(k, r, -g * r, g), (0.0, 0.0));
    }

    #[test]
    fn a_tilted_flat_part_gives_the_tilt_the_moment_and_a_turn_that_cancels_them() {
        let mut g = flat(0.02);
        g.misplace_x = 0.05;
        g.tool_length = 0.0;
        let mut c = Contact::new(g, InnerLoopModel::P0);
        let st = c.state(10_000.0, 0.0, 0.003, 0.0, 0.0, 0.0, 0.001);
        // Normal n = (0, −tan r, 1)/‖·‖: the rotation from the tool axis onto it is r about x.
        assert!(
            (st.tilt - Vector3::new(0.05, 0.0, 0.0)).norm() < 1e-9,
            "{:?}",
            st.tilt
        );
        // Moment about the TCP: −K·ψ with K = k r²/4 (to first order in ψ).
        let r: f64 = 0.02;
        let kr = 10_000.0 * r * r / 4.0;
        let m = -kr * (0.05f64).sin() * (0.05f64).cos();
        assert!((st.torque.x - m).abs() < 0.01 * m.abs(), "{:?}", st.torque);
        assert!(st.torque.y.abs() < 1e-12);
        // Turn the tool by the tilt: square to the part, no moment.
        c.advance(Some(st.tilt), 0.0);
        let st = c.state(10_000.0, 0.0, 0.003, 0.0, 0.0, 0.0, 0.001);
        assert!(st.tilt.norm() < 1e-9 && st.torque.norm() < 1e-9, "{st:?}");
    }

    #[test]
    fn friction_acts_against_the_feed_with_its_lever_at_the_sensor() {
        let mut g = flat(0.02);
        g.friction = 0.3;
        let c = Contact::new(g, InnerLoopModel::P0);
        let st = c.state(10_000.0, 0.0, 0.003, 0.0, 0.0, 0.1, 0.001);
        // The tool drags the part along the feed: +x on the part, μ·N.
        assert!((st.force.x - 6.0).abs() < 1e-9, "{:?}", st.force);
        // Its moment about the sensor 0.1 m behind the pad: (L·z) × (F_x·x) = L·F_x about y.
        assert!((st.torque.y - 0.6).abs() < 1e-9, "{:?}", st.torque);
        let still = c.state(10_000.0, 0.0, 0.003, 0.0, 0.0, 0.0, 0.001);
        assert_eq!(still.force.x, 0.0);
    }

    #[test]
    fn shapes_give_their_slopes() {
        let mut g = flat(0.02);
        g.shape = Shape::Cylinder {
            radius: 0.15,
            axis: Axis::Across,
            centre: 0.05,
        };
        let (h, gu, gv) = g.surface(0.05 + 0.03).unwrap();
        assert!((h - (0.15 - (0.15f64 * 0.15 - 0.0009).sqrt())).abs() < 1e-12);
        assert!((gu - 0.03 / (0.15f64 * 0.15 - 0.0009).sqrt()).abs() < 1e-12 && gv == 0.0);
        assert!(g.surface(0.3).is_none());
        g.shape = Shape::Saddle {
            radius: 0.2,
            angle: core::f64::consts::FRAC_PI_4,
            centre: 0.0,
        };
        let (h, gu, gv) = g.surface(0.02).unwrap();
        assert!(h.abs() < 1e-12 && gu.abs() < 1e-12 && (gv - 0.1).abs() < 1e-12);
        g.shape = Shape::Flat;
        g.misplace_y = 0.1;
        let (h, gu, _) = g.surface(0.02).unwrap();
        assert!((h + 0.02 * 0.1f64.tan()).abs() < 1e-15 && (gu + 0.1f64.tan()).abs() < 1e-15);
        g.pad_radius = 0.0;
        assert!(g.validate().unwrap_err().contains("pad_radius"));
    }

    #[test]
    fn the_rotation_goes_through_the_inner_loops_lag_and_delay() {
        let mut c = Contact::new(flat(0.02), InnerLoopModel::P2);
        for _ in 0..3 {
            c.advance(Some(Vector3::new(0.01, -0.02, 0.0)), 0.0);
            assert_eq!(c.rotation(), Vector3::zeros(), "delay");
        }
        c.advance(Some(Vector3::new(f64::NAN, 0.0, 0.0)), 0.0);
        assert!(c.rotation().x > 0.0 && c.rotation().y < 0.0);
        for _ in 0..200 {
            c.advance(None, 0.0);
        }
        assert!((c.rotation() - Vector3::new(0.01, -0.02, 0.0)).norm() < 1e-9);
    }
}
