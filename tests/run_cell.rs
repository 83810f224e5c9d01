//! `forcecell run`'s wiring from a cell file: the RSI link bound as configured, the simulated KUKA
//! controller in lockstep on loopback standing in for the robot, the control loop with gravity
//! compensation in between, and a clean `Stop` at the end.

use std::sync::atomic::AtomicBool;
use std::thread;
use std::time::Duration;

use forcecell::cell::{CellConfig, CellOutcome, run_cell};
use kuka_rsi::{EthernetConfig, RsiLink};
use sim::krc::{Krc, KrcConfig, KrcEnd, KrcReport, Timing};
use sim::{ContactPlant, InProcSensor, InnerLoopModel, SensorParams, SharedWorld, Window, World};

const CELL: &str = r#"
tuning = "robust"
duration = 1.5

[robot]
listen = "127.0.0.1:49152"
robot_ip = "127.0.0.1"

[sensor]
kind = "ati"
can = "vcan0"
"#;

/// The simulated KUKA controller in lockstep (500 ms deadline) against the link at `addr`, moving
/// `world`, at most `cycles` datagrams (so a missing `Stop` fails a test instead of hanging it), its
/// configuration adjusted by `tweak`.
fn lockstep_krc(
    addr: std::net::SocketAddr,
    cycles: u64,
    world: &SharedWorld,
    tweak: impl FnOnce(&mut KrcConfig),
) -> thread::JoinHandle<KrcReport> {
    let mut kc = KrcConfig::new(
        EthernetConfig::forcecell([127, 0, 0, 1].into(), addr.port(), false),
        addr,
    );
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(500),
    };
    kc.cycles = Some(cycles);
    tweak(&mut kc);
    let mut krc = Krc::new(kc).unwrap();
    let mut mech = world.clone();
    thread::spawn(move || krc.run(&mut mech))
}

/// The cell of `CELL` against the simulated KUKA controller in lockstep on loopback, on a world whose
/// tool starts on its programmed path (correction 0, as at a real `RSI_ON`) with the surface 1 mm below.
/// The controller sends at most `cycles` datagrams, so a missing `Stop` fails the test instead of hanging it.
fn run_against_sim_krc(cycles: u64, stop: bool) -> (CellOutcome, KrcReport, SharedWorld) {
    run_with(cycles, stop, SensorParams::default(), None)
}

fn run_against_sim_krc_recorded(
    cycles: u64,
    stop: bool,
    recorder: Option<forcecell::recorder::Recorder>,
) -> (CellOutcome, KrcReport, SharedWorld) {
    run_with(cycles, stop, SensorParams::default(), recorder)
}

/// As [`run_against_sim_krc`], with the given sensor model and recorder.
fn run_with(
    cycles: u64,
    stop: bool,
    sensor: SensorParams,
    recorder: Option<forcecell::recorder::Recorder>,
) -> (CellOutcome, KrcReport, SharedWorld) {
    let mut cfg = CellConfig::from_toml(CELL, "cell.toml").unwrap();
    // Port 0 is refused in a cell file (the robot needs the real port); here the OS picks one.
    cfg.robot.listen.set_port(0);
    let tuning = cfg.tuning().unwrap();
    let lc = cfg.link_config(&tuning).unwrap();
    // The driver's envelope lies inside the robot's POSCORR (5 mm default), whatever the tuning allows.
    assert!(lc.limits.max_translation <= 0.0045 + 1e-12);
    let link = RsiLink::bind(lc).unwrap();
    let addr = link.local_addr().unwrap();
    let world: SharedWorld = World::new(
        ContactPlant::spring(70_000.0, 0.001),
        InnerLoopModel::P2,
        sensor,
        0.0,
    )
    .shared();
    let mut kc = KrcConfig::new(
        EthernetConfig::forcecell([127, 0, 0, 1].into(), addr.port(), false),
        addr,
    );
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(500),
    };
    kc.cycles = Some(cycles);
    let mut krc = Krc::new(kc).unwrap();
    let mut mech = world.clone();
    let robot = thread::spawn(move || krc.run(&mut mech));
    let flag = AtomicBool::new(stop);
    let out = forcecell::cell::run_cell_recorded(
        &cfg,
        &tuning,
        link,
        InProcSensor::new(world.clone()),
        &flag,
        recorder,
    )
    .unwrap();
    (out, robot.join().unwrap(), world)
}

#[test]
fn a_cell_file_runs_the_loop_over_rsi_and_ends_with_stop() {
    let (out, report, world) = run_against_sim_krc(2_000, false);
    assert!(out.stopped, "{}", out.ended);
    assert_eq!(
        report.end,
        KrcEnd::Stopped,
        "the robot saw Stop: {report:?}"
    );
    assert_eq!(report.late, 0);
    let last = out.rows.last().unwrap();
    assert!(last.t >= 1.5, "ran {} s", last.t);
    assert!((last.f - 5.0).abs() < 0.1, "held {} N at the end", last.f);
    let w = sim::world::lock(&world);
    assert!(
        (w.true_force() - 5.0).abs() < 0.1,
        "true force {}",
        w.true_force()
    );
}

#[test]
fn a_sensor_silent_in_contact_ends_the_run_backed_off_with_stop() {
    // The sensor gives nothing from 1.0 s on, while the tool presses 5 N: the loop may hold its last
    // command for `max_hold` (0.1 s), then backs off and ends, and the robot is told `Stop`.
    let silent = SensorParams {
        dropouts: vec![Window {
            at: 1.0,
            duration: 10.0,
        }],
        ..SensorParams::default()
    };
    let (out, report, world) = run_with(2_000, false, silent, None);
    assert!(out.ended.contains("held the last command"), "{}", out.ended);
    assert!(out.stopped, "{}", out.ended);
    // A fault of the loop's own guard has its own exit status, not a lost link's.
    assert_eq!(out.end, forcecell::cell::CellEnd::Fault, "{out:?}");
    assert_eq!(out.end.exit_status(), 4);
    assert_eq!(report.end, KrcEnd::Stopped, "{report:?}");
    let held = out.rows.iter().filter(|r| r.condition == 1).count();
    assert!(held > 0 && held <= 26, "held {held} cycles of 4 ms");
    let pressing = out.rows.iter().rev().find(|r| r.condition != 7).unwrap();
    let last = out.rows.last().unwrap();
    assert!(
        pressing.x_cmd - last.x_cmd >= 0.002 - 1e-9,
        "backed off {} m",
        pressing.x_cmd - last.x_cmd
    );
    // The tool is off the workpiece: no force, whatever the sensor would have said.
    assert_eq!(sim::world::lock(&world).true_force(), 0.0);
    assert!(last.t < 1.5, "ended at {} s", last.t);
}

#[test]
fn a_set_stop_flag_ends_the_run_with_stop_before_any_control() {
    let (out, report, _) = run_against_sim_krc(100, true);
    assert!(out.stopped && out.rows.is_empty(), "{out:?}");
    assert_eq!(report.end, KrcEnd::Stopped);
}

#[test]
fn bad_cell_files_are_refused_with_the_reason() {
    let cases = [
        (
            CELL.replace("robot_ip = \"127.0.0.1\"", "robot_ip = \"nope\""),
            "IP address",
        ),
        (format!("{CELL}\n[extra]\n"), "extra"),
        (
            CELL.replace("duration = 1.5", "duration = -1.0"),
            "duration",
        ),
        (CELL.replace("[robot]", "[robot]\ncycle_ms = 5"), "cycle_ms"),
        (
            CELL.replace("kind = \"ati\"", "kind = \"ati\"\nbase = 200"),
            "base",
        ),
        (
            CELL.replace("kind = \"ati\"", "kind = \"kistler\""),
            "kistler",
        ),
        (
            // A Robotiq sensor has a serial port, not a CAN interface.
            CELL.replace("kind = \"ati\"", "kind = \"robotiq\""),
            "unknown field `can`",
        ),
        (
            format!("{CELL}\n[gravity]\nsigned_mass = nan\nmass_moment = [0.0, 0.0, 0.0]\n"),
            "gravity",
        ),
    ];
    for (text, needle) in cases {
        let e = format!(
            "{:#}",
            CellConfig::from_toml(&text, "cell.toml").unwrap_err()
        );
        assert!(e.contains(needle), "{needle}: {e}");
        assert!(!e.contains('\n'), "one line: {e}");
    }
    let cfg = CellConfig::from_toml(&CELL.replace("robust", "nope"), "cell.toml").unwrap();
    assert!(format!("{:#}", cfg.tuning().unwrap_err()).contains("unknown tuning"));
}

#[test]
fn run_refuses_a_missing_config_file_cleanly() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(["run", "--config", "/nonexistent/cell.toml"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("cannot read cell config") && !err.contains("panicked"),
        "{err}"
    );
}

#[test]
fn the_example_cell_file_is_valid() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml");
    let cfg = CellConfig::load(&path).unwrap();
    let tuning = cfg.tuning().unwrap();
    let lc = cfg.link_config(&tuning).unwrap();
    assert_eq!(lc.period, Duration::from_millis(4));
    assert!(cfg.gravity.is_some());
    assert!((cfg.compensator().model.mass() - 2.0).abs() < 1e-12);
}

#[test]
fn the_printed_gravity_section_reads_back_as_the_same_model() {
    use controller::gravity::GravityModel;
    use hal::{UnitQuaternion, Vector3};
    let m = GravityModel {
        signed_mass: -1.75,
        mass_moment: Vector3::new(0.001, -0.002, 0.14),
        force_bias: Vector3::new(0.5, -1.25, 3.0),
        torque_bias: Vector3::new(0.01, 0.0, -0.02),
    };
    let mount = UnitQuaternion::from_euler_angles(0.0, 0.0, 0.5);
    let text = format!("{CELL}\n{}", forcecell::cell::gravity_section(&m, mount));
    let cfg = CellConfig::from_toml(&text, "cell.toml").unwrap();
    let c = cfg.compensator();
    assert!((c.model.signed_mass - m.signed_mass).abs() < 1e-6);
    assert!((c.model.mass_moment - m.mass_moment).norm() < 1e-6);
    assert!((c.model.force_bias - m.force_bias).norm() < 1e-6);
    assert!(c.mount.angle_to(&mount) < 1e-6);
}

#[test]
fn calibrate_refuses_too_few_poses_before_touching_any_device() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args([
            "calibrate",
            "--config",
            "examples/cell.toml",
            "--poses",
            "2",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--poses must be 3..=64"), "{err}");
}

#[test]
fn a_recorded_cell_run_streams_every_cycle_to_mcap() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let (tx, recording) =
        forcecell::recorder::start(&path, forcecell::recorder::RecorderOptions::default(), None)
            .unwrap();
    let (out, report, _) = run_against_sim_krc_recorded(2_000, false, Some(tx));
    assert!(out.stopped, "{}", out.ended);
    assert_eq!(report.end, KrcEnd::Stopped);
    assert!(
        out.rows.is_empty(),
        "the recording holds the trace, not a Vec grown in the loop"
    );
    let summary = recording.finish(Vec::new()).unwrap();
    assert!(summary.finished, "{summary}");
    // Every answered cycle but the final Stop is a record.
    assert_eq!(
        summary.written + summary.dropped,
        out.stats.cycles - 1,
        "{summary}"
    );
    let bytes = std::fs::read(&path).unwrap();
    let back = forcecell::recorder::read_mcap(&bytes).unwrap();
    assert_eq!(back.rows.len() as u64, summary.written);
    let last = back.rows.last().unwrap();
    assert!(last.t >= 1.5 && (last.f - 5.0).abs() < 0.1, "{last:?}");
    // The raw (uncompensated) wrench is recorded beside the compensated one, in every cycle.
    let raw = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == scenario::telemetry::CYCLE_TOPIC)
        .filter(|m| {
            let mut rec = forcecell::recorder::Record::unknown();
            scenario::telemetry::decode(&scenario::telemetry::CYCLE, &m.data, &mut rec).unwrap();
            rec.wrench_raw.iter().all(|v| v.is_finite())
        })
        .count() as u64;
    assert_eq!(raw, summary.written);
}

/// `run`'s wait for the robot's first datagram ends when the stop flag is set (Ctrl-C, SIGTERM): the
/// link waits in short slices and the interruptible wrapper ends the wait between them.
#[test]
fn a_stop_ends_the_wait_for_a_robot_that_never_sends() {
    use forcecell::cell::CellEnd;
    use forcecell::stop::Interruptible;
    use std::sync::atomic::Ordering;
    let mut cfg = CellConfig::from_toml(CELL, "cell.toml").unwrap();
    // Port 0 is refused in a cell file (the robot needs the real port); here the OS picks one.
    cfg.robot.listen.set_port(0);
    let tuning = cfg.tuning().unwrap();
    let lc = cfg.link_config(&tuning).unwrap();
    assert!(
        lc.first_contact_timeout.is_some(),
        "the wait comes back now and then"
    );
    let mut link = RsiLink::bind(lc).unwrap();
    let world: SharedWorld = World::new(
        ContactPlant::spring(70_000.0, 0.001),
        InnerLoopModel::P2,
        SensorParams::default(),
        0.0,
    )
    .shared();
    let flag = AtomicBool::new(false);
    let out = thread::scope(|s| {
        let run = s.spawn(|| {
            run_cell(
                &cfg,
                &tuning,
                Interruptible::new(&mut link, &flag),
                InProcSensor::new(world.clone()),
                &flag,
            )
            .unwrap()
        });
        // No robot: the run is waiting. The operator stops it.
        thread::sleep(Duration::from_millis(300));
        flag.store(true, Ordering::Relaxed);
        run.join().unwrap()
    });
    assert_eq!(out.end, CellEnd::Stopped, "{out:?}");
    assert_eq!(out.end.exit_status(), 130);
    assert!(out.rows.is_empty() && !out.stopped, "{out:?}");
}

/// A robot that falls silent before the configured duration ends the run early, with its own status.
#[test]
fn a_lost_link_ends_the_run_early_with_status_3() {
    use forcecell::cell::CellEnd;
    let mut cfg = CellConfig::from_toml(CELL, "cell.toml").unwrap();
    // Port 0 is refused in a cell file (the robot needs the real port); here the OS picks one.
    cfg.robot.listen.set_port(0);
    let tuning = cfg.tuning().unwrap();
    let link = RsiLink::bind(cfg.link_config(&tuning).unwrap()).unwrap();
    let addr = link.local_addr().unwrap();
    let world: SharedWorld = World::new(
        ContactPlant::spring(70_000.0, 0.001),
        InnerLoopModel::P2,
        SensorParams::default(),
        0.0,
    )
    .shared();
    let robot = lockstep_krc(addr, 2_000, &world, |kc| {
        kc.faults.silent_from = Some(100);
    });
    let flag = AtomicBool::new(false);
    let out = run_cell(&cfg, &tuning, link, InProcSensor::new(world.clone()), &flag).unwrap();
    robot.join().unwrap();
    assert_eq!(out.end, CellEnd::EndedEarly, "{out:?}");
    assert_eq!(out.end.exit_status(), 3);
    assert_eq!(out.rows.len(), 100);
    assert!(out.ended.contains("link lost"), "{}", out.ended);
}

/// `forcecell run` with `[robot] process = true`: the robot program drives the pass over `FcCmd` /
/// `FcState` (here the simulated controller running a program), and the run lasts until the robot
/// ends its session.
#[test]
fn a_cell_with_process_channels_follows_the_robot_program() {
    use sim::program::SegmentMode;
    use sim::{Program, Segment};
    const PROCESS_CELL: &str = r#"
tuning = "robust"

[robot]
listen = "127.0.0.1:49152"
robot_ip = "127.0.0.1"
process = true

[sensor]
kind = "ati"
can = "vcan0"
"#;
    let mut cfg = CellConfig::from_toml(PROCESS_CELL, "cell.toml").unwrap();
    // Port 0 is refused in a cell file (the robot needs the real port); here the OS picks one.
    cfg.robot.listen.set_port(0);
    let tuning = cfg.tuning().unwrap();
    let link = RsiLink::bind(cfg.link_config(&tuning).unwrap()).unwrap();
    let addr = link.local_addr().unwrap();
    let seg = |mode, force, segment, length| Segment {
        mode,
        force,
        ramp: 0.3,
        segment,
        feed: 0.05,
        length,
        dwell: 0.0,
    };
    let program = Program {
        segments: vec![
            seg(SegmentMode::Press, 10.0, 1, 0.05),
            seg(SegmentMode::Release, 0.0, 2, 0.0),
        ],
        wait_timeout: 5.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let world: SharedWorld = World::new(
        ContactPlant::spring(10_000.0, 0.001),
        InnerLoopModel::P2,
        SensorParams::default(),
        0.0,
    )
    .with_program(program)
    .shared();
    let mut kc = KrcConfig::new(
        EthernetConfig::forcecell([127, 0, 0, 1].into(), addr.port(), false)
            .with_process(kuka_rsi::ProcessChannels::default()),
        addr,
    );
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(500),
    };
    // About 3 s of pass at 4 ms, then the robot falls silent (its RSI_OFF).
    kc.cycles = Some(1_500);
    let mut krc = Krc::new(kc).unwrap();
    let mut mech = world.clone();
    let robot = thread::spawn(move || krc.run(&mut mech));
    let flag = AtomicBool::new(false);
    let out = forcecell::cell::run_cell_recorded(
        &cfg,
        &tuning,
        link,
        InProcSensor::new(world.clone()),
        &flag,
        None,
    )
    .unwrap();
    let report = robot.join().unwrap();
    assert_eq!(report.bad_process, 0, "{report:?}");
    assert_eq!(
        out.end,
        forcecell::cell::CellEnd::Done,
        "the robot ending its session is the run's end: {}",
        out.ended
    );
    let w = sim::world::lock(&world);
    let p = w.program().unwrap();
    assert!(p.done() && p.aborted().is_none(), "{:?}", p.aborted());
    drop(w);
    let mut phases: Vec<u8> = out.rows.iter().filter_map(|r| r.phase).collect();
    phases.dedup();
    assert_eq!(phases, [1, 2, 3, 4, 0], "{}", out.ended);
    let pressing: Vec<f64> = out
        .rows
        .iter()
        .filter(|r| r.phase == Some(3))
        .map(|r| r.f)
        .collect();
    assert!(pressing.len() > 200, "pressed along 50 mm");
    assert!(
        pressing.iter().all(|f| (f - 10.0).abs() <= 0.5),
        "held 10 N ± 5 %"
    );
    assert!(
        out.rows.iter().all(|r| r.segment.is_some()),
        "every row carries its segment"
    );
    assert_eq!(
        out.rows.last().unwrap().x_cmd,
        0.0,
        "the correction is back at zero"
    );
}

/// `forcecell run` with the robot's own Ethernet configuration (from `tests/rsi-corpus/`): one that
/// the force control cannot work through is refused with one line naming what is missing, before the
/// recording directory is made, the sensor opened or the port bound.
#[test]
fn run_refuses_a_configuration_it_cannot_control_through_before_anything_moves() {
    let corpus = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rsi-corpus/configs");
    let cases = [
        (
            "axis-only.xml",
            false,
            "RECEIVE has no Cartesian correction RKorr.X, RKorr.Y, RKorr.Z (it has axis corrections only",
        ),
        ("no-stop.xml", false, "RECEIVE has no Stop channel"),
        ("onlysend.xml", false, "ONLYSEND is TRUE"),
        (
            "internal-receive.xml",
            true,
            "process = true but SEND has no FcCmd and RECEIVE no FcState",
        ),
    ];
    for (file, process, words) in cases {
        let dir = tempfile::tempdir().unwrap();
        let cell = CELL
            .replace(
                "[robot]",
                &format!(
                    "record = {:?}\n\n[robot]\nethernet_config = {:?}\nprocess = {process}",
                    dir.path().join("rec").display().to_string(),
                    corpus.join(file).display().to_string()
                ),
            )
            // A port nothing else uses: the refusal must come before it is bound.
            .replace("127.0.0.1:0", "127.0.0.1:1");
        std::fs::write(dir.path().join("cell.toml"), cell).unwrap();
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_forcecell"))
            .args(["run", "--config", "cell.toml"])
            .current_dir(dir.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{file}: {err}");
        assert!(err.contains(words), "{file}: {err}");
        assert!(err.contains(file), "{file}: names the file: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!dir.path().join("rec").exists(), "{file}: nothing recorded");
    }
}

/// A cell whose tuning follows the surface: the robot's POSCORR rotation (15°, POSCORRMON 18°) said.
const TURNING_CELL: &str = r#"
tuning = "robust-curved"
duration = 1.5

[robot]
listen = "127.0.0.1:49152"
robot_ip = "127.0.0.1"
poscorr_deg = 15.0
poscorrmon_deg = 18.0

[sensor]
kind = "ati"
can = "vcan0"
"#;

/// `cell` against the simulated KUKA controller (its POSCORR rotation 15°, POSCORRMON 18°) on a flat
/// part tilted 3° about the path under a 10 N/mm pad, 1 mm below the path: the outcome and the tilt
/// error (truth) and rotation sent at the end.
fn run_on_tilted_part(cell: &str) -> (CellOutcome, f64, f64) {
    use sim::geometry::{Geometry, Shape};
    let mut cfg = CellConfig::from_toml(cell, "cell.toml").unwrap();
    cfg.robot.listen.set_port(0);
    let tuning = cfg.tuning().unwrap();
    let lc = cfg.link_config(&tuning).unwrap();
    let link = RsiLink::bind(lc).unwrap();
    let addr = link.local_addr().unwrap();
    let world: SharedWorld = World::new(
        ContactPlant::spring(10_000.0, 0.001),
        InnerLoopModel::P2,
        SensorParams::default(),
        0.0,
    )
    .with_geometry(Geometry {
        shape: Shape::Flat,
        misplace_x: 3f64.to_radians(),
        misplace_y: 0.0,
        pad_radius: 0.02,
        friction: 0.0,
        tool_length: 0.1,
        program_tilt: 0.0,
    })
    .shared();
    let robot = lockstep_krc(addr, 1_000, &world, |kc| {
        kc.poscorr.rotation = 15f64.to_radians();
        kc.poscorrmon.rotation = 18f64.to_radians();
    });
    let flag = AtomicBool::new(false);
    let out = run_cell(&cfg, &tuning, link, InProcSensor::new(world.clone()), &flag).unwrap();
    robot.join().unwrap();
    let tilt = sim::world::lock(&world).truth().tilt_error;
    let turned = out.rows.last().unwrap().rotation;
    (out, tilt, turned)
}

#[test]
fn run_follows_the_surface_with_a_tuning_that_has_orientation_and_not_without() {
    let (out, tilt, turned) = run_on_tilted_part(TURNING_CELL);
    assert!(out.stopped, "{}", out.ended);
    assert!(
        tilt.to_degrees() < 1.0,
        "the tool came square to the part: tilt error {}°",
        tilt.to_degrees()
    );
    assert!(
        (turned.to_degrees() - 3.0).abs() < 0.5,
        "turned by {}°",
        turned.to_degrees()
    );
    let last = out.rows.last().unwrap();
    assert!((last.f - 5.0).abs() < 0.25, "held {} N", last.f);
    // The same cell with the law along the normal only: the tool keeps the program's orientation.
    let (_, tilt, turned) = run_on_tilted_part(&TURNING_CELL.replace("robust-curved", "robust"));
    assert!(
        (tilt.to_degrees() - 3.0).abs() < 0.01,
        "tilt {}°",
        tilt.to_degrees()
    );
    assert_eq!(turned, 0.0);
}

#[test]
fn an_orientation_following_tuning_is_refused_where_the_robot_cannot_turn_as_it_asks() {
    let err = |text: &str| {
        let cfg = CellConfig::from_toml(text, "cell.toml").unwrap();
        let t = cfg.tuning().unwrap();
        format!("{:#}", cfg.link_config(&t).unwrap_err())
    };
    // RSI's default 5° POSCORR rotation is below the tuning's 15°.
    let e = err(&TURNING_CELL.replace("poscorr_deg = 15.0\nposcorrmon_deg = 18.0\n", ""));
    assert!(
        e.contains("robot.poscorr_deg") && e.contains("limit is 5.0°"),
        "{e}"
    );
    // A robot limit of 12.5° is below the tuning's own 15° per axis.
    let e = err(&TURNING_CELL.replace("poscorr_deg = 15.0", "poscorr_deg = 12.5"));
    assert!(e.contains("orientation.poscorr"), "{e}");
    // A law envelope of 14.3° beyond the driver's 13.5° (90 % of 15°): the robot would clamp first.
    let dir = tempfile::tempdir().unwrap();
    let shipped = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tunings/robust-curved.toml"),
    )
    .unwrap();
    let wide = dir.path().join("wide.toml");
    std::fs::write(
        &wide,
        shipped.replace("max_angle = 0.21", "max_angle = 0.25"),
    )
    .unwrap();
    let e = err(&TURNING_CELL.replace(
        "\"robust-curved\"",
        &format!("{:?}", wide.display().to_string()),
    ));
    assert!(e.contains("orientation.max_angle 14.3°"), "{e}");
    // An Ethernet config without the rotational channels.
    let xml = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false)
        .to_xml()
        .lines()
        .filter(|l| !l.contains("RKorr.A") && !l.contains("RKorr.B"))
        .collect::<Vec<_>>()
        .join("\n");
    let path = dir.path().join("rsi.xml");
    std::fs::write(&path, xml).unwrap();
    let e = err(&TURNING_CELL.replace(
        "[robot]\n",
        &format!(
            "[robot]\nethernet_config = {:?}\n",
            path.display().to_string()
        ),
    ));
    assert!(
        e.contains("RKorr.A, RKorr.B") && !e.contains("RKorr.C"),
        "{e}"
    );
    // The same robot with a tuning along the normal needs none of it.
    let plain = TURNING_CELL.replace("robust-curved", "robust");
    let cfg = CellConfig::from_toml(&plain, "cell.toml").unwrap();
    cfg.link_config(&cfg.tuning().unwrap()).unwrap();
    // POSCORRMON's rotation at or below POSCORR's.
    let e = format!(
        "{:#}",
        CellConfig::from_toml(
            &TURNING_CELL.replace("poscorrmon_deg = 18.0", "poscorrmon_deg = 15.0"),
            "cell.toml"
        )
        .unwrap_err()
    );
    assert!(e.contains("poscorrmon_deg"), "{e}");
}

#[test]
fn an_orientation_following_tuning_is_refused_on_an_abb_robot() {
    let cell = r#"
tuning = "robust-curved"

[robot]
kind = "abb-egm"
listen = "127.0.0.1:6510"
robot_ip = "127.0.0.1"

[sensor]
kind = "ati"
can = "vcan0"
"#;
    let cfg = CellConfig::from_toml(cell, "cell.toml").unwrap();
    let e = format!("{:#}", cfg.robot_spec(&cfg.tuning().unwrap()).unwrap_err());
    assert!(e.contains("translation only"), "{e}");
    let cfg = CellConfig::from_toml(&cell.replace("robust-curved", "robust"), "cell.toml").unwrap();
    cfg.robot_spec(&cfg.tuning().unwrap()).unwrap();
}
