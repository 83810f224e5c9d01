//! The ABB EGM wiring of the application: `forcecell sim --robot egm` runs the EGM driver against the
//! simulated IRC5 over real loopback UDP. [`crate::rsi::RobotSide`] starts it and runs the scenario
//! through the one run loop; everything EGM-specific is here.

use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::thread;
use std::time::Duration;

use abb_egm::{
    CommandSlots, CorrectionRange, Diagnostics, EgmLink, Limits, LinkConfig, RobotFilter,
};
use anyhow::{Context, Result};
use controller::LoopConfig;
use sim::SharedWorld;
use sim::irc5::{Irc5, Irc5Config, Irc5Report};
use sim::krc::Timing;

use crate::runner::RunSpec;

/// The driver's envelope and rate limit from a tuning's own loop limits (so the driver never acts
/// before the loop does), and the robot's path-correction range 10 % beyond the envelope.
pub fn cell_limits(loop_cfg: &LoopConfig) -> (Limits, CorrectionRange) {
    (
        Limits {
            max_translation: loop_cfg.max_offset,
            max_translation_step: loop_cfg.max_step,
        },
        CorrectionRange {
            translation: loop_cfg.max_offset * 1.1,
        },
    )
}

/// The EGM driver bound on loopback and the simulated IRC5 already running in its thread.
pub struct SimulatedEgm {
    /// The driver.
    pub link: EgmLink,
    /// The controller's thread.
    pub irc5: thread::JoinHandle<Irc5Report>,
    /// Set to end the controller.
    pub abort: Arc<AtomicBool>,
}

/// Start the driver and the simulated IRC5 on `world` for `spec`. A scenario with a robot program
/// runs it on the controller: its command goes out in `RAPIDfromRobot`, the state comes back through
/// the controller's RAPID variables (the driver's state channel). `clear_on_exit` is cleared however
/// the controller's thread ends.
pub fn start_simulated(
    spec: &RunSpec,
    world: &SharedWorld,
    realtime: bool,
    first_contact: Duration,
    clear_on_exit: Arc<AtomicBool>,
) -> Result<SimulatedEgm> {
    let period = Duration::from_secs_f64(spec.plant.period);
    let process = spec.scenario.program.is_some().then(CommandSlots::default);
    let (limits, range) = cell_limits(&spec.tuning.loop_cfg);
    let mut lc = LinkConfig::new(SocketAddr::from((Ipv4Addr::LOCALHOST, 0)), RobotFilter::Any);
    lc.period = period;
    lc.limits = limits;
    lc.range = range;
    lc.process = process;
    lc.first_contact_timeout = Some(first_contact);
    // 1 s: lockstep pauses whenever the loop does.
    lc.watchdog_cycles = ((1.0 / spec.plant.period).ceil() as u32).max(25);
    // A sequence-number jump of up to 1 s is still the same session.
    lc.session_jump = lc.watchdog_cycles;
    let mut link = EgmLink::bind(lc).context("EGM driver")?;
    let mut kc = Irc5Config::new(link.local_addr()?);
    kc.period = period;
    kc.range = range;
    kc.process = process;
    kc.timing = if realtime {
        Timing::Realtime
    } else {
        // As for the simulated KRC: lockstep has no real-time meaning, a long wait keeps one datagram
        // per step on a loaded host.
        Timing::Lockstep {
            deadline: Duration::from_secs(5),
        }
    };
    // One more than the run's steps: the last cycle is answered with `stop`.
    kc.cycles = (!realtime).then(|| spec.steps() + 1);
    let mut irc5 = Irc5::new(kc).context("simulated IRC5")?;
    link.set_robot_filter(RobotFilter::Exact(irc5.local_addr()?));
    if process.is_some() {
        link.set_state_channel(Box::new(irc5.rapid_variables()));
    }
    let abort = irc5.abort_handle();
    let mut mech = world.clone();
    let handle = thread::Builder::new()
        .name("sim-irc5".into())
        .spawn(move || {
            let _alive = crate::rsi::ClearOnDrop(clear_on_exit);
            irc5.run(&mut mech)
        })?;
    Ok(SimulatedEgm {
        link,
        irc5: handle,
        abort,
    })
}

/// Print the EGM link's counters and its receive→send latency.
pub fn print_link(d: &Diagnostics) {
    let c = d.counters;
    let l = &d.latency;
    println!(
        "EGM link: {} received, {} answered, {} late after arrival, {} skipped, {} stale, {} foreign, {} malformed, {} oversized, {} implausible, {} rotations dropped, {} states published",
        c.received,
        c.answered,
        c.late,
        c.skipped,
        c.stale,
        c.foreign,
        c.malformed,
        c.oversized,
        c.implausible,
        c.rotation_dropped,
        c.states_published
    );
    let a = &d.from_arrival;
    println!(
        "  arrival→send: p50 {:?}, p99 {:?}, p99.9 {:?}, max {:?}{}",
        a.quantile(0.5),
        a.quantile(0.99),
        a.quantile(0.999),
        a.max(),
        if c.unstamped > 0 {
            format!(
                " ({} replies without a kernel receive stamp: measured from the receive call)",
                c.unstamped
            )
        } else {
            String::new()
        }
    );
    println!(
        "  receive→send: p50 {:?}, p99 {:?}, p99.9 {:?}, max {:?}",
        l.quantile(0.5),
        l.quantile(0.99),
        l.quantile(0.999),
        l.max()
    );
}

/// Print the simulated IRC5's report in one line.
pub fn print_irc5(r: &Irc5Report) {
    println!(
        "  simulated IRC5: {} cycles, {} good, {} late, {} bad, {} clamped, max age {} ms, ended {:?}",
        r.cycles, r.good, r.late, r.bad, r.clamped, r.max_age, r.end
    );
}

/// The controller settings and RAPID module of `forcecell egm-config`, from its arguments.
pub fn egm_cell_config(a: &crate::args::EgmConfigArgs) -> abb_egm::rapid::EgmCellConfig {
    let mut c = abb_egm::rapid::EgmCellConfig::new(a.host);
    c.port = a.port;
    c.device = a.device.clone();
    c.ext_motion = a.ext_motion.clone();
    c.module = a.module.clone();
    c.tool = a.tool.clone();
    c.wobj = a.wobj.clone();
    c.max_wait = a.max_wait;
    c.correction_mm = a.correction_mm;
    c
}

/// `forcecell egm-config`: everything is validated and rendered first; an existing file of the same
/// name is refused (all of them named) unless `--force`; each file goes to a temporary file in the
/// output directory and is renamed over its name only when every one was written.
pub fn egm_config(a: &crate::args::EgmConfigArgs) -> Result<Vec<std::path::PathBuf>> {
    let files = egm_cell_config(a)
        .render()
        .map_err(|e| anyhow::anyhow!("egm-config: {e}"))?;
    let paths: Vec<_> = files.iter().map(|(n, _)| a.out.join(n)).collect();
    if !a.force {
        let existing: Vec<String> = paths
            .iter()
            .filter(|p| p.exists())
            .map(|p| p.display().to_string())
            .collect();
        if !existing.is_empty() {
            anyhow::bail!(
                "egm-config: {} already exist(s); nothing was written (--force replaces them)",
                existing.join(", ")
            );
        }
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create output directory {}", a.out.display()))?;
    let mut temps = Vec::new();
    let cleanup = |temps: &[std::path::PathBuf]| {
        for t in temps {
            let _ = std::fs::remove_file(t);
        }
    };
    for ((name, text), path) in files.iter().zip(&paths) {
        let tmp = a.out.join(format!(".{name}.tmp-{}", std::process::id()));
        temps.push(tmp.clone());
        if let Err(e) = std::fs::write(&tmp, text) {
            cleanup(&temps);
            return Err(e).with_context(|| format!("cannot write {}", path.display()));
        }
    }
    for (tmp, path) in temps.iter().zip(&paths) {
        std::fs::rename(tmp, path).with_context(|| {
            cleanup(&temps);
            format!("cannot rename {} to {}", tmp.display(), path.display())
        })?;
    }
    Ok(paths)
}

/// `forcecell sim --external-robot ADDR --robot egm`: the dry run for an EGM client — the external
/// device, e.g. `forcecell run` with a `kind = "abb-egm"` cell file listening on `ADDR`. This side
/// plays the robot: the simulated IRC5 sends `EgmRobot` to `ADDR` every period of wall-clock time and
/// applies the path corrections it gets to the scenario's plant and workpiece; a simulated FT 300 on
/// a pseudo-terminal (linked at `sensor_link`) measures that workpiece for the client's `[sensor]`;
/// the scenario's robot program, if any, runs on the controller (its command in `RAPIDfromRobot`),
/// and reads its state from the controller's Robot Web Services endpoint (the simulated one,
/// [`sim::rws::RwsServer`]: HTTPS on loopback; the client's `robot.rws` and `rws_fingerprint`, which
/// this prints). The controller starts once the client's sensor has started its stream (the
/// client is then about to listen), and stops after the scenario's duration. Loopback only.
/// Returns the exit status: 0 when the controller ran its course, 3 when it ended early.
pub fn dry_run(
    spec: &RunSpec,
    client: SocketAddr,
    sensor_link: Option<&std::path::Path>,
) -> Result<u8> {
    use std::sync::atomic::Ordering;
    if !client.ip().is_loopback() {
        anyhow::bail!(
            "--external-robot {client} with --robot egm: the simulated IRC5 sends on loopback only; give the client's robot.listen as 127.0.0.1:PORT"
        );
    }
    let ms = spec.plant.period * 1e3;
    if !((ms / 4.0).round() >= 1.0 && ((ms / 4.0).round() * 4.0 - ms).abs() < 1e-9) {
        anyhow::bail!(
            "the EGM dry run runs at EGM's cycle, a multiple of 4 ms; plant {} has {ms} ms: give --plant p2 (4 ms)",
            spec.plant_label
        );
    }
    let world = spec.world();
    let period = Duration::from_secs_f64(spec.plant.period);
    let (_, range) = cell_limits(&spec.tuning.loop_cfg);
    let process = spec.scenario.program.is_some().then(CommandSlots::default);
    let mut kc = Irc5Config::new(client);
    kc.period = period;
    kc.range = range;
    kc.process = process;
    kc.timing = Timing::Realtime;
    kc.cycles = Some(spec.steps());
    let mut irc5 = Irc5::new(kc).context("simulated IRC5")?;
    let device = sim::ft300::SimFt300::spawn(
        sim::ft300::Ft300Config {
            noise_force: 0.0,
            noise_torque: 0.0,
            link: sensor_link.map(std::path::Path::to_path_buf),
            ..sim::ft300::Ft300Config::default()
        },
        sim::ati_node::WorldSource::measured(world.clone()),
    )
    .context("simulated FT 300")?;
    let mut rws =
        sim::rws::RwsServer::start(sim::rws::RwsServerConfig::default(), irc5.rapid_variables())
            .context("the simulated controller's Robot Web Services")?;
    println!(
        "simulated IRC5 ({} ms, path-correction range {:.1} mm) sending EgmRobot to {client} from {}",
        period.as_millis(),
        range.translation * 1e3,
        irc5.local_addr()?
    );
    println!(
        "sensor: simulated FT 300 measuring the virtual workpiece: [sensor] kind = \"robotiq\", port = \"{}\"",
        device.link().unwrap_or(device.path()).display()
    );
    match process {
        Some(_) => println!(
            "robot program: {} (its command in RAPIDfromRobot.dnum); its state over Robot Web Services: robot.rws = \"{}\", rws_fingerprint = \"{}\"",
            spec.scenario.name,
            rws.url(),
            abb_egm::rws::fingerprint_text(&rws.fingerprint())
        ),
        None => {
            println!("robot program: none (the client runs force control from its first cycle)")
        }
    }
    let stop = crate::stop::flag();
    // The controller waits for the client's sensor to start its stream: the client binds its link
    // right after (as a robot's program is started once the external device listens).
    println!("waiting for the client to start its sensor (Ctrl-C ends)");
    while device.stats().starts == 0 {
        if stop.load(Ordering::Relaxed) {
            println!("stopped before the client started");
            device.stop().context("simulated FT 300")?;
            return Ok(crate::stop::INTERRUPTED);
        }
        thread::sleep(Duration::from_millis(20));
    }
    thread::sleep(Duration::from_millis(500));
    println!("client's sensor streaming: EGM starts");
    let abort = irc5.abort_handle();
    let done = Arc::new(AtomicBool::new(false));
    let helper = {
        let done = done.clone();
        thread::Builder::new()
            .name("sim-irc5-stop".into())
            .spawn(move || {
                while !done.load(Ordering::Relaxed) {
                    if stop.load(Ordering::Relaxed) {
                        abort.store(true, Ordering::Relaxed);
                    }
                    thread::sleep(Duration::from_millis(20));
                }
            })?
    };
    let mut mech = world.clone();
    let report = irc5.run(&mut mech);
    done.store(true, Ordering::Relaxed);
    let _ = helper.join();
    rws.stop();
    let states = rws.stats().writes.load(Ordering::Relaxed);
    let s = device.stats();
    device.stop().context("simulated FT 300")?;
    print_irc5(&report);
    println!(
        "  process variables written over RWS: {states}; FT 300 frames sent: {}",
        s.frames
    );
    let w = sim::world::lock(&world);
    if let Some(why) = w.program().and_then(sim::program::ProgramRunner::aborted) {
        println!("  the robot program aborted: {why}");
    }
    Ok(match report.end {
        sim::irc5::Irc5End::Completed => crate::stop::OK,
        sim::irc5::Irc5End::Aborted => crate::stop::INTERRUPTED,
        _ => crate::stop::ENDED_EARLY,
    })
}
