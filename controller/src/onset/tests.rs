//! The onset fit's unit tests.

use super::*;

#[test]
fn finds_the_break_and_the_slope() {
    let (k, xc, s) = (70_000.0, 0.010, 1e-4);
    let mut o = OnsetFit::new();
    let mut x = 0.00996;
    for _ in 0..40 {
        o.remember(x, (k * (x - xc)).max(0.0), 0.002, 48);
        x += 2e-6;
    }
    o.begin(x, s, 0.1);
    let fit = o.fit(0.0).unwrap();
    assert!((fit.b / s - k).abs() < 1.0, "k {}", fit.b / s);
    assert!((fit.a - k * (x - xc)).abs() < 1e-6);
}

/// A damped transient: `f = k·(x − x_c) + c_e·ẋ` with the tool settling and a wobble on top.
fn damped(o: &mut OnsetFit, k: f64, xc: f64, c_e: f64) {
    let dt = 1e-3;
    for i in 0..300 {
        let t = i as f64 * dt;
        let x = 0.0101 - 5e-5 * (-t / 0.02).exp() + 2e-6 * (t * 40.0).sin();
        let v = 5e-5 / 0.02 * (-t / 0.02).exp() + 2e-6 * 40.0 * (t * 40.0).cos();
        o.add(x, k * (x - xc) + c_e * v, v, dt);
    }
}

#[test]
fn the_damping_is_fitted_with_the_stiffness() {
    let (k, xc, c_e, s) = (70_000.0, 0.010, 200.0, 1e-4);
    let mut o = OnsetFit::new();
    o.begin(0.0101, s, 1.0);
    damped(&mut o, k, xc, c_e);
    let fit = o.fit(0.0).unwrap();
    assert!((fit.b / s - k).abs() < 1e-3 * k, "k {}", fit.b / s);
    assert!((fit.c / s - c_e).abs() < 1e-3 * c_e, "c_e {}", fit.c / s);
    let (through, _) = o.fit_through(xc, 0.0).unwrap();
    assert!((through.b / s - k).abs() < 1e-3 * k, "k {}", through.b / s);
    assert!(through.sse < 1e-9, "{}", through.sse);
    // Through a surface 10 µm off the line leaves a residual.
    let off = o.fit_through(xc + 1e-5, 0.0).unwrap().0.sse;
    assert!(off > 1e-3, "{off}");
}

/// A window of the tool settling (a loop's answer: not at a constant speed) into a surface of
/// stiffness `k` at `xc(t)`.
fn settling(o: &mut OnsetFit, k: f64, xc: impl Fn(f64) -> f64) {
    let dt = 4e-3;
    for i in 0..75 {
        let t = i as f64 * dt;
        let x = 0.0101 + 5e-5 * (1.0 - (-t / 0.05).exp());
        let v = 5e-5 / 0.05 * (-t / 0.05).exp();
        o.add(x, k * (x - xc(t)), v, dt);
    }
}

#[test]
fn a_moving_surface_and_a_changed_stiffness_are_told_apart() {
    let (k, s) = (200_000.0, 1e-4);
    // The stale stiffness on a surface moving at 0.15 mm/s: the moving fit explains the window,
    // the stiffness line does not.
    let mut o = OnsetFit::new();
    o.begin(0.0101, s, 1.0);
    o.also_moving(k * s, 0.0, 1e-4);
    settling(&mut o, k, |t| 0.010 + 1.5e-4 * t);
    let moving = o.moving_sse().unwrap();
    let line = o.fit(0.0).unwrap().sse;
    assert!(moving < 1e-9, "{moving}");
    assert!(line > 1e3 * moving.max(1e-12), "{line}");
    // The stiffness halved on a still surface: the other way round (whatever speed the moving fit
    // puts on the surface).
    let mut o = OnsetFit::new();
    o.begin(0.0101, s, 1.0);
    o.also_moving(k * s, 0.0, 0.0);
    settling(&mut o, 0.5 * k, |_| 0.010);
    let moving = o.moving_sse().unwrap();
    let (through, _) = o.fit_through(0.010, 0.0).unwrap();
    assert!(through.sse < 1e-9, "{}", through.sse);
    assert!(moving > 1e-2, "{moving}");
    // Not asked for: none.
    let mut o = OnsetFit::new();
    o.begin(0.0101, s, 1.0);
    settling(&mut o, k, |_| 0.010);
    assert!(o.moving_sse().is_none());
    // A surface crawling at 0.05 mm/s, below the slowest motion the law acts on (0.1 mm/s): no
    // moving surface, however well it fits.
    let crawl = |slowest: f64| {
        let mut o = OnsetFit::new();
        o.begin(0.0101, s, 1.0);
        o.also_moving(k * s, 0.0, slowest);
        settling(&mut o, k, |t| 0.010 + 5e-5 * t);
        o.moving_sse()
    };
    assert!(crawl(0.0).is_some_and(|sse| sse < 1e-9));
    assert_eq!(crawl(1e-4), None);
}

/// A sample passed (a bounce in the window) still counts the moving surface's time.
#[test]
fn a_passed_sample_keeps_the_moving_fit_s_clock() {
    let (k, s, dt) = (200_000.0, 1e-4, 4e-3);
    let mut o = OnsetFit::new();
    o.begin(0.0101, s, 1.0);
    o.also_moving(k * s, 0.0, 1e-4);
    for i in 0..75 {
        let t = i as f64 * dt;
        let x = 0.0101 + 5e-5 * (1.0 - (-t / 0.05).exp());
        if (30..35).contains(&i) {
            o.pass(dt);
        } else {
            o.add(x, k * (x - 0.010 - 1.5e-4 * t), 0.0, dt);
        }
    }
    let moving = o.moving_sse().unwrap();
    assert!(moving < 1e-9, "{moving}");
}
