//! Unit tests of the surface observer.

use super::*;

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

#[test]
fn a_jump_seen_raw_starts_a_jump_and_is_no_motion_while_it_passes() {
    let r = crate::robust::ResponseParams {
        kappa: 0.8,
        integral: 1.5,
        integral_limit: 3e-4,
        surface_bandwidth: 8.0,
        surface_jerk: 1e-3,
        noise_floor: 0.02,
        feedforward_deadband: 6e-4,
        set_point_rate: 50.0,
        noise_gate: 1.0,
        integration_band: 0.05,
    };
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
        o.feedforward(&s, &r, 1e-3, 0.01, 0.004, dt, 0.03, dt);
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
        moving |= o.hold(0.0, 1e-3, true, dt);
    }
    assert!(
        !moving && o.still(),
        "the passing step was taken for motion"
    );
}
