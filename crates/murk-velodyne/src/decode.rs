//! From pcap bytes to frames: packet classification, telling the sensor
//! (VLP-16, Puck Hi-Res, HDL-32E or VLP-32C, [`SensorModel`]), data-packet
//! decoding, azimuth interpolation and frame splitting.

use std::path::Path;

use murk_types::PointCloud;

use crate::pcap::{self, Other, Packet, Records};
use crate::{
    Capture, CaptureStats, ForeignPolicy, FrameStats, PcapOptions, ProductPolicy, ReturnMode,
    ReturnSelect, SensorModel, VelodyneError,
};

/// Payload length of a data packet.
pub const DATA_PAYLOAD_LEN: usize = 1206;
/// Payload length of a position packet.
pub const POSITION_PAYLOAD_LEN: usize = 512;
/// Blocks per data packet.
pub const BLOCKS: usize = 12;
/// Bytes per block: flag, azimuth, 32 channel records of 3 bytes.
pub const BLOCK_LEN: usize = 100;
/// Most lasers of a sensor this crate decodes (the HDL-32E's and VLP-32C's).
const MAX_LASERS: usize = 32;

/// The largest azimuth step accepted between two consecutive blocks (dual:
/// block pairs), hundredths of a degree: 2.5 times the 0.8° of a VLP-16 at
/// its fastest 1200 rpm. A larger step is corrupt data, not a rotation.
const MAX_BLOCK_STEP: u16 = 200;
/// A first frame starting within this azimuth after 0°, or a last frame
/// ending within it before 360°, covers the revolution (hundredths of a
/// degree; a VLP-16 at 1200 rpm fires every 0.4°).
const FULL_FRAME_EDGE: f32 = 100.0;
/// Microseconds in the hour that the packet timestamp counts.
const HOUR_US: i64 = 3_600_000_000;
/// Data packets read to tell a capture's sensor by its packet period.
const DETECT_PACKETS: usize = 64;

/// Decodes a classic libpcap capture held in memory.
///
/// Errors name the input `<bytes>`; use [`decode_pcap_named`] to give it a
/// name, or [`read_pcap_file`] to read a file.
pub fn decode_pcap(bytes: &[u8], opts: &PcapOptions) -> Result<Capture, VelodyneError> {
    decode_pcap_named(bytes, Path::new("<bytes>"), opts)
}

/// Reads and decodes a classic libpcap capture; errors name `path`.
/// The file is read once and not modified.
pub fn read_pcap_file(path: &Path, opts: &PcapOptions) -> Result<Capture, VelodyneError> {
    let bytes = std::fs::read(path).map_err(|source| VelodyneError::Io {
        path: path.into(),
        source,
    })?;
    decode_pcap_named(&bytes, path, opts)
}

/// Decodes a capture held in memory; errors name `name` (a path or any
/// label of where the bytes came from).
pub fn decode_pcap_named(
    bytes: &[u8],
    name: &Path,
    opts: &PcapOptions,
) -> Result<Capture, VelodyneError> {
    let header = pcap::parse_header(bytes, name)?;
    let mut stats = CaptureStats {
        link_type: header.link_type,
        ..CaptureStats::default()
    };
    let model = detect_model(header, bytes, name, opts)?;
    stats.sensor = Some(model);
    let mut frames = Assembler::new(opts.return_mode, model);
    let mut clock = Clock::default();

    for record in Records::new(header, bytes, name) {
        let record = match record {
            Ok(r) => r,
            // The records iterator reports a cut only at the end of the file.
            Err(e @ VelodyneError::Truncated { .. }) if opts.keep_truncated_tail => {
                stats.truncated_tail = Some(e.to_string());
                break;
            }
            Err(e) => return Err(e),
        };
        stats.packets_total += 1;
        let at = At {
            path: name,
            packet: record.index,
            offset: record.offset,
        };
        match classify(pcap::parse_frame(header.link_type, record.data), opts) {
            Kind::Data(payload) => {
                let packet = check_data(payload, opts, model, &at)?;
                let ts = clock.unwrap(packet.timestamp_us);
                *stats.return_modes.entry(packet.mode).or_default() += 1;
                *stats.product_ids.entry(packet.product).or_default() += 1;
                stats.packets_data += 1;
                frames.push_packet(payload, packet.mode, ts, &at)?;
            }
            Kind::Position => stats.packets_position += 1,
            Kind::Truncated(reason) => return Err(at.truncated(reason)),
            Kind::Foreign(what) => match opts.on_foreign {
                ForeignPolicy::Error => return Err(at.foreign(what)),
                ForeignPolicy::Skip => {
                    stats.packets_foreign_skipped += 1;
                    *stats.foreign_kinds.entry(what).or_default() += 1;
                }
            },
        }
    }
    if stats.packets_data == 0 {
        return Err(VelodyneError::NoData {
            path: name.into(),
            packets: stats.packets_total,
            position: stats.packets_position,
            foreign: stats.packets_foreign_skipped,
        });
    }
    stats.no_return = frames.no_return;
    stats.dual_duplicates = frames.dual_duplicates;
    let frames = frames.finish(opts.min_frame_points, &mut stats);
    Ok(Capture { frames, stats })
}

/// Where in the file a packet sits, for errors.
struct At<'a> {
    path: &'a Path,
    packet: u64,
    offset: u64,
}

impl At<'_> {
    fn bad(&self, reason: String) -> VelodyneError {
        VelodyneError::BadPacket {
            path: self.path.into(),
            packet: self.packet,
            offset: self.offset,
            reason,
        }
    }
    fn truncated(&self, reason: String) -> VelodyneError {
        VelodyneError::Truncated {
            path: self.path.into(),
            packet: self.packet,
            offset: self.offset,
            reason,
        }
    }
    fn foreign(&self, what: String) -> VelodyneError {
        VelodyneError::Foreign {
            path: self.path.into(),
            packet: self.packet,
            offset: self.offset,
            what,
        }
    }
}

/// What a record is to this crate.
enum Kind<'a> {
    /// A complete 1206-byte data payload with valid block flags.
    Data(&'a [u8]),
    Position,
    Truncated(String),
    Foreign(String),
}

fn classify<'a>(packet: Packet<'a>, opts: &PcapOptions) -> Kind<'a> {
    let (dst_port, payload, length) = match packet {
        Packet::Udp {
            dst_port,
            payload,
            length,
        } => (dst_port, payload, length),
        Packet::Other(Other::Malformed(what)) => {
            return Kind::Foreign(format!("malformed {what}"));
        }
        Packet::Other(other) => return Kind::Foreign(other.to_string()),
    };
    let on = |port: Option<u16>| port.is_none_or(|p| p == dst_port);
    let cut = |kind: &str| {
        Kind::Truncated(format!(
            "{kind} packet captured with {} of its {length} payload bytes (snap length too small)",
            payload.len()
        ))
    };
    if length == DATA_PAYLOAD_LEN && on(opts.port) {
        if payload.len() < length {
            return cut("data");
        }
        for b in 0..BLOCKS {
            let flag = &payload[b * BLOCK_LEN..b * BLOCK_LEN + 2];
            if flag != [0xff, 0xee] {
                return Kind::Foreign(format!(
                    "UDP to port {dst_port} with a 1206-byte payload whose block {b} flag is {:02x} {:02x}, not ff ee",
                    flag[0], flag[1]
                ));
            }
        }
        Kind::Data(payload)
    } else if length == POSITION_PAYLOAD_LEN && on(opts.position_port) {
        if payload.len() < length {
            return cut("position");
        }
        Kind::Position
    } else {
        Kind::Foreign(format!(
            "UDP to port {dst_port} with a {length}-byte payload (Velodyne sends 1206-byte data packets to port {} and 512-byte position packets to port {})",
            port_name(opts.port),
            port_name(opts.position_port)
        ))
    }
}

fn port_name(p: Option<u16>) -> String {
    p.map_or_else(|| "any".to_string(), |p| p.to_string())
}

/// The trailer of a data packet.
struct DataHeader {
    timestamp_us: u32,
    mode: ReturnMode,
    product: u8,
}

fn check_data(
    payload: &[u8],
    opts: &PcapOptions,
    model: SensorModel,
    at: &At,
) -> Result<DataHeader, VelodyneError> {
    let timestamp_us =
        u32::from_le_bytes([payload[1200], payload[1201], payload[1202], payload[1203]]);
    let mode_byte = payload[1204];
    let product = payload[1205];
    let mode = ReturnMode::from_byte(mode_byte).ok_or_else(|| {
        at.bad(format!(
            "unknown return-mode byte 0x{mode_byte:02x} at payload byte 1204 (expected 0x37 strongest, 0x38 last or 0x39 dual)"
        ))
    })?;
    if opts.products == ProductPolicy::Known {
        let reason = if SensorModel::from_product(product).is_none() {
            Some(format!(
                "{} packets are not a geometry murk decodes; only 0x22 (VLP-16), 0x23 (Puck LITE), 0x24 (Puck Hi-Res), 0x28 (VLP-32C) and 0x21 (HDL-32E, or a VLP-16 tagged so, told by the packet period) are (ProductPolicy::Any decodes any product as a VLP-16)",
                product_name(product)
            ))
        } else if !model.accepts_product(product) {
            Some(format!(
                "{} packets in a capture of {} packets: one capture holds one sensor",
                product_name(product),
                model.name()
            ))
        } else {
            None
        };
        if let Some(reason) = reason {
            return Err(VelodyneError::UnsupportedProduct {
                path: at.path.into(),
                packet: at.packet,
                offset: at.offset,
                product,
                reason,
            });
        }
    }
    if i64::from(timestamp_us) >= HOUR_US {
        return Err(at.bad(format!(
            "timestamp {timestamp_us} µs is past the hour (the field counts µs since the top of the hour)"
        )));
    }
    let available = match (opts.return_mode, mode) {
        (ReturnSelect::AsRecorded, _) | (_, ReturnMode::Dual) => true,
        (ReturnSelect::Strongest, m) => m == ReturnMode::Strongest,
        (ReturnSelect::Last, m) => m == ReturnMode::Last,
        (ReturnSelect::Both, _) => false,
    };
    if !available {
        return Err(VelodyneError::ReturnModeUnavailable {
            path: at.path.into(),
            packet: at.packet,
            offset: at.offset,
            asked: opts.return_mode,
            recorded: mode,
        });
    }
    Ok(DataHeader {
        timestamp_us,
        mode,
        product,
    })
}

/// The Velodyne model a product-id byte names.
pub fn product_name(product: u8) -> &'static str {
    match product {
        0x21 => "HDL-32E",
        0x22 => "VLP-16",
        0x23 => "Puck LITE",
        0x24 => "Puck Hi-Res",
        0x28 => "VLP-32C",
        0x31 => "Velarray",
        0xa1 => "VLS-128",
        _ => "unknown product",
    }
}

/// Turns the hour-relative packet timestamps into a monotone µs count.
#[derive(Default)]
struct Clock {
    last: Option<u32>,
    base: i64,
}

impl Clock {
    fn unwrap(&mut self, ts: u32) -> i64 {
        if let Some(last) = self.last {
            let jump = i64::from(ts) - i64::from(last);
            if jump < -HOUR_US / 2 {
                self.base += HOUR_US;
            } else if jump > HOUR_US / 2 {
                self.base -= HOUR_US;
            }
        }
        self.last = Some(ts);
        self.base + i64::from(ts)
    }
}

/// The sensor of a capture, from its first data packets: the one the first
/// packet's product byte names, unless it is 0x21 (the HDL-32E's id, which
/// VLP-16 captures carry too), then the sensor whose packet period (single
/// or dual return) the median gap between them is within 15 % of. A
/// product this crate does not decode is left to the decode that follows,
/// which refuses it. `ProductPolicy::Any`: the VLP-16, unchecked. Records
/// the scan cannot read are left to the decode too, which reports them.
fn detect_model(
    header: pcap::PcapHeader,
    bytes: &[u8],
    name: &Path,
    opts: &PcapOptions,
) -> Result<SensorModel, VelodyneError> {
    if opts.products == ProductPolicy::Any {
        return Ok(SensorModel::Vlp16);
    }
    let mut first: Option<(u64, u64)> = None;
    let mut clock = Clock::default();
    let mut prev: Option<i64> = None;
    let mut gaps: Vec<(f64, bool)> = Vec::new();
    let mut seen = 0;
    for record in Records::new(header, bytes, name) {
        let Ok(record) = record else { break };
        let Kind::Data(payload) = classify(pcap::parse_frame(header.link_type, record.data), opts)
        else {
            continue;
        };
        let product = payload[1205];
        if seen == 0 && product != 0x21 {
            return Ok(SensorModel::from_product(product).unwrap_or(SensorModel::Vlp16));
        }
        first.get_or_insert((record.index, record.offset));
        let ts = clock.unwrap(u32::from_le_bytes([
            payload[1200],
            payload[1201],
            payload[1202],
            payload[1203],
        ]));
        let dual = payload[1204] == ReturnMode::Dual.byte();
        if let Some(p) = prev {
            gaps.push(((ts - p) as f64, dual));
        }
        prev = Some(ts);
        seen += 1;
        if seen >= DETECT_PACKETS {
            break;
        }
    }
    let Some((packet, offset)) = first else {
        // No data packet: the decode says so.
        return Ok(SensorModel::Vlp16);
    };
    let refuse = |reason: String| {
        Err(VelodyneError::UnsupportedProduct {
            path: name.into(),
            packet,
            offset,
            product: 0x21,
            reason,
        })
    };
    let ratio = |model: SensorModel| {
        // Gaps from dropped packets or pauses say nothing about the period.
        let mut r: Vec<f64> = gaps
            .iter()
            .map(|&(g, dual)| g / model.packet_period_us(dual))
            .filter(|&r| r > 0.0 && r < 10.0)
            .collect();
        r.sort_by(f64::total_cmp);
        r.get(r.len() / 2).copied()
    };
    let within = |r: Option<f64>| r.is_some_and(|r| (0.85..=1.15).contains(&r));
    if gaps.len() < 2 {
        return refuse(
            "0x21 names the HDL-32E, and VLP-16 captures carry it too: the packet period tells them apart (1327 µs VLP-16, 553 µs HDL-32E, half in dual return), which needs at least 3 consecutive data packets (ProductPolicy::Any decodes it as a VLP-16 unchecked)".into(),
        );
    }
    if within(ratio(SensorModel::Vlp16)) {
        Ok(SensorModel::Vlp16)
    } else if within(ratio(SensorModel::Hdl32e)) {
        Ok(SensorModel::Hdl32e)
    } else {
        refuse(format!(
            "0x21 names the HDL-32E, and VLP-16 captures carry it too, but these packets come {:.0} % of the HDL-32E's period apart (553 µs single, 276 µs dual return) and {:.0} % of the VLP-16's (1327 µs, 664 µs): neither sensor (ProductPolicy::Any decodes it as a VLP-16 anyway)",
            100.0 * ratio(SensorModel::Hdl32e).unwrap_or(f64::NAN),
            100.0 * ratio(SensorModel::Vlp16).unwrap_or(f64::NAN)
        ))
    }
}

/// One channel record: distance (2 mm units) and reflectivity.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Return {
    distance: u16,
    reflectivity: u8,
}

#[inline]
fn channel(payload: &[u8], block: usize, ch: usize) -> Return {
    let o = block * BLOCK_LEN + 4 + ch * 3;
    Return {
        distance: u16::from_le_bytes([payload[o], payload[o + 1]]),
        reflectivity: payload[o + 2],
    }
}

/// Wraps an azimuth in hundredths of a degree within a turn of [0, 36000)
/// into it.
#[inline]
fn wrap(az: f32) -> f32 {
    if az >= 36000.0 {
        az - 36000.0
    } else if az < 0.0 {
        az + 36000.0
    } else {
        az
    }
}

/// Accumulates firings into frames.
struct Assembler {
    select: ReturnSelect,
    model: SensorModel,
    cos_el: [f32; MAX_LASERS],
    sin_el: [f32; MAX_LASERS],
    /// Each laser's horizontal offset, hundredths of a degree.
    az_offset: [f32; MAX_LASERS],
    /// Metres per distance unit.
    unit_m: f32,
    done: Vec<(PointCloud, FrameStats)>,
    cloud: PointCloud,
    meta: Option<FrameStats>,
    /// Timestamp of the current frame's first packet, µs.
    t0: i64,
    /// Timestamp of the packet being decoded, µs.
    ts: i64,
    prev_az: f32,
    no_return: u64,
    dual_duplicates: u64,
}

impl Assembler {
    fn new(select: ReturnSelect, model: SensorModel) -> Self {
        let mut cos_el = [0.0; MAX_LASERS];
        let mut sin_el = [0.0; MAX_LASERS];
        // Laser id = ring: the campaign format indexes elevations by laser id.
        for (l, e) in model.elevation_deg().iter().take(MAX_LASERS).enumerate() {
            let (s, c) = e.to_radians().sin_cos();
            cos_el[l] = c as f32;
            sin_el[l] = s as f32;
        }
        let mut az_offset = [0.0; MAX_LASERS];
        for (l, o) in model
            .azimuth_offset_deg()
            .iter()
            .take(MAX_LASERS)
            .enumerate()
        {
            az_offset[l] = (o * 100.0) as f32;
        }
        Assembler {
            select,
            model,
            cos_el,
            sin_el,
            az_offset,
            unit_m: model.distance_unit_m() as f32,
            done: Vec::new(),
            cloud: PointCloud::with_capacity(0),
            meta: None,
            t0: 0,
            ts: 0,
            prev_az: 0.0,
            no_return: 0,
            dual_duplicates: 0,
        }
    }

    /// Decodes one data packet (flags already checked).
    fn push_packet(
        &mut self,
        payload: &[u8],
        mode: ReturnMode,
        ts: i64,
        at: &At,
    ) -> Result<(), VelodyneError> {
        let mut az = [0u16; BLOCKS];
        for (b, a) in az.iter_mut().enumerate() {
            let o = b * BLOCK_LEN + 2;
            *a = u16::from_le_bytes([payload[o], payload[o + 1]]);
            // Sensors report a full turn as 36000 now and then (the real
            // test capture does once): it is 0°.
            if *a == 36000 {
                *a = 0;
            } else if *a > 36000 {
                return Err(at.bad(format!(
                    "block {b}: azimuth {} is above 36000 hundredths of a degree",
                    *a
                )));
            }
        }
        self.ts = ts;
        // Columns: one per firing time. Dual mode repeats each column in a
        // (last, strongest) block pair sharing its azimuth.
        let stride = if mode == ReturnMode::Dual { 2 } else { 1 };
        if stride == 2 {
            for k in 0..BLOCKS / 2 {
                if az[2 * k] != az[2 * k + 1] {
                    return Err(at.bad(format!(
                        "dual-return blocks {} and {} must share an azimuth, found {} and {}",
                        2 * k,
                        2 * k + 1,
                        az[2 * k],
                        az[2 * k + 1]
                    )));
                }
            }
        }
        let columns = BLOCKS / stride;
        let mut step = [0f32; BLOCKS];
        for c in 0..columns - 1 {
            let (a, b) = (az[c * stride], az[(c + 1) * stride]);
            let d = (i32::from(b) - i32::from(a)).rem_euclid(36000) as u16;
            if d > MAX_BLOCK_STEP {
                return Err(at.bad(format!(
                    "azimuth jumps from {:.2}° (block {}) to {:.2}° (block {}), more than {}° between consecutive firings",
                    f32::from(a) / 100.0,
                    c * stride,
                    f32::from(b) / 100.0,
                    (c + 1) * stride,
                    MAX_BLOCK_STEP / 100
                )));
            }
            step[c] = f32::from(d);
        }
        // The last column has no next block in the packet: it turns at the
        // rate of the one before.
        step[columns - 1] = step[columns - 2];

        let m = self.model;
        let (lasers, block_us) = (m.lasers(), m.block_period_us());
        for c in 0..columns {
            let base = f32::from(az[c * stride]);
            for s in 0..m.sequences_per_block() {
                let t_seq = c as f64 * block_us + s as f64 * m.sequence_period_us();
                self.firing(wrap(base + step[c] * 0.5 * s as f32), at.packet);
                for l in 0..lasers {
                    let ch = s * lasers + l;
                    let t_us = t_seq + m.firing_offset_us(l);
                    // Each laser fires at its own time in the sequence, so
                    // at its own azimuth (VLP-16 manual, "precise azimuth";
                    // the others likewise), plus its horizontal offset
                    // (VLP-32C).
                    let turned = step[c] * (t_us / block_us - c as f64) as f32;
                    let a = wrap(base + turned + self.az_offset[l]);
                    if stride == 1 {
                        self.emit(channel(payload, c, ch), l, a, t_us);
                    } else {
                        let last = channel(payload, 2 * c, ch);
                        let strongest = channel(payload, 2 * c + 1, ch);
                        self.emit_dual(last, strongest, l, a, t_us);
                    }
                }
            }
        }
        Ok(())
    }

    fn emit_dual(&mut self, last: Return, strongest: Return, l: usize, a: f32, t_us: f64) {
        match self.select {
            ReturnSelect::Last => self.emit(last, l, a, t_us),
            ReturnSelect::Strongest => {
                let pick = if last.distance == 0 {
                    strongest
                } else if strongest.distance == 0 || last.reflectivity > strongest.reflectivity {
                    last
                } else {
                    strongest
                };
                self.emit(pick, l, a, t_us);
            }
            ReturnSelect::Both | ReturnSelect::AsRecorded => {
                self.emit(last, l, a, t_us);
                if strongest == last {
                    if last.distance != 0 {
                        self.dual_duplicates += 1;
                    }
                } else {
                    self.emit(strongest, l, a, t_us);
                }
            }
        }
    }

    /// Starts a firing sequence at sensor azimuth `az` (hundredths of a
    /// degree), opening a new frame at the 360°→0° crossing.
    fn firing(&mut self, az: f32, packet: u64) {
        match self.meta.as_mut() {
            Some(m) if self.prev_az - az <= 18000.0 => {
                m.firings += 1;
                m.end_azimuth_deg = az / 100.0;
            }
            _ => {
                let capacity = self.cloud.len().max(1024);
                let cloud = std::mem::replace(&mut self.cloud, PointCloud::with_capacity(capacity));
                if let Some(mut meta) = self.meta.take() {
                    meta.points = cloud.len();
                    self.done.push((cloud, meta));
                }
                self.t0 = self.ts;
                self.meta = Some(FrameStats {
                    points: 0,
                    firings: 1,
                    partial: false,
                    first_packet: packet,
                    start_azimuth_deg: az / 100.0,
                    end_azimuth_deg: az / 100.0,
                });
            }
        }
        self.prev_az = az;
    }

    /// Appends one return as a point. Velodyne's frame has y forward, x right
    /// (azimuth clockwise from y); murk's has x forward, y left: so
    /// `x = r·cos ω·cos α`, `y = −r·cos ω·sin α`, `z = r·sin ω`.
    #[inline]
    fn emit(&mut self, ret: Return, laser: usize, az: f32, t_us: f64) {
        if ret.distance == 0 {
            self.no_return += 1;
            return;
        }
        let r = f32::from(ret.distance) * self.unit_m;
        let (s, c) = (az * (std::f32::consts::PI / 18000.0)).sin_cos();
        let horizontal = r * self.cos_el[laser];
        let time = (((self.ts - self.t0) as f64 + t_us) * 1e-6) as f32;
        self.cloud.push_timed(
            horizontal * c,
            -horizontal * s,
            r * self.sin_el[laser],
            f32::from(ret.reflectivity),
            laser as u16,
            time,
        );
    }

    /// Closes the last frame, flags partial frames, drops the small ones.
    fn finish(mut self, min_points: usize, stats: &mut CaptureStats) -> Vec<PointCloud> {
        if let Some(mut meta) = self.meta.take() {
            meta.points = self.cloud.len();
            let cloud = std::mem::take(&mut self.cloud);
            self.done.push((cloud, meta));
        }
        let n = self.done.len();
        if let Some((_, first)) = self.done.first_mut() {
            first.partial |= first.start_azimuth_deg * 100.0 > FULL_FRAME_EDGE;
        }
        if let Some((_, last)) = self.done.last_mut() {
            last.partial |= last.end_azimuth_deg * 100.0 < 36000.0 - FULL_FRAME_EDGE;
        }
        let mut frames = Vec::with_capacity(n);
        for (i, (cloud, meta)) in self.done.into_iter().enumerate() {
            let edge = i == 0 || i + 1 == n;
            if edge && meta.partial && meta.points < min_points {
                stats.frames_dropped += 1;
                stats.points_dropped += meta.points as u64;
                continue;
            }
            stats.points += meta.points as u64;
            stats.frames.push(meta);
            frames.push(cloud);
        }
        stats.first_frame_partial = stats.frames.first().is_some_and(|f| f.partial);
        stats.last_frame_partial = stats.frames.last().is_some_and(|f| f.partial);
        frames
    }
}
