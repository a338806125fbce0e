//! Reading the configuration file into its raw form, with a cell's
//! `[[tags]]` tables read a thousand at a time: a TOML reader holds the
//! whole document it parses, tokens and tables, several times its size in
//! memory (256 MB at peak for 100,000 tags in one file), while the tags are
//! most of any large file and each table stands alone.
//!
//! The document is read with its `[[tags]]` tables blanked out (every byte
//! but a line's end a space, so every place in it stays where it was), then
//! the tables a thousand at a time, each piece the document's own bytes
//! with what is not a tag table between them blanked, and each value's
//! place moved back to where it is in the file. Whatever this way does not
//! read (a tag table that ends inside a multi-line string, a document
//! whose tables this way splits wrongly) is read again whole, as TOML says,
//! so that a file is taken or refused exactly as it would be whole.

use std::ops::Range;

use toml::Spanned;

use super::raw::{RawConfig, RawTag};

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

/// The raw configuration in `text`.
///
/// # Errors
/// The document is no TOML, or not of the configuration's shape.
pub(crate) fn read(text: &str) -> Result<RawConfig, Unread> {
    let tables = tag_tables(text);
    if tables.len() <= TAGS_AT_ONCE {
        return Ok(toml::from_str(text)?);
    }
    in_pieces(text, &tables).or_else(|_| Ok(toml::from_str(text)?))
}

/// The document without its tag tables, then the tables piece by piece.
fn in_pieces(text: &str, tables: &[Range<usize>]) -> Result<RawConfig, Unread> {
    let mut rest = text.as_bytes().to_vec();
    for t in tables {
        blank(&mut rest[t.clone()]);
    }
    let rest = String::from_utf8(rest).map_err(|e| Unread {
        message: e.to_string(),
        at: None,
    })?;
    let mut raw: RawConfig = toml::from_str(&rest)?;
    drop(rest);
    #[derive(serde::Deserialize)]
    struct Piece {
        tags: Vec<RawTag>,
    }
    let mut tags = Vec::with_capacity(tables.len());
    for piece in tables.chunks(TAGS_AT_ONCE) {
        let start = piece[0].start;
        let end = piece[piece.len() - 1].end;
        let mut bytes = text.as_bytes()[start..end].to_vec();
        // Between the tables: other tables of the document, already read.
        for pair in piece.windows(2) {
            blank(&mut bytes[pair[0].end - start..pair[1].start - start]);
        }
        let piece_text = String::from_utf8(bytes).map_err(|e| Unread {
            message: e.to_string(),
            at: None,
        })?;
        let read: Piece = toml::from_str(&piece_text).map_err(|e| {
            let mut u = Unread::from(e);
            u.at = u.at.map(|a| a + start);
            u
        })?;
        if read.tags.len() != piece.len() {
            return Err(Unread {
                message: "the tag tables were split where TOML does not split them".into(),
                at: None,
            });
        }
        tags.extend(read.tags.into_iter().map(|t| shifted(t, start)));
    }
    raw.tags = tags;
    Ok(raw)
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
/// header (or the end).
fn tag_tables(text: &str) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut open: Option<usize> = None;
    let mut at = 0;
    for line in text.split_inclusive('\n') {
        let head = line.trim_start();
        if head.starts_with('[') {
            if let Some(s) = open.take() {
                out.push(s..at);
            }
            let name = head.trim_end();
            let name = name.split('#').next().unwrap_or("").trim_end();
            if name == "[[tags]]" {
                open = Some(at);
            }
        }
        at += line.len();
    }
    if let Some(s) = open {
        out.push(s..text.len());
    }
    out
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
        let pieces =
            in_pieces(&text, &tag_tables(&text)).unwrap_or_else(|e| panic!("{}", e.message));
        assert_eq!(pieces.tags.len(), 2_500);
        assert_eq!(pieces.checks.discrete.len(), 1);
        assert_eq!(
            pieces.metrics.listen.as_ref().map(|l| l.get_ref().clone()),
            Some("off".into())
        );
        for (a, b) in whole.tags.iter().zip(&pieces.tags) {
            assert_eq!(a.name.span(), b.name.span());
            assert_eq!(a.name.get_ref(), b.name.get_ref());
            assert_eq!(a.address.span(), b.address.span());
            assert_eq!(a.comment, b.comment);
        }
        assert_eq!(&text[pieces.tags[2_499].address.span()], "\"X2499.0\"");
    }

    #[test]
    fn a_bad_tag_table_is_said_at_its_place_in_the_file() {
        let text = document(1_500).replace("name = \"t1200\"", "name = 1200");
        let e = read(&text).err().unwrap();
        let at = e.at.unwrap();
        assert!(text[at..].starts_with("1200"), "{}", &text[at..at + 20]);
        // Read whole, the same message.
        let whole = toml::from_str::<RawConfig>(&text).unwrap_err();
        assert_eq!(e.message, whole.message().trim_end());
    }
}
