//! Velodyne `.pcap` captures, decoded by `murk-velodyne`.

use std::path::Path;

use murk_types::PcapReturn;
use murk_types::{PointCloud, PointFormat};
use murk_velodyne::{ForeignPolicy, PcapOptions, ReturnMode, ReturnSelect, read_pcap_file};

use crate::{Frames, IoError, ReadNotes, ReadOptions, ScaleSource};

/// The decoder settings murk-io reads captures with: `murk-velodyne`'s
/// defaults (data port 2368, returns as recorded, partial frames decoded
/// and flagged) except two, chosen for captures from the field:
///
/// - packets that are not the sensor's (ARP, GPS/NMEA on other ports, TCP)
///   are **skipped and counted**, not an error: a shared network puts them
///   in almost every real capture, and they carry no point;
/// - a capture cut inside its last record (a recording stopped by pulling
///   power, an interrupted copy) **keeps the frames before the cut**; the
///   cut is reported in the notes.
///
/// The returns are as recorded unless [`ReadOptions::declared_pcap_return`]
/// names one.
fn pcap_options(opts: &ReadOptions) -> PcapOptions {
    PcapOptions {
        on_foreign: ForeignPolicy::Skip,
        keep_truncated_tail: true,
        return_mode: match opts.declared_pcap_return() {
            None => ReturnSelect::AsRecorded,
            Some(PcapReturn::Strongest) => ReturnSelect::Strongest,
            Some(PcapReturn::Last) => ReturnSelect::Last,
        },
        ..PcapOptions::default()
    }
}

/// One cloud per revolution of the capture at `path`, flagged partial or
/// not, with what the decode skipped or cut (see [`pcap_options`]).
///
/// The frames carry the decoder's calibrated intensity; an explicit
/// [`ReadOptions::intensity_scale`] relabels them (values untouched).
pub(crate) fn read_frames(path: &Path, opts: &ReadOptions) -> Result<Frames, IoError> {
    let capture = read_pcap_file(path, &pcap_options(opts)).map_err(|reason| IoError::Pcap {
        path: path.to_path_buf(),
        reason,
    })?;
    let scale = opts.scale_for(PointFormat::Pcap);
    let stats = capture.stats;
    let mut notes = ReadNotes {
        scale_source: if opts.declared_scale().is_some() {
            ScaleSource::Declared
        } else {
            ScaleSource::Default
        },
        foreign_packets: stats.packets_foreign_skipped,
        both_returns: opts.declared_pcap_return().is_none()
            && stats.return_modes.contains_key(&ReturnMode::Dual),
        ..ReadNotes::default()
    };
    if stats.packets_foreign_skipped > 0 {
        let kinds: Vec<String> = stats
            .foreign_kinds
            .iter()
            .map(|(k, n)| format!("{n} × {k}"))
            .collect();
        notes.warnings.push(format!(
            "{}: skipped {} packet{} that are not the sensor's ({})",
            path.display(),
            stats.packets_foreign_skipped,
            if stats.packets_foreign_skipped == 1 {
                ""
            } else {
                "s"
            },
            kinds.join(", ")
        ));
    }
    if let Some(cut) = &stats.truncated_tail {
        notes.warnings.push(format!(
            "{cut}; the {} revolution{} before the cut {} kept",
            stats.frames.len(),
            if stats.frames.len() == 1 { "" } else { "s" },
            if stats.frames.len() == 1 { "is" } else { "are" },
        ));
    }
    let mut clouds: Vec<PointCloud> = capture.frames;
    for f in &mut clouds {
        f.intensity_scale = scale;
    }
    Ok(Frames {
        partial: stats.frames.iter().map(|f| f.partial).collect(),
        clouds,
        notes,
    })
}
