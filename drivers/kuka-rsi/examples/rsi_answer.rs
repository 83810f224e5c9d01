//! forcecell's RSI link answering a robot with the process channels in use (`FcCmd` in, `FcState`
//! out): the measured side of the turnaround benchmark (`examples/turnaround.rs`), and the process
//! to trace for the system calls per cycle. Binds `127.0.0.1:0`, prints the address, answers every
//! cycle at once with a correction and the state for the command it carries.
//!
//! `rsi_answer [CYCLES]`: exit after CYCLES answered cycles (for `strace -c`); default: run until killed.

use std::io::Write as _;
use std::time::Duration;

use hal::{Correction, ProcessFault, ProcessMode, ProcessPhase, ProcessState, RobotLink};
use kuka_rsi::{EthernetConfig, LinkConfig, ProcessChannels, RobotFilter, RsiLink};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let cycles: Option<u64> = std::env::args().nth(1).map(|s| s.parse()).transpose()?;
    let eth = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false)
        .with_process(ProcessChannels::default());
    let mut lc = LinkConfig::new(eth, RobotFilter::Ip([127, 0, 0, 1].into()));
    lc.bind = Some("127.0.0.1:0".parse()?);
    lc.watchdog_cycles = 25_000; // 100 s: the client may pause between runs
    let mut link = RsiLink::bind(lc)?;
    let mut out = std::io::stdout();
    writeln!(out, "{}", link.local_addr()?)?;
    out.flush()?;
    let mut n = 0u64;
    while cycles.is_none_or(|c| n < c) {
        let c = match link.next_cycle() {
            Ok(c) => c,
            Err(e) if hal::Error::kind(&e) == hal::ErrorKind::LinkLost => continue,
            Err(e) => return Err(e.into()),
        };
        let phase = match c.process.map(|p| p.mode) {
            Some(ProcessMode::Press) => ProcessPhase::Pressing,
            Some(ProcessMode::Release) => ProcessPhase::Release,
            _ => ProcessPhase::Off,
        };
        link.reply(&Correction {
            process: ProcessState {
                phase,
                force: c.process.map_or(0.0, |p| p.force),
                fault: ProcessFault::None,
            },
            ..Correction::along_z(1e-5)
        })?;
        n += 1;
    }
    // Let the last reply leave before the process (and a tracer's summary) ends.
    std::thread::sleep(Duration::from_millis(10));
    Ok(())
}
