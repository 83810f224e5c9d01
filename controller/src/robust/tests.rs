//! The law as a whole: the stages composed, against an ideal inner loop.

use super::*;
use crate::config::{LawConfig, Tuning};

fn params() -> RobustParams {
    let t: Tuning = toml::from_str(include_str!("../../../tunings/robust.toml")).unwrap();
    match t.law {
        LawConfig::Robust(p) => *p,
        other => panic!("robust tuning expected, got {other:?}"),
    }
}

/// Ideal inner loop against a spring whose surface is `xc(step)`; returns the law and the position.
fn drive(
    law: &mut RobustLaw,
    x: &mut f64,
    steps: usize,
    k: f64,
    xc: impl Fn(usize) -> f64,
) -> Vec<Output> {
    (0..steps)
        .map(|i| {
            let f = (k * (*x - xc(i))).max(0.0);
            let out = law.step(*x, f, 1e-3);
            *x += 0.2 * (out.x_cmd - *x);
            out
        })
        .collect()
}

#[test]
fn start_is_bumpless_and_approach_is_bounded() {
    let p = params();
    let mut law = RobustLaw::new(p).unwrap();
    law.start(0.004);
    let out = law.step(0.004, 0.0, 1e-3);
    assert_eq!(out.state, Some(ContactState::Approach));
    assert!((out.x_cmd - 0.004).abs() <= p.contact.approach_speed * 1e-3 + 1e-15);
}

#[test]
fn state_machine_contact_lift_off_reacquire() {
    let p = params();
    let mut law = RobustLaw::new(p).unwrap();
    let mut x = 0.0095;
    law.start(x);
    let outs = drive(&mut law, &mut x, 6000, 70_000.0, |i| {
        if i < 3000 { 0.010 } else { 0.0115 }
    });
    let first_contact = outs.iter().position(|o| o.events.contact).unwrap();
    assert!(
        outs[..first_contact]
            .iter()
            .all(|o| o.state == Some(ContactState::Approach))
    );
    let lift = outs.iter().position(|o| o.events.lift_off).unwrap();
    assert!(lift >= 3000, "lift-off only after the surface retreats");
    assert_eq!(outs[lift].state, Some(ContactState::Reacquire));
    assert!(outs[lift..].iter().any(|o| o.events.contact));
    assert_eq!(outs.last().unwrap().state, Some(ContactState::Contact));
    let c = law.counters();
    // The fast re-acquisition may bounce once; the search after a bounce is slow and holds.
    assert!(
        (2..=3).contains(&c.contacts) && c.lift_offs == c.contacts - 1,
        "{c:?}"
    );
    let f = 70_000.0 * (x - 0.0115);
    assert!((f - p.f_r).abs() < 0.05, "force {f} N");
}

#[test]
fn force_limit_retracts_and_is_reported() {
    let p = params();
    let mut law = RobustLaw::new(p).unwrap();
    let mut x = 0.0100714;
    law.start(x);
    drive(&mut law, &mut x, 1000, 70_000.0, |_| 0.010);
    // The surface jumps 2 mm towards the tool: 140 N.
    let outs = drive(&mut law, &mut x, 400, 70_000.0, |_| 0.008);
    let hit = outs.iter().position(|o| o.events.force_limit).unwrap();
    assert!(hit < 20, "limit seen after {hit} steps");
    assert_eq!(outs[hit].state, Some(ContactState::Retract));
    assert!(outs[hit + 10].x_cmd < outs[hit].x_cmd, "moving away");
    assert_eq!(law.counters().force_limits, 1);
}

#[test]
fn set_point_change_is_bumpless() {
    let p = params();
    let mut law = RobustLaw::new(p).unwrap();
    let mut x = 0.0100714;
    law.start(x);
    drive(&mut law, &mut x, 1500, 70_000.0, |_| 0.010);
    law.set_set_point(10.0).unwrap();
    let before = x;
    let outs = drive(&mut law, &mut x, 1500, 70_000.0, |_| 0.010);
    // The set-point slews at its rate: the first command moves by the slew's step (rate·dt/k̂, times κ)
    // plus the slew's feed-forward over the loop's lead time (rate·(lag + delay)/k̂) — a fraction of
    // the 71 µm a jump to the new set-point would be.
    let first_move = (outs[0].x_cmd - before).abs();
    let ff = p.response.set_point_rate * (p.cell.lag + p.cell.delay) / 60_000.0;
    assert!(first_move < 2e-6 + ff, "first move {first_move} m");
    assert!(
        first_move < 5.0 / 70_000.0 / 4.0,
        "first move {first_move} m"
    );
    assert!(outs.iter().all(|o| !o.events.any_limit()));
    assert!((law.active_set_point() - 10.0).abs() < 1e-12);
    let f = 70_000.0 * (x - 0.010);
    assert!((f - 10.0).abs() < 0.05, "force {f} N");
}

#[test]
fn the_approach_identifies_the_stiffness_whatever_the_guess_and_set_point() {
    for (kc0, f_r) in [(50_000.0, 5.0), (200_000.0, 5.0), (30_000.0, 12.0)] {
        let mut p = params();
        p.estimator.kc0 = kc0;
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = 0.0095;
        law.start(x);
        // A set-point changed before contact must not confuse the fit's position scale.
        law.set_set_point(f_r).unwrap();
        drive(&mut law, &mut x, 2000, 70_000.0, |_| 0.010);
        let k = law.step(x, 70_000.0 * (x - 0.010), 1e-3).kc_hat;
        assert!((k - 70_000.0).abs() < 700.0, "k̂(0) {kc0}, f_r {f_r}: k̂ {k}");
    }
}

#[test]
fn deviation_limit_is_an_event_never_a_silent_clamp() {
    let mut p = params();
    p.limits.max_deviation = 0.0002;
    let mut law = RobustLaw::new(p).unwrap();
    let mut x = 0.0;
    law.start(x);
    // The surface is out of reach (1 mm): the approach runs into the deviation limit.
    let outs = drive(&mut law, &mut x, 2000, 70_000.0, |_| 0.001);
    assert!(outs.iter().all(|o| o.x_cmd.abs() <= 0.0002 + 1e-15));
    assert!(outs.iter().any(|o| o.events.deviation_limit));
    assert!(law.counters().deviation_limits > 0);
}

#[test]
fn validation_names_what_is_wrong() {
    let mut p = params();
    p.contact.lift_force = p.contact.contact_force;
    assert!(RobustLaw::new(p).unwrap_err().contains("lift_force"));
    let mut p = params();
    p.response.kappa = 1.5;
    assert!(RobustLaw::new(p).unwrap_err().contains("kappa"));
    let mut p = params();
    p.estimator.kc0 = 1e7;
    assert!(RobustLaw::new(p).unwrap_err().contains("kc0"));
    let mut p = params();
    p.limits.max_force = 1.0;
    assert!(RobustLaw::new(p).unwrap_err().contains("max_force"));
}

#[test]
fn a_stiffness_change_on_a_still_surface_is_re_identified() {
    // (Contact losses after the change are the closed-loop scenarios' business, B2 on P1 and P2.)
    for factor in [0.5, 2.0] {
        let mut law = RobustLaw::new(params()).unwrap();
        let mut x = 0.0095;
        law.start(x);
        drive(&mut law, &mut x, 3000, 70_000.0, |_| 0.010);
        let k = 70_000.0 * factor;
        let outs = drive(&mut law, &mut x, 2000, k, |_| 0.010);
        let end = outs.last().unwrap();
        assert!(
            (end.kc_hat - k).abs() <= 0.1 * k,
            "×{factor}: k̂ {} after 2 s, k {k}",
            end.kc_hat
        );
    }
}

#[test]
fn one_zero_sample_or_a_short_dropout_is_not_a_lift_off_even_on_a_slow_cycle() {
    let mut law = RobustLaw::new(params()).unwrap();
    let (k, dt) = (70_000.0, 0.004);
    let mut x = 0.0099;
    law.start(x);
    for i in 0..1500 {
        let f = (k * (x - 0.010)).max(0.0);
        // One zero sample every 0.4 s once in contact, and a NaN (a dropout) beside it.
        let f = match i % 100 {
            50 if i > 500 => 0.0,
            51 if i > 500 => f64::NAN,
            _ => f,
        };
        let out = law.step(x, f, dt);
        assert!(
            !out.events.lift_off,
            "step {i}: a glitch taken for a lift-off"
        );
        x += 0.3 * (out.x_cmd - x);
    }
    assert_eq!(law.counters().contacts, 1);
}

#[test]
fn a_restarted_law_is_a_fresh_law() {
    // `start` (each PRESS of a process pass) must forget what the last pass learnt: anything a stage
    // keeps across it makes the next pass differ from a first one. The first pass touches down, is
    // fitted, loses the contact to a retreat and re-acquires it; the second, on a stiffer surface,
    // loses its contact within a few cycles of touching down, before any fit of its own.
    let p = params();
    let mut used = RobustLaw::new(p).unwrap();
    let mut x = 0.0095;
    used.start(x);
    let first = drive(&mut used, &mut x, 6000, 70_000.0, |i| {
        if i < 3000 { 0.010 } else { 0.0115 }
    });
    assert!(
        first.iter().any(|o| o.events.lift_off),
        "the first pass lost contact"
    );

    let k = 200_000.0;
    let touch = {
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = 0.0095;
        law.start(x);
        let outs = drive(&mut law, &mut x, 3000, k, |_| 0.010);
        outs.iter().position(|o| o.events.contact).unwrap()
    };
    let surface = move |i: usize| if i < touch + 3 { 0.010 } else { 0.0115 };
    let mut fresh = RobustLaw::new(p).unwrap();
    let (mut xa, mut xb) = (0.0095, 0.0095);
    used.start(xa);
    fresh.start(xb);
    let again = drive(&mut used, &mut xa, 6000, k, surface);
    let first = drive(&mut fresh, &mut xb, 6000, k, surface);
    assert!(
        first.iter().any(|o| o.events.lift_off),
        "the second pass lost contact"
    );
    let differs = again
        .iter()
        .zip(&first)
        .position(|(a, b)| a.x_cmd.to_bits() != b.x_cmd.to_bits() || a.state != b.state);
    assert_eq!(
        differs, None,
        "the restarted law departs from a fresh one at step {differs:?}"
    );
}

/// A servo that stops short of its command (2 µm here, 1.25 N on 500 kN/m: stiction, a position loop
/// without integral action) is pulled in by the law's integral, which the proportional path, anchored
/// on the reported position, cannot do: without the integral the force stands 1.25 N short.
#[test]
fn a_servo_that_stops_short_is_pulled_in() {
    let p = params();
    let (k, short) = (500_000.0, 2e-6);
    let mut law = RobustLaw::new(p).unwrap();
    let mut x = 0.0095;
    law.start(x);
    let mut f = 0.0;
    for _ in 0..4000 {
        f = (k * (x - 0.010)).max(0.0);
        let out = law.step(x, f, 1e-3);
        x += 0.2 * (out.x_cmd - short - x);
    }
    assert!((f - p.f_r).abs() < 0.01, "force {f} N after 4 s");
}
