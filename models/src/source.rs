//! Where a piece of input came from, and the error that points at it.
//!
//! Every error a user can cause by bad input carries its origin (a file name,
//! or the name of a command-line option), the 1-based line and column, and a
//! message that quotes the offending text. This module owns that shape; it
//! does not read files.

use std::fmt;

/// A 1-based line and column in a text input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Location {
    /// Line number, starting at 1.
    pub line: usize,
    /// Column number in characters, starting at 1.
    pub col: usize,
}

impl Location {
    /// The location of a line's first character.
    pub fn line_start(line: usize) -> Self {
        Location { line, col: 1 }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.col)
    }
}

/// An error in a text input, printed as `ORIGIN:LINE:COL: message`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{origin}:{at}: {message}")]
pub struct SourceError {
    /// The file name or option the text came from.
    pub origin: String,
    /// Where in the text the problem is.
    pub at: Location,
    /// What is wrong, quoting the input.
    pub message: String,
}

impl SourceError {
    /// An error at `at` in `origin`.
    pub fn new(origin: &str, at: Location, message: impl Into<String>) -> Self {
        SourceError {
            origin: origin.to_string(),
            at,
            message: message.into(),
        }
    }
}

/// Several errors in one input, reported together, one per line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceErrors(pub Vec<SourceError>);

impl fmt::Display for SourceErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for SourceErrors {}

impl From<SourceError> for SourceErrors {
    fn from(e: SourceError) -> Self {
        SourceErrors(vec![e])
    }
}

/// Checks that `bytes` are UTF-8 text and returns them as `&str`.
///
/// # Errors
/// A [`SourceError`] at the line and column of the first byte that is not
/// UTF-8, naming that byte.
pub fn text<'a>(origin: &str, bytes: &'a [u8]) -> Result<&'a str, SourceError> {
    match std::str::from_utf8(bytes) {
        Ok(s) => Ok(s),
        Err(e) => {
            let good = &bytes[..e.valid_up_to()];
            // The prefix is valid UTF-8 by construction.
            let prefix = std::str::from_utf8(good).unwrap_or_default();
            let line = prefix.matches('\n').count() + 1;
            let col = prefix.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            let byte = bytes[e.valid_up_to()];
            Err(SourceError::new(
                origin,
                Location { line, col },
                format!("not UTF-8 text (byte 0x{byte:02X}); save the file as UTF-8 or ASCII"),
            ))
        }
    }
}

/// The 1-based column of the byte offset `offset` within `line`.
pub(crate) fn column(line: &str, offset: usize) -> usize {
    line[..offset.min(line.len())].chars().count() + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_utf8_names_line_column_and_byte() {
        let err = text("prog.il", b"RD X0.00\nWRT \xFFY0.00\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "prog.il:2:5: not UTF-8 text (byte 0xFF); save the file as UTF-8 or ASCII"
        );
    }

    #[test]
    fn utf8_passes_through() {
        assert_eq!(text("a", "RD X1 ; ü".as_bytes()).unwrap(), "RD X1 ; ü");
    }
}
