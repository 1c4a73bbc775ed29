//! Choosing the image format and writing files atomically.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::FigureError;

/// The file formats figures are written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ImageFormat {
    /// Raster PNG.
    Png,
    /// Vector SVG.
    Svg,
}

impl ImageFormat {
    /// The format of `path`, from its extension.
    pub fn from_path(path: &Path) -> Result<ImageFormat, FigureError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "png" => Ok(ImageFormat::Png),
            "svg" => Ok(ImageFormat::Svg),
            _ => Err(FigureError::UnsupportedFormat {
                path: path.to_path_buf(),
                ext,
            }),
        }
    }
}

/// A temporary path next to `path`, ending in the same extension (the
/// bitmap backend picks its encoder from the extension).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp-{}.{ext}", std::process::id()))
}

fn render_error(path: &Path, e: impl std::fmt::Display) -> FigureError {
    FigureError::Render {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// Renames `tmp` over `path`, removing `tmp` when that fails.
fn commit(tmp: &Path, path: &Path) -> Result<(), FigureError> {
    std::fs::rename(tmp, path).map_err(|source| {
        let _ = std::fs::remove_file(tmp);
        FigureError::Io {
            path: path.to_path_buf(),
            reason: "cannot move the finished figure into place".into(),
            source,
        }
    })
}

/// Writes a PNG drawn by `draw` to `path` atomically.
pub(crate) fn write_png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>) -> Result<(), String>,
) -> Result<(), FigureError> {
    let tmp = temp_path(path);
    let result = {
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        draw(root)
    };
    if let Err(reason) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(render_error(path, reason));
    }
    if !tmp.is_file() {
        return Err(render_error(path, "the bitmap backend wrote no file"));
    }
    commit(&tmp, path)
}

/// Writes an SVG drawn by `draw` to `path` atomically.
pub(crate) fn write_svg(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(DrawingArea<SVGBackend<'_>, plotters::coord::Shift>) -> Result<(), String>,
) -> Result<(), FigureError> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        draw(root).map_err(|r| render_error(path, r))?;
    }
    let tmp = temp_path(path);
    std::fs::write(&tmp, text.as_bytes()).map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        FigureError::Io {
            path: tmp.clone(),
            reason: "cannot write the figure".into(),
            source,
        }
    })?;
    commit(&tmp, path)
}
