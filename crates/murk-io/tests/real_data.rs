//! The real sample files in `../shared/data/real/` beside the checkout,
//! when present. Each test prints a line and passes when its file is absent
//! (fails with `MURK_REQUIRE_REAL_DATA=1`: see `murk_types::real_data`).

use murk_io::{ReadOptions, read_cloud, read_frames};
use murk_types::IntensityScale;

/// The path of a sample file, or `None` (with a note) when it is absent.
fn sample(name: &str) -> Option<std::path::PathBuf> {
    murk_types::real_data::real_data_file(env!("CARGO_MANIFEST_DIR"), name)
}

#[test]
fn kitti_000008_reads_with_kitti_scale_and_plausible_values() {
    let Some(p) = sample("kitti-000008.bin") else {
        return;
    };
    let c = read_cloud(&p, &ReadOptions::default()).unwrap();
    let size = std::fs::metadata(&p).unwrap().len() as usize;
    assert_eq!(c.len(), size / 16);
    println!("kitti-000008.bin: {} points", c.len());
    assert_eq!(c.intensity_scale, IntensityScale::KITTI);
    // KITTI stores intensity in 0..=1 and the HDL-64E sees to ~120 m.
    assert!(c.intensity.iter().all(|v| (0.0..=1.0).contains(v)));
    let max_range = (0..c.len()).map(|i| c.range(i)).fold(0f32, f32::max);
    assert!(
        max_range > 20.0 && max_range < 130.0,
        "max range {max_range}"
    );
    // Rings derived with the VLP-16 spec stay within its 16 ids.
    assert!(c.ring.iter().all(|&r| r < 16));
}

#[test]
fn nuscenes_lidar_top_reads_with_rings_0_to_31() {
    let Some(p) = sample("nuscenes-lidar-top.pcd.bin") else {
        return;
    };
    let c = read_cloud(&p, &ReadOptions::default()).unwrap();
    let size = std::fs::metadata(&p).unwrap().len() as usize;
    assert_eq!(c.len(), size / 20);
    let (lo, hi) = (
        c.ring.iter().copied().min().unwrap(),
        c.ring.iter().copied().max().unwrap(),
    );
    println!(
        "nuscenes-lidar-top.pcd.bin: {} points, rings {lo}..={hi}",
        c.len()
    );
    assert_eq!((lo, hi), (0, 31));
    // nuScenes intensity is the HDL-32E's 0–255 byte.
    assert!(c.intensity.iter().all(|v| (0.0..=255.0).contains(v)));
}

#[test]
fn vlp16_pcap_reads_as_frames_whose_concatenation_is_the_whole_file() {
    let Some(p) = sample("vlp16-test-90deg-1-50-frames.pcap") else {
        return;
    };
    let frames = match read_frames(&p, &ReadOptions::default()) {
        Ok(f) => f,
        Err(e) => panic!("{e}"),
    };
    let all = read_cloud(&p, &ReadOptions::default()).unwrap();
    let total: usize = frames.iter().map(|f| f.len()).sum();
    println!("{}: {} frames, {} points", p.display(), frames.len(), total);
    assert!(frames.len() > 1);
    assert_eq!(all.len(), total);
    assert!(all.ring.iter().all(|&r| r < 16));
}
