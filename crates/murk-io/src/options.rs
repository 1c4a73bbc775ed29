//! Reader and writer settings.

use std::path::Path;

use murk_types::{BinLayout, IntensityScale, LidarSpec, PcapReturn, PointFormat};

use crate::IoError;

/// How to read a point-cloud file.
///
/// | field | default | purpose |
/// |---|---|---|
/// | `format` | from the extension ([`PointFormat::from_path`]) | force a format |
/// | `lidar` | [`LidarSpec::vlp16`] | ring elevations for files without a ring (KITTI `.bin`, CSV/PCD/Parquet without ring) |
/// | `intensity_scale` | `lidar.intensity_scale`, else what the file records (a murk PCD's `# intensity_scale` comment), else the format's / layout's default | the scale the file's intensity is in |
/// | `bin_layout` | `lidar.bin_layout`, else decided from the file size (see [`crate::parse_kitti`]) | record layout of `.bin` / `.pcd.bin` files |
/// | `csv_columns` | `lidar.csv_columns`, else none: the first line is the header | column names of a header-less CSV file |
/// | `pcap_return` | `lidar.pcap_return`, else as recorded (both returns of a dual-return capture, [`crate::ReadNotes::both_returns`]) | which return of each firing a `.pcap` gives |
///
/// Readers never convert intensity: they label the returned cloud with the
/// scale and callers call [`murk_types::PointCloud::to_calibrated`].
#[derive(Debug, Clone, Default)]
pub struct ReadOptions {
    /// Force a format instead of guessing from the extension.
    pub format: Option<PointFormat>,
    /// Sensor whose ring elevations give the ring of points that have none.
    pub lidar: Option<LidarSpec>,
    /// Scale of the file's intensity (overrides the format's default).
    pub intensity_scale: Option<IntensityScale>,
    /// Record layout of headerless binary files (overrides the sensor
    /// description's and the size-based choice).
    pub bin_layout: Option<BinLayout>,
    /// Column names of header-less CSV files, in file order (`x`, `y`, `z`,
    /// `intensity` required; `ring`, `time` optional; any other name is a
    /// column murk keeps but does not read).
    pub csv_columns: Option<Vec<String>>,
    /// Which return of each firing to read from a `.pcap` (overrides the
    /// sensor description's); `None`: as recorded.
    pub pcap_return: Option<PcapReturn>,
}

impl ReadOptions {
    /// The return the caller asked `.pcap` captures for (the option, else
    /// the sensor description's), if any.
    pub fn declared_pcap_return(&self) -> Option<PcapReturn> {
        self.pcap_return
            .or_else(|| self.lidar.as_ref().and_then(|l| l.pcap_return))
    }

    /// The format of `path` under these options.
    pub fn format_of(&self, path: &Path) -> Result<PointFormat, IoError> {
        match self.format {
            Some(f) => Ok(f),
            None => PointFormat::from_path(path).map_err(|e| IoError::Format {
                path: path.to_path_buf(),
                reason: e.to_string(),
            }),
        }
    }

    /// The intensity scale a cloud read as `format` is labelled with.
    pub fn scale_for(&self, format: PointFormat) -> IntensityScale {
        self.declared_scale()
            .unwrap_or_else(|| format.default_intensity_scale())
    }

    /// The intensity scale the caller declared (the option, else the sensor
    /// description's), if any: it wins over what a file records and over a
    /// format's default.
    pub fn declared_scale(&self) -> Option<IntensityScale> {
        self.intensity_scale
            .or_else(|| self.lidar.as_ref().and_then(|l| l.intensity_scale))
    }

    /// The binary record layout the caller declared (the option, else the
    /// sensor description's), if any.
    pub fn declared_bin_layout(&self) -> Option<BinLayout> {
        self.bin_layout
            .or_else(|| self.lidar.as_ref().and_then(|l| l.bin_layout))
    }

    /// The column names of header-less CSV files the caller declared (the
    /// option, else the sensor description's), if any.
    pub fn declared_csv_columns(&self) -> Option<&[String]> {
        self.csv_columns
            .as_deref()
            .or_else(|| self.lidar.as_ref().and_then(|l| l.csv_columns.as_deref()))
    }
}

/// The `DATA` encoding of a written PCD file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub enum PcdData {
    /// Whitespace-separated text, one point per line (shortest round-trip
    /// decimal form of each `f32`).
    Ascii,
    /// Little-endian records, one per point (PCL's default; fastest to read).
    #[default]
    Binary,
    /// PCL's LZF-compressed field-by-field layout.
    BinaryCompressed,
}

impl PcdData {
    /// The word written after `DATA` in the header.
    pub fn name(self) -> &'static str {
        match self {
            PcdData::Ascii => "ascii",
            PcdData::Binary => "binary",
            PcdData::BinaryCompressed => "binary_compressed",
        }
    }

    /// Parses `ascii`, `binary` or `binary_compressed`.
    pub fn from_name(name: &str) -> Option<PcdData> {
        match name {
            "ascii" => Some(PcdData::Ascii),
            "binary" => Some(PcdData::Binary),
            "binary_compressed" => Some(PcdData::BinaryCompressed),
            _ => None,
        }
    }
}

impl std::str::FromStr for PcdData {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        PcdData::from_name(s).ok_or_else(|| {
            format!("unknown PCD data encoding {s:?}: expected ascii, binary or binary_compressed")
        })
    }
}

impl std::fmt::Display for PcdData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How to write a point-cloud file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WriteOptions {
    /// The format to write (every [`PointFormat`] except `Pcap`).
    pub format: PointFormat,
    /// The PCD `DATA` encoding (ignored by other formats).
    pub pcd_data: PcdData,
}

impl WriteOptions {
    /// `format` with the default PCD encoding (`binary`).
    pub fn new(format: PointFormat) -> Self {
        WriteOptions {
            format,
            pcd_data: PcdData::default(),
        }
    }
}
