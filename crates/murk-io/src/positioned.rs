//! Reads and writes at a file offset without moving the file's cursor (on
//! Unix; on Windows the cursor moves, which callers that only use offsets
//! do not see): the spill files of murk-fit's clear images and
//! murk-diagnose's kept returns, read back a run at a time by several
//! threads through one handle.
//!
//! ```
//! let file = tempfile::tempfile().unwrap();
//! murk_io::write_all_at(&file, b"murk", 3).unwrap();
//! let mut buf = [0u8; 4];
//! murk_io::read_exact_at(&file, &mut buf, 3).unwrap();
//! assert_eq!(&buf, b"murk");
//! ```

use std::fs::File;
use std::io;

/// Fills `buf` from `file` at `offset` (an error at the end of the file).
#[cfg(unix)]
pub fn read_exact_at(file: &File, buf: &mut [u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

/// Fills `buf` from `file` at `offset` (an error at the end of the file).
#[cfg(windows)]
pub fn read_exact_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, offset)? {
            0 => return Err(io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

/// Fills `buf` from `file` at `offset`: not supported on this platform.
#[cfg(not(any(unix, windows)))]
pub fn read_exact_at(_file: &File, _buf: &mut [u8], _offset: u64) -> io::Result<()> {
    Err(io::Error::other("positioned reads are not supported here"))
}

/// Writes all of `buf` to `file` at `offset`.
#[cfg(unix)]
pub fn write_all_at(file: &File, buf: &[u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(file, buf, offset)
}

/// Writes all of `buf` to `file` at `offset`.
#[cfg(windows)]
pub fn write_all_at(file: &File, mut buf: &[u8], mut offset: u64) -> io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_write(file, buf, offset)? {
            0 => return Err(io::ErrorKind::WriteZero.into()),
            n => {
                buf = &buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

/// Writes all of `buf` to `file` at `offset`: not supported on this
/// platform.
#[cfg(not(any(unix, windows)))]
pub fn write_all_at(_file: &File, _buf: &[u8], _offset: u64) -> io::Result<()> {
    Err(io::Error::other("positioned writes are not supported here"))
}
