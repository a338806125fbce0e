//! Reading the configuration file into its raw form, with a cell's
//! `[[tags]]` tables read a thousand at a time: a TOML reader holds the
//! whole document it parses, tokens and tables, several times its size in
//! memory (256 MB at peak for 100,000 tags in one file), while the tags are
//! most of any large file and each table stands alone.
//!
//! The document is read with its `[[tags]]` tables blanked out (every byte
//! but a line's end a space, so every place in it stays where it was);
//! the tables are read as the validator asks for them ([`TomlTags`]), a
//! thousand at a time, each piece the document's own bytes with what is not
//! a tag table between them blanked, each value's place moved back to where
//! it is in the file: the file's tags are never all held as raw tables, as
//! a tags file's rows never are. A line inside a multi-line string is no
//! table header; a document that does not read with its tag tables blanked
//! is read whole, as TOML says, so that its problem is said as it would be.

use std::ops::Range;

use toml::Spanned;

use super::raw::{RawConfig, RawTag, TagRows};

/// How many `[[tags]]` tables one piece holds.
const TAGS_AT_ONCE: usize = 1000;

/// Why the document does not read: the message and where, if known.
pub(crate) struct Unread {
    /// What the reader says.
    pub(crate) message: String,
    /// The byte it says it at.
    pub(crate) at: Option<usize>,
}

impl From<toml::de::Error> for Unread {
    fn from(e: toml::de::Error) -> Unread {
        Unread {
            message: e.message().trim_end().to_string(),
            at: e.span().map(|s| s.start),
        }
    }
}

/// The raw configuration in `text`, and, for a document of more than a
/// thousand `[[tags]]` tables, those tables to be read as the validator
/// goes ([`TomlTags`]; `RawConfig::tags` is then empty).
///
/// # Errors
/// The document is no TOML, or not of the configuration's shape.
pub(crate) fn read(text: &str) -> Result<(RawConfig, Option<TomlTags<'_>>), Unread> {
    let tables = tag_tables(text);
    if tables.len() > TAGS_AT_ONCE {
        if let Some(rest) = without_tags(text, &tables) {
            return Ok((rest, Some(TomlTags::new(text, tables))));
        }
    }
    Ok((toml::from_str(text)?, None))
}

/// The document with its tag tables blanked, read; `None` if it does not
/// read that way or still has tag tables (a document this way splits
/// wrongly: read whole instead).
fn without_tags(text: &str, tables: &[Range<usize>]) -> Option<RawConfig> {
    let mut rest = text.as_bytes().to_vec();
    for t in tables {
        blank(&mut rest[t.clone()]);
    }
    let rest = String::from_utf8(rest).ok()?;
    let raw: RawConfig = toml::from_str(&rest).ok()?;
    raw.tags.is_empty().then_some(raw)
}

/// The `[[tags]]` tables of a document, read a thousand at a time as they
/// are asked for; a piece that does not read is a problem at its place.
pub(crate) struct TomlTags<'a> {
    text: &'a str,
    tables: Vec<Range<usize>>,
    /// The next piece's first table.
    next: usize,
    /// The piece being handed out.
    piece: std::vec::IntoIter<RawTag>,
    problems: Vec<(usize, String, String)>,
}

impl<'a> TomlTags<'a> {
    fn new(text: &'a str, tables: Vec<Range<usize>>) -> TomlTags<'a> {
        TomlTags {
            text,
            tables,
            next: 0,
            piece: Vec::new().into_iter(),
            problems: Vec::new(),
        }
    }

    /// Reads the next piece, or says why it does not read.
    fn read_piece(&mut self) {
        let end_table = (self.next + TAGS_AT_ONCE).min(self.tables.len());
        let piece = &self.tables[self.next..end_table];
        let key = format!("tags[{}]", self.next);
        self.next = end_table;
        match read_piece(self.text, piece) {
            Ok(tags) => self.piece = tags.into_iter(),
            Err(e) => self
                .problems
                .push((e.at.unwrap_or(piece[0].start), key, e.message)),
        }
    }
}

impl Iterator for TomlTags<'_> {
    type Item = RawTag;

    fn next(&mut self) -> Option<RawTag> {
        loop {
            if let Some(t) = self.piece.next() {
                return Some(t);
            }
            if self.next >= self.tables.len() {
                return None;
            }
            self.read_piece();
        }
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (0, Some(self.tables.len()))
    }
}

impl TagRows for TomlTags<'_> {
    fn problems(&mut self) -> Vec<(usize, String, String)> {
        std::mem::take(&mut self.problems)
    }
}

/// The tag tables `piece` of `text`, each value at its place in `text`.
fn read_piece(text: &str, piece: &[Range<usize>]) -> Result<Vec<RawTag>, Unread> {
    #[derive(serde::Deserialize)]
    struct Piece {
        tags: Vec<RawTag>,
    }
    let start = piece[0].start;
    let end = piece[piece.len() - 1].end;
    let mut bytes = text.as_bytes()[start..end].to_vec();
    // Between the tables: other tables of the document, read with it.
    for pair in piece.windows(2) {
        blank(&mut bytes[pair[0].end - start..pair[1].start - start]);
    }
    let piece_text = String::from_utf8(bytes).map_err(|e| Unread {
        message: e.to_string(),
        at: Some(start),
    })?;
    let read: Piece = toml::from_str(&piece_text).map_err(|e| {
        let mut u = Unread::from(e);
        u.at = u.at.map(|a| a + start);
        u
    })?;
    if read.tags.len() != piece.len() {
        return Err(Unread {
            message: format!(
                "{} [[tags]] tables read where {} begin: a table header inside a value?",
                read.tags.len(),
                piece.len()
            ),
            at: Some(start),
        });
    }
    Ok(read.tags.into_iter().map(|t| shifted(t, start)).collect())
}

/// Every byte a space but the ends of lines.
fn blank(bytes: &mut [u8]) {
    for b in bytes {
        if *b != b'\n' && *b != b'\r' {
            *b = b' ';
        }
    }
}

/// Where each `[[tags]]` table is: from its header line to the next table
/// header (or the end). A line inside a multi-line string is no header.
fn tag_tables(text: &str) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut open: Option<usize> = None;
    let mut string: Option<&str> = None;
    let mut at = 0;
    for line in text.split_inclusive('\n') {
        let head = line.trim_start();
        if string.is_none() && head.starts_with('[') {
            if let Some(s) = open.take() {
                out.push(s..at);
            }
            let name = head.split('#').next().unwrap_or("").trim_end();
            if name == "[[tags]]" {
                open = Some(at);
            }
        }
        string = multi_line_string(line, string);
        at += line.len();
    }
    if let Some(s) = open {
        out.push(s..text.len());
    }
    out
}

/// Whether a multi-line string (`"""` or `\'\'\'`) is open after `line`,
/// given whether one was before it.
fn multi_line_string<'d>(line: &str, mut open: Option<&'d str>) -> Option<&'d str> {
    let mut rest = line;
    loop {
        match open {
            Some(d) => match rest.find(d) {
                Some(i) => {
                    rest = &rest[i + 3..];
                    open = None;
                }
                None => return open,
            },
            None => {
                let found = [r#"""""#, "\'\'\'"]
                    .into_iter()
                    .filter_map(|d| rest.find(d).map(|i| (i, d)))
                    .min();
                match found {
                    Some((i, d)) if !rest[..i].contains('#') => {
                        rest = &rest[i + 3..];
                        open = Some(d);
                    }
                    _ => return None,
                }
            }
        }
    }
}

/// `tag` with every value's place moved `by` bytes on.
fn shifted(tag: RawTag, by: usize) -> RawTag {
    fn moved<T>(v: Spanned<T>, by: usize) -> Spanned<T> {
        let span = v.span();
        Spanned::new(span.start + by..span.end + by, v.into_inner())
    }
    RawTag {
        name: moved(tag.name, by),
        node_id: moved(tag.node_id, by),
        address: moved(tag.address, by),
        comment: tag.comment,
        value_type: tag.value_type.map(|v| moved(v, by)),
        bit: tag.bit.map(|v| moved(v, by)),
        sampling_interval: tag.sampling_interval.map(|v| moved(v, by)),
        deadband: tag.deadband.map(|v| moved(v, by)),
        deadband_percent: tag.deadband_percent.map(|v| moved(v, by)),
        export: tag.export,
        max: tag.max.map(|v| moved(v, by)),
        states: tag.states.map(|v| moved(v, by)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A document of `n` tags, a check between them and a table after.
    fn document(n: usize) -> String {
        let mut t = String::from("[cell]\nid = \"c1\"\n\n");
        for i in 0..n {
            t += &format!(
                "[[tags]]  # tag {i}\nname = \"t{i}\"\nnode_id = \"ns=2;s=T{i}\"\naddress = \"X{i}.0\"\ncomment = \"[not a header] é\"\n\n"
            );
            if i == n / 2 {
                t += "[[checks.discrete]]\nid = \"d\"\ntag = \"t1\"\n\n";
            }
        }
        t += "[metrics]\nlisten = \"off\"\n";
        t
    }

    #[test]
    fn tag_tables_read_in_pieces_are_the_tables_read_whole_at_their_places() {
        let text = document(2_500);
        let whole: RawConfig = toml::from_str(&text).unwrap();
        let (rest, tags) = read(&text).unwrap_or_else(|e| panic!("{}", e.message));
        let mut tags = tags.unwrap();
        let pieces: Vec<RawTag> = tags.by_ref().collect();
        assert!(tags.problems().is_empty());
        assert!(rest.tags.is_empty());
        assert_eq!(pieces.len(), 2_500);
        assert_eq!(rest.checks.discrete.len(), 1);
        assert_eq!(
            rest.metrics.listen.as_ref().map(|l| l.get_ref().clone()),
            Some("off".into())
        );
        for (a, b) in whole.tags.iter().zip(&pieces) {
            assert_eq!(a.name.span(), b.name.span());
            assert_eq!(a.name.get_ref(), b.name.get_ref());
            assert_eq!(a.address.span(), b.address.span());
            assert_eq!(a.comment, b.comment);
        }
        assert_eq!(&text[pieces[2_499].address.span()], "\"X2499.0\"");
    }

    #[test]
    fn a_bad_tag_table_is_said_at_its_place_in_the_file() {
        let text = document(1_500).replace("name = \"t1200\"", "name = 1200");
        let (_, tags) = read(&text).unwrap_or_else(|e| panic!("{}", e.message));
        let mut tags = tags.unwrap();
        assert_eq!(tags.by_ref().count(), 1_000);
        let problems = tags.problems();
        assert_eq!(problems.len(), 1, "{problems:?}");
        let (at, key, message) = &problems[0];
        assert!(text[*at..].starts_with("1200"), "{}", &text[*at..*at + 20]);
        assert_eq!(key, "tags[1000]");
        // Read whole, the same message.
        let whole = toml::from_str::<RawConfig>(&text).unwrap_err();
        assert_eq!(message, whole.message().trim_end());
    }

    #[test]
    fn a_header_inside_a_multi_line_string_is_no_table() {
        let mut text = document(1_200);
        text = text.replacen(
            "comment = \"[not a header] é\"",
            "comment = \"\"\"two\n[[tags]]\nlines\"\"\"",
            1,
        );
        assert_eq!(tag_tables(&text).len(), 1_200);
        let (_, tags) = read(&text).unwrap_or_else(|e| panic!("{}", e.message));
        let first = tags.unwrap().next().unwrap();
        assert_eq!(first.comment.as_deref(), Some("two\n[[tags]]\nlines"));
    }
}
