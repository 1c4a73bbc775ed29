//! Known-answer tests of the decoder against packets written field by field
//! with `murk_velodyne::synth`, one test per bad input, and the real capture.

use std::path::Path;

use murk_types::{IntensityScale, LidarSpec, PointCloud};
use murk_velodyne::synth::{
    DataPacket, PcapWriter, Sweep, ethernet, ethernet_arp, ethernet_udp, ipv4_udp, position_payload,
};
use murk_velodyne::{
    Capture, DATA_PORT, ForeignPolicy, POSITION_PORT, PcapOptions, ProductPolicy, ReturnMode,
    ReturnSelect, SensorModel, VelodyneError, decode_pcap, read_pcap_file,
};

/// Coordinates are compared to 0.1 mm.
const TOL_M: f32 = 1e-4;
/// Times are compared to 1 ns.
const TOL_S: f32 = 1e-9;

/// A little-endian µs Ethernet capture of these link-layer frames.
fn pcap_of(frames: &[Vec<u8>]) -> Vec<u8> {
    let mut w = PcapWriter::new(1, false, false);
    for (i, f) in frames.iter().enumerate() {
        w.push(1_700_000_000, i as u32 * 1327, f);
    }
    w.into_bytes()
}

/// A capture of these data packets on the data port.
fn pcap_of_packets(packets: &[DataPacket]) -> Vec<u8> {
    let frames: Vec<Vec<u8>> = packets
        .iter()
        .map(|p| ethernet_udp(&p.to_payload(), DATA_PORT))
        .collect();
    pcap_of(&frames)
}

fn decode(bytes: &[u8]) -> Capture {
    decode_pcap(bytes, &PcapOptions::default()).expect("decodes")
}

fn decode_err(bytes: &[u8], opts: &PcapOptions) -> VelodyneError {
    decode_pcap(bytes, opts).expect_err("must fail")
}

/// A single-return packet whose blocks turn by `step` from `start`
/// (hundredths of a degree), without returns.
fn turning(mode: ReturnMode, start: u16, step: u16) -> DataPacket {
    let mut p = DataPacket::new(mode, 1000);
    let columns = if mode == ReturnMode::Dual { 6 } else { 12 };
    for b in 0..12 {
        let column = if columns == 6 { b / 2 } else { b } as u32;
        p.azimuths[b] = ((u32::from(start) + column * u32::from(step)) % 36000) as u16;
    }
    p
}

/// Index of the point of `laser` in a cloud holding one point per laser.
fn by_ring(cloud: &PointCloud, laser: u16) -> usize {
    cloud
        .ring
        .iter()
        .position(|&r| r == laser)
        .expect("ring present")
}

/// The point murk expects for a return at sensor azimuth `az_deg`
/// (clockwise from forward), laser `laser`, distance `raw` × 2 mm.
fn expected_xyz(raw: u16, laser: usize, az_deg: f64) -> [f32; 3] {
    expected_xyz_of(&LidarSpec::vlp16(), raw, laser, az_deg)
}

/// [`expected_xyz`] for the lasers of `spec`.
fn expected_xyz_of(spec: &LidarSpec, raw: u16, laser: usize, az_deg: f64) -> [f32; 3] {
    expected_xyz_m(spec, f64::from(raw) * 0.002, laser, az_deg)
}

/// [`expected_xyz_of`] at range `r` metres.
fn expected_xyz_m(spec: &LidarSpec, r: f64, laser: usize, az_deg: f64) -> [f32; 3] {
    let w = spec.elevation_deg[laser].to_radians();
    let a = az_deg.to_radians();
    [
        (r * w.cos() * a.cos()) as f32,
        (-r * w.cos() * a.sin()) as f32,
        (r * w.sin()) as f32,
    ]
}

fn assert_point(cloud: &PointCloud, i: usize, xyz: [f32; 3]) {
    let got = [cloud.x[i], cloud.y[i], cloud.z[i]];
    for k in 0..3 {
        assert!(
            (got[k] - xyz[k]).abs() < TOL_M,
            "point {i}: got {got:?}, expected {xyz:?}"
        );
    }
}

// ---------------------------------------------------------------- geometry

#[test]
fn known_point_lands_in_murk_frame_with_ring_intensity_and_time() {
    // Laser 1 (+1°) at azimuth 90° (the sensor's right), 10 m, reflectivity 77.
    // Laser 15 (+15°) in the second sequence of block 3 of a standing
    // sensor at 0°, 2 m, reflectivity 200.
    let mut q = turning(ReturnMode::Strongest, 0, 0);
    q.channels[3][16 + 15] = (1000, 200);
    let mut p = turning(ReturnMode::Strongest, 9000, 40);
    p.channels[0][1] = (5000, 77);

    let c = decode(&pcap_of_packets(&[p]));
    assert_eq!(c.frames.len(), 1);
    let cloud = &c.frames[0];
    assert_eq!(cloud.len(), 1);
    assert_eq!(cloud.intensity_scale, IntensityScale::Calibrated);
    assert_eq!(cloud.ring, vec![1]);
    assert_eq!(cloud.intensity, vec![77.0]);
    // Laser 1 fires 2.304 µs into the block: its azimuth is 90° + 0.4° × 2.304/110.592.
    let az = 90.0 + 0.4 * 2.304 / 110.592;
    assert_point(cloud, 0, expected_xyz(5000, 1, az));
    assert!(cloud.y[0] < -9.9, "90° is to the right: y < 0");
    assert!((cloud.range(0) - 10.0).abs() < TOL_M);
    let t = cloud.time.as_ref().expect("time column");
    assert!((t[0] - 2.304e-6).abs() < TOL_S, "time {}", t[0]);

    let c = decode(&pcap_of_packets(&[q]));
    let cloud = &c.frames[0];
    assert_eq!(cloud.ring, vec![15]);
    assert_eq!(cloud.intensity, vec![200.0]);
    assert_point(
        cloud,
        0,
        [
            2.0 * 15f32.to_radians().cos(),
            0.0,
            2.0 * 15f32.to_radians().sin(),
        ],
    );
    let t = cloud.time.as_ref().expect("time column");
    let expected = (3.0 * 110.592 + 55.296 + 15.0 * 2.304) * 1e-6;
    assert!((t[0] - expected as f32).abs() < TOL_S, "time {}", t[0]);
}

#[test]
fn second_sequence_and_each_laser_are_interpolated_towards_the_next_block() {
    let mut p = turning(ReturnMode::Strongest, 1000, 40);
    p.channels[0][16] = (5000, 1); // block 0, sequence 2, laser 0
    p.channels[0][16 + 5] = (5000, 2); // block 0, sequence 2, laser 5
    p.channels[11][16] = (5000, 3); // last block, sequence 2, laser 0
    let cloud = &decode(&pcap_of_packets(&[p])).frames[0];
    assert_eq!(cloud.len(), 3);
    // Sequence 2 fires half a block later: 10° + 0.2°.
    let i = cloud.intensity.iter().position(|&v| v == 1.0).unwrap();
    assert_point(cloud, i, expected_xyz(5000, 0, 10.2));
    assert!((cloud.azimuth_deg(i) - (360.0 - 10.2)).abs() < 1e-3);
    // Laser 5 of sequence 2: (55.296 + 5 × 2.304) / 110.592 of the step.
    let i = cloud.intensity.iter().position(|&v| v == 2.0).unwrap();
    let frac = (55.296 + 5.0 * 2.304) / 110.592;
    assert_point(cloud, i, expected_xyz(5000, 5, 10.0 + 0.4 * frac));
    // The last block has no next block: it turns at the previous step.
    let i = cloud.intensity.iter().position(|&v| v == 3.0).unwrap();
    assert_point(cloud, i, expected_xyz(5000, 0, 10.0 + 11.0 * 0.4 + 0.2));
}

#[test]
fn interpolation_crosses_the_360_degree_wrap() {
    // Block 0 at 359.80°, block 1 at 0.20°: the second sequence of block 0
    // fires at 360.00° = 0°.
    let mut p = turning(ReturnMode::Strongest, 35980, 40);
    assert_eq!(p.azimuths[1], 20);
    p.channels[0][16] = (5000, 9);
    let c = decode(&pcap_of_packets(&[p]));
    // The wrap splits the packet: block 0 sequence 1 is the last firing of
    // frame 0, the point (sequence 2) opens frame 1.
    assert_eq!(c.frames.len(), 2);
    assert_eq!(c.stats.frames[0].firings, 1);
    assert_eq!(c.frames[0].len(), 0);
    let cloud = &c.frames[1];
    assert_point(cloud, 0, expected_xyz(5000, 0, 0.0));
    assert!((c.stats.frames[1].start_azimuth_deg - 0.0).abs() < 1e-4);
}

#[test]
fn frames_split_at_the_azimuth_wrap_with_times_from_the_frame_first_packet() {
    // Blocks 0–5 at 357.6°..359.6°, blocks 6–11 at 0°..2° (step 0.4°).
    let mut p = turning(ReturnMode::Strongest, 35760, 40);
    for b in 0..12 {
        for ch in 0..32 {
            p.channels[b][ch] = (1000, b as u8);
        }
    }
    let mut second = turning(ReturnMode::Strongest, 240, 40);
    second.timestamp_us = p.timestamp_us + 1327;
    for b in 0..12 {
        for ch in 0..32 {
            second.channels[b][ch] = (1000, 100 + b as u8);
        }
    }
    let c = decode(&pcap_of_packets(&[p, second]));
    assert_eq!(c.frames.len(), 2);
    assert_eq!(c.stats.points_per_frame(), vec![6 * 32, 18 * 32]);
    assert_eq!(c.stats.frames[0].firings, 12);
    assert_eq!(c.stats.frames[1].first_packet, 1);
    // Frame 0 starts at 357.6°: partial. Frame 1 starts at 0° but ends at
    // 7°: partial too.
    assert!(c.stats.first_frame_partial && c.stats.last_frame_partial);
    assert!(c.frames[0].intensity.iter().all(|&v| v < 6.0));
    assert!(c.frames[1].intensity.iter().all(|&v| v >= 6.0));
    // Frame 1's first packet is packet 1: its first point fires 6 blocks in,
    // and packet 2's first point 1327 µs after packet 1's start.
    let t = c.frames[1].time.as_ref().unwrap();
    assert!((t[0] - (6.0 * 110.592e-6) as f32).abs() < TOL_S, "{}", t[0]);
    let first_of_second = 6 * 32;
    assert!((t[first_of_second] - 1327e-6).abs() < TOL_S);
    // Time never decreases within a frame.
    assert!(t.windows(2).all(|w| w[0] <= w[1]));
}

#[test]
fn a_steady_sweep_gives_full_frames_between_partial_ends() {
    // 600 rpm: 0.398° per block, 904.2 blocks per turn. From 100°: 653
    // blocks to the first wrap, two full turns, 299 blocks more.
    let sweep = Sweep {
        rpm: 600.0,
        packets: 230,
        start_azimuth_deg: 100.0,
        ..Sweep::default()
    };
    let c = decode(&sweep.to_pcap());
    assert_eq!(c.frames.len(), 4);
    let f = &c.stats.frames;
    assert!(f[0].partial && f[3].partial);
    assert!(!f[1].partial && !f[2].partial);
    // A full turn has 904 or 905 blocks: 1809 ± 1 firings.
    for m in &f[1..3] {
        assert!((1808..=1810).contains(&m.firings), "{m:?}");
        assert!(
            m.start_azimuth_deg < 0.4 && m.end_azimuth_deg > 359.6,
            "{m:?}"
        );
    }
    let total: usize = c.frames.iter().map(PointCloud::len).sum();
    assert_eq!(total as u64, c.stats.points);
    // Every channel record is a point or a no-return: nothing lost.
    assert_eq!(c.stats.points + c.stats.no_return, 230 * 384);
}

// ---------------------------------------------------------------- returns

/// A dual packet whose pair 0 carries four channel cases.
fn dual_packet() -> DataPacket {
    let mut p = turning(ReturnMode::Dual, 2000, 40);
    // Laser 0: last (10 m, r 10), strongest (8 m, r 50).
    p.channels[0][0] = (5000, 10);
    p.channels[1][0] = (4000, 50);
    // Laser 1: the strongest is also the last → the strongest block holds
    // the second-strongest (6 m, r 20).
    p.channels[0][1] = (5000, 90);
    p.channels[1][1] = (3000, 20);
    // Laser 2: a single return, repeated in both blocks.
    p.channels[0][2] = (6000, 30);
    p.channels[1][2] = (6000, 30);
    // Laser 3: no return at all.
    p
}

#[test]
fn dual_both_returns_merge_a_repeated_single_return() {
    let c = decode(&pcap_of_packets(&[dual_packet()]));
    assert_eq!(c.stats.return_mode(), Some(ReturnMode::Dual));
    let cloud = &c.frames[0];
    let mut got: Vec<(u16, f32)> = cloud
        .ring
        .iter()
        .copied()
        .zip(cloud.intensity.iter().copied())
        .collect();
    got.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(
        got,
        vec![(0, 10.0), (0, 50.0), (1, 20.0), (1, 90.0), (2, 30.0)]
    );
    assert_eq!(c.stats.dual_duplicates, 1);
    // Both returns of a pair share azimuth and time.
    let i0 = cloud.intensity.iter().position(|&v| v == 10.0).unwrap();
    let i1 = cloud.intensity.iter().position(|&v| v == 50.0).unwrap();
    assert_point(cloud, i0, expected_xyz(5000, 0, 20.0));
    assert_point(cloud, i1, expected_xyz(4000, 0, 20.0));
    let t = cloud.time.as_ref().unwrap();
    assert_eq!(t[i0], t[i1]);
    let as_recorded = decode(&pcap_of_packets(&[dual_packet()]));
    let both = decode_pcap(
        &pcap_of_packets(&[dual_packet()]),
        &PcapOptions {
            return_mode: ReturnSelect::Both,
            ..PcapOptions::default()
        },
    )
    .unwrap();
    assert_eq!(as_recorded.frames, both.frames);
}

#[test]
fn dual_pairs_fire_one_column_per_pair() {
    // Pair 2 (blocks 4, 5), sequence 2, laser 3: time 2 × 110.592 + 55.296
    // + 3 × 2.304 µs; azimuth 20° + 2 × 0.4° + 0.4° × (55.296 + 6.912)/110.592.
    let mut p = turning(ReturnMode::Dual, 2000, 40);
    p.channels[4][16 + 3] = (2500, 5);
    p.channels[5][16 + 3] = (2500, 5);
    let cloud = &decode(&pcap_of_packets(&[p])).frames[0];
    assert_eq!(cloud.len(), 1);
    let frac = (55.296 + 3.0 * 2.304) / 110.592;
    assert_point(cloud, 0, expected_xyz(2500, 3, 20.8 + 0.4 * frac));
    let t = cloud.time.as_ref().unwrap()[0];
    let expected = (2.0 * 110.592 + 55.296 + 3.0 * 2.304) * 1e-6;
    assert!((t - expected as f32).abs() < TOL_S, "{t}");
}

#[test]
fn dual_strongest_is_the_brighter_return_of_the_pair() {
    let opts = PcapOptions {
        return_mode: ReturnSelect::Strongest,
        ..PcapOptions::default()
    };
    let c = decode_pcap(&pcap_of_packets(&[dual_packet()]), &opts).unwrap();
    let cloud = &c.frames[0];
    let i = by_ring(cloud, 1);
    assert_eq!(
        cloud.intensity[i], 90.0,
        "the last block held the strongest"
    );
    assert!((cloud.range(i) - 10.0).abs() < TOL_M);
    let i = by_ring(cloud, 0);
    assert_eq!(cloud.intensity[i], 50.0);
    assert!((cloud.range(i) - 8.0).abs() < TOL_M);
    assert_eq!(cloud.len(), 3);
}

#[test]
fn dual_last_is_the_last_block() {
    let opts = PcapOptions {
        return_mode: ReturnSelect::Last,
        ..PcapOptions::default()
    };
    let c = decode_pcap(&pcap_of_packets(&[dual_packet()]), &opts).unwrap();
    let cloud = &c.frames[0];
    assert_eq!(cloud.intensity, vec![10.0, 90.0, 30.0]);
    assert_eq!(cloud.ring, vec![0, 1, 2]);
}

#[test]
fn single_mode_captures_give_exactly_what_they_recorded() {
    for mode in [ReturnMode::Strongest, ReturnMode::Last] {
        let mut p = turning(mode, 0, 40);
        p.channels[2][7] = (4321, 12);
        let bytes = pcap_of_packets(&[p]);
        let c = decode(&bytes);
        assert_eq!(c.stats.return_mode(), Some(mode));
        assert_eq!(c.frames[0].len(), 1);
        let same = match mode {
            ReturnMode::Strongest => ReturnSelect::Strongest,
            _ => ReturnSelect::Last,
        };
        let other = match mode {
            ReturnMode::Strongest => ReturnSelect::Last,
            _ => ReturnSelect::Strongest,
        };
        let ok = decode_pcap(
            &bytes,
            &PcapOptions {
                return_mode: same,
                ..PcapOptions::default()
            },
        )
        .unwrap();
        assert_eq!(ok.frames, c.frames);
        for asked in [other, ReturnSelect::Both] {
            let e = decode_err(
                &bytes,
                &PcapOptions {
                    return_mode: asked,
                    ..PcapOptions::default()
                },
            );
            assert!(
                matches!(e, VelodyneError::ReturnModeUnavailable { packet: 1, offset: 24, recorded, .. } if recorded == mode),
                "{e}"
            );
        }
    }
}

// ---------------------------------------------------------------- containers

#[test]
fn both_byte_orders_and_timestamp_resolutions_decode_identically() {
    let sweep = Sweep {
        packets: 80,
        position_every: 7,
        ..Sweep::default()
    };
    let reference = decode(&sweep.to_pcap());
    assert_eq!(reference.stats.packets_position, 11);
    for big_endian in [false, true] {
        for nanos in [false, true] {
            let mut w = PcapWriter::new(1, big_endian, nanos);
            for p in sweep.data_packets() {
                w.push(5, 0, &ethernet_udp(&p.to_payload(), DATA_PORT));
            }
            let c = decode(w.bytes());
            assert_eq!(c.frames, reference.frames, "be {big_endian} ns {nanos}");
            assert_eq!(c.stats.packets_data, 80);
        }
    }
}

#[test]
fn every_supported_link_layer_decodes_identically() {
    let sweep = Sweep {
        packets: 30,
        ..Sweep::default()
    };
    let reference = decode(&sweep.to_pcap());
    type Wrap = fn(Vec<u8>) -> Vec<u8>;
    let wrap: [(u32, Wrap); 6] = [
        (0, |ip| [2u32.to_le_bytes().to_vec(), ip].concat()),
        (101, |ip| ip),
        (228, |ip| ip),
        (113, |ip| {
            let mut h = vec![
                0, 0, 0, 1, 0, 6, 0x60, 0x76, 0x88, 0, 0, 0, 0, 0, 0x08, 0x00,
            ];
            h.extend(ip);
            h
        }),
        (276, |ip| {
            let mut h = vec![0x08, 0x00, 0, 0, 0, 0, 0, 2, 0, 1, 0, 6];
            h.extend_from_slice(&[0x60, 0x76, 0x88, 0, 0, 0, 0, 0]);
            h.extend(ip);
            h
        }),
        (1, |ip| {
            // An 802.1Q-tagged Ethernet frame.
            let mut body = vec![0x00, 0x05, 0x08, 0x00];
            body.extend(ip);
            ethernet(0x8100, &body)
        }),
    ];
    for (link, f) in wrap {
        let mut w = PcapWriter::new(link, false, false);
        for p in sweep.data_packets() {
            w.push(0, 0, &f(ipv4_udp(&p.to_payload(), DATA_PORT, DATA_PORT)));
        }
        let c = decode(w.bytes());
        assert_eq!(c.stats.link_type, link);
        assert_eq!(c.frames, reference.frames, "link type {link}");
    }
}

#[test]
fn hour_rollover_of_the_packet_timestamp_keeps_time_increasing() {
    let sweep = Sweep {
        packets: 40,
        start_us: 3_599_990_000,
        ..Sweep::default()
    };
    let packets = sweep.data_packets();
    assert!(
        packets.last().unwrap().timestamp_us < 100_000,
        "the sweep wraps"
    );
    let c = decode(&sweep.to_pcap());
    assert_eq!(c.frames.len(), 1);
    let t = c.frames[0].time.as_ref().unwrap();
    assert!(t.windows(2).all(|w| w[0] <= w[1]));
    // The last point fires in the last block of packet 40, 39 packet periods
    // after the frame's first packet.
    let last = f64::from(*t.last().unwrap());
    let (lo, hi) = (
        39.0 * 1327.104e-6 + 11.0 * 110.592e-6,
        39.0 * 1327.104e-6 + 12.0 * 110.592e-6,
    );
    assert!(lo - 1e-6 <= last && last <= hi + 1e-6, "{last}");
}

#[test]
fn position_packets_are_counted_and_other_ports_are_foreign() {
    let data = turning(ReturnMode::Strongest, 0, 40).to_payload();
    let bytes = pcap_of(&[
        ethernet_udp(&position_payload(0), POSITION_PORT),
        ethernet_udp(&data, DATA_PORT),
        ethernet_udp(&data, 2369),
    ]);
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::Foreign { packet: 3, what, .. } if what.contains("port 2369")),
        "{e}"
    );
    let any_port = PcapOptions {
        port: None,
        ..PcapOptions::default()
    };
    let c = decode_pcap(&bytes, &any_port).unwrap();
    assert_eq!((c.stats.packets_position, c.stats.packets_data), (1, 2));
}

#[test]
fn skipped_foreign_packets_are_counted_by_kind() {
    let data = turning(ReturnMode::Strongest, 0, 40).to_payload();
    let bytes = pcap_of(&[
        ethernet_arp(),
        ethernet_udp(&data, DATA_PORT),
        ethernet_udp(b"hello", 53),
        ethernet_arp(),
    ]);
    let opts = PcapOptions {
        on_foreign: ForeignPolicy::Skip,
        ..PcapOptions::default()
    };
    let c = decode_pcap(&bytes, &opts).unwrap();
    assert_eq!(c.stats.packets_total, 4);
    assert_eq!(c.stats.packets_data, 1);
    assert_eq!(c.stats.packets_foreign_skipped, 3);
    assert_eq!(
        c.stats.foreign_kinds.get("ARP (EtherType 0x0806)"),
        Some(&2)
    );
    assert_eq!(c.stats.foreign_kinds.len(), 2);
}

#[test]
fn min_frame_points_drops_small_partial_frames_but_never_full_ones() {
    let sweep = Sweep {
        packets: 230,
        start_azimuth_deg: 100.0,
        ..Sweep::default()
    };
    let bytes = sweep.to_pcap();
    let all = decode(&bytes);
    let counts = all.stats.points_per_frame();
    let c = decode_pcap(&bytes, &PcapOptions::full_frames_only()).unwrap();
    assert_eq!(c.frames.len(), 2);
    assert_eq!(c.stats.frames_dropped, 2);
    assert_eq!(c.stats.points_dropped as usize, counts[0] + counts[3]);
    assert!(!c.stats.first_frame_partial && !c.stats.last_frame_partial);
    assert_eq!(c.frames[0], all.frames[1]);
    // A threshold between the two partial frames' sizes drops only the smaller.
    let (small, large) = (counts[0].min(counts[3]), counts[0].max(counts[3]));
    let c = decode_pcap(
        &bytes,
        &PcapOptions {
            min_frame_points: small + 1,
            ..PcapOptions::default()
        },
    )
    .unwrap();
    assert_eq!(c.frames.len(), 3);
    assert!(
        c.stats
            .frames
            .iter()
            .all(|f| f.points > small || !f.partial)
    );
    assert!(large > small);
}

// ---------------------------------------------------------------- bad input

#[test]
fn truncated_global_header_is_an_error() {
    let bytes = &pcap_of(&[])[..20];
    let e = decode_err(bytes, &PcapOptions::default());
    assert!(
        matches!(e, VelodyneError::TruncatedHeader { len: 20, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("<bytes>"), "{e}");
}

#[test]
fn truncated_record_is_an_error_naming_the_packet() {
    let p = turning(ReturnMode::Strongest, 0, 40);
    let bytes = pcap_of_packets(&[p.clone(), p]);
    let cut = &bytes[..bytes.len() - 100];
    let e = decode_err(cut, &PcapOptions::default());
    let second = 24 + 16 + 1248;
    assert!(
        matches!(&e, VelodyneError::Truncated { packet: 2, offset, reason, .. }
            if *offset == second as u64 && reason.contains("1248")),
        "{e}"
    );
}

#[test]
fn a_cut_last_record_keeps_the_packets_before_it_when_asked() {
    let sweep = Sweep {
        packets: 200,
        start_azimuth_deg: 90.0,
        ..Sweep::default()
    };
    let bytes = sweep.to_pcap();
    let keep = PcapOptions {
        keep_truncated_tail: true,
        ..PcapOptions::default()
    };
    let whole = decode_pcap(&bytes, &keep).unwrap();
    assert!(whole.stats.truncated_tail.is_none());
    // Cut inside the payload and inside the record header of the last packet.
    for cut in [700, 1260] {
        let c = decode_pcap(&bytes[..bytes.len() - cut], &keep).unwrap();
        assert_eq!(c.stats.packets_data, 199, "cut {cut}");
        let n = whole.frames.len();
        assert_eq!(c.frames.len(), n);
        assert_eq!(c.frames[..n - 1], whole.frames[..n - 1]);
        assert!(c.stats.last_frame_partial);
        let why = c.stats.truncated_tail.unwrap();
        assert!(
            why.contains("packet 200") && why.contains("truncated"),
            "{why}"
        );
        // Without the option the same bytes are an error.
        assert!(decode_pcap(&bytes[..bytes.len() - cut], &PcapOptions::default()).is_err());
    }
}

#[test]
fn truncated_record_header_is_an_error() {
    let p = turning(ReturnMode::Strongest, 0, 40);
    let bytes = pcap_of_packets(&[p.clone(), p]);
    let cut = &bytes[..24 + 16 + 1248 + 10];
    let e = decode_err(cut, &PcapOptions::default());
    assert!(
        matches!(e, VelodyneError::Truncated { packet: 2, .. }),
        "{e}"
    );
}

#[test]
fn snap_length_cut_data_packet_is_an_error() {
    let frame = ethernet_udp(
        &turning(ReturnMode::Strongest, 0, 40).to_payload(),
        DATA_PORT,
    );
    let bytes = pcap_of(&[frame[..600].to_vec()]);
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::Truncated { packet: 1, reason, .. } if reason.contains("snap length")),
        "{e}"
    );
}

#[test]
fn foreign_packet_is_an_error_naming_index_offset_and_kind() {
    let data = turning(ReturnMode::Strongest, 0, 40).to_payload();
    let bytes = pcap_of(&[ethernet_udp(&data, DATA_PORT), ethernet_arp()]);
    let e = decode_err(&bytes, &PcapOptions::default());
    let offset = (24 + 16 + 1248) as u64;
    assert!(
        matches!(&e, VelodyneError::Foreign { packet: 2, offset: o, what, .. } if *o == offset && what.contains("ARP")),
        "{e}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("packet 2") && msg.contains(&format!("byte {offset}")),
        "{msg}"
    );
}

#[test]
fn bad_block_flag_is_a_foreign_packet() {
    let mut p = turning(ReturnMode::Strongest, 0, 40);
    p.flags[7] = [0xff, 0xdd];
    let e = decode_err(&pcap_of_packets(&[p]), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::Foreign { packet: 1, what, .. } if what.contains("block 7 flag is ff dd")),
        "{e}"
    );
}

#[test]
fn pcapng_is_refused_with_the_conversion_command() {
    let mut bytes = vec![
        0x0a, 0x0d, 0x0d, 0x0a, 0x1c, 0, 0, 0, 0x4d, 0x3c, 0x2b, 0x1a,
    ];
    bytes.resize(64, 0);
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(matches!(e, VelodyneError::Pcapng { .. }), "{e}");
    assert!(e.to_string().contains("editcap -F pcap"), "{e}");
}

#[test]
fn unknown_magic_is_not_pcap() {
    let e = decode_err(
        b"PCD v0.7 not a capture, just some text",
        &PcapOptions::default(),
    );
    assert!(
        matches!(
            e,
            VelodyneError::NotPcap {
                magic: 0x50434420,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn unsupported_link_type_is_named() {
    let bytes = PcapWriter::new(127, false, false).into_bytes();
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(
        matches!(e, VelodyneError::UnsupportedLinkType { link_type: 127, .. }),
        "{e}"
    );
}

#[test]
fn unsupported_pcap_version_is_named() {
    let mut bytes = PcapWriter::new(1, false, false).into_bytes();
    bytes[4] = 3;
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(
        matches!(
            e,
            VelodyneError::UnsupportedVersion {
                major: 3,
                minor: 4,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn unknown_return_mode_byte_is_an_error() {
    let mut p = turning(ReturnMode::Strongest, 0, 40);
    p.return_mode = 0x40;
    let e = decode_err(&pcap_of_packets(&[p]), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::BadPacket { packet: 1, reason, .. } if reason.contains("0x40")),
        "{e}"
    );
}

#[test]
fn azimuth_above_a_full_turn_is_an_error() {
    let mut p = turning(ReturnMode::Strongest, 0, 40);
    p.azimuths[4] = 36001;
    let e = decode_err(&pcap_of_packets(&[p]), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::BadPacket { reason, .. } if reason.contains("block 4") && reason.contains("36001")),
        "{e}"
    );
}

#[test]
fn azimuth_of_36000_is_zero() {
    // The real test capture reports one block at 36000.
    let mut p = turning(ReturnMode::Strongest, 35960, 40);
    assert_eq!(p.azimuths[1], 0);
    p.azimuths[1] = 36000;
    p.channels[1][0] = (5000, 1);
    let c = decode(&pcap_of_packets(&[p]));
    assert_eq!(c.frames.len(), 2);
    assert_point(&c.frames[1], 0, expected_xyz(5000, 0, 0.0));
}

#[test]
fn azimuth_jump_inside_a_packet_is_an_error() {
    let mut p = turning(ReturnMode::Strongest, 0, 40);
    p.azimuths[6] = 9000;
    let e = decode_err(&pcap_of_packets(&[p]), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::BadPacket { reason, .. } if reason.contains("block 5") && reason.contains("block 6")),
        "{e}"
    );
}

#[test]
fn dual_pair_with_two_azimuths_is_an_error() {
    let mut p = turning(ReturnMode::Dual, 0, 40);
    p.azimuths[3] += 1;
    let e = decode_err(&pcap_of_packets(&[p]), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::BadPacket { reason, .. } if reason.contains("blocks 2 and 3")),
        "{e}"
    );
}

#[test]
fn timestamp_past_the_hour_is_an_error() {
    let mut p = turning(ReturnMode::Strongest, 0, 40);
    p.timestamp_us = 3_600_000_000;
    let e = decode_err(&pcap_of_packets(&[p]), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::BadPacket { reason, .. } if reason.contains("past the hour")),
        "{e}"
    );
}

#[test]
fn other_velodyne_products_are_refused_unless_asked() {
    let mut p = turning(ReturnMode::Strongest, 0, 40);
    p.product = 0xa1;
    p.channels[0][0] = (500, 1);
    let bytes = pcap_of_packets(&[p]);
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::UnsupportedProduct { product: 0xa1, reason, .. } if reason.contains("VLS-128")),
        "{e}"
    );
    let any = PcapOptions {
        products: ProductPolicy::Any,
        ..PcapOptions::default()
    };
    assert_eq!(decode_pcap(&bytes, &any).unwrap().points(), 1);
}

/// Ten packets tagged 0x21, `period_us` apart, blocks turning 0.4° from 0°.
fn tagged_0x21(period_us: u32) -> Vec<u8> {
    let packets: Vec<DataPacket> = (0..10)
        .map(|n| {
            let mut p = turning(ReturnMode::Strongest, (n * 480) as u16, 40);
            p.product = 0x21;
            p.timestamp_us = 5000 + n * period_us;
            p
        })
        .collect();
    pcap_of_packets(&packets)
}

#[test]
fn product_0x21_is_the_sensor_whose_packet_period_it_keeps() {
    let c = decode(&tagged_0x21(1327));
    assert_eq!(c.stats.product_ids.get(&0x21), Some(&10));
    assert_eq!(c.stats.sensor, Some(SensorModel::Vlp16));
    let c = decode(&tagged_0x21(553));
    assert_eq!(c.stats.sensor, Some(SensorModel::Hdl32e));
    // Neither sensor's period: refused, naming the first 0x21 packet.
    let e = decode_err(&tagged_0x21(900), &PcapOptions::default());
    assert!(
        matches!(
            &e,
            VelodyneError::UnsupportedProduct {
                product: 0x21,
                packet: 1,
                reason,
                ..
            } if reason.contains("neither sensor")
        ),
        "{e}"
    );
}

/// Single-return packets of `model` (its product byte, at its packet
/// period: HDL-32E 0x21 every 552.96 µs, VLP-32C 0x28 every 663.552 µs),
/// blocks turning by `step` hundredths of a degree from 0°, without
/// returns.
fn model_packets(model: SensorModel, n: u32, step: u16) -> Vec<DataPacket> {
    (0..n)
        .map(|k| {
            let mut p = turning(
                ReturnMode::Strongest,
                (k * 12 * u32::from(step)) as u16,
                step,
            );
            p.product = model.product();
            p.timestamp_us = 5000 + (f64::from(k) * model.packet_period_us(false)).round() as u32;
            p
        })
        .collect()
}

fn hdl32e_packets(n: u32, step: u16) -> Vec<DataPacket> {
    model_packets(SensorModel::Hdl32e, n, step)
}

#[test]
fn hdl32e_returns_land_on_its_32_lasers_with_their_own_azimuth_and_time() {
    // Packet 0, block 2 (at 0.32°, turning 0.16° a block): laser 0
    // (−30.67°) at 10 m, laser 15 (0°) at 20 m, laser 31 (+10.67°) at 4 m.
    let mut packets = hdl32e_packets(3, 16);
    packets[0].channels[2][0] = (5000, 11);
    packets[0].channels[2][15] = (10000, 33);
    packets[0].channels[2][31] = (2000, 22);
    let c = decode(&pcap_of_packets(&packets));
    assert_eq!(c.stats.sensor, Some(SensorModel::Hdl32e));
    assert_eq!(c.frames.len(), 1);
    let cloud = &c.frames[0];
    assert_eq!(cloud.len(), 3);
    let hdl = LidarSpec::hdl32e();
    let t = cloud.time.as_ref().expect("time column");
    for (refl, laser, raw) in [(11.0, 0usize, 5000u16), (33.0, 15, 10000), (22.0, 31, 2000)] {
        let i = cloud.intensity.iter().position(|&v| v == refl).unwrap();
        assert_eq!(cloud.ring[i] as usize, laser);
        // Laser l fires l × 1.152 µs into the 46.08 µs block.
        let frac = laser as f64 * 1.152 / 46.08;
        assert_point(
            cloud,
            i,
            expected_xyz_of(&hdl, raw, laser, 0.32 + 0.16 * frac),
        );
        let want = (2.0 * 46.08 + laser as f64 * 1.152) * 1e-6;
        assert!(
            (t[i] - want as f32).abs() < TOL_S,
            "laser {laser}: time {}",
            t[i]
        );
    }
}

#[test]
fn an_hdl32e_sweep_gives_its_turns_of_2170_firings() {
    // 600 rpm: 0.1659° a block, 2170.1 blocks a turn; from 100°, 500
    // packets (6,000 blocks) hold two full turns between partial ends.
    let sweep = Sweep {
        rpm: 600.0,
        packets: 500,
        start_azimuth_deg: 100.0,
        model: SensorModel::Hdl32e,
        ..Sweep::default()
    };
    let c = decode(&sweep.to_pcap());
    assert_eq!(c.stats.sensor, Some(SensorModel::Hdl32e));
    let f = &c.stats.frames;
    assert_eq!(f.len(), 4, "{f:?}");
    assert!(f[0].partial && f[3].partial && !f[1].partial && !f[2].partial);
    for m in &f[1..3] {
        assert!((2169..=2171).contains(&m.firings), "{m:?}");
    }
    assert_eq!(c.stats.points + c.stats.no_return, 500 * 384);
    // Every laser is a ring at its own elevation.
    let hdl = LidarSpec::hdl32e();
    let cloud = &c.frames[1];
    for laser in 0..32u16 {
        let i = by_ring(cloud, laser);
        let e = hdl.elevation_deg[laser as usize] as f32;
        assert!((cloud.elevation_deg(i) - e).abs() < 1e-3, "laser {laser}");
    }
    // A VLP-16 sweep is still told as one.
    let vlp = decode(&Sweep::default().to_pcap());
    assert_eq!(vlp.stats.sensor, Some(SensorModel::Vlp16));
}

#[test]
fn hdl32e_dual_return_packets_are_told_by_their_period_and_paired() {
    // Dual return: block pairs share an azimuth, packets every 276.48 µs.
    let packets: Vec<DataPacket> = (0..4u32)
        .map(|k| {
            let mut p = turning(ReturnMode::Dual, (k * 6 * 16) as u16, 16);
            p.product = 0x21;
            p.timestamp_us = 5000 + (f64::from(k) * 276.48).round() as u32;
            p
        })
        .collect();
    let mut packets = packets;
    // Pair 1 (blocks 2, 3 at 0.16°): laser 20 (−17.33°) last at 12 m,
    // strongest at 7 m.
    packets[0].channels[2][20] = (6000, 15);
    packets[0].channels[3][20] = (3500, 90);
    let c = decode(&pcap_of_packets(&packets));
    assert_eq!(c.stats.sensor, Some(SensorModel::Hdl32e));
    assert_eq!(c.stats.return_mode(), Some(ReturnMode::Dual));
    let cloud = &c.frames[0];
    assert_eq!(cloud.len(), 2);
    assert_eq!(cloud.ring, vec![20, 20]);
    let hdl = LidarSpec::hdl32e();
    let az = 0.16 + 0.16 * 20.0 * 1.152 / 46.08;
    for (refl, raw) in [(15.0, 6000u16), (90.0, 3500)] {
        let i = cloud.intensity.iter().position(|&v| v == refl).unwrap();
        assert_point(cloud, i, expected_xyz_of(&hdl, raw, 20, az));
    }
    // The same packets at the VLP-16's dual period are a VLP-16's.
    let mut vlp = packets.clone();
    for (k, p) in vlp.iter_mut().enumerate() {
        p.timestamp_us = 5000 + (k as f64 * 663.552).round() as u32;
    }
    let c = decode(&pcap_of_packets(&vlp));
    assert_eq!(c.stats.sensor, Some(SensorModel::Vlp16));
}

#[test]
fn a_capture_mixing_hdl32e_packets_with_others_is_refused() {
    let mut packets = hdl32e_packets(6, 16);
    packets[4].product = 0x22;
    let e = decode_err(&pcap_of_packets(&packets), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::UnsupportedProduct { product: 0x22, packet: 5, reason, .. } if reason.contains("one capture holds one sensor")),
        "{e}"
    );
}

fn vlp32c_packets(n: u32, step: u16) -> Vec<DataPacket> {
    model_packets(SensorModel::Vlp32c, n, step)
}

#[test]
fn vlp32c_returns_land_on_their_lasers_at_their_pair_time_offset_and_4_mm_units() {
    // Packet 0, block 2 (at 0.40°, turning 0.20° a block). Laser 0 (−25°,
    // offset +1.4°) at 10 m, laser 1 (−1°, −4.2°, fired with laser 0) at
    // 20 m, laser 19 (−3.667°, −4.2°, the tenth pair) at 30 m, laser 31
    // (−1.333°, −1.4°, the last pair) at 4 m; distances count 4 mm.
    let mut packets = vlp32c_packets(3, 20);
    packets[0].channels[2][0] = (2500, 11);
    packets[0].channels[2][1] = (5000, 33);
    packets[0].channels[2][19] = (7500, 44);
    packets[0].channels[2][31] = (1000, 22);
    let c = decode(&pcap_of_packets(&packets));
    assert_eq!(c.stats.sensor, Some(SensorModel::Vlp32c));
    assert_eq!(c.frames.len(), 1);
    let cloud = &c.frames[0];
    assert_eq!(cloud.len(), 4);
    let spec = LidarSpec::vlp32c();
    let t = cloud.time.as_ref().expect("time column");
    for (refl, laser, r_m, offset) in [
        (11.0, 0usize, 10.0, 1.4),
        (33.0, 1, 20.0, -4.2),
        (44.0, 19, 30.0, -4.2),
        (22.0, 31, 4.0, -1.4),
    ] {
        let i = cloud.intensity.iter().position(|&v| v == refl).unwrap();
        assert_eq!(cloud.ring[i] as usize, laser);
        // Pair p = laser / 2 fires p × 2.304 µs into the 55.296 µs block.
        let into = (laser / 2) as f64 * 2.304;
        let az = (0.40 + 0.20 * into / 55.296 + offset).rem_euclid(360.0);
        assert_point(cloud, i, expected_xyz_m(&spec, r_m, laser, az));
        let want = (2.0 * 55.296 + into) * 1e-6;
        assert!(
            (t[i] - want as f32).abs() < TOL_S,
            "laser {laser}: time {}",
            t[i]
        );
    }
}

#[test]
fn vlp32c_and_puck_hi_res_sweeps_are_told_by_their_product_byte() {
    // 600 rpm, 55.296 µs a firing sequence: 0.1991° a sequence, 1808.4 a
    // turn. From 100°, 450 packets (5,400 firings) hold two full turns
    // between partial ends; in dual return (6 firings a packet) 900
    // packets do, and 225 of the Puck Hi-Res (two sequences a block).
    for (model, mode, packets) in [
        (SensorModel::Vlp32c, ReturnMode::Strongest, 450),
        (SensorModel::Vlp32c, ReturnMode::Dual, 900),
        (SensorModel::PuckHiRes, ReturnMode::Strongest, 225),
    ] {
        let sweep = Sweep {
            rpm: 600.0,
            packets,
            start_azimuth_deg: 100.0,
            mode,
            model,
            ..Sweep::default()
        };
        let c = decode(&sweep.to_pcap());
        let what = format!("{} {mode:?}", model.name());
        assert_eq!(c.stats.sensor, Some(model), "{what}");
        let f = &c.stats.frames;
        assert_eq!(f.len(), 4, "{what}: {f:?}");
        assert!(f[0].partial && f[3].partial && !f[1].partial && !f[2].partial);
        let per_turn = 360.0 / 0.1991;
        for m in &f[1..3] {
            assert!(
                (m.firings as f64 - per_turn).abs() <= 1.5,
                "{what}: {m:?} against {per_turn}"
            );
        }
        if mode != ReturnMode::Dual {
            // Every channel record is a point or a firing without return.
            assert_eq!(
                c.stats.points + c.stats.no_return,
                packets as u64 * 384,
                "{what}"
            );
        }
        // Every laser is a ring at its own elevation.
        let el = model.elevation_deg();
        let cloud = &c.frames[1];
        for laser in 0..model.lasers() as u16 {
            let i = by_ring(cloud, laser);
            let e = el[laser as usize] as f32;
            assert!(
                (cloud.elevation_deg(i) - e).abs() < 1e-3,
                "{what}: laser {laser}"
            );
        }
    }
}

#[test]
fn a_capture_mixing_vlp32c_packets_with_others_is_refused() {
    let mut packets = vlp32c_packets(6, 20);
    packets[3].product = 0x22;
    let e = decode_err(&pcap_of_packets(&packets), &PcapOptions::default());
    assert!(
        matches!(&e, VelodyneError::UnsupportedProduct { product: 0x22, packet: 4, reason, .. } if reason.contains("VLP-16 packets in a capture of VLP-32C packets")),
        "{e}"
    );
}

#[test]
fn capture_without_data_packets_is_an_error() {
    let bytes = pcap_of(&[ethernet_udp(&position_payload(0), POSITION_PORT)]);
    let e = decode_err(&bytes, &PcapOptions::default());
    assert!(
        matches!(
            e,
            VelodyneError::NoData {
                packets: 1,
                position: 1,
                foreign: 0,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn missing_file_error_names_the_path() {
    let path = Path::new("/nonexistent/murk/capture.pcap");
    let e = read_pcap_file(path, &PcapOptions::default()).unwrap_err();
    assert!(matches!(e, VelodyneError::Io { .. }), "{e}");
    assert!(
        e.to_string().contains("/nonexistent/murk/capture.pcap"),
        "{e}"
    );
}

#[test]
fn file_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.pcap");
    std::fs::write(&path, pcap_of(&[ethernet_arp()])).unwrap();
    let e = read_pcap_file(&path, &PcapOptions::default()).unwrap_err();
    assert!(
        e.to_string()
            .starts_with(&format!("{}: packet 1 at byte 24", path.display())),
        "{e}"
    );
}

// ---------------------------------------------------------------- real data

const REAL: &str = "vlp16-test-90deg-1-50-frames.pcap";

/// Points per full frame the capturing tool's own test expects.
const EXPECTED_FULL_FRAME_POINTS: f64 = 13_860.0;
/// Tolerance on it: 1 % (the scene is static; frames differ by noise only).
const FULL_FRAME_TOLERANCE: f64 = 0.01;

#[test]
fn real_vlp16_capture_decodes_to_fifty_full_frames() {
    let Some(path) = murk_types::real_data::real_data_file(env!("CARGO_MANIFEST_DIR"), REAL) else {
        return;
    };
    let path = path.as_path();
    let c = read_pcap_file(path, &PcapOptions::default()).expect("reads without flags");
    let s = &c.stats;
    assert_eq!(s.packets_data, 1902);
    assert_eq!(s.packets_position, 367);
    assert_eq!(s.packets_total, 2269);
    assert_eq!(s.packets_foreign_skipped, 0);
    assert_eq!(s.return_mode(), Some(ReturnMode::Strongest));
    assert!(s.first_frame_partial && s.last_frame_partial);
    let full: Vec<usize> = s
        .frames
        .iter()
        .filter(|f| !f.partial)
        .map(|f| f.points)
        .collect();
    assert_eq!(full.len(), 50);
    for n in &full {
        let rel = (*n as f64 - EXPECTED_FULL_FRAME_POINTS).abs() / EXPECTED_FULL_FRAME_POINTS;
        assert!(rel < FULL_FRAME_TOLERANCE, "full frame of {n} points");
    }
    for cloud in &c.frames {
        cloud.check().unwrap();
        assert!(cloud.ring.iter().all(|&r| r < 16));
        // VLP-16 range: 100 m nominal, 131 m of distance field at most.
        assert!((0..cloud.len()).all(|i| cloud.range(i) < 131.1));
    }
    // Dropping the partial ends keeps exactly the 50 full frames.
    let full_only = read_pcap_file(path, &PcapOptions::full_frames_only()).unwrap();
    assert_eq!(full_only.frames.len(), 50);
    assert_eq!(full_only.stats.frames_dropped, 2);
}
