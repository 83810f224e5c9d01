//! The per-sample hot path — decode both poll frames, reassemble the gauges, check saturation, convert
//! to SI — allocates nothing (counted by `stats_alloc`'s global allocator).

use std::alloc::System;

use ati_can::codec::interleave;
use ati_can::{Answer, Base, Calibration, ForceUnit, Frame, TorqueUnit};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn decode_and_convert_do_not_allocate() {
    let mut matrix = [[0.0f32; 6]; 6];
    for (i, row) in matrix.iter_mut().enumerate() {
        row[i] = 1000.0;
    }
    let conv = Calibration {
        matrix,
        counts_per_force: 1_000_000,
        counts_per_torque: 1_000_000,
        force_unit: ForceUnit::N,
        torque_unit: TorqueUnit::Nm,
    }
    .converter()
    .unwrap();
    let f0 = Frame::standard(0x200, &[0x00, 0x00, 0x01, 0xF4, 0xFF, 0x9C, 0x00, 0x00]).unwrap();
    let f1 = Frame::standard(0x201, &[0x00, 0xFA, 0x7F, 0x00, 0x00, 0x0A]).unwrap();
    let bias = [1.0; 6];
    let mut fz = 0.0;
    let region = Region::new(GLOBAL);
    {
        for _ in 0..1000 {
            let (Ok(Answer::PollFirst { status, gauges: a }), Ok(Answer::PollSecond { gauges: b })) = (
                Answer::decode(&f0, Base::DEFAULT),
                Answer::decode(&f1, Base::DEFAULT),
            ) else {
                panic!("golden frames must decode");
            };
            let g = interleave(a, b);
            assert!(!status.is_critical() && !g.is_saturated());
            fz += conv.wrench(&g, &bias).force.x;
        }
    }
    let change = region.change();
    assert_eq!(change.allocations + change.reallocations, 0, "{change:?}");
    // The work was done: (500 − 1)·1000 / 1e6 N per sample.
    assert!((fz - 499.0).abs() < 1e-9, "{fz}");
}
