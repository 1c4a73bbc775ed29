//! Point-cloud file formats, chosen by extension.

use std::path::Path;

use crate::{IntensityScale, TypesError};

/// A point-cloud file format murk reads (and, except pcap, writes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum PointFormat {
    /// PCL `.pcd` (`ascii`, `binary`, `binary_compressed`).
    Pcd,
    /// KITTI `.bin`: little-endian f32 records `x y z intensity`.
    KittiBin,
    /// nuScenes `.pcd.bin`: little-endian f32 records `x y z intensity ring`.
    NuscenesBin,
    /// CSV: `x,y,z,intensity,ring` or a VeloView export.
    Csv,
    /// Apache Parquet with columns `x y z intensity ring`.
    Parquet,
    /// Raw Velodyne VLP-16 UDP capture (read only).
    Pcap,
}

impl PointFormat {
    /// Every format, in a stable order.
    pub const ALL: [PointFormat; 6] = [
        PointFormat::Pcd,
        PointFormat::KittiBin,
        PointFormat::NuscenesBin,
        PointFormat::Csv,
        PointFormat::Parquet,
        PointFormat::Pcap,
    ];

    /// The format of `path`, from its extension (`.pcd.bin` before `.bin`).
    pub fn from_path(path: &Path) -> Result<Self, TypesError> {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if name.ends_with(".pcd.bin") {
            return Ok(PointFormat::NuscenesBin);
        }
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "pcd" => Ok(PointFormat::Pcd),
            "bin" => Ok(PointFormat::KittiBin),
            "csv" => Ok(PointFormat::Csv),
            "parquet" => Ok(PointFormat::Parquet),
            "pcap" => Ok(PointFormat::Pcap),
            _ => Err(TypesError::UnknownFormat {
                path: path.display().to_string(),
                ext,
            }),
        }
    }

    /// Parses a CLI format name (`pcd`, `bin`, `nuscenes`, `csv`, `parquet`).
    pub fn from_name(name: &str) -> Result<Self, TypesError> {
        match name.to_ascii_lowercase().as_str() {
            "pcd" => Ok(PointFormat::Pcd),
            "bin" | "kitti" => Ok(PointFormat::KittiBin),
            "pcd.bin" | "nuscenes" => Ok(PointFormat::NuscenesBin),
            "csv" => Ok(PointFormat::Csv),
            "parquet" => Ok(PointFormat::Parquet),
            "pcap" => Ok(PointFormat::Pcap),
            other => Err(TypesError::UnknownFormat {
                path: String::new(),
                ext: other.to_string(),
            }),
        }
    }

    /// The file extension written for this format, without the leading dot.
    pub fn extension(self) -> &'static str {
        match self {
            PointFormat::Pcd => "pcd",
            PointFormat::KittiBin => "bin",
            PointFormat::NuscenesBin => "pcd.bin",
            PointFormat::Csv => "csv",
            PointFormat::Parquet => "parquet",
            PointFormat::Pcap => "pcap",
        }
    }

    /// The intensity scale files of this format carry unless told otherwise.
    pub fn default_intensity_scale(self) -> IntensityScale {
        match self {
            PointFormat::KittiBin => IntensityScale::KITTI,
            _ => IntensityScale::Calibrated,
        }
    }

    /// True when murk can write this format.
    pub fn writable(self) -> bool {
        !matches!(self, PointFormat::Pcap)
    }
}

/// The record layout of a headerless binary point file (`.bin`,
/// `.pcd.bin`): little-endian `f32` values, one record per point.
///
/// | name | record | fields | typical source |
/// |---|---|---|---|
/// | `xyzi` | 16 bytes | x y z intensity | KITTI (intensity 0–1) |
/// | `xyzir` | 20 bytes | x y z intensity ring | nuScenes, Seeing Through Fog (intensity 0–255) |
/// | `xyzit` | 20 bytes | x y z intensity time (seconds) | other five-float exports |
///
/// `xyzir` and `xyzit` have the same size, and a file of `80·k` bytes fits
/// all three: the bytes alone cannot tell them apart, so murk's readers take
/// the layout from the caller (`--bin-layout`, `bin_layout` in
/// `campaign.toml`) and refuse to guess when the size fits several.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BinLayout {
    /// `x y z intensity` (16 bytes).
    Xyzi,
    /// `x y z intensity ring` (20 bytes; ring a whole number).
    Xyzir,
    /// `x y z intensity time` (20 bytes; time in seconds).
    Xyzit,
}

impl BinLayout {
    /// Every layout, in a stable order.
    pub const ALL: [BinLayout; 3] = [BinLayout::Xyzi, BinLayout::Xyzir, BinLayout::Xyzit];

    /// Bytes per record.
    pub fn record_len(self) -> usize {
        match self {
            BinLayout::Xyzi => 16,
            BinLayout::Xyzir | BinLayout::Xyzit => 20,
        }
    }

    /// The name used by `--bin-layout` and `campaign.toml`.
    pub fn name(self) -> &'static str {
        match self {
            BinLayout::Xyzi => "xyzi",
            BinLayout::Xyzir => "xyzir",
            BinLayout::Xyzit => "xyzit",
        }
    }

    /// The intensity scale files of this layout carry unless told otherwise:
    /// KITTI's 0–1 for `xyzi`, the 8-bit byte convention (calibrated) for
    /// the five-float layouts (nuScenes, Seeing Through Fog).
    pub fn default_intensity_scale(self) -> IntensityScale {
        match self {
            BinLayout::Xyzi => IntensityScale::KITTI,
            BinLayout::Xyzir | BinLayout::Xyzit => IntensityScale::Calibrated,
        }
    }
}

/// Which return of each firing murk reads from a dual-return `.pcap`
/// capture (`--pcap-return`, `pcap_return` in `campaign.toml`).
///
/// A sensor in dual-return mode reports two returns of each firing, the
/// strongest and the last (one, repeated, where they are the same echo).
/// murk's weather model has one return per firing — what a sensor in
/// strongest-return (its default) or last-return mode reports — so fit and
/// diagnose refuse a dual-return capture until told which to read; apply
/// and convert write both unless told. Single-return captures are read as
/// recorded; asking for the return they did not record is an error.
///
/// ```
/// use murk_types::PcapReturn;
///
/// let r: PcapReturn = "last".parse().unwrap();
/// assert_eq!(r, PcapReturn::Last);
/// assert_eq!(r.name(), "last");
/// assert!("first".parse::<PcapReturn>().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PcapReturn {
    /// The strongest return of each firing (a sensor's default mode).
    Strongest,
    /// The last return of each firing (through fog, rain or spray, the
    /// farthest echo the sensor detected).
    Last,
}

impl PcapReturn {
    /// The name used by `--pcap-return` and `campaign.toml`.
    pub fn name(self) -> &'static str {
        match self {
            PcapReturn::Strongest => "strongest",
            PcapReturn::Last => "last",
        }
    }
}

impl std::str::FromStr for PcapReturn {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "strongest" => Ok(PcapReturn::Strongest),
            "last" => Ok(PcapReturn::Last),
            other => Err(format!(
                "unknown pcap return {other:?}: expected strongest or last"
            )),
        }
    }
}

impl std::fmt::Display for PcapReturn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for BinLayout {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "xyzi" | "kitti" => Ok(BinLayout::Xyzi),
            "xyzir" | "nuscenes" | "stf" => Ok(BinLayout::Xyzir),
            "xyzit" => Ok(BinLayout::Xyzit),
            other => Err(format!(
                "unknown binary layout {other:?}: expected xyzi, xyzir or xyzit"
            )),
        }
    }
}

impl std::fmt::Display for BinLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bin_layouts_parse_and_size() {
        for l in BinLayout::ALL {
            assert_eq!(l.name().parse::<BinLayout>().unwrap(), l);
        }
        assert_eq!(BinLayout::Xyzi.record_len(), 16);
        assert_eq!(BinLayout::Xyzir.record_len(), 20);
        let e = "xyz".parse::<BinLayout>().unwrap_err();
        assert!(e.contains("xyzi, xyzir or xyzit"), "{e}");
    }

    #[test]
    fn nuscenes_before_kitti() {
        assert_eq!(
            PointFormat::from_path(Path::new("a/b.pcd.bin")).unwrap(),
            PointFormat::NuscenesBin
        );
        assert_eq!(
            PointFormat::from_path(Path::new("000008.bin")).unwrap(),
            PointFormat::KittiBin
        );
        assert_eq!(
            PointFormat::from_path(Path::new("X.PCD")).unwrap(),
            PointFormat::Pcd
        );
        let e = PointFormat::from_path(Path::new("a.las"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.las") && e.contains("las"), "{e}");
    }
}
