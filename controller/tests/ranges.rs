//! Generalisation as a test family: the B criteria carried over to ranges instead of fixed files —
//! set-points 2–50 N, stiffness 10–500 kN/m with ×0.5/×2 changes at any time, cycles of 1, 4 and 12 ms
//! with their delays, sensor noise up to 1 N, surface damping up to 200 N·s/m, surface steps up to
//! ±3 mm. Closed loop against the simulated cell through `forcecell-scenario` (the same run and
//! metrics as `forcecell sim`), shipped robust tuning (only the force limit — the law's and the
//! loop's — follows the set-point: a 60 N limit means nothing at 50 N), simulated time only, seeded
//! cases.

mod common;

use common::{
    CELLS, cell, census, change_bound, config, floor, floor_after, mean_error, reach_time, sine,
    stiffness, tuning,
};
use controller::LawConfig;
use proptest::prelude::*;
use scenario::run::{run, run_to_end};
use sim::InnerLoopModel;

// Known limits, measured, not hidden:
// * `k̂_c` within 10 % 2 s after a change is asserted where the information the change brings
//   allows it with a margin of four standard deviations ([`common::change_bound`]): noise-free
//   always; under noise not at small set-points on slow cells (f_r 2 N, 20 → 10 kN/m, σ 0.43 N, 12
//   ms: the bound is 22 %). At three a noisy doubling on the 12 ms cell misses: f_r 6.9 N, 245 →
//   490 kN/m, σ 0.43 N, 12.1 % off against a bound of 3.2 % (11.3 % before the re-fit ran its whole
//   window; with the re-fit's refinement and without the cautious answer to a rise, all 200 cases
//   passed at three, and 1000 cases found a contact loss — the caution was chosen). Where it is not
//   asserted `k̂_c` can end outside even four deviations: asserting them there too, 200 cases found a
//   damped halving that kept the stale `k̂_c`, 98 % off against 51 % (fixed,
//   `a_damped_halving_under_noise_is_no_moving_surface`), then an undamped halving (f_r 3.9 N, 35.9 →
//   17.9 kN/m, σ 0.42 N, 12 ms, seed 143) 53 % off against 44 %, `k̂_c` 23 % low before the change
//   and the moving surface the better explanation with it (not solved);
// * the touch-down under noise still fails at its corners, where the noise is a large part of a
//   small set-point or the cycle is slow: `noise_corners` (ignored; `--ignored` runs it) counts the
//   seeds 1–199 that fail the touch-down criteria — f_r 2 N on 10 kN/m, P1: 1 at σ 0.82 N, 2 at 1
//   N (on the mean error at the end); on the 12 ms cell at σ 1 N: f_r 5 N on 50 kN/m 37 (41 before the
//   observer learnt from a velocity a still measurement contradicts, 42 once; 37 before the
//   true force's spread at the end was asserted: five seeds spread 0.60–1.16 N), f_r 2 N on
//   10 kN/m 54 (58 before the observer learnt from a velocity a still measurement contradicts, 59
//   while the predictor's acceleration bound kept the velocity inferred with it; 61
//   before the landing waited for the force to show the contact; 62, the mean error
//   but for four impacts, before the caution of an unresolved rise kept a feed-forward that backs
//   off); on P2 at σ 1 N f_r 20 N on 500 kN/m 1 (0 before that landing: seed 112 trips at 102 N, a
//   touch-down bounced before its force showed, went back to the approach, and the second fit left
//   `k̂_c` 2.6 times too soft, as the first had). They were 8, 10, 55 and 86 while the integral
//   kept its full gain inside the noise and random-walked on it
//   (`a_noisy_hold_at_a_small_set_point_does_not_wander_on_its_integral`). Before that: the
//   helper branch alone measured 9, 12, 0, 67 and 89 (breakdown there: at f_r 5 N 58 on the mean
//   error alone, at f_r 2 N 75 and 4 fault-5 endings); merged with the identification changes of
//   this session (`changes.rs`) 8, 10, 0, 56, 88, and with the landing's cap 8, 10, 0, 55, 87
//   (with the onset window's bounce rule, a session later, 86). They
//   were 21, 46, 84 and 184 at the session's start (the file said 90 and 181): the onset fit now
//   waits for a significant slope (`a_noisy_touch_down_on_a_soft_surface_is_identified`: at f_r 2 N
//   on 10 kN/m it kept the 50 kN/m guess, a loop five times too slow), the fallback feed-forward no
//   longer feeds the noise forward on soft surfaces on slow cells
//   (`a_noisy_hold_on_a_soft_surface_on_a_slow_cell_holds`), and a hold at a small set-point no
//   longer lifts off on its own noise, after which the fast search pressed 15–21 N into the surface
//   (`a_noisy_hold_at_a_small_set_point_does_not_lift_off_on_its_noise`; 116 → 93), and no contact
//   is declared before the noise is measured on 16 samples
//   (`no_contact_is_declared_on_noise_measured_on_few_samples`: 93 → 89, 73 → 67; on the 12 ms cell
//   the conditioning's step time was 4 samples). The fault-5 endings left (the loop's 0.5 s
//   contact-loss limit, 0.9–1.8 s into the run) are not diagnosed. On the 12 ms cell what is left
//   of the mean error is mostly the noise's own: the last 0.5 s hold 42 samples, whose mean is
//   known to σ/√42 = 0.154 N, and the loop answers within tens of milliseconds, so the force
//   follows the measured noise's mean; against 0.02·f_r + 0.1·σ = 0.14 N (f_r 2 N) and 0.2 N (f_r 5
//   N) that alone fails P(|z| > 0.91) = 36 % and P(|z| > 1.30) = 19 % of the seeds, 72 and 39 of
//   199. Only a hold that averages the whole contact (≈ 190 samples, σ/√190 = 0.073 N) could pass
//   most of them. On P1 the noise's own mean is σ/√500 = 0.045 N: what fails there is the loop's
//   slow wander — the integral random-walks on the noise while the noise gate weights the
//   proportional path down to a tenth; weighting the integral alike brought 9 and 15 to 5 and 7
//   (before the dead-band change), but slowed the settle after a noise-free 1 mm retreat on 500
//   kN/m on the 12 ms cell past its bound (`surface_step_corners`: the noise meter reads that
//   transient as 0.1 N of noise). Taking the spring's share `k̂_c·Δ²x` out of the meter's second
//   difference in contact mends that (with the weighted integral: that settle 1.01 s, was 1.03; the
//   corners 3, 3, 0, 69, 102) but reads a surface's motion the tool follows as noise instead: B5b
//   on P2 went from 0.22 to 0.52 N rms (taking the smaller of the two differences: 6.9 N, failed).
//   Neither is done. Before the noise was measured from the first samples and a single raw sample
//   had to stand out of the raw noise, they were 94, 158, 183 and 198, and f_r 20 N on 500 kN/m,
//   P2, σ 1 N failed 106 (now 0). The 200 cases drawn here pass;
// * every touch-down the 3000 cases draw, each miss counted (`touch_down_census`, ignored): the true
//   force's spread at the end above 0.02·f_r + 0.5·σ once (f_r 3.1 N on 54 kN/m, 12 ms, σ 0.95 N:
//   0.554 against 0.54 N; f_r 43 N on 12.6 kN/m on P2 under σ 0.68 N rang 34–51 N until a
//   touch-down's window outlasted the motion its guess shows,
//   [`a_soft_surface_under_a_stiff_guess_is_identified_before_the_landing_ends`]), the
//   mean error seven times (small set-points under noise, mostly on the 12 ms cell), the impact twice
//   (P2, f_r 2.3 and 3.7 N on 330–380 kN/m under σ 0.57–0.95 N: 17.9 against 16.6 N, 18.6 against
//   18.0 N), and one fault, fixed since ([`a_contact_declared_on_noise_does_not_dash_into_a_stiff_surface`];
//   with that fix the mean error misses once more, f_r 3.75 N on 15.9 kN/m, 12 ms, σ 0.93 N: 0.211
//   against 0.168 N);
// * with 3000 cases (`FORCECELL_RANGE_CASES=3000`; `FORCECELL_RANGE_SHRINK=0` shows them as drawn)
//   `stiffness_changes` misses its mean error under noise at a small set-point on P2 (f_r 2.5 N,
//   78 → 39 kN/m, σ 0.47 N, 135 N·s/m: 0.103 N against 0.097 N, 0.161 N before its re-fit was
//   taken); 1000 pass. With 1000 cases
//   `touch_down_and_hold` misses its mean error under σ 0.43 N at f_r 2.46 N on the 12 ms cell
//   (0.145 N against 0.093 N, the corners below); it found and we fixed a contact the law took back
//   counted as lost (`a_contact_taken_back_at_the_start_is_not_a_lost_one`). `surface_steps` passes 5000 cases; 20000 find a
//   step whose jump is within 0.03 % of the force limit (72.68 N against 72.71 N), which trips it:
//   this test's bound has no margin there. Found with 1000 and 5000 cases and fixed
//   (`surface_steps_found_on_the_slow_cell`): the fast search's re-contact at the force limit times
//   `k_c/k̂_c` with `k̂_c` 1.7 % low (60.2 N; it now stops within the limit three of `k̂_c`'s deviations
//   stiffer), and a recursion that compared its first sample after an inconclusive re-fit with its
//   averages from before a surface step (`k̂_c` 21.6 → 13.7 kN/m, settled after 1.07 s). Found with
//   1000 cases and fixed before: a bounce in the onset window fitted as on
//   the spring's line (`robust::identify` unit test: 340 → 164 kN/m, then a trip at 75.7 N), and a
//   conditioned force's overshoot of a 54.7 N surface step taken for the 60 N limit. (With the delay
//   and one cycle as the search's stopping time, 200 cases tripped the limit on that cell too — f_r
//   15.3 N, 74.7 kN/m, 0.48 mm, 61.1 N — and two of `surface_step_corners`; `robust::stopping`
//   models the stop and all pass.) Found with 200 cases and fixed,
//   each a named test (in `changes.rs`, the retreat in `surface_step_corners`): a 2.62 mm retreat
//   on 10 kN/m that the search did not reach (fault 5); damped doublings that rang into lost
//   contacts or fault 5 (f_r 2 N on 49.6 kN/m, P2), that the recursion pressed to 73 N (f_r 20.3 N,
//   P2) or left 37 % off (f_r 10.2 N, 12 ms); a hold whose recursion took noise for excitation (f_r
//   46.8 N, 12 ms: 142 → 102 kN/m, then a lost contact); a halving whose precise re-fit the
//   recursion undid (f_r 42.8 N, P2: 13 % off); a noisy hold on the 12 ms cell that looked moving,
//   so no re-fit opened (32 % off).
// * (fixed, `a_noise_spike_in_free_air_is_no_touch_down`: a noise spike taken for contact short of
//   the surface — σ 0.9 N, f_r 20 N, 500 kN/m, P2, seed 7 — ended the run on fault 2 at 65.9 N; the
//   touch-down now peaks at 23.9 N, 21.0 N on 100 kN/m. The touch-down goes on at approach speed
//   until `k̂_c` is identified; before that, f_r 36.6 N on 354 kN/m on P2 hit 115 N against 84.5 N,
//   now 37 N.)

// 200 seeded cases each for the touch-down and the stiffness changes (a second of CPU); what more
// cases find is listed above.
proptest! {
    #![proptest_config(config(200))]

    /// B1 carried over: first contact from an approach at 2 mm/s, whatever the set-point, stiffness,
    /// cycle and noise: the impact stays within 2·f_r above the physical floor, the contact holds, the
    /// force ends at the set-point (within the noise).
    #[test]
    fn touch_down_and_hold(
        f_r in 2.0f64..50.0,
        k_c in stiffness(10e3, 500e3),
        cell_i in 0usize..3,
        noise in prop_oneof![Just(0.0), 0.0f64..=1.0],
        seed in 1u64..1000,
    ) {
        touch_down(f_r, k_c, &CELLS[cell_i], noise, seed)?;
    }

    /// B2 carried over: the stiffness halves or doubles at any time in a steady contact; the force
    /// comes back (noise-free and undamped: within ±2 % in 0.5 s), the contact holds, and `k̂_c` ends
    /// within 10 % of the new stiffness within 2 s, with surface damping or without.
    #[test]
    fn stiffness_changes(
        f_r in 2.0f64..50.0,
        k_c in stiffness(20e3, 250e3),
        double in any::<bool>(),
        at in 2.0f64..3.0,
        cell_i in 0usize..3,
        noise in prop_oneof![Just(0.0), 0.0f64..0.5],
        c_e in prop_oneof![Just(0.0), 0.0f64..200.0],
        seed in 1u64..1000,
    ) {
        let change = Change { f_r, k_c, double, at, cell_i, noise, c_e, seed };
        if let Some(miss) = change_misses(&change, false).into_iter().next() {
            return Err(TestCaseError::fail(miss));
        }
    }
}

/// One case of [`stiffness_changes`]: set-point (N), stiffness (N/m), doubled or halved, at (s), cell,
/// sensor noise (N), surface damping (N·s/m), seed.
#[derive(Clone, Copy, Debug)]
struct Change {
    f_r: f64,
    k_c: f64,
    double: bool,
    at: f64,
    cell_i: usize,
    noise: f64,
    c_e: f64,
    seed: u64,
}

impl Change {
    /// The stiffness's factor: ×2 or ×0.5.
    fn factor(&self) -> f64 {
        if self.double { 2.0 } else { 0.5 }
    }

    /// The change run as the property test runs it: 2 s after it, in process.
    fn run(&self) -> Result<scenario::run::Run, String> {
        let s = cell(
            self.at + 2.0,
            self.k_c,
            self.c_e,
            Some((self.at, self.factor())),
            None,
            self.noise,
            self.seed,
        );
        run(&s, &CELLS[self.cell_i], &tuning(self.f_r)).map_err(|e| e.to_string())
    }
}

/// Every criterion of [`stiffness_changes`] the case misses, in the order it asserts them (none: it
/// holds); with `beyond`, also a `k̂_c` that is not asserted (the change's information allows no 10 %)
/// but ends beyond four deviations of that information.
fn change_misses(c: &Change, beyond: bool) -> Vec<String> {
    let (plant, factor) = (CELLS[c.cell_i], c.factor());
    let r = match c.run() {
        Ok(r) => r,
        Err(e) => return vec![e.to_string()],
    };
    let after = r.metrics(c.at, f64::INFINITY);
    let mut misses = Vec::new();
    let mut check = |holds: bool, miss: String| {
        if !holds {
            misses.push(miss);
        }
    };
    check(
        after.contact_losses == 0.0,
        format!("{} contact losses", after.contact_losses),
    );
    let mean_err = mean_error(&r.rows, c.at + 1.5);
    check(
        mean_err <= 0.02 * c.f_r + 0.1 * c.noise,
        format!("mean error {mean_err} N at the end"),
    );
    if c.noise == 0.0 && c.c_e == 0.0 {
        check(
            after.settle_time <= 0.5,
            format!("settle: back in ±2 % after {} s", after.settle_time),
        );
    }
    let information = 4.0 * change_bound(c.f_r, factor, c.noise, &plant);
    if information <= 0.1 {
        check(
            after.kc_rel_error <= 0.1,
            format!("k̂_c off by {}", after.kc_rel_error),
        );
    } else if beyond {
        check(
            after.kc_rel_error <= information,
            format!(
                "k̂_c off by {} beyond its information's {information} (not asserted)",
                after.kc_rel_error
            ),
        );
    }
    misses
}

// 200 seeded cases for the surface steps too (24 while more found the fast search's re-contact above
// the force limit; 5000 pass now).
proptest! {
    #![proptest_config(config(200))]

    /// B3 carried over: the surface steps up to ±3 mm in a steady contact (see [`surface_step`]).
    #[test]
    fn surface_steps(
        f_r in 2.0f64..50.0,
        k_c in stiffness(10e3, 500e3),
        delta in -0.003f64..0.003,
        cell_i in 0usize..3,
    ) {
        surface_step(f_r, k_c, delta, &CELLS[cell_i])?;
    }
}

/// B3's criteria for a surface step of `delta` (m, positive away from the tool) in an `f_r` hold on
/// `k_c`: the contact comes back and the force settles at the set-point within 1 s of the time the
/// search can first reach the surface ([`common::reach_time`]) — unless the step
/// itself presses the tool past the force limit (a surface that jumps `δ` towards the tool adds
/// `k_c·δ` at once, before any loop can act): then the loop must end on fault 2, backed off; or the
/// surface went farther than the search can reach at the speeds the cell can stop
/// ([`common::reach_time`]) within 80 % of the loop's contact-loss time (the rest is the search's
/// acceleration, the delay and the detection): then the loop may end on fault 5, backed off.
fn surface_step(
    f_r: f64,
    k_c: f64,
    delta: f64,
    plant: &InnerLoopModel,
) -> Result<(), TestCaseError> {
    let s = cell(4.0, k_c, 0.0, None, Some((2.0, delta)), 0.0, 1);
    let t = tuning(f_r);
    let LawConfig::Robust(p) = &t.law else {
        unreachable!()
    };
    let jump = f_r + k_c * (-delta).max(0.0);
    let reach = reach_time(&t, k_c, delta - f_r / k_c, plant);
    let loss_time = t.loop_cfg.process.contact_loss_time;
    match run(&s, plant, &t) {
        Ok(r) => {
            prop_assert!(
                jump <= p.limits.max_force,
                "a {jump} N step did not trip the limit"
            );
            // 1 s from when the search can first reach the surface.
            let after = r.metrics(2.0, f64::INFINITY);
            prop_assert!(
                after.settle_time <= 1.0 + reach,
                "back in ±2 % after {} s",
                after.settle_time
            );
        }
        Err(e) => {
            let e = e.to_string();
            prop_assert!(
                (jump > p.limits.max_force && e.contains("fault 2 (force limit)"))
                    || (reach > 0.8 * loss_time && e.contains("fault 5 (contact lost)")),
                "{jump} N, the surface {reach} s away: {e}"
            );
        }
    }
    Ok(())
}

/// The surface steps' corners: every cell, soft to stiff, small to large set-points, the largest
/// steps both ways (issue #11: a 2.62 mm retreat on 10 kN/m at f_r 2 N ended on fault 5 — the search
/// counted its fast distance at the speed it asked for, not the one the limits let through, and went
/// on at approach speed where a surface that stops within 2·f_r allows far more; 14 of these 135
/// corners ended on fault 5 before). Every one must settle or end as `surface_step` allows; none may
/// trip the force limit on the search's re-contact (a 1 mm retreat on 500 kN/m on P1 at f_r 2 and
/// 20 N did, 65.6 / 65.5 N, while the search's stopping time was the delay and one cycle: the tool
/// stops 6.2–7.9 ms after the contact there, not 5 — `stopping_times`, `robust::stopping`).
#[test]
fn surface_step_corners() {
    for plant in &CELLS {
        for k_c in [10e3, 70e3, 500e3] {
            for f_r in [2.0, 20.0, 50.0] {
                for delta in [-0.003, -0.0005, 0.001, 0.00262, 0.003] {
                    if let Err(e) = surface_step(f_r, k_c, delta, plant) {
                        panic!("{plant:?}, {k_c} N/m, f_r {f_r} N, step {delta} m: {e}");
                    }
                }
            }
        }
    }
}

/// Surface steps on the 12 ms cell that 1000 and 5000 cases found, drawn values:
/// * a 0.66 mm retreat at f_r 2.6 N on 355 kN/m, whose touch-down bounced within its onset window
///   and fitted the bounce's 0 N sample as on the spring's line (`k̂_c` 256 kN/m; its search then
///   tripped the limit at 75.7 N);
/// * a 1.2 mm advance at f_r 7.2 N on 39.5 kN/m, a 54.7 N step whose conditioned force overshot the
///   60 N limit (60.05 N) and retracted;
/// * a 1.08 mm retreat at f_r 4.1 N on 374 kN/m, whose touch-down fit `k̂_c` 1.7 % low (1.6 of its
///   deviations) and whose fast search, stopping within the limit at that `k̂_c`, re-contacted at
///   60.2 N (the search now stops within the limit three deviations stiffer: 46.2 N);
/// * a 1.82 mm advance at f_r 33.6 N on 21.6 kN/m (5000 cases), whose re-fit rightly kept `k̂_c`;
///   the recursion, which had waited out the window, then compared the next sample with its
///   averages from before the step and read the 1.8 mm as a slope of almost none: `k̂_c` fell from
///   21.6 to 13.7 kN/m in one step, the loop rang, and the force was back in ±2 % after 1.07 s
///   (now 0.45 s: the recursion starts again where a re-fit ends without a fit).
#[test]
fn surface_steps_found_on_the_slow_cell() {
    let cases = [
        (2.649606391760847, 354693.7495260486, 0.000659256598849384),
        (7.247474537209428, 39538.86076955438, -0.0011990159879613563),
        (4.085307634032092, 373532.36814209307, 0.0010769273334807767),
        (
            33.60326138798699,
            21568.962259785367,
            -0.0018197796014105085,
        ),
    ];
    for (f_r, k_c, delta) in cases {
        if let Err(e) = surface_step(f_r, k_c, delta, &CELLS[2]) {
            panic!("f_r {f_r} N, {k_c} N/m, step {delta} m: {e}");
        }
    }
}

/// The touch-down criteria (see `touch_down_and_hold`).
fn touch_down(
    f_r: f64,
    k_c: f64,
    plant: &InnerLoopModel,
    noise: f64,
    seed: u64,
) -> Result<(), TestCaseError> {
    match touch_down_misses(f_r, k_c, plant, noise, seed)
        .into_iter()
        .next()
    {
        Some(miss) => Err(TestCaseError::fail(miss)),
        None => Ok(()),
    }
}

/// Every criterion of [`touch_down`] the run misses, in the order it asserts them (none: it holds).
fn touch_down_misses(
    f_r: f64,
    k_c: f64,
    plant: &InnerLoopModel,
    noise: f64,
    seed: u64,
) -> Vec<String> {
    let s = cell(3.0, k_c, 0.0, None, None, noise, seed);
    let r = match run(&s, plant, &tuning(f_r)) {
        Ok(r) => r,
        Err(e) => return vec![e.to_string()],
    };
    let all = r.metrics(0.0, f64::INFINITY);
    if !all.first_contact.is_finite() {
        return vec!["no contact".to_string()];
    }
    let mut misses = Vec::new();
    let mut check = |holds: bool, miss: String| {
        if !holds {
            misses.push(miss);
        }
    };
    let limit = 2.0 * f_r + floor(k_c, 0.002, plant);
    check(
        all.peak_force <= limit,
        format!("impact {} N > {limit} N", all.peak_force),
    );
    let hold = r.metrics(all.first_contact + 0.5, f64::INFINITY);
    check(
        hold.contact_losses == 0.0,
        format!("{} contact losses", hold.contact_losses),
    );
    let end = r.metrics(2.5, f64::INFINITY);
    let mean_err = mean_error(&r.rows, 2.5);
    check(
        mean_err <= 0.02 * f_r + 0.1 * noise,
        format!(
            "mean error {mean_err} N at the end (ripple {})",
            end.ss_ripple
        ),
    );
    if noise == 0.0 {
        check(
            all.settle_time <= 1.0,
            format!("settle {} s", all.settle_time),
        );
    }
    // B6 carried over: the true force's spread at the end is the loop's answer to the noise, a share
    // of it (at most 0.43 σ measured over 1000 cases but one), not a ringing of its own.
    check(
        end.true_force_std <= 0.02 * f_r + 0.5 * noise,
        format!("the true force's std {} N at the end", end.true_force_std),
    );
    // B8 carried over: the touch-down identifies `k̂_c` (noise-free within 2.2 % measured).
    if noise == 0.0 {
        check(
            end.kc_rel_error <= 0.1,
            format!("k̂_c off by {}", end.kc_rel_error),
        );
    }
    misses
}

/// Contact was declared no sooner than the tool touched the surface: the observed surface exists
/// from the first declared contact on.
fn declared_on_the_surface(r: &scenario::run::Run) -> Result<(), String> {
    let touched = r.metrics(0.0, f64::INFINITY).first_contact;
    let declared = r
        .rows
        .iter()
        .find(|row| !row.xc_hat.is_nan())
        .map(|row| row.t);
    match declared {
        Some(t) if t >= touched => Ok(()),
        _ => Err(format!(
            "contact declared at {declared:?} s, the surface touched at {touched} s"
        )),
    }
}

/// A noise spike in free air is no touch-down (issue #11): σ 0.9 N, f_r 20 N, P2, seed 7. No contact
/// is declared before the tool reaches the surface, and the touch-down criteria hold. (Before, the
/// noise meter was still rising from zero 0.2 s into the approach, the conditioned noise crossed the
/// 1 N contact threshold 0.6 mm short of the surface, that contact was lost, the surface was found as a
/// re-acquisition and not fitted, and on 500 kN/m the guess of 50 kN/m drove the force to 65.9 N:
/// fault 2 ended the run.)
#[test]
fn a_noise_spike_in_free_air_is_no_touch_down() {
    for k_c in [500e3, 100e3] {
        let plant = CELLS[1];
        let s = cell(3.0, k_c, 0.0, None, None, 0.9, 7);
        let r = run(&s, &plant, &tuning(20.0)).expect("no fault");
        if let Err(e) = declared_on_the_surface(&r) {
            panic!("{k_c} N/m: {e}");
        }
        if let Err(e) = touch_down(20.0, k_c, &plant, 0.9, 7) {
            panic!("{k_c} N/m: {e}");
        }
    }
}

/// A touch-down whose onset fit is not significant within `onset_window` waits for more samples
/// (`identify.onset_patience`) instead of keeping the tuning's guess: f_r 2 N on 10 kN/m, P1, σ 1 N,
/// where the whole rise is 0.2 mm. Seeds 6, 8 and 28 kept 50 kN/m (ending at 48.6, 48.6 and 50 kN/m
/// after the steady-contact fit's bounded rate) and failed the mean error at the end.
#[test]
fn a_noisy_touch_down_on_a_soft_surface_is_identified() {
    for seed in [6, 8, 28] {
        let s = cell(3.0, 10e3, 0.0, None, None, 1.0, seed);
        let r = run(&s, &CELLS[0], &tuning(2.0)).expect("no fault");
        let k = r.rows.last().expect("rows").kc_hat;
        assert!(k < 15e3, "seed {seed}: k̂_c {k} N/m on 10 kN/m");
        if let Err(e) = touch_down(2.0, 10e3, &CELLS[0], 1.0, seed) {
            panic!("seed {seed}: {e}");
        }
    }
}

/// The fallback feed-forward does not feed the sensor's noise forward on a soft surface on a slow
/// cell (`observer.deadband_significance`): f_r 2 N on 10 kN/m on the 12 ms cell under σ 1 N, where
/// the observer's velocity under noise alone is about 1.7 mm/s per newton against a dead-band of
/// 0.6 mm/s per newton. Seeds 3, 7 and 10 failed the touch-down criteria before — impacts of 19 N
/// and more against a bound of 4.7 N after a loss of contact, mean errors of 1.1–2 N at the end.
#[test]
fn a_noisy_hold_on_a_soft_surface_on_a_slow_cell_holds() {
    small_noisy_touch_downs_on_the_slow_cell(&[3, 7, 10]);
}

/// A hold at a small set-point under noise does not lift off on its own noise (the lift-off's count
/// of samples in a row below `lift`, [`controller::robust::ContactMachine::thresholds`]): f_r 2 N on
/// 10 kN/m on the 12 ms cell under σ 1 N, where 13 % of the hold's samples are below the 0.88 N lift
/// force. Seeds 46, 70 and 95 lifted off after 4 such samples in a row while the tool still pressed,
/// and the fast search pressed 15.3, 15.6 and 21 N into the surface (the bound is 4.7 N).
#[test]
fn a_noisy_hold_at_a_small_set_point_does_not_lift_off_on_its_noise() {
    small_noisy_touch_downs_on_the_slow_cell(&[46, 70, 95]);
}

/// The touch-down criteria for f_r 2 N on 10 kN/m on the 12 ms cell under σ 1 N, for each of `seeds`.
fn small_noisy_touch_downs_on_the_slow_cell(seeds: &[u64]) {
    for &seed in seeds {
        if let Err(e) = touch_down(2.0, 10e3, &CELLS[2], 1.0, seed) {
            panic!("seed {seed}: {e}");
        }
    }
}

/// Contact is not declared on noise while the noise is measured on few samples: f_r 2 N on 10 kN/m
/// on the 12 ms cell under σ 1 N, where the conditioning's step time is 4 samples, a deviation
/// known to about ±50 %. Seeds 27 and 154 declared contact in free air and ended on fault 5 (contact
/// lost 0.5 s), seed 31 declared it at 0.17 s, 0.37 s before the surface, and pressed 4.8 N.
#[test]
fn no_contact_is_declared_on_noise_measured_on_few_samples() {
    for seed in [27, 31, 154] {
        let s = cell(3.0, 10e3, 0.0, None, None, 1.0, seed);
        let r = run(&s, &CELLS[2], &tuning(2.0)).expect("no fault");
        if let Err(e) = declared_on_the_surface(&r) {
            panic!("seed {seed}: {e}");
        }
        if let Err(e) = touch_down(2.0, 10e3, &CELLS[2], 1.0, seed) {
            panic!("seed {seed}: {e}");
        }
    }
}

/// A noisy hold at a small set-point on P1 does not wander on its integral: f_r 2 N on 10 kN/m under
/// σ 1 N, seeds that ended 0.12–0.2 N off on average over the last 0.5 s (bound 0.14 N) while the
/// integral, at its full gain inside the noise, random-walked and the noise gate's weighted-down
/// proportional path let the force follow the walk. The integral's gain now falls with the noise
/// relative to the set-point (`response.integral_noise`).
#[test]
fn a_noisy_hold_at_a_small_set_point_does_not_wander_on_its_integral() {
    for seed in [46, 71, 73, 106, 116, 133, 171, 173, 183] {
        if let Err(e) = touch_down(2.0, 10e3, &CELLS[0], 1.0, seed) {
            panic!("seed {seed}: {e}");
        }
    }
}

/// Found with 1000 cases: a first sample 3.1 N of noise (σ 0.91 N, before any noise was measured a
/// strong raw sample is contact) was declared contact at f_r 21 N on 48 kN/m on P2, seed 625. The
/// law took it back as a spike in free air and approached on, but the loop's guard counted the
/// approach as contact lost while pressing and ended the run on fault 5 0.5 s later, just as the
/// tool reached the surface.
#[test]
fn a_contact_taken_back_at_the_start_is_not_a_lost_one() {
    touch_down(21.05, 48.25e3, &CELLS[1], 0.9065, 625).unwrap();
}

/// The touch-down's known limits under noise (see above), as failing seeds out of 1–199 per corner:
/// no more than measured when this was written.
#[test]
#[ignore = "995 closed-loop runs: the known limits' figures, not a criterion"]
fn noise_corners() {
    // (f_r, k_c, cell, σ); the failing seeds' bounds are in tests/census-bounds.toml (the 2 N,
    // 10 kN/m, 12 ms cell, σ 1 N corner: 59 → 58 → 54, the 5 N one 41 → 37: see
    // docs/robust-law-limits.md).
    let corners = [
        (2.0, 10e3, 0, 0.82),
        (2.0, 10e3, 0, 1.0),
        (20.0, 500e3, 1, 1.0),
        (5.0, 50e3, 2, 1.0),
        (2.0, 10e3, 2, 1.0),
    ];
    for (f_r, k_c, cell_i, noise) in corners {
        let failing = (1..200u64)
            .filter(|&seed| touch_down(f_r, k_c, &CELLS[cell_i], noise, seed).is_err())
            .count();
        let corner = format!("f_r {f_r} N, {k_c} N/m, cell {cell_i}, σ {noise} N");
        println!("{corner}: {failing} of 199 fail");
        let measured = common::bound("noise_corners", &corner);
        assert!(failing as f64 <= measured, "{failing} > {measured}");
    }
}

/// Every touch-down [`touch_down_and_hold`] draws (the same seeded cases: 3000, or
/// `FORCECELL_RANGE_CASES`), each miss printed and counted by its criterion, not stopped at the first
/// failing case as the property test is; no more than measured with 3000 cases (the known limits
/// list them): the true force's spread once, the mean error eight times (nine while the observer
/// learnt from a velocity a still measurement contradicts but the onset fit still took a sample
/// surely behind its surface for one on its line: f_r 4.26 N on 344 kN/m on the 12 ms cell under
/// σ 0.81 N, 0.187 N against 0.166 N), the impact twice, nothing else.
#[test]
#[ignore = "3000 closed-loop touch-downs: the known limits' figures, not a criterion"]
fn touch_down_census() {
    let cases = (
        2.0f64..50.0,
        stiffness(10e3, 500e3),
        0usize..3,
        prop_oneof![Just(0.0), 0.0f64..=1.0],
        1u64..1000,
    );
    let kinds = [
        "impact",
        "contact losses",
        "mean error",
        "settle",
        "std",
        "k̂_c",
        "loop ended",
    ];
    // No more than measured with 3000 cases: two impacts, eight mean errors, one spread, no fault.
    census(
        3000,
        cases,
        &kinds,
        "touch_down_census",
        |(f_r, k_c, cell_i, noise, seed)| {
            (
                format!("f_r {f_r:.2} N, {k_c:.0} N/m, cell {cell_i}, σ {noise:.3} N, seed {seed}"),
                touch_down_misses(f_r, k_c, &CELLS[cell_i], noise, seed),
            )
        },
    );
}

/// Every stiffness change [`stiffness_changes`] draws (the same seeded cases: 3000, or
/// `FORCECELL_RANGE_CASES`), each miss printed and counted by its criterion; no more than measured
/// with 3000 cases (the known limits list them): the mean error three times (small set-points under
/// noise; four before the predictor's extrapolated acceleration was bounded), nothing else. Before a jump's first sample was no excitation, also `k̂_c` once
/// ([`a_jump_s_first_sample_is_no_excitation`]). Also counted, not asserted by the property test: a
/// `k̂_c` beyond four deviations of what the change's information allows, where that allows no 10 %
/// — none (once, a damped doubling at f_r 2.5 N on the 12 ms cell, 49 % off against 29 %, until the
/// observer learnt from a velocity a still measurement contradicts); four times before a halving was no
/// crawling surface ([`a_halving_is_no_crawling_surface`]; at f_r 3.9 N on the 12 ms cell 53 % off,
/// now 12 %), twice before a window that rejects the stale stiffness was no hold
/// ([`a_window_that_rejects_the_stale_stiffness_is_no_hold`]).
#[test]
#[ignore = "3000 closed-loop stiffness changes: the known limits' figures, not a criterion"]
fn stiffness_changes_census() {
    let cases = (
        2.0f64..50.0,
        stiffness(20e3, 250e3),
        any::<bool>(),
        2.0f64..3.0,
        0usize..3,
        prop_oneof![Just(0.0), 0.0f64..0.5],
        prop_oneof![Just(0.0), 0.0f64..200.0],
        1u64..1000,
    );
    let kinds = [
        "contact losses",
        "mean error",
        "settle",
        "beyond its information",
        "k̂_c",
        "loop ended",
    ];
    census(
        3000,
        cases,
        &kinds,
        "stiffness_changes_census",
        |(f_r, k_c, double, at, cell_i, noise, c_e, seed)| {
            let c = Change {
                f_r,
                k_c,
                double,
                at,
                cell_i,
                noise,
                c_e,
                seed,
            };
            (format!("{c:?}"), change_misses(&c, true))
        },
    );
}

/// Moving surfaces beyond B5's two files (not a spec'd range, and not the issue's): a sine of 0.2,
/// 0.5 or 1 mm at 0.25, 0.5 or 1 Hz, starting at full speed at 2 s away from the tool or towards it,
/// on 10–500 kN/m, f_r 2–50 N, the three cells, 6 s each. Counted per stiffness: runs that end on a
/// fault, runs that end with `k̂_c` more than 15 % off, and runs that lose contact after 3 s — no more
/// than measured when this was written (docs/known-limits.md). Starting away from the tool only, at
/// the commit before the re-contact's wait and the drift test: 132 faults, 56 off, 17 lossy; before
/// `identify.max_refit_change` 93, 38, 22; before the fast search's re-contact waited 72, 23, 22
/// (towards it: 101, 30, 17); before a drifting surface kept re-fits from opening 69, 17, 22 (98, 32,
/// 17); before a re-fit weighed a moving surface against a stiffness change 67, 17, 21 (98, 32, 16);
/// with it 65, 18, 22 (93, 34, 16); with a feed-forward that backs off kept under the caution of an
/// unresolved rise 61, 17, 21 (78, 18, 21); now, with the recursion's `k̂_c` falling at most 10/s
/// instead of 30/s, 55, 6, 21 (towards it: 70, 20, 21); now, with the slow surfaces' feed-forward
/// (`observer.feedforward_speed`), 49, 3, 11 (towards it: 53, 19, 11); now, with a landing that
/// ends only once the force shows the contact, 49, 4, 11 (54, 18, 11); now, with a touch-down whose
/// force never showed the contact searched for at approach speed, 49, 4, 11 (53, 19, 11: one run on
/// 500 kN/m ends 15 % off instead of on a fault); now, with a jump's first sample no excitation for
/// the recursion, 49, 5, 11 (53, 19, 11: one fault moved from 300 to 500 kN/m, one more run off at
/// 500 kN/m, the worst trip at 300 kN/m 3.03 → 3.05); now, with a new `k̂_c` no surface motion to
/// the observer and the predictor, the predictor's jumps no longer integrating the motion they
/// contradict, and the recursion learning nothing while the observer holds a motion that began
/// after a calm contact, 44, 5, 10 (44, 3, 13: faults 102 → 88, `k̂_c` off 24 → 8, lossy 22 → 23,
/// one more at 500 kN/m; the worst trip at 300 kN/m 3.05 → 1.92, at 100 kN/m 1.46 → 1.07, RMS p90
/// 0.077 → 0.076, median 0.0071); now, with the recursion waiting on a slow motion (the feed-forward's) that began
/// after a calm contact too, 41, 2, 10 (44, 0, 13: faults 88 → 85, the slow sines at f_r 50 N on the
/// 12 ms cell, `k̂_c` off 8 → 2); now, with the search after a bounce chasing a surface seen
/// receding at the gentle speed plus the surface's, 19, 2, 17 (40, 0, 17: faults 85 → 59, of them
/// ending on a contact lost for 0.5 s 34 → 6; lossy 23 → 34 and the RMS p90 0.0762 → 0.0965, the
/// runs that no longer end on a fault counted — some hold, some go on bouncing off a surface that
/// recedes faster than the contact can follow; three that ended on fault 5 now trip at 66.9, 67.5
/// and 85.4 N, f_r 2 N on the 12 ms cell, surfaces whose own floor is 28–34 N). Also printed: how
/// many faults are forced — a surface approaching so fast that the set-point and its floor
/// `k_c·v·(delay + cycle)` are beyond the force limit (12 of the 59; the worst trip left, 2.78 × at
/// 500 kN/m, is one: 6.3 mm/s on the 12 ms cell), how many end on a contact lost for 0.5 s
/// (fault 5: 6), and of the other trips how many pressed past the limit without a contact lost
/// since the sine began (20) and how many on a re-contact (21). Also printed and bounded: the
/// highest true force of a faulted run (the trip's back-off included, [`run_to_end`]) over its force
/// limit — with the fall at 30/s 4.36 at 500 kN/m (262 N at f_r 20 N on the 12 ms cell), 3.03 at 300
/// kN/m — and how well the runs without a fault hold the force: the 90th percentile of their RMS error
/// after 3 s over the set-point, 0.264 before the slow surfaces' feed-forward, 0.077 with it (median
/// 0.0165 and 0.0075; 0.0073 with the landing's end above). Then, with the predictor's acceleration
/// bound 52 faults, with jumps in a row a ramp 41 (12 forced, 5 on fault 5, 11 pressed, 13 on a
/// re-contact); now, with the bound taking the velocity inferred with the excess acceleration along,
/// 37 (12, 5, 11, 9; `k̂_c` off 2, lossy 34, RMS p90 0.0999, as before); with the observer learning
/// from a velocity a still measurement contradicts (it had taken every cycle of it for a jump), 37,
/// `k̂_c` off 2, lossy 29, RMS p90 0.0973. Also printed: of the re-contacts, how many are forced (5
/// of 9: a sine starting away whose floor is above the set-point loses the contact at its start,
/// and comes back at the same peak speed), and of the other trips how many are forced once the
/// inner loop's lag `τ` counts in the floor too (8, all pressed: a surface approaching at `v` gains
/// `k_c·v·τ` more while the tool catches up with its command). Then, with a line that misses a clean
/// force far beyond its noise no stiffness change, 36 faults (0 / 0 / 0 / 11 / 25), `k̂_c` off 0,
/// lossy 29, RMS p90 0.0970. Since a steady contact's lift-off threshold rises with the measured
/// noise (which a moving surface's force shows too), 37 (0 / 0 / 0 / 11 / 26), lossy 28, RMS p90
/// 0.0965: one more run at 500 kN/m starting towards the tool ends on a fault.
#[test]
#[ignore = "1080 closed-loop runs: the known limits' figures, not a criterion"]
fn moving_surfaces() {
    // Per stiffness: faults, k̂_c off, lossy, the highest force of a faulted run over its limit;
    // and the RMS error after 3 s over the set-point of every run without a fault, its 90th
    // percentile: bounds in tests/census-bounds.toml.
    let b = |key: &str| common::bound("moving_surfaces", key);
    let rows = [10e3, 30e3, 100e3, 300e3, 500e3].map(|k_c: f64| {
        let at = |what: &str| b(&format!("{k_c} N/m {what}"));
        (k_c, at("faults"), at("off"), at("lossy"), at("worst"))
    });
    let (mut rel, rel_p90_measured) = (Vec::new(), b("rms p90"));
    // [away from the tool, towards it] × [faults, k̂_c off, lossy], over all stiffnesses.
    let mut all = [[0usize; 3]; 2];
    // Of the faults: forced (a surface approaching so fast that the set-point plus its own floor
    // `k_c·v·(delay + cycle)` is beyond the force limit: no law avoids the trip), contacts lost
    // for the loop's 0.5 s (fault 5), and the other trips: pressed past the limit without a contact
    // lost since the sine began, or on a re-contact.
    let (mut forced, mut lost, mut pressed, mut recontacts) = (0, 0, 0, 0);
    // Of the other trips, those forced once the inner loop's lag counts too: the tool follows a
    // command `τ` behind, so the floor is `k_c·v·(delay + cycle + τ)` (the leaves `τ` out).
    let mut forced_with_lag = 0;
    // Of the re-contacts, those forced too: a sine starting away from the tool whose floor is above
    // the set-point (the contact is lost at its start whatever the law: the force falls by the
    // floor before any answer arrives) comes back at the same peak speed, and a contact found again
    // while it approaches presses at least the set-point plus its floor.
    let mut recontacts_forced = 0;
    for (k_c, faults_measured, off_measured, lossy_measured, worst_measured) in rows {
        let mut counts = [[0usize; 3]; 2];
        // The highest true force of a run a fault ended, over its force limit.
        let mut worst = 0.0f64;
        for f_r in [2.0, 5.0, 20.0, 50.0] {
            for plant in &CELLS {
                for amplitude in [-1e-3, -0.5e-3, -0.2e-3, 0.2e-3, 0.5e-3, 1e-3] {
                    let way = usize::from(amplitude < 0.0);
                    for frequency in [0.25, 0.5, 1.0] {
                        let s = sine(k_c, amplitude, frequency);
                        let t = tuning(f_r);
                        let ended = run_to_end(&s, plant, &t).expect("a valid tuning");
                        if ended.fault.is_some() {
                            counts[way][0] += 1;
                            let v = std::f64::consts::TAU * frequency * amplitude.abs();
                            let limit = t.loop_cfg.process.max_force;
                            let is_forced = amplitude < 0.0 && f_r + floor(k_c, v, plant) > limit;
                            forced += usize::from(is_forced);
                            lost += usize::from(ended.fault_code == Some(5));
                            let with_lag = floor_after(k_c, v, plant, plant.tau);
                            forced_with_lag += usize::from(
                                !is_forced
                                    && ended.fault_code == Some(2)
                                    && amplitude < 0.0
                                    && f_r + with_lag > limit,
                            );
                            if !is_forced && ended.fault_code == Some(2) {
                                // Up to the force's first crossing of the limit: the trip's
                                // back-off lifts off after it.
                                let rows = &ended.run.rows;
                                let over = rows.iter().find(|r| r.f > limit);
                                let trip = over.map_or(f64::INFINITY, |r| r.t);
                                if ended.run.metrics(2.0, trip).contact_losses == 0.0 {
                                    pressed += 1;
                                } else {
                                    recontacts += 1;
                                    let fl = floor(k_c, v, plant);
                                    recontacts_forced += usize::from(
                                        amplitude > 0.0 && fl > f_r && f_r + fl > limit,
                                    );
                                }
                            }
                            let peak = ended.run.metrics(0.0, f64::INFINITY).peak_force;
                            worst = worst.max(peak / t.loop_cfg.process.max_force);
                            continue;
                        }
                        let m = ended.run.metrics(3.0, f64::INFINITY);
                        rel.push(m.rms_error / f_r);
                        if m.kc_rel_error > 0.15 {
                            counts[way][1] += 1;
                        } else if m.contact_losses > 0.0 {
                            counts[way][2] += 1;
                        }
                    }
                }
            }
        }
        let [away, towards] = counts;
        let [faults, off, lossy] = [0, 1, 2].map(|i| away[i] + towards[i]);
        println!(
            "{k_c} N/m: {faults} faults (the highest force {worst:.3} × the limit), {off} k̂_c off > \
             15 %, {lossy} lossy after 3 s, of 216 (faults / off / lossy starting away from the tool \
             {away:?}, towards it {towards:?})"
        );
        for (way, c) in counts.iter().enumerate() {
            for (i, n) in c.iter().enumerate() {
                all[way][i] += n;
            }
        }
        assert!(
            faults as f64 <= faults_measured,
            "{faults} faults > {faults_measured}"
        );
        assert!(off as f64 <= off_measured, "{off} off > {off_measured}");
        assert!(
            lossy as f64 <= lossy_measured,
            "{lossy} lossy > {lossy_measured}"
        );
        assert!(
            worst <= worst_measured,
            "{worst} × the limit > {worst_measured}"
        );
    }
    let [away, towards] = all;
    println!("all, of 540 each way: away from the tool {away:?}, towards it {towards:?}");
    println!(
        "of the {} faults: {forced} forced (approaching faster than the force limit allows at any \
         law), {lost} contacts lost for 0.5 s (fault 5); of the other trips {pressed} pressed past \
         the limit without losing contact since the sine began, {recontacts} on a re-contact \
         ({recontacts_forced} of them forced: the contact lost at the sine's start and the surface \
         back at a speed whose floor is beyond the limit); {forced_with_lag} of the other trips \
         forced once the inner loop's lag counts",
        away[0] + towards[0]
    );
    rel.sort_by(f64::total_cmp);
    let at = |q: f64| rel[((rel.len() - 1) as f64 * q).round() as usize];
    let (median, p90) = (at(0.5), at(0.9));
    println!(
        "RMS error after 3 s over the set-point, {} runs without a fault: median {median:.4}, 90th \
         percentile {p90:.4}",
        rel.len()
    );
    assert!(p90 <= rel_p90_measured, "{p90} > {rel_p90_measured}");
}

/// A surface receding at 0.31 mm/s (0.2 mm at 0.25 Hz, under `max_surface_speed`) on 500 kN/m at
/// f_r 20 N on P1 (a `moving_surfaces` case): the force drifted out of its band, which opened a re-fit
/// as for a stiffness change on a still surface, and the samples, the tool following the surface,
/// lay on a line of 183 kN/m through the surface before. The surface predictor, fed what that `k̂_c`
/// makes of the tool's motion, ran the command away: 268 N before the 60 N trip. A re-fit further
/// than `identify.max_refit_change` from `k̂_c` is not taken now: 22 N at most, `k̂_c` 500 kN/m.
#[test]
fn a_surface_receding_slowly_is_no_stiffness_change() {
    holds_a_sine(500e3, 0.2e-3, 0.25, &CELLS[0], 20.0, 2.0);
}

/// A sine surface ([`sine`]: `k_c` N/m, `amplitude` m, `frequency` Hz) under an `f_r` (N) contact
/// on `plant`: no fault, the peak force at most `peak` times the set-point, `k̂_c` within 10 %.
fn holds_a_sine(
    k_c: f64,
    amplitude: f64,
    frequency: f64,
    plant: &InnerLoopModel,
    f_r: f64,
    peak: f64,
) {
    let s = sine(k_c, amplitude, frequency);
    let r = run(&s, plant, &tuning(f_r)).expect("no fault");
    let m = r.metrics(0.0, f64::INFINITY);
    assert!(m.peak_force <= peak * f_r, "peak {} N", m.peak_force);
    assert!(m.kc_rel_error <= 0.1, "k̂_c off by {}", m.kc_rel_error);
}

/// A surface starting to move slowly (0.2 mm at 0.5 Hz: 0.63 mm/s, under `max_surface_speed`) under a
/// steady 20 N contact on 200 kN/m on P2: the force left its band and opened a re-fit, whose samples —
/// the tool following the surface — lay on a line through the surface before of 88 kN/m, within
/// `identify.max_refit_change`. With that `k̂_c` the surface predictor ran the command away: 172 N
/// before the 60 N trip (`forcecell sim` over the default wires too). The re-fit now weighs the other
/// explanation of its window, the stale stiffness on a surface moving at a constant speed, and
/// takes no stiffness change that explains no better (`robust::identify::refit`).
#[test]
fn a_slowly_moving_surface_is_no_softer_surface() {
    holds_a_sine(200e3, 0.2e-3, 0.5, &CELLS[1], 20.0, 1.5);
}

/// The same slow surface on 500 kN/m: each rise of the force opened a re-fit, and while it was
/// unresolved the law's caution (the stiffer hypothesis) fed no surface motion forward at all, so the
/// approaching surface pressed the force into a 60 N trip (fault 2 at 5.5 s, 84 N; with the moving fit
/// alone no trip, but 36 N over the default wires, 42 N in process, and the recursion, restarted after
/// each window, took `k̂_c` to 393 kN/m). The caution now keeps a feed-forward that backs off: 25 N
/// at most, `k̂_c` exact.
#[test]
fn a_slowly_approaching_stiff_surface_is_fed_forward_under_caution() {
    holds_a_sine(500e3, 0.2e-3, 0.5, &CELLS[1], 20.0, 1.5);
}

/// The same slow surface (0.2 mm at 0.5 Hz, 0.63 mm/s) on 500 kN/m at f_r 20 N, on P1 and P2: the
/// surface predictor's motion test counted it as still below `max_surface_speed` (1 mm/s), so nothing
/// of its motion was fed forward, and the force swung with it, 15–25 N on P2 (RMS error after 3 s
/// 1.69 N on P1 and 2.57 N on P2, over the default wires). The feed-forward now has its own speed,
/// `observer.feedforward_speed` (0.1 mm/s, and never within the noise); the identification takes
/// such a surface for a still one, but for the recursion's wait once it started after a calm contact
/// ([`a_slow_surface_that_starts_to_move_is_no_softer_surface`]).
#[test]
fn a_slow_surface_on_a_stiff_material_is_fed_forward() {
    for plant in &CELLS[..2] {
        let s = sine(500e3, 0.2e-3, 0.5);
        let r = run(&s, plant, &tuning(20.0)).expect("no fault");
        let m = r.metrics(3.0, f64::INFINITY);
        assert!(m.rms_error <= 0.5, "RMS error {} N", m.rms_error);
        assert!(m.kc_rel_error <= 0.02, "k̂_c off by {}", m.kc_rel_error);
    }
}

/// A surface that starts to move at full speed under a steady 20 N contact: 1 mm at 0.5 Hz (3.1 mm/s)
/// on 300 kN/m on P1, and 0.2 mm at 1 Hz (1.3 mm/s) on 100 kN/m on the 12 ms cell. The observer
/// established the motion at once, but the recursion's own motion flag (the predictor's test) passed
/// only on some samples — the tool's answer to the force hid the motion on the others — and the
/// recursion, learning in between, took the sine for a softer surface: `k̂_c` ended 26 % and 31 %
/// off (RMS error after 3 s 0.071 and 0.64 N). Now it learns nothing while the observer holds a
/// motion that began after a calm contact: `k̂_c` exact, RMS 0.090 and 0.34 N (the loop a little
/// slower on P1).
#[test]
fn a_surface_that_starts_to_move_is_no_softer_surface() {
    holds_a_sine(300e3, 1e-3, 0.5, &CELLS[0], 20.0, 1.1);
    holds_a_sine(100e3, -0.2e-3, 1.0, &CELLS[2], 20.0, 1.4);
}

/// A slow surface that starts to move under a steady 50 N contact on the 12 ms cell: 0.2 mm at
/// 0.25 Hz (0.31 mm/s) receding from 500 kN/m (a `moving_surfaces` case). Slower than
/// `max_surface_speed`, it was fed forward (the feed-forward's slow test), but the recursion took it
/// for a still surface and learnt from the tool's answer to the falling force, which the surface,
/// receding at a third of the tool's speed, made look softer: `k̂_c` fell at its 10/s from 493 to
/// 304 kN/m within 0.3 s, the loop's gain rose with it until the force rang into a lost contact, and
/// the re-contact (a re-fit of the ringing seeding 469 kN/m on it) tripped the 150 N limit at 247 N. So did 0.2 mm at 0.5 Hz and 0.5 mm at
/// 0.25 Hz on 300 kN/m (177 and 270 N). The recursion now waits on a slow motion that began after a
/// calm contact as on a fast one (`Motion::after_calm`): no fault, at most 58.8 N, `k̂_c` within
/// 1.4 %.
#[test]
fn a_slow_surface_that_starts_to_move_is_no_softer_surface() {
    for (k_c, amplitude, frequency) in [
        (500e3, 0.2e-3, 0.25),
        (300e3, 0.2e-3, 0.5),
        (300e3, 0.5e-3, 0.25),
    ] {
        holds_a_sine(k_c, amplitude, frequency, &CELLS[2], 50.0, 1.3);
    }
}

/// A surface that starts to move at its full speed under a steady 50 N contact on the 12 ms cell:
/// 0.5 mm at 1 Hz (3.1 mm/s) on 300 kN/m, towards the tool and away from it (`moving_surfaces`
/// cases). The surface predictor's constant-acceleration model read the velocity step as an
/// acceleration and carried it over the loop's lead: the command stepped 0.37 mm back in one cycle
/// where 0.05 mm answered the force, and the loop rang into trips at 190.6 and 153.3 N (150 N limit).
/// The predictor now extrapolates no more than `response.surface_acceleration`: no fault, at most
/// 86.8 and 56.3 N, `k̂_c` within 1 %.
#[test]
fn a_surface_that_starts_at_full_speed_is_not_extrapolated_past_its_path() {
    holds_a_sine(300e3, -0.5e-3, 1.0, &CELLS[2], 50.0, 1.8);
    holds_a_sine(300e3, 0.5e-3, 1.0, &CELLS[2], 50.0, 1.2);
}

/// A stiff surface that starts to move away at its full speed under a steady 50 N contact on the 12 ms
/// cell (`moving_surfaces` cases: 0.5 mm at 1 Hz on 500 kN/m, 1 mm at 1 Hz on 300 kN/m, 3.1 and 6.3
/// mm/s). Two samples into the motion the surface predictor's velocity stood at 4.3 mm/s where the
/// surface moved at 3.1: its constant-acceleration model had put the velocity step's excess into an
/// acceleration of 0.2 m/s² and the velocity together. The command bounded the acceleration but kept
/// the velocity inferred with it and led the surface by 0.11 mm (55 N at 500 kN/m): the tool ran into
/// the receding surface and the loop rang into trips at 212 and 181 N (150 N limit). The bound now
/// takes the velocity and position inferred with the excess acceleration along, by the filter's
/// correlations (`SurfacePredictor::command`): no fault, at most 99 and 109 N, `k̂_c` within 2 %.
#[test]
fn a_velocity_inferred_with_an_impossible_acceleration_is_not_extrapolated() {
    holds_a_sine(500e3, 0.5e-3, 1.0, &CELLS[2], 50.0, 2.1);
    holds_a_sine(300e3, 1e-3, 1.0, &CELLS[2], 50.0, 2.3);
}

/// Sines on 100 kN/m on the 12 ms cell (`moving_surfaces` cases: 1 mm at 1 Hz at f_r 20 N, 0.5 mm at
/// 0.5 Hz and 1 mm at 0.25 Hz at f_r 5 N, all starting away from the tool). The sine's start opened a
/// re-fit, and its window held the tool chasing a surface that slowed down: a line of 44 kN/m
/// explained it a little better than the stale stiffness on a surface at a constant speed (an SSE
/// of 14.1 against 17.4 N²), though it missed the samples by 1.7 N RMS where the clean sensor's
/// noise is 0.02 N. Taken, it tripped at 102 N or rang 29–58 % off. A line that leaves more than
/// `SIGNIFICANCE²` noise variances is no spring's now (unless the force comes through a filter,
/// whose shape a line misses by far more: `filtered` in `robust::identify`): no fault, at most 36,
/// 17 and 9 N, `k̂_c` within 10 %.
#[test]
fn a_line_that_misses_a_clean_force_far_beyond_its_noise_is_no_stiffness_change() {
    holds_a_sine(100e3, 1e-3, 1.0, &CELLS[2], 20.0, 2.0);
    holds_a_sine(100e3, 0.5e-3, 0.5, &CELLS[2], 5.0, 4.0);
    holds_a_sine(100e3, 1e-3, 0.25, &CELLS[2], 5.0, 2.5);
}

/// A stiff surface that starts towards the tool at full speed under a clean sensor
/// (`moving_surfaces` cases, 500 kN/m: 1 mm at 1 Hz, 6.3 mm/s, at f_r 2 and 5 N on P1; 0.5 mm at
/// 1 Hz, 3.1 mm/s, at f_r 5 N on P2). The force rises 3.1 N a millisecond on P1, each sample far
/// beyond the sensor's noise, so the surface predictor took every sample for a jump for the
/// conditioning's step time (31 ms on P1) and fed none of the motion forward: the conditioned force
/// lagging, the loop tripped the 60 N limit at 72.3, 73.6 and 64.5 N. Jumps in a row of the same
/// size are a ramp now, tracked at their speed from the third: no fault, at most 52.7 N.
#[test]
fn a_stiff_surface_starting_at_full_speed_is_no_series_of_jumps() {
    for (f_r, amplitude, plant) in [(2.0, -1e-3, 0), (5.0, -1e-3, 0), (5.0, -0.5e-3, 1)] {
        let r = run(&sine(500e3, amplitude, 1.0), &CELLS[plant], &tuning(f_r)).expect("no fault");
        let m = r.metrics(0.0, f64::INFINITY);
        assert!(m.peak_force <= 55.0, "peak {} N", m.peak_force);
        assert!(m.kc_rel_error <= 0.1, "k̂_c off by {}", m.kc_rel_error);
    }
}

/// A stiff surface receding faster than the gentle search (`moving_surfaces` cases on P2, 500 kN/m:
/// 0.5 mm at 0.25 Hz at f_r 2 N, 0.79 mm/s, and 1 mm at 0.25 Hz at f_r 5 N, 1.57 mm/s): the contact
/// is lost at the sine's start (its floor `k_c·v·(delay + cycle)`, 6.3 and 12.6 N, is above the
/// set-point), the fast search finds the surface and bounces off it, and the search after the
/// bounce, bounded to what stops within 2·f_r on a still surface (0.5 and 1.25 mm/s), never caught
/// it again: fault 5 after 0.5 s. It now chases a surface the search before found receding at that
/// speed plus the surface's, closing on it as gently as on a still one: no fault, no contact lost
/// after 3 s, 0.35 N RMS error after 3 s in both.
#[test]
fn a_receding_surface_is_chased_at_its_own_speed() {
    for (f_r, amplitude) in [(2.0, 0.5e-3), (5.0, 1e-3)] {
        let r = run(&sine(500e3, amplitude, 0.25), &CELLS[1], &tuning(f_r)).expect("no fault");
        let m = r.metrics(3.0, f64::INFINITY);
        assert_eq!(m.contact_losses, 0.0, "contacts lost after 3 s");
        assert!(m.rms_error <= 0.25 * f_r, "RMS error {} N", m.rms_error);
    }
}

/// A damped halving at a small set-point under noise on the 12 ms cell (f_r 2.06 N, 89.8 → 44.9 kN/m,
/// σ 0.26 N, 101 N·s/m; drawn by `stiffness_changes`, where its information allows no 10 % and nothing
/// was asserted): the re-fit found 48.5 kN/m (±3.3 %), but the other explanation of its window, the
/// stale stiffness on a surface moving at a constant speed, was within `pivot_gate`² noise variances
/// of it, and the margin went to the stale `k̂_c`, which stayed 98 % off. The better explanation is
/// taken now: `k̂_c` within four deviations of what the change tells (51 %; it ends 8.5 % off).
#[test]
fn a_damped_halving_under_noise_is_no_moving_surface() {
    let (f_r, k_c, at, noise) = (
        2.064646842136853,
        89753.88605904543,
        2.376788133324876,
        0.2556,
    );
    let s = cell(at + 2.0, k_c, 100.746, Some((at, 0.5)), None, noise, 647);
    let r = run(&s, &CELLS[2], &tuning(f_r)).expect("no fault");
    let m = r.metrics(at, f64::INFINITY);
    let bound = 4.0 * change_bound(f_r, 0.5, noise, &CELLS[2]);
    assert!(
        m.kc_rel_error <= bound,
        "k̂_c off by {} (bound {bound})",
        m.kc_rel_error
    );
    assert_eq!(m.contact_losses, 0.0, "lost contacts");
}

/// A touch-down the 3000 range cases draw (f_r 38.6 N on 454 kN/m on the 12 ms cell under σ 0.8 N,
/// seed 421): contact was declared on noise 290 µm short of the surface, the onset fit of that noise
/// gave `k̂_c` 33 kN/m at once, which ended the landing's approach-speed bound, and the command
/// stepped at the loop's 0.5 mm a cycle into the surface: 296 N, fault 2, backed off. The landing
/// now ends only once the force has shown the contact too (`robust::contact` `land`): the noise
/// contact lifts off at approach speed, and the touch-down that follows holds.
#[test]
fn a_contact_declared_on_noise_does_not_dash_into_a_stiff_surface() {
    let (f_r, k_c) = (38.61952439190985, 454117.21694586956);
    let s = cell(3.0, k_c, 0.0, None, None, 0.7975178058515975, 421);
    let t = tuning(f_r);
    let limit = 2.0 * f_r + floor(k_c, 0.002, &CELLS[2]);
    let ended = run_to_end(&s, &CELLS[2], &t).expect("a valid tuning");
    let peak = ended.run.metrics(0.0, f64::INFINITY).peak_force;
    assert!(ended.fault.is_none(), "the run ended on a fault");
    assert!(peak <= limit, "impact {peak} N > {limit} N");
}

/// The σ 1 N corner of `noise_corners` on P2 (f_r 20 N, 500 kN/m, seed 112): contact was declared on
/// noise 0.87 mm short of the surface, and no fit concluded. Past the onset window the landing's
/// approach-speed bound ended, and the command went on at the speed that stops within 2·f_r at the
/// tuning's guess of `k̂_c` (50 kN/m): 45 mm/s into the surface, a 2.6 times too soft fit of that
/// impact, and a ringing into 102 N, fault 2. A touch-down whose force has not shown the contact
/// goes on at approach speed however long it lasts, and its loss is no contact (`robust::contact`).
#[test]
fn a_contact_declared_on_noise_far_short_of_a_stiff_surface_approaches_on() {
    let (f_r, k_c) = (20.0, 500e3);
    let s = cell(3.0, k_c, 0.0, None, None, 1.0, 112);
    let limit = 2.0 * f_r + floor(k_c, 0.002, &CELLS[1]);
    let ended = run_to_end(&s, &CELLS[1], &tuning(f_r)).expect("a valid tuning");
    let peak = ended.run.metrics(0.0, f64::INFINITY).peak_force;
    println!("peak {peak:.1} N (bound {limit:.1} N)");
    assert!(ended.fault.is_none(), "the run ended on a fault");
    assert!(peak <= limit, "impact {peak} N > {limit} N");
}

/// The σ 1 N corner of `noise_corners` on the 12 ms cell at f_r 5 N on 50 kN/m, seed 112: a contact
/// declared on noise 0.55 mm short of the surface was fitted at 10–12 kN/m within its four samples and
/// taken back as a spike; the next touch-down, whose fit under that noise was not significant, began
/// from the noise's 10 kN/m and rang into a lost contact (peak 12.6 N). A touch-down taken back now
/// forgets what it identified (`Identifier::forget_touch_down`).
#[test]
fn a_touch_down_taken_back_leaves_no_fit_of_its_noise() {
    touch_down(5.0, 50e3, &CELLS[2], 1.0, 112).unwrap();
}

/// A touch-down the 1000 range cases draw (f_r 43 N on 12.6 kN/m on P2 under σ 0.68 N, seed 354):
/// seen through the tuning's guess (50 kN/m), the tool's own motion looked like the surface's, the
/// motion test ended the onset window before its fit, the landing ended on the guess, the command
/// ran in at 30 mm/s into 51 N, and the fit of that left `k̂_c` at 27 kN/m: the force rang at 34–51 N
/// for the whole run. A touch-down's window now outlasts motion until its fit is significant.
#[test]
fn a_soft_surface_under_a_stiff_guess_is_identified_before_the_landing_ends() {
    touch_down(
        42.94746419391765,
        12564.613878935359,
        &CELLS[1],
        0.684243801378516,
        354,
    )
    .unwrap();
}

/// A damped halving the 3000 `stiffness_changes` cases draw behind their first miss (f_r 40 N, 26.6
/// → 13.3 kN/m, 194 N·s/m, σ 0.18 N, the 12 ms cell, seed 258): the recursion learnt from the
/// jump's first sample, before the conditioned force left its band and the re-fit opened, and took
/// `k̂_c` 36 % up, the wrong way, in that one step (its rise limit on a 12 ms step); the loop and the
/// re-fit then worked against that, and `k̂_c` ended 19 % off where the change's information allows
/// 10 %. A raw force out of its band in a calm contact is no excitation now; `k̂_c` ends 0.6 % off.
#[test]
fn a_jump_s_first_sample_is_no_excitation() {
    let c = Change {
        f_r: 39.97872569606507,
        k_c: 26593.57595707148,
        double: false,
        at: 2.025879857904099,
        cell_i: 2,
        noise: 0.1817387478895071,
        c_e: 193.50865806883607,
        seed: 258,
    };
    assert!(4.0 * change_bound(c.f_r, 0.5, c.noise, &CELLS[2]) <= 0.1);
    identified_within(&c, 0.1);
}

/// A damped halving the 3000 `stiffness_changes` cases draw where `k̂_c` is not asserted (f_r 4.8 N,
/// 74.6 → 37.3 kN/m, 80 N·s/m, σ 0.47 N, the 12 ms cell, seed 886: the change's information allows
/// 40 %): the re-fit through the surface found 36.5 ± 1.1 kN/m, but the stale stiffness on a surface
/// crawling at 0.09 mm/s explained the window better (the tool advancing steadily, time and position
/// nearly collinear), and `k̂_c` was kept, 89 % off. A moving surface is no slower than the slowest
/// motion the law acts on (`observer.feedforward_speed`); `k̂_c` now ends 4 % off.
#[test]
fn a_halving_is_no_crawling_surface() {
    let damped = Change {
        f_r: 4.847431351152553,
        k_c: 74596.8085901484,
        double: false,
        at: 2.473893068108747,
        cell_i: 2,
        noise: 0.47163677404470283,
        c_e: 79.96571327926478,
        seed: 886,
    };
    identified_within(&damped, 0.1);
    // Undamped, at f_r 3.9 N under σ 0.42 N (seed 143): 53 % off against the 44 % its information
    // allows; now within that.
    let undamped = Change {
        f_r: 3.92880919831548,
        k_c: 35854.59425840925,
        double: false,
        at: 2.9636707257734654,
        cell_i: 2,
        noise: 0.424065370483518,
        c_e: 0.0,
        seed: 143,
    };
    let information = 4.0 * change_bound(undamped.f_r, 0.5, undamped.noise, &CELLS[2]);
    identified_within(&undamped, information);
}

/// A damped halving on P2 at a small set-point under noise (f_r 2.5 N, 78.4 → 39.2 kN/m, 135 N·s/m,
/// σ 0.47 N, seed 983; the first of the 3000 `stiffness_changes` cases to miss, on its mean error):
/// the re-fit's free line had 28 ± 11 kN/m, short of three deviations above zero, so the window was
/// taken for a hold that says nothing, although the same line put the stale 94 kN/m six deviations
/// off and the line through the surface said 45 ± 1.6 kN/m. `k̂_c` was kept, 139 % off (its
/// information allows 51 %), and the loop, 2.4 times too stiff in its model, left 0.16 N of mean
/// error. A window whose free line rejects the stale stiffness says something now: `k̂_c` ends
/// within its information, the mean error 0.103 N (against 0.097 N: still the known miss).
#[test]
fn a_window_that_rejects_the_stale_stiffness_is_no_hold() {
    let c = Change {
        f_r: 2.509072495832505,
        k_c: 78420.31737805235,
        double: false,
        at: 2.12866173718441,
        cell_i: 1,
        noise: 0.4655689792269648,
        c_e: 134.71756146313928,
        seed: 983,
    };
    identified_within(&c, 4.0 * change_bound(c.f_r, 0.5, c.noise, &CELLS[1]));
}

/// The change `c` holds the contact and ends with `k̂_c` within `bound` (relative); the error is
/// printed (`--nocapture`: the figure docs/known-limits.md quotes).
fn identified_within(c: &Change, bound: f64) {
    let after = c.run().unwrap().metrics(c.at, f64::INFINITY);
    println!("k̂_c off by {:.4} (bound {bound:.3})", after.kc_rel_error);
    assert_eq!(after.contact_losses, 0.0);
    assert!(
        after.kc_rel_error <= bound,
        "k̂_c off by {} beyond {bound}",
        after.kc_rel_error
    );
}

/// A noisy damped doubling at a small set-point on the 12 ms cell (found by 1000 `stiffness_changes`
/// cases with the slow surfaces' feed-forward): under the stale `k̂_c` the loop rang, and its ringing
/// showed an apparent surface motion above `observer.feedforward_speed` that the motion test passed
/// for a few samples at a time. Fed forward, it rang into three lost contacts. The slow surfaces'
/// test now confirms a motion over the loop's lead time, within which the ringing turns.
#[test]
fn a_loop_ringing_after_a_doubling_is_no_slow_surface() {
    let (f_r, k_c, at) = (2.49112030369369, 77173.92474520428, 2.796917972276051);
    let s = cell(
        at + 2.0,
        k_c,
        67.452,
        Some((at, 2.0)),
        None,
        0.35598832487743154,
        391,
    );
    let r = run(&s, &CELLS[2], &tuning(f_r)).expect("no fault");
    let m = r.metrics(at, f64::INFINITY);
    assert_eq!(m.contact_losses, 0.0, "lost contacts");
}

/// A surface approaching at 1.3 mm/s (0.2 mm at 1 Hz) under a 20 N contact on 500 kN/m on the 12 ms
/// cell (a `moving_surfaces` case): the recursion, the motion not established, took `k̂_c` from 487 to
/// 101 kN/m in five steps, and the loop, five times too soft, drove into 262 N before the trip's
/// back-off. `k̂_c` now falls at most 10/s (`estimator::MAX_FALL_RATE`): the run still ends on the
/// trip (not traced further), but at 60.2 N.
#[test]
fn a_trip_on_an_approaching_stiff_surface_presses_little_past_the_limit() {
    let t = tuning(20.0);
    let ended = run_to_end(&sine(500e3, -0.2e-3, 1.0), &CELLS[2], &t).expect("a valid tuning");
    let peak = ended.run.metrics(0.0, f64::INFINITY).peak_force;
    let limit = t.loop_cfg.process.max_force;
    assert!(
        peak <= 1.1 * limit,
        "peak {peak} N against the limit {limit} N"
    );
}

/// The tool's own stopping time after a fast re-contact, the figures behind the search's speed bound
/// ([`controller::robust::stopping`], docs/known-limits.md): a 1 mm retreat at f_r 2 N re-contacted
/// by the fast search, the force limit lifted to 1000 N (the search at its configured 50 mm/s, or at
/// what the limiter lets through), on every cell and 20–500 kN/m. The stopping time is the peak
/// penetration over the tool's speed when it touched (its last step before the contact), printed
/// beside the law's model at that speed (the contact just after a sample, the hardest stop) and the
/// delay and one cycle alone. The set-point's own penetration `f_r/k_c` is taken off the peak: the law
/// presses to it on purpose. Asserted: every run re-contacts and stops, and from 100 kN/m up the
/// model is never short (on softer surfaces the law, seeing a small force, does not brake hard).
#[test]
#[ignore = "figures for docs/known-limits.md, not a criterion"]
fn stopping_times() {
    for plant in &CELLS {
        let model_cell = scenario::run::cell_model(plant, &sim::SensorParams::default());
        let mut line = format!(
            "{:>4.0} ms cycle (delay + cycle {:.1} ms):",
            plant.period * 1e3,
            (plant.delay() + plant.period) * 1e3
        );
        for k_c in [20e3, 50e3, 100e3, 200e3, 500e3] {
            let mut t = tuning(2.0);
            let LawConfig::Robust(p) = &mut t.law else {
                unreachable!()
            };
            p.limits.max_force = 1000.0;
            let limits = p.limits;
            t.loop_cfg.process.max_force = 1000.0;
            let s = cell(3.0, k_c, 0.0, None, Some((2.0, 0.001)), 0.0, 1);
            let r = run(&s, plant, &t).expect("re-contacted and stopped");
            let rows: Vec<_> = r.rows.iter().filter(|r| r.t > 2.0).collect();
            let i = rows.iter().position(|r| r.x > r.x_c).expect("re-contacted");
            let v = (rows[i].x - rows[i - 1].x) / (rows[i].t - rows[i - 1].t);
            let peak = rows[i..]
                .iter()
                .take_while(|r| r.t < rows[i].t + 0.2)
                .map(|r| r.x - r.x_c)
                .fold(0.0, f64::max)
                - 2.0 / k_c;
            let model =
                controller::robust::stopping::travel(&model_cell, plant.period, &limits, v) / v;
            line += &format!(
                " {:.0} kN/m {:.0} mm/s {:.1} ms (model {:.1});",
                k_c / 1e3,
                v * 1e3,
                peak / v * 1e3,
                model * 1e3
            );
            if k_c >= 100e3 {
                assert!(peak / v <= model, "{plant:?}, {k_c} N/m: {line}");
            }
        }
        println!("{line}");
    }
}
