//! Layouts murk must be told about, and what a read reports besides points:
//! header-less CSV (`csv_columns`), five-float `.bin` (`bin_layout`), the
//! refusal to guess a `.bin` whose size fits several layouts, the intensity
//! scale a PCD records, fields a cloud cannot carry, and captures from the
//! field (foreign packets, a cut last packet, partial revolutions).

// Point clouds are columns (SoA): one index addresses several of them.
#![allow(clippy::needless_range_loop)]

mod common;

use std::path::{Path, PathBuf};

use common::{f32s, file, same_points, synthetic};
use murk_io::{
    BinLayout, IoError, ReadOptions, ScaleSource, parse_csv, parse_csv_rows, read_cloud,
    read_cloud_noted, read_frames_noted, write_cloud,
};
use murk_types::{IntensityScale, LidarSpec, PointCloud, PointFormat};
use murk_velodyne::synth::{PcapWriter, Sweep, ethernet_arp, ethernet_udp};

/// `../shared/data/real/NAME` next to the checkout (the workspace root is
/// found by walking up from this crate), or `None` with a printed note.
fn real(name: &str) -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .find(|d| d.join("Cargo.lock").exists())
        .unwrap_or(Path::new(env!("CARGO_MANIFEST_DIR")));
    let p = root.join("../shared/data/real").join(name);
    if p.exists() {
        Some(p)
    } else {
        println!("skipping: {} is not present", p.display());
        None
    }
}

/// `cloud` as header-less `x,y,z,intensity,ring` rows.
fn headerless_csv(cloud: &PointCloud) -> String {
    let mut s = String::new();
    for i in 0..cloud.len() {
        s.push_str(&format!(
            "{},{},{},{},{}\n",
            cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i], cloud.ring[i]
        ));
    }
    s
}

fn columns(names: &str) -> ReadOptions {
    ReadOptions {
        csv_columns: Some(names.split(',').map(str::to_string).collect()),
        ..ReadOptions::default()
    }
}

#[test]
fn a_headerless_csv_reads_with_declared_columns_and_is_refused_without() {
    let cloud = synthetic(300, false);
    let text = headerless_csv(&cloud);
    let p = Path::new("radiate.csv");
    let back = parse_csv(text.as_bytes(), p, &columns("x,y,z,intensity,ring")).unwrap();
    same_points(&back, &cloud);

    // Without columns: the first line is data, and the error says what to do.
    let e = parse_csv(text.as_bytes(), p, &ReadOptions::default()).unwrap_err();
    assert!(matches!(e, IoError::NoHeader { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("radiate.csv") && msg.contains("--columns") && msg.contains("not a header"),
        "{msg}"
    );

    // The declared names come from the sensor description too, and an
    // unread column (a label) is allowed and reported as not carried.
    let labelled: String = text
        .lines()
        .map(|l| format!("{l},car\n"))
        .collect::<String>();
    let mut spec = LidarSpec::vlp16();
    spec.csv_columns = Some(
        ["x", "y", "z", "intensity", "ring", "label"]
            .map(String::from)
            .to_vec(),
    );
    let opts = ReadOptions {
        lidar: Some(spec),
        ..ReadOptions::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let f = file(dir.path(), "l.csv", labelled.as_bytes());
    let (back, notes) = read_cloud_noted(&f, &opts).unwrap();
    same_points(&back, &cloud);
    assert_eq!(notes.dropped_fields, vec!["label".to_string()]);

    // A declared column list without x is refused, naming the field.
    let e = parse_csv(text.as_bytes(), p, &columns("a,y,z,intensity,ring")).unwrap_err();
    assert!(e.to_string().contains("no x"), "{e}");
}

#[test]
fn the_real_radiate_frames_read_with_declared_columns() {
    let Some(p) = real("radiate-fog/000001.csv") else {
        return;
    };
    assert!(matches!(
        read_cloud(&p, &ReadOptions::default()),
        Err(IoError::NoHeader { .. })
    ));
    let c = read_cloud(&p, &columns("x,y,z,intensity,ring")).unwrap();
    let lines = std::fs::read_to_string(&p).unwrap().lines().count();
    assert_eq!(c.len(), lines);
    // The HDL-32E's 32 rings, from the ring column (not from elevation).
    let hi = *c.ring.iter().max().unwrap();
    println!("radiate 000001: {} points, rings 0..={hi}", c.len());
    assert_eq!(hi, 31);
}

/// `n` five-float records `x y z intensity fifth`.
fn five_floats(cloud: &PointCloud, fifth: impl Fn(usize) -> f32) -> Vec<u8> {
    let mut v = Vec::new();
    for i in 0..cloud.len() {
        v.extend_from_slice(&[
            cloud.x[i],
            cloud.y[i],
            cloud.z[i],
            cloud.intensity[i],
            fifth(i),
        ]);
    }
    f32s(&v)
}

#[test]
fn a_five_float_bin_is_read_when_declared_and_refused_when_the_size_cannot_tell() {
    // 8 points: 160 bytes, a multiple of both 16 and 20.
    let cloud = synthetic(8, false);
    let bytes = five_floats(&cloud, |i| f32::from(cloud.ring[i]));
    assert_eq!(bytes.len() % 80, 0);
    let p = Path::new("stf.bin");
    let e = murk_io::parse_kitti(&bytes, p, &ReadOptions::default()).unwrap_err();
    assert!(matches!(e, IoError::AmbiguousLayout { .. }), "{e}");
    let msg = e.to_string();
    for want in ["stf.bin", "160 bytes", "xyzi", "xyzir", "--bin-layout"] {
        assert!(msg.contains(want), "{want} missing in {msg}");
    }

    let opts = ReadOptions {
        bin_layout: Some(BinLayout::Xyzir),
        ..ReadOptions::default()
    };
    let back = murk_io::parse_kitti(&bytes, p, &opts).unwrap();
    same_points(&back, &cloud);
    // Five-float files carry the 8-bit byte convention unless told.
    assert_eq!(back.intensity_scale, IntensityScale::Calibrated);

    // 7 points: 140 bytes, a multiple of 20 only: still two layouts.
    let seven = five_floats(&synthetic(7, false), |i| (i % 16) as f32);
    let e = murk_io::parse_kitti(&seven, p, &ReadOptions::default()).unwrap_err();
    assert!(
        e.to_string().contains("xyzir or xyzit") && e.to_string().contains("140 bytes"),
        "{e}"
    );
}

#[test]
fn a_time_fifth_float_is_refused_undeclared_and_read_as_xyzit() {
    // 20 points: 400 bytes (16 and 20 both divide it); times within 0.1 s.
    let cloud = synthetic(20, false);
    let bytes = five_floats(&cloud, |i| i as f32 * 0.005 + 0.0001);
    let p = Path::new("t.bin");
    let e = murk_io::parse_kitti(&bytes, p, &ReadOptions::default()).unwrap_err();
    assert!(e.to_string().contains("point times"), "{e}");
    let opts = ReadOptions {
        bin_layout: Some(BinLayout::Xyzit),
        ..ReadOptions::default()
    };
    let back = murk_io::parse_kitti(&bytes, p, &opts).unwrap();
    assert_eq!(back.x, cloud.x);
    let t = back.time.unwrap();
    assert_eq!(t[3], 3.0 * 0.005 + 0.0001);
    // No ring column: rings from elevation, which the synthetic points sit on.
    assert_eq!(back.ring, cloud.ring);
}

#[test]
fn kitti_sized_like_a_five_float_file_still_reads_as_kitti() {
    // A KITTI scan of 10 points (160 bytes): read as 20-byte records its
    // fifth floats are x/y/z/intensity of other points, neither ring ids
    // nor one scan's times, so the KITTI default holds.
    let mut cloud = synthetic(10, false);
    for v in &mut cloud.intensity {
        *v /= 255.0;
    }
    let bytes = f32s(
        &(0..10)
            .flat_map(|i| [cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i]])
            .collect::<Vec<_>>(),
    );
    assert_eq!(bytes.len() % 80, 0);
    let back = murk_io::parse_kitti(&bytes, Path::new("k.bin"), &ReadOptions::default()).unwrap();
    assert_eq!(back.intensity_scale, IntensityScale::KITTI);
    assert_eq!(back.x, cloud.x);
    assert_eq!(back.intensity, cloud.intensity);
}

#[test]
fn the_real_kitti_scan_cut_to_a_multiple_of_80_bytes_reads_as_kitti() {
    let Some(p) = real("kitti-000008.bin") else {
        return;
    };
    let bytes = std::fs::read(&p).unwrap();
    let full = murk_io::parse_kitti(&bytes, &p, &ReadOptions::default()).unwrap();
    let n = bytes.len() / 16 / 5 * 5; // whole 80-byte groups
    let cut = &bytes[..n * 16];
    assert_eq!(cut.len() % 20, 0);
    let back = murk_io::parse_kitti(cut, &p, &ReadOptions::default()).unwrap();
    assert_eq!(back.len(), n);
    assert_eq!(back.x[..], full.x[..n]);
    assert_eq!(back.intensity[..], full.intensity[..n]);
}

#[test]
fn a_pcd_records_its_intensity_scale_and_gives_it_back() {
    let dir = tempfile::tempdir().unwrap();
    for scale in [
        IntensityScale::KITTI,
        IntensityScale::SIX_BIT,
        IntensityScale::linear(0.5, 2.0).unwrap(),
    ] {
        let mut cloud = synthetic(50, true);
        cloud.intensity_scale = scale;
        let p = dir.path().join("s.pcd");
        write_cloud(&p, &cloud, PointFormat::Pcd).unwrap();
        let text = std::fs::read(&p).unwrap();
        assert!(
            String::from_utf8_lossy(&text[..200]).contains("# murk: intensity_scale"),
            "no scale comment"
        );
        let (back, notes) = read_cloud_noted(&p, &ReadOptions::default()).unwrap();
        assert_eq!(back.intensity_scale, scale);
        assert_eq!(notes.scale_source, ScaleSource::File);
        assert_eq!(back.intensity, cloud.intensity);
        // A declared scale wins over the file's.
        let opts = ReadOptions {
            intensity_scale: Some(IntensityScale::Calibrated),
            ..ReadOptions::default()
        };
        let (back, notes) = read_cloud_noted(&p, &opts).unwrap();
        assert_eq!(back.intensity_scale, IntensityScale::Calibrated);
        assert_eq!(notes.scale_source, ScaleSource::Declared);
    }
    // Calibrated clouds get no comment: PCL's own files read as before.
    let cloud = synthetic(5, false);
    let p = dir.path().join("c.pcd");
    write_cloud(&p, &cloud, PointFormat::Pcd).unwrap();
    assert!(!String::from_utf8_lossy(&std::fs::read(&p).unwrap()).contains("murk:"));
    let (_, notes) = read_cloud_noted(&p, &ReadOptions::default()).unwrap();
    assert_eq!(notes.scale_source, ScaleSource::Default);

    // A comment murk cannot read is an error naming the line.
    let bad = "# .PCD v0.7\n# murk: intensity_scale furlongs\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3 4\n";
    let e = murk_io::parse_pcd(bad.as_bytes(), Path::new("b.pcd"), &ReadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("b.pcd: line 2") && e.contains("furlongs"), "{e}");
}

#[test]
fn pcd_fields_a_cloud_cannot_carry_are_named() {
    let text = "VERSION 0.7\nFIELDS x y z intensity rgb label _\nSIZE 4 4 4 4 4 4 1\nTYPE F F F F F U U\nCOUNT 1 1 1 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3 4 0.5 7 0\n5 6 7 8 0.25 9 0\n";
    let dir = tempfile::tempdir().unwrap();
    let p = file(dir.path(), "rgb.pcd", text.as_bytes());
    let (cloud, notes) = read_cloud_noted(&p, &ReadOptions::default()).unwrap();
    assert_eq!(cloud.len(), 2);
    assert_eq!(
        notes.dropped_fields,
        vec!["rgb".to_string(), "label".into()]
    );
}

#[test]
fn a_ring_murk_cannot_hold_is_refused_by_every_csv_path() {
    let text = b"x,y,z,intensity,ring\n1,0,0,5,3\n2,0,0,5,70000\n";
    let p = Path::new("r.csv");
    let full = parse_csv(text, p, &ReadOptions::default()).unwrap_err();
    // What `murk apply` uses when it does not need rings: still checked.
    let rows = parse_csv_rows(
        text,
        p,
        &ReadOptions::default(),
        murk_io::CsvNeeds::default(),
    )
    .unwrap_err();
    for e in [&full, &rows] {
        let m = e.to_string();
        assert!(
            m.contains("r.csv") && m.contains("point 1") && m.contains("70000"),
            "{m}"
        );
    }
}

/// A capture of `packets` data packets from `start_deg`, with `extra`
/// frames inserted after data packet `at`.
fn capture(packets: usize, start_deg: f64, at: usize, extra: &[Vec<u8>]) -> Vec<u8> {
    let sweep = Sweep {
        packets,
        start_azimuth_deg: start_deg,
        ..Sweep::default()
    };
    let mut w = PcapWriter::new(1, false, false);
    for (n, p) in sweep.data_packets().iter().enumerate() {
        let t = u64::from(p.timestamp_us);
        let (sec, usec) = ((t / 1_000_000) as u32, (t % 1_000_000) as u32);
        w.push(sec, usec, &ethernet_udp(&p.to_payload(), 2368));
        if n == at {
            for e in extra {
                w.push(sec, usec, e);
            }
        }
    }
    w.into_bytes()
}

#[test]
fn foreign_packets_are_skipped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    // An ARP request and a GPS NMEA datagram to another port.
    let gps = ethernet_udp(b"$GPRMC,000000,A,4546.0,N,00257.0,E*00\r\n", 10110);
    let clean = file(dir.path(), "clean.pcap", &capture(200, 90.0, 50, &[]));
    let dirty = file(
        dir.path(),
        "dirty.pcap",
        &capture(200, 90.0, 50, &[ethernet_arp(), gps]),
    );
    let a = read_frames_noted(&clean, &ReadOptions::default()).unwrap();
    let b = read_frames_noted(&dirty, &ReadOptions::default()).unwrap();
    assert_eq!(a.clouds, b.clouds, "skipping changes no point");
    assert_eq!(b.notes.foreign_packets, 2);
    let w = b.notes.warnings.join("\n");
    assert!(
        w.contains("dirty.pcap") && w.contains("ARP") && w.contains("skipped 2"),
        "{w}"
    );
    // First (from 90°) and last revolutions are partial, the middle full.
    assert_eq!(b.partial.first(), Some(&true));
    assert_eq!(b.partial.last(), Some(&true));
    assert!(b.partial[1..b.partial.len() - 1].iter().all(|p| !p));
    assert!(b.clouds.len() >= 3);
}

#[test]
fn a_capture_cut_mid_packet_keeps_the_frames_before_the_cut() {
    let dir = tempfile::tempdir().unwrap();
    let whole = capture(200, 90.0, usize::MAX, &[]);
    let full = file(dir.path(), "full.pcap", &whole);
    // Cut 500 bytes into the last record (header + part of its payload).
    let cut = file(dir.path(), "cut.pcap", &whole[..whole.len() - 800]);
    let a = read_frames_noted(&full, &ReadOptions::default()).unwrap();
    let b = read_frames_noted(&cut, &ReadOptions::default()).unwrap();
    assert_eq!(a.clouds.len(), b.clouds.len());
    let n = a.clouds.len();
    assert_eq!(
        a.clouds[..n - 1],
        b.clouds[..n - 1],
        "earlier frames intact"
    );
    // The last frame lost one packet's 384 firings at most.
    let lost = a.clouds[n - 1].len() - b.clouds[n - 1].len();
    assert!(lost > 0 && lost <= 384, "{lost}");
    let w = b.notes.warnings.join("\n");
    assert!(
        w.contains("cut.pcap") && w.contains("truncated") && w.contains("kept"),
        "{w}"
    );
}

/// The x, y, z, intensity and ring of every point of `frames`, in order.
fn points_of(frames: &murk_io::Frames) -> Vec<(f32, f32, f32, f32, u16)> {
    frames
        .clouds
        .iter()
        .flat_map(|c| {
            (0..c.len()).map(move |i| (c.x[i], c.y[i], c.z[i], c.intensity[i], c.ring[i]))
        })
        .collect()
}

#[test]
fn a_dual_return_capture_gives_the_return_asked_for_and_says_when_it_gives_both() {
    use murk_types::PcapReturn;
    use murk_velodyne::ReturnMode;
    let dir = tempfile::tempdir().unwrap();
    let sweep = |mode: ReturnMode, packets: usize| Sweep {
        packets,
        start_azimuth_deg: 90.0,
        mode,
        ..Sweep::default()
    };
    // The same firings recorded in dual and in last-return mode (a dual
    // packet holds half the firings of a single one).
    let dual = file(
        dir.path(),
        "dual.pcap",
        &sweep(ReturnMode::Dual, 200).to_pcap(),
    );
    let last = file(
        dir.path(),
        "last.pcap",
        &sweep(ReturnMode::Last, 100).to_pcap(),
    );
    let read = |p: &Path, r: Option<PcapReturn>| {
        let opts = ReadOptions {
            pcap_return: r,
            ..ReadOptions::default()
        };
        read_frames_noted(p, &opts)
    };
    let both = read(&dual, None).unwrap();
    assert!(both.notes.both_returns);
    let from_dual = read(&dual, Some(PcapReturn::Last)).unwrap();
    assert!(!from_dual.notes.both_returns);
    let recorded = read(&last, None).unwrap();
    assert!(!recorded.notes.both_returns);
    let got = points_of(&from_dual);
    let want = points_of(&recorded);
    // The same return, at the same place to 1 cm (0.01° at 60 m): a
    // packet's last firing turns at the rate of the one before it, and a
    // dual packet ends after six firings where a single one ends after
    // twelve, so the azimuths of a few firings differ by thousandths of a
    // degree.
    let same = |a: &(f32, f32, f32, f32, u16), b: &(f32, f32, f32, f32, u16)| {
        (a.0 - b.0).abs() < 1e-2
            && (a.1 - b.1).abs() < 1e-2
            && (a.2 - b.2).abs() < 1e-2
            && (a.3, a.4) == (b.3, b.4)
    };
    let first_diff = got.iter().zip(&want).position(|(a, b)| !same(a, b));
    assert!(
        got.len() == want.len() && first_diff.is_none(),
        "the last returns, as a last-return sensor gives them: {} against {} points, first difference at {first_diff:?}: {:?} against {:?}",
        got.len(),
        want.len(),
        first_diff.map(|i| got[i]),
        first_diff.map(|i| want[i])
    );
    // Both returns: the last ones and the strongest where they differ (two
    // of three firings of the synthetic scene).
    let strongest = read(&dual, Some(PcapReturn::Strongest)).unwrap();
    let (n_both, n_last, n_strong) = (
        points_of(&both).len(),
        got.len(),
        points_of(&strongest).len(),
    );
    assert!(n_both > n_last && n_both < 2 * n_last, "{n_both} {n_last}");
    assert_eq!(n_strong, n_last, "one return per firing");
    // The sensor's description asks too, and the option wins over it.
    let mut spec = murk_types::LidarSpec::vlp16();
    spec.pcap_return = Some(PcapReturn::Strongest);
    let opts = ReadOptions {
        lidar: Some(spec.clone()),
        ..ReadOptions::default()
    };
    assert_eq!(
        points_of(&read_frames_noted(&dual, &opts).unwrap()),
        points_of(&strongest)
    );
    let opts = ReadOptions {
        lidar: Some(spec),
        pcap_return: Some(PcapReturn::Last),
        ..ReadOptions::default()
    };
    assert_eq!(points_of(&read_frames_noted(&dual, &opts).unwrap()), got);
    // A single-return capture has no other return to give.
    let e = read(&last, Some(PcapReturn::Strongest))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("last.pcap") && e.contains("asked for strongest"),
        "{e}"
    );
}

#[test]
fn a_pcap_error_is_its_message_once() {
    let dir = tempfile::tempdir().unwrap();
    let p = file(dir.path(), "x.pcap", b"not a capture at all, just text....");
    let e = read_cloud(&p, &ReadOptions::default()).unwrap_err();
    // No source: a chain printer (anyhow's {:#}) prints it once.
    assert!(std::error::Error::source(&e).is_none());
    assert_eq!(e.to_string().matches("x.pcap").count(), 1, "{e}");
}

#[test]
fn the_real_capture_flags_its_partial_first_and_last_revolutions() {
    let Some(p) = real("vlp16-test-90deg-1-50-frames.pcap") else {
        return;
    };
    let f = read_frames_noted(&p, &ReadOptions::default()).unwrap();
    let sizes: Vec<usize> = f.clouds.iter().map(PointCloud::len).collect();
    println!(
        "real capture: {} revolutions, first {} points, last {}, partial {:?}",
        sizes.len(),
        sizes[0],
        sizes[sizes.len() - 1],
        f.partial.iter().filter(|&&p| p).count()
    );
    assert_eq!(sizes.len(), 52);
    assert!(f.partial[0] && f.partial[51]);
    assert!(f.partial[1..51].iter().all(|p| !p));
    assert_eq!(f.notes.foreign_packets, 0);
}
