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

/// The records of a simulated run at 250 Hz (plant P2, robust tuning, in-process robot and sensor)
/// over `seconds`, and its rows with the world's truth filled in (what `sim` writes on `/truth`).
fn simulated(scenario: &str, seconds: f64) -> (Vec<Record>, Vec<forcecell::record::Row>) {
    use forcecell::runner::{RunSpec, run_recorded};
    use forcecell::scenario::Scenario;
    let mut s = Scenario::load(scenario).unwrap();
    s.duration = seconds;
    let spec = RunSpec::new(s, Some("p2"), Some("robust")).unwrap();
    let world = spec.world();
    let (tx, mut rx) = recorder::queue(spec.steps() as usize + 16, Full::Drop);
    let run = run_recorded(
        &spec,
        &world,
        sim::InProcRobot::new(world.clone()),
        sim::InProcSensor::new(world.clone()),
        Some(tx),
        &mut |_| {},
    )
    .unwrap();
    let mut recs = Vec::new();
    while let Ok(r) = rx.pop() {
        recs.push(r);
    }
    (recs, run.rows)
}

/// The writer's cost per cycle: a simulated run's records (a clean surface step, b03a; sensor noise,
/// b06) pushed into a recording on a file (`/dev/shm` where there is one: the disk's speed is not what
/// is measured) and finished with the truth, as `sim` does. Prints the file's bytes per cycle.
#[divan::bench(args = ["b03a-surface-retreat", "b06-noise-drift"], sample_count = 20, sample_size = 1)]
fn writer(b: Bencher, scenario: &str) {
    let (recs, truth) = simulated(scenario, 10.0);
    let n = recs.len();
    let shm = std::path::Path::new("/dev/shm");
    let dir = if shm.is_dir() {
        tempfile::tempdir_in(shm).unwrap()
    } else {
        tempfile::tempdir().unwrap()
    };
    let path = dir.path().join("bench.mcap");
    let mut bytes = 0;
    b.counter(divan::counter::ItemsCount::new(n))
        .bench_local(|| {
            let opts = recorder::RecorderOptions {
                full: Full::Wait,
                ..recorder::RecorderOptions::default()
            };
            let (mut tx, recording) = recorder::start(&path, opts, None).unwrap();
            for r in &recs {
                tx.push(*r);
            }
            drop(tx);
            bytes = recording.finish(truth.clone()).unwrap().bytes;
        });
    eprintln!(
        "writer {scenario}: {n} cycles, {bytes} B in the file, {:.1} B a cycle",
        bytes as f64 / n as f64
    );
}
