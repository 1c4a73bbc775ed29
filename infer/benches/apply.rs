//! Throughput of the applier: in memory (mask only, mask + compaction, with
//! near-range returns) and file to file (KITTI `.bin`, CSV).
//!
//! Data is built outside the timed code from fixed seeds. Run with
//! `cargo bench -p murk-infer`; `RAYON_NUM_THREADS` picks the core count.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use murk_infer::batch::{plan, run};
use murk_infer::{ApplyParams, BatchOptions, CoefficientTable, PointCloud, Severity};
use murk_types::{IntensityScale, PointFormat, WeatherClass};

/// The seed's fog and rain slopes (Table 4) and fog ghost/ring laws (Table 5).
fn table() -> CoefficientTable {
    CoefficientTable::from_json(
        r#"{
  "format": "weather-noise-coefficients/1", "campaign": "bench",
  "lidar": { "model": "VLP16", "range_scale": 1.0 },
  "weathers": { "fog": {
    "recordings": 28, "quantile": 0.99, "no_change_rate": 0.38,
    "vanishing_slope": [
      { "reflectivity_min": 0,  "reflectivity_max": 10,   "slope": 0.30286536, "points": 1 },
      { "reflectivity_min": 10, "reflectivity_max": null, "slope": 0.34634364, "points": 1 } ],
    "ghost": { "distance_m": { "mean": 5.011, "std": 1.753, "lower": 3, "upper": 10 },
               "reflectivity": { "mean": 4.113, "std": 11.533, "lower": 0 }, "points_per_scan": 41 },
    "ring":  { "distance_m": { "mean": 1.308, "std": 0.172, "lower": 0.5, "upper": 3 },
               "reflectivity": { "mean": 1.461, "std": 3.055, "lower": 0 }, "points_per_scan": 12 } } },
  "provenance": { "tool": "bench", "inputs_sha256": "", "parameters": {} }
}"#,
    )
    .expect("bench table")
}

/// A VLP-16-like scan of `n` points (xorshift, fixed seed): ranges
/// 0.5–100 m, reflectivity 0–255, 16 rings.
fn scan(n: usize, seed: u64) -> PointCloud {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = || {
        s ^= s >> 12;
        s ^= s << 25;
        s ^= s >> 27;
        (s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut c = PointCloud::with_capacity(n);
    for i in 0..n {
        let r = 0.5 + 99.5 * next();
        let az = next() * std::f32::consts::TAU;
        let ring = (i % 16) as u16;
        let el = (-15.0 + 2.0 * ring as f32).to_radians();
        c.push(
            r * el.cos() * az.cos(),
            r * el.cos() * az.sin(),
            r * el.sin(),
            (next() * 255.0).floor(),
            ring,
        );
    }
    c
}

/// One scan of a typical size with near-range returns, without and with a
/// count term along the returns' own range that reshapes the ghost law but
/// keeps its expected count (×1.2 below 5 m, ×0.85 beyond: mean 1.00 under
/// the ghost law; the ring law, all below 5 m, gets ×1.2). Any extension
/// term sends a scan through the extended path, which computes each point's
/// range for the survival law (the plain hard-threshold path compares
/// squared ranges): that is most of the difference. Measured (release,
/// 2 cores): 1.0 ms without terms, 4.9 ms with the term, of which `perf`
/// puts under 0.5 % in the range term's own tables (1,024 cells per kind
/// per scan) and a third in `hypot`.
fn near_range_terms(c: &mut Criterion) {
    let plain = table();
    let mut terms = plain.clone();
    let count = |covariate: &str, edge: f64, values: [f64; 2]| murk_types::ModelExtension {
        observable: murk_types::ExtensionObservable::Count,
        covariate: covariate.into(),
        function: murk_types::ExtensionFunction::Bins {
            edges: vec![edge],
            values: values.to_vec(),
        },
        default: 1.0,
        description: String::new(),
    };
    terms
        .weathers
        .get_mut(&WeatherClass::Fog)
        .expect("fog")
        .extensions = vec![count("range", 5.0, [1.2, 0.85])];
    let build = |t: &CoefficientTable| {
        ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
            .near_range(true)
            .lidar(murk_types::LidarSpec::vlp16())
            .build(t)
            .unwrap()
    };
    let (without, with) = (build(&plain), build(&terms));
    let n = 120_000;
    let cloud = scan(n, 2);
    let mut g = c.benchmark_group("near_range_terms");
    g.sample_size(30);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_with_input(BenchmarkId::new("without_terms", n), &cloud, |b, cl| {
        b.iter(|| black_box(without.apply(cl, "bench").unwrap()))
    });
    g.bench_with_input(BenchmarkId::new("range_term", n), &cloud, |b, cl| {
        b.iter(|| black_box(with.apply(cl, "bench").unwrap()))
    });
    g.finish();
}

fn in_memory(c: &mut Criterion) {
    let t = table();
    let vanish = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .build(&t)
        .unwrap();
    let near = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .near_range(true)
        .lidar(murk_types::LidarSpec::vlp16())
        .build(&t)
        .unwrap();
    let mut g = c.benchmark_group("in_memory");
    g.sample_size(20);
    for n in [1_000_000usize, 10_000_000] {
        let cloud = scan(n, 1);
        g.throughput(Throughput::Elements(n as u64));
        let mut mask = Vec::with_capacity(n);
        g.bench_with_input(BenchmarkId::new("mask_only", n), &cloud, |b, cl| {
            b.iter(|| black_box(vanish.mask(cl, "bench", &mut mask).unwrap()))
        });
        g.bench_with_input(BenchmarkId::new("mask_and_compact", n), &cloud, |b, cl| {
            b.iter(|| black_box(vanish.apply(cl, "bench").unwrap()))
        });
        g.bench_with_input(BenchmarkId::new("with_near_range", n), &cloud, |b, cl| {
            b.iter(|| black_box(near.apply(cl, "bench").unwrap()))
        });
        let mut kitti = cloud.clone();
        kitti.to_scale(IntensityScale::KITTI);
        g.bench_with_input(
            BenchmarkId::new("mask_only_kitti_scale", n),
            &kitti,
            |b, cl| b.iter(|| black_box(vanish.mask(cl, "bench", &mut mask).unwrap())),
        );
    }
    g.finish();
}

/// Writes `files` scans of `n` points in `format` to a temporary folder.
fn corpus(format: PointFormat, files: usize, n: usize) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in");
    std::fs::create_dir_all(&input).unwrap();
    for f in 0..files {
        let mut cl = scan(n, 100 + f as u64);
        if format == PointFormat::KittiBin {
            cl.to_scale(IntensityScale::KITTI);
        }
        let name = format!("{f:06}.{}", format.extension());
        murk_io::write_cloud(&input.join(name), &cl, format).unwrap();
    }
    (dir, input)
}

fn file_to_file(c: &mut Criterion) {
    let t = table();
    let a = ApplyParams::new(WeatherClass::Fog, Severity::Mor(60.0))
        .build(&t)
        .unwrap();
    let mut g = c.benchmark_group("file_to_file");
    g.sample_size(10);
    for (format, files, n) in [
        (PointFormat::KittiBin, 16usize, 1_000_000usize),
        (PointFormat::NuscenesBin, 16, 1_000_000),
        (PointFormat::Csv, 8, 250_000),
    ] {
        let (dir, input) = corpus(format, files, n);
        let out = dir.path().join("out");
        let opts = BatchOptions::default();
        let p = plan(&[input], &out, &opts).unwrap();
        g.throughput(Throughput::Elements((files * n) as u64));
        g.bench_function(BenchmarkId::new(format.extension(), files * n), |b| {
            b.iter(|| black_box(run(&a, &p, &opts, &|_| {}).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, in_memory, near_range_terms, file_to_file);
criterion_main!(benches);
