//! CSV point clouds: `x,y,z,intensity,ring[,time]` and VeloView exports.
//!
//! Columns are matched by name, case-insensitively, after trimming spaces
//! and quotes, in any order; other columns are ignored:
//!
//! | field | accepted headers |
//! |---|---|
//! | x, y, z | `x`, `y`, `z`; VeloView `Points_m_XYZ:0..2`; ParaView `Points:0..2` |
//! | intensity | `intensity` |
//! | ring (optional) | `ring`, VeloView `laser_id` |
//! | time (optional) | `time` (seconds; VeloView's `timestamp`/`adjustedtime` are not read) |
//!
//! When an export has several columns for one coordinate (VeloView writes
//! `Points_m_XYZ:0` and, in some versions, `X` too), `Points_m_XYZ` wins
//! over `Points`, which wins over a plain `x`; two columns of the same kind
//! for one field are an error.
//!
//! Without a ring column the ring comes from each point's elevation.

use std::fmt::Write as _;
use std::path::Path;

use murk_types::{PointCloud, PointFormat};

use crate::columns;
use crate::{IoError, ReadOptions, ring_lookup};

/// The fields murk reads, in `FIELDS` order.
const FIELDS: [&str; 6] = ["x", "y", "z", "intensity", "ring", "time"];

/// Which field a header names, if any, and its precedence (lower wins).
fn field_of(header: &str) -> Option<(usize, u8)> {
    let h = header.trim().trim_matches('"').trim().to_ascii_lowercase();
    Some(match h.as_str() {
        "points_m_xyz:0" => (0, 0),
        "points_m_xyz:1" => (1, 0),
        "points_m_xyz:2" => (2, 0),
        "points:0" => (0, 1),
        "points:1" => (1, 1),
        "points:2" => (2, 1),
        "x" => (0, 2),
        "y" => (1, 2),
        "z" => (2, 2),
        "intensity" => (3, 0),
        "ring" | "laser_id" => (4, 0),
        "time" => (5, 0),
        _ => return None,
    })
}

/// Parses a CSV point cloud held in memory.
///
/// ```
/// use std::path::Path;
/// use murk_io::{parse_csv, ReadOptions};
///
/// let text = "\"Points_m_XYZ:0\",\"Points_m_XYZ:1\",\"Points_m_XYZ:2\",\"intensity\",\"laser_id\",\"azimuth\"\n\
///             1.5,-2.25,0.125,17,14,9001\n";
/// let cloud = parse_csv(text.as_bytes(), Path::new("veloview.csv"), &ReadOptions::default())?;
/// assert_eq!((cloud.x[0], cloud.y[0], cloud.z[0]), (1.5, -2.25, 0.125));
/// assert_eq!((cloud.intensity[0], cloud.ring[0]), (17.0, 14));
/// # Ok::<(), murk_io::IoError>(())
/// ```
pub fn parse_csv(bytes: &[u8], source: &Path, opts: &ReadOptions) -> Result<PointCloud, IoError> {
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: source.to_path_buf(),
        });
    }
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_reader(bytes);
    let parse_err = |line: u64, column: &str, reason: String| IoError::Parse {
        path: source.to_path_buf(),
        line,
        column: column.to_string(),
        reason,
    };
    let csv_err = |e: csv::Error| {
        let line = e.position().map_or(0, csv::Position::line);
        parse_err(line, "-", e.to_string())
    };
    let headers = rdr.byte_headers().map_err(csv_err)?.clone();
    let mut names = Vec::with_capacity(headers.len());
    // Column index and precedence of each field.
    let mut chosen: [Option<(usize, u8)>; 6] = [None; 6];
    for (j, h) in headers.iter().enumerate() {
        let name = std::str::from_utf8(h)
            .map_err(|_| parse_err(1, &(j + 1).to_string(), "header is not UTF-8".into()))?;
        names.push(name.to_string());
        if let Some((f, rank)) = field_of(name) {
            match chosen[f] {
                Some((prev, r)) if r == rank => {
                    return Err(parse_err(
                        1,
                        name,
                        format!(
                            "column {} and column {} both give {}",
                            prev + 1,
                            j + 1,
                            FIELDS[f]
                        ),
                    ));
                }
                Some((_, r)) if r < rank => {}
                _ => chosen[f] = Some((j, rank)),
            }
        }
    }
    let col = chosen.map(|c| c.map(|(j, _)| j));
    let mut req = [0usize; 4];
    for f in 0..4 {
        req[f] = col[f].ok_or_else(|| IoError::MissingField {
            path: source.to_path_buf(),
            field: FIELDS[f],
            found: names.join(", "),
        })?;
    }
    let lookup = match col[4] {
        Some(_) => None,
        None => Some(ring_lookup(source, opts)?),
    };
    let mut cloud = PointCloud::with_capacity(bytes.len() / 32);
    cloud.intensity_scale = opts.scale_for(PointFormat::Csv);
    let mut time = Vec::new();
    let mut rec = csv::ByteRecord::new();
    while rdr.read_byte_record(&mut rec).map_err(csv_err)? {
        let line = rec.position().map_or(0, csv::Position::line);
        let i = cloud.len();
        let cell = |j: usize| -> Result<&str, IoError> {
            let c = rec.get(j).unwrap_or_default();
            let s = std::str::from_utf8(c)
                .map_err(|_| parse_err(line, &names[j], "cell is not UTF-8".into()))?;
            if s.is_empty() {
                return Err(parse_err(line, &names[j], "empty cell".into()));
            }
            Ok(s)
        };
        let mut v = [0f32; 4];
        for f in 0..4 {
            let j = req[f];
            let s = cell(j)?;
            v[f] = s
                .parse::<f32>()
                .map_err(|_| parse_err(line, &names[j], format!("{s:?} is not a number")))?;
            if !v[f].is_finite() {
                return Err(columns::non_finite(source, i, FIELDS[f], f64::from(v[f])));
            }
        }
        cloud.x.push(v[0]);
        cloud.y.push(v[1]);
        cloud.z.push(v[2]);
        cloud.intensity.push(v[3]);
        if let Some(j) = col[4] {
            let s = cell(j)?;
            let r = s
                .parse::<f64>()
                .map_err(|_| parse_err(line, &names[j], format!("{s:?} is not a number")))?;
            let r = columns::ring_id(r).map_err(|reason| IoError::BadValue {
                path: source.to_path_buf(),
                point: i,
                field: "ring",
                reason,
            })?;
            cloud.ring.push(r);
        }
        if let Some(j) = col[5] {
            let s = cell(j)?;
            let t = s
                .parse::<f64>()
                .map_err(|_| parse_err(line, &names[j], format!("{s:?} is not a number")))?;
            if !t.is_finite() {
                return Err(columns::non_finite(source, i, "time", t));
            }
            time.push(t);
        }
    }
    if let Some(lookup) = lookup {
        let mut ring = Vec::with_capacity(cloud.len());
        lookup.extend(&mut ring, &cloud.x, &cloud.y, &cloud.z);
        cloud.ring = ring;
    }
    if col[5].is_some() {
        cloud.time = Some(columns::time_to_f32(source, &time)?);
    }
    Ok(cloud)
}

/// Encodes `cloud` as `x,y,z,intensity,ring[,time]` CSV (shortest
/// round-trip decimals).
pub(crate) fn encode_csv(cloud: &PointCloud, path: &Path) -> Result<Vec<u8>, IoError> {
    let io = |e: csv::Error| IoError::Io {
        path: path.to_path_buf(),
        action: "encode CSV",
        source: e.into(),
    };
    let mut w = csv::Writer::from_writer(Vec::with_capacity(cloud.len() * 40));
    let ncol = if cloud.time.is_some() { 6 } else { 5 };
    w.write_record(&FIELDS[..ncol]).map_err(io)?;
    let mut cell = String::new();
    for i in 0..cloud.len() {
        for v in [cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i]] {
            cell.clear();
            let _ = write!(cell, "{v}");
            w.write_field(&cell).map_err(io)?;
        }
        cell.clear();
        let _ = write!(cell, "{}", cloud.ring[i]);
        w.write_field(&cell).map_err(io)?;
        if let Some(t) = &cloud.time {
            cell.clear();
            let _ = write!(cell, "{}", t[i]);
            w.write_field(&cell).map_err(io)?;
        }
        w.write_record(None::<&[u8]>).map_err(io)?;
    }
    w.into_inner().map_err(|e| IoError::Io {
        path: path.to_path_buf(),
        action: "encode CSV",
        source: e.into_error(),
    })
}
