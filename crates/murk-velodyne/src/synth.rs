//! Synthetic Velodyne captures (every [`SensorModel`]): the packet and pcap builders that this
//! crate's tests, benches and fuzz seeds share, public so that fixtures and
//! other crates' tests can write `.pcap` recordings too.
//!
//! Nothing here decodes: the builders write bytes field by field from the
//! VLP-16 manual's layout, so a test that round-trips through
//! [`crate::decode_pcap`] checks the decoder against an independent writer.

use crate::decode::{BLOCK_LEN, BLOCKS, DATA_PAYLOAD_LEN, POSITION_PAYLOAD_LEN};
use crate::options::{DATA_PORT, POSITION_PORT};
use crate::{ReturnMode, SensorModel};

/// One channel record: distance in the sensor's units (2 mm; 4 mm for the
/// VLP-32C; 0 = no return) and calibrated reflectivity.
pub type Channel = (u16, u8);

/// A VLP-16 data packet, field by field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DataPacket {
    /// The two flag bytes of each block (`[0xff, 0xee]` when valid).
    pub flags: [[u8; 2]; BLOCKS],
    /// Azimuth of each block, hundredths of a degree clockwise from forward.
    pub azimuths: [u16; BLOCKS],
    /// 32 channel records per block: VLP-16 and Puck Hi-Res, lasers 0–15
    /// of the first firing sequence, then lasers 0–15 of the second;
    /// HDL-32E and VLP-32C, lasers 0–31 of their one sequence.
    pub channels: [[Channel; 32]; BLOCKS],
    /// µs since the top of the hour.
    pub timestamp_us: u32,
    /// Return-mode byte (0x37 strongest, 0x38 last, 0x39 dual).
    pub return_mode: u8,
    /// Product-id byte (0x22 VLP-16, 0x21 HDL-32E, 0x24 Puck Hi-Res, 0x28
    /// VLP-32C).
    pub product: u8,
}

impl DataPacket {
    /// A VLP-16 packet with valid flags, every azimuth 0 and no return.
    pub fn new(mode: ReturnMode, timestamp_us: u32) -> Self {
        DataPacket {
            flags: [[0xff, 0xee]; BLOCKS],
            azimuths: [0; BLOCKS],
            channels: [[(0, 0); 32]; BLOCKS],
            timestamp_us,
            return_mode: mode.byte(),
            product: 0x22,
        }
    }

    /// The 1206-byte UDP payload.
    pub fn to_payload(&self) -> Vec<u8> {
        let mut p = Vec::with_capacity(DATA_PAYLOAD_LEN);
        for b in 0..BLOCKS {
            p.extend_from_slice(&self.flags[b]);
            p.extend_from_slice(&self.azimuths[b].to_le_bytes());
            for &(d, r) in &self.channels[b] {
                p.extend_from_slice(&d.to_le_bytes());
                p.push(r);
            }
        }
        debug_assert_eq!(p.len(), BLOCKS * BLOCK_LEN);
        p.extend_from_slice(&self.timestamp_us.to_le_bytes());
        p.push(self.return_mode);
        p.push(self.product);
        p
    }
}

/// A 512-byte position-packet payload (content is not decoded).
pub fn position_payload(timestamp_us: u32) -> Vec<u8> {
    let mut p = vec![0u8; POSITION_PAYLOAD_LEN];
    p[198..202].copy_from_slice(&timestamp_us.to_le_bytes());
    p
}

/// An IPv4 + UDP datagram around `payload` (192.168.1.201 → broadcast).
pub fn ipv4_udp(payload: &[u8], src_port: u16, dst_port: u16) -> Vec<u8> {
    let udp_len = 8 + payload.len();
    let total = 20 + udp_len;
    let mut d = Vec::with_capacity(total);
    d.extend_from_slice(&[0x45, 0x00]);
    d.extend_from_slice(&(total as u16).to_be_bytes());
    d.extend_from_slice(&[0, 0, 0x40, 0, 0xff, 17, 0, 0]);
    d.extend_from_slice(&[192, 168, 1, 201, 255, 255, 255, 255]);
    d.extend_from_slice(&src_port.to_be_bytes());
    d.extend_from_slice(&dst_port.to_be_bytes());
    d.extend_from_slice(&(udp_len as u16).to_be_bytes());
    d.extend_from_slice(&[0, 0]);
    d.extend_from_slice(payload);
    d
}

/// An Ethernet II frame carrying `ethertype` and `body`.
pub fn ethernet(ethertype: u16, body: &[u8]) -> Vec<u8> {
    let mut d = Vec::with_capacity(14 + body.len());
    d.extend_from_slice(&[0xff; 6]);
    d.extend_from_slice(&[0x60, 0x76, 0x88, 0x00, 0x00, 0x00]);
    d.extend_from_slice(&ethertype.to_be_bytes());
    d.extend_from_slice(body);
    d
}

/// An Ethernet frame with a UDP datagram from and to `port`.
pub fn ethernet_udp(payload: &[u8], port: u16) -> Vec<u8> {
    ethernet(0x0800, &ipv4_udp(payload, port, port))
}

/// An Ethernet ARP request (a typical foreign packet).
pub fn ethernet_arp() -> Vec<u8> {
    let mut arp = vec![0, 1, 8, 0, 6, 4, 0, 1];
    arp.extend_from_slice(&[0x60, 0x76, 0x88, 0, 0, 0, 192, 168, 1, 201]);
    arp.extend_from_slice(&[0, 0, 0, 0, 0, 0, 192, 168, 1, 77]);
    ethernet(0x0806, &arp)
}

/// Writes a classic libpcap file.
#[derive(Debug, Clone)]
pub struct PcapWriter {
    bytes: Vec<u8>,
    big_endian: bool,
}

impl PcapWriter {
    /// A capture of `link_type` (1 Ethernet, 113 SLL, 228 raw IPv4, …), in
    /// big- or little-endian byte order, with µs or ns timestamps.
    pub fn new(link_type: u32, big_endian: bool, nanoseconds: bool) -> Self {
        let mut w = PcapWriter {
            bytes: Vec::new(),
            big_endian,
        };
        w.u32(if nanoseconds {
            0xa1b2_3c4d
        } else {
            0xa1b2_c3d4
        });
        w.u16(2);
        w.u16(4);
        w.u32(0);
        w.u32(0);
        w.u32(65535);
        w.u32(link_type);
        w
    }

    /// Appends one record.
    pub fn push(&mut self, ts_sec: u32, ts_frac: u32, frame: &[u8]) -> &mut Self {
        self.u32(ts_sec);
        self.u32(ts_frac);
        self.u32(frame.len() as u32);
        self.u32(frame.len() as u32);
        self.bytes.extend_from_slice(frame);
        self
    }

    /// The file so far.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// The file.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    fn u16(&mut self, v: u16) {
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.bytes.extend_from_slice(&b);
    }

    fn u32(&mut self, v: u32) {
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.bytes.extend_from_slice(&b);
    }
}

/// The return a synthetic scene gives for `laser` at block azimuth
/// `azimuth` (hundredths of a degree); `second` asks for the strongest
/// block of a dual-return pair. Deterministic, 5–60 m, about one channel in
/// eleven without return, and one dual pair in three with a single return
/// (repeated in both blocks, as the sensor does).
pub fn scene(laser: usize, azimuth: u16, second: bool) -> Channel {
    let (l, a) = (laser as u32, u32::from(azimuth));
    if (l + a / 40) % 11 == 0 {
        return (0, 0);
    }
    let d = 2500 + (l * 7919 + a * 31) % 27500;
    let r = (l * 37 + a / 13) % 256;
    if second && (l + a / 40) % 3 != 0 {
        // A nearer, brighter return (e.g. a droplet before the wall).
        return ((d - 1000) as u16, ((r + 40) % 256) as u8);
    }
    (d as u16, r as u8)
}

/// A steadily spinning sensor looking at [`scene`].
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// Rotation speed, revolutions per minute (VLP-16: 300–1200).
    pub rpm: f64,
    /// Data packets to write.
    pub packets: usize,
    /// Azimuth of the first block, degrees clockwise from forward.
    pub start_azimuth_deg: f64,
    /// Recorded return mode.
    pub mode: ReturnMode,
    /// Timestamp of the first packet, µs past the hour.
    pub start_us: u32,
    /// Write a position packet after every this many data packets (0: never).
    pub position_every: usize,
    /// The sensor: its timing, lasers and product byte
    /// ([`SensorModel::product`]).
    pub model: SensorModel,
}

impl Default for Sweep {
    fn default() -> Self {
        Sweep {
            rpm: 600.0,
            packets: 100,
            start_azimuth_deg: 0.0,
            mode: ReturnMode::Strongest,
            start_us: 0,
            position_every: 0,
            model: SensorModel::Vlp16,
        }
    }
}

impl Sweep {
    /// Azimuth step between firing columns, hundredths of a degree.
    pub fn column_step(&self) -> f64 {
        self.rpm / 60.0 * 36000.0 * self.model.block_period_us() * 1e-6
    }

    /// The data packets.
    pub fn data_packets(&self) -> Vec<DataPacket> {
        let dual = self.mode == ReturnMode::Dual;
        let columns = if dual { BLOCKS / 2 } else { BLOCKS };
        let period = columns as f64 * self.model.block_period_us();
        let lasers = self.model.lasers();
        let step = self.column_step();
        (0..self.packets)
            .map(|n| {
                let ts = (f64::from(self.start_us) + n as f64 * period).round() as u64;
                let mut p = DataPacket::new(self.mode, (ts % 3_600_000_000) as u32);
                p.product = self.model.product();
                for b in 0..BLOCKS {
                    let column = n * columns + if dual { b / 2 } else { b };
                    let az = (self.start_azimuth_deg * 100.0 + column as f64 * step).round();
                    let az = (az as u64 % 36000) as u16;
                    p.azimuths[b] = az;
                    let second = dual && b % 2 == 1;
                    for ch in 0..32 {
                        p.channels[b][ch] = scene(ch % lasers, az, second);
                    }
                }
                p
            })
            .collect()
    }

    /// The capture as a little-endian µs Ethernet pcap.
    pub fn to_pcap(&self) -> Vec<u8> {
        let mut w = PcapWriter::new(1, false, false);
        for (n, p) in self.data_packets().iter().enumerate() {
            let t = u64::from(p.timestamp_us);
            let (sec, usec) = ((t / 1_000_000) as u32, (t % 1_000_000) as u32);
            w.push(sec, usec, &ethernet_udp(&p.to_payload(), DATA_PORT));
            if self.position_every > 0 && (n + 1) % self.position_every == 0 {
                let pos = position_payload(p.timestamp_us);
                w.push(sec, usec, &ethernet_udp(&pos, POSITION_PORT));
            }
        }
        w.into_bytes()
    }
}
