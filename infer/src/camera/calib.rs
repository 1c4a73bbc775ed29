//! KITTI object-benchmark calibration: the parser and the LiDAR → image
//! projection.
//!
//! A KITTI `calib/*.txt` file holds one `KEY: v1 v2 …` entry per line. murk
//! needs three of them: `P2` (3×4 projection of the colour camera, row
//! major), `R0_rect` (3×3 rectifying rotation) and `Tr_velo_to_cam` (3×4
//! Velodyne → camera-0 transform). The tracking benchmark's spellings
//! `R_rect` and `Tr_velo_cam` are accepted too. Other keys (`P0`, `P1`, `P3`,
//! `Tr_imu_to_velo`, …) are read for syntax and ignored. Every error names
//! the file and the 1-based line.

use std::path::{Path, PathBuf};

use crate::error::InferError;

/// Pinhole intrinsics of the image being rendered, in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Horizontal focal length, pixels.
    pub fx: f64,
    /// Vertical focal length, pixels.
    pub fy: f64,
    /// Principal point column, pixels (0 = left edge of the first column).
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// The murk default for an image of `width`×`height` with no
    /// calibration: focal length 0.8 × width (≈ 64° horizontal field of
    /// view, close to nuScenes' front camera) and the principal point at the
    /// image centre.
    pub fn default_for(width: u32, height: u32) -> Self {
        let f = 0.8 * f64::from(width);
        Intrinsics {
            fx: f,
            fy: f,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
        }
    }
}

/// The three entries of a KITTI calibration file that the projection needs.
#[derive(Debug, Clone, PartialEq)]
pub struct KittiCalib {
    /// `P2`, the colour camera's 3×4 projection matrix, row major.
    pub p2: [f64; 12],
    /// `R0_rect`, the 3×3 rectifying rotation, row major.
    pub r0_rect: [f64; 9],
    /// `Tr_velo_to_cam`, the 3×4 Velodyne → camera transform, row major.
    pub tr_velo_to_cam: [f64; 12],
}

impl KittiCalib {
    /// Reads and parses a calibration file.
    pub fn from_file(path: &Path) -> Result<Self, InferError> {
        let text = std::fs::read_to_string(path).map_err(|source| InferError::Fs {
            path: path.to_path_buf(),
            action: "read the calibration file",
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses the text of a calibration file; `path` is only used in error
    /// messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self, InferError> {
        let err = |line: usize, reason: String| InferError::Calib {
            path: PathBuf::from(path),
            line,
            reason,
        };
        let mut p2: Option<[f64; 12]> = None;
        let mut r0: Option<[f64; 9]> = None;
        let mut tr: Option<[f64; 12]> = None;
        let mut last = 0;
        for (i, raw) in text.lines().enumerate() {
            let line_no = i + 1;
            last = line_no;
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let Some((key, rest)) = line.split_once(':') else {
                return Err(err(
                    line_no,
                    format!("expected `KEY: numbers`, found {line:?}"),
                ));
            };
            let key = key.trim();
            let mut values = Vec::with_capacity(12);
            for (col, tok) in rest.split_whitespace().enumerate() {
                let v: f64 = tok.parse().map_err(|_| {
                    err(
                        line_no,
                        format!("{key}: value {} ({tok:?}) is not a number", col + 1),
                    )
                })?;
                if !v.is_finite() {
                    return Err(err(
                        line_no,
                        format!("{key}: value {} ({tok}) is not finite", col + 1),
                    ));
                }
                values.push(v);
            }
            let want = |n: usize| -> Result<(), InferError> {
                if values.len() == n {
                    Ok(())
                } else {
                    Err(err(
                        line_no,
                        format!("{key}: expected {n} numbers, found {}", values.len()),
                    ))
                }
            };
            match key {
                "P2" => {
                    want(12)?;
                    p2 = Some(values.as_slice().try_into().expect("length checked"));
                }
                "R0_rect" | "R_rect" => {
                    want(9)?;
                    r0 = Some(values.as_slice().try_into().expect("length checked"));
                }
                "Tr_velo_to_cam" | "Tr_velo_cam" => {
                    want(12)?;
                    tr = Some(values.as_slice().try_into().expect("length checked"));
                }
                _ => {}
            }
        }
        let missing = |name: &str| {
            err(
                last,
                format!(
                    "end of file: no {name} entry (a KITTI object calibration needs P2, R0_rect and Tr_velo_to_cam)"
                ),
            )
        };
        let calib = KittiCalib {
            p2: p2.ok_or_else(|| missing("P2"))?,
            r0_rect: r0.ok_or_else(|| missing("R0_rect"))?,
            tr_velo_to_cam: tr.ok_or_else(|| missing("Tr_velo_to_cam"))?,
        };
        if calib.p2[0] <= 0.0 || calib.p2[5] <= 0.0 {
            return Err(err(
                last,
                format!(
                    "P2: focal lengths {} and {} must be positive",
                    calib.p2[0], calib.p2[5]
                ),
            ));
        }
        Ok(calib)
    }

    /// The colour camera's intrinsics, read from `P2`.
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics {
            fx: self.p2[0],
            fy: self.p2[5],
            cx: self.p2[2],
            cy: self.p2[6],
        }
    }

    /// Projects a Velodyne point: `P2 · R0_rect · Tr_velo_to_cam · (x, y, z, 1)`.
    /// Returns `(u, v, depth)` with `depth` the third homogeneous coordinate
    /// (metres along the optical axis), or `None` when the point is not in
    /// front of the camera (`depth ≤ 0`).
    pub fn project(&self, x: f64, y: f64, z: f64) -> Option<(f64, f64, f64)> {
        let t = &self.tr_velo_to_cam;
        let c = [
            t[0] * x + t[1] * y + t[2] * z + t[3],
            t[4] * x + t[5] * y + t[6] * z + t[7],
            t[8] * x + t[9] * y + t[10] * z + t[11],
        ];
        let r = &self.r0_rect;
        let rc = [
            r[0] * c[0] + r[1] * c[1] + r[2] * c[2],
            r[3] * c[0] + r[4] * c[1] + r[5] * c[2],
            r[6] * c[0] + r[7] * c[1] + r[8] * c[2],
        ];
        let p = &self.p2;
        let h = [
            p[0] * rc[0] + p[1] * rc[1] + p[2] * rc[2] + p[3],
            p[4] * rc[0] + p[5] * rc[1] + p[6] * rc[2] + p[7],
            p[8] * rc[0] + p[9] * rc[1] + p[10] * rc[2] + p[11],
        ];
        (h[2] > 0.0).then(|| (h[0] / h[2], h[1] / h[2], h[2]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AXIS: &str = "P2: 700 0 600 0 0 700 180 0 0 0 1 0\n\
        R0_rect: 1 0 0 0 1 0 0 0 1\n\
        Tr_velo_to_cam: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";

    #[test]
    fn velodyne_forward_axis_projects_to_principal_point() {
        let c = KittiCalib::parse(AXIS, Path::new("axis.txt")).unwrap();
        let (u, v, d) = c.project(10.0, 0.0, 0.0).unwrap();
        assert!((u - 600.0).abs() < 1e-9 && (v - 180.0).abs() < 1e-9);
        assert!((d - 10.0).abs() < 1e-9);
        // 1 m to the left of the car (velodyne +y) lands left of centre.
        let (u, _, _) = c.project(10.0, 1.0, 0.0).unwrap();
        assert!((u - (600.0 - 70.0)).abs() < 1e-9);
        // Behind the camera: no projection.
        assert!(c.project(-5.0, 0.0, 0.0).is_none());
    }
}
