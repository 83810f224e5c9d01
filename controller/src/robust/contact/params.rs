//! The contact state machine's parameters.

use serde::{Deserialize, Serialize};

use crate::robust::{non_negative, positive};

/// Speed away from the surface after the force limit, m/s. It was the parameter
/// `contact.retract_speed`; the force limit trips in no B scenario, pass or range case with a figure
/// that depends on it (at half of it and at twice it every one is the same), so it left the tuning
/// (docs/robust-law.md, "Fewer parameters"). At or below `limits.max_velocity`.
pub const RETRACT_SPEED: f64 = 0.01;

/// Distance retracted after the force limit before approaching again, m: a tenth of the speed,
/// a tenth of a second of retreat. It was the parameter `contact.retract_distance`, measured as
/// [`RETRACT_SPEED`] was.
pub const RETRACT_DISTANCE: f64 = 0.001;

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
    /// Speed after a loss of contact, m/s.
    pub reacquire_speed: f64,
    /// Distance covered at `reacquire_speed` before falling back to `approach_speed`, m.
    pub reacquire_distance: f64,
    /// A loss of contact sooner than this after contact was detected is a bounce, s: the search after
    /// it is at approach speed (advanced).
    #[serde(default = "default_bounce_time")]
    pub bounce_time: f64,
    /// One raw sample this many times the contact threshold (`contact_force`, scaled), or this many
    /// times the significance in the raw force's own noise, is contact on its own (advanced; see
    /// [`ContactMachine::thresholds`](super::ContactMachine::thresholds)).
    #[serde(default = "default_strong_contact")]
    pub strong_contact: f64,
    /// How far beyond the position where contact was lost the search stays at the gentle speed, in
    /// set-point penetrations `f_r/k̂_c` (advanced; 0: off, the fast search; `inf`: the whole search
    /// towards a surface not found yet is gentle, the `robust-gentle` tuning). The gentle speed is
    /// what the cell can stop within twice the set-point, counting what the force reaches before the
    /// contact is certainly seen (one raw sample at the strong threshold). A surface found there is
    /// the lost one moved a little; farther on it went away, and the search is fast. Each
    /// penetration costs a retreating surface about the stopping time
    /// ([`Stopping`](crate::robust::Stopping)) before it is found again; what the choice costs and
    /// buys on P1 and P2 is measured in docs/controller.md ("Choosing the re-acquire search").
    #[serde(default)]
    pub reacquire_margin: f64,
    /// Once the search is past `reacquire_distance`, it moves faster than the approach by this many
    /// times the surface's speed away from the tool seen at lift-off (advanced; above 1 a surface that
    /// keeps receding is caught up with, at `(reacquire_outrun − 1)` times its speed, bounded by the fast search).
    #[serde(default = "default_reacquire_outrun")]
    pub reacquire_outrun: f64,
}

fn default_bounce_time() -> f64 {
    0.5
}

fn default_strong_contact() -> f64 {
    3.0
}

fn default_reacquire_outrun() -> f64 {
    1.5
}

impl ContactParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("contact.approach_speed", self.approach_speed)?;
        positive("contact.contact_force", self.contact_force)?;
        non_negative("contact.lift_force", self.lift_force)?;
        positive("contact.reacquire_speed", self.reacquire_speed)?;
        non_negative("contact.reacquire_distance", self.reacquire_distance)?;
        non_negative("contact.bounce_time", self.bounce_time)?;
        positive("contact.strong_contact", self.strong_contact)?;
        // `inf` is a margin: the whole search is gentle.
        if self.reacquire_margin.is_nan() || self.reacquire_margin < 0.0 {
            return Err(format!(
                "contact.reacquire_margin must be >= 0 (inf: the whole search is gentle), got {}",
                self.reacquire_margin
            ));
        }
        non_negative("contact.reacquire_outrun", self.reacquire_outrun)?;
        if self.lift_force >= self.contact_force {
            return Err(format!(
                "contact.lift_force {} N must be below contact.contact_force {} N",
                self.lift_force, self.contact_force
            ));
        }
        Ok(())
    }
}
