//! Unit tests of the identification stage.

use super::*;
use crate::robust::contact::Search;

fn est() -> EstimatorParams {
    EstimatorParams {
        kc0: 50_000.0,
        kc_min: 10_000.0,
        kc_max: 500_000.0,
        memory: 0.3,
        excitation: 1.5,
        excitation_window: 0.05,
        initial_uncertainty: 1.0,
        max_surface_speed: 0.001,
    }
}

#[test]
fn the_onset_of_a_contact_from_the_approach_is_fitted() {
    let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, 5.0 / 50_000.0);
    let k: f64 = 70_000.0;
    let mut x: f64 = 0.0095;
    let (mut seeded, mut contact) = (false, false);
    for _ in 0..2000 {
        let f = (k * (x - 0.010)).max(0.0);
        let mut first = false;
        if !contact {
            if f < 1.0 {
                id.remember(x, f, 2e-3, 1e-3);
                x += 2e-6;
                continue;
            }
            contact = true;
            first = true;
            id.begin_contact(x, f, true);
        }
        let out = id.step(
            x,
            f,
            0.0,
            f,
            1e-3,
            StepState {
                first,
                ..StepState::default()
            },
            0.0,
            0.02,
        );
        seeded |= out.seeded;
        if x < 0.010 + 5.0 / k {
            x += 2e-6;
        }
    }
    assert!(seeded, "the transient was fitted");
    assert!((id.kc() - k).abs() < 0.02 * k, "k̂ {}", id.kc());
    assert!(id.kc_rel_sd() < 0.1, "the fit knows k̂: {}", id.kc_rel_sd());
    id.reset();
    assert_eq!(id.kc(), 50_000.0);
    // Back at the tuning's guess, nothing is known of it: no fit's confidence survives a reset
    // (the fast search's margin and a re-contact's confidence come from it).
    assert_eq!(id.kc_rel_sd(), est().initial_uncertainty);
}

/// A touch-down on a surface four times softer than the tuning's guess: seen through the guess, the
/// tool's own motion looks like the surface's (the observer's surface `x − f/k̂_c` moves with three
/// quarters of it), and the motion test calls it moving from the first step. That ended the window
/// before its fit (f_r 43 N on 12.6 kN/m on P2 under σ 0.68 N: the landing ended on the guess, the
/// command ran in at 30 mm/s, and `k̂_c` ended twice too stiff with the force ringing 34–51 N). A
/// touch-down's window is not ended by motion before its fit is significant; after, it is.
/// A noise-free touch-down on a spring of stiffness `k` (N/m) at 10 mm, approached at `v` (m/s) on a
/// cycle `dt` (s), the tuning's guess 50 kN/m at set-point `f_r`: the approach is remembered, contact
/// is declared at 1 N, and the contact goes on in at `v` for at most `steps` steps (with the motion
/// test calling the surface `moving`) until the fit sets `k̂_c`. Whether it did, and the last position.
fn touch_down_on(
    k: f64,
    f_r: f64,
    v: f64,
    dt: f64,
    steps: usize,
    moving: bool,
) -> (Identifier, bool, f64) {
    let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, f_r / 50_000.0);
    let force = |x: f64| (k * (x - 0.010)).max(0.0);
    let mut x = 0.0099;
    while force(x) < 1.0 {
        id.remember(x, force(x), v, dt);
        x += v * dt;
    }
    id.begin_contact(x, force(x), true);
    for i in 0..steps {
        let state = StepState {
            first: i == 0,
            moving,
            ..StepState::default()
        };
        if id
            .step(x, force(x), v, force(x), dt, state, 0.0, 0.02)
            .seeded
        {
            return (id, true, x);
        }
        x += v * dt;
    }
    (id, false, x)
}

#[test]
fn a_touch_down_window_outlasts_motion_seen_through_the_guess() {
    let k = 12_565.0;
    let (mut id, seeded, x) = touch_down_on(k, 43.0, 2e-3, 4e-3, 10, true);
    assert!(seeded, "the window ended on the motion the guess shows");
    assert!((id.kc() - k).abs() < 0.05 * k, "k̂ {}", id.kc());
    // Fitted, the surface is seen through the surface's own stiffness: motion ends the window.
    let (x, f) = (x + 8e-6, k * (x + 8e-6 - 0.010));
    let moving = StepState {
        moving: true,
        ..StepState::default()
    };
    id.step(x, f, 2e-3, f, 4e-3, moving, 0.0, 0.02);
    assert!(!id.onset_open());
}

/// A touch-down on the 12 ms cell that bounces within the onset window (f_r 2.6 N on 355 kN/m, the
/// samples of `surface_steps`' 1000-case find, mm): the sample off the surface is on the hinge's flat
/// part, not on the line; fitted as on it, it took `k̂_c` from 340 to 164 kN/m. Flagged as lifted
/// (its force below the lift force) or not, it is behind the fit's surface beyond doubt.
#[test]
fn a_bounce_within_the_onset_window_is_not_on_the_line() {
    let k: f64 = 354_694.0;
    let force = |x_mm: f64| (k * (x_mm - 10.0) * 1e-3).max(0.0);
    let fit = |skip_off_surface: bool| {
        let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, 5.0 / 50_000.0);
        // The approach at 2 mm/s, 24 µm a cycle, up to the sample that declares contact.
        for i in (0..12).rev() {
            let x_mm = 10.02166 - 0.024 * i as f64;
            id.remember(x_mm * 1e-3, force(x_mm), 2e-3, 0.012);
        }
        id.begin_contact(10.02166e-3, force(10.02166), true);
        let first = StepState {
            first: true,
            ..StepState::default()
        };
        let f = force(10.02166);
        id.step(10.02166e-3, f, 0.0, 0.0, 0.012, first, 0.0, 0.02);
        let window = [
            10.04566, 10.06966, 10.02965, 9.96472, 10.00019, 10.01102, 9.98989,
        ];
        for x_mm in window {
            let f = force(x_mm);
            let lifted = skip_off_surface && f < 0.3;
            let state = StepState {
                lifted,
                ..StepState::default()
            };
            id.step(x_mm * 1e-3, f, 0.0, f, 0.012, state, 0.0, 0.02);
        }
        id.kc()
    };
    assert!((fit(true) - k).abs() < 0.05 * k, "{}", fit(true));
    assert!(
        (fit(false) - k).abs() < 0.05 * k,
        "the bounce fitted as on the line: {}",
        fit(false)
    );
}

/// The same through a sensor's 100 Hz filter (f_r 2 N on 500 kN/m on the 12 ms cell, `[law.cell]
/// sensor_delay` pairing each force with the position of its time; the samples of the
/// `filtered_sensors` trace, mm and N): the contact ends between two samples, and the filter still
/// shows 1.47 N 51 µm behind the surface. Above the lift force it was fitted as on the line, and
/// `k̂_c` fell from 397 to 116 kN/m, a loop four times too slow that bounced and never settled.
/// Behind the fit's surface beyond its doubt, it is off the line whatever its force.
#[test]
fn a_filtered_force_s_tail_behind_the_surface_is_not_on_the_line() {
    let k: f64 = 500_000.0;
    let fit = |tail: bool| {
        let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, 2.0 / 50_000.0);
        for i in (1..12).rev() {
            id.remember((10.0172 - 0.024 * i as f64) * 1e-3, 0.0, 2e-3, 0.012);
        }
        id.remember(10.0172e-3, 8.81, 2e-3, 0.012);
        id.begin_contact(10.0172e-3, 8.81, true);
        let first = StepState {
            first: true,
            ..StepState::default()
        };
        id.step(10.0172e-3, 8.81, 0.0, 0.0, 0.012, first, 0.0, 0.02);
        for (x_mm, f) in [(10.0412, 20.58), (10.0652, 32.58), (10.0257, 12.81)] {
            let state = StepState::default();
            id.step(x_mm * 1e-3, f, 0.0, f, 0.012, state, 0.0, 0.02);
        }
        if tail {
            id.step(
                9.9496e-3,
                1.47,
                0.0,
                1.47,
                0.012,
                StepState::default(),
                0.0,
                0.02,
            );
        }
        id.kc()
    };
    let (without, with) = (fit(false), fit(true));
    assert!(without > 0.5 * k, "{without}");
    assert!(
        (with - without).abs() < 0.01 * without,
        "the tail fitted as on the line: {with} against {without}"
    );
}

#[test]
fn validation_names_the_field() {
    let p = IdentifyParams {
        steady_done: 0.5,
        ..IdentifyParams::default()
    };
    assert!(p.validate().unwrap_err().contains("steady_done"));
}

/// A steady contact at 5 N on a still surface at 10 mm of stiffness `k`, held for 1 s, then the
/// environment changes to stiffness `k2` and surface `xc2` at the same position; the tool moves to the
/// new equilibrium with a 20 ms time constant and `c_e` of damping, and the re-fit runs. Returns k̂_c.
fn change(k: f64, k2: f64, xc2: f64, c_e: f64) -> f64 {
    change_judged(k, k2, xc2, c_e, f64::INFINITY)
}

/// [`change`] with the re-fit judged from `early` s on.
fn change_judged(k: f64, k2: f64, xc2: f64, c_e: f64, early: f64) -> f64 {
    let (xc, f_r, dt) = (0.010, 5.0, 1e-3);
    let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, f_r / 50_000.0);
    let mut x = xc + f_r / k;
    id.begin_contact(x, f_r, false);
    for _ in 0..1000 {
        id.step(x, f_r, 0.0, f_r, dt, StepState::default(), 0.0, 0.02);
    }
    assert!(
        (id.kc() - k).abs() < 1e-6 * k,
        "k̂ {} before the change",
        id.kc()
    );
    let x_end = xc2 + f_r / k2;
    id.refit(x, k2 * (x - xc2), early, 1e-4);
    for _ in 0..1000 {
        let v = (x_end - x) / 0.020;
        x += v * dt;
        let f = k2 * (x - xc2) + c_e * v;
        id.step(x, f, v, f, dt, StepState::default(), 0.0, 0.02);
    }
    id.kc()
}

#[test]
fn a_stiffness_change_on_a_still_surface_is_re_learnt_through_the_surface() {
    for (k2, c_e) in [
        (100_000.0, 0.0),
        (25_000.0, 0.0),
        (100_000.0, 200.0),
        (25_000.0, 200.0),
    ] {
        let k = change(50_000.0, k2, 0.010, c_e);
        assert!((k - k2).abs() < 0.02 * k2, "k̂ {k} for {k2} at {c_e} N·s/m");
    }
}

#[test]
fn a_conclusive_re_fit_is_taken_before_its_window_ends() {
    // 60 ms in: the 20 ms settling has shown; the judgement takes the fit there.
    for (k2, c_e) in [(100_000.0, 0.0), (25_000.0, 200.0)] {
        let k = change_judged(50_000.0, k2, 0.010, c_e, 0.06);
        assert!((k - k2).abs() < 0.02 * k2, "k̂ {k} for {k2} at {c_e} N·s/m");
    }
    for step in [-3e-4, 3e-4] {
        let k = change_judged(50_000.0, 50_000.0, 0.010 + step, 0.0, 0.06);
        assert!(
            (k - 50_000.0).abs() < 0.02 * 50_000.0,
            "k̂ {k} after a {step} m step"
        );
    }
}

#[test]
fn a_surface_step_is_no_stiffness_change() {
    for step in [-3e-4, 3e-4] {
        let k = change(50_000.0, 50_000.0, 0.010 + step, 0.0);
        assert!(
            (k - 50_000.0).abs() < 0.02 * 50_000.0,
            "k̂ {k} after a {step} m step"
        );
    }
}

#[test]
fn a_contact_declared_on_noise_is_not_fitted() {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let noise = Normal::new(0.0, 0.9).unwrap();
    let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, 20.0 / 50_000.0);
    // Free air at 2 mm/s on a 4 ms cycle, 0.9 N of noise: no force rises with the position.
    let mut x = 0.0095;
    for _ in 0..60 {
        id.remember(x, noise.sample(&mut rng), 2e-3, 4e-3);
        x += 8e-6;
    }
    id.begin_contact(x, 1.5, true);
    let mut seeded = false;
    for i in 0..25 {
        x += 8e-6;
        let f = noise.sample(&mut rng);
        let first = StepState {
            first: i == 0,
            ..StepState::default()
        };
        let out = id.step(x, f, 2e-3, 0.0, 4e-3, first, 0.81, 0.02);
        seeded |= out.seeded;
    }
    assert!(!seeded, "a fit of noise set k̂ to {}", id.kc());
    assert_eq!(id.kc(), 50_000.0);
}

#[test]
fn a_touch_down_taken_back_forgets_what_it_identified() {
    // A touch-down on 20 kN/m, fitted: `k̂_c` leaves the tuning's guess.
    let k = 20_000.0;
    let (mut id, seeded, _) = touch_down_on(k, 5.0, 2e-3, 1e-3, 100, false);
    assert!(seeded && (id.kc() - k).abs() < 0.05 * k, "k̂ {}", id.kc());
    // Taken back (the contact machine found it was no contact): the guess again.
    id.forget_touch_down();
    assert_eq!(id.kc(), 50_000.0);
    assert!(!id.fitting());
}

#[test]
fn a_surface_in_doubt_gives_the_line_through_it_no_preference() {
    // A transient on 100 kN/m with a ±0.05 N wobble, through the surface: known, or in doubt by 10 µm.
    let (k, xc, s) = (100_000.0, 0.010, 1e-4);
    let mut o = crate::onset::OnsetFit::new();
    o.begin(0.010_05, s, 1.0);
    for i in 0..60 {
        let x = 0.010_05 - 2.5e-5 * (1.0 - (-(i as f64) / 10.0).exp());
        let wobble = if i % 2 == 0 { 0.05 } else { -0.05 };
        o.add(x, k * (x - xc) + wobble, 0.0, 1e-3);
    }
    let (pivot, r) = (xc, 0.05 * 0.05);
    let sure = refit::choose(&o, pivot, 0.0, r, r, 3.0, f64::INFINITY).unwrap();
    let doubt = refit::choose(&o, pivot, 1e-10, r, r, 3.0, f64::INFINITY).unwrap();
    let free = o.fit(r).unwrap();
    assert!(
        sure.var_b < free.var_b,
        "through the surface when it is known"
    );
    assert_eq!(doubt, free, "the free line when the surface is in doubt");
    assert!((doubt.b / s - k).abs() < 0.02 * k, "k̂ {}", doubt.b / s);
}

/// A search that began at `x_lost` (m) and took `t_lost` (s), `fast` or not.
fn search(x_lost: f64, t_lost: f64, fast: bool) -> Search {
    Search {
        x_lost,
        t_lost,
        fast,
    }
}

/// A re-contact on a surface moving in with the tool backing off faster: the force falls at
/// `k_c·(v_tool − v_surface)`, which a still-surface model reads as a softer surface. Returns `k̂_c`
/// after `steps` of 1 ms, the contact re-acquired at `x` after a search from `x_lost` of 0.26 s.
fn re_contact_on_a_surface_moving_in(x_lost: f64, steps: usize) -> (Identifier, f64) {
    let k = 50_000.0;
    let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, 5.0 / k);
    let (v_tool, v_surface) = (-4.3e-3, -3.35e-3);
    let (mut x, mut xc) = (0.011, 0.011 - 7.0 / k);
    id.begin_contact(x, 7.0, false);
    id.recontact(x, 7.0, &search(x_lost, 0.26, false), 5.0, 0.001, 0.5);
    for i in 0..steps {
        let f = k * (x - xc);
        let state = StepState {
            first: i == 0,
            ..StepState::default()
        };
        id.step(x, f, v_tool, f, 1e-3, state, 0.0, 0.02);
        x += v_tool * 1e-3;
        xc += v_surface * 1e-3;
    }
    (id, k)
}

/// B5b's re-contacts on 500 kN/m: the surface found 1 mm from where contact was lost has moved, and
/// may be moving still; the recursion waits for the observer's `motion_hold` instead of reading the
/// motion as stiffness. Found where contact was lost, the same data moves `k̂_c` (what the wait
/// prevents); the wait runs on through a bounce and a touch-down from the approach ends it. A
/// re-contact the fast search made waits too, wherever it found the surface.
#[test]
fn a_re_contact_that_found_the_surface_moved_learns_nothing_while_it_may_move() {
    let (id, k) = re_contact_on_a_surface_moving_in(0.010, 120);
    assert_eq!(id.kc(), k, "nothing learnt from the motion");
    assert!(id.held(), "0.12 s into a 0.5 s wait");
    let (unmoved, _) = re_contact_on_a_surface_moving_in(0.011, 120);
    assert!(!unmoved.held(), "found where it was lost: no wait");
    assert!(
        unmoved.kc() < 0.9 * k,
        "the same samples read as a softer surface: {}",
        unmoved.kc()
    );
    let (mut id, _) = re_contact_on_a_surface_moving_in(0.010, 120);
    // A bounce off it, re-contacted where it was lost: the surface is no stiller for that.
    id.begin_contact(0.0105, 2.0, false);
    id.recontact(0.0105, 2.0, &search(0.0105, 0.01, false), 5.0, 0.001, 0.5);
    assert!(id.held(), "the wait runs on through a bounce");
    id.begin_contact(0.011, 2.0, true);
    assert!(!id.held(), "a touch-down from the approach ends the wait");
    let (id, _) = re_contact_on_a_surface_moving_in(0.010, 501);
    assert!(!id.held(), "the wait ends after motion_hold");
    // Found where it was lost, but by the fast search: its momentum's transient is no stiffness.
    let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, 1e-4);
    id.begin_contact(0.011, 30.0, false);
    id.recontact(0.011, 30.0, &search(0.011, 0.02, true), 5.0, 0.001, 0.5);
    assert!(id.held(), "a re-contact the fast search made waits");
}

/// A doubling on a still surface whose re-fit window holds one sample off the surface, 50 µm behind
/// it at 0 N (a bounce). In a re-fit only the lift-off test leaves such a sample out (the touch-down's
/// test of a sample behind the fit's surface beyond doubt does not apply there: a change's transient
/// can lie behind the line of its first samples): flagged as lifted it is passed over, fitted as on the
/// line it pulls `k̂_c` off.
#[test]
fn a_bounce_in_a_re_fit_s_window_is_not_on_the_line() {
    let fit = |flagged: bool| {
        let (xc, f_r, dt, k, k2) = (0.010, 5.0, 1e-3, 50_000.0, 100_000.0);
        let mut id = Identifier::new(IdentifyParams::default(), est(), 0.02, f_r / 50_000.0);
        let mut x = xc + f_r / k;
        id.begin_contact(x, f_r, false);
        for _ in 0..1000 {
            id.step(x, f_r, 0.0, f_r, dt, StepState::default(), 0.0, 0.02);
        }
        let x_end = xc + f_r / k2;
        id.refit(x, k2 * (x - xc), f64::INFINITY, 1e-4);
        for i in 0..1000 {
            let v = (x_end - x) / 0.020;
            x += v * dt;
            let (xs, f, lifted) = if i == 30 {
                (xc - 5e-5, 0.0, flagged)
            } else {
                (x, k2 * (x - xc), false)
            };
            let state = StepState {
                lifted,
                ..StepState::default()
            };
            id.step(xs, f, v, f, dt, state, 0.0, 0.02);
        }
        id.kc()
    };
    let k2 = 100_000.0;
    assert!((fit(true) - k2).abs() < 0.02 * k2, "{}", fit(true));
    assert!(
        (fit(false) - k2).abs() > 0.05 * k2,
        "the bounce fitted as on the line: {}",
        fit(false)
    );
}
