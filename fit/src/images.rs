//! Where a fit holds its clear recordings' cell images until the reference
//! is built: in memory up to a budget, beyond it in an anonymous temporary
//! file.
//!
//! The images are a campaign's largest summaries: 16 bytes per clear
//! recording and occupied cell (200 clear recordings of an HDL-64 at 100 k
//! points per scan: about 450 MB). A fit keeps them in memory up to
//! [`clear_image_memory`] bytes (256 MB unless set with
//! [`set_clear_image_memory`]) and writes the others, as they are read, to
//! one anonymous temporary file (removed by the system when the fit lets
//! it go) in the system's temporary folder or the one given to
//! [`set_clear_image_dir`]. The reference is built from
//! them a block of rings at a time ([`ClearReference`]), so with the
//! images in the file a fit's memory does not grow with its number of
//! clear recordings but for a few kilobytes each. The values read back are
//! the values written: a fit gives the same bytes whether or not, and how
//! many of, its images were spilled.
//!
//! ```
//! // Spill every clear image (tests, or a machine short of memory).
//! murk_fit::set_clear_image_memory(0);
//! assert_eq!(murk_fit::clear_image_memory(), 0);
//! murk_fit::set_clear_image_memory(256 << 20);
//! ```
//!
//! [`ClearReference`]: crate::observe::ClearReference

use std::borrow::Cow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::FitError;
use crate::reference::{CellImage, ImageEntry, ImageSource, sorted_image};

/// The default of [`clear_image_memory`]: 256 MB.
pub const DEFAULT_CLEAR_IMAGE_MEMORY: u64 = 256 << 20;

static MEMORY: AtomicU64 = AtomicU64::new(DEFAULT_CLEAR_IMAGE_MEMORY);
static DIR: RwLock<Option<PathBuf>> = RwLock::new(None);

/// Sets how many bytes of clear images a fit started after this call keeps
/// in memory before it writes the others to a temporary file (the process's
/// setting; 0 spills every image). It changes memory and time only, never
/// a fit's result.
pub fn set_clear_image_memory(bytes: u64) {
    MEMORY.store(bytes, Ordering::Relaxed);
}

/// [`set_clear_image_memory`] in megabytes (MiB, as `--clear-memory-mb`),
/// refused unless a number ≥ 0 (infinity keeps every image in memory).
pub fn set_clear_image_memory_mb(mb: f64) -> Result<(), FitError> {
    if mb.is_nan() || mb < 0.0 {
        return Err(FitError::InvalidParam {
            name: "clear_memory_mb",
            value: mb.to_string(),
            reason: "megabytes of clear images held in memory must be a number ≥ 0".into(),
        });
    }
    // `as` saturates: infinity (and anything past u64) holds every image.
    set_clear_image_memory((mb * 1_048_576.0).round() as u64);
    Ok(())
}

/// How many bytes of clear images a fit keeps in memory
/// ([`set_clear_image_memory`]).
pub fn clear_image_memory() -> u64 {
    MEMORY.load(Ordering::Relaxed)
}

/// Sets the folder of the temporary file that fits started after this call
/// spill clear images to (the process's setting; `None`, the default: the
/// system's temporary folder, `TMPDIR` on Unix). Put it on a disk, not a
/// RAM-backed `/tmp`.
pub fn set_clear_image_dir(dir: Option<PathBuf>) {
    *DIR.write().unwrap_or_else(|p| p.into_inner()) = dir;
}

/// The folder clear images spill to ([`set_clear_image_dir`]).
pub fn clear_image_dir() -> PathBuf {
    DIR.read()
        .unwrap_or_else(|p| p.into_inner())
        .clone()
        .unwrap_or_else(std::env::temp_dir)
}

/// Bytes of one spilled entry: cell, range, reflectivity, hits.
const ENTRY_BYTES: usize = 16;

/// The anonymous temporary file of a fit's spilled images.
#[derive(Debug)]
struct SpillFile {
    file: std::fs::File,
    /// The folder it was created in (for messages).
    dir: PathBuf,
}

impl SpillFile {
    fn error(&self, what: &str, e: std::io::Error) -> FitError {
        FitError::File {
            path: self.dir.clone(),
            reason: format!("cannot {what} the temporary file of the clear images: {e}"),
        }
    }

    fn write_at(&self, buf: &[u8], offset: u64) -> std::io::Result<()> {
        murk_io::write_all_at(&self.file, buf, offset)
    }

    fn read_at(&self, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
        murk_io::read_exact_at(&self.file, buf, offset)
    }
}

/// The images of one fit as they are read: in memory while they fit the
/// budget, then in the fit's spill file.
#[derive(Debug)]
pub(crate) struct ClearImages {
    budget: u64,
    dir: PathBuf,
    held: u64,
    file: Option<Arc<SpillFile>>,
    end: u64,
}

impl ClearImages {
    /// An empty store under the current [`clear_image_memory`].
    pub(crate) fn new() -> ClearImages {
        ClearImages {
            budget: clear_image_memory(),
            dir: clear_image_dir(),
            held: 0,
            file: None,
            end: 0,
        }
    }

    /// Stores `img` (its cells put in ascending order first, if they are
    /// not): kept in memory within the budget, else written to the spill
    /// file.
    pub(crate) fn store(&mut self, img: CellImage) -> Result<StoredImage, FitError> {
        let img = if img.cells.is_sorted_by(|a, b| a < b) {
            img
        } else {
            sorted_image(&img)
        };
        let bytes = (img.cells.len() * ENTRY_BYTES) as u64;
        if self.held + bytes <= self.budget {
            self.held += bytes;
            return Ok(StoredImage(Repr::Memory(img)));
        }
        let file = match &self.file {
            Some(f) => f.clone(),
            None => {
                let dir = self.dir.clone();
                let file = tempfile::tempfile_in(&dir).map_err(|e| FitError::File {
                    path: dir.clone(),
                    reason: format!("cannot create the temporary file of the clear images: {e}"),
                })?;
                let f = Arc::new(SpillFile { file, dir });
                self.file = Some(f.clone());
                f
            }
        };
        let mut buf = Vec::with_capacity(bytes as usize);
        for q in 0..img.cells.len() {
            buf.extend_from_slice(&img.cells[q].to_le_bytes());
            buf.extend_from_slice(&img.range[q].to_bits().to_le_bytes());
            buf.extend_from_slice(&img.reflectivity[q].to_bits().to_le_bytes());
            buf.extend_from_slice(&img.hits[q].to_le_bytes());
        }
        file.write_at(&buf, self.end)
            .map_err(|e| file.error("write", e))?;
        let stored = StoredImage(Repr::Spilled {
            file,
            offset: self.end,
            len: img.cells.len(),
            frames: img.frames,
        });
        self.end += bytes;
        Ok(stored)
    }
}

/// One clear recording's cell image, in memory or in its fit's spill file
/// ([`ClearImages`]). Serialised as the [`CellImage`] it holds.
#[derive(Debug, Clone)]
pub(crate) struct StoredImage(Repr);

#[derive(Debug, Clone)]
enum Repr {
    Memory(CellImage),
    Spilled {
        file: Arc<SpillFile>,
        offset: u64,
        len: usize,
        frames: u32,
    },
}

impl StoredImage {
    /// An image held in memory as it is.
    pub(crate) fn memory(img: CellImage) -> StoredImage {
        StoredImage(Repr::Memory(img))
    }

    /// Scans the image was made from.
    fn frames(&self) -> u32 {
        match &self.0 {
            Repr::Memory(img) => img.frames,
            Repr::Spilled { frames, .. } => *frames,
        }
    }

    /// Entries (occupied cells).
    fn len(&self) -> usize {
        match &self.0 {
            Repr::Memory(img) => img.cells.len(),
            Repr::Spilled { len, .. } => *len,
        }
    }

    /// Appends entries `from .. from + n` to `out`.
    fn read(&self, from: usize, n: usize, out: &mut Vec<ImageEntry>) -> Result<(), FitError> {
        match &self.0 {
            Repr::Memory(img) => {
                img.entries(from, n, out);
                Ok(())
            }
            Repr::Spilled { file, offset, .. } => {
                let mut buf = vec![0u8; n * ENTRY_BYTES];
                file.read_at(&mut buf, offset + (from * ENTRY_BYTES) as u64)
                    .map_err(|e| file.error("read back", e))?;
                let word =
                    |b: &[u8], k: usize| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
                out.extend(buf.chunks_exact(ENTRY_BYTES).map(|b| ImageEntry {
                    cell: word(b, 0),
                    range: f32::from_bits(word(b, 4)),
                    reflectivity: f32::from_bits(word(b, 8)),
                    hits: word(b, 12),
                }));
                Ok(())
            }
        }
    }

    /// The whole image: borrowed from memory, or read back.
    pub(crate) fn load(&self) -> Result<Cow<'_, CellImage>, FitError> {
        match &self.0 {
            Repr::Memory(img) => Ok(Cow::Borrowed(img)),
            Repr::Spilled { len, frames, .. } => {
                let mut entries = Vec::with_capacity(*len);
                self.read(0, *len, &mut entries)?;
                Ok(Cow::Owned(CellImage {
                    cells: entries.iter().map(|e| e.cell).collect(),
                    range: entries.iter().map(|e| e.range).collect(),
                    reflectivity: entries.iter().map(|e| e.reflectivity).collect(),
                    hits: entries.iter().map(|e| e.hits).collect(),
                    frames: *frames,
                }))
            }
        }
    }
}

impl PartialEq for StoredImage {
    fn eq(&self, other: &Self) -> bool {
        match (self.load(), other.load()) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        }
    }
}

impl Serialize for StoredImage {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.load()
            .map_err(serde::ser::Error::custom)?
            .as_ref()
            .serialize(s)
    }
}

impl<'de> Deserialize<'de> for StoredImage {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        CellImage::deserialize(d).map(StoredImage::memory)
    }
}

/// A fit's stored images as the reference build reads them; images held in
/// memory with their cells out of order (from a state file) are sorted
/// first.
pub(crate) struct StoredImages<'a> {
    images: Vec<Cow<'a, StoredImage>>,
}

impl<'a> StoredImages<'a> {
    /// The source of `images`, in the order given.
    pub(crate) fn new(images: &[&'a StoredImage]) -> StoredImages<'a> {
        let images = images
            .iter()
            .map(|&s| match &s.0 {
                Repr::Memory(img) if !img.cells.is_sorted_by(|a, b| a < b) => {
                    Cow::Owned(StoredImage::memory(sorted_image(img)))
                }
                _ => Cow::Borrowed(s),
            })
            .collect();
        StoredImages { images }
    }
}

impl ImageSource for StoredImages<'_> {
    type Error = FitError;

    fn count(&self) -> usize {
        self.images.len()
    }

    fn frames(&self, i: usize) -> u32 {
        self.images[i].frames()
    }

    fn len(&self, i: usize) -> usize {
        self.images[i].len()
    }

    fn read(
        &self,
        i: usize,
        from: usize,
        n: usize,
        out: &mut Vec<ImageEntry>,
    ) -> Result<(), FitError> {
        self.images[i].read(from, n, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FitParams;
    use crate::observe::{CellGrid, ClearReference};
    use crate::reference::tests::{noisy_images, same};
    use murk_types::LidarSpec;

    fn store(budget: u64, dir: PathBuf) -> ClearImages {
        ClearImages {
            budget,
            dir,
            held: 0,
            file: None,
            end: 0,
        }
    }

    fn grid() -> CellGrid {
        let mut spec = LidarSpec::vlp16();
        spec.azimuth_resolution_deg = 1.0;
        CellGrid::new(&spec)
    }

    #[test]
    fn a_spilled_image_reads_back_and_serialises_as_it_was() {
        let imgs = noisy_images(&grid(), 3, 7);
        let mut s = store(0, std::env::temp_dir());
        let cfg = bincode::config::standard();
        for img in &imgs {
            let stored = s.store(img.clone()).unwrap();
            assert!(matches!(stored.0, Repr::Spilled { .. }));
            assert_eq!(stored.load().unwrap().as_ref(), img);
            assert_eq!(stored.frames(), img.frames);
            let a = bincode::serde::encode_to_vec(&stored, cfg).unwrap();
            let b = bincode::serde::encode_to_vec(img, cfg).unwrap();
            assert_eq!(a, b);
            let (back, _): (StoredImage, usize) =
                bincode::serde::decode_from_slice(&a, cfg).unwrap();
            assert_eq!(back, stored);
        }
        // An image whose cells are out of order is stored in order.
        let mut rev = imgs[0].clone();
        rev.cells.reverse();
        rev.range.reverse();
        rev.reflectivity.reverse();
        rev.hits.reverse();
        let stored = s.store(rev).unwrap();
        assert_eq!(stored.load().unwrap().as_ref(), &imgs[0]);
    }

    #[test]
    fn the_reference_is_the_same_from_memory_and_from_the_file() {
        let g = grid();
        let p = FitParams::default().check().unwrap();
        for seed in 1..=3 {
            let imgs = noisy_images(&g, 8, seed);
            let expected = ClearReference::build(g.clone(), &imgs, &p);
            let one = (imgs[0].cells.len() * ENTRY_BYTES) as u64;
            // All in memory, none, and the first three (the budget of three
            // and a half images).
            for (budget, spilled) in [(u64::MAX, 0), (0, 8), (7 * one / 2, 5)] {
                let mut s = store(budget, std::env::temp_dir());
                let stored: Vec<StoredImage> =
                    imgs.iter().map(|m| s.store(m.clone()).unwrap()).collect();
                let n = stored
                    .iter()
                    .filter(|m| matches!(m.0, Repr::Spilled { .. }))
                    .count();
                assert!(
                    n.abs_diff(spilled) <= 1,
                    "{n} spilled, about {spilled} meant"
                );
                let refs: Vec<&StoredImage> = stored.iter().collect();
                let r =
                    ClearReference::build_from(g.clone(), &StoredImages::new(&refs), &p).unwrap();
                assert!(same(&r, &expected), "seed {seed}, budget {budget}: differs");
            }
        }
    }

    #[test]
    fn a_spill_folder_that_cannot_hold_the_file_is_named_in_the_error() {
        let missing = std::env::temp_dir().join("murk-no-such-folder-for-spills");
        let mut s = store(0, missing.clone());
        let img = noisy_images(&grid(), 1, 1).remove(0);
        let e = s.store(img).unwrap_err().to_string();
        assert!(e.starts_with(&missing.display().to_string()), "{e}");
        assert!(
            e.contains("cannot create the temporary file of the clear images"),
            "{e}"
        );
        // Within the budget nothing is written, and nothing fails.
        let mut s = store(u64::MAX, missing);
        assert!(s.store(noisy_images(&grid(), 1, 1).remove(0)).is_ok());
    }
}
