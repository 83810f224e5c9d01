//! The command out of contact: the approach, the search after a lost contact, the retract.
//!
//! Every speed towards a surface is bounded by what the cell can stop ([`Stopping`]: after the contact
//! is seen the tool still goes on for the delay and one cycle, and until the command has taken back
//! its lead over the lagging tool) in a surface of stiffness `k̂_c`. The approach stops within
//! `2·f_r`, the fast search after a lost contact below the force limit (less what the force may
//! reach before the contact is certainly seen: the limit is a trip); after `reacquire_distance` the
//! search is at the speed that stops within `2·f_r`, over a surface seen receding that speed plus the
//! surface's. Behind the position where contact was lost the search is fast: the tool was there.
//!
//! The fast search cannot also stop within `2·f_r` where a lost surface is found again close by (a
//! transient, B8): the commands that catch up with a retreating surface in time (B3: 1 mm in 50 ms on
//! P2, whose delay alone is 12 ms) are in the delay line before the tool has moved at all, so a surface
//! found close by is pressed by all of them. `reacquire_margin` trades one for the other: within
//! `reacquire_margin·f_r/k̂_c` of the position where contact was lost the search moves at the gentle
//! speed, which stops within `2·f_r` counting what the force reaches before the contact is certainly
//! seen (one raw sample at the strong threshold), and costs a surface that went away about
//! `reacquire_margin·T_s/2`. With `reacquire_margin = inf` (the `robust-gentle` tuning) every speed
//! of the search towards a surface not found yet is gentle.

use super::{ContactMachine, RETRACT_SPEED, Thresholds};
use crate::law::ContactState;
use crate::robust::Stopping;
use crate::robust::guards::STIFFNESS_GUARD;

/// Standard deviations of `k̂_c` above the estimate the fast search takes the surface's stiffness
/// for: its re-contact presses to the limit times `k_c/k̂_c`, and the limit is a trip (a 12 ms cell's
/// touch-down fit 1.7 % low, 1.6 of its deviations, re-contacted a 1.08 mm retreat at 60.2 N).
pub const TRIP_CONFIDENCE: f64 = 3.0;

/// Speeds out of contact for one step, bounded by what the cell can stop (see
/// [`ContactMachine::speeds`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Speeds {
    /// Approach and slow search, m/s.
    pub approach: f64,
    /// Search past the fast distance, and a landing the force does not touch: stops within twice the
    /// set-point, the detection not counted (as the approach), m/s.
    pub near: f64,
    /// Search within `margin`: stops within twice the set-point counting what the force reaches
    /// before the contact is certainly seen (the approach's speed where seeing it takes more), m/s.
    pub gentle: f64,
    /// Fast search after a loss of contact, farther on: stops below the force limit, m/s.
    pub reacquire: f64,
    /// How far beyond the position where contact was lost the search is `gentle`, m.
    pub margin: f64,
    /// One set-point penetration `f_r/k̂_c`, m.
    pub penetration: f64,
}

impl ContactMachine {
    /// Speeds for stiffness estimate `k` (N/m) known to relative deviation `k_sd`, set-point `f_r`
    /// (N), force limit `max_force` (N) and `seen` (N: what the force may reach before a contact is
    /// certainly seen, one raw sample at the strong threshold): the approach and the search near the
    /// lost contact no faster than the cell stops within `2·f_r` at `k`; the gentle search and the
    /// fast search no faster than it stops within `2·f_r − seen` and `max_force − seen` at `k`
    /// `TRIP_CONFIDENCE` deviations stiffer (bounds, not targets; the gentle one at the approach's
    /// speed where `seen` is more than `2·f_r`: under noise whose strong threshold is beyond it)
    /// ([`Stopping`]).
    pub fn speeds(
        &self,
        k: f64,
        k_sd: f64,
        f_r: f64,
        max_force: f64,
        seen: f64,
        stop: &Stopping,
    ) -> Speeds {
        let c = &self.p;
        let k_trip = k * (1.0 + TRIP_CONFIDENCE * k_sd.max(0.0));
        let twice = 2.0 * f_r.max(c.contact_force);
        let approach = stop.speed_within(twice, k, c.approach_speed);
        let near = stop.speed_within(twice, k, c.reacquire_speed).max(approach);
        Speeds {
            approach,
            near,
            gentle: if twice > seen {
                stop.speed_within(twice - seen, k_trip, c.reacquire_speed)
            } else {
                approach
            },
            reacquire: stop
                .speed_within(max_force - seen, k_trip, c.reacquire_speed)
                .max(near),
            margin: c.reacquire_margin * f_r.max(c.contact_force) / k.max(STIFFNESS_GUARD),
            penetration: f_r.max(c.contact_force) / k.max(STIFFNESS_GUARD),
        }
    }

    /// The command out of contact, `None` in contact (`command`), after taking in
    /// whether this step identified the stiffness touched down on (`identified`).
    pub fn search_command(&mut self, i: &SearchInput<'_>) -> Option<f64> {
        if i.identified {
            self.identified();
        }
        self.command(i.x, i.u, i.speeds, i.anchor, i.dt)
    }

    /// The command in contact: the law's `want` through the touch-down's bounds
    /// (`touch`, then `land`).
    pub fn landing_command(&mut self, i: &LandInput<'_>) -> f64 {
        let touching = self.touch(i.ff, i.th, i.confirm, i.dt);
        self.land(i.want, i.u, i.speeds, i.open, touching, i.dt)
    }

    /// The stiffness of the surface touched down on is identified: the landing is over once the force
    /// shows the contact too (see [`land`](Self::land)).
    pub(super) fn identified(&mut self) {
        self.fitted = true;
    }

    /// Whether the conditioned force `ff` (N) touches this contact step (above `th.contact`), and
    /// what it shows of the contact: above it for `confirm` s without a break, or once above
    /// `th.strong` (`evidence.rs`). Called once a step in contact, before [`land`](Self::land).
    pub(super) fn touch(&mut self, ff: f64, th: &Thresholds, confirm: f64, dt: f64) -> bool {
        self.evidence.conditioned(ff, th, confirm, dt)
    }

    /// The command in contact `want` during a touch-down, while its onset window is `open` (the
    /// identification's, stretched by its patience while the fit is not significant) and the force
    /// is `touching` ([`touch`](Self::touch)): until `k̂_c` is the surface's and not the tuning's
    /// guess, and the force has shown the contact (the conditioned force above the contact threshold
    /// for the step time without a break, or once above the strong threshold, or the raw mean since
    /// the declaration: `evidence.rs`), the command goes on in at no more
    /// than the approach speed from the last command `u` (a guess too soft would command a step deep
    /// into the surface; the approach's speed is what the impact bound is made of). A contact
    /// declared on a noise spike short of the surface, whose onset fit of that noise gave a `k̂_c` at
    /// once, ended the landing there, and the command stepped at the loop's 0.5 mm a cycle into the
    /// surface (f_r 38.6 N on 454 kN/m on the 12 ms cell under σ 0.8 N: 296 N). A window that closed
    /// at its 0.1 s while the fit waited on its patience let the tuning's guess through: on 12.6 kN/m
    /// at f_r 43 N on P2 under σ 0.68 N the command ran at 30 mm/s into 51 N, and the fit of that
    /// run-in left `k̂_c` twice too stiff and the loop ringing. Later, while the force shows no
    /// touch (the conditioned force below the contact threshold), no faster than stops within
    /// `2·f_r`, or than the approach while the landing is not over: a contact declared on noise short
    /// of the surface, with the `k̂_c` of a fit of noise or the tuning's guess, would otherwise drive
    /// in at the force error over that stiffness per cycle (on the 12 ms cell 27 mm/s, into 44 N; on
    /// P2 45 mm/s into a 500 kN/m surface, 102 N).
    pub(super) fn land(
        &mut self,
        want: f64,
        u: f64,
        sp: &Speeds,
        open: bool,
        touching: bool,
        dt: f64,
    ) -> f64 {
        if self.landing && self.fitted && self.evidence.shown() {
            self.landing = false;
        }
        if self.landing && open {
            want.min(u + sp.approach * dt)
        } else if !touching {
            let speed = if self.landing { sp.approach } else { sp.near };
            want.min(u + speed * dt)
        } else {
            want
        }
    }

    /// The command out of contact (`None` in contact): from the last command `u` and the measured
    /// position `x`, never more than `anchor` (s at approach speed) ahead of the robot.
    pub(super) fn command(
        &mut self,
        x: f64,
        u: f64,
        sp: &Speeds,
        anchor: f64,
        dt: f64,
    ) -> Option<f64> {
        let c = self.p;
        // The travel counts the command the limits let through (the last one, `u`).
        let moved = if self.last_u.is_nan() {
            0.0
        } else {
            u - self.last_u
        };
        self.last_u = u;
        match self.state {
            ContactState::Approach => {
                let gap = sp.approach * anchor;
                Some((u + sp.approach * dt).min(x + gap))
            }
            ContactState::Reacquire => {
                self.travelled += moved.max(0.0);
                // Fast back to where contact was lost (less one set-point penetration): the tool
                // was there, the surface is not nearer (a loss of contact the loop's own answer
                // made, or a bounce, can leave the tool millimetres behind). Beyond it bounded near
                // the lost contact, fast farther on; after the fast distance at what stops within
                // 2·f_r (after a bounce or the tool's own retreat at approach speed: the `k̂_c` the
                // speed is bounded with may be a fit of noise), or faster when the surface was seen
                // receding at lift-off (a receding surface outruns a slow search). After a bounce
                // off a re-contact, a surface seen going away during the search before is chased at
                // up to the speed that stops within 2·f_r plus the speed it was seen at: it closes on
                // a surface that goes on receding no faster than the gentle search on a still one
                // (B5b's sine start on P2: the observer, restarted at the re-contact, saw 0.2 mm/s of
                // the surface's 6 mm/s, and the search at approach speed caught it 0.21 s later as it
                // turned; at the seen speed, bounded only by the fast search, it hit at 18 N; bounded
                // by the gentle speed alone, a stiff surface receding faster than that was never
                // caught: f_r 2 N on 500 kN/m on P2 receding at 0.79 mm/s, fault 5).
                // Within the margin beyond the lost contact, what stops within 2·f_r is the gentle
                // speed, the detection counted.
                let gentle = sp.margin > 0.0 && u < self.x_lost + sp.margin;
                let near = if gentle { sp.gentle } else { sp.near };
                let speed = if u < self.x_lost - sp.penetration {
                    sp.reacquire
                } else if self.travelled >= c.reacquire_distance {
                    let slow = if self.slow { sp.approach } else { near };
                    let chase =
                        (sp.approach + c.reacquire_outrun * self.v_seen).min(near + self.v_seen);
                    slow.max(sp.approach + c.reacquire_outrun * self.v_lost)
                        .max(chase)
                        .min(sp.reacquire)
                } else if gentle {
                    sp.gentle
                } else {
                    sp.reacquire
                };
                let gap = c.reacquire_distance + sp.approach * anchor;
                self.fast = speed > sp.near;
                Some((u + speed * dt).min(x + gap))
            }
            ContactState::Retract => {
                self.travelled += (-moved).max(0.0);
                Some(u - RETRACT_SPEED * dt)
            }
            ContactState::Contact => None,
        }
    }
}

/// The out-of-contact command's input ([`ContactMachine::search_command`]).
#[derive(Clone, Copy, Debug)]
pub struct SearchInput<'a> {
    /// The measured position, m.
    pub x: f64,
    /// The last command the limits let through, m.
    pub u: f64,
    /// The speeds now.
    pub speeds: &'a Speeds,
    /// How far ahead of the robot the command may run, s at approach speed.
    pub anchor: f64,
    /// The step, s.
    pub dt: f64,
    /// This step's identification set `k̂_c` from the touch-down's fit.
    pub identified: bool,
}

/// The in-contact command's input ([`ContactMachine::landing_command`]).
#[derive(Clone, Copy, Debug)]
pub struct LandInput<'a> {
    /// The law's command in contact, m.
    pub want: f64,
    /// The last command the limits let through, m.
    pub u: f64,
    /// The speeds now.
    pub speeds: &'a Speeds,
    /// The identification's onset window is open.
    pub open: bool,
    /// The conditioned force, N.
    pub ff: f64,
    /// The detector's thresholds.
    pub th: &'a Thresholds,
    /// How long the force must show the contact, s.
    pub confirm: f64,
    /// The step, s.
    pub dt: f64,
}
