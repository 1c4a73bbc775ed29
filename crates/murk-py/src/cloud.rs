//! Point clouds between numpy and murk: arrays of records (KITTI, nuScenes
//! layouts) and dicts of columns.
//!
//! A C-contiguous float32 `(N, 4)` or `(N, 5)` array is handed to murk-io's
//! KITTI / nuScenes parser as the bytes it already holds (no copy): the
//! scan is decoded exactly as `murk apply` decodes the same records read
//! from a file (same ring rule, same checks, same messages with the
//! argument's name in place of the file's). Other inputs (a dict of
//! columns, the time layout) are packed into those records first (one
//! copy), so every input goes through the same reader.

use std::path::Path;

use murk_io::ReadOptions;
use murk_types::{IntensityScale, PointCloud};
use numpy::{
    PyArray1, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyUntypedArray, PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{input, io_arg};

/// How the columns of an array of records are laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// `x y z intensity` (KITTI `.bin`).
    Xyzi,
    /// `x y z intensity ring` (nuScenes `.pcd.bin`, Seeing Through Fog).
    Xyzir,
    /// `x y z intensity time`.
    Xyzit,
}

impl Layout {
    fn columns(self) -> usize {
        match self {
            Layout::Xyzi => 4,
            Layout::Xyzir | Layout::Xyzit => 5,
        }
    }

    /// The layout named `name` (`None`: from the column count).
    pub fn resolve(name: Option<&str>, columns: usize) -> PyResult<Layout> {
        let l = match name.map(|s| s.trim().to_ascii_lowercase()) {
            None => match columns {
                4 => Layout::Xyzi,
                5 => Layout::Xyzir,
                c => {
                    return Err(input(format!(
                        "points: array has {c} columns: expected 4 (x, y, z, intensity) or 5 (x, y, z, intensity, ring)"
                    )));
                }
            },
            Some(n) => match n.as_str() {
                "xyzi" | "kitti" => Layout::Xyzi,
                "xyzir" | "nuscenes" | "ring" => Layout::Xyzir,
                "xyzit" | "time" => Layout::Xyzit,
                _ => {
                    return Err(input(format!(
                        "layout: unknown layout {n:?}: expected \"xyzi\" (KITTI), \"xyzir\" (nuScenes, ring last) or \"xyzit\" (time last)"
                    )));
                }
            },
        };
        if l.columns() != columns {
            return Err(input(format!(
                "points: array has {columns} columns but layout {:?} has {}",
                l.name(),
                l.columns()
            )));
        }
        Ok(l)
    }

    /// The layout's name.
    pub fn name(self) -> &'static str {
        match self {
            Layout::Xyzi => "xyzi",
            Layout::Xyzir => "xyzir",
            Layout::Xyzit => "xyzit",
        }
    }
}

/// Points borrowed from Python, ready to decode without the GIL.
pub enum Points<'py> {
    /// An array of records, borrowed read-only (no copy).
    Records {
        /// The array.
        array: PyReadonlyArray2<'py, f32>,
        /// Its layout.
        layout: Layout,
    },
    /// Columns copied out of a dict, packed as KITTI or nuScenes records.
    Packed {
        /// `x y z intensity [ring]` records.
        records: Vec<f32>,
        /// True when a ring column was given (5 values per record).
        ring: bool,
        /// The time column, when given.
        time: Option<Vec<f32>>,
    },
}

/// What a result is turned back into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// An array of records in this layout.
    Array(Layout),
    /// A dict of columns (with `time` when the input had it).
    Dict,
}

impl<'py> Points<'py> {
    /// The shape the output takes.
    pub fn shape(&self) -> Shape {
        match self {
            Points::Records { layout, .. } => Shape::Array(*layout),
            Points::Packed { .. } => Shape::Dict,
        }
    }

    /// The default intensity scale of this input: KITTI's 0–1 for the
    /// `xyzi` layout (what a KITTI `.bin` file is read as), else
    /// calibrated.
    pub fn default_scale(&self) -> IntensityScale {
        match self {
            Points::Records {
                layout: Layout::Xyzi,
                ..
            } => IntensityScale::KITTI,
            _ => IntensityScale::Calibrated,
        }
    }

    /// Borrowed form that can cross into a `py.detach` closure.
    pub fn view(&self) -> PyResult<View<'_>> {
        Ok(match self {
            Points::Records { array, layout } => View {
                records: array
                    .as_slice()
                    .map_err(|_| input("points: array is not C-contiguous"))?,
                layout: *layout,
                time: None,
            },
            Points::Packed {
                records,
                ring,
                time,
            } => View {
                records,
                layout: if *ring { Layout::Xyzir } else { Layout::Xyzi },
                time: time.as_deref(),
            },
        })
    }
}

/// The records of an input, without the GIL.
#[derive(Debug, Clone, Copy)]
pub struct View<'a> {
    records: &'a [f32],
    layout: Layout,
    time: Option<&'a [f32]>,
}

/// `f32` records as the little-endian bytes murk-io parses.
#[cfg(target_endian = "little")]
fn record_bytes(records: &[f32]) -> std::borrow::Cow<'_, [u8]> {
    std::borrow::Cow::Borrowed(bytemuck::cast_slice(records))
}

/// `f32` records as the little-endian bytes murk-io parses.
#[cfg(not(target_endian = "little"))]
fn record_bytes(records: &[f32]) -> std::borrow::Cow<'_, [u8]> {
    std::borrow::Cow::Owned(records.iter().flat_map(|v| v.to_le_bytes()).collect())
}

impl View<'_> {
    /// Decodes the records into a cloud (intensity labelled `scale`), as
    /// murk-io reads the same records from a KITTI or nuScenes file.
    /// `arg` names the input in errors.
    pub fn decode(&self, scale: IntensityScale, arg: &str) -> PyResult<PointCloud> {
        let opts = ReadOptions {
            intensity_scale: Some(scale),
            ..ReadOptions::default()
        };
        let src = Path::new(arg);
        let mut cloud = match self.layout {
            _ if self.records.is_empty() => {
                let mut c = PointCloud::with_capacity(0);
                c.intensity_scale = scale;
                c
            }
            Layout::Xyzi => murk_io::parse_kitti(&record_bytes(self.records), src, &opts)
                .map_err(|e| io_arg(&e))?,
            Layout::Xyzir => murk_io::parse_nuscenes(&record_bytes(self.records), src, &opts)
                .map_err(|e| io_arg(&e))?,
            Layout::Xyzit => {
                let kitti: Vec<f32> = self
                    .records
                    .chunks_exact(5)
                    .flat_map(|r| [r[0], r[1], r[2], r[3]])
                    .collect();
                let mut c = murk_io::parse_kitti(&record_bytes(&kitti), src, &opts)
                    .map_err(|e| io_arg(&e))?;
                let time: Vec<f32> = self.records.chunks_exact(5).map(|r| r[4]).collect();
                check_finite(&time, arg, "time")?;
                c.time = Some(time);
                c
            }
        };
        if let Some(t) = self.time {
            check_finite(t, arg, "time")?;
            cloud.time = Some(t.to_vec());
        }
        cloud.intensity_scale = scale;
        Ok(cloud)
    }
}

fn check_finite(col: &[f32], arg: &str, name: &str) -> PyResult<()> {
    match col.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(input(format!(
            "{arg}: point {i}: {name} is {} (not a finite 32-bit float)",
            col[i]
        ))),
        None => Ok(()),
    }
}

/// A numpy shape as Python prints it: `(10, 4)`, `(10,)`.
fn shape(dims: &[usize]) -> String {
    match dims {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            dims.iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Describes a Python object for an error message.
fn describe(obj: &Bound<'_, PyAny>) -> String {
    if let Ok(a) = obj.cast::<PyUntypedArray>() {
        let dtype = a
            .dtype()
            .str()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| "?".into());
        return format!("a {dtype} array of shape {}", shape(a.shape()));
    }
    obj.get_type()
        .name()
        .map(|n| format!("a {n}"))
        .unwrap_or_else(|_| "an object".into())
}

/// Reads `points` (an array of records or a dict of columns) without
/// copying an array of records.
pub fn extract<'py>(
    obj: &Bound<'py, PyAny>,
    layout: Option<&str>,
    arg: &str,
) -> PyResult<Points<'py>> {
    if let Ok(d) = obj.cast::<PyDict>() {
        if layout.is_some() {
            return Err(input(format!(
                "layout: only for arrays of records; {arg} is a dict of columns"
            )));
        }
        return from_dict(d, arg);
    }
    let expected = "expected a float32 array of shape (N, 4) or (N, 5) or a dict of columns";
    let Ok(untyped) = obj.cast::<PyUntypedArray>() else {
        return Err(input(format!("{arg}: {expected}, got {}", describe(obj))));
    };
    if untyped.ndim() != 2 {
        return Err(input(format!(
            "{arg}: {expected}, got {} ({} dimensions)",
            describe(obj),
            untyped.ndim()
        )));
    }
    let is_f32 = untyped.dtype().is_equiv_to(&numpy::dtype::<f32>(obj.py()));
    if !is_f32 {
        return Err(input(format!(
            "{arg}: {expected}, got {}: convert with points.astype(numpy.float32)",
            describe(obj)
        )));
    }
    if !untyped.is_c_contiguous() {
        return Err(input(format!(
            "{arg}: array of shape {} is not C-contiguous (a slice, transpose or strided view): pass numpy.ascontiguousarray({arg})",
            shape(untyped.shape())
        )));
    }
    let l = Layout::resolve(layout, untyped.shape()[1])?;
    let array: PyReadonlyArray2<'py, f32> = obj
        .extract()
        .map_err(|e| input(format!("{arg}: {expected}: {e}")))?;
    Ok(Points::Records { array, layout: l })
}

/// A float32 column of a dict.
fn float_column(d: &Bound<'_, PyDict>, name: &str, arg: &str) -> PyResult<Option<Vec<f32>>> {
    let Some(col) = d.get_item(name)? else {
        return Ok(None);
    };
    let a: PyReadonlyArray1<'_, f32> = col.extract().map_err(|_| {
        input(format!(
            "{arg}[{name:?}]: expected a 1-D float32 array, got {}",
            describe(&col)
        ))
    })?;
    Ok(Some(a.as_array().iter().copied().collect()))
}

/// The ring column of a dict, any integer dtype (values 0–65535).
fn ring_column(d: &Bound<'_, PyDict>, arg: &str) -> PyResult<Option<Vec<f32>>> {
    let Some(col) = d.get_item("ring")? else {
        return Ok(None);
    };
    let bad = || {
        input(format!(
            "{arg}[\"ring\"]: expected a 1-D integer array (uint16 as murk.read gives), got {}",
            describe(&col)
        ))
    };
    let values: Vec<i64> = if let Ok(a) = col.extract::<PyReadonlyArray1<'_, u16>>() {
        a.as_array().iter().map(|&v| i64::from(v)).collect()
    } else if let Ok(a) = col.extract::<PyReadonlyArray1<'_, u8>>() {
        a.as_array().iter().map(|&v| i64::from(v)).collect()
    } else if let Ok(a) = col.extract::<PyReadonlyArray1<'_, i32>>() {
        a.as_array().iter().map(|&v| i64::from(v)).collect()
    } else if let Ok(a) = col.extract::<PyReadonlyArray1<'_, i64>>() {
        a.as_array().to_vec()
    } else if let Ok(a) = col.extract::<PyReadonlyArray1<'_, u32>>() {
        a.as_array().iter().map(|&v| i64::from(v)).collect()
    } else {
        return Err(bad());
    };
    if let Some(i) = values.iter().position(|&v| !(0..=65535).contains(&v)) {
        return Err(input(format!(
            "{arg}[\"ring\"][{i}]: ring {} is not in 0..=65535",
            values[i]
        )));
    }
    Ok(Some(values.into_iter().map(|v| v as f32).collect()))
}

fn from_dict<'py>(d: &Bound<'py, PyDict>, arg: &str) -> PyResult<Points<'py>> {
    for key in d.keys() {
        let k: String = key
            .extract()
            .map_err(|_| input(format!("{arg}: column names must be strings")))?;
        if !matches!(k.as_str(), "x" | "y" | "z" | "intensity" | "ring" | "time") {
            return Err(input(format!(
                "{arg}: unknown column {k:?}: expected x, y, z, intensity, ring, time"
            )));
        }
    }
    let mut cols = Vec::with_capacity(4);
    for name in ["x", "y", "z", "intensity"] {
        match float_column(d, name, arg)? {
            Some(c) => cols.push(c),
            None => {
                return Err(input(format!(
                    "{arg}: missing column {name:?} (x, y, z and intensity are required)"
                )));
            }
        }
    }
    let ring = ring_column(d, arg)?;
    let time = float_column(d, "time", arg)?;
    let n = cols[0].len();
    let lens = [
        ("y", cols[1].len()),
        ("z", cols[2].len()),
        ("intensity", cols[3].len()),
        ("ring", ring.as_ref().map_or(n, Vec::len)),
        ("time", time.as_ref().map_or(n, Vec::len)),
    ];
    for (name, len) in lens {
        if len != n {
            return Err(input(format!(
                "{arg}[{name:?}] has {len} values, {arg}[\"x\"] has {n}"
            )));
        }
    }
    let width = if ring.is_some() { 5 } else { 4 };
    let mut records = Vec::with_capacity(n * width);
    for i in 0..n {
        records.extend_from_slice(&[cols[0][i], cols[1][i], cols[2][i], cols[3][i]]);
        if let Some(r) = &ring {
            records.push(r[i]);
        }
    }
    Ok(Points::Packed {
        records,
        ring: ring.is_some(),
        time,
    })
}

/// A cloud as flat records of `layout` (what murk-io writes for KITTI and
/// nuScenes; the time layout puts `time` last, 0 when the cloud has none).
pub fn to_records(cloud: &PointCloud, layout: Layout) -> Vec<f32> {
    let n = cloud.len();
    let mut out = Vec::with_capacity(n * layout.columns());
    for i in 0..n {
        out.extend_from_slice(&[cloud.x[i], cloud.y[i], cloud.z[i], cloud.intensity[i]]);
        match layout {
            Layout::Xyzi => {}
            Layout::Xyzir => out.push(f32::from(cloud.ring[i])),
            Layout::Xyzit => out.push(cloud.time.as_ref().map_or(0.0, |t| t[i])),
        }
    }
    out
}

/// A result: flat records, or the cloud itself for a dict.
pub enum Output {
    /// Records of a layout.
    Records(Vec<f32>, Layout),
    /// Columns.
    Cloud(PointCloud),
}

impl Output {
    /// The output of `cloud` in `shape` (computed without the GIL).
    pub fn new(cloud: PointCloud, shape: Shape) -> Output {
        match shape {
            Shape::Array(l) => Output::Records(to_records(&cloud, l), l),
            Shape::Dict => Output::Cloud(cloud),
        }
    }

    /// The Python object: an `(N, C)` float32 array or a dict of columns.
    pub fn into_py(self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        match self {
            Output::Records(v, l) => {
                let n = v.len() / l.columns();
                let a = PyArray1::from_vec(py, v).reshape([n, l.columns()])?;
                Ok(a.into_any().unbind())
            }
            Output::Cloud(c) => Ok(cloud_to_dict(py, c)?.into_any().unbind()),
        }
    }
}

/// A cloud as a dict of numpy columns (`x y z intensity` float32, `ring`
/// uint16, `time` float32 when present). Moves the columns (no copy).
pub fn cloud_to_dict(py: Python<'_>, c: PointCloud) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("x", PyArray1::from_vec(py, c.x))?;
    d.set_item("y", PyArray1::from_vec(py, c.y))?;
    d.set_item("z", PyArray1::from_vec(py, c.z))?;
    d.set_item("intensity", PyArray1::from_vec(py, c.intensity))?;
    d.set_item("ring", PyArray1::from_vec(py, c.ring))?;
    if let Some(t) = c.time {
        d.set_item("time", PyArray1::from_vec(py, t))?;
    }
    Ok(d)
}
