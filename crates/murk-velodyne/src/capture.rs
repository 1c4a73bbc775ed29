//! The decoded capture: frames and what was seen on the way.

use std::collections::BTreeMap;

use murk_types::PointCloud;
use serde::Serialize;

use crate::ReturnMode;

/// A decoded capture: one [`PointCloud`] per revolution, and statistics.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct Capture {
    /// One cloud per revolution, in capture order, each with a `time` column
    /// (seconds since the frame's first packet) and calibrated intensity.
    pub frames: Vec<PointCloud>,
    /// What was read and decoded.
    pub stats: CaptureStats,
}

impl Capture {
    /// Total number of points over the kept frames.
    pub fn points(&self) -> usize {
        self.frames.iter().map(PointCloud::len).sum()
    }
}

/// What a decode saw. Packet counts cover the whole file; frame fields
/// describe the frames kept in [`Capture::frames`], index for index.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
#[non_exhaustive]
pub struct CaptureStats {
    /// Link-layer type of the capture (1 Ethernet, 113 SLL, …).
    pub link_type: u32,
    /// Packet records in the file.
    pub packets_total: u64,
    /// Velodyne data packets decoded.
    pub packets_data: u64,
    /// Velodyne position packets counted and skipped.
    pub packets_position: u64,
    /// Foreign packets skipped under [`crate::ForeignPolicy::Skip`].
    pub packets_foreign_skipped: u64,
    /// Skipped foreign packets by kind (`"ARP (EtherType 0x0806)"`, …).
    pub foreign_kinds: BTreeMap<String, u64>,
    /// Data packets per recorded return mode.
    pub return_modes: BTreeMap<ReturnMode, u64>,
    /// Data packets per product-id byte.
    pub product_ids: BTreeMap<u8, u64>,
    /// Channel records with distance 0 (no return), in the selected returns.
    pub no_return: u64,
    /// Dual-return pairs with identical returns that became one point.
    pub dual_duplicates: u64,
    /// Points in the kept frames.
    pub points: u64,
    /// One entry per kept frame.
    pub frames: Vec<FrameStats>,
    /// True when the first kept frame does not start at the 0° crossing.
    pub first_frame_partial: bool,
    /// True when the last kept frame does not end at the 0° crossing.
    pub last_frame_partial: bool,
    /// Partial frames dropped by [`crate::PcapOptions::min_frame_points`].
    pub frames_dropped: usize,
    /// Points in the dropped frames.
    pub points_dropped: u64,
    /// Where and how the file ends inside a packet record, when
    /// [`crate::PcapOptions::keep_truncated_tail`] kept the packets before
    /// it (`None`: the capture ends on a record boundary).
    pub truncated_tail: Option<String>,
    /// The sensor the data packets were decoded as (from their product
    /// byte and packet period).
    pub sensor: Option<crate::SensorModel>,
}

impl CaptureStats {
    /// Points of each kept frame.
    pub fn points_per_frame(&self) -> Vec<usize> {
        self.frames.iter().map(|f| f.points).collect()
    }

    /// The return mode of the data packets when they all share one.
    pub fn return_mode(&self) -> Option<ReturnMode> {
        let mut modes = self.return_modes.keys();
        match (modes.next(), modes.next()) {
            (Some(m), None) => Some(*m),
            _ => None,
        }
    }
}

/// One frame (revolution) of a capture.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[non_exhaustive]
pub struct FrameStats {
    /// Points in the frame.
    pub points: usize,
    /// Firing sequences (16-laser columns) in the frame.
    pub firings: usize,
    /// True for a first or last frame that does not cover a revolution.
    pub partial: bool,
    /// 1-based index of the packet holding the frame's first firing.
    pub first_packet: u64,
    /// Sensor azimuth of the first firing, degrees clockwise from forward
    /// (the packet's own convention).
    pub start_azimuth_deg: f32,
    /// Sensor azimuth of the last firing, degrees clockwise from forward.
    pub end_azimuth_deg: f32,
}
