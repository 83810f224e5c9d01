//! The loop's guard over force control: the force limit, the law's correction limit and a contact
//! lost too long are faults (codes 2, 3 and 5 of the process contract). One definition for both ways
//! the loop runs: a process the robot program commands latches them (and the program re-arms with
//! OFF); a loop without process channels ends on them, backed off, with `Stop`.

use hal::ProcessFault;

use super::process::ProcessConfig;
use crate::law::{ContactState, Output};

/// A fault the guard found: its contract code and why, for the operator.
pub type Tripped = (ProcessFault, String);

/// What a law step's output says of contact, as the guard read it: the one reading the process
/// follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Touch {
    /// In contact: the law's contact state, or the filtered force without one.
    Contact,
    /// The law approaches: the first approach, or anew after what it had taken for contact it now
    /// calls a touch-down that bounced, or a noise spike in free air. No contact is lost; the next
    /// one counts.
    Approach,
    /// No contact: not made yet, or lost for less than `contact_loss_time`.
    Free,
}

/// The guard's state: the filtered force, and whether and how long contact was lost.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Guard {
    /// The measured force through a first-order filter of `force_filter`, N (also `FcState.F`).
    pub f_filt: f64,
    /// Contact was made since the last reset (a loss only counts after it).
    pub had_contact: bool,
    /// Robot time without contact after contact, s.
    pub lost: f64,
    /// The law's command at its last step in contact, m: where a loss's search is measured from.
    pub contact_cmd: f64,
}

impl Guard {
    /// Forget contact (a new approach starts); the force filter runs on.
    pub fn reset(&mut self) {
        self.had_contact = false;
        self.lost = 0.0;
    }

    /// The deepest command the search for a lost surface may send (`+∞` while no contact is lost,
    /// or for a law without a contact state): where the law last commanded in contact, plus
    /// `search_depth`. The check trips on a step that wants beyond it; that step is sent clipped.
    pub fn search_limit(&self, cfg: &ProcessConfig, out: &Output) -> f64 {
        let searching = out.state.is_some_and(|s| s != ContactState::Contact)
            && out.state != Some(ContactState::Approach);
        if self.had_contact && searching {
            self.contact_cmd + cfg.search_depth
        } else {
            f64::INFINITY
        }
    }

    /// Filter a usable force sample    /// Filter a usable force sample taken `dt` after the last.
    pub fn observe(&mut self, cfg: &ProcessConfig, f: f64, dt: f64) {
        let a = (dt / (cfg.force_filter + dt)).clamp(0.0, 1.0);
        self.f_filt += a * (f - self.f_filt);
    }

    /// Check a law step's output `out` taken with force `f` against set-point `f_r`, `dt` after the
    /// last step. Contact is the law's own contact state where it has one, else the filtered force
    /// at or above `min(entry_force, f_r)`.
    pub fn check(
        &mut self,
        cfg: &ProcessConfig,
        out: &Output,
        f: f64,
        f_r: f64,
        dt: f64,
    ) -> Result<Touch, Tripped> {
        if out.events.force_limit || f > cfg.max_force {
            return Err((
                ProcessFault::ForceLimit,
                format!("force {f:.1} N above the limit {:.1} N", cfg.max_force),
            ));
        }
        if out.events.orientation_envelope {
            return Err((
                ProcessFault::CorrectionLimit,
                "the tool's rotation reached its envelope (orientation.max_angle)".into(),
            ));
        }
        if out.events.deviation_limit {
            return Err((
                ProcessFault::CorrectionLimit,
                "the law's correction reached its deviation limit".into(),
            ));
        }
        let in_contact = match out.state {
            Some(s) => s == ContactState::Contact,
            None => self.f_filt >= cfg.entry_force.min(f_r),
        };
        if in_contact {
            self.had_contact = true;
            self.lost = 0.0;
            self.contact_cmd = out.x_cmd;
            return Ok(Touch::Contact);
        }
        if out.state == Some(ContactState::Approach) {
            // The law approaches at approach speed, bounded like any approach. A loss counts again
            // after the next contact (a spike on the first sample, before the noise was measured,
            // ended a run 0.5 s later, as the tool reached the surface).
            self.reset();
            return Ok(Touch::Approach);
        }
        if self.had_contact {
            // The search is a contact state machine's (the paper's law has none: its envelope and
            // the contact-loss time bound it, and its reproduction stays exact).
            if out.x_cmd > self.search_limit(cfg, out) {
                let depth = out.x_cmd - self.contact_cmd;
                return Err((
                    ProcessFault::ContactLost,
                    format!(
                        "contact lost: the search reached {:.1} mm beyond where the surface was \
                         (search_depth {:.1} mm: the part's edge, or a hole?)",
                        depth * 1e3,
                        cfg.search_depth * 1e3
                    ),
                ));
            }
            self.lost += dt;
            if self.lost > cfg.contact_loss_time {
                return Err((
                    ProcessFault::ContactLost,
                    format!("contact lost for {:.0} ms while pressing", self.lost * 1e3),
                ));
            }
        }
        Ok(Touch::Free)
    }
}

/// Where a fault's back-off ends: `target`, or — while force `f` shows the tool still touching
/// (above `entry_force`: the surface came after it, or the limit tripped deeper than `lift`) — `lift`
/// beyond the command `cmd`, never beyond `floor`. The tool backs off until it is free, then `lift`
/// further.
pub(super) fn back_off_target(
    target: f64,
    f: Option<f64>,
    entry_force: f64,
    cmd: f64,
    lift: f64,
    floor: f64,
) -> f64 {
    if f.is_some_and(|f| f > entry_force) {
        target.min((cmd - lift).max(floor))
    } else {
        target
    }
}

/// The fault of a command the loop had to clip to its envelope (`max_offset`).
pub(super) fn envelope(max_offset: f64) -> Tripped {
    (
        ProcessFault::CorrectionLimit,
        format!(
            "correction reached its envelope of {:.1} mm",
            max_offset * 1e3
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::Events;

    fn out(state: Option<ContactState>) -> Output {
        Output {
            state,
            ..Output::default()
        }
    }

    #[test]
    fn the_force_limit_and_the_laws_deviation_limit_trip() {
        let cfg = ProcessConfig::default();
        let mut g = Guard::default();
        let contact = out(Some(ContactState::Contact));
        assert_eq!(
            g.check(&cfg, &contact, 59.9, 20.0, 0.004),
            Ok(Touch::Contact)
        );
        let (code, why) = g.check(&cfg, &contact, 60.1, 20.0, 0.004).unwrap_err();
        assert_eq!(code, ProcessFault::ForceLimit);
        assert!(why.contains("60.1"), "{why}");
        let mut limited = contact;
        limited.events = Events {
            force_limit: true,
            ..Events::default()
        };
        assert_eq!(
            g.check(&cfg, &limited, 10.0, 20.0, 0.004).unwrap_err().0,
            ProcessFault::ForceLimit,
            "the law's own force-limit event"
        );
        limited.events = Events {
            deviation_limit: true,
            ..Events::default()
        };
        assert_eq!(
            g.check(&cfg, &limited, 10.0, 20.0, 0.004).unwrap_err().0,
            ProcessFault::CorrectionLimit
        );
    }

    #[test]
    fn a_loss_counts_only_after_contact_and_only_while_it_lasts() {
        let cfg = ProcessConfig::default();
        let mut g = Guard::default();
        let searching = out(Some(ContactState::Approach));
        // An approach that never touched is not a lost contact, however long it lasts.
        for _ in 0..1000 {
            assert_eq!(
                g.check(&cfg, &searching, 0.0, 20.0, 0.004),
                Ok(Touch::Approach)
            );
        }
        g.check(&cfg, &out(Some(ContactState::Contact)), 20.0, 20.0, 0.004)
            .unwrap();
        let lost = out(Some(ContactState::Reacquire));
        // 0.4 s lost, then contact again: the count starts over.
        for _ in 0..100 {
            g.check(&cfg, &lost, 0.0, 20.0, 0.004).unwrap();
        }
        g.check(&cfg, &out(Some(ContactState::Contact)), 20.0, 20.0, 0.004)
            .unwrap();
        assert_eq!(g.lost, 0.0);
        let mut r = Ok(Touch::Free);
        let mut n = 0;
        while r.is_ok() {
            r = g.check(&cfg, &lost, 0.0, 20.0, 0.004);
            n += 1;
        }
        assert_eq!(r.unwrap_err().0, ProcessFault::ContactLost);
        // The first count of 4 ms cycles beyond contact_loss_time = 0.5 s (the sum's float error
        // decides between the 125th and the 126th).
        assert!((125..=126).contains(&n), "{n}");
        assert!(g.lost > cfg.contact_loss_time && g.lost - 0.004 <= cfg.contact_loss_time);
        g.reset();
        assert_eq!(g.check(&cfg, &lost, 0.0, 20.0, 0.004), Ok(Touch::Free));
    }

    /// A contact the law itself takes back (it approaches anew: a bounce at touch-down, a noise
    /// spike in free air) is no contact lost while pressing, however long the approach then takes;
    /// the count starts at the next contact.
    #[test]
    fn a_contact_the_law_takes_back_is_not_lost() {
        let cfg = ProcessConfig::default();
        let mut g = Guard::default();
        g.check(&cfg, &out(Some(ContactState::Contact)), 3.0, 20.0, 0.004)
            .unwrap();
        let approach = out(Some(ContactState::Approach));
        for _ in 0..1000 {
            assert_eq!(
                g.check(&cfg, &approach, 0.0, 20.0, 0.004),
                Ok(Touch::Approach)
            );
        }
        g.check(&cfg, &out(Some(ContactState::Contact)), 20.0, 20.0, 0.004)
            .unwrap();
        let lost = out(Some(ContactState::Reacquire));
        let n = (0..1000)
            .position(|_| g.check(&cfg, &lost, 0.0, 20.0, 0.004).is_err())
            .expect("a contact lost after the next contact still trips");
        assert!((124..=125).contains(&n), "{n}");
    }

    /// The search for a lost surface may command `search_depth` beyond the law's last command in
    /// contact: a step that wants further is sent clipped there and trips fault 5.
    #[test]
    fn the_search_stops_at_its_depth_beyond_the_last_contact() {
        let cfg = ProcessConfig::default();
        let mut g = Guard::default();
        let at = |state, x_cmd| Output {
            x_cmd,
            ..out(Some(state))
        };
        assert_eq!(
            g.search_limit(&cfg, &at(ContactState::Approach, 0.0)),
            f64::INFINITY
        );
        g.check(&cfg, &at(ContactState::Contact, 0.003), 20.0, 20.0, 0.004)
            .unwrap();
        let searching = at(ContactState::Reacquire, 0.004);
        assert_eq!(g.search_limit(&cfg, &searching), 0.003 + cfg.search_depth);
        assert_eq!(g.check(&cfg, &searching, 0.0, 20.0, 0.004), Ok(Touch::Free));
        let deep = at(ContactState::Reacquire, 0.003 + cfg.search_depth + 1e-6);
        let (code, why) = g.check(&cfg, &deep, 0.0, 20.0, 0.004).unwrap_err();
        assert_eq!(code, ProcessFault::ContactLost);
        assert!(why.contains("beyond where the surface was"), "{why}");
        // The paper's law has no search to bound (its envelope does).
        let mut g = Guard::default();
        for _ in 0..100 {
            g.observe(&cfg, 20.0, 0.004);
        }
        g.check(&cfg, &out(None), 20.0, 20.0, 0.004).unwrap();
        let far = Output {
            x_cmd: 1.0,
            ..out(None)
        };
        assert_eq!(g.search_limit(&cfg, &far), f64::INFINITY);
        assert!(g.check(&cfg, &far, 20.0, 20.0, 0.004).is_ok());
    }

    #[test]
    fn without_a_contact_state_the_filtered_force_decides() {
        let cfg = ProcessConfig::default();
        let mut g = Guard::default();
        let none = out(None);
        assert_eq!(g.check(&cfg, &none, 0.0, 20.0, 0.004), Ok(Touch::Free));
        for _ in 0..100 {
            g.observe(&cfg, 5.0, 0.004);
        }
        assert!((g.f_filt - 5.0).abs() < 1e-6);
        assert_eq!(
            g.check(&cfg, &none, 5.0, 20.0, 0.004),
            Ok(Touch::Contact),
            "5 N ≥ the 2 N entry force"
        );
        assert_eq!(
            g.check(&cfg, &none, 5.0, 1.0, 0.004),
            Ok(Touch::Contact),
            "a set-point below the entry force lowers the bar"
        );
    }
}
