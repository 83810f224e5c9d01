//! The ATI driver against the simulated node on the in-memory bus (virtual clock: deterministic, no
//! wall time). The same scenarios run on a real vcan interface in `ati_vcan.rs`.

mod ati_common;

use ati_can::{CanTransport, Config, MemBus};
use ati_common::*;
use sim::ati_node::NodeConfig;

struct Mem;

impl Bus for Mem {
    fn config(&self) -> Config {
        Config::default()
    }

    fn rig(&self, cfg: Config, mut node_cfg: NodeConfig) -> Rig {
        node_cfg.base = cfg.base;
        let bus = MemBus::with_virtual_clock();
        let source = Source::new();
        let node = make_node(node_cfg, &source);
        bus.attach(node.clone());
        let port: Box<dyn CanTransport + Send> = Box::new(bus.port());
        let injector: Box<dyn CanTransport + Send> = Box::new(bus.port());
        let raiser = bus.clone();
        Rig {
            driver: ati_can::Driver::new(port, cfg).expect("driver"),
            node,
            source,
            injector,
            raise: Some(Box::new(move |e| raiser.raise_error(e))),
            settle: || {},
            keep: Vec::new(),
        }
    }
}

#[test]
fn startup_reads_identity_and_calibration() {
    ati_common::startup_reads_identity_and_calibration(&Mem);
}

#[test]
fn samples_pair_with_their_requests() {
    ati_common::samples_pair_with_their_requests(&Mem);
}

#[test]
fn answer_faults_are_counted_and_never_give_a_sample() {
    ati_common::answer_faults_are_counted_and_never_give_a_sample(&Mem);
}

#[test]
fn extra_frames_never_disturb_pairing() {
    ati_common::extra_frames_never_disturb_pairing(&Mem);
}

#[test]
fn timeouts_enter_and_leave_the_timeout_state_with_hysteresis() {
    ati_common::timeouts_enter_and_leave_the_timeout_state_with_hysteresis(&Mem);
}

#[test]
fn critical_status_withholds_samples_until_it_clears() {
    ati_common::critical_status_withholds_samples_until_it_clears(&Mem);
}

#[test]
fn saturation_is_detected_on_raw_counts() {
    ati_common::saturation_is_detected_on_raw_counts(&Mem);
}

#[test]
fn watchdog_reset_runs_start_up_again() {
    ati_common::watchdog_reset_runs_start_up_again(&Mem);
}

#[test]
fn old_firmware_falls_back_to_legacy_counts() {
    ati_common::old_firmware_falls_back_to_legacy_counts(&Mem);
}

#[test]
fn start_up_refuses_a_wrong_slot_echo_and_a_silent_board() {
    ati_common::start_up_refuses_a_wrong_slot_echo_and_a_silent_board(&Mem);
}

#[test]
fn corrupted_matrix_rows_are_asked_again() {
    ati_common::corrupted_matrix_rows_are_asked_again(&Mem);
}

#[test]
fn bias_is_averaged_on_raw_gauges_and_refused_when_unsafe() {
    ati_common::bias_is_averaged_on_raw_gauges_and_refused_when_unsafe(&Mem);
}

#[test]
fn bus_off_stops_polling_until_restart() {
    ati_common::bus_off_stops_polling_until_restart(&Mem);
}
