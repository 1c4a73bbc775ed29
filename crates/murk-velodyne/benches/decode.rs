//! Decode throughput on a synthetic ~1M-point VLP-16 capture, in points/s.
//!
//! `cargo bench -p murk-velodyne --bench decode`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use murk_velodyne::synth::Sweep;
use murk_velodyne::{PcapOptions, ReturnMode, ReturnSelect, decode_pcap};

fn decode(c: &mut Criterion) {
    let mut group = c.benchmark_group("decode_pcap");
    group.sample_size(20);
    // 2900 single-return packets at 600 rpm: 2900 × 384 channel records, of
    // which the scene leaves about 1/11 without return → ~1.0M points.
    for (name, mode, packets, select) in [
        (
            "strongest",
            ReturnMode::Strongest,
            2900,
            ReturnSelect::AsRecorded,
        ),
        ("dual-both", ReturnMode::Dual, 4300, ReturnSelect::Both),
    ] {
        let bytes = Sweep {
            rpm: 600.0,
            packets,
            mode,
            position_every: 10,
            ..Sweep::default()
        }
        .to_pcap();
        let opts = PcapOptions {
            return_mode: select,
            ..PcapOptions::default()
        };
        let points = decode_pcap(&bytes, &opts)
            .expect("synthetic capture decodes")
            .points();
        eprintln!(
            "{name}: {packets} packets, {points} points, {} MB",
            bytes.len() / 1_000_000
        );
        group.throughput(Throughput::Elements(points as u64));
        group.bench_function(name, |b| {
            b.iter(|| decode_pcap(std::hint::black_box(&bytes), &opts).map(|c| c.points()))
        });
    }
    group.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
