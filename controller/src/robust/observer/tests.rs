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
