//! Velodyne pcap decoding (VLP-16, Puck LITE, Puck Hi-Res, HDL-32E,
//! VLP-32C): a capture file in, one
//! [`murk_types::PointCloud`] per revolution out.
//!
//! - [`read_pcap_file`] / [`decode_pcap`]: decode a classic libpcap capture
//!   (either byte order, µs or ns timestamps; Ethernet, Linux cooked SLL and
//!   SLL2, raw IPv4, BSD loopback links) into a [`Capture`]: frames plus
//!   [`CaptureStats`] (packet counts by kind, return mode, points per frame,
//!   partial first/last frames).
//! - [`PcapOptions`]: data port, which returns ([`ReturnSelect`]), what a
//!   foreign packet does ([`ForeignPolicy`]), dropping partial frames,
//!   which product ids are decoded ([`ProductPolicy`]); the sensor is told
//!   by the product byte and, for 0x21, the packet period ([`SensorModel`]).
//! - [`VelodyneError`]: every error names the file, the 1-based packet index
//!   and the byte offset of its record.
//! - [`synth`]: writers for synthetic captures (tests, benches, fixtures).
//!
//! # Geometry
//!
//! A data packet holds 12 blocks; each block an azimuth and two firing
//! sequences of the 16 lasers (an HDL-32E or VLP-32C block: one sequence of
//! its 32). The second sequence's azimuth, and each laser's (VLP-16 lasers
//! fire 2.304 µs apart, sequences 55.296 µs apart; HDL-32E lasers 1.152 µs
//! apart, 46.08 µs a block; VLP-32C lasers in pairs 2.304 µs apart, 55.296
//! µs a block), are interpolated towards the next block's azimuth across
//! the 360° wrap; the last block of a packet turns at the rate of the block
//! before. A VLP-32C laser's horizontal offset (±1.4°, ±4.2°) is added to
//! its azimuth, and its distances count 4 mm, not 2. Laser id is the ring,
//! and its elevation ω comes from [`SensorModel::elevation_deg`] (the
//! VLP-16's is [`murk_types::LidarSpec::vlp16`]'s, the HDL-32E's
//! [`murk_types::LidarSpec::hdl32e`]'s, the VLP-32C's
//! [`murk_types::LidarSpec::vlp32c`]'s): a campaign of these sensors
//! declares its `elevation_deg` by laser id in that order.
//! The per-laser vertical offsets of the VLP-16 (≤ 11.2 mm) are not applied.
//!
//! **Frame convention.** The sensor measures azimuth α clockwise (seen from
//! above) from its forward axis, in a frame with y forward and x right:
//! `x_v = r·cos ω·sin α, y_v = r·cos ω·cos α, z_v = r·sin ω`. murk's frame is
//! x forward, y left, z up, so points are stored as
//! `x = y_v = r·cos ω·cos α`, `y = −x_v = −r·cos ω·sin α`, `z = r·sin ω`
//! (the ROS `velodyne_pointcloud` convention): a return at α = 90° (to the
//! sensor's right) has y < 0. [`murk_types::PointCloud::azimuth_deg`] is then
//! `360° − α`.
//!
//! Distance 0 means no return and gives no point. Intensity is the
//! calibrated reflectivity byte ([`murk_types::IntensityScale::Calibrated`]).
//! `time` is seconds since the sensor timestamp of the frame's first packet,
//! plus the firing offset within the packet.
//!
//! **Frames** split where the firing azimuth drops across 360° → 0°. The
//! first frame is partial unless it starts within 1° after 0°, the last
//! unless it ends within 1° before 360°.
//!
//! **Architecture invariant:** this crate decodes packets and nothing else;
//! it does no statistics, knows no campaign and writes no file.
//!
//! ```
//! use murk_velodyne::{decode_pcap, synth::Sweep, PcapOptions, ReturnMode};
//!
//! // 1.5 revolutions of a sensor spinning at 600 rpm, from 0°.
//! let sweep = Sweep { rpm: 600.0, packets: 113, position_every: 10, ..Sweep::default() };
//! let capture = decode_pcap(&sweep.to_pcap(), &PcapOptions::default())?;
//!
//! assert_eq!(capture.stats.packets_data, 113);
//! assert_eq!(capture.stats.packets_position, 11);
//! assert_eq!(capture.stats.return_mode(), Some(ReturnMode::Strongest));
//! assert_eq!(capture.frames.len(), 2);
//! assert!(!capture.stats.frames[0].partial && capture.stats.last_frame_partial);
//! let cloud = &capture.frames[0];
//! assert!(cloud.ring.iter().all(|&r| r < 16));
//! # Ok::<(), murk_velodyne::VelodyneError>(())
//! ```

mod capture;
mod decode;
mod error;
mod model;
mod options;
mod pcap;
pub mod synth;

pub use capture::{Capture, CaptureStats, FrameStats};
pub use decode::{decode_pcap, decode_pcap_named, product_name, read_pcap_file};
pub use error::VelodyneError;
pub use model::SensorModel;
pub use options::{
    DATA_PORT, ForeignPolicy, POSITION_PORT, PcapOptions, ProductPolicy, ReturnMode, ReturnSelect,
};
