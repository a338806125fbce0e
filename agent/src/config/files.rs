//! Where a configuration's files are read from: the disk, or memory in tests.

use std::path::{Path, PathBuf};

/// Reads files a configuration names, relative to its directory.
pub trait Files {
    /// The bytes of `path`.
    ///
    /// # Errors
    /// The file cannot be read.
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>>;

    /// The files directly in folder `dir`, sorted by name.
    ///
    /// # Errors
    /// The folder cannot be listed.
    fn list(&self, dir: &Path) -> std::io::Result<Vec<PathBuf>>;
}

/// [`Files`] on disk.
pub struct Disk;

impl Files for Disk {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        std::fs::read(path)
    }

    fn list(&self, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let mut files = Vec::new();
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            if entry.file_type()?.is_file() {
                files.push(entry.path());
            }
        }
        files.sort();
        Ok(files)
    }
}

/// The TIA Portal tag tables exported beside a SimaticML program at
/// `program` (TIA writes one object per file): every other `.xml` file of
/// its folder that is a PLC tag table, with its text, in name order. None
/// for a program of another format; a folder that cannot be listed, or a
/// file that cannot be read, holds none.
pub fn tag_tables_beside(files: &dyn Files, program: &Path, text: &str) -> Vec<(PathBuf, String)> {
    if !cellwatch_models::comments::is_simaticml(text) {
        return Vec::new();
    }
    let dir = program.parent().unwrap_or(Path::new(""));
    tag_tables_in(files, dir)
        .into_iter()
        .filter(|(p, _)| p.file_name() != program.file_name())
        .collect()
}

/// Every TIA Portal tag table of folder `dir` (each `.xml` file that is
/// one), with its text, in name order: each file read once. A folder that
/// cannot be listed, or a file that cannot be read, holds none.
pub(super) fn tag_tables_in(files: &dyn Files, dir: &Path) -> Vec<(PathBuf, String)> {
    let Ok(list) = files.list(dir) else {
        return Vec::new();
    };
    list.into_iter()
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("xml")))
        .filter_map(|p| {
            let bytes = files.read(&p).ok()?;
            let text = cellwatch_models::source::text(&p.display().to_string(), &bytes, None)
                .ok()?
                .into_owned();
            cellwatch_models::comments::is_tag_table(&text).then_some((p, text))
        })
        .collect()
}
