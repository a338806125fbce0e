//! A configuration table checked by the component that owns it: each
//! problem with its place in the text ([`Problem`]), what the check found
//! ([`Checked`]), and a place as a line and a column ([`line_col`]). The
//! configuration's validator (`crate::config`) puts every component's
//! problems at their line and column; a component's check imports nothing
//! of the document.

use std::ops::Range;

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

/// The 1-based line and column of byte `offset` in `text`.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}
