//! Velodyne `.pcap` captures, decoded by `murk-velodyne`.

use std::path::Path;

use murk_types::{PointCloud, PointFormat};
use murk_velodyne::{PcapOptions, read_pcap_file};

use crate::{IoError, ReadOptions};

/// One cloud per revolution of the capture at `path`, decoded with
/// `murk-velodyne`'s defaults (data port 2368, returns as recorded, a
/// non-Velodyne packet is an error, partial first/last frames kept).
///
/// The frames carry the decoder's calibrated intensity; an explicit
/// [`ReadOptions::intensity_scale`] relabels them (values untouched).
pub(crate) fn read_frames(path: &Path, opts: &ReadOptions) -> Result<Vec<PointCloud>, IoError> {
    let capture =
        read_pcap_file(path, &PcapOptions::default()).map_err(|source| IoError::Pcap {
            path: path.to_path_buf(),
            source,
        })?;
    let scale = opts.scale_for(PointFormat::Pcap);
    let mut frames = capture.frames;
    for f in &mut frames {
        f.intensity_scale = scale;
    }
    Ok(frames)
}
