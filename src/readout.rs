//! `forcecell sensor KIND read`: a force sensor's readings on the terminal, whatever the sensor. Each
//! sensor family's command opens its driver and prints its own counters; the readout is shared.

use core::fmt::Debug;
use core::time::Duration;
use std::time::Instant;

use hal::ForceSensor;

/// Print `count` readings of `sensor`, one every 100 ms: time, the wrench (N, N·m), the sample's age
/// and `health(sensor)`; a read error is printed in the reading's place. Returns the time it took.
pub fn print_readings<S: ForceSensor, H: Debug>(
    sensor: &mut S,
    count: u32,
    health: impl Fn(&S) -> H,
) -> Duration {
    let t0 = Instant::now();
    println!(
        "{:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>7}  health",
        "t s", "Fx N", "Fy N", "Fz N", "Mx N·m", "My N·m", "Mz N·m", "age ms"
    );
    for _ in 0..count {
        std::thread::sleep(Duration::from_millis(100));
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
