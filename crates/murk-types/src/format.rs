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

#[cfg(test)]
mod tests {
    use super::*;

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
