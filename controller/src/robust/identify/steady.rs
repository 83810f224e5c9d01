//! The steady-contact part of identification: the slow fit on the loop's answer to sensor noise.

use super::Identifier;

impl Identifier {
    /// The steady-contact estimator: runs while nothing moves, jumps or adapts, and once confident
    /// moves `k̂_c` to its estimate at a bounded rate. `r` is the force noise variance, N².
    pub(super) fn steady_step(&mut self, x: f64, f: f64, dt: f64, disturbed: bool, r: f64) {
        let p = self.p;
        if disturbed {
            self.steady.stop();
            self.steady_var0 = f64::INFINITY;
            return;
        }
        if !self.steady.active() {
            let s = self.est.scale();
            let theta0 = self.est.kc() * s;
            let u = self.est.params().initial_uncertainty * theta0;
            let var0 = self.steady_var0.min(u * u);
            self.steady.start(x, self.est.predict(x), theta0, var0, s);
            self.steady_var0 = f64::INFINITY;
            return;
        }
        // Learnt: a steady contact has nothing more to teach, and a sensor bias that has drifted as
        // far as the set-point lifts the tool off unseen (the law holds the measured force), which
        // would teach it wrong.
        let learnt = self
            .steady
            .estimate()
            .is_some_and(|(_, rel)| rel <= p.steady_done);
        if !learnt {
            self.steady.update(x, f, r, dt);
        }
        if let Some((k, rel)) = self.steady.estimate()
            && self.steady.age() >= p.steady_min_age
            && rel <= p.steady_confidence
        {
            let now = self.est.kc();
            let step = p.steady_rate * dt * now;
            self.est.set_kc(now + (k - now).clamp(-step, step), x);
        }
    }
}
