//! Per-sample cost of the codec and the conversion (`cargo bench -p forcecell-ati-can`).
//! The poll rate and sample age of the whole driver are measured in `sim/benches/ati_poll.rs`.

use ati_can::codec::interleave;
use ati_can::{Answer, Base, Calibration, Converter, ForceUnit, Frame, Request, TorqueUnit};
use divan::black_box;

fn main() {
    divan::main();
}

fn converter() -> Converter {
    let mut matrix = [[0.0f32; 6]; 6];
    for (i, row) in matrix.iter_mut().enumerate() {
        for (j, c) in row.iter_mut().enumerate() {
            *c = if i == j {
                10_000.0
            } else {
                12.5 * (i + j) as f32
            };
        }
    }
    Calibration {
        matrix,
        counts_per_force: 1_000_000,
        counts_per_torque: 1_000_000,
        force_unit: ForceUnit::N,
        torque_unit: TorqueUnit::Nm,
    }
    .converter()
    .unwrap()
}

/// Both poll frames → status check, saturation check, wrench in SI.
#[divan::bench]
fn decode_and_convert_one_sample(b: divan::Bencher) {
    let conv = converter();
    let f0 = Frame::standard(0x200, &[0x00, 0x00, 0x01, 0xF4, 0xFF, 0x9C, 0x00, 0x00]).unwrap();
    let f1 = Frame::standard(0x201, &[0x00, 0xFA, 0x7F, 0x00, 0x00, 0x0A]).unwrap();
    let bias = [3.0; 6];
    b.bench(|| {
        let (Ok(Answer::PollFirst { status, gauges: a }), Ok(Answer::PollSecond { gauges: g })) = (
            Answer::decode(black_box(&f0), Base::DEFAULT),
            Answer::decode(black_box(&f1), Base::DEFAULT),
        ) else {
            unreachable!()
        };
        let g = interleave(a, g);
        black_box((status.is_critical(), g.is_saturated()));
        conv.wrench(&g, &bias)
    });
}

/// Just the conversion.
#[divan::bench]
fn convert_only(b: divan::Bencher) {
    let conv = converter();
    let g = ati_can::Gauges([500, 250, -100, 1200, 0, 10]);
    let bias = [3.0; 6];
    b.bench(|| conv.wrench(black_box(&g), &bias));
}

/// Encoding the poll request.
#[divan::bench]
fn encode_poll_request() -> Frame {
    Request::Poll.encode(black_box(Base::DEFAULT)).unwrap()
}
