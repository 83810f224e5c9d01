//! Codec speed per message, both directions, with allocations counted (`cargo bench -p forcecell-kuka-rsi --bench codec`).

use divan::{AllocProfiler, Bencher, black_box};
use kuka_rsi::{EthernetConfig, Frame, Ipoc, Layout, Schema};

#[global_allocator]
static ALLOC: AllocProfiler = AllocProfiler::system();

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

fn schemas() -> (Schema, Schema) {
    let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false);
    (cfg.rob_schema(4).unwrap(), cfg.sen_schema(4).unwrap())
}

fn rob_frame(rob: &Schema) -> Frame {
    let mut f = Frame::new();
    f.set6(
        rob.six("RIst", POSE).unwrap(),
        [445.1234, -12.5, 890.0001, 179.9, 0.25, -179.5],
    );
    f.set6(
        rob.six("RSol", POSE).unwrap(),
        [445.0, -12.5, 890.0, 180.0, 0.0, 180.0],
    );
    f.set_ipoc(Ipoc::new(123_645_634_563));
    f
}

fn main() {
    divan::main();
}

/// Driver side: parse one `<Rob>` (RIst, RSol, AIPos, ASPos, Delay, IPOC).
#[divan::bench]
fn parse_rob(b: Bencher) {
    let (rob, _) = schemas();
    let mut buf = [0u8; 2048];
    let n = rob.write(&rob_frame(&rob), &mut buf).unwrap();
    let mut f = Frame::new();
    b.bench_local(|| rob.parse(black_box(&buf[..n]), &mut f).unwrap());
}

/// Driver side: the same `<Rob>` through the layout learnt from the previous one (what the session
/// does every cycle once the robot's layout is known).
#[divan::bench]
fn parse_rob_learnt(b: Bencher) {
    let (rob, _) = schemas();
    let mut buf = [0u8; 2048];
    let n = rob.write(&rob_frame(&rob), &mut buf).unwrap();
    let mut f = Frame::new();
    let mut layout = Layout::new(4096);
    layout.parse(&rob, &buf[..n], &mut f).unwrap();
    b.bench_local(|| layout.parse(&rob, black_box(&buf[..n]), &mut f).unwrap());
}

/// Driver side: write one `<Sen>` (RKorr X..C, Stop, IPOC).
#[divan::bench]
fn write_sen(b: Bencher) {
    let (_, sen) = schemas();
    let mut f = Frame::new();
    f.set6(
        sen.six("RKorr", POSE).unwrap(),
        [0.0, 0.0, 0.0123, 0.0, 0.0, 0.0],
    );
    f.set_ipoc(Ipoc::new(123_645_634_563));
    let mut buf = [0u8; 1024];
    b.bench_local(|| sen.write(black_box(&f), &mut buf).unwrap());
}

/// Simulator side: write one `<Rob>`.
#[divan::bench]
fn write_rob(b: Bencher) {
    let (rob, _) = schemas();
    let f = rob_frame(&rob);
    let mut buf = [0u8; 2048];
    b.bench_local(|| rob.write(black_box(&f), &mut buf).unwrap());
}

/// Simulator side: parse one `<Sen>`.
#[divan::bench]
fn parse_sen(b: Bencher) {
    let (_, sen) = schemas();
    let text = br#"<Sen Type="ImFree"><RKorr X="0.0000" Y="0.0000" Z="0.0120" A="0.0000" B="0.0000" C="0.0000"/><Stop>0</Stop><IPOC>123645634563</IPOC></Sen>"#;
    let mut f = Frame::new();
    b.bench_local(|| sen.parse(black_box(text), &mut f).unwrap());
}
