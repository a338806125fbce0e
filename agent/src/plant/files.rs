//! Writing the plant's folder: derived files rewritten only when the
//! inventory changes them and never over a hand edit, secrets made once
//! and never overwritten, links made once. What the plant last wrote is
//! kept in a manifest (`.plant-written`: each file's SHA-256), which tells
//! a file the plant wrote from one somebody changed since.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::layout::Layout;
use super::PlantError;

/// What one run did to the plant's folder, file by file (paths relative
/// to the folder).
#[derive(Debug, Default, PartialEq, Eq)]
pub struct Made {
    /// Files written for the first time (and keys and certificates made).
    pub made: Vec<String>,
    /// Derived files written again, the inventory having changed them.
    pub updated: Vec<String>,
    /// Derived files changed by hand since the plant wrote them: kept as
    /// they are, not written.
    pub edited: Vec<String>,
}

impl Made {
    /// Whether the run changed nothing.
    pub fn nothing(&self) -> bool {
        self.made.is_empty() && self.updated.is_empty()
    }
}

/// Writes the files of one run.
pub(crate) struct Writer<'l> {
    layout: &'l Layout,
    /// SHA-256 (hex) of each derived file as the plant last wrote it.
    manifest: BTreeMap<String, String>,
    /// What this run wrote or would have written, by path: two cells
    /// asking for one file with different text is a clash.
    this_run: BTreeMap<PathBuf, Vec<u8>>,
    pub(super) made: Made,
}

fn sha256(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> PlantError + '_ {
    move |source| PlantError::Write {
        path: path.to_path_buf(),
        source,
    }
}

/// Creates `dir` and its parents, the last with `mode`.
pub(crate) fn make_dir(dir: &Path, mode: u32) -> Result<(), PlantError> {
    use std::os::unix::fs::DirBuilderExt;
    if dir.is_dir() {
        return Ok(());
    }
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent).map_err(io(parent))?;
    }
    std::fs::DirBuilder::new()
        .mode(mode)
        .create(dir)
        .or_else(|e| if dir.is_dir() { Ok(()) } else { Err(e) })
        .map_err(io(dir))
}

impl<'l> Writer<'l> {
    /// A writer over the plant's folder, its manifest read.
    ///
    /// # Errors
    /// The manifest exists but cannot be read.
    pub(crate) fn open(layout: &'l Layout) -> Result<Writer<'l>, PlantError> {
        let path = layout.manifest();
        let mut manifest = BTreeMap::new();
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                for line in text.lines() {
                    if let Some((hash, file)) = line.split_once("  ") {
                        manifest.insert(file.to_string(), hash.to_string());
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => return Err(PlantError::Read { path, source }),
        }
        Ok(Writer {
            layout,
            manifest,
            this_run: BTreeMap::new(),
            made: Made::default(),
        })
    }

    /// Writes derived file `path` with `text` (mode 0644), unless it holds
    /// that already, or somebody changed it since the plant wrote it.
    ///
    /// # Errors
    /// Another part of this run asked for other text at `path`, or the
    /// file cannot be read or written.
    pub(crate) fn derived(
        &mut self,
        path: &Path,
        text: impl AsRef<[u8]>,
    ) -> Result<(), PlantError> {
        let text = text.as_ref();
        if let Some(before) = self.this_run.insert(path.to_path_buf(), text.to_vec()) {
            if before != text {
                return Err(PlantError::Clash {
                    path: path.to_path_buf(),
                });
            }
            return Ok(());
        }
        let shown = self.layout.shown(path);
        let new = sha256(text);
        let fresh = match std::fs::read(path) {
            Ok(old) if old == text => {
                self.manifest.insert(shown, new);
                return Ok(());
            }
            Ok(old) => {
                if self.manifest.get(&shown) != Some(&sha256(&old)) {
                    self.made.edited.push(shown);
                    return Ok(());
                }
                false
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => true,
            Err(source) => {
                return Err(PlantError::Read {
                    path: path.to_path_buf(),
                    source,
                })
            }
        };
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io(parent))?;
        }
        // Written beside, then renamed: a reader sees the old file or the
        // new one, never half of it.
        let partial = path.with_extension("plant-partial");
        std::fs::write(&partial, text).map_err(io(&partial))?;
        std::fs::rename(&partial, path).map_err(io(path))?;
        self.manifest.insert(shown.clone(), new);
        if fresh {
            self.made.made.push(shown);
        } else {
            self.made.updated.push(shown);
        }
        Ok(())
    }

    /// Makes secret or identity `path` with `make` if it does not exist
    /// (`make` creates it and its folder, owner-only); an existing one is
    /// never touched.
    ///
    /// # Errors
    /// What `make` says.
    pub(crate) fn once(
        &mut self,
        path: &Path,
        make: impl FnOnce() -> Result<(), PlantError>,
    ) -> Result<(), PlantError> {
        if path.exists() {
            return Ok(());
        }
        make()?;
        self.made.made.push(self.layout.shown(path));
        Ok(())
    }

    /// Makes symbolic link `path` to `target` if there is none.
    ///
    /// # Errors
    /// It cannot be made.
    pub(crate) fn link(&mut self, path: &Path, target: &str) -> Result<(), PlantError> {
        if path.symlink_metadata().is_ok() {
            return Ok(());
        }
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io(parent))?;
        }
        std::os::unix::fs::symlink(target, path).map_err(io(path))?;
        self.made.made.push(self.layout.shown(path));
        Ok(())
    }

    /// Writes the manifest and says what was done.
    ///
    /// # Errors
    /// The manifest cannot be written.
    pub(crate) fn finish(self) -> Result<Made, PlantError> {
        let mut text = String::new();
        for (file, hash) in &self.manifest {
            text.push_str(&format!("{hash}  {file}\n"));
        }
        let path = self.layout.manifest();
        if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
            std::fs::write(&path, text).map_err(io(&path))?;
        }
        Ok(self.made)
    }
}
