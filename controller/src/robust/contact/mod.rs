//! The contact state machine: `Approach` (bounded speed, anchored to the measured position) → `Contact`
//! when the conditioned force reaches `contact_force` (confirmed by the raw one), or one raw sample
//! `strong_contact` times that → `Reacquire` when the raw force stays below `lift_force` for `samples` in a row
//! (fast back to where contact was lost and for `reacquire_distance` beyond, optionally bounded by what
//! the cell can stop near it, then at what stops within `2·f_r`: `search.rs`) → `Contact` … and from
//! anywhere `Retract` when the conditioned force exceeds the force limit and the raw one confirms it.
//! A touch-down from the approach lost within a bounce before its stiffness was identified, or lost
//! before its force ever showed the contact, goes back to `Approach` (and the law forgets what it
//! identified there).

use super::signals::Signals;
use crate::law::ContactState;
use evidence::Evidence;

/// What a step of the state machine did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transition {
    /// Nothing.
    None,
    /// Contact declared; `from_approach`: made from the approach (a still surface).
    Contact {
        /// Made from the approach (a still surface).
        from_approach: bool,
    },
    /// Contact lost.
    LiftOff,
    /// The force limit: retracting.
    ForceLimit,
}

/// What one step of the contact machine gives the rest of the law: the transition, and the state,
/// the steadiness and the search as they are after it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactStep {
    /// What the step did.
    pub transition: Transition,
    /// The state after it.
    pub state: ContactState,
    /// The contact has lasted longer than a bounce.
    pub steady: bool,
    /// The search that ended in this step's re-contact (meaningful on a re-contact).
    pub search: Search,
}

/// The search that ended in a re-contact: where it began and how.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Search {
    /// The measured position where contact was lost, m.
    pub x_lost: f64,
    /// The time searched since, s.
    pub t_lost: f64,
    /// The search's last command was faster than what stops within `2·f_r`: its momentum presses the
    /// surface beyond the set-point at the re-contact.
    pub fast: bool,
}

/// The state machine's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactMachine {
    p: ContactParams,
    state: ContactState,
    /// For how many samples in a row the raw force has been below the lift force (at least two, see
    /// `Thresholds::samples`: the time it held, `contact.lift_time` of 2 ms once, is that at 1 kHz).
    below_samples: u32,
    /// Distance the command travelled in the current re-acquire or retract, m: what the limits let
    /// through, not what was asked for (near a stop the limiter brakes the command).
    travelled: f64,
    /// The last command seen in that re-acquire or retract, m (NaN: none yet).
    last_u: f64,
    /// Time since contact was last detected, s.
    in_contact: f64,
    /// The observed surface velocity away from the tool when contact was last lost, m/s.
    v_lost: f64,
    /// The measured position when contact was last lost, m.
    x_lost: f64,
    /// Time searched since contact was last lost, s.
    t_lost: f64,
    /// How fast the surface went away during the search that ended in the last re-contact: the
    /// re-contact's position less the loss's, over the search's time (0 when it came nearer, and
    /// after a touch-down from the approach), m/s. Kept through a bounce off that re-contact (the
    /// surface is going away at about that speed while the observer, restarted at the re-contact,
    /// has not seen it move); a steady contact's loss clears it.
    v_seen: f64,
    /// That loss is searched for at approach speed (a bounce, or the tool moving away).
    slow: bool,
    /// The search's last command was faster than what stops within `2·f_r` (the fast search).
    fast: bool,
    /// A touch-down from the approach whose stiffness is not identified yet, or whose force has not
    /// shown the contact yet (for as long as a step takes to pass the conditioning, or beyond what a
    /// noise spike reaches).
    landing: bool,
    /// The touch-down's stiffness is identified.
    fitted: bool,
    /// What the force has shown since contact was declared.
    evidence: Evidence,
}

impl ContactMachine {
    /// A machine approaching.
    pub fn new(p: ContactParams) -> Self {
        let mut m = Self {
            p,
            state: ContactState::Approach,
            below_samples: 0,
            travelled: 0.0,
            last_u: f64::NAN,
            in_contact: f64::INFINITY,
            v_lost: 0.0,
            x_lost: 0.0,
            t_lost: 0.0,
            v_seen: 0.0,
            slow: false,
            fast: false,
            landing: false,
            fitted: false,
            evidence: Evidence::default(),
        };
        m.reset();
        m
    }

    /// Take new parameters, keeping the state.
    pub fn set_params(&mut self, p: ContactParams) {
        self.p = p;
    }

    /// Back to the approach.
    pub fn reset(&mut self) {
        self.state = ContactState::Approach;
        self.below_samples = 0;
        self.travelled = 0.0;
        self.last_u = f64::NAN;
        self.in_contact = f64::INFINITY;
        self.v_lost = 0.0;
        self.x_lost = 0.0;
        self.t_lost = 0.0;
        self.v_seen = 0.0;
        self.slow = false;
        self.fast = false;
        self.landing = false;
        self.fitted = false;
        self.evidence.reset();
    }

    /// Whether the contact has lasted longer than a bounce (a steady contact), s.
    fn steady(&self) -> bool {
        self.state == ContactState::Contact && self.in_contact >= self.p.bounce_time
    }

    /// The search that ended in a re-contact this step.
    fn search(&self) -> Search {
        Search {
            x_lost: self.x_lost,
            t_lost: self.t_lost,
            fast: self.fast,
        }
    }

    /// The state.
    pub fn state(&self) -> ContactState {
        self.state
    }

    /// Advance with this step's signals; `max_force` is the force limit, N, and `receding` the observed
    /// surface's velocity away from the tool, m/s.
    pub fn step(
        &mut self,
        s: &Signals,
        th: &Thresholds,
        max_force: f64,
        receding: f64,
        dt: f64,
    ) -> ContactStep {
        let transition = self.advance(s, th, max_force, receding, dt);
        ContactStep {
            transition,
            state: self.state,
            steady: self.steady(),
            search: self.search(),
        }
    }

    fn advance(
        &mut self,
        s: &Signals,
        th: &Thresholds,
        max_force: f64,
        receding: f64,
        dt: f64,
    ) -> Transition {
        let c = self.p;
        // The conditioned force, confirmed by the raw one: the conditioning overshoots a step (on
        // the 12 ms cell a 54.7 N surface step read 60.05 N against a 60 N limit).
        if s.ff > max_force && s.f > max_force && self.state != ContactState::Retract {
            self.state = ContactState::Retract;
            self.landing = false;
            self.travelled = 0.0;
            self.last_u = f64::NAN;
            return Transition::ForceLimit;
        }
        match self.state {
            ContactState::Approach | ContactState::Reacquire => {
                // The conditioned force, confirmed by the raw one (the filter still remembers a
                // contact just lost), or one strong raw sample.
                if self.state == ContactState::Reacquire {
                    self.t_lost += dt;
                }
                if (s.ff >= th.contact && s.f >= th.lift) || s.f >= th.strong {
                    let from_approach = self.state == ContactState::Approach;
                    self.v_seen = if from_approach {
                        0.0
                    } else {
                        ((s.x - self.x_lost) / self.t_lost.max(dt)).max(0.0)
                    };
                    self.landing = from_approach;
                    self.fitted = false;
                    self.evidence.reset();
                    self.state = ContactState::Contact;
                    self.below_samples = 0;
                    self.in_contact = 0.0;
                    return Transition::Contact { from_approach };
                }
            }
            ContactState::Contact => {
                self.in_contact += dt;
                self.evidence.raw(s.f, th);
                // A steady contact's samples are held at the set-point: a lost one's are noise about
                // zero, below a threshold raised with the noise (`Thresholds::lift_off`).
                let (lift, samples) = if self.steady() && !self.landing {
                    (th.lift_off, th.off_samples)
                } else {
                    (th.lift, th.samples)
                };
                if s.f < lift {
                    self.below_samples += 1;
                    if self.below_samples >= samples {
                        let shown = self.evidence.shown();
                        if self.landing && (self.in_contact < c.bounce_time || !shown) {
                            // A touch-down lost before its stiffness was identified and shown by
                            // the force, within a bounce, or whose force never showed the contact:
                            // nothing was learnt of a surface (a noise spike in free air looks like
                            // this). The approach goes on, and the next contact is a touch-down
                            // again, fitted.
                            self.state = ContactState::Approach;
                            self.landing = false;
                            return Transition::LiftOff;
                        }
                        self.state = ContactState::Reacquire;
                        // The fast search is for a surface that went away. A contact lost while the
                        // tool itself was moving away (the law's own answer to a force jump), or lost
                        // again soon after a re-acquisition (a bounce), is searched for at approach
                        // speed.
                        let retracting = s.v_x < -c.approach_speed;
                        self.slow = retracting || self.in_contact < c.bounce_time;
                        self.travelled = if self.slow { c.reacquire_distance } else { 0.0 };
                        self.last_u = f64::NAN;
                        self.v_lost = receding;
                        if self.in_contact >= c.bounce_time {
                            self.v_seen = 0.0;
                        }
                        self.t_lost = 0.0;
                        self.landing = false;
                        self.x_lost = s.x;
                        return Transition::LiftOff;
                    }
                } else {
                    self.below_samples = 0;
                }
            }
            ContactState::Retract => {
                if self.travelled >= RETRACT_DISTANCE && s.ff < th.lift {
                    self.state = ContactState::Approach;
                }
            }
        }
        Transition::None
    }
}

mod evidence;
mod params;
mod search;
#[cfg(test)]
mod tests;
mod thresholds;

pub use params::{ContactParams, RETRACT_DISTANCE, RETRACT_SPEED};
pub use search::{LandInput, SearchInput, Speeds};
pub use thresholds::{LIFT_NOISE, SIGNIFICANCE, Thresholds};
