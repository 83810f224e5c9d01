//! The cases the range tests found after a stiffness change in a steady contact, each named and
//! deterministic: small set-points on soft surfaces, where a stale `k̂_c` costs the most.

mod common;

use common::{CELLS, cell, mean_error, tuning};
use controller::LawConfig;
use scenario::metrics::Metrics;
use scenario::run::run;

/// A change of stiffness by `factor` at `at` s in a 2 N contact on a 20 kN/m surface with damping
/// `c_e` (N·s/m), on cell `cell_i`, noise-free; the metrics from the change on, and the mean error
/// from 1.5 s after it.
fn change(c_e: f64, at: f64, factor: f64, cell_i: usize) -> (Metrics, f64) {
    let s = cell(at + 2.0, 20e3, c_e, Some((at, factor)), None, 0.0, 1);
    let r = run(&s, &CELLS[cell_i], &tuning(2.0)).expect("the run ends well");
    (r.metrics(at, f64::INFINITY), mean_error(&r.rows, at + 1.5))
}

/// A change found by the range tests, `(f_r, k_c, c_e, at, factor, noise, seed, cell)`: stiffness
/// ×`factor` at `at` s in an `f_r` (N) hold on `k_c` (N/m) with damping `c_e` (N·s/m), sensor noise
/// `noise` (N, seeded `seed`), on `CELLS[cell]`.
type Found = (f64, f64, f64, f64, f64, f64, u64, usize);

/// The run of `case`, which must end well, and its metrics from the change on, asserted to hold the
/// contact and end with `k̂_c` within `tol` of the new stiffness.
fn held(case: Found, tol: f64) -> (scenario::run::Run, Metrics) {
    let (f_r, k_c, c_e, at, factor, noise, seed, cell_i) = case;
    let s = cell(at + 2.0, k_c, c_e, Some((at, factor)), None, noise, seed);
    let r = run(&s, &CELLS[cell_i], &tuning(f_r)).expect("the run ends well");
    let m = r.metrics(at, f64::INFINITY);
    assert_eq!(m.contact_losses, 0.0, "f_r {f_r} N: contact lost");
    assert!(
        m.kc_rel_error <= tol,
        "f_r {f_r} N: k̂ off by {}",
        m.kc_rel_error
    );
    (r, m)
}

/// A doubling (20 → 40 kN/m) on P2 at any time of the hold: with the stale `k̂_c` the loop rings, so
/// the re-fit is taken as soon as it is conclusive instead of at its window's end (was: 1.4 s at 2 s,
/// 1.3 s at 2.3 s; 3 and 2 contact losses at 2.7 s and 3 s).
#[test]
fn a_doubling_at_a_small_set_point_settles_within_half_a_second() {
    for at in [2.0, 2.3, 2.7, 3.0] {
        let (m, err) = change(0.0, at, 2.0, 1);
        assert_eq!(m.contact_losses, 0.0, "at {at} s");
        assert!(m.settle_time <= 0.5, "at {at} s: {} s", m.settle_time);
        assert!(
            m.kc_rel_error <= 0.1,
            "at {at} s: k̂ off by {}",
            m.kc_rel_error
        );
        assert!(err <= 0.04, "at {at} s: mean error {err} N");
    }
}

/// A halving (20 → 10 kN/m) on a damped surface on P2: the observed surface `x − f/k̂_c` is the
/// spring's (the identified damping taken out), or the surface seems to move with the tool and the
/// feed-forward chases it (was, at 118 N·s/m: 3 contact losses and 20 N off at the end).
#[test]
fn a_halving_on_a_damped_surface_holds_the_contact() {
    for c_e in [50.0, 118.0, 180.0] {
        for at in [2.0, 2.5] {
            let (m, err) = change(c_e, at, 0.5, 1);
            assert_eq!(m.contact_losses, 0.0, "{c_e} N·s/m at {at} s");
            assert!(
                m.settle_time <= 0.5,
                "{c_e} N·s/m at {at} s: {} s",
                m.settle_time
            );
            assert!(
                m.kc_rel_error <= 0.1,
                "{c_e} N·s/m: k̂ off by {}",
                m.kc_rel_error
            );
            assert!(err <= 0.04, "{c_e} N·s/m at {at} s: mean error {err} N");
        }
    }
}

/// A doubling on a damped surface on the 12 ms cell: the jump takes a cycle more than the
/// conditioning's own step time to pass, and counted as motion it fed the retreat forward (1 contact
/// loss with the damping already taken out of the observed surface).
#[test]
fn a_doubling_on_a_damped_surface_on_a_slow_cell_holds_the_contact() {
    let (m, err) = change(118.27, 2.0, 2.0, 2);
    assert_eq!(m.contact_losses, 0.0);
    assert!(m.kc_rel_error <= 0.1, "k̂ off by {}", m.kc_rel_error);
    assert!(err <= 0.04, "mean error {err} N");
}

/// A touch-down on the 12 ms cell at nearly constant approach speed: the onset fit's damping trades
/// off against its intercept and means nothing; taken out of the observed surface, it made the law
/// see the surface move and drive in (fault 2 at 101.5 N). The damping is used only where the fit
/// determines it.
#[test]
fn an_undetermined_damping_is_not_taken() {
    let s = cell(3.0, 17_707.0, 0.0, None, None, 0.0, 1);
    let r = run(&s, &CELLS[2], &tuning(33.65)).expect("no fault");
    let m = r.metrics(0.0, f64::INFINITY);
    assert!(m.peak_force <= 2.0 * 33.65, "impact {} N", m.peak_force);
    assert!(mean_error(&r.rows, 2.5) <= 0.02 * 33.65);
}

/// A doubling under sensor noise on the 12 ms cell (f_r 6.9 N, 20 → 40 kN/m at 2.69 s, σ 0.43 N,
/// seed 461): the noise alone made the still surface look moving (the surface velocity's standard
/// deviation is 0.41 mm/s there, the motion threshold 1 mm/s), so the contact was never calm, no re-fit
/// opened at the change, and `k̂_c` ended 32 % off (27 against 40 kN/m). A velocity within
/// `motion_significance` deviations of the noise's is no motion now.
#[test]
fn a_noisy_hold_on_a_slow_cell_is_still_and_a_change_is_refitted() {
    held((6.922, 20e3, 0.0, 2.694, 2.0, 0.432, 461, 2), 0.1);
}

/// A doubling on a damped surface under noise at a small set-point on P2 (f_r 2 N, 49.6 → 99.3 kN/m
/// at 2 s, 112 N·s/m, σ 0.16 N, seed 666; found with 200 range cases): the re-fit's free line said
/// "doubled" within 3 % after the loop's answer, but only a 2 % fit was taken early; the stale gain
/// rang until contact was lost, the fast search re-contacted at 51 N, and the run ended on fault 5
/// (later 4 contact losses). A fit within `steady_confidence` that puts the stale `k̂_c` beyond
/// `pivot_gate` of its deviations is taken early now.
#[test]
fn a_damped_doubling_under_noise_is_refitted_before_the_loop_rings() {
    let (_, m) = held((2.0, 49.6e3, 112.0, 2.0, 2.0, 0.16, 666, 1), 0.1);
    assert!(m.peak_force <= 2.0 * 2.0 * 2.0, "peak {} N", m.peak_force);
}

/// A doubling on a damped surface under noise on the 12 ms cell (f_r 10.2 N, 92.6 → 185 kN/m at 2 s,
/// 166 N·s/m, σ 0.44 N, seed 62): a fit taken early on the loose rule (within 10 %) ended the re-fit,
/// and the recursion, agile again, followed the rest of the damped transient to 253 kN/m (37 % off).
/// The window now runs on after a fit taken early, the recursion waiting, and its end refines it.
#[test]
fn a_fit_taken_early_is_refined_by_its_window() {
    held((10.16, 92_615.0, 166.0, 2.0, 2.0, 0.439, 62, 2), 0.1);
}

/// A doubling on a damped surface at a large set-point on P2 (f_r 20.3 N, 49.6 → 99.3 kN/m at 2.28 s,
/// 112 N·s/m, σ 0.16 N, seed 533; found with 200 range cases): the recursion, fed the transient
/// while the re-fit ran, moved `k̂_c` from 54 to 94 kN/m in 30 ms; the observed surface `x − f/k̂_c`
/// moved 0.37 mm with it, the feed-forward took that for motion and pressed to 73 N: fault 2. The
/// recursion waits while a re-fit runs.
#[test]
fn the_recursion_waits_while_a_re_fit_runs() {
    let (_, m) = held((20.283, 49_637.0, 112.16, 2.281, 2.0, 0.1565, 533, 1), 0.1);
    assert!(m.peak_force <= 2.5 * 20.283, "peak {} N", m.peak_force);
}

/// A noisy hold at a large set-point on the 12 ms cell (f_r 46.8 N on 142.6 kN/m, σ 0.47 N, seed 690;
/// found with 200 range cases): the recursion took the loop's answer to noise for excitation (its
/// 1.5 N threshold is three deviations of this noise), moved `k̂_c` 18 % on one sample and then,
/// with the force excursion its own command made, to 102 kN/m; the doubling at 2 s then met a gain
/// 2.8 times too high and lost contact. The excitation stands out of the noise now.
#[test]
fn a_noisy_hold_keeps_its_stiffness_estimate() {
    let (r, _) = held((46.77, 142_579.0, 0.0, 2.0, 2.0, 0.471, 690, 2), 0.1);
    let hold = r.metrics(1.0, 2.0);
    assert!(
        hold.kc_rel_error <= 0.1,
        "k̂ off by {} before the change",
        hold.kc_rel_error
    );
}

/// A halving at a large set-point under noise on P2 (f_r 42.8 N, 59.7 → 29.8 kN/m at 2 s, σ 0.45 N,
/// seed 75; found with 200 range cases): the re-fit was taken early at 0.4 % precision (1.4 % off),
/// and the recursion, agile after it, followed the transient's tail to 25.9 kN/m (13 % off). The
/// window runs on after any early fit now.
#[test]
fn a_precise_early_fit_is_not_undone_by_the_transients_tail() {
    held((42.8, 59_659.0, 0.0, 2.0, 0.5, 0.4506, 75, 1), 0.05);
}

/// A doubling on the 12 ms cell at a small set-point after a touch-down that left `k̂_c` 26 % low
/// (f_r 2 N, 20 → 40 kN/m at 2 s, σ 0.19 N, seed 232; found with 1000 range cases): under the stale
/// gain (2.7 times too high) the loop rang off the surface. While the rise is unresolved the
/// correction takes the stiffer hypothesis (`response.jump_caution`) and feeds no surface motion
/// forward; with the caution off the same run loses contact.
#[test]
fn an_unresolved_rise_is_answered_as_a_stiffer_surface() {
    let s = cell(4.0, 20e3, 0.0, Some((2.0, 2.0)), None, 0.19, 232);
    let losses = |caution: f64| {
        let mut t = tuning(2.0);
        let LawConfig::Robust(p) = &mut t.law else {
            panic!("robust")
        };
        p.response.jump_caution = caution;
        let r = run(&s, &CELLS[2], &t).expect("the run ends well");
        r.metrics(2.0, f64::INFINITY).contact_losses
    };
    assert!(losses(1.0) > 0.0, "the case no longer needs the caution");
    assert_eq!(losses(2.0), 0.0);
}

/// The same caution on a damped doubling (f_r 7.2 N, 41.4 kN/m at 2.59 s, 116 N·s/m, σ 0.19 N, seed
/// 479; 1000 range cases), and noise-free at a large set-point (f_r 28.9 N, 87.6 kN/m at 2.3 s), where
/// a first version that still fed the observer's motion forward took the slower retreat for surface
/// motion, threw the command 0.5 mm back and lost contact twice.
#[test]
fn the_cautious_answer_holds_the_contact_on_the_slow_cell() {
    for case in [
        (7.18, 41_414.0, 116.0, 2.589, 2.0, 0.19, 479, 2),
        (28.876, 87_556.0, 0.0, 2.302, 2.0, 0.0, 1, 2),
    ] {
        held(case, 0.1);
    }
}
