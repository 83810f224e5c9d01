//! The surface predictor's unit tests.

use super::*;

#[test]
fn tracks_a_sine_and_inverts_the_loop() {
    let dt: f64 = 1e-3;
    let (delay, lag): (f64, f64) = (0.004, 0.010);
    let mut p = SurfacePredictor::new();
    let xc = |t: f64| 0.001 * (core::f64::consts::TAU * t).sin();
    // The inner loop: a queue of `delay/dt` commands, then the lag.
    let alpha = 1.0 - (-dt / lag).exp();
    let mut queue = [0.0; 4];
    let mut x = 0.0;
    let mut worst: f64 = 0.0;
    for k in 0..4000 {
        let t = k as f64 * dt;
        if k > 2000 {
            worst = worst.max((x - xc(t)).abs());
        }
        p.update(xc(t), 1e-14, 1e-3, dt, &JumpTest::gated(6.0, 1e-5));
        let u = p.command(0.0, delay, lag, dt, f64::INFINITY);
        let applied = queue[k % 4];
        queue[k % 4] = u;
        x += alpha * (applied - x);
    }
    // 1 µm of 1 mm amplitude: 0.07 N at 70 kN/m.
    assert!(worst < 1e-6, "tracking error {worst} m");
}

/// The most the tool, driven by the command through the inner loop, runs past a surface that
/// starts to move at 3 mm/s after 0.5 s at rest (P2's cycle: 4 ms, 12 ms delay, 10 ms lag), m.
/// With the largest acceleration the filter estimated meanwhile, m/s².
fn overshoot_after_a_velocity_step(max_acceleration: f64) -> (f64, f64) {
    let (dt, delay, lag, v): (f64, f64, f64, f64) = (0.004, 0.012, 0.010, 0.003);
    let mut p = SurfacePredictor::new();
    let xc = |t: f64| v * (t - 0.5).max(0.0);
    let alpha = 1.0 - (-dt / lag).exp();
    let mut queue = [0.0; 3];
    let (mut x, mut worst, mut accel) = (0.0, 0.0f64, 0.0f64);
    for k in 0..250 {
        let t = k as f64 * dt;
        worst = worst.max(x - xc(t));
        p.update(xc(t), 1e-14, 1e-3, dt, &JumpTest::gated(6.0, 1e-3));
        accel = accel.max(p.state()[2].abs());
        let u = p.command(0.0, delay, lag, dt, max_acceleration);
        let applied = queue[k % 3];
        queue[k % 3] = u;
        x += alpha * (applied - x);
    }
    (worst, accel)
}

/// To the constant-acceleration model a velocity step is an acceleration of 0.2 m/s², which the
/// command carried over the lead time: the tool ran 37 µm past the surface's path (11 N on
/// 300 kN/m). Bounded to 0.05 m/s² (the shipped `response.surface_acceleration`): 19 µm while the
/// velocity the filter inferred with the excess acceleration was kept, 12 µm with it taken along.
#[test]
fn a_surface_that_starts_at_full_speed_is_not_extrapolated_past_its_path() {
    let (bounded, _) = overshoot_after_a_velocity_step(0.05);
    assert!(bounded < 15e-6, "{bounded} m past the surface");
    let (free, accel) = overshoot_after_a_velocity_step(f64::INFINITY);
    assert!(free > 30e-6, "{free} m past the surface");
    assert!((0.15..0.25).contains(&accel), "{accel} m/s²");
}

#[test]
fn noise_lowers_the_bandwidth() {
    // The same white noise (σ = 7 µm: 0.5 N at 70 kN/m) on a still surface, told as it is and told
    // as if the sensor were clean: the velocity estimate must be much quieter when R is right.
    let sigma = 7e-6;
    let velocity_std = |r: f64| {
        let mut p = SurfacePredictor::new();
        let mut seed: u64 = 12345;
        let (mut sum, mut n) = (0.0, 0.0);
        for k in 0..20_000 {
            // Sum of uniforms: roughly Gaussian, deterministic.
            let mut u = 0.0;
            for _ in 0..12 {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                u += (seed >> 11) as f64 / (1u64 << 53) as f64;
            }
            p.update(
                sigma * (u - 6.0),
                r,
                1e-3,
                1e-3,
                &JumpTest::gated(6.0, 1e-3),
            );
            if k > 2000 {
                sum += p.state()[1].powi(2);
                n += 1.0;
            }
        }
        (sum / n).sqrt()
    };
    let told = velocity_std(sigma * sigma);
    let untold = velocity_std((0.02f64 / 70_000.0).powi(2));
    assert!(told < 0.25 * untold, "told {told} m/s, untold {untold} m/s");
    assert!(told < 2e-4, "velocity noise {told} m/s");
}

#[test]
fn a_step_is_a_jump_not_a_velocity() {
    let mut p = SurfacePredictor::new();
    let test = JumpTest::gated(6.0, 1e-5);
    for _ in 0..100 {
        p.update(0.0, 1e-14, 1e-3, 1e-3, &test);
    }
    assert_eq!(p.update(0.001, 1e-14, 1e-3, 1e-3, &test), Some(0.001));
    let [x, v, a] = p.state();
    assert_eq!((x, v, a), (0.001, 0.0, 0.0));
}

/// A surface at rest for 100 samples of `dt`, then `z(k)` for samples `k = 1, 2, …` under a test
/// that takes anything beyond 1 µm for a jump: what the filter made of each sample.
fn after_rest(dt: f64, z: impl Fn(f64) -> f64, n: usize) -> Vec<(Option<f64>, [f64; 3])> {
    let (mut p, test) = (SurfacePredictor::new(), JumpTest::gated(6.0, 1e-6));
    for _ in 0..100 {
        p.update(0.0, 1e-14, 1e-3, dt, &test);
    }
    (1..=n)
        .map(|k| (p.update(z(k as f64), 1e-14, 1e-3, dt, &test), p.state()))
        .collect()
}

/// A surface that starts to move at 6.3 mm/s under a clean sensor: 6.3 µm a sample at 1 kHz,
/// every one far beyond the noise (on 500 kN/m 3.1 N a sample). Its first two samples are
/// jumps; the third, the same size again, makes the three a ramp, tracked at its speed from then
/// on (read as jumps for the conditioning's step time, 31 ms on P1, the force rose 40 N before
/// any of the motion was fed forward).
#[test]
fn jumps_in_a_row_of_the_same_size_are_a_ramp() {
    let (dt, v) = (1e-3, 6.3e-3);
    let out = after_rest(dt, |k| v * dt * k, 10);
    assert!(out[0].0.is_some() && out[1].0.is_some());
    assert_eq!(out[2].0, None);
    assert!((out[2].1[1] - v).abs() < 1e-9, "{:?}", out[2].1);
    for (jump, [_, speed, _]) in &out[3..] {
        assert_eq!(*jump, None);
        assert!((speed - v).abs() < 0.05 * v, "{speed} m/s");
    }
}

/// A surface tracked at 1 mm/s that goes on at 7 mm/s: its three jumps of 6 µm are a ramp at
/// 7 mm/s, the motion the jumps kept and theirs (not 6 mm/s).
#[test]
fn a_ramp_from_a_moving_surface_keeps_the_motion_before_it() {
    let (dt, test) = (1e-3, JumpTest::gated(6.0, 1e-6));
    let mut p = SurfacePredictor::new();
    let mut z = 0.0;
    for _ in 0..500 {
        z += 1e-3 * dt;
        p.update(z, 1e-14, 1e-3, dt, &test);
    }
    assert!((p.state()[1] - 1e-3).abs() < 1e-6, "{:?}", p.state());
    let out: Vec<_> = (0..3)
        .map(|_| {
            z += 7e-3 * dt;
            p.update(z, 1e-14, 1e-3, dt, &test)
        })
        .collect();
    assert!(out[0].is_some() && out[1].is_some() && out[2].is_none());
    assert!((p.state()[1] - 7e-3).abs() < 1e-5, "{:?}", p.state());
}

/// A 0.3 mm step seen through a sensor's own first-order filter of three samples: every sample
/// a jump, each 28 % smaller than the one before — no ramp, no velocity. (A filter slower than
/// about nine samples would pass for one.)
#[test]
fn a_step_through_a_sensor_filter_is_no_ramp() {
    let out = after_rest(1e-3, |k| 3e-4 * (1.0 - (-k / 3.0).exp()), 12);
    for (jump, [_, speed, _]) in &out {
        assert!(jump.is_some());
        assert_eq!(*speed, 0.0);
    }
}

/// A velocity step read as an acceleration (a sine that starts at full speed), then samples
/// that each contradict the prediction (a contact lost and regained: `x − f/k̂_c` is the bouncing
/// tool's own position): the motion stays what it was before them. Carried through every jump,
/// the acceleration was integrated into the velocity on each (on the 12 ms cell 4 → 13 mm/s in
/// five samples, fed forward into a 181 N re-contact on 300 kN/m).
#[test]
fn jumps_do_not_integrate_the_motion_they_contradict() {
    let (dt, test) = (12e-3, JumpTest::gated(6.0, 1e-4));
    let mut p = SurfacePredictor::new();
    for _ in 0..100 {
        p.update(0.0, 1e-14, 1e-3, dt, &test);
    }
    // The surface starts away at 3 mm/s: the filter reads it as an acceleration.
    let mut z = 0.0;
    for _ in 0..2 {
        z += 3e-3 * dt;
        assert_eq!(p.update(z, 1e-14, 1e-3, dt, &test), None);
    }
    let [_, v0, a0] = p.state();
    assert!(
        a0 > 0.05,
        "a velocity step reads as an acceleration: {a0} m/s²"
    );
    // Samples 0.3 mm either side: every one a jump.
    for i in 0..5 {
        let y = z + if i % 2 == 0 { -3e-4 } else { 3e-4 };
        assert!(p.update(y, 1e-14, 1e-3, dt, &test).is_some());
        let [x, v, a] = p.state();
        assert_eq!((x, v, a), (y, v0, a0));
    }
}

/// A still surface measured at `r` for 100 steps of 4 ms, then `z`: what the filter made of it.
fn after_still(z: f64, test: &JumpTest) -> (Option<f64>, f64) {
    let mut p = SurfacePredictor::new();
    for _ in 0..100 {
        p.update(0.0, 1e-12, 1e-3, 4e-3, test);
    }
    let out = p.update(z, 1e-12, 1e-3, 4e-3, test);
    (out, p.state()[1])
}

#[test]
fn a_step_below_the_floor_is_a_jump_where_no_motion_or_robot_explains_it() {
    // 0.3 mm on a surface measured to 1 µm, under a 0.5 mm floor (a soft pad's).
    let mut test = JumpTest {
        gate: 6.0,
        floor: 5e-4,
        step_gate: 70.0,
        step_floor: 2e-6,
    };
    assert_eq!(after_still(3e-4, &test), (Some(3e-4), 0.0));
    // The gate and the floor alone: the same step would be a surface velocity.
    let (out, v) = after_still(3e-4, &JumpTest::gated(6.0, 5e-4));
    assert!(out.is_none() && v > 0.01, "{out:?}, {v} m/s");
    // A robot that moved 0.4 mm in the cycle explains it (a stale k̂_c's apparent motion).
    test.step_floor = 4e-4;
    assert!(after_still(3e-4, &test).0.is_none());
    // Within the step gate (the start of real motion) it is motion.
    test.step_floor = 2e-6;
    let (out, v) = after_still(2e-5, &test);
    assert!(out.is_none() && v > 0.0, "{out:?}, {v} m/s");
}
