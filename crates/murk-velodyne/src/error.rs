//! The error type of this crate.
//!
//! Every variant names the file (or `<bytes>` for [`crate::decode_pcap`]) and,
//! past the global header, the 1-based packet index and the byte offset of
//! that packet's record header in the file, so that `editcap`, Wireshark's
//! "Go to packet" or `xxd -s OFFSET` lead straight to the bad bytes.

use std::path::PathBuf;

use crate::{ReturnMode, ReturnSelect};

/// Errors raised while reading or decoding a Velodyne capture.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum VelodyneError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        source: std::io::Error,
    },
    /// The file is a pcapng capture.
    #[error(
        "{}: byte 0: pcapng not supported, convert with `editcap -F pcap IN.pcapng OUT.pcap`",
        .path.display()
    )]
    Pcapng {
        /// The file.
        path: PathBuf,
    },
    /// The file does not start with a libpcap magic number.
    #[error(
        "{}: byte 0: not a pcap capture (magic 0x{magic:08x}; expected 0xa1b2c3d4 or 0xa1b23c4d in either byte order)",
        .path.display()
    )]
    NotPcap {
        /// The file.
        path: PathBuf,
        /// The first four bytes, read big-endian.
        magic: u32,
    },
    /// The file is shorter than the 24-byte pcap global header.
    #[error(
        "{}: byte {len}: truncated pcap global header ({len} bytes, 24 needed)",
        .path.display()
    )]
    TruncatedHeader {
        /// The file.
        path: PathBuf,
        /// Its length in bytes.
        len: usize,
    },
    /// A pcap major version other than 2.
    #[error(
        "{}: byte 4: unsupported pcap version {major}.{minor} (expected 2.x)",
        .path.display()
    )]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// Major version as read.
        major: u16,
        /// Minor version as read.
        minor: u16,
    },
    /// A link-layer type this crate does not parse.
    #[error(
        "{}: byte 20: unsupported link type {link_type}; murk reads BSD loopback (0), Ethernet (1), raw IPv4 (101, 228), Linux cooked SLL (113) and SLL2 (276)",
        .path.display()
    )]
    UnsupportedLinkType {
        /// The file.
        path: PathBuf,
        /// Link type as read (lower 16 bits of the header field).
        link_type: u32,
    },
    /// A packet record that runs past the end of the file, or a Velodyne
    /// packet cut short by the capture's snap length.
    #[error(
        "{}: packet {packet} at byte {offset}: truncated: {reason}",
        .path.display()
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// 1-based packet index.
        packet: u64,
        /// Byte offset of the packet's record header.
        offset: u64,
        /// What was missing.
        reason: String,
    },
    /// A packet that is neither a Velodyne data nor position packet, with
    /// [`crate::ForeignPolicy::Error`].
    #[error(
        "{}: packet {packet} at byte {offset}: foreign packet: {what} (decode with ForeignPolicy::Skip, what murk-io does, to count and skip such packets)",
        .path.display()
    )]
    Foreign {
        /// The file.
        path: PathBuf,
        /// 1-based packet index.
        packet: u64,
        /// Byte offset of the packet's record header.
        offset: u64,
        /// What the packet was.
        what: String,
    },
    /// A Velodyne data packet whose content cannot be decoded.
    #[error("{}: packet {packet} at byte {offset}: {reason}", .path.display())]
    BadPacket {
        /// The file.
        path: PathBuf,
        /// 1-based packet index.
        packet: u64,
        /// Byte offset of the packet's record header.
        offset: u64,
        /// What is wrong, naming the block when it is one block.
        reason: String,
    },
    /// A data packet from a Velodyne model whose geometry is not the VLP-16's.
    #[error(
        "{}: packet {packet} at byte {offset}: product id 0x{product:02x}: {reason}",
        .path.display()
    )]
    UnsupportedProduct {
        /// The file.
        path: PathBuf,
        /// 1-based packet index.
        packet: u64,
        /// Byte offset of the packet's record header.
        offset: u64,
        /// The product-id byte.
        product: u8,
        /// Why it was refused.
        reason: String,
    },
    /// The caller asked for a return the sensor did not record.
    #[error(
        "{}: packet {packet} at byte {offset}: asked for {asked} returns but the packet was recorded in {recorded} return mode",
        .path.display()
    )]
    ReturnModeUnavailable {
        /// The file.
        path: PathBuf,
        /// 1-based packet index.
        packet: u64,
        /// Byte offset of the packet's record header.
        offset: u64,
        /// What the caller asked for.
        asked: ReturnSelect,
        /// What the packet holds.
        recorded: ReturnMode,
    },
    /// The capture holds no Velodyne data packet.
    #[error(
        "{}: no Velodyne data packet among {packets} packets ({position} position packets, {foreign} foreign packets skipped)",
        .path.display()
    )]
    NoData {
        /// The file.
        path: PathBuf,
        /// Packets read.
        packets: u64,
        /// Of which position packets.
        position: u64,
        /// Of which foreign packets skipped.
        foreign: u64,
    },
}
