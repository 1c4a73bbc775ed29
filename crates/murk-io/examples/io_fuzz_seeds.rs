//! Writes the seed corpus of the fuzz targets (`crates/murk-io/fuzz/seeds/`).
//!
//! ```sh
//! cargo run -p murk-io --example io_fuzz_seeds -- crates/murk-io/fuzz/seeds
//! ```
//!
//! Each seed is one options byte (see `fuzz/fuzz_targets/common/mod.rs`)
//! followed by a small valid file, so the fuzzer starts from inputs that
//! reach the decoders instead of stopping at the header.

use std::path::{Path, PathBuf};

use murk_io::{PcdData, WriteOptions, encode_cloud};
use murk_types::{PointCloud, PointFormat};

/// A 6-point scan on three VLP-16 rings, with or without time.
fn scan(timed: bool) -> PointCloud {
    let mut c = PointCloud::with_capacity(6);
    let pts: [(f32, f32, f32, f32, u16); 6] = [
        (10.0, 0.0, -2.68, 12.0, 0),
        (0.0, 8.0, 0.14, 101.0, 1),
        (-5.5, 1.25, 0.0, 0.0, 1),
        (3.0, -3.0, 0.78, 255.0, 3),
        (20.0, 20.0, 7.6, 7.5, 15),
        (1.0, 0.5, -0.3, 42.0, 0),
    ];
    for (i, (x, y, z, v, r)) in pts.into_iter().enumerate() {
        if timed {
            c.push_timed(x, y, z, v, r, i as f32 * 5.5e-5);
        } else {
            c.push(x, y, z, v, r);
        }
    }
    c
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: io_fuzz_seeds OUT_DIR (e.g. crates/murk-io/fuzz/seeds)")?,
    );
    let here = Path::new("seed");
    let mut seeds: Vec<(&str, String, Vec<u8>)> = Vec::new();
    for (timed, t) in [(false, "plain"), (true, "timed")] {
        for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            let opts = WriteOptions {
                format: PointFormat::Pcd,
                pcd_data: data,
            };
            seeds.push((
                "pcd",
                format!("{data}-{t}"),
                encode_cloud(&scan(timed), &opts, here)?,
            ));
        }
        seeds.push((
            "csv",
            t.to_string(),
            encode_cloud(&scan(timed), &WriteOptions::new(PointFormat::Csv), here)?,
        ));
    }
    // A PCD without ring, with padding and an unknown field, in PCL's layout.
    let header = "VERSION 0.7\nFIELDS x y z _ intensity return_type\nSIZE 4 4 4 1 2 1\n\
                  TYPE F F F U U U\nCOUNT 1 1 1 3 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n";
    let mut b = header.as_bytes().to_vec();
    for (x, y, z, v) in [(1.0f32, 2.0f32, 0.5f32, 7u16), (-4.0, 0.25, -1.0, 300)] {
        b.extend(x.to_le_bytes());
        b.extend(y.to_le_bytes());
        b.extend(z.to_le_bytes());
        b.extend([0, 0, 0]);
        b.extend(v.to_le_bytes());
        b.push(1);
    }
    seeds.push(("pcd", "noring-padded".into(), b));
    seeds.push((
        "csv",
        "veloview".into(),
        b"\"Points_m_XYZ:0\",\"Points_m_XYZ:1\",\"Points_m_XYZ:2\",\"intensity\",\"laser_id\",\"azimuth\"\n\
          1.5,-2.25,0.125,17,14,9001\n3.9,-0.01,0.07,12,1,35978\n"
            .to_vec(),
    ));
    seeds.push((
        "kitti_bin",
        "scan".into(),
        encode_cloud(
            &scan(false),
            &WriteOptions::new(PointFormat::KittiBin),
            here,
        )?,
    ));
    seeds.push((
        "nuscenes_bin",
        "scan".into(),
        encode_cloud(
            &scan(false),
            &WriteOptions::new(PointFormat::NuscenesBin),
            here,
        )?,
    ));
    for (target, name, bytes) in seeds {
        let dir = root.join(target);
        std::fs::create_dir_all(&dir)?;
        // Options byte 0 (VLP-16 rings, format scale) and 2 (40-ring sensor).
        for opt in [0u8, 2] {
            let mut seed = vec![opt];
            seed.extend(&bytes);
            std::fs::write(dir.join(format!("seed-{name}-{opt}")), seed)?;
        }
    }
    Ok(())
}
