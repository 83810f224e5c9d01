//! Unit tests of the identification stage.

use super::*;

fn est() -> EstimatorParams {
    EstimatorParams {
        kc0: 50_000.0,
        kc_min: 10_000.0,
        kc_max: 500_000.0,
        memory: 0.3,
        excitation: 1.5,
        excitation_window: 0.05,
        dead_zone: 0.02,
        initial_uncertainty: 1.0,
        max_surface_speed: 0.001,
    }
}

#[test]
fn the_onset_of_a_contact_from_the_approach_is_fitted() {
    let mut id = Identifier::new(IdentifyParams::default(), est(), 5.0 / 50_000.0);
    let k: f64 = 70_000.0;
    let mut x: f64 = 0.0095;
    let (mut seeded, mut contact) = (false, false);
    for _ in 0..2000 {
        let f = (k * (x - 0.010)).max(0.0);
        let mut first = false;
        if !contact {
            if f < 1.0 {
                id.remember(x, f, 2e-3);
                x += 2e-6;
                continue;
            }
            contact = true;
            first = true;
            id.begin_contact(x, f, true);
        }
        let out = id.step(x, f, 0.0, f, 1e-3, false, first, false, 0.0, 0.02);
        seeded |= out.seeded;
        if x < 0.010 + 5.0 / k {
            x += 2e-6;
        }
    }
    assert!(seeded, "the transient was fitted");
    assert!((id.kc() - k).abs() < 0.02 * k, "k̂ {}", id.kc());
    id.reset();
    assert_eq!(id.kc(), 50_000.0);
}

#[test]
fn validation_names_the_field() {
    let p = IdentifyParams {
        steady_done: 0.5,
        ..IdentifyParams::default()
    };
    assert!(p.validate().unwrap_err().contains("steady_done"));
}
