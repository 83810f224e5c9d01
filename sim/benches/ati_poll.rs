//! The ATI driver against the simulated node on the in-memory bus (`cargo bench -p forcecell-sim
//! --bench ati_poll`):
//! * divan: the cost of `AtiSensor::read` while the poller runs, and of one lockstep exchange;
//! * then a report of the achieved poll rate and the sample age seen by a reader at 1 kHz.

use core::time::Duration;
use std::time::Instant;

use ati_can::{AtiSensor, Config, Driver, Health, Lockstep, MemBus};
use divan::black_box;
use hal::{ForceSensor, Wrench};
use sim::ati_node::{AtiNode, NodeConfig, SharedNode};

fn node() -> SharedNode {
    let w = Wrench::from_array([1.0, 2.0, 30.0, 0.1, 0.2, 0.3]);
    SharedNode::new(AtiNode::new(NodeConfig::default(), move |_t: Duration| w).unwrap())
}

fn polling_sensor(rate_hz: f64) -> AtiSensor {
    let bus = MemBus::new();
    bus.attach(node());
    let driver = Driver::new(bus.port(), Config::default()).unwrap();
    let sensor = AtiSensor::spawn(driver, rate_hz).unwrap();
    let t0 = Instant::now();
    while sensor.health() != Health::Ok {
        assert!(t0.elapsed() < Duration::from_secs(5), "no start-up");
        std::thread::sleep(Duration::from_millis(1));
    }
    sensor
}

/// `read` hands over the newest sample without touching the bus.
#[divan::bench]
fn read_while_polling_at_1khz(b: divan::Bencher) {
    let mut sensor = polling_sensor(1000.0);
    b.bench_local(|| black_box(sensor.read().is_ok()));
}

/// One lockstep exchange: request, node answers in the caller's thread, decode, convert.
#[divan::bench]
fn lockstep_exchange_on_the_virtual_bus(b: divan::Bencher) {
    let bus = MemBus::with_virtual_clock();
    bus.attach(node());
    let mut driver = Driver::new(bus.port(), Config::default()).unwrap();
    driver.start().unwrap();
    let mut sensor = Lockstep(driver);
    b.bench_local(|| black_box(sensor.read().is_ok()));
}

fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn report_rate_and_age() {
    let rate = 1000.0;
    let mut sensor = polling_sensor(rate);
    let run = Duration::from_secs(3);
    let start_samples = sensor.counters().samples;
    let t0 = Instant::now();
    let mut ages = Vec::new();
    let mut errors = 0u64;
    let mut k = 0u64;
    while t0.elapsed() < run {
        match sensor.read() {
            Ok(s) => ages.push(s.age),
            Err(_) => errors += 1,
        }
        // An irregular reader, like a control loop on another clock.
        k += 1;
        std::thread::sleep(Duration::from_micros(150 + (k * 7919) % 700));
    }
    let elapsed = t0.elapsed().as_secs_f64();
    let c = sensor.counters();
    let achieved = (c.samples - start_samples) as f64 / elapsed;
    ages.sort();
    println!(
        "ATI poll at {rate} Hz on the in-memory bus: achieved {achieved:.1} Hz ({:+.2} %), \
         reader saw age p50 {:?}, p99 {:?}, max {:?} over {} reads ({errors} errors); timeouts {}",
        (achieved / rate - 1.0) * 100.0,
        percentile(&ages, 0.5),
        percentile(&ages, 0.99),
        ages.last().copied().unwrap_or_default(),
        ages.len(),
        c.timeouts,
    );
}

fn main() {
    divan::main();
    report_rate_and_age();
}
