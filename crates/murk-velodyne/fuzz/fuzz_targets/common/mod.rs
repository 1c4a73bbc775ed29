//! The body of the `pcap` fuzz target, kept out of the `fuzz_target!` file
//! so that murk-velodyne's stable test `tests/fuzz_corpus.rs` (which
//! includes this file by path) replays the committed seeds through exactly
//! what the fuzzer runs.

use murk_velodyne::{ForeignPolicy, PcapOptions, ReturnSelect, decode_pcap};

/// One fuzz input: `decode_pcap` must return `Ok` or `Err`, never panic,
/// and its `Ok` must be self-consistent. The first byte picks the options,
/// so both policies and every return selection are explored; the rest is
/// the capture.
pub fn pcap(data: &[u8]) {
    let Some((&knob, bytes)) = data.split_first() else {
        return;
    };
    let opts = PcapOptions {
        on_foreign: if knob & 1 == 0 {
            ForeignPolicy::Error
        } else {
            ForeignPolicy::Skip
        },
        return_mode: match (knob >> 1) & 3 {
            0 => ReturnSelect::AsRecorded,
            1 => ReturnSelect::Strongest,
            2 => ReturnSelect::Last,
            _ => ReturnSelect::Both,
        },
        port: if knob & 8 == 0 { Some(2368) } else { None },
        min_frame_points: if knob & 16 == 0 { 0 } else { usize::MAX },
        ..PcapOptions::default()
    };
    if let Ok(capture) = decode_pcap(bytes, &opts) {
        let s = &capture.stats;
        assert_eq!(capture.frames.len(), s.frames.len());
        assert!(s.packets_data >= 1);
        assert!(s.packets_data + s.packets_position + s.packets_foreign_skipped == s.packets_total);
        for (cloud, meta) in capture.frames.iter().zip(&s.frames) {
            assert_eq!(cloud.len(), meta.points);
            cloud.check().expect("columns agree");
            assert!(cloud.ring.iter().all(|&r| r < 16));
            assert!(
                cloud
                    .x
                    .iter()
                    .chain(&cloud.y)
                    .chain(&cloud.z)
                    .all(|v| v.is_finite())
            );
        }
    }
}
