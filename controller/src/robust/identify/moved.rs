//! A re-contact that found the surface elsewhere, or that the fast search made: the recursion waits.
//!
//! After a contact is lost the search finds the surface again. If it is found further away than a
//! still surface's penetration explains (and than `max_surface_speed` moves it over the search), the
//! surface moved while it was lost, and may be moving still. Then the re-contact's transients are
//! the surface's motion as much as the stiffness: with the tool and the surface moving the same way,
//! a still-surface model reads `k_c·(1 − v_surface/v_tool)`. The observer, restarted at the
//! re-contact, has not seen the motion yet, and a strong force transient would pass the estimator's
//! motion gate anyway. So nothing is learnt for the observer's `motion_hold`, through the bounces
//! that follow (each found the surface a little further: B5b on 140 kN/m re-contacted five times
//! within 0.2 s, the last 47 µm from its loss); a touch-down from the approach ends the wait. B5b's
//! 1 mm, 1 Hz sine on 500 kN/m on P1 took `k̂_c` from 470 to 155 kN/m within 53 ms of such a
//! re-contact, and the loop, three times too stiff, lost contact 122 times.
//!
//! A re-contact the fast search made waits too: its momentum presses the surface beyond the set-point
//! (the search stops within the force limit, not within `2·f_r`), and while the tool backs off from
//! that, a surface that is moving away reads as a stiffer one (B5a on 200 kN/m on P2: the fast search
//! re-contacted 33 µm from the loss, pressed to 30 N, and `k̂_c` went 177 → 238 kN/m in 16 ms).

use super::Identifier;
use crate::robust::contact::Search;

impl Identifier {
    /// A contact re-acquired at the raw `(x, f)` after `search`: if the surface was found moved beyond
    /// `max_surface_speed` (m/s) over the search's time and twice the penetration of `f` or the
    /// set-point `f_r` (N) at `k̂_c`, or the fast search made the contact, the recursion waits for
    /// `hold` (s).
    pub(super) fn recontact(
        &mut self,
        x: f64,
        f: f64,
        search: &Search,
        f_r: f64,
        max_surface_speed: f64,
        hold: f64,
    ) {
        let still = max_surface_speed * search.t_lost + 2.0 * f.max(f_r) / self.kc();
        if search.fast || (x - search.x_lost).abs() > still {
            self.recontact_hold = hold;
        }
    }

    /// Whether the recursion waits after a re-contact (set by a re-contact: `recontact`).
    pub fn held(&self) -> bool {
        self.recontact_hold > 0.0
    }

    /// Count a step of the wait down; whether it still runs.
    pub(super) fn hold_step(&mut self, dt: f64) -> bool {
        let held = self.held();
        self.recontact_hold = (self.recontact_hold - dt).max(0.0);
        held
    }
}
