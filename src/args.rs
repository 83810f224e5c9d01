//! Command-line numbers, bounded where they are parsed: each parser accepts only what the physical
//! quantity can be, and says why in its error (clap prints it as `error: invalid value … for '--flag'`).

/// Parse a finite number in `[lo, hi]`; `why` is the physical reason for the bounds.
fn bounded(s: &str, lo: f64, hi: f64, unit: &str, why: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number"))?;
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{} {unit} is outside [{lo}, {hi}] {unit}: {why}",
            s.trim()
        ))
    }
}

/// A sensor poll rate, Hz.
pub fn poll_rate_hz(s: &str) -> Result<f64, String> {
    bounded(
        s,
        1.0,
        10_000.0,
        "Hz",
        "the driver polls at most 10 kHz, and below 1 Hz every sample is stale before the next",
    )
}

/// How long a simulated node serves, s.
pub fn serve_seconds(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        604_800.0,
        "s",
        "at most a week (Ctrl-C or SIGTERM ends it sooner; omit the flag to serve until then)",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 s: the node must serve for a positive time".into())
    }
}

/// A force a simulated sensor reports, N.
pub fn sensor_force_n(s: &str) -> Result<f64, String> {
    bounded(
        s,
        -10_000.0,
        10_000.0,
        "N",
        "beyond the range of any F/T sensor this node simulates",
    )
}

/// Gauge noise of a simulated sensor, counts (standard deviation).
pub fn noise_counts(s: &str) -> Result<f64, String> {
    bounded(
        s,
        0.0,
        10_000.0,
        "counts",
        "a standard deviation is not negative, and 10 000 counts is noise larger than any reading",
    )
}

/// The CAN board's turnaround allowance, µs.
pub fn turnaround_us(s: &str) -> Result<u64, String> {
    let v: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number of µs"))?;
    if v <= 10_000_000 {
        Ok(v)
    } else {
        Err(format!(
            "{v} µs is above 10 000 000 µs (10 s): a CAN board answers within milliseconds (a slow virtual interface within seconds), and every request waits this long before it times out"
        ))
    }
}

/// A control period, s.
pub fn period_s(s: &str) -> Result<f64, String> {
    bounded(
        s,
        1e-4,
        1.0,
        "s",
        "robot position loops run at 1 Hz to 10 kHz",
    )
}

/// A position-loop lag or a pure delay, s.
pub fn lag_s(s: &str) -> Result<f64, String> {
    bounded(
        s,
        0.0,
        1.0,
        "s",
        "a robot loop answering a second or more late cannot be force-controlled",
    )
}

/// A surface stiffness, N/m.
pub fn stiffness_n_per_m(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        1e10,
        "N/m",
        "from any soft surface up to steel on steel",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 N/m: a surface the tool presses on has a positive stiffness".into())
    }
}

/// A force set-point, N.
pub fn set_point_n(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        10_000.0,
        "N",
        "a polishing set-point presses (> 0) and stays within an F/T sensor's range",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 N: the set-point must press on the surface".into())
    }
}

/// A UDP port the robot sends to (0 would let the OS choose one the robot cannot know).
pub fn robot_port(s: &str) -> Result<u16, String> {
    let v: u16 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a port (1..=65535)"))?;
    if v == 0 {
        Err("port 0 lets the OS choose one at random; the robot's file needs the real port (1..=65535)".into())
    } else {
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_parser_refuses_the_absurd_and_says_why() {
        assert_eq!(poll_rate_hz("500"), Ok(500.0));
        assert!(poll_rate_hz("1e-20").unwrap_err().contains("stale"));
        assert!(poll_rate_hz("nan").is_err() && poll_rate_hz("inf").is_err());
        assert!(serve_seconds("1e20").unwrap_err().contains("week"));
        assert!(serve_seconds("0").is_err());
        assert!(sensor_force_n("nan").is_err());
        assert_eq!(sensor_force_n("-5"), Ok(-5.0));
        assert!(turnaround_us("18446744073709551615").is_err());
        assert_eq!(turnaround_us("20000"), Ok(20_000));
        assert!(period_s("1e300").is_err() && lag_s("1e8").is_err());
        assert!(stiffness_n_per_m("0").is_err() && set_point_n("-1").is_err());
        assert!(robot_port("0").unwrap_err().contains("port 0"));
        assert_eq!(robot_port("6008"), Ok(6008));
    }
}
