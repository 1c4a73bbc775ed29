//! What the caller can choose when decoding a capture: ports, returns,
//! what to do with foreign packets and partial frames.

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

/// UDP destination port of VLP-16 data packets (factory default).
pub const DATA_PORT: u16 = 2368;
/// UDP destination port of VLP-16 position (GPS/PPS) packets.
pub const POSITION_PORT: u16 = 8308;

/// Options of [`crate::decode_pcap`] and [`crate::read_pcap_file`].
///
/// | field | default | purpose |
/// |---|---|---|
/// | `port` | `Some(2368)` | UDP destination port of data packets; `None` = any UDP port |
/// | `position_port` | `Some(8308)` | UDP destination port of 512-byte position packets (counted, skipped); `None` = any port |
/// | `return_mode` | [`ReturnSelect::AsRecorded`] | which returns become points |
/// | `on_foreign` | [`ForeignPolicy::Error`] | what a non-Velodyne packet does |
/// | `min_frame_points` | `0` | a *partial* first/last frame with fewer points is dropped |
/// | `keep_truncated_tail` | `false` | a capture cut inside its last record keeps the frames before the cut ([`crate::CaptureStats::truncated_tail`]) instead of failing |
/// | `products` | [`ProductPolicy::Known`] | which product-id bytes are decoded, as which sensor |
///
/// Position packets are legitimate VLP-16 traffic and never need a flag;
/// anything else in the capture (ARP, TCP, other UDP) is an error unless the
/// caller opts into [`ForeignPolicy::Skip`].
///
/// Build with struct-update syntax so new fields keep their defaults:
///
/// ```
/// use murk_velodyne::{ForeignPolicy, PcapOptions, ReturnSelect};
/// let opts = PcapOptions {
///     return_mode: ReturnSelect::Strongest,
///     on_foreign: ForeignPolicy::Skip,
///     ..PcapOptions::default()
/// };
/// assert_eq!(opts.port, Some(2368));
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PcapOptions {
    /// UDP destination port of data packets; `None` accepts any port.
    pub port: Option<u16>,
    /// UDP destination port of position packets; `None` accepts any port.
    pub position_port: Option<u16>,
    /// Which returns become points.
    pub return_mode: ReturnSelect,
    /// What a packet that is not Velodyne traffic does.
    pub on_foreign: ForeignPolicy,
    /// A partial first or last frame with fewer points than this is dropped
    /// (and counted in [`crate::CaptureStats::frames_dropped`]). Full frames
    /// are always kept: a revolution in dense fog can legitimately hold few
    /// points, and dropping it would bias every statistic fitted from it.
    /// `usize::MAX` drops every partial frame.
    pub min_frame_points: usize,
    /// Which product-id bytes are decoded with the VLP-16 geometry.
    pub products: ProductPolicy,
    /// When the file ends inside a packet record (a capture cut short, a
    /// copy interrupted), keep the packets before it and describe the cut
    /// in [`crate::CaptureStats::truncated_tail`] instead of failing with
    /// [`crate::VelodyneError::Truncated`]. The frame the cut falls in is
    /// then the last one, flagged partial when it does not reach 360°.
    pub keep_truncated_tail: bool,
}

impl Default for PcapOptions {
    fn default() -> Self {
        PcapOptions {
            port: Some(DATA_PORT),
            position_port: Some(POSITION_PORT),
            return_mode: ReturnSelect::AsRecorded,
            on_foreign: ForeignPolicy::Error,
            min_frame_points: 0,
            products: ProductPolicy::Known,
            keep_truncated_tail: false,
        }
    }
}

impl PcapOptions {
    /// The defaults, except that partial first/last frames are dropped.
    pub fn full_frames_only() -> Self {
        PcapOptions {
            min_frame_points: usize::MAX,
            ..PcapOptions::default()
        }
    }
}

/// Which returns of each laser firing become points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReturnSelect {
    /// Whatever the sensor recorded: the one return of a single-return
    /// capture, both returns of a dual-return capture (as [`Self::Both`]).
    #[default]
    AsRecorded,
    /// The strongest return. From a single-return capture it requires the
    /// strongest mode (0x37). From a dual capture it is, per laser firing,
    /// the return with the higher reflectivity of the two blocks: the sensor
    /// puts the *second*-strongest return in the strongest block when the
    /// strongest is also the last, so the strongest block alone is not it.
    Strongest,
    /// The last return: a last-mode (0x38) capture, or the last block of
    /// each dual-return pair.
    Last,
    /// Both returns of a dual-return (0x39) capture. When only one return
    /// was detected the sensor repeats it in both blocks; such an identical
    /// pair (same distance and reflectivity) becomes one point, counted in
    /// [`crate::CaptureStats::dual_duplicates`].
    Both,
}

impl ReturnSelect {
    /// The kebab-case name (`as-recorded`, `strongest`, `last`, `both`).
    pub fn name(self) -> &'static str {
        match self {
            ReturnSelect::AsRecorded => "as-recorded",
            ReturnSelect::Strongest => "strongest",
            ReturnSelect::Last => "last",
            ReturnSelect::Both => "both",
        }
    }
}

impl fmt::Display for ReturnSelect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ReturnSelect {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "as-recorded" | "as_recorded" | "recorded" => Ok(ReturnSelect::AsRecorded),
            "strongest" => Ok(ReturnSelect::Strongest),
            "last" => Ok(ReturnSelect::Last),
            "both" | "dual" => Ok(ReturnSelect::Both),
            other => Err(format!(
                "unknown return selection {other:?}: expected as-recorded, strongest, last or both"
            )),
        }
    }
}

/// The return mode a data packet was recorded in (its byte 1204).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ReturnMode {
    /// 0x37: one return per firing, the strongest.
    Strongest,
    /// 0x38: one return per firing, the last.
    Last,
    /// 0x39: two returns per firing in block pairs (last, strongest).
    Dual,
}

impl ReturnMode {
    /// The mode of a return-mode byte, `None` for an unknown byte.
    pub fn from_byte(b: u8) -> Option<Self> {
        match b {
            0x37 => Some(ReturnMode::Strongest),
            0x38 => Some(ReturnMode::Last),
            0x39 => Some(ReturnMode::Dual),
            _ => None,
        }
    }

    /// The byte that encodes this mode in a data packet.
    pub fn byte(self) -> u8 {
        match self {
            ReturnMode::Strongest => 0x37,
            ReturnMode::Last => 0x38,
            ReturnMode::Dual => 0x39,
        }
    }

    /// Lower-case name (`strongest`, `last`, `dual`).
    pub fn name(self) -> &'static str {
        match self {
            ReturnMode::Strongest => "strongest",
            ReturnMode::Last => "last",
            ReturnMode::Dual => "dual",
        }
    }
}

impl fmt::Display for ReturnMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a packet that is not Velodyne traffic (ARP, TCP, UDP of another
/// size or port, a 1206-byte payload without the 0xFFEE block flags) does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ForeignPolicy {
    /// Stop with [`crate::VelodyneError::Foreign`] naming the packet.
    #[default]
    Error,
    /// Count it in [`crate::CaptureStats::packets_foreign_skipped`] (by kind
    /// in [`crate::CaptureStats::foreign_kinds`]) and go on.
    Skip,
}

/// Which data packets are decoded, by their product-id byte (byte 1205).
///
/// The VLP-16 geometry (16 lasers at ±15°, two firing sequences per
/// block), the Puck Hi-Res's (the same over ±10°), the HDL-32E's (32 lasers
/// from −30.67° to +10.67°, one sequence per block) and the VLP-32C's (32
/// lasers from −25° to +15° fired in pairs, at horizontal offsets) are
/// implemented ([`crate::SensorModel`]); a packet from another model would
/// decode to wrong points, so it is refused with
/// [`crate::VelodyneError::UnsupportedProduct`] instead.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ProductPolicy {
    /// 0x22 (VLP-16) and 0x23 (Puck LITE, same lasers) are decoded as the
    /// VLP-16, 0x24 as the Puck Hi-Res, 0x28 as the VLP-32C. 0x21 names the HDL-32E, but VLP-16 captures carrying it
    /// exist (the real test capture of this repository is one): 0x21
    /// packets are decoded as the sensor whose packet period they keep —
    /// the VLP-16's 1327 µs (664 µs dual return) or the HDL-32E's 553 µs
    /// (276 µs) — and refused when they keep neither. Any other product
    /// byte is refused, and so is a capture that mixes one sensor's packets
    /// with another's.
    #[default]
    Known,
    /// Every product byte is decoded with the VLP-16 geometry, unchecked.
    Any,
}
