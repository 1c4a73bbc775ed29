//! PCL `.pcd` files: header, `ascii`, `binary` and `binary_compressed` data.
//!
//! The header is read keyword by keyword (`VERSION FIELDS SIZE TYPE COUNT
//! WIDTH HEIGHT VIEWPOINT POINTS DATA`, in any order, `DATA` last). Fields are
//! found by name in any order; `x y z intensity` are required, `ring` and
//! `time` optional, any other field (`_` padding, `return_type`, …) is
//! skipped by its `SIZE × COUNT`. As in PCL, `_` fields take no room in
//! `binary_compressed` data or in `ascii` lines (a file that does count them
//! is accepted too). `VIEWPOINT` is checked and otherwise ignored: points are
//! returned in the file's frame.

use std::fmt::Write as _;
use std::path::Path;

use murk_types::{IntensityScale, PointCloud};

use crate::columns::{self, Field, Layout, Scalar};
use crate::{IoError, PcdData, ReadNotes, ReadOptions, ScaleSource, ring_lookup};

/// LZF never expands more than this: a 3-byte back reference yields at most
/// 264 bytes. A header claiming more is refused before anything is allocated.
const LZF_MAX_EXPANSION: u64 = 88;

/// One `FIELDS` entry.
#[derive(Debug)]
struct PcdField<'a> {
    name: &'a str,
    /// `None` for a type murk does not decode (only allowed for skipped fields).
    ty: Option<Scalar>,
    size: usize,
    count: usize,
}

impl PcdField<'_> {
    fn bytes(&self) -> usize {
        self.size * self.count
    }
    fn is_padding(&self) -> bool {
        self.name == "_"
    }
}

/// A parsed header.
#[derive(Debug)]
struct Header<'a> {
    fields: Vec<PcdField<'a>>,
    points: usize,
    data: PcdData,
    /// Byte offset of the data section.
    data_start: usize,
    /// 1-based line number of the `DATA` line.
    data_line: usize,
    /// The scale a `# murk: intensity_scale …` comment records.
    scale: Option<IntensityScale>,
}

/// The comment murk writes to record a cloud's intensity scale (PCD has no
/// field for it; comments are part of the format and other readers skip
/// them): `# murk: intensity_scale kitti`, or `… gain G offset O`.
const SCALE_COMMENT: &str = "# murk: intensity_scale";

/// The value of [`SCALE_COMMENT`] for `scale`.
fn scale_comment(scale: IntensityScale) -> String {
    match scale {
        IntensityScale::Linear { gain, offset }
            if scale != IntensityScale::KITTI && scale != IntensityScale::SIX_BIT =>
        {
            format!("gain {gain} offset {offset}")
        }
        s => s.describe(),
    }
}

/// Parses the value of a [`SCALE_COMMENT`].
fn parse_scale_comment(value: &str) -> Result<IntensityScale, String> {
    let tokens: Vec<&str> = value.split_ascii_whitespace().collect();
    match tokens[..] {
        [name] => IntensityScale::from_name(name).map_err(|e| e.to_string()),
        ["gain", g, "offset", o] => match (g.parse::<f32>(), o.parse::<f32>()) {
            (Ok(g), Ok(o)) => IntensityScale::linear(g, o).map_err(|e| e.to_string()),
            _ => Err(format!("{value:?}: gain and offset must be numbers")),
        },
        _ => Err(format!(
            "{value:?} is not a scale name or `gain G offset O`"
        )),
    }
}

/// A header keyword's values and line.
#[derive(Debug, Default)]
struct Entry<'a> {
    line: usize,
    values: Vec<&'a str>,
}

fn header_err(path: &Path, line: usize, reason: impl Into<String>) -> IoError {
    IoError::Header {
        path: path.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

/// Parses one unsigned integer header value.
fn header_uint(path: &Path, e: &Entry, key: &str, i: usize) -> Result<u64, IoError> {
    let v = e.values[i];
    v.parse::<u64>().map_err(|_| {
        header_err(
            path,
            e.line,
            format!("{key} value {v:?} is not a non-negative integer"),
        )
    })
}

fn parse_header<'a>(bytes: &'a [u8], path: &Path) -> Result<Header<'a>, IoError> {
    const KEYS: [&str; 9] = [
        "VERSION",
        "FIELDS",
        "SIZE",
        "TYPE",
        "COUNT",
        "WIDTH",
        "HEIGHT",
        "VIEWPOINT",
        "POINTS",
    ];
    let mut entries: [Option<Entry<'a>>; 9] = Default::default();
    let mut pos = 0usize;
    let mut line = 0usize;
    let mut scale = None;
    let (data, data_start, data_line) = loop {
        if pos >= bytes.len() {
            return Err(header_err(
                path,
                line.max(1),
                "the header ends before its DATA line",
            ));
        }
        let (raw, next) = match bytes[pos..].iter().position(|&b| b == b'\n') {
            Some(k) => (&bytes[pos..pos + k], pos + k + 1),
            None => (&bytes[pos..], bytes.len()),
        };
        line += 1;
        pos = next;
        let text = std::str::from_utf8(raw)
            .map_err(|_| header_err(path, line, "header line is not UTF-8 text"))?
            .trim();
        if let Some(value) = text.strip_prefix(SCALE_COMMENT) {
            scale = Some(parse_scale_comment(value.trim()).map_err(|e| {
                header_err(path, line, format!("murk's intensity_scale comment: {e}"))
            })?);
            continue;
        }
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut tokens = text.split_ascii_whitespace();
        let key = tokens.next().unwrap_or_default();
        let values: Vec<&'a str> = tokens.collect();
        let upper = key.to_ascii_uppercase();
        if upper == "DATA" {
            let [word] = values[..] else {
                return Err(header_err(
                    path,
                    line,
                    "DATA needs exactly one value: ascii, binary or binary_compressed",
                ));
            };
            let data = PcdData::from_name(&word.to_ascii_lowercase()).ok_or_else(|| {
                header_err(
                    path,
                    line,
                    format!("DATA {word:?} is not ascii, binary or binary_compressed"),
                )
            })?;
            break (data, pos, line);
        }
        let Some(k) = KEYS.iter().position(|&k| k == upper) else {
            return Err(header_err(
                path,
                line,
                format!("unknown header keyword {key:?} (is this a PCD file?)"),
            ));
        };
        if let Some(prev) = &entries[k] {
            return Err(header_err(
                path,
                line,
                format!("{upper} appears twice (first on line {})", prev.line),
            ));
        }
        if values.is_empty() {
            return Err(header_err(path, line, format!("{upper} has no value")));
        }
        entries[k] = Some(Entry { line, values });
    };
    let [
        _version,
        fields,
        size,
        ty,
        count,
        width,
        height,
        viewpoint,
        points,
    ] = entries;
    let need = |e: Option<Entry<'a>>, key: &str| {
        e.ok_or_else(|| header_err(path, data_line, format!("the header has no {key} line")))
    };
    let fields = need(fields, "FIELDS")?;
    let size = need(size, "SIZE")?;
    let ty = need(ty, "TYPE")?;
    let width = need(width, "WIDTH")?;
    let nf = fields.values.len();
    for (e, key) in [
        (Some(&size), "SIZE"),
        (Some(&ty), "TYPE"),
        (count.as_ref(), "COUNT"),
    ] {
        if let Some(e) = e
            && e.values.len() != nf
        {
            return Err(header_err(
                path,
                e.line,
                format!("{key} has {} values for {nf} FIELDS", e.values.len()),
            ));
        }
    }
    let mut out = Vec::with_capacity(nf);
    for i in 0..nf {
        let name = fields.values[i];
        let (t, s) = (ty.values[i], size.values[i]);
        let bytes = header_uint(path, &size, "SIZE", i)?;
        if !matches!(t, "F" | "U" | "I") || bytes == 0 || bytes > 1 << 16 {
            return Err(header_err(
                path,
                ty.line,
                format!("field {name}: TYPE {t} SIZE {s} is not a numeric type"),
            ));
        }
        let n = match &count {
            Some(c) => header_uint(path, c, "COUNT", i)?,
            None => 1,
        };
        if n == 0 || n > 1 << 16 {
            let line = count.as_ref().map_or(fields.line, |c| c.line);
            return Err(header_err(
                path,
                line,
                format!("field {name}: COUNT {n} is not in 1..=65536"),
            ));
        }
        out.push(PcdField {
            name,
            ty: Scalar::from_pcd(t, s),
            size: bytes as usize,
            count: n as usize,
        });
    }
    for (i, f) in out.iter().enumerate() {
        if !f.is_padding() && out[..i].iter().any(|g| g.name == f.name) {
            return Err(header_err(
                path,
                fields.line,
                format!("field {} is listed twice", f.name),
            ));
        }
    }
    let w = header_uint(path, &width, "WIDTH", 0)?;
    let h = match &height {
        Some(e) => header_uint(path, e, "HEIGHT", 0)?,
        None => 1,
    };
    let wh = w.checked_mul(h).ok_or_else(|| {
        header_err(
            path,
            width.line,
            format!("WIDTH {w} × HEIGHT {h} overflows"),
        )
    })?;
    let n = match &points {
        Some(e) => {
            let p = header_uint(path, e, "POINTS", 0)?;
            if p != wh {
                return Err(header_err(
                    path,
                    e.line,
                    format!("POINTS {p} differs from WIDTH {w} × HEIGHT {h} = {wh}"),
                ));
            }
            p
        }
        None => wh,
    };
    if let Some(v) = &viewpoint
        && (v.values.len() != 7 || v.values.iter().any(|s| s.parse::<f64>().is_err()))
    {
        return Err(header_err(
            path,
            v.line,
            "VIEWPOINT needs 7 numbers (tx ty tz qw qx qy qz)",
        ));
    }
    let points = usize::try_from(n)
        .map_err(|_| header_err(path, data_line, format!("{n} points is too many")))?;
    Ok(Header {
        fields: out,
        points,
        data,
        data_start,
        data_line,
        scale,
    })
}

/// Index of the field named `name`, checking it can be decoded as one value.
fn find_field(path: &Path, h: &Header, name: &'static str) -> Result<Option<usize>, IoError> {
    let Some(i) = h.fields.iter().position(|f| f.name == name) else {
        return Ok(None);
    };
    let f = &h.fields[i];
    if f.ty.is_none() {
        return Err(header_err(
            path,
            h.data_line,
            format!(
                "field {name} has SIZE {} which is not a numeric type murk reads (F4, F8, U1, U2, U4, U8, I1, I2, I4, I8)",
                f.size
            ),
        ));
    }
    if f.count != 1 {
        return Err(header_err(
            path,
            h.data_line,
            format!("field {name} has COUNT {}; murk reads COUNT 1", f.count),
        ));
    }
    Ok(Some(i))
}

/// The positions of the fields murk reads.
struct Wanted {
    x: usize,
    y: usize,
    z: usize,
    intensity: usize,
    ring: Option<usize>,
    time: Option<usize>,
}

impl Wanted {
    /// The binary layout of the wanted fields, `field(i)` locating the
    /// header's field `i`.
    fn layout<'a>(&self, field: impl Fn(usize) -> Field<'a>) -> Layout<'a> {
        Layout {
            x: field(self.x),
            y: field(self.y),
            z: field(self.z),
            intensity: field(self.intensity),
            ring: self.ring.map(&field),
            time: self.time.map(&field),
        }
    }
}

fn wanted(path: &Path, h: &Header) -> Result<Wanted, IoError> {
    let req = |name: &'static str| -> Result<usize, IoError> {
        find_field(path, h, name)?.ok_or_else(|| IoError::MissingField {
            path: path.to_path_buf(),
            field: name,
            found: h
                .fields
                .iter()
                .map(|f| f.name)
                .collect::<Vec<_>>()
                .join(", "),
        })
    };
    Ok(Wanted {
        x: req("x")?,
        y: req("y")?,
        z: req("z")?,
        intensity: req("intensity")?,
        ring: find_field(path, h, "ring")?,
        time: find_field(path, h, "time")?,
    })
}

/// Parses a `.pcd` file held in memory.
///
/// `source` names the file in errors. See the [module docs](crate) for how
/// `opts` supplies rings and the intensity scale.
pub fn parse_pcd(bytes: &[u8], source: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    parse_pcd_noted(bytes, source, opts).map(|(c, _)| c)
}

/// [`parse_pcd`] with what the caller should be told: where the intensity
/// scale came from (the option, murk's header comment, or the default) and
/// the fields the cloud does not carry.
pub(crate) fn parse_pcd_noted(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
) -> Result<(PointCloud, ReadNotes), IoError> {
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: source.to_path_buf(),
        });
    }
    let h = parse_header(bytes, source)?;
    let want = wanted(source, &h)?;
    let (scale, scale_source) = match (opts.declared_scale(), h.scale) {
        (Some(s), _) => (s, ScaleSource::Declared),
        (None, Some(s)) => (s, ScaleSource::File),
        (None, None) => (
            opts.scale_for(murk_types::PointFormat::Pcd),
            ScaleSource::Default,
        ),
    };
    let notes = ReadNotes {
        scale_source,
        dropped_fields: h
            .fields
            .iter()
            .filter(|f| {
                !f.is_padding()
                    && !matches!(f.name, "x" | "y" | "z" | "intensity" | "ring" | "time")
            })
            .map(|f| f.name.to_string())
            .collect(),
        ..ReadNotes::default()
    };
    parse_pcd_data(bytes, source, opts, &h, &want, scale).map(|c| (c, notes))
}

/// The data section of a PCD file whose header is `h`.
fn parse_pcd_data(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
    h: &Header,
    want: &Wanted,
    scale: IntensityScale,
) -> Result<PointCloud, IoError> {
    let lookup = match want.ring {
        Some(_) => None,
        None => Some(ring_lookup(source, opts)?),
    };
    let data = &bytes[h.data_start..];
    let n = h.points;
    let size_err = |expected: u64, found: usize, reason: String| IoError::DataSize {
        path: source.to_path_buf(),
        expected,
        found: found as u64,
        reason,
    };
    match h.data {
        PcdData::Ascii => parse_ascii(source, h, want, data, lookup.as_ref(), scale),
        PcdData::Binary => {
            let step: usize = h.fields.iter().map(PcdField::bytes).sum();
            let need = n.checked_mul(step);
            if need != Some(data.len()) {
                return Err(size_err(
                    need.map_or(u64::MAX, |v| v as u64),
                    data.len(),
                    format!("DATA binary with {n} points of {step} bytes"),
                ));
            }
            let mut offsets = Vec::with_capacity(h.fields.len());
            let mut off = 0;
            for f in &h.fields {
                offsets.push(off);
                off += f.bytes();
            }
            let field = |i: usize| Field {
                bytes: data,
                stride: step,
                offset: offsets[i],
                ty: h.fields[i].ty.expect("checked by find_field"),
            };
            columns::decode(source, &want.layout(field), n, lookup.as_ref(), scale)
        }
        PcdData::BinaryCompressed => {
            if data.len() < 8 {
                return Err(size_err(
                    8,
                    data.len(),
                    "DATA binary_compressed needs its two size words".into(),
                ));
            }
            let comp = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) as usize;
            let uncomp = u32::from_le_bytes([data[4], data[5], data[6], data[7]]) as usize;
            let payload = &data[8..];
            if payload.len() != comp {
                return Err(size_err(
                    comp as u64 + 8,
                    data.len(),
                    format!("DATA binary_compressed announcing {comp} compressed bytes"),
                ));
            }
            let packed: usize = h
                .fields
                .iter()
                .filter(|f| !f.is_padding())
                .map(PcdField::bytes)
                .sum();
            let full: usize = h.fields.iter().map(PcdField::bytes).sum();
            let skip_padding = if n.checked_mul(packed) == Some(uncomp) {
                true
            } else if n.checked_mul(full) == Some(uncomp) {
                false
            } else {
                return Err(size_err(
                    n.checked_mul(packed).map_or(u64::MAX, |v| v as u64),
                    uncomp,
                    format!(
                        "uncompressed size word of DATA binary_compressed ({n} points of {packed} bytes)"
                    ),
                ));
            };
            let offset = h.data_start + 8;
            let buf = if uncomp == 0 {
                Vec::new()
            } else {
                if uncomp as u64 > LZF_MAX_EXPANSION * comp as u64 {
                    return Err(IoError::Compression {
                        path: source.to_path_buf(),
                        offset,
                        reason: format!(
                            "{comp} compressed bytes cannot expand to the announced {uncomp} bytes"
                        ),
                    });
                }
                lzf::decompress(payload, uncomp).map_err(|e| IoError::Compression {
                    path: source.to_path_buf(),
                    offset,
                    reason: e.to_string(),
                })?
            };
            if buf.len() != uncomp {
                return Err(size_err(
                    uncomp as u64,
                    buf.len(),
                    "decompressed DATA binary_compressed".into(),
                ));
            }
            // Field-by-field layout: each field's n values are contiguous.
            let mut starts = vec![0usize; h.fields.len()];
            let mut off = 0;
            for (i, f) in h.fields.iter().enumerate() {
                if skip_padding && f.is_padding() {
                    continue;
                }
                starts[i] = off;
                off += n * f.bytes();
            }
            let field = |i: usize| {
                let f = &h.fields[i];
                Field {
                    bytes: &buf[starts[i]..starts[i] + n * f.bytes()],
                    stride: f.bytes(),
                    offset: 0,
                    ty: f.ty.expect("checked by find_field"),
                }
            };
            columns::decode(source, &want.layout(field), n, lookup.as_ref(), scale)
        }
    }
}

/// `DATA ascii`: one point per non-blank line, whitespace-separated tokens.
fn parse_ascii(
    path: &Path,
    h: &Header,
    want: &Wanted,
    data: &[u8],
    lookup: Option<&crate::ring::RingLookup>,
    scale: murk_types::IntensityScale,
) -> Result<PointCloud, IoError> {
    // Token index of each field, without and with `_` padding tokens.
    let mut first_token = [Vec::new(), Vec::new()];
    let mut totals = [0usize; 2];
    for f in &h.fields {
        for (k, with_padding) in [false, true].into_iter().enumerate() {
            first_token[k].push(totals[k]);
            if with_padding || !f.is_padding() {
                totals[k] += f.count;
            }
        }
    }
    let n = h.points;
    // Never trust the header for an allocation: a point needs ≥ 2 bytes per token.
    let cap = n.min(data.len() / (2 * totals[0].max(1)) + 1);
    let mut cloud = PointCloud::with_capacity(cap);
    cloud.intensity_scale = scale;
    let mut time = Vec::new();
    let mut lines = data.split(|&b| b == b'\n');
    let mut line_no = h.data_line;
    let mut tokens: Vec<&str> = Vec::with_capacity(totals[1]);
    let parse_err = |line: usize, column: &str, reason: String| IoError::Parse {
        path: path.to_path_buf(),
        line: line as u64,
        column: column.to_string(),
        reason,
    };
    while let Some(raw) = lines.next() {
        line_no += 1;
        let text = std::str::from_utf8(raw)
            .map_err(|_| parse_err(line_no, "-", "line is not UTF-8 text".into()))?;
        tokens.clear();
        tokens.extend(text.split_ascii_whitespace());
        if tokens.is_empty() {
            continue;
        }
        let i = cloud.len();
        if i == n {
            return Err(IoError::PointCount {
                path: path.to_path_buf(),
                line: line_no,
                expected: n as u64,
                found: n as u64 + 1 + lines.filter(|l| !l.trim_ascii().is_empty()).count() as u64,
            });
        }
        let layout = if tokens.len() == totals[0] {
            0
        } else if tokens.len() == totals[1] {
            1
        } else {
            return Err(parse_err(
                line_no,
                "-",
                format!(
                    "{} values for {} fields (point {i})",
                    tokens.len(),
                    totals[0]
                ),
            ));
        };
        let tok = |f: usize| tokens[first_token[layout][f]];
        let mut val = [0f32; 4];
        for (k, (f, name)) in [
            (want.x, "x"),
            (want.y, "y"),
            (want.z, "z"),
            (want.intensity, "intensity"),
        ]
        .into_iter()
        .enumerate()
        {
            let t = tok(f);
            let v = t
                .parse::<f32>()
                .map_err(|_| parse_err(line_no, name, format!("{t:?} is not a number")))?;
            if !v.is_finite() {
                return Err(columns::non_finite(path, i, name, f64::from(v)));
            }
            val[k] = v;
        }
        let [x, y, z, v] = val;
        cloud.x.push(x);
        cloud.y.push(y);
        cloud.z.push(z);
        cloud.intensity.push(v);
        if let Some(f) = want.ring {
            let t = tok(f);
            let r = t
                .parse::<f64>()
                .map_err(|_| parse_err(line_no, "ring", format!("{t:?} is not a number")))
                .and_then(|r| {
                    columns::ring_id(r).map_err(|reason| IoError::BadValue {
                        path: path.to_path_buf(),
                        point: i,
                        field: "ring",
                        reason,
                    })
                })?;
            cloud.ring.push(r);
        }
        if let Some(f) = want.time {
            let t = tok(f);
            let v = t
                .parse::<f64>()
                .map_err(|_| parse_err(line_no, "time", format!("{t:?} is not a number")))?;
            if !v.is_finite() {
                return Err(columns::non_finite(path, i, "time", v));
            }
            time.push(v);
        }
    }
    if cloud.len() != n {
        return Err(IoError::PointCount {
            path: path.to_path_buf(),
            line: line_no,
            expected: n as u64,
            found: cloud.len() as u64,
        });
    }
    if let Some(lookup) = lookup {
        let mut ring = Vec::with_capacity(n);
        lookup.extend(&mut ring, &cloud.x, &cloud.y, &cloud.z);
        cloud.ring = ring;
    }
    if want.time.is_some() {
        cloud.time = Some(columns::time_to_f32(path, &time)?);
    }
    Ok(cloud)
}

/// The header murk writes.
fn header(cloud: &PointCloud, data: PcdData) -> String {
    let n = cloud.len();
    let timed = cloud.time.is_some();
    let t = if timed { " time" } else { "" };
    let s = if timed { " 4" } else { "" };
    let ty = if timed { " F" } else { "" };
    let c = if timed { " 1" } else { "" };
    let comment = if cloud.intensity_scale == IntensityScale::Calibrated {
        String::new()
    } else {
        format!("{SCALE_COMMENT} {}\n", scale_comment(cloud.intensity_scale))
    };
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\n\
         {comment}VERSION 0.7\n\
         FIELDS x y z intensity ring{t}\n\
         SIZE 4 4 4 4 2{s}\n\
         TYPE F F F F U{ty}\n\
         COUNT 1 1 1 1 1{c}\n\
         WIDTH {n}\n\
         HEIGHT 1\n\
         VIEWPOINT 0 0 0 1 0 0 0\n\
         POINTS {n}\n\
         DATA {}\n",
        data.name()
    )
}

/// Encodes `cloud` as a PCD file (`x y z intensity ring` + `time` if present).
///
/// The cloud must have passed the writer's checks (equal column lengths).
pub(crate) fn encode_pcd(
    cloud: &PointCloud,
    data: PcdData,
    path: &Path,
) -> Result<Vec<u8>, IoError> {
    let n = cloud.len();
    let head = header(cloud, data);
    let step = 18 + if cloud.time.is_some() { 4 } else { 0 };
    match data {
        PcdData::Ascii => {
            let mut s = head;
            s.reserve(n * 40);
            for i in 0..n {
                // `Display` of f32 is the shortest decimal that reads back
                // to the same f32, so ascii files round-trip exactly.
                let _ = write!(
                    s,
                    "{} {} {} {} {}",
                    cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i], cloud.ring[i]
                );
                if let Some(t) = &cloud.time {
                    let _ = write!(s, " {}", t[i]);
                }
                s.push('\n');
            }
            Ok(s.into_bytes())
        }
        PcdData::Binary => {
            let mut out = Vec::with_capacity(head.len() + n * step);
            out.extend_from_slice(head.as_bytes());
            for i in 0..n {
                out.extend_from_slice(&cloud.x[i].to_le_bytes());
                out.extend_from_slice(&cloud.y[i].to_le_bytes());
                out.extend_from_slice(&cloud.z[i].to_le_bytes());
                out.extend_from_slice(&cloud.intensity[i].to_le_bytes());
                out.extend_from_slice(&cloud.ring[i].to_le_bytes());
                if let Some(t) = &cloud.time {
                    out.extend_from_slice(&t[i].to_le_bytes());
                }
            }
            Ok(out)
        }
        PcdData::BinaryCompressed => {
            let mut soa = Vec::with_capacity(n * step);
            for col in [&cloud.x, &cloud.y, &cloud.z, &cloud.intensity] {
                soa.extend(col.iter().flat_map(|v| v.to_le_bytes()));
            }
            soa.extend(cloud.ring.iter().flat_map(|v| v.to_le_bytes()));
            if let Some(t) = &cloud.time {
                soa.extend(t.iter().flat_map(|v| v.to_le_bytes()));
            }
            let too_big = |what: &str| IoError::InvalidCloud {
                path: path.to_path_buf(),
                point: 0,
                reason: format!(
                    "{n} points need {what} beyond binary_compressed's 4 GiB limit; use DATA binary"
                ),
            };
            let uncomp = u32::try_from(soa.len()).map_err(|_| too_big("a data block"))?;
            let packed = compress_lzf(&soa).map_err(|reason| IoError::Compression {
                path: path.to_path_buf(),
                offset: head.len() + 8,
                reason,
            })?;
            let comp = u32::try_from(packed.len()).map_err(|_| too_big("a compressed block"))?;
            let mut out = Vec::with_capacity(head.len() + 8 + packed.len());
            out.extend_from_slice(head.as_bytes());
            out.extend_from_slice(&comp.to_le_bytes());
            out.extend_from_slice(&uncomp.to_le_bytes());
            out.extend_from_slice(&packed);
            Ok(out)
        }
    }
}

/// LZF-compresses `data`, falling back to an all-literal LZF stream when the
/// data does not shrink.
fn compress_lzf(data: &[u8]) -> Result<Vec<u8>, String> {
    match lzf::compress(data) {
        Ok(c) => Ok(c),
        // Hand-written fallback: the `lzf` crate refuses output larger than
        // its input, which PCL allows; runs of ≤ 32 literals (control byte
        // `len - 1`) are a valid LZF stream any decoder reads.
        Err(lzf::LzfError::NoCompressionPossible) => {
            let mut out = Vec::with_capacity(data.len() + data.len() / 32 + 1);
            for run in data.chunks(32) {
                out.push((run.len() - 1) as u8);
                out.extend_from_slice(run);
            }
            Ok(out)
        }
        Err(e) => Err(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lzf_crate_compresses_and_decompresses() {
        // Repetitive data shrinks and comes back identical.
        let data: Vec<u8> = (0..10_000u32).flat_map(|i| (i % 7).to_le_bytes()).collect();
        let c = compress_lzf(&data).unwrap();
        assert!(c.len() < data.len() / 4, "{} bytes", c.len());
        assert_eq!(lzf::decompress(&c, data.len()).unwrap(), data);
    }

    #[test]
    fn incompressible_data_falls_back_to_literal_runs() {
        // A xorshift byte stream has no 3-byte repeats within LZF's window.
        let mut s = 0x9E37_79B9u32;
        let data: Vec<u8> = (0..1000)
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s >> 24) as u8
            })
            .collect();
        assert_eq!(
            lzf::compress(&data),
            Err(lzf::LzfError::NoCompressionPossible)
        );
        let c = compress_lzf(&data).unwrap();
        assert_eq!(c.len(), 1000 + 32);
        assert_eq!(lzf::decompress(&c, data.len()).unwrap(), data);
        // Tiny inputs (which the crate refuses) are literal streams too.
        assert_eq!(compress_lzf(&[5]).unwrap(), vec![0, 5]);
        assert_eq!(compress_lzf(&[]).unwrap(), Vec::<u8>::new());
    }
}
