//! Real-time settings for `run` (the cell file's `[realtime]`): a `SCHED_FIFO` priority for the
//! cycle's thread and a lower one for the sensor's reader, the cycle pinned to a CPU, and memory
//! locked with the stack touched before the first cycle. Each is applied where the system grants
//! it; where it refuses, the run says so once, naming the fix, and goes on: a run without the
//! settings is still correct, only later in its tail (docs/realtime.md).

use std::fmt;

use nix::sched::{CpuSet, sched_getaffinity, sched_setaffinity};
use nix::sys::mman::{MlockAllFlags, mlockall};
use nix::unistd::Pid;
use serde::{Deserialize, Serialize};
use thread_priority::unix::{
    RealtimeThreadSchedulePolicy, ThreadSchedulePolicy, set_thread_priority_and_policy,
    thread_native_id, thread_schedule_policy_param,
};
use thread_priority::{ThreadPriority, ThreadPriorityValue};

/// The highest `SCHED_FIFO` priority accepted (Linux's range is 1..=99; 99 is left to the kernel's
/// own watchdogs).
pub const MAX_PRIORITY: u8 = 98;
/// How much stack the cycle's thread touches before its first cycle, bytes: its pages are then
/// mapped and, with the memory locked, stay so (a page fault in a cycle costs tens of µs).
pub const STACK_PREFAULT: usize = 256 * 1024;

/// What the fix for a refused setting is, for the operator.
const FIX_RTPRIO: &str = "give the user an rtprio limit (a file in /etc/security/limits.d/ with \
                          `USER - rtprio 98`, then log in again) or the binary CAP_SYS_NICE \
                          (`setcap cap_sys_nice,cap_ipc_lock+ep forcecell`)";
const FIX_MEMLOCK: &str = "give the user a memlock limit (`USER - memlock unlimited` in \
                           /etc/security/limits.d/) or the binary CAP_IPC_LOCK";

/// The cell file's `[realtime]`: on by default.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Realtime {
    /// `SCHED_FIFO` priority of the cycle's thread, 1..=98; 0 leaves it `SCHED_OTHER`.
    pub priority: u8,
    /// `SCHED_FIFO` priority of the sensor's reader thread, below `priority`; 0 leaves it
    /// `SCHED_OTHER`.
    pub sensor_priority: u8,
    /// The CPU the cycle's thread runs on (`None`: wherever the scheduler puts it). Keep other load
    /// off it (`isolcpus`, or pin the rest elsewhere).
    pub cpu: Option<usize>,
    /// Lock all memory (`mlockall`, current and future) before the first cycle.
    pub lock_memory: bool,
}

impl Default for Realtime {
    fn default() -> Self {
        Self {
            priority: 80,
            sensor_priority: 70,
            cpu: None,
            lock_memory: true,
        }
    }
}

impl Realtime {
    /// No real-time setting at all.
    pub const OFF: Self = Self {
        priority: 0,
        sensor_priority: 0,
        cpu: None,
        lock_memory: false,
    };

    /// Checks the values against this machine (the CPU must be one the process may run on).
    pub fn validate(&self) -> Result<(), String> {
        for (name, p) in [
            ("priority", self.priority),
            ("sensor_priority", self.sensor_priority),
        ] {
            if p > MAX_PRIORITY {
                return Err(format!(
                    "realtime.{name} is a SCHED_FIFO priority of at most {MAX_PRIORITY} (99 is the \
                     kernel's own), got {p}"
                ));
            }
        }
        if self.priority > 0 && self.sensor_priority >= self.priority {
            return Err(format!(
                "realtime.sensor_priority {} must be below the cycle's priority {}: the cycle \
                 must never wait for the sensor's reader",
                self.sensor_priority, self.priority
            ));
        }
        if let Some(cpu) = self.cpu {
            let allowed = allowed_cpus();
            if !allowed.contains(&cpu) {
                return Err(format!(
                    "realtime.cpu {cpu} is not a CPU this process may run on ({})",
                    list(&allowed)
                ));
            }
        }
        Ok(())
    }

    /// Apply the cycle's settings to the calling thread: priority, CPU, memory lock, the stack
    /// touched. Never fails: what was refused is in the result.
    pub fn apply_to_cycle_thread(&self) -> Applied {
        let mut a = Applied::default();
        if self.priority > 0 {
            a.priority = Some(set_fifo(thread_native_id(), self.priority));
        }
        if let Some(cpu) = self.cpu {
            let mut set = CpuSet::new();
            a.cpu = Some(
                set.set(cpu)
                    .and_then(|()| sched_setaffinity(Pid::from_raw(0), &set))
                    .map(|()| cpu)
                    .map_err(|e| format!("pinning to CPU {cpu} refused: {e}")),
            );
        }
        if self.lock_memory {
            a.locked = Some(
                mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE)
                    .map_err(|e| format!("locking memory refused ({e}): {FIX_MEMLOCK}")),
            );
        }
        prefault_stack();
        a
    }

    /// Give the sensor's reader thread (`thread`, its pthread) its priority. `None` when none is set.
    pub fn apply_to_sensor_thread(
        &self,
        thread: std::os::unix::thread::RawPthread,
    ) -> Option<Result<u8, String>> {
        (self.sensor_priority > 0).then(|| set_fifo(thread, self.sensor_priority))
    }
}

fn set_fifo(thread: std::os::unix::thread::RawPthread, priority: u8) -> Result<u8, String> {
    let value = ThreadPriorityValue::try_from(priority)
        .map_err(|e| format!("SCHED_FIFO priority {priority}: {e}"))?;
    set_thread_priority_and_policy(
        thread,
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map(|()| priority)
    .map_err(|e| format!("SCHED_FIFO {priority} refused ({e}): {FIX_RTPRIO}"))
}

/// Touch [`STACK_PREFAULT`] bytes of the stack so its pages are mapped before the first cycle.
#[inline(never)]
fn prefault_stack() {
    let mut buf = [0u8; STACK_PREFAULT];
    for i in (0..buf.len()).step_by(4096) {
        buf[i] = 1;
    }
    std::hint::black_box(&mut buf);
}

/// What the settings got: each `None` when not asked for, else granted or refused with the fix.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Applied {
    /// The cycle's `SCHED_FIFO` priority.
    pub priority: Option<Result<u8, String>>,
    /// The sensor reader's `SCHED_FIFO` priority.
    pub sensor_priority: Option<Result<u8, String>>,
    /// The CPU the cycle is pinned to.
    pub cpu: Option<Result<usize, String>>,
    /// Memory locked.
    pub locked: Option<Result<(), String>>,
}

impl Applied {
    /// Every refusal, one line each with its fix.
    pub fn refusals(&self) -> Vec<&str> {
        [
            self.priority.as_ref().and_then(|r| r.as_ref().err()),
            self.sensor_priority.as_ref().and_then(|r| r.as_ref().err()),
            self.cpu.as_ref().and_then(|r| r.as_ref().err()),
            self.locked.as_ref().and_then(|r| r.as_ref().err()),
        ]
        .into_iter()
        .flatten()
        .map(String::as_str)
        .collect()
    }
}

impl fmt::Display for Applied {
    /// One line: what the cycle runs with.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (policy, _) = current_policy();
        write!(f, "real-time: cycle thread {policy}")?;
        match &self.sensor_priority {
            Some(Ok(p)) => write!(f, ", sensor reader SCHED_FIFO {p}")?,
            Some(Err(_)) => write!(f, ", sensor reader refused")?,
            None => {}
        }
        match &self.cpu {
            Some(Ok(c)) => write!(f, ", on CPU {c}")?,
            Some(Err(_)) => write!(f, ", not pinned (refused)")?,
            None => write!(f, ", not pinned")?,
        }
        match &self.locked {
            Some(Ok(())) => write!(f, ", memory locked ({} kB)", vm_locked_kb().unwrap_or(0)),
            Some(Err(_)) => write!(f, ", memory not locked (refused)"),
            None => write!(f, ", memory not locked"),
        }
    }
}

/// The calling thread's scheduling policy as the kernel reports it (`SCHED_FIFO 80`,
/// `SCHED_OTHER`), and its priority.
pub fn current_policy() -> (String, i32) {
    match thread_schedule_policy_param(thread_native_id()) {
        Ok((ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo), p)) => {
            (format!("SCHED_FIFO {}", p.sched_priority), p.sched_priority)
        }
        Ok((ThreadSchedulePolicy::Realtime(r), p)) => {
            (format!("{r:?} {}", p.sched_priority), p.sched_priority)
        }
        Ok((ThreadSchedulePolicy::Normal(n), _)) => (format!("SCHED_{n:?}").to_uppercase(), 0),
        Err(e) => (format!("unknown ({e})"), 0),
    }
}

/// The process's locked memory, kB (`VmLck` of `/proc/self/status`).
pub fn vm_locked_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmLck:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

/// The CPUs the calling thread may run on.
pub fn allowed_cpus() -> Vec<usize> {
    match sched_getaffinity(Pid::from_raw(0)) {
        Ok(set) => (0..CpuSet::count())
            .filter(|&c| set.is_set(c).unwrap_or(false))
            .collect(),
        Err(_) => Vec::new(),
    }
}

fn list(cpus: &[usize]) -> String {
    let v: Vec<String> = cpus.iter().map(usize::to_string).collect();
    if v.is_empty() {
        "none known".into()
    } else {
        format!("CPUs {}", v.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_are_refused_with_their_reason() {
        let bad = |r: Realtime| r.validate().unwrap_err();
        let e = bad(Realtime {
            priority: 99,
            ..Realtime::default()
        });
        assert!(e.contains("at most 98"), "{e}");
        let e = bad(Realtime {
            sensor_priority: 80,
            ..Realtime::default()
        });
        assert!(e.contains("below the cycle's"), "{e}");
        let e = bad(Realtime {
            cpu: Some(100_000),
            ..Realtime::default()
        });
        assert!(e.contains("not a CPU this process may run on"), "{e}");
        Realtime::default().validate().unwrap();
        Realtime::OFF.validate().unwrap();
    }

    /// Applied on a thread of its own, read back from the kernel: what was granted is in effect,
    /// what was refused says how to fix it and left the thread as it was.
    #[test]
    fn the_settings_are_in_effect_or_refused_with_the_fix() {
        let cpu = *allowed_cpus().last().expect("some CPU");
        let want = Realtime {
            priority: 10,
            sensor_priority: 5,
            cpu: Some(cpu),
            lock_memory: true,
        };
        let (applied, policy, cpus, locked) = std::thread::spawn(move || {
            let a = want.apply_to_cycle_thread();
            (a, current_policy(), allowed_cpus(), vm_locked_kb())
        })
        .join()
        .unwrap();
        match &applied.priority {
            Some(Ok(10)) => assert_eq!(policy, ("SCHED_FIFO 10".to_string(), 10)),
            Some(Err(e)) => {
                assert!(e.contains("rtprio") && e.contains("CAP_SYS_NICE"), "{e}");
                assert_eq!(policy.1, 0, "refused: still {}", policy.0);
            }
            other => panic!("{other:?}"),
        }
        match &applied.cpu {
            Some(Ok(c)) => assert_eq!(cpus, [*c]),
            other => panic!("pinning within the allowed set: {other:?}"),
        }
        match &applied.locked {
            Some(Ok(())) => assert!(locked.unwrap() > 0, "VmLck {locked:?}"),
            Some(Err(e)) => assert!(e.contains("memlock"), "{e}"),
            None => panic!("asked for"),
        }
        let line = applied.to_string();
        assert!(line.starts_with("real-time: cycle thread SCHED_"), "{line}");
        // The memory lock is the process's: undo it for the other tests.
        let _ = nix::sys::mman::munlockall();
    }

    /// Without the privilege — as `nobody` (through `setpriv`, when the tests run as root), with no
    /// rtprio or memlock limit — the priority and the memory lock are refused, each with its fix,
    /// and the thread stays `SCHED_OTHER`; pinning within the allowed CPUs needs no privilege.
    #[test]
    fn without_the_privilege_the_settings_are_refused_with_their_fix() {
        let exe = std::env::current_exe().unwrap();
        let mut cmd = if nix::unistd::geteuid().is_root() {
            let mut c = std::process::Command::new("setpriv");
            c.args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"]);
            c.arg(&exe);
            c
        } else {
            std::process::Command::new(&exe)
        };
        let out = cmd
            .args([
                "--ignored",
                "--exact",
                "rt::tests::unprivileged_probe",
                "--nocapture",
            ])
            // No rtprio and no locked memory beyond the default.
            .env("FORCECELL_RT_PROBE", "1")
            .output()
            .expect("setpriv (util-linux) runs the probe as nobody");
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.status.success(), "{text}");
        assert!(text.contains("1 passed"), "the probe ran: {text}");
    }

    /// The unprivileged half of the test above (run by it, as `nobody`).
    #[test]
    #[ignore = "run by without_the_privilege_the_settings_are_refused_with_their_fix"]
    fn unprivileged_probe() {
        assert!(
            std::env::var_os("FORCECELL_RT_PROBE").is_some(),
            "run through without_the_privilege_the_settings_are_refused_with_their_fix"
        );
        // A user without rtprio may still have a limit: only a zero limit is refused.
        let rtprio = nix::sys::resource::getrlimit(nix::sys::resource::Resource::RLIMIT_RTPRIO)
            .map(|(soft, _)| soft)
            .unwrap_or(0);
        let want = Realtime {
            priority: 10,
            sensor_priority: 5,
            cpu: allowed_cpus().first().copied(),
            lock_memory: true,
        };
        let (a, policy) = std::thread::spawn(move || {
            let a = want.apply_to_cycle_thread();
            (a, current_policy())
        })
        .join()
        .unwrap();
        if rtprio == 0 {
            let e = a.priority.clone().unwrap().unwrap_err();
            assert!(e.contains("rtprio") && e.contains("CAP_SYS_NICE"), "{e}");
            assert_eq!(policy.0, "SCHED_OTHER");
        }
        assert!(matches!(a.cpu, Some(Ok(_))), "{:?}", a.cpu);
        if let Some(Err(e)) = &a.locked {
            assert!(e.contains("memlock"), "{e}");
        }
        assert!(!a.refusals().is_empty() || rtprio > 0, "{a:?}");
        println!("{a}");
        for r in a.refusals() {
            println!("refused: {r}");
        }
    }
}
