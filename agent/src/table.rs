//! A configuration table checked by the component that owns it: each
//! problem with its place in the text ([`Problem`]), what the check found
//! ([`Checked`]), and a place as a line and a column ([`line_col`]). The
//! configuration's validator (`crate::config`) puts every component's
//! problems at their line and column; a component's check imports nothing
//! of the document.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// One problem and where it is in the configuration's text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem<E> {
    /// The bytes of the configuration it is about.
    pub span: Range<usize>,
    /// The key, dotted (`sparkplug.broker`, `oee.shifts[0].start`).
    pub key: String,
    /// What is wrong.
    pub error: E,
}

/// What a component's check of its table found: its configuration if
/// nothing is wrong, every problem, and what is worth a warning.
#[derive(Debug)]
pub struct Checked<T, E> {
    /// The configuration, when there is no problem.
    pub config: Option<T>,
    /// Every problem.
    pub problems: Vec<Problem<E>>,
    /// Things worth saying at start.
    pub warnings: Vec<String>,
}

impl<T, E> Default for Checked<T, E> {
    fn default() -> Self {
        Checked {
            config: None,
            problems: Vec::new(),
            warnings: Vec::new(),
        }
    }
}

impl<T, E> Checked<T, E> {
    /// Notes a problem: `error` at `span`, of `key`.
    pub fn problem(&mut self, span: Range<usize>, key: impl Into<String>, error: E) {
        self.problems.push(Problem {
            span,
            key: key.into(),
            error,
        });
    }
}

/// The 1-based line and column of byte `offset` in `text`.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Why a duration does not read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DurationError {
    /// Zero.
    #[error("must be longer than zero")]
    Zero,
    /// Not a duration.
    #[error("'{text}' is not a duration ({reason}); write e.g. 100ms, 2s, 30d")]
    NotADuration {
        /// The text.
        text: String,
        /// Why not.
        reason: String,
    },
}

/// A duration longer than zero, as written (`100ms`, `2s`, `30d`).
///
/// # Errors
/// Zero, or not a duration.
pub fn duration(text: &str) -> Result<Duration, DurationError> {
    match humantime::parse_duration(text) {
        Ok(d) if d.is_zero() => Err(DurationError::Zero),
        Ok(d) => Ok(d),
        Err(e) => Err(DurationError::NotADuration {
            text: text.into(),
            reason: e.to_string(),
        }),
    }
}

/// `path` as written in a configuration: relative to `base`, the
/// configuration file's directory, unless absolute.
pub fn path(base: &Path, path: &str) -> PathBuf {
    let p = Path::new(path);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}
