//! The contact state machine: `Approach` (bounded speed, anchored to the measured position) → `Contact`
//! when the conditioned force reaches `contact_force` (confirmed by the raw one), or one raw sample
//! `strong_contact` times that → `Reacquire` when the raw force stays below `lift_force` for `lift_time`
//! (fast for `reacquire_distance`, then at approach speed) → `Contact` … and from anywhere `Retract`
//! when the conditioned force exceeds the force limit.

use serde::{Deserialize, Serialize};

use super::signals::Signals;
use super::{non_negative, positive};
use crate::law::ContactState;

/// The contact state machine.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactParams {
    /// Speed towards an unknown surface, m/s.
    pub approach_speed: f64,
    /// Conditioned force that means contact, N.
    pub contact_force: f64,
    /// Raw force below which contact is lost, N (< `contact_force`).
    pub lift_force: f64,
    /// How long the force must stay below `lift_force`, s.
    pub lift_time: f64,
    /// Speed after a loss of contact, m/s.
    pub reacquire_speed: f64,
    /// Distance covered at `reacquire_speed` before falling back to `approach_speed`, m.
    pub reacquire_distance: f64,
    /// Speed away from the surface after the force limit, m/s.
    pub retract_speed: f64,
    /// Distance to retract before approaching again, m.
    pub retract_distance: f64,
    /// A loss of contact sooner than this after contact was detected is a bounce, s: the search after
    /// it is at approach speed (advanced).
    #[serde(default = "default_bounce_time")]
    pub bounce_time: f64,
    /// One raw sample this many times `contact_force` is contact on its own (advanced).
    #[serde(default = "default_strong_contact")]
    pub strong_contact: f64,
}

fn default_bounce_time() -> f64 {
    0.5
}

fn default_strong_contact() -> f64 {
    3.0
}

impl ContactParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("contact.approach_speed", self.approach_speed)?;
        positive("contact.contact_force", self.contact_force)?;
        non_negative("contact.lift_force", self.lift_force)?;
        non_negative("contact.lift_time", self.lift_time)?;
        positive("contact.reacquire_speed", self.reacquire_speed)?;
        non_negative("contact.reacquire_distance", self.reacquire_distance)?;
        positive("contact.retract_speed", self.retract_speed)?;
        non_negative("contact.retract_distance", self.retract_distance)?;
        non_negative("contact.bounce_time", self.bounce_time)?;
        positive("contact.strong_contact", self.strong_contact)?;
        if self.lift_force >= self.contact_force {
            return Err(format!(
                "contact.lift_force {} N must be below contact.contact_force {} N",
                self.lift_force, self.contact_force
            ));
        }
        Ok(())
    }
}

/// The detector's thresholds for one step, scaled to the set-point and the measured noise (see
/// [`ContactMachine::thresholds`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thresholds {
    /// Conditioned force that means contact, N.
    pub contact: f64,
    /// Raw force below which a sample counts towards a lift-off, N.
    pub lift: f64,
    /// Consecutive samples below `lift` a lift-off needs (never one: a single bad or zero sample, or
    /// the first sample after a dropout, is not a lift-off; more under noise).
    pub samples: u32,
}

/// Speeds out of contact for one step, bounded by what the cell can stop (see
/// [`ContactMachine::speeds`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Speeds {
    /// Approach and slow search, m/s.
    pub approach: f64,
    /// Fast search after a loss of contact, m/s.
    pub reacquire: f64,
}

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

/// The state machine's state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactMachine {
    p: ContactParams,
    state: ContactState,
    /// Time the raw force has been below the lift force, s, and for how many samples.
    below: f64,
    below_samples: u32,
    /// Distance travelled in the current re-acquire or retract, m.
    travelled: f64,
    /// Time since contact was last detected, s.
    in_contact: f64,
    /// The observed surface velocity away from the tool when contact was last lost, m/s.
    v_lost: f64,
}

impl ContactMachine {
    /// A machine approaching.
    pub fn new(p: ContactParams) -> Self {
        let mut m = Self {
            p,
            state: ContactState::Approach,
            below: 0.0,
            below_samples: 0,
            travelled: 0.0,
            in_contact: f64::INFINITY,
            v_lost: 0.0,
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
        self.below = 0.0;
        self.below_samples = 0;
        self.travelled = 0.0;
        self.in_contact = f64::INFINITY;
        self.v_lost = 0.0;
    }

    /// Whether the contact has lasted longer than a bounce (a steady contact), s.
    pub fn steady(&self) -> bool {
        self.state == ContactState::Contact && self.in_contact >= self.p.bounce_time
    }

    /// The state.
    pub fn state(&self) -> ContactState {
        self.state
    }

    /// The thresholds for set-point `f_r` (N) and the conditioned force's noise `sigma_ff` (N) and the
    /// raw force's `sigma` (N): `contact_force` and `lift_force` as configured for a set-point of at
    /// least twice `contact_force`, scaled down with a smaller set-point (contact at half of it), and
    /// raised to four standard deviations of the conditioned force's noise; a lift-off needs two
    /// samples, and one more per `lift_force` of raw noise.
    pub fn thresholds(&self, f_r: f64, sigma: f64, sigma_ff: f64) -> Thresholds {
        let c = &self.p;
        let contact = c.contact_force.min(0.5 * f_r).max(4.0 * sigma_ff);
        let lift = c.lift_force * contact / c.contact_force;
        let extra = (sigma / lift.max(1e-9)).ceil().min(64.0);
        Thresholds {
            contact,
            lift,
            samples: 2 + extra as u32,
        }
    }

    /// Speeds for stiffness estimate `k` (N/m), set-point `f_r` (N), force limit `max_force` (N) and
    /// stopping time `stop` (s: after a stop command the tool still travels for the delay and one
    /// cycle): the approach and the slow search no faster than stops within `2·f_r`, the fast search
    /// no faster than stops below the force limit.
    pub fn speeds(&self, k: f64, f_r: f64, max_force: f64, stop: f64) -> Speeds {
        let c = &self.p;
        let per_newton = 1.0 / (k * stop).max(1e-12);
        let approach = c
            .approach_speed
            .min(2.0 * f_r.max(c.contact_force) * per_newton);
        Speeds {
            approach,
            reacquire: c.reacquire_speed.min(max_force * per_newton).max(approach),
        }
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
    ) -> Transition {
        let c = self.p;
        if s.ff > max_force && self.state != ContactState::Retract {
            self.state = ContactState::Retract;
            self.travelled = 0.0;
            return Transition::ForceLimit;
        }
        match self.state {
            ContactState::Approach | ContactState::Reacquire => {
                // The conditioned force, confirmed by the raw one (the filter still remembers a
                // contact just lost), or one strong raw sample.
                if (s.ff >= th.contact && s.f >= th.lift) || s.f >= c.strong_contact * th.contact {
                    let from_approach = self.state == ContactState::Approach;
                    self.state = ContactState::Contact;
                    self.below = 0.0;
                    self.below_samples = 0;
                    self.in_contact = 0.0;
                    return Transition::Contact { from_approach };
                }
            }
            ContactState::Contact => {
                self.in_contact += dt;
                if s.f < th.lift {
                    self.below += dt;
                    self.below_samples += 1;
                    if self.below >= c.lift_time && self.below_samples >= th.samples {
                        self.state = ContactState::Reacquire;
                        // The fast search is for a surface that went away. A contact lost while the
                        // tool itself was moving away (the law's own answer to a force jump), or lost
                        // again soon after a re-acquisition (a bounce), is searched for at approach
                        // speed.
                        let retracting = s.v_x < -c.approach_speed;
                        self.travelled = if !retracting && self.in_contact >= c.bounce_time {
                            0.0
                        } else {
                            c.reacquire_distance
                        };
                        self.v_lost = receding;
                        return Transition::LiftOff;
                    }
                } else {
                    self.below = 0.0;
                    self.below_samples = 0;
                }
            }
            ContactState::Retract => {
                if self.travelled >= c.retract_distance && s.ff < th.lift {
                    self.state = ContactState::Approach;
                }
            }
        }
        Transition::None
    }

    /// The command out of contact (`None` in contact): from the last command `u` and the measured
    /// position `x`, never more than `anchor` (s at approach speed) ahead of the robot.
    pub fn command(&mut self, x: f64, u: f64, sp: &Speeds, anchor: f64, dt: f64) -> Option<f64> {
        let c = self.p;
        match self.state {
            ContactState::Approach => {
                let gap = sp.approach * anchor;
                Some((u + sp.approach * dt).min(x + gap))
            }
            ContactState::Reacquire => {
                // Fast first; then at approach speed, or faster when the surface was seen receding at
                // lift-off (a receding surface outruns a slow search).
                let speed = if self.travelled < c.reacquire_distance {
                    sp.reacquire
                } else {
                    (sp.approach + 1.5 * self.v_lost).min(sp.reacquire)
                };
                self.travelled += speed * dt;
                let gap = c.reacquire_distance + sp.approach * anchor;
                Some((u + speed * dt).min(x + gap))
            }
            ContactState::Retract => {
                self.travelled += c.retract_speed * dt;
                Some(u - c.retract_speed * dt)
            }
            ContactState::Contact => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> ContactParams {
        ContactParams {
            approach_speed: 0.002,
            contact_force: 1.0,
            lift_force: 0.3,
            lift_time: 0.002,
            reacquire_speed: 0.05,
            reacquire_distance: 0.002,
            retract_speed: 0.01,
            retract_distance: 0.001,
            bounce_time: 0.5,
            strong_contact: 3.0,
        }
    }

    const TH: Thresholds = Thresholds {
        contact: 1.0,
        lift: 0.3,
        samples: 2,
    };
    const SP: Speeds = Speeds {
        approach: 0.002,
        reacquire: 0.05,
    };

    fn sig(f: f64, ff: f64) -> Signals {
        Signals {
            x: 0.0,
            f,
            ff,
            xf: 0.0,
            v_x: 0.0,
            v_raw: 0.0,
        }
    }

    #[test]
    fn contact_lift_off_after_lift_time_and_force_limit() {
        let mut m = ContactMachine::new(params());
        assert_eq!(
            m.step(&sig(0.5, 0.5), &TH, 60.0, 0.0, 1e-3),
            Transition::None
        );
        assert_eq!(
            m.step(&sig(1.2, 1.1), &TH, 60.0, 0.0, 1e-3),
            Transition::Contact {
                from_approach: true
            }
        );
        // One low sample is not a lift-off; `lift_time` of them is.
        assert_eq!(
            m.step(&sig(0.0, 1.0), &TH, 60.0, 0.0, 1e-3),
            Transition::None
        );
        assert_eq!(
            m.step(&sig(5.0, 1.0), &TH, 60.0, 0.0, 1e-3),
            Transition::None
        );
        m.step(&sig(0.0, 1.0), &TH, 60.0, 0.0, 1e-3);
        assert_eq!(
            m.step(&sig(0.0, 1.0), &TH, 60.0, 0.0, 1e-3),
            Transition::LiftOff
        );
        assert_eq!(m.state(), ContactState::Reacquire);
        // A bounce: the search goes on at approach speed.
        let u = m.command(0.0, 0.0, &SP, 0.1, 1e-3).unwrap();
        assert!((u - 0.002e-3).abs() < 1e-15, "{u}");
        assert_eq!(
            m.step(&sig(70.0, 61.0), &TH, 60.0, 0.0, 1e-3),
            Transition::ForceLimit
        );
        assert!(m.command(0.0, 0.0, &SP, 0.1, 1e-3).unwrap() < 0.0);
        m.reset();
        assert_eq!(m.state(), ContactState::Approach);
    }

    #[test]
    fn thresholds_scale_with_set_point_and_noise_and_speeds_with_stiffness() {
        let m = ContactMachine::new(params());
        assert_eq!(m.thresholds(5.0, 0.0, 0.0), TH);
        let small = m.thresholds(1.0, 0.0, 0.0);
        assert!((small.contact - 0.5).abs() < 1e-12 && (small.lift - 0.15).abs() < 1e-12);
        let noisy = m.thresholds(5.0, 1.0, 0.4);
        assert!(
            (noisy.contact - 1.6).abs() < 1e-12 && noisy.samples > 3,
            "{noisy:?}"
        );
        // 70 kN/m, 16 ms to stop: 2·5 N is 8.9 mm/s, 60 N is 54 mm/s.
        assert_eq!(m.speeds(70_000.0, 5.0, 60.0, 0.016), SP);
        let stiff = m.speeds(500_000.0, 5.0, 60.0, 0.016);
        assert!((stiff.approach - 0.00125).abs() < 1e-12);
        assert!((stiff.reacquire - 0.0075).abs() < 1e-12);
    }

    #[test]
    fn validation_names_the_field() {
        let p = ContactParams {
            lift_force: 1.0,
            ..params()
        };
        assert!(p.validate().unwrap_err().contains("lift_force"));
    }
}
