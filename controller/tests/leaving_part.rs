//! Leaving the part while pressing (`scenarios/edge-pass.toml`, `hole-pass.toml`, `hole-hold.toml`):
//! a pass that runs off the part's edge or over a hole, with the robot program's process channels,
//! and a hold without them whose surface drops away. In each, on P1 and P2:
//! - no force above the set-point's pressing band (`F·(1 + tolerance)`) at any time;
//! - the search for the lost surface never commands deeper than `search_depth` beyond the law's last
//!   command in contact;
//! - the run ends on fault 5 (backed off), and the correction is back on the programmed path (zero,
//!   or behind it) before the robot gets its `Stop`.
//!
//! Before the search was bounded, the edge pass searched 21 mm past the last surface and the session
//! ended with the correction still there.

use controller::{ContactState, Tuning};
use scenario::run::run_watched;
use scenario::scenario::{Scenario, load_tuning};
use sim::InnerLoopModel;

const PLANTS: [(&str, InnerLoopModel); 2] =
    [("P1", InnerLoopModel::P1), ("P2", InnerLoopModel::P2)];

/// What one cycle showed: the law's contact state, the normal command sent, the set-point in effect.
#[derive(Clone, Copy, Debug)]
struct Seen {
    state: Option<ContactState>,
    cmd: f64,
    set_point: f64,
}

fn leave(name: &str) {
    let scenario = Scenario::load(name).expect("a built-in scenario");
    let tuning: Tuning = load_tuning(&scenario.tuning).expect("its tuning");
    let cfg = tuning.loop_cfg.process;
    for (plant_name, plant) in PLANTS {
        let mut seen = Vec::new();
        let ended = run_watched(&scenario, &plant, &tuning, &mut |r, _| {
            seen.push(Seen {
                state: r.out.state,
                cmd: r.command.translation.z,
                set_point: r.set_point,
            })
        })
        .expect("the law builds");
        let at = format!("{name} on {plant_name}");
        // The true force of the control's cycles (the return only moves away: asserted below).
        let f_true: Vec<f64> = ended.run.rows.iter().map(|r| r.f_true).collect();
        let f_max = seen.iter().map(|s| s.set_point).fold(0.0f64, f64::max).max(
            scenario.program.as_ref().map_or(0.0, |p| {
                p.segments.iter().map(|s| s.force).fold(0.0, f64::max)
            }),
        );
        let peak = f_true.iter().copied().fold(0.0f64, f64::max);
        assert!(
            peak <= f_max * (1.0 + cfg.tolerance),
            "{at}: {peak} N above the pressing band of {f_max} N"
        );

        // The search's depth, from the law's last command in contact.
        let mut contact_cmd = None;
        let mut deepest = 0.0f64;
        for s in &seen {
            match s.state {
                Some(ContactState::Contact) => contact_cmd = Some(s.cmd),
                Some(ContactState::Approach) => contact_cmd = None,
                _ => {
                    if let Some(c) = contact_cmd {
                        deepest = deepest.max(s.cmd - c);
                    }
                }
            }
        }
        assert!(
            deepest <= cfg.search_depth + 1e-12,
            "{at}: searched {} mm beyond the last contact (search_depth {} mm)",
            deepest * 1e3,
            cfg.search_depth * 1e3
        );
        assert!(
            deepest > 0.5 * cfg.search_depth,
            "{at}: the search ran out its bound ({} mm): the surface was gone",
            deepest * 1e3
        );

        assert_eq!(ended.fault_code.or(Some(5)), Some(5), "{at}");
        let why = ended
            .fault
            .as_ref()
            .map(|e| e.to_string())
            .or(ended.aborted.clone())
            .unwrap_or_else(|| panic!("{at}: the run ended early"));
        assert!(
            why.contains("FAULT 5") || why.contains("search reached"),
            "{at}: {why}"
        );
        let last = seen.last().expect("cycles were answered");
        assert!(
            last.cmd <= 0.0,
            "{at}: the correction ended at {} mm, not back on the path",
            last.cmd * 1e3
        );
        assert!(ended.stopped, "{at}: the robot got its Stop");
        // The return went no deeper, and no faster than the retract speed allows.
        let unwound: Vec<f64> = seen[ended.run.rows.len()..].iter().map(|s| s.cmd).collect();
        assert!(!unwound.is_empty(), "{at}: a return was answered");
        for w in unwound.windows(2) {
            assert!(w[1] <= w[0], "{at}: the return went towards the part");
            assert!(
                w[0] - w[1] <= tuning.loop_cfg.retract_speed * plant.period + 1e-12,
                "{at}: the return stepped {} mm in one cycle",
                (w[0] - w[1]) * 1e3
            );
        }
    }
}

#[test]
fn a_pass_off_the_parts_edge_stops_its_search_and_returns_to_the_path() {
    leave("edge-pass");
}

#[test]
fn a_pass_over_a_hole_stops_its_search_and_returns_to_the_path() {
    leave("hole-pass");
}

#[test]
fn a_hold_without_process_channels_whose_surface_drops_away_returns_to_the_path() {
    leave("hole-hold");
}
