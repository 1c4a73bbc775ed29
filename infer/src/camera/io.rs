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
    // Encoded in memory (an image is a few MB), then written atomically.
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, format)
        .map_err(|e| InferError::Input {
            path: path.to_path_buf(),
            reason: format!("cannot encode the image: {e}"),
        })?;
    crate::batch::write_atomic(path, bytes.get_ref())
}
