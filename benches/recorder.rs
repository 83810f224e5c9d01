//! The control loop's cycle with and without the recorder attached (`cargo bench --bench recorder`):
//! the robust law on an ideal spring ([`forcecell::rig`]: no wire, no allocation), so what differs is
//! the record built and pushed into the recorder's ring. A consumer thread drains the ring (as the MCAP
//! writer does) so each push takes the normal path, not the full-queue one. divan's allocation profiler
//! counts heap allocations per cycle.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use controller::{ControlLoop, ForceLaw, Tuning};
use divan::{AllocProfiler, Bencher};
use forcecell::recorder::{self, Full, Record};
use forcecell::rig::Spring;

#[global_allocator]
static ALLOC: AllocProfiler = AllocProfiler::system();

fn main() {
    divan::main();
}

fn tuning() -> Tuning {
    toml::from_str(include_str!("../tunings/robust.toml")).unwrap()
}

/// One control cycle, no recorder.
#[divan::bench(sample_count = 200, sample_size = 2000)]
fn cycle(b: Bencher) {
    let t = tuning();
    let law = t.law.build().unwrap();
    let spring = Spring::new(70_000.0, 0.010, 0.0099, t.loop_cfg.force_sign);
    let (robot, sensor) = spring.devices(0.004);
    let mut lp = ControlLoop::new(robot, sensor, law, t.loop_cfg);
    b.bench_local(|| lp.cycle().unwrap());
}

/// One control cycle with its record built and pushed to the recorder's ring.
#[divan::bench(sample_count = 200, sample_size = 2000)]
fn cycle_recorded(b: Bencher) {
    let t = tuning();
    let law = t.law.build().unwrap();
    let f_r = law.set_point();
    let spring = Spring::new(70_000.0, 0.010, 0.0099, t.loop_cfg.force_sign);
    let (robot, sensor) = spring.devices(0.004);
    let mut lp = ControlLoop::new(robot, sensor, law, t.loop_cfg);
    let (mut tx, mut rx) = recorder::queue(8192, Full::Drop);
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let drain = std::thread::spawn(move || {
        let mut n = 0u64;
        while !s.load(Ordering::Relaxed) {
            while let Ok(r) = rx.pop() {
                n += u64::from(r.row.t > 0.0);
            }
            std::thread::yield_now();
        }
        n
    });
    b.bench_local(|| {
        let r = lp.cycle().unwrap();
        tx.push(Record::from_report(&r, f_r))
    });
    stop.store(true, Ordering::Relaxed);
    drain.join().unwrap();
    eprintln!("recorder: {} records dropped (queue full)", tx.dropped());
}
