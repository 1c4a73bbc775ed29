//! The libpcap container and the link, IPv4 and UDP headers inside it.
//!
//! Hand-parsed rather than taken from a pcap crate: it is about sixty lines,
//! it borrows the payload straight out of the input slice, and it lets every
//! error name the exact packet index and byte offset, which the crates we
//! looked at do not expose.

use std::path::Path;

use crate::VelodyneError;

/// Length of the pcap global header.
pub(crate) const GLOBAL_HEADER_LEN: usize = 24;
/// Length of a pcap record header.
const RECORD_HEADER_LEN: usize = 16;

/// The parsed pcap global header.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PcapHeader {
    big_endian: bool,
    /// Link-layer type (lower 16 bits of the header field).
    pub(crate) link_type: u32,
}

/// Parses the 24-byte global header.
pub(crate) fn parse_header(bytes: &[u8], path: &Path) -> Result<PcapHeader, VelodyneError> {
    if bytes.len() >= 4 && bytes[..4] == [0x0a, 0x0d, 0x0d, 0x0a] {
        return Err(VelodyneError::Pcapng { path: path.into() });
    }
    if bytes.len() < GLOBAL_HEADER_LEN {
        // Name what the few bytes look like before complaining about length.
        if bytes.len() >= 4 && magic_endian(be32(bytes, 0)).is_none() {
            return Err(VelodyneError::NotPcap {
                path: path.into(),
                magic: be32(bytes, 0),
            });
        }
        return Err(VelodyneError::TruncatedHeader {
            path: path.into(),
            len: bytes.len(),
        });
    }
    let magic = be32(bytes, 0);
    let big_endian = magic_endian(magic).ok_or_else(|| VelodyneError::NotPcap {
        path: path.into(),
        magic,
    })?;
    let h = PcapHeader {
        big_endian,
        link_type: 0,
    };
    let (major, minor) = (h.u16(bytes, 4), h.u16(bytes, 6));
    if major != 2 {
        return Err(VelodyneError::UnsupportedVersion {
            path: path.into(),
            major,
            minor,
        });
    }
    // The upper bits of the field carry FCS information (pcap spec §4).
    let link_type = h.u32(bytes, 20) & 0xffff;
    if !matches!(link_type, 0 | 1 | 101 | 113 | 228 | 276) {
        return Err(VelodyneError::UnsupportedLinkType {
            path: path.into(),
            link_type,
        });
    }
    Ok(PcapHeader { link_type, ..h })
}

/// `Some(big_endian)` for the four libpcap magics (µs and ns resolution),
/// read as big-endian bytes. Timestamps of the records are not used, so the
/// resolution only matters for recognising the file.
fn magic_endian(magic: u32) -> Option<bool> {
    match magic {
        0xa1b2_c3d4 | 0xa1b2_3c4d => Some(true),
        0xd4c3_b2a1 | 0x4d3c_b2a1 => Some(false),
        _ => None,
    }
}

impl PcapHeader {
    fn u16(&self, b: &[u8], at: usize) -> u16 {
        let v = [b[at], b[at + 1]];
        if self.big_endian {
            u16::from_be_bytes(v)
        } else {
            u16::from_le_bytes(v)
        }
    }

    fn u32(&self, b: &[u8], at: usize) -> u32 {
        let v = [b[at], b[at + 1], b[at + 2], b[at + 3]];
        if self.big_endian {
            u32::from_be_bytes(v)
        } else {
            u32::from_le_bytes(v)
        }
    }
}

/// One packet record.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Record<'a> {
    /// 1-based packet index.
    pub(crate) index: u64,
    /// Byte offset of the record header in the file.
    pub(crate) offset: u64,
    /// The captured bytes.
    pub(crate) data: &'a [u8],
}

/// Iterates over the records after the global header.
pub(crate) struct Records<'a> {
    header: PcapHeader,
    bytes: &'a [u8],
    pos: usize,
    index: u64,
    path: &'a Path,
}

impl<'a> Records<'a> {
    /// Records of `bytes`, whose global header is `header`.
    pub(crate) fn new(header: PcapHeader, bytes: &'a [u8], path: &'a Path) -> Self {
        Records {
            header,
            bytes,
            pos: GLOBAL_HEADER_LEN,
            index: 0,
            path,
        }
    }
}

impl<'a> Iterator for Records<'a> {
    type Item = Result<Record<'a>, VelodyneError>;

    fn next(&mut self) -> Option<Self::Item> {
        let left = self.bytes.len() - self.pos;
        if left == 0 {
            return None;
        }
        self.index += 1;
        let offset = self.pos as u64;
        let truncated = |reason: String| {
            Some(Err(VelodyneError::Truncated {
                path: self.path.into(),
                packet: self.index,
                offset,
                reason,
            }))
        };
        if left < RECORD_HEADER_LEN {
            self.pos = self.bytes.len();
            return truncated(format!(
                "the record header needs 16 bytes, the file ends after {left}"
            ));
        }
        let incl = self.header.u32(self.bytes, self.pos + 8) as usize;
        let body = left - RECORD_HEADER_LEN;
        if incl > body {
            self.pos = self.bytes.len();
            return truncated(format!(
                "the record holds {incl} bytes, the file ends after {body}"
            ));
        }
        let start = self.pos + RECORD_HEADER_LEN;
        self.pos = start + incl;
        Some(Ok(Record {
            index: self.index,
            offset,
            data: &self.bytes[start..start + incl],
        }))
    }
}

/// What a record carries, as far as this crate cares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Packet<'a> {
    /// A UDP datagram. `payload` is what was captured of it, `length` the
    /// payload length its header declares (larger when the snap length cut it).
    Udp {
        /// Destination port.
        dst_port: u16,
        /// Captured payload.
        payload: &'a [u8],
        /// Declared payload length.
        length: usize,
    },
    /// Anything else, with a short description.
    Other(Other),
}

/// A packet that is not IPv4/UDP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Other {
    /// A link-layer frame of another protocol (ARP, IPv6, …).
    EtherType(u16),
    /// IPv4 with another transport protocol.
    IpProtocol(u8),
    /// A fragment of an IPv4 datagram.
    Fragment,
    /// A header too short or inconsistent to read.
    Malformed(&'static str),
    /// A BSD loopback frame of another address family.
    Family(u32),
}

impl std::fmt::Display for Other {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Other::EtherType(t) => {
                let name = match t {
                    0x0806 => "ARP",
                    0x86dd => "IPv6",
                    0x88cc => "LLDP",
                    0x8035 => "RARP",
                    _ => "non-IPv4",
                };
                write!(f, "{name} (EtherType 0x{t:04x})")
            }
            Other::IpProtocol(p) => {
                let name = match p {
                    1 => "ICMP",
                    2 => "IGMP",
                    6 => "TCP",
                    _ => "non-UDP",
                };
                write!(f, "{name} (IPv4 protocol {p})")
            }
            Other::Fragment => f.write_str("IPv4 fragment"),
            Other::Malformed(what) => write!(f, "malformed {what}"),
            Other::Family(fam) => write!(f, "loopback address family {fam}"),
        }
    }
}

/// Strips the link layer, IPv4 and UDP headers of one captured frame.
pub(crate) fn parse_frame(link_type: u32, d: &[u8]) -> Packet<'_> {
    let ip = match link_type {
        // BSD loopback: 4-byte address family in the capturing host's order.
        0 => {
            if d.len() < 4 {
                return Packet::Other(Other::Malformed("loopback header"));
            }
            let le = u32::from_le_bytes([d[0], d[1], d[2], d[3]]);
            let be = u32::from_be_bytes([d[0], d[1], d[2], d[3]]);
            if le != 2 && be != 2 {
                return Packet::Other(Other::Family(le.min(be)));
            }
            &d[4..]
        }
        1 => {
            if d.len() < 14 {
                return Packet::Other(Other::Malformed("Ethernet header"));
            }
            let mut ethertype = be16(d, 12);
            let mut at = 14;
            // Up to two 802.1Q / 802.1ad VLAN tags.
            while matches!(ethertype, 0x8100 | 0x88a8) && at < 22 {
                if d.len() < at + 4 {
                    return Packet::Other(Other::Malformed("VLAN tag"));
                }
                ethertype = be16(d, at + 2);
                at += 4;
            }
            if ethertype != 0x0800 {
                return Packet::Other(Other::EtherType(ethertype));
            }
            &d[at..]
        }
        101 | 228 => d,
        113 => {
            if d.len() < 16 {
                return Packet::Other(Other::Malformed("Linux cooked (SLL) header"));
            }
            let proto = be16(d, 14);
            if proto != 0x0800 {
                return Packet::Other(Other::EtherType(proto));
            }
            &d[16..]
        }
        276 => {
            if d.len() < 20 {
                return Packet::Other(Other::Malformed("Linux cooked (SLL2) header"));
            }
            let proto = be16(d, 0);
            if proto != 0x0800 {
                return Packet::Other(Other::EtherType(proto));
            }
            &d[20..]
        }
        _ => return Packet::Other(Other::Malformed("link layer")),
    };
    parse_ipv4(ip)
}

fn parse_ipv4(ip: &[u8]) -> Packet<'_> {
    if ip.len() < 20 {
        return Packet::Other(Other::Malformed("IPv4 header"));
    }
    if ip[0] >> 4 != 4 {
        return match ip[0] >> 4 {
            6 => Packet::Other(Other::EtherType(0x86dd)),
            _ => Packet::Other(Other::Malformed("IP version")),
        };
    }
    let ihl = usize::from(ip[0] & 0x0f) * 4;
    let total = usize::from(be16(ip, 2));
    if ihl < 20 || ip.len() < ihl || total < ihl {
        return Packet::Other(Other::Malformed("IPv4 header"));
    }
    if ip[9] != 17 {
        return Packet::Other(Other::IpProtocol(ip[9]));
    }
    let frag = be16(ip, 6);
    if frag & 0x3fff != 0 {
        return Packet::Other(Other::Fragment);
    }
    // Ethernet pads short frames: trust the IP total length, not the frame.
    let ip = &ip[..total.min(ip.len())];
    let udp = &ip[ihl..];
    if udp.len() < 8 {
        return Packet::Other(Other::Malformed("UDP header"));
    }
    let declared = usize::from(be16(udp, 4));
    if declared < 8 || declared > total - ihl {
        return Packet::Other(Other::Malformed("UDP header"));
    }
    let end = declared.min(udp.len());
    Packet::Udp {
        dst_port: be16(udp, 2),
        payload: &udp[8..end],
        length: declared - 8,
    }
}

#[inline]
pub(crate) fn be16(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}

#[inline]
fn be32(b: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}
