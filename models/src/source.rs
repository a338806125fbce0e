//! Where a piece of input came from, and the error that points at it.
//!
//! Every error a user can cause by bad input carries its origin (a file name,
//! or the name of a command-line option), the 1-based line and column, and a
//! message that quotes the offending text. This module owns that shape; it
//! does not read files.

use std::borrow::Cow;
use std::fmt;

pub use encoding_rs::{Encoding, UTF_8};

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

/// Several errors in one input, reported together, one per line — at most
/// [`SourceErrors::SHOWN`] of them, then how many more there are.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceErrors(pub Vec<SourceError>);

impl SourceErrors {
    /// `value` if no error was found, else the errors.
    ///
    /// # Errors
    /// `errors`, when there are any.
    pub fn or_ok<T>(value: T, errors: Vec<SourceError>) -> Result<T, SourceErrors> {
        if errors.is_empty() {
            Ok(value)
        } else {
            Err(SourceErrors(errors))
        }
    }

    /// How many errors are printed; a file in the wrong format would
    /// otherwise print one per line.
    pub const SHOWN: usize = 20;

    /// The printed lines: the first [`SourceErrors::SHOWN`] errors, then a
    /// count of the rest.
    pub fn lines(&self) -> Vec<String> {
        let mut out: Vec<String> = self
            .0
            .iter()
            .take(Self::SHOWN)
            .map(ToString::to_string)
            .collect();
        if self.0.len() > Self::SHOWN {
            out.push(format!(
                "... and {} more errors ({} in all)",
                self.0.len() - Self::SHOWN,
                self.0.len()
            ));
        }
        out
    }
}

impl fmt::Display for SourceErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.lines().join("\n"))
    }
}

impl std::error::Error for SourceErrors {}

impl From<SourceError> for SourceErrors {
    fn from(e: SourceError) -> Self {
        SourceErrors(vec![e])
    }
}

/// An encoding's name that no encoding answers to.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown encoding '{label}': use utf-8, utf-16le, utf-16be or latin1 (windows-1252)")]
pub struct UnknownEncoding {
    /// The name as given.
    pub label: String,
}

/// The encoding a user names (`--encoding`): any WHATWG label, such as
/// `utf-8`, `utf-16le`, `utf-16be`, `latin1`, `iso-8859-1`, `windows-1252`.
///
/// # Errors
/// [`UnknownEncoding`]: a label no encoding answers to.
pub fn encoding(label: &str) -> Result<&'static Encoding, UnknownEncoding> {
    Encoding::for_label(label.trim().as_bytes()).ok_or_else(|| UnknownEncoding {
        label: label.into(),
    })
}

/// Decodes a text file: a byte-order mark decides (UTF-8, UTF-16 LE/BE);
/// otherwise `encoding` if given; otherwise UTF-8 if the bytes are UTF-8,
/// and Windows-1252 (a superset of Latin-1, the encoding of older European
/// PLC sources) if they are not. UTF-16 without a byte-order mark is told
/// apart by its zero bytes and refused with the option that reads it.
///
/// # Errors
/// Bytes that are not text in the encoding used: the line and column of
/// the first bad byte, and the byte.
pub fn text<'a>(
    origin: &str,
    bytes: &'a [u8],
    encoding: Option<&'static Encoding>,
) -> Result<Cow<'a, str>, SourceError> {
    if let Some((bom, len)) = Encoding::for_bom(bytes) {
        return decode(origin, &bytes[len..], bom);
    }
    if let Some(e) = encoding {
        return decode(origin, bytes, e);
    }
    if let Ok(s) = std::str::from_utf8(bytes) {
        if !s.contains('\0') {
            return Ok(Cow::Borrowed(s));
        }
    }
    let zeros = |parity: usize| {
        bytes
            .iter()
            .skip(parity)
            .step_by(2)
            .take(512)
            .filter(|&&b| b == 0)
            .count()
    };
    let (even, odd) = (zeros(0), zeros(1));
    let pairs = bytes.len().min(1024) / 2;
    if pairs > 0 && even.max(odd) * 2 > pairs {
        let guess = if odd > even { "utf-16le" } else { "utf-16be" };
        return Err(SourceError::new(
            origin,
            Location::line_start(1),
            format!(
                "this looks like UTF-16 text without a byte-order mark: pass --encoding {guess}"
            ),
        ));
    }
    decode(origin, bytes, encoding_rs::WINDOWS_1252)
}

fn decode<'a>(
    origin: &str,
    bytes: &'a [u8],
    encoding: &'static Encoding,
) -> Result<Cow<'a, str>, SourceError> {
    if encoding == encoding_rs::UTF_8 {
        return match std::str::from_utf8(bytes) {
            Ok(s) => Ok(Cow::Borrowed(s)),
            Err(e) => {
                let good = &bytes[..e.valid_up_to()];
                // The prefix is valid UTF-8 by construction.
                let prefix = std::str::from_utf8(good).unwrap_or_default();
                Err(SourceError::new(
                    origin,
                    end_of(prefix),
                    format!(
                        "not UTF-8 text (byte 0x{:02X}); pass --encoding latin1 (or the file's encoding), or save it as UTF-8",
                        bytes[e.valid_up_to()]
                    ),
                ))
            }
        };
    }
    match encoding.decode_without_bom_handling_and_without_replacement(bytes) {
        Some(text) => Ok(text),
        None => {
            // Where it goes wrong: the text decoded with replacements, up
            // to the first replacement character.
            let (lossy, _) = encoding.decode_without_bom_handling(bytes);
            let bad = lossy.find('\u{FFFD}').unwrap_or(lossy.len());
            Err(SourceError::new(
                origin,
                end_of(&lossy[..bad]),
                format!("not {} text", encoding.name()),
            ))
        }
    }
}

/// The location just after `prefix`.
fn end_of(prefix: &str) -> Location {
    let line = prefix.matches('\n').count() + 1;
    let col = prefix.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    Location { line, col }
}

/// The 1-based column of the byte offset `offset` within `line`.
pub(crate) fn column(line: &str, offset: usize) -> usize {
    line[..offset.min(line.len())].chars().count() + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_utf8_names_line_column_and_byte_when_utf8_is_asked_for() {
        let err = text(
            "prog.il",
            b"RD X0.00\nWRT \xFFY0.00\n",
            Some(encoding_rs::UTF_8),
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "prog.il:2:5: not UTF-8 text (byte 0xFF); pass --encoding latin1 (or the file's encoding), or save it as UTF-8"
        );
    }

    #[test]
    fn utf8_passes_through() {
        assert_eq!(
            text("a", "RD X1 ; ü".as_bytes(), None).unwrap(),
            "RD X1 ; ü"
        );
        let bom = b"\xEF\xBB\xBFLD a";
        assert_eq!(text("a", bom, None).unwrap(), "LD a");
    }

    #[test]
    fn latin1_and_utf16_are_read() {
        // An old German STL comment: "Förderband" in Latin-1.
        let latin1 = b"U E 0.0 // F\xF6rderband\n= A 4.0\n";
        assert_eq!(
            text("a.awl", latin1, None).unwrap(),
            "U E 0.0 // Förderband\n= A 4.0\n"
        );
        assert_eq!(
            text("a.awl", latin1, Some(encoding("latin1").unwrap())).unwrap(),
            "U E 0.0 // Förderband\n= A 4.0\n"
        );
        let utf16: Vec<u8> = [0xFF, 0xFE]
            .into_iter()
            .chain("LD ä\n".encode_utf16().flat_map(u16::to_le_bytes))
            .collect();
        assert_eq!(text("a.il", &utf16, None).unwrap(), "LD ä\n");
        let be: Vec<u8> = [0xFE, 0xFF]
            .into_iter()
            .chain("LD a".encode_utf16().flat_map(u16::to_be_bytes))
            .collect();
        assert_eq!(text("a.il", &be, None).unwrap(), "LD a");
        let bare: Vec<u8> = "LD a\nST b\n"
            .encode_utf16()
            .flat_map(u16::to_le_bytes)
            .collect();
        assert_eq!(
            text("a.il", &bare, None).unwrap_err().to_string(),
            "a.il:1:1: this looks like UTF-16 text without a byte-order mark: pass --encoding utf-16le"
        );
        assert_eq!(
            text("a.il", &bare, Some(encoding("utf-16le").unwrap())).unwrap(),
            "LD a\nST b\n"
        );
        assert_eq!(
            encoding("klingon").unwrap_err().to_string(),
            "unknown encoding 'klingon': use utf-8, utf-16le, utf-16be or latin1 (windows-1252)"
        );
    }

    #[test]
    fn at_most_twenty_errors_are_printed() {
        let errors = SourceErrors(
            (1..=1139)
                .map(|l| SourceError::new("p.il", Location::line_start(l), "unknown instruction"))
                .collect(),
        );
        let printed = errors.to_string();
        assert_eq!(printed.lines().count(), 21);
        assert!(printed.lines().nth(19).unwrap().starts_with("p.il:20:1: "));
        assert_eq!(
            printed.lines().last().unwrap(),
            "... and 1119 more errors (1139 in all)"
        );
    }
}
