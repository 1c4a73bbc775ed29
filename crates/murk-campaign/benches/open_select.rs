//! Opening a campaign and applying its rules, on campaigns the size of the
//! seed's winter 2022-2023 database (2 723 recordings) and ten times that.
//! The folders are written before timing; point files are empty because
//! this crate never reads them.

use std::hint::black_box;
use std::path::Path;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use murk_campaign::Campaign;

const HEADER: &str = "recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),WXT530_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),PWD12_Temperature (°C),wind (m/s),humidity (%)";

/// Writes a campaign of `n` recordings whose weather cycles through every
/// class, with some outages, and a review keeping every third recording.
fn write_campaign(dir: &Path, n: usize) {
    std::fs::write(
        dir.join("campaign.toml"),
        "name = \"bench\"\nrules = \"pdd-2022-2023\"\n[lidar]\nmodel = \"VLP16\"\n\
         elevation_deg = [-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0]\n",
    )
    .unwrap();
    let rows = [
        "Clear,0,0,2500,2400",
        "Fog,0,0,120,150",
        "Rain,1.2,0.8,600,700",
        "Snow,0,0,300,320",
        "Fog,0,,120,150",
        "Unknown,0,0,900,900",
    ];
    let mut weather = format!("{HEADER}\n");
    let mut review = String::from("recording,keep,reason\n");
    std::fs::create_dir_all(dir.join("lidar")).unwrap();
    for i in 0..n {
        let id = format!("r{i:06}");
        weather.push_str(&format!(
            "{id},2023-01-01T00:00:00Z,{},{},{},{}\n",
            rows[i % rows.len()],
            (i % 17) as f64 - 8.0,
            (i % 11) as f64 * 0.5,
            if i % 5 == 0 {
                "wet".to_string()
            } else {
                format!("{}", 50 + i % 50)
            }
        ));
        review.push_str(&format!("{id},{},\n", i % 3 == 0));
        std::fs::write(dir.join("lidar").join(format!("{id}.pcd")), "").unwrap();
    }
    std::fs::write(dir.join("weather.csv"), weather).unwrap();
    std::fs::write(dir.join("review.csv"), review).unwrap();
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("campaign");
    group.sample_size(20);
    for n in [2_723usize, 27_230] {
        let dir = tempfile::tempdir().unwrap();
        write_campaign(dir.path(), n);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::new("open", n), dir.path(), |b, d| {
            b.iter(|| black_box(Campaign::open(d).unwrap()))
        });
        let campaign = Campaign::open(dir.path()).unwrap();
        group.bench_with_input(BenchmarkId::new("select", n), &campaign, |b, c| {
            b.iter(|| black_box(c.select()))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
