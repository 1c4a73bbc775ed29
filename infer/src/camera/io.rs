//! Reading and writing images for the rain renderer: decode to 8-bit RGB
//! with errors naming the file, and atomic writes (temporary file in the
//! output's folder, then rename), so that a crash never leaves a half
//! image under the final name.

use std::path::Path;

use image::{ImageFormat, RgbImage};

use crate::error::InferError;

/// Reads an image (PNG or JPEG) as 8-bit RGB; other colour types are
/// converted (16-bit PNGs are reduced to 8 bits, alpha is dropped).
pub fn read_rgb(path: &Path) -> Result<RgbImage, InferError> {
    let img = image::open(path).map_err(|e| InferError::Input {
        path: path.to_path_buf(),
        reason: format!("cannot decode the image: {e}"),
    })?;
    Ok(img.to_rgb8())
}

/// Writes `img` to `path` atomically; the format (PNG or JPEG) comes from
/// the extension. The input is never touched.
pub fn write_rgb_atomic(path: &Path, img: &RgbImage) -> Result<(), InferError> {
    let format = ImageFormat::from_path(path)
        .ok()
        .filter(|f| matches!(f, ImageFormat::Png | ImageFormat::Jpeg))
        .ok_or_else(|| InferError::Input {
            path: path.to_path_buf(),
            reason: "output must end in .png, .jpg or .jpeg".to_string(),
        })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let fs = |action: &'static str, p: &Path, source: std::io::Error| InferError::Fs {
        path: p.to_path_buf(),
        action,
        source,
    };
    {
        let file =
            std::fs::File::create(&tmp).map_err(|e| fs("create a temporary file", &tmp, e))?;
        let mut w = std::io::BufWriter::new(file);
        img.write_to(&mut w, format)
            .map_err(|e| InferError::Input {
                path: path.to_path_buf(),
                reason: format!("cannot encode the image: {e}"),
            })?;
        let file = w
            .into_inner()
            .map_err(|e| fs("flush the temporary file", &tmp, e.into_error()))?;
        file.sync_all()
            .map_err(|e| fs("sync the temporary file", &tmp, e))?;
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        fs("rename the temporary file over the output", path, e)
    })
}
