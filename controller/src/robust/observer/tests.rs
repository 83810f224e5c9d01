//! Unit tests of the surface observer.

use super::*;
use crate::robust::Context;
use crate::robust::noise::NoiseEstimate;

/// A step's context with the cell's `lag` and `delay`, the `cycle`, the whole `lead` and the step `dt`
/// (what the feed-forward reads of it).
fn ctx(lag: f64, delay: f64, cycle: f64, lead: f64, dt: f64) -> Context {
    Context {
        dt,
        cycle,
        set_point: 5.0,
        force_scale: 5.0,
        noise: NoiseEstimate {
            var: 0.0,
            std: 0.0,
            age: 0.0,
        },
        noise_gain: 1.0,
        step_time: 0.03,
        filter_delay: 0.0,
        lag,
        loop_delay: delay,
        lead,
    }
}

fn view(xf: f64, ff: f64) -> View {
    View {
        x: xf,
        f: ff,
        xf,
        ff,
        v_raw: 0.0,
        k: 70_000.0,
        force_scale: 5.0,
        noise_var: 0.0,
        noise_gain: 1.0,
        step_time: 0.03,
    }
}

#[test]
fn a_step_moves_the_observed_surface_without_a_velocity_kick() {
    let mut o = SurfaceObserver::new(ObserverParams::default());
    o.restart(0.010);
    // The surface seen jumps 0.5 mm (35 N at the same position).
    o.track(&view(0.0105, 0.0), 8.0, 1e-3);
    assert_eq!(o.surface(), 0.0105);
    assert_eq!(o.receding(), 0.0);
    assert!(o.disturbed(), "a jump is a disturbance");
}

#[test]
fn a_still_surface_stays_still_and_a_moving_one_is_followed() {
    let mut o = SurfaceObserver::new(ObserverParams::default());
    o.restart(0.010);
    for _ in 0..1000 {
        o.track(&view(0.010 + 5.0 / 70_000.0, 5.0), 8.0, 1e-3);
    }
    assert!((o.surface() - 0.010).abs() < 1e-12 && !o.disturbed());
    for i in 0..1000 {
        let z = 0.010 + 0.002 * i as f64 * 1e-3;
        o.track(&view(z + 5.0 / 70_000.0, 5.0), 8.0, 1e-3);
    }
    assert!((o.receding() - 0.002).abs() < 1e-4, "{}", o.receding());
    o.reset();
    assert!(o.surface().is_nan() && !o.disturbed());
}

fn response() -> crate::robust::ResponseParams {
    crate::robust::ResponseParams {
        kappa: 0.8,
        integral: 1.5,
        integral_noise: 0.1,
        surface_bandwidth: 8.0,
        surface_jerk: 1e-3,
        surface_acceleration: 0.05,
        noise_floor: 0.02,
        feedforward_deadband: 6e-4,
        set_point_rate: 50.0,
        noise_gate: 1.0,
        integration_band: 0.05,
        jump_caution: 2.0,
    }
}

#[test]
fn a_jump_seen_raw_starts_a_jump_and_is_no_motion_while_it_passes() {
    let r = response();
    let (dt, x) = (1e-3, 0.010 + 5.0 / 70_000.0);
    let mut o = SurfaceObserver::new(ObserverParams::default());
    o.restart(0.010);
    let step = |o: &mut SurfaceObserver, f: f64, ff: f64| {
        let s = View {
            f,
            ff,
            ..view(x, ff)
        };
        o.track(&s, 8.0, dt);
        o.feedforward(&s, &ctx(0.01, 0.004, dt, 0.03, dt), &r, 1e-3);
    };
    for _ in 0..200 {
        step(&mut o, 5.0, 5.0);
    }
    // The stiffness quadruples under the still tool: the raw force jumps to 20 N at once, the
    // conditioned one rises over the step time; the tool has not moved yet.
    let mut moving = false;
    for i in 1..=25 {
        let ff = 5.0 + 15.0 * (i as f64 / 25.0);
        step(&mut o, 20.0, ff);
        if i == 1 {
            assert!(o.jump_on_still_surface(), "the raw jump starts a jump");
        }
        moving |= o.hold(0.0, 1e-3, true, dt).moving;
    }
    assert!(
        !moving && o.still(),
        "the passing step was taken for motion"
    );
}

/// A soft pad (10 N/mm) pressed at 20 N on a 4 ms cycle, still, then the part steps 0.3 mm away under
/// the still tool (−3 N at once raw, over the step time conditioned): below the observer's jump floor
/// (a quarter of the 2 mm penetration). Returns whether motion was established, the largest fallback
/// feed-forward and the observed surface at the end.
fn soft_pad_step(p: ObserverParams) -> (bool, f64, f64) {
    let (r, dt, k) = (response(), 4e-3, 10_000.0);
    let x = 0.010 + 20.0 / k;
    let mut o = SurfaceObserver::new(p);
    o.restart(0.010);
    let step = |o: &mut SurfaceObserver, f: f64, ff: f64| {
        let s = View {
            f,
            ff,
            k,
            force_scale: 20.0,
            step_time: 0.03,
            ..view(x, ff)
        };
        o.track(&s, 8.0, dt);
        let ff = o.feedforward(&s, &ctx(0.01, 0.012, dt, 0.03, dt), &r, 1e-3);
        o.hold(0.0, 1e-3, true, dt);
        (ff.weight, ff.fallback)
    };
    for _ in 0..100 {
        step(&mut o, 20.0, 20.0);
    }
    let (mut established, mut fallback) = (false, 0.0f64);
    for i in 1..=50 {
        let ff = 20.0 - 3.0 * (i as f64 / 8.0).min(1.0);
        let (w, fb) = step(&mut o, 17.0, ff);
        established |= w > 0.0 || !o.still();
        fallback = fallback.max(fb.abs());
    }
    (established, fallback, o.surface())
}

#[test]
fn a_step_below_the_floor_that_nothing_else_explains_is_no_motion() {
    let (established, fallback, surface) = soft_pad_step(ObserverParams::default());
    assert!(!established, "the step was taken for motion");
    assert!(fallback < 1e-6, "fed forward {fallback} m");
    assert!((surface - 0.0103).abs() < 1e-6, "surface at {surface} m");
    // Without the step gate the same step is a motion, and the feed-forward throws the tool.
    let old = ObserverParams {
        step_gate: f64::INFINITY,
        ..ObserverParams::default()
    };
    let (established, fallback, _) = soft_pad_step(old);
    assert!(
        established && fallback > 1e-5,
        "{established}, {fallback} m"
    );
}

/// The fallback's dead-band scales with the noise seen on the observer's velocity: with the sensor's
/// noise over the stiffness, not with the noise alone.
#[test]
fn the_fallback_dead_band_is_outside_the_velocity_noise() {
    let (p, r) = (ObserverParams::default(), response());
    // Noise-free: the floor.
    assert_eq!(p.deadband(&r, 0.0, 0.7, 10_000.0), p.feedforward_speed);
    // σ 1 N, 73 % through the conditioning (a 12 ms cycle), 10 kN/m: beyond the per-newton dead-band.
    let soft = p.deadband(&r, 1.0, 0.73, 10_000.0);
    let scale = 0.73 / 10_000.0 * core::f64::consts::TAU * r.surface_bandwidth;
    assert!(
        (soft - 2.0 * scale).abs() < 1e-12 && soft > r.feedforward_deadband,
        "{soft}"
    );
    // Stiff and filtered (1 ms): the per-newton dead-band as before.
    assert_eq!(p.deadband(&r, 1.0, 0.21, 500_000.0), r.feedforward_deadband);
}

/// A still surface held at 48 N on a 12 ms cell while the recursion takes `k̂_c` down 12 % a cycle
/// (its fastest fall, 10/s) from 298 kN/m: the observed surface `x − f/k̂_c` moves 22 µm a cycle, and
/// that is the model changing, not the surface. Read as motion, the predictor fed forward 0.2 mm
/// the wrong way in one cycle (a sine receding at 0.79 mm/s on 300 kN/m at f_r 50 N: the loop rang
/// and pressed 457 N before the trip).
#[test]
fn a_new_stiffness_estimate_is_no_surface_motion() {
    let (r, dt, f) = (response(), 12e-3, 48.0);
    let mut o = SurfaceObserver::new(ObserverParams::default());
    let mut k = 298e3;
    let x = 0.010 + f / k;
    o.restart(0.010);
    let step = |o: &mut SurfaceObserver, k: f64| {
        let s = View {
            k,
            force_scale: f,
            ..view(x, f)
        };
        o.track(&s, 8.0, dt);
        o.feedforward(&s, &ctx(0.010, 0.024, dt, 0.04, dt), &r, 1e-3)
    };
    for _ in 0..50 {
        step(&mut o, k);
    }
    for _ in 0..4 {
        k *= 1.0 - 10.0 * dt;
        let ff = step(&mut o, k);
        assert!(
            ff.predicted.abs() < 1e-6 && ff.fallback.abs() < 1e-6,
            "fed forward {} m (fallback {} m) at k̂_c {k:.0} N/m",
            ff.predicted,
            ff.fallback
        );
        assert!((o.surface() - (x - f / k)).abs() < 1e-9, "{}", o.surface());
        assert!(o.receding() < 1e-9, "{} m/s", o.receding());
    }
}

/// A tracker that learnt a surface's motion on a slow cell, the surface then still: each cycle its
/// velocity carried it more than the jump threshold off the measurement (0.2 mm/s is 2.4 µm a 12 ms
/// cycle, the threshold a quarter of 2 N on 500 kN/m, 1 µm), which was taken for a jump — the
/// position reset, the velocity kept — and the velocity never decayed. Where the measurement stayed
/// put, that innovation is the velocity contradicted.
#[test]
fn a_velocity_a_still_surface_contradicts_every_cycle_decays() {
    let (dt, k, f) = (0.012, 500_000.0, 2.0);
    let at = |z: f64| View {
        k,
        force_scale: f,
        step_time: 0.048,
        ..view(z + f / k, f)
    };
    let mut o = SurfaceObserver::new(ObserverParams::default());
    o.restart(0.010);
    let mut z = 0.010;
    for _ in 0..100 {
        z += 2e-4 * dt;
        o.track(&at(z), 8.0, dt);
    }
    assert!(
        o.receding() > 1e-4,
        "the motion learnt: {} m/s",
        o.receding()
    );
    for _ in 0..200 {
        o.track(&at(z), 8.0, dt);
    }
    assert!(
        o.receding() < 1e-6,
        "still after 2.4 s: {} m/s",
        o.receding()
    );
    assert!((o.surface() - z).abs() < 1e-7, "{} m off", o.surface() - z);
}
