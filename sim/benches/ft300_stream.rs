//! The FT 300 driver against the simulated sensor over a real pseudo-terminal
//! (`cargo bench -p forcecell-sim --bench ft300_stream`):
//! * divan: the cost of `Ft300::read` while the background reader runs;
//! * then a report of the achieved stream rate and the sample age seen by a reader at about 1 kHz.

use core::time::Duration;
use std::time::Instant;

use divan::black_box;
use hal::{ForceSensor, Wrench};
use robotiq::{Config, Ft300, Health};
use sim::ft300::{Ft300Config, SimFt300};

fn streaming() -> (SimFt300, Ft300) {
    let w = Wrench::from_array([1.0, 2.0, 30.0, 0.1, 0.2, 0.3]);
    let sim = SimFt300::spawn(Ft300Config::default(), move |_t: Duration| w).unwrap();
    let ft = Ft300::open(Config::new(sim.path())).unwrap();
    let t0 = Instant::now();
    while ft.health() != Health::Ok {
        assert!(t0.elapsed() < Duration::from_secs(5), "no stream");
        std::thread::sleep(Duration::from_millis(1));
    }
    (sim, ft)
}

/// `read` hands over the newest sample without touching the port.
#[divan::bench]
fn read_while_streaming(b: divan::Bencher) {
    let (_sim, mut ft) = streaming();
    b.bench_local(|| black_box(ft.read().is_ok()));
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn report_rate_and_age() {
    let (sim, mut ft) = streaming();
    let run = Duration::from_secs(5);
    let start = ft.counters();
    let t0 = Instant::now();
    let mut ages = Vec::new();
    let mut errors = 0u64;
    let mut k = 0u64;
    while t0.elapsed() < run {
        match ft.read() {
            Ok(s) => ages.push(s.age),
            Err(_) => errors += 1,
        }
        // An irregular reader, like a control loop on another clock.
        k += 1;
        std::thread::sleep(Duration::from_micros(150 + (k * 7919) % 1700));
    }
    let elapsed = t0.elapsed().as_secs_f64();
    let c = ft.counters();
    let achieved = (c.frames - start.frames) as f64 / elapsed;
    ages.sort();
    println!(
        "FT 300 stream over a pseudo-terminal: achieved {achieved:.2} Hz (device sent {} frames), \
         reader saw age p50 {:?}, p99 {:?}, max {:?} over {} reads ({errors} errors); \
         CRC errors {}, stale {}, lost {}",
        sim.stats().frames,
        percentile(&ages, 0.5),
        percentile(&ages, 0.99),
        ages.last().copied().unwrap_or_default(),
        ages.len(),
        c.crc_errors - start.crc_errors,
        c.stale_events,
        c.lost_events,
    );
}

fn main() {
    divan::main();
    report_rate_and_age();
}
