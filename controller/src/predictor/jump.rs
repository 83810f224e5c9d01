//! The jump test: when an innovation of the surface filter is a jump rather than motion.

/// When an innovation `y` (of standard deviation `σ`) is a jump rather than motion: `|y| > gate·σ`,
/// and either `|y| > floor` or both `|y| > step_gate·σ` and `|y| > step_floor`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JumpTest {
    /// Standard deviations every jump exceeds.
    pub gate: f64,
    /// Size above which an innovation beyond `gate` is a jump, m.
    pub floor: f64,
    /// Standard deviations beyond which a smaller innovation is a jump too…
    pub step_gate: f64,
    /// …when it is also above this size, m (what the robot's own motion may explain).
    pub step_floor: f64,
}

impl JumpTest {
    /// Whether innovation `y` of variance `var` is a jump.
    pub fn is_jump(&self, y: f64, var: f64) -> bool {
        let y2 = y * y;
        y2 > self.gate * self.gate * var
            && (y.abs() > self.floor
                || (y2 > self.step_gate * self.step_gate * var && y.abs() > self.step_floor))
    }

    /// The test of a gate and a floor only.
    pub fn gated(gate: f64, floor: f64) -> Self {
        Self {
            gate,
            floor,
            step_gate: f64::INFINITY,
            step_floor: f64::INFINITY,
        }
    }
}
