//! Property tests: decoded geometry against the packet's own fields, and no
//! panic on corrupted captures.

use murk_velodyne::synth::{DataPacket, PcapWriter, Sweep, ethernet_udp};
use murk_velodyne::{DATA_PORT, ForeignPolicy, PcapOptions, ReturnMode, decode_pcap};
use proptest::prelude::*;

/// Relative tolerance on ranges: f32 rounding of x, y, z and the square root.
const REL_TOL: f32 = 2e-6;

fn packet_strategy() -> impl Strategy<Value = DataPacket> {
    (
        0u16..36000,
        0u16..=200,
        prop::collection::vec((any::<u16>(), any::<u8>()), 12 * 32),
        0u32..3_600_000_000,
    )
        .prop_map(|(start, step, channels, ts)| {
            let mut p = DataPacket::new(ReturnMode::Strongest, ts);
            for b in 0..12 {
                p.azimuths[b] = ((u32::from(start) + b as u32 * u32::from(step)) % 36000) as u16;
                p.channels[b].copy_from_slice(&channels[b * 32..(b + 1) * 32]);
            }
            p
        })
}

proptest! {
    #[test]
    fn points_keep_distance_ring_and_reflectivity(p in packet_strategy()) {
        let mut w = PcapWriter::new(1, false, false);
        w.push(0, 0, &ethernet_udp(&p.to_payload(), DATA_PORT));
        let c = decode_pcap(w.bytes(), &PcapOptions::default()).unwrap();
        // Points come in channel order; distance 0 gives none.
        let expected: Vec<(u16, u8, u16)> = (0..12)
            .flat_map(|b| (0..32).map(move |ch| (b, ch)))
            .map(|(b, ch)| (p.channels[b][ch].0, p.channels[b][ch].1, (ch % 16) as u16))
            .filter(|e| e.0 != 0)
            .collect();
        let mut got = Vec::new();
        for cloud in &c.frames {
            for i in 0..cloud.len() {
                got.push((cloud.range(i), cloud.intensity[i], cloud.ring[i]));
            }
        }
        prop_assert_eq!(got.len(), expected.len());
        for ((range, intensity, ring), (d, r, laser)) in got.into_iter().zip(expected) {
            let want = f32::from(d) * 0.002;
            prop_assert!((range - want).abs() <= want * REL_TOL + 1e-6, "{} vs {}", range, want);
            prop_assert!(ring < 16);
            prop_assert_eq!(ring, laser);
            prop_assert_eq!(intensity, f32::from(r));
        }
    }

    #[test]
    fn corrupted_captures_fail_cleanly(flips in prop::collection::vec((any::<usize>(), any::<u8>()), 1..20), cut in any::<usize>()) {
        let mut bytes = Sweep { packets: 3, position_every: 2, ..Sweep::default() }.to_pcap();
        for (at, v) in flips {
            let n = bytes.len();
            bytes[at % n] = v;
        }
        let keep = bytes.len() - cut % 64;
        bytes.truncate(keep);
        let opts = PcapOptions { on_foreign: ForeignPolicy::Skip, ..PcapOptions::default() };
        // Either result is fine; a panic is not.
        let _ = decode_pcap(&bytes, &opts);
    }
}
