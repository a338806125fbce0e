//! The I/O database of paper 000: address → comment.
//!
//! Read from CSV `address,comment` (a header row `address,comment` is
//! optional; quote comments that contain commas), or from a TIA Portal tag
//! table exported as SimaticML (`SW.Tags.PlcTagTable`: each tag's name and
//! address get its comment). A comment ending in `(B)` marks a
//! normally-closed contact. This module parses text it is given; it opens
//! no file.

use std::collections::HashMap;

use crate::signal::{AddressError, Signal};
use crate::source::{Location, SourceError};

/// Comments by signal.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CommentDb {
    comments: HashMap<Signal, String>,
}

impl FromIterator<(Signal, String)> for CommentDb {
    fn from_iter<I: IntoIterator<Item = (Signal, String)>>(pairs: I) -> Self {
        CommentDb {
            comments: pairs.into_iter().collect(),
        }
    }
}

/// Whether `text` is a TIA Portal export (SimaticML) whose comments a
/// program exported beside it should get: a PLC tag table. TIA writes one
/// object per file, so a block's tag table is a file of its own in the
/// same folder.
pub fn is_tag_table(text: &str) -> bool {
    crate::programs::simaticml::is_simaticml(text) && text.contains("<SW.Tags.PlcTagTable")
}

/// Whether `text` is a TIA Portal export (SimaticML): a block or a tag
/// table.
pub fn is_simaticml(text: &str) -> bool {
    crate::programs::simaticml::is_simaticml(text)
}

impl CommentDb {
    /// Parses `address,comment` rows, or a TIA Portal tag table (told by
    /// its content); `resolve` canonicalises addresses in the program's
    /// dialect (its error is the message at the row or tag).
    ///
    /// # Errors
    /// The first malformed row or tag, as `ORIGIN:LINE:COL: message`.
    pub fn parse(
        origin: &str,
        text: &str,
        resolve: impl Fn(&str) -> Result<Signal, AddressError>,
    ) -> Result<CommentDb, SourceError> {
        Self::parse_in(origin, text, resolve, None)
    }

    /// [`CommentDb::parse`], a TIA Portal tag table's comments taken in
    /// `language` (`de-DE`) where they have it; `None`: in `en-US`. Else in
    /// the first language that has a text.
    ///
    /// # Errors
    /// As [`CommentDb::parse`].
    pub fn parse_in(
        origin: &str,
        text: &str,
        resolve: impl Fn(&str) -> Result<Signal, AddressError>,
        language: Option<&str>,
    ) -> Result<CommentDb, SourceError> {
        if crate::programs::simaticml::is_simaticml(text) {
            let language = language.unwrap_or(crate::programs::simaticml::LANGUAGE);
            return Self::tag_table(origin, text, resolve, language);
        }
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_reader(text.as_bytes());
        let mut comments = HashMap::new();
        let mut first = true;
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(1, |p| p.line() as usize);
                SourceError::new(
                    origin,
                    Location::line_start(line),
                    format!("unreadable CSV: {e}"),
                )
            })?;
            let line = record.position().map_or(1, |p| p.line() as usize);
            let at = Location::line_start(line);
            let header = first
                && record
                    .get(0)
                    .is_some_and(|a| a.eq_ignore_ascii_case("address"));
            first = false;
            if header || record.iter().all(str::is_empty) {
                continue;
            }
            if record.len() != 2 {
                let row = record.iter().collect::<Vec<_>>().join(",");
                return Err(SourceError::new(
                    origin,
                    at,
                    format!("expected 'address,comment', found {} fields in '{row}' (quote comments that contain commas)", record.len()),
                ));
            }
            let signal =
                resolve(&record[0]).map_err(|e| SourceError::new(origin, at, e.to_string()))?;
            comments.insert(signal, record[1].to_string());
        }
        Ok(CommentDb { comments })
    }

    /// A tag table's comments: each tag's name (`"Start"`) and, when the
    /// program's dialect reads it as a bit, its address (`%I0.0`; a German
    /// `%E0.0` as `E0.0` and `I0.0`).
    fn tag_table(
        origin: &str,
        text: &str,
        resolve: impl Fn(&str) -> Result<Signal, AddressError>,
        language: &str,
    ) -> Result<CommentDb, SourceError> {
        let mut comments = HashMap::new();
        for tag in crate::programs::simaticml::tag_table(origin, text, language)? {
            let Some(comment) = tag.comment.clone() else {
                continue;
            };
            let signal =
                resolve(&tag.name).map_err(|e| SourceError::new(origin, tag.at, e.to_string()))?;
            comments.insert(signal, comment.clone());
            // A word (`%MW10`) is not a contact: its name carries the
            // comment. A German address (`%E0.0`) gives its English form
            // (`I0.0`), a block's absolute operand, the comment too.
            for address in tag.addresses().iter().filter_map(|a| resolve(a).ok()) {
                comments.insert(address, comment.clone());
            }
        }
        Ok(CommentDb { comments })
    }

    /// This database with `over`'s comments added, replacing any for the
    /// same signal (a CSV file over the program's own declarations).
    #[must_use]
    pub fn overridden_by(mut self, over: CommentDb) -> CommentDb {
        self.comments.extend(over.comments);
        self
    }

    /// The comment of `signal`, if the database has one.
    pub fn get(&self, signal: &Signal) -> Option<&str> {
        self.comments.get(signal).map(String::as_str)
    }

    /// How many addresses have a comment.
    pub fn len(&self) -> usize {
        self.comments.len()
    }

    /// Whether the database is empty.
    pub fn is_empty(&self) -> bool {
        self.comments.is_empty()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_tag_table_is_told_from_a_block_and_from_csv() {
        let table = include_str!("../../tests/data/paper000/fig6.tags.SimaticML.xml");
        let block = include_str!("../../tests/data/paper000/fig6.lad.SimaticML.xml");
        assert!(super::is_tag_table(table));
        assert!(!super::is_tag_table(block));
        assert!(super::is_simaticml(block));
        assert!(!super::is_tag_table(
            "address,comment\nX1,<SW.Tags.PlcTagTable\n"
        ));
    }

    use super::*;
    use crate::signal::pmc_address;

    #[test]
    fn reads_table_rows() {
        let db = CommentDb::parse(
            "c.csv",
            "address,comment\nX0.06,Y Over Travel Limit SW (B)\nx0.a,\"Z2 Over Travel, Limit SW (B)\"\n\n# note\n",
            pmc_address,
        )
        .unwrap();
        assert_eq!(
            db.get(&Signal::new("X0.06")),
            Some("Y Over Travel Limit SW (B)")
        );
        assert_eq!(
            db.get(&Signal::new("X0.0A")),
            Some("Z2 Over Travel, Limit SW (B)")
        );
        assert_eq!(db.len(), 2);
    }

    #[test]
    fn bad_rows_are_pinned() {
        let e = CommentDb::parse("c.csv", "X0.06,a\nX0.0G,b\n", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.csv:2:1: malformed address 'X0.0G': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)"
        );
        let e = CommentDb::parse("c.csv", "X0.06,a,b\n", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.csv:1:1: expected 'address,comment', found 3 fields in 'X0.06,a,b' (quote comments that contain commas)"
        );
    }
}
