//! `forcecell sensor KIND read`: a force sensor's readings on the terminal, whatever the sensor. Each
//! sensor family's command opens its driver and prints its own counters; the readout is shared.

use core::fmt::Debug;
use core::time::Duration;
use std::time::Instant;

use hal::ForceSensor;

/// The readout's pace: ten lines a second, or one per sample when the sensor delivers fewer (a line
/// more often than that would print the same sample again).
pub fn reading_interval(sample_rate_hz: f64) -> Duration {
    let tenth = Duration::from_millis(100);
    if sample_rate_hz.is_finite() && sample_rate_hz > 0.0 {
        tenth.max(Duration::from_secs_f64(1.0 / sample_rate_hz))
    } else {
        tenth
    }
}

/// Print `count` readings of `sensor`, one every `every`: time, the wrench (N, N·m), the sample's
/// age and `health(sensor)`; a read error is printed in the reading's place. Returns the time it took.
pub fn print_readings<S: ForceSensor, H: Debug>(
    sensor: &mut S,
    count: u32,
    every: Duration,
    health: impl Fn(&S) -> H,
) -> Duration {
    let t0 = Instant::now();
    println!(
        "{:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7}  health",
        "t s", "Fx N", "Fy N", "Fz N", "Mx N·m", "My N·m", "Mz N·m", "age ms"
    );
    for _ in 0..count {
        std::thread::sleep(every);
        let t = t0.elapsed().as_secs_f64();
        match sensor.read() {
            Ok(s) => {
                let w = s.wrench.to_array();
                println!(
                    "{t:>8.2} {:>9.3} {:>9.3} {:>9.3} {:>9.4} {:>9.4} {:>9.4} {:>7.2}  {:?}",
                    w[0],
                    w[1],
                    w[2],
                    w[3],
                    w[4],
                    w[5],
                    s.age.as_secs_f64() * 1e3,
                    health(sensor)
                );
            }
            Err(e) => println!("{t:>8.2} {e}"),
        }
    }
    t0.elapsed()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readings_come_ten_a_second_or_one_per_sample_when_slower() {
        assert_eq!(reading_interval(500.0), Duration::from_millis(100));
        assert_eq!(reading_interval(10.0), Duration::from_millis(100));
        assert_eq!(reading_interval(2.0), Duration::from_millis(500));
        assert_eq!(reading_interval(f64::NAN), Duration::from_millis(100));
        assert_eq!(reading_interval(0.0), Duration::from_millis(100));
    }
}
