//! The application's tare (`sensor ati tare`, `sensor ati read --tare`, `run`'s start-up bias) against
//! the simulated node on the in-memory bus: a window that missed one poll is taken again, a bus that
//! keeps missing gives up after `TARE_WINDOWS` windows and says so, and a moving tool is refused at
//! once, never retried into a bias.

use std::time::Duration;

use ati_can::{Base, Config, Driver, Frame, MemBus};
use forcecell::ati::{TARE_WINDOWS, bias_config, first_sample, tare};
use hal::Wrench;
use sim::ati_node::{AtiNode, NodeConfig, SharedNode};

/// The node, with no answer to the polls `drop(n)` picks (counted from 1).
struct DropPolls<F: FnMut(u32) -> bool + Send> {
    node: SharedNode,
    polls: u32,
    drop: F,
}

impl<F: FnMut(u32) -> bool + Send> ati_can::Responder for DropPolls<F> {
    fn on_frame(&mut self, frame: &Frame, now: Duration, out: &mut dyn FnMut(Duration, Frame)) {
        if matches!(
            ati_can::Request::decode(frame, Base::DEFAULT),
            Ok(ati_can::Request::Poll)
        ) {
            self.polls += 1;
            if (self.drop)(self.polls) {
                return;
            }
        }
        self.node.on_frame(frame, now, out);
    }
}

/// A started driver with a first sample, talking to a node that reads `wrench(t)`, dropping the
/// polls `drop` picks.
fn rig(
    wrench: impl FnMut(Duration) -> Wrench + Send + 'static,
    drop: impl FnMut(u32) -> bool + Send + 'static,
) -> Driver<ati_can::MemPort> {
    let node = SharedNode::new(AtiNode::new(NodeConfig::default(), wrench).unwrap());
    let bus = MemBus::with_virtual_clock();
    bus.attach(DropPolls {
        node,
        polls: 0,
        drop,
    });
    let mut driver = Driver::new(bus.port(), Config::default()).unwrap();
    driver.start().unwrap();
    first_sample(&mut driver).unwrap();
    driver
}

fn still(_: Duration) -> Wrench {
    Wrench::from_array([1.5, -2.0, 12.5, 0.1, -0.2, 0.03])
}

#[test]
fn a_window_that_missed_a_poll_is_taken_again() {
    // Poll 50 is inside the first window (the first sample took poll 1).
    let mut driver = rig(still, |n| n == 50);
    let bias = tare(&mut driver).expect("the second window has every sample");
    assert_eq!(driver.counters().timeouts, 1);
    // The bias is the still tool's load: the reading after it is zero.
    driver.step().unwrap();
    let w = driver.last_sample().unwrap().wrench.to_array();
    assert!(
        w.iter().all(|v| v.abs() < 0.05),
        "{w:?} after bias {bias:?}"
    );
    // Two windows' worth of polls, not one.
    let polls = driver.counters().requests;
    assert!(polls > u64::from(bias_config().window) + 50, "{polls}");
}

#[test]
fn a_bus_that_keeps_missing_polls_refuses_the_bias_and_says_so() {
    let mut driver = rig(still, |n| n % 50 == 0);
    let e = tare(&mut driver).unwrap_err().to_string();
    assert!(
        e.contains(&format!("each of {TARE_WINDOWS} windows")),
        "{e}"
    );
    assert_eq!(driver.counters().timeouts, u64::from(TARE_WINDOWS));
    assert_eq!(driver.bias(), [0.0; 6], "no bias was taken");
}

#[test]
fn a_moving_tool_is_refused_at_once_not_taken_again() {
    // A load swinging by 20 N (counted in samples: the bus's clock is virtual): far beyond the
    // window's allowed spread.
    let mut n = 0u32;
    let moving = move |_: Duration| {
        n += 1;
        let fz = 20.0 * (f64::from(n) * 0.05).sin();
        Wrench::from_array([0.0, 0.0, fz, 0.0, 0.0, 0.0])
    };
    let mut driver = rig(moving, |_| false);
    let before = driver.counters().requests;
    let e = tare(&mut driver).unwrap_err().to_string();
    assert!(e.contains("hold the tool still"), "{e}");
    let polls = driver.counters().requests - before;
    assert_eq!(polls, u64::from(bias_config().window), "one window only");
}
