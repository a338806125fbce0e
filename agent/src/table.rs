//! A configuration table checked by the component that owns it: each
//! problem with its place in the text ([`Problem`]), what the check found
//! ([`Checked`]), and a place as a line and a column ([`line_col`]). The
//! configuration's validator (`crate::config`) puts every component's
//! problems at their line and column; a component's check imports nothing
//! of the document. [`Table`] is the kit the older checks use: problems
//! as text, durations, counts and paths read as the document reads them.

use std::fmt;
use std::ops::Range;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};
use std::time::Duration;

use toml::Spanned;

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
pub(crate) fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Why a duration does not read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum DurationError {
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
pub(crate) fn duration(text: &str) -> Result<Duration, DurationError> {
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
pub(crate) fn path(base: &Path, path: &str) -> PathBuf {
    let p = Path::new(path);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}

/// A whole number out of its range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{value} is not between {} and {}", range.start(), range.end())]
pub(crate) struct OutOfRange {
    /// The number written.
    pub value: i64,
    /// What it may be.
    pub range: RangeInclusive<u32>,
}

/// A whole number in `range`.
///
/// # Errors
/// Outside it.
pub(crate) fn count(value: i64, range: RangeInclusive<u32>) -> Result<u32, OutOfRange> {
    match u32::try_from(value) {
        Ok(n) if range.contains(&n) => Ok(n),
        _ => Err(OutOfRange { value, range }),
    }
}

/// A component's table being checked: where its relative paths start,
/// each problem found with its place, and what is worth a warning.
pub(crate) struct Table<'a> {
    base: &'a Path,
    found: Checked<(), String>,
}

impl<'a> Table<'a> {
    /// A table of a configuration whose relative paths start at `base`.
    pub(crate) fn new(base: &'a Path) -> Table<'a> {
        Table {
            base,
            found: Checked::default(),
        }
    }

    /// Notes a problem of `key` at `span`.
    pub(crate) fn problem(&mut self, span: Range<usize>, key: &str, message: impl fmt::Display) {
        self.found.problem(span, key, message.to_string());
    }

    /// Notes something worth a warning at start.
    pub(crate) fn warn(&mut self, warning: String) {
        self.found.warnings.push(warning);
    }

    /// `p` as written: relative to the configuration's directory.
    pub(crate) fn path(&self, p: &str) -> PathBuf {
        path(self.base, p)
    }

    /// A duration longer than zero, or a problem and `default`.
    pub(crate) fn duration(
        &mut self,
        value: Option<Spanned<String>>,
        key: &str,
        default: Duration,
    ) -> Duration {
        let Some(v) = value else { return default };
        duration(v.get_ref()).unwrap_or_else(|e| {
            self.problem(v.span(), key, e);
            default
        })
    }

    /// A whole number in `range`, or a problem and `default`.
    pub(crate) fn count(
        &mut self,
        value: Spanned<i64>,
        key: &str,
        range: RangeInclusive<u32>,
        default: u32,
    ) -> u32 {
        count(*value.get_ref(), range).unwrap_or_else(|e| {
            self.problem(value.span(), key, e);
            default
        })
    }

    /// What was found: the problems and warnings (the configuration is
    /// what the check returned).
    pub(crate) fn found(self) -> Checked<(), String> {
        self.found
    }
}
