//! The robot's inner position loop and its sampling: first-order lag plus pure delay.
//!
//! P0 ideal (1 ms, no lag, the command of step k is the position at step k+1), P1 realistic (1 kHz,
//! τ = 10 ms, 4 ms delay), P2 RSI-like (4 ms cycle, τ = 10 ms, 3-cycle delay). The lag is discretised
//! exactly for a command held over the period: `x ← x + (1 − e^{−T/τ})·(u − x)`.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// Period, lag and delay of an inner loop.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InnerLoopModel {
    /// Control period, s.
    pub period: f64,
    /// First-order lag time constant, s (0: none).
    pub tau: f64,
    /// Pure delay, whole periods.
    pub delay_cycles: u32,
}

impl InnerLoopModel {
    /// P0 ideal.
    pub const P0: Self = Self {
        period: 0.001,
        tau: 0.0,
        delay_cycles: 0,
    };
    /// P1 realistic.
    pub const P1: Self = Self {
        period: 0.001,
        tau: 0.010,
        delay_cycles: 4,
    };
    /// P2 RSI-like.
    pub const P2: Self = Self {
        period: 0.004,
        tau: 0.010,
        delay_cycles: 3,
    };

    /// One of `p0`, `p1`, `p2`.
    pub fn by_name(name: &str) -> Option<Self> {
        match name.to_ascii_lowercase().as_str() {
            "p0" => Some(Self::P0),
            "p1" => Some(Self::P1),
            "p2" => Some(Self::P2),
            _ => None,
        }
    }

    /// Pure delay in seconds.
    pub fn delay(&self) -> f64 {
        self.delay_cycles as f64 * self.period
    }

    /// The shortest period accepted, s (10 kHz: faster than any robot's position interface).
    pub const MIN_PERIOD: f64 = 1e-4;
    /// The longest period accepted, s (1 Hz: no force loop holds contact slower).
    pub const MAX_PERIOD: f64 = 1.0;
    /// The longest lag `tau` and pure delay accepted, s.
    pub const MAX_LAG: f64 = 1.0;

    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.period.is_finite()
            && (Self::MIN_PERIOD..=Self::MAX_PERIOD).contains(&self.period))
        {
            return Err(format!(
                "period must be in [{}, {}] s (robot position loops run at 1 Hz to 10 kHz), got {}",
                Self::MIN_PERIOD,
                Self::MAX_PERIOD,
                self.period
            ));
        }
        if !(self.tau.is_finite() && (0.0..=Self::MAX_LAG).contains(&self.tau)) {
            return Err(format!(
                "tau must be in [0, {}] s (a position loop lagging seconds cannot be force-controlled), got {}",
                Self::MAX_LAG,
                self.tau
            ));
        }
        if self.delay_cycles > 10_000 || self.delay() > Self::MAX_LAG {
            return Err(format!(
                "delay_cycles {} × period {} s must stay within {} s of pure delay",
                self.delay_cycles,
                self.period,
                Self::MAX_LAG
            ));
        }
        Ok(())
    }
}

/// State of an inner loop.
#[derive(Clone, Debug, PartialEq)]
pub struct InnerLoop {
    model: InnerLoopModel,
    alpha: f64,
    queue: VecDeque<f64>,
    x: f64,
    v: f64,
}

impl InnerLoop {
    /// At rest at `x0`, with the delay line full of `x0`.
    pub fn new(model: InnerLoopModel, x0: f64) -> Self {
        let alpha = if model.tau > 0.0 {
            1.0 - (-model.period / model.tau).exp()
        } else {
            1.0
        };
        Self {
            model,
            alpha,
            queue: std::iter::repeat_n(x0, model.delay_cycles as usize).collect(),
            x: x0,
            v: 0.0,
        }
    }

    /// The model.
    pub fn model(&self) -> &InnerLoopModel {
        &self.model
    }

    /// Position, m.
    pub fn position(&self) -> f64 {
        self.x
    }

    /// Mean velocity over the last period, m/s.
    pub fn velocity(&self) -> f64 {
        self.v
    }

    /// Take command `u` (m) and advance one period.
    pub fn advance(&mut self, u: f64) {
        let applied = if self.model.delay_cycles == 0 {
            u
        } else {
            self.queue.push_back(u);
            self.queue.pop_front().unwrap_or(u)
        };
        let old = self.x;
        self.x += self.alpha * (applied - self.x);
        self.v = (self.x - old) / self.model.period;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn p0_follows_the_command_one_step_later() {
        let mut l = InnerLoop::new(InnerLoopModel::P0, 0.0);
        l.advance(0.001);
        assert_eq!(l.position(), 0.001);
    }

    #[test]
    fn p2_waits_its_delay_then_lags() {
        let mut l = InnerLoop::new(InnerLoopModel::P2, 0.0);
        for _ in 0..3 {
            l.advance(1.0);
            assert_eq!(l.position(), 0.0, "pure delay of three cycles");
        }
        l.advance(1.0);
        let expect = 1.0 - (-0.4f64).exp();
        assert!((l.position() - expect).abs() < 1e-12);
        for _ in 0..200 {
            l.advance(1.0);
        }
        assert!((l.position() - 1.0).abs() < 1e-9);
    }
}
