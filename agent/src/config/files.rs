//! Where a configuration's files are read from: the disk, or memory in tests.

use std::path::Path;

/// Reads files a configuration names, relative to its directory.
pub trait Files {
    /// The bytes of `path`.
    ///
    /// # Errors
    /// The file cannot be read.
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>>;
}

/// [`Files`] on disk.
pub struct Disk;

impl Files for Disk {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        std::fs::read(path)
    }
}
