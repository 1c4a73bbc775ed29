//! Apache Parquet point clouds through polars: columns `x y z intensity ring`
//! (+ `time`), any integer or float type, cast on read.

use std::io::Cursor;
use std::path::Path;

use murk_types::{PointCloud, PointFormat};
use polars::prelude::*;

use crate::columns;
use crate::{IoError, ReadOptions, ring_lookup};

fn pq_err(path: &Path, e: impl std::fmt::Display) -> IoError {
    IoError::Parquet {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// The values of column `name` as `f64`, or `None` when the column is absent.
fn column_f64(
    df: &DataFrame,
    name: &'static str,
    path: &Path,
) -> Result<Option<Vec<f64>>, IoError> {
    let Ok(col) = df.column(name) else {
        return Ok(None);
    };
    if !col.dtype().is_primitive_numeric() {
        return Err(IoError::ColumnType {
            path: path.to_path_buf(),
            column: name.to_string(),
            reason: format!("type {} is not a number", col.dtype()),
        });
    }
    let cast = col.cast(&DataType::Float64).map_err(|e| pq_err(path, e))?;
    let ca = cast.f64().map_err(|e| pq_err(path, e))?;
    let mut out = Vec::with_capacity(ca.len());
    for (i, v) in ca.iter().enumerate() {
        out.push(v.ok_or_else(|| IoError::BadValue {
            path: path.to_path_buf(),
            point: i,
            field: name,
            reason: "null".into(),
        })?);
    }
    Ok(Some(out))
}

/// Parses a Parquet point cloud held in memory.
pub fn parse_parquet(
    bytes: &[u8],
    source: &Path,
    opts: &ReadOptions,
) -> Result<PointCloud, IoError> {
    if bytes.is_empty() {
        return Err(IoError::Empty {
            path: source.to_path_buf(),
        });
    }
    let df = ParquetReader::new(Cursor::new(bytes))
        .finish()
        .map_err(|e| pq_err(source, e))?;
    let found = || {
        df.get_column_names()
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut cloud = PointCloud::with_capacity(df.height());
    cloud.intensity_scale = opts.scale_for(PointFormat::Parquet);
    let cols: [(&mut Vec<f32>, &'static str); 4] = [
        (&mut cloud.x, "x"),
        (&mut cloud.y, "y"),
        (&mut cloud.z, "z"),
        (&mut cloud.intensity, "intensity"),
    ];
    for (dst, name) in cols {
        let v = column_f64(&df, name, source)?.ok_or_else(|| IoError::MissingField {
            path: source.to_path_buf(),
            field: name,
            found: found(),
        })?;
        dst.extend(v.iter().map(|&a| a as f32));
        if let Some(i) = columns::first_non_finite(dst) {
            return Err(columns::non_finite(source, i, name, v[i]));
        }
    }
    match column_f64(&df, "ring", source)? {
        Some(v) => {
            for (i, &r) in v.iter().enumerate() {
                let id = columns::ring_id(r).map_err(|reason| IoError::BadValue {
                    path: source.to_path_buf(),
                    point: i,
                    field: "ring",
                    reason,
                })?;
                cloud.ring.push(id);
            }
        }
        None => {
            let lookup = ring_lookup(source, opts)?;
            let mut ring = Vec::with_capacity(cloud.len());
            lookup.extend(&mut ring, &cloud.x, &cloud.y, &cloud.z);
            cloud.ring = ring;
        }
    }
    if let Some(t) = column_f64(&df, "time", source)? {
        if let Some(i) = t.iter().position(|v| !v.is_finite()) {
            return Err(columns::non_finite(source, i, "time", t[i]));
        }
        cloud.time = Some(columns::time_to_f32(source, &t)?);
    }
    Ok(cloud)
}

/// Encodes `cloud` as Parquet: `x y z intensity` Float32, `ring` UInt32,
/// `time` Float32 when present.
pub(crate) fn encode_parquet(cloud: &PointCloud, path: &Path) -> Result<Vec<u8>, IoError> {
    let n = cloud.len();
    let mut cols = vec![
        Column::new("x".into(), &cloud.x),
        Column::new("y".into(), &cloud.y),
        Column::new("z".into(), &cloud.z),
        Column::new("intensity".into(), &cloud.intensity),
        // UInt32, not UInt16: the workspace's polars is built without the
        // small-integer dtypes; readers cast any integer type back.
        Column::new(
            "ring".into(),
            cloud
                .ring
                .iter()
                .map(|&r| u32::from(r))
                .collect::<Vec<u32>>(),
        ),
    ];
    if let Some(t) = &cloud.time {
        cols.push(Column::new("time".into(), t));
    }
    let mut df = DataFrame::new(n, cols).map_err(|e| pq_err(path, e))?;
    let mut out = Vec::new();
    ParquetWriter::new(&mut out)
        .finish(&mut df)
        .map_err(|e| pq_err(path, e))?;
    Ok(out)
}
