//! Helpers shared by the integration tests: a deterministic synthetic scan
//! and small file utilities.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use murk_types::{LidarSpec, PointCloud};

/// A deterministic scan of `n` points lying on the VLP-16 rings (so a ring
/// derived from elevation gives back the stored ring), ranges 2–80 m,
/// fractional intensities 0–255 and, when `timed`, increasing times.
pub fn synthetic(n: usize, timed: bool) -> PointCloud {
    let elevations = LidarSpec::vlp16().elevation_deg;
    let mut c = PointCloud::with_capacity(n);
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..n {
        let ring = (i % 16) as u16;
        let el = elevations[ring as usize].to_radians();
        let az = next() * std::f64::consts::TAU;
        let r = 2.0 + 78.0 * next();
        let x = (r * el.cos() * az.cos()) as f32;
        let y = (r * el.cos() * az.sin()) as f32;
        let z = (r * el.sin()) as f32;
        let intensity = (next() * 255.0) as f32;
        if timed {
            c.push_timed(x, y, z, intensity, ring, i as f32 * 1.5e-5);
        } else {
            c.push(x, y, z, intensity, ring);
        }
    }
    c
}

/// Writes `bytes` to `dir/name` and returns the path.
pub fn file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Little-endian bytes of a list of f32.
pub fn f32s(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Asserts that two clouds hold the same points (columns compared exactly,
/// scale not compared).
pub fn same_points(a: &PointCloud, b: &PointCloud) {
    assert_eq!(a.len(), b.len(), "point count");
    assert_eq!(a.x, b.x, "x");
    assert_eq!(a.y, b.y, "y");
    assert_eq!(a.z, b.z, "z");
    assert_eq!(a.intensity, b.intensity, "intensity");
    assert_eq!(a.ring, b.ring, "ring");
}
