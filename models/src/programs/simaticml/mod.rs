//! Programs from Siemens TIA Portal: SimaticML, the XML that TIA Openness
//! (or a block's "Export") writes, one object per file: a block
//! (`SW.Blocks.FC`, `FB`, `OB`) whose LAD and FBD networks are read as
//! instructions, or a tag table (`SW.Tags.PlcTagTable`) whose comments
//! are an I/O list.
//!
//! Each network (`SW.Blocks.CompileUnit`) with a `FlgNet` source (any
//! version, `.../NetworkSource/FlgNet/v1` to `v5`) is read by [`flgnet`];
//! STL, SCL and GRAPH networks are warnings at the network ("not read").
//! Every message is located and names the block and network:
//! `FILE:LINE:COL: block "Conveyor" network 3: part 'Calc' is not read`.
//!
//! # Addresses
//! Signals are named as the STL reader names them, so a SimaticML block and
//! its STL source give the same signals, observability and comments:
//!
//! | SimaticML | signal | STL |
//! |---|---|---|
//! | `<Address Area="Input" Type="Bool" BitOffset="9"/>` | `I1.1` | `I 1.1` |
//! | `Area="Output"`, `"Memory"`, `"Local"` | `Q4.0`, `M10.1`, `L0.0` | `Q 4.0`, `M 10.1` |
//! | `Area="DB" BlockNumber="1"` | `DB1.DBX2.3` | `DB1.DBX 2.3` |
//! | `Type="Int"` / `"Byte"` / `"DInt"` (compared only) | `MW10`, `MB0`, `MD4` | `MW 10` |
//! | global tag `<Symbol><Component Name="Start"/>` | `Start` | `"Start"` |
//! | DB member `"Line_DB".Ready` (two components) | `Line_DB.Ready` | `"Line_DB".Ready` |
//! | local `#Release` in block `Valve` (`Scope="LocalVariable"`) | `Valve.#Release` | `"Valve".#Release` |
//! | IEC timer `TON` of instance `"T1_DB"`, output `Q` | `T1_DB.Q` | |
//! | tag-table address `%I0.0`, `%E0.0`, `%Q4.0`, `%M10.1` | `I0.0`, `E0.0`, `Q4.0`, `M10.1` | as written |
//!
//! A tag table's address keeps the project's mnemonics (`%E0.0` in a
//! German project, as STL's `E 0.0`); a block's `Address` is always
//! English (`I`), the way Openness writes areas. So a German address's
//! comment goes to its English form too (`%E0.0` to `I0.0`, `%A4.0` to
//! `Q4.0`, `%PEW256` to `PIW256`, `%Z3` to `C3`), where a block's
//! absolute operands meet it.
//!
//! # Comments
//! A block's interface members (`Section/Member/Comment`) and a tag
//! table's tags (`Comment`) carry comments in several languages; the
//! `en-US` text is taken, else the first language that has one.

mod access;
mod flgnet;

use roxmltree::{Document, Node};

use super::{plcopen, Instruction, Operation, Outside};
use crate::source::{Location, SourceError, SourceErrors};
use access::{at, child, text_of, Place};

/// The comment language taken when a text has it, unless one is asked
/// for (`--language`, `comment_language`).
pub const LANGUAGE: &str = "en-US";

/// Whether `text` is a SimaticML document: its root element is
/// `<Document>`.
pub(crate) fn is_simaticml(text: &str) -> bool {
    let mut rest = text.trim_start_matches('\u{FEFF}').trim_start();
    loop {
        if let Some(r) = rest.strip_prefix("<?") {
            match r.find("?>") {
                Some(end) => rest = r[end + 2..].trim_start(),
                None => return false,
            }
        } else if let Some(r) = rest.strip_prefix("<!--") {
            match r.find("-->") {
                Some(end) => rest = r[end + 3..].trim_start(),
                None => return false,
            }
        } else {
            break;
        }
    }
    rest.strip_prefix("<Document")
        .is_some_and(|r| r.starts_with(['>', '/']) || r.starts_with(char::is_whitespace))
}

/// The text of `texts` (`(language, text)`) in `lang`, else the first
/// that is not empty; whitespace collapsed.
fn pick<'a>(lang: &str, texts: impl Iterator<Item = (&'a str, String)>) -> Option<String> {
    let texts: Vec<(&str, String)> = texts
        .map(|(l, t)| (l, t.split_whitespace().collect::<Vec<_>>().join(" ")))
        .filter(|(_, t)| !t.is_empty())
        .collect();
    texts
        .iter()
        .find(|(l, _)| l.eq_ignore_ascii_case(lang))
        .or_else(|| texts.first())
        .map(|(_, t)| t.clone())
}

/// An interface member's comment (`<Comment><MultiLanguageText Lang=..>`).
fn member_comment(member: Node<'_, '_>, lang: &str) -> Option<String> {
    let comment = child(member, "Comment")?;
    pick(
        lang,
        comment
            .children()
            .filter(|c| c.has_tag_name("MultiLanguageText"))
            .map(|c| (c.attribute("Lang").unwrap_or(""), text_of(c))),
    )
}

/// An object's comment (`<MultilingualText CompositionName="Comment">`
/// with its items' `Culture` and `Text`).
fn object_comment(object: Node<'_, '_>, lang: &str) -> Option<String> {
    let text = child(object, "ObjectList")?.children().find(|c| {
        c.has_tag_name("MultilingualText") && c.attribute("CompositionName") == Some("Comment")
    })?;
    pick(
        lang,
        text.descendants()
            .filter(|c| c.has_tag_name("MultilingualTextItem"))
            .filter_map(|item| {
                let attrs = child(item, "AttributeList")?;
                let culture = child(attrs, "Culture")?.text().unwrap_or("").trim();
                Some((
                    culture,
                    child(attrs, "Text").map(text_of).unwrap_or_default(),
                ))
            }),
    )
}

/// How deep interface structures are followed for comments.
const MAX_MEMBER_DEPTH: usize = 16;

/// `(name, comment)` of every member under `parent` with a comment, the
/// name `prefix` + the member's path.
fn members(
    parent: Node<'_, '_>,
    prefix: &str,
    depth: usize,
    lang: &str,
    out: &mut Vec<(String, String)>,
) {
    if depth > MAX_MEMBER_DEPTH {
        return;
    }
    for m in parent.children().filter(|c| c.has_tag_name("Member")) {
        let Some(name) = m.attribute("Name") else {
            continue;
        };
        let path = format!("{prefix}{name}");
        if let Some(c) = member_comment(m, lang) {
            out.push((path.clone(), c));
        }
        members(m, &format!("{path}."), depth + 1, lang, out);
    }
}

/// The comments of a block's or a global DB's interface, named as STL
/// names them: `"Valve".#Release`, `"Line_DB".Ready`.
fn interface_comments(
    block: Node<'_, '_>,
    name: &str,
    db: bool,
    lang: &str,
) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let sections = child(block, "AttributeList")
        .and_then(|a| child(a, "Interface"))
        .and_then(|i| child(i, "Sections"));
    for section in sections
        .into_iter()
        .flat_map(|s| s.children())
        .filter(|c| c.has_tag_name("Section"))
    {
        let prefix = if db {
            format!("\"{name}\".")
        } else {
            format!("\"{name}\".#")
        };
        members(section, &prefix, 0, lang, &mut out);
    }
    out
}

/// A tag of a tag table: its name (`"Start"`), its address as STL writes
/// it (`I0.0`, from `%I0.0`), its comment, and where it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Tag {
    pub(crate) name: String,
    pub(crate) address: Option<String>,
    pub(crate) comment: Option<String>,
    pub(crate) at: Location,
}

impl Tag {
    /// The addresses the tag's comment belongs to: its address as written
    /// and, in German mnemonics, its English form too (`E0.0` and `I0.0`),
    /// which a block's absolute addresses use.
    pub(crate) fn addresses(&self) -> Vec<String> {
        let Some(address) = &self.address else {
            return Vec::new();
        };
        let mut out = vec![address.clone()];
        out.extend(english(address));
        out
    }
}

/// A German-mnemonic address (`E0.0`, `AW4`, `PEW256`, `Z3`) in English
/// mnemonics (`I0.0`, `QW4`, `PIW256`, `C3`); `None` for one written alike
/// in both (`M10.1`, `MW10`, `T1`) or not an address.
pub(crate) fn english(address: &str) -> Option<String> {
    let letters = address
        .chars()
        .take_while(char::is_ascii_alphabetic)
        .count();
    let (area, rest) = address.split_at(letters);
    if !rest.starts_with(|c: char| c.is_ascii_digit()) {
        return None;
    }
    let area = area.to_ascii_uppercase();
    let (head, size) = if let Some(size) = area.strip_prefix("PE") {
        ("PI", size)
    } else if let Some(size) = area.strip_prefix("PA") {
        ("PQ", size)
    } else if let Some(size) = area.strip_prefix('E') {
        ("I", size)
    } else if let Some(size) = area.strip_prefix('A') {
        ("Q", size)
    } else if area == "Z" {
        ("C", "")
    } else {
        return None;
    };
    matches!(size, "" | "X" | "B" | "W" | "D").then(|| format!("{head}{size}{rest}"))
}

/// The tags of every tag table in `doc`.
fn tags(doc: &Document<'_>, lang: &str) -> Vec<Tag> {
    doc.descendants()
        .filter(|n| n.has_tag_name("SW.Tags.PlcTag"))
        .filter_map(|tag| {
            let attrs = child(tag, "AttributeList")?;
            let name = text_of(child(attrs, "Name")?);
            let address = child(attrs, "LogicalAddress")
                .map(text_of)
                .map(|a| a.trim_start_matches('%').to_string())
                .filter(|a| !a.is_empty());
            Some(Tag {
                name: format!("\"{name}\""),
                address,
                comment: object_comment(tag, lang),
                at: at(doc, tag),
            })
        })
        .collect()
}

/// The tags of the tag table `text` (a SimaticML document).
///
/// # Errors
/// XML that is not well-formed; a document with no tag table.
pub(crate) fn tag_table(origin: &str, text: &str, lang: &str) -> Result<Vec<Tag>, SourceError> {
    let doc = plcopen::document(origin, text)?;
    if !doc
        .descendants()
        .any(|n| n.has_tag_name("SW.Tags.PlcTagTable"))
    {
        return Err(SourceError::new(
            origin,
            at(&doc, doc.root_element()),
            "this SimaticML document has no tag table (SW.Tags.PlcTagTable): export the PLC tag table, not a block",
        ));
    }
    Ok(tags(&doc, lang))
}

/// The block kinds read.
const BLOCKS: &[&str] = &["SW.Blocks.FC", "SW.Blocks.FB", "SW.Blocks.OB"];

/// Reads every block of the document `text`: its networks as
/// instructions, and its interface's and tag tables' comments as
/// `(name or address, comment)`.
///
/// # Errors
/// XML that is not well-formed, a document with no block, parts that
/// cannot be read, each at its place.
pub(crate) fn lex(origin: &str, text: &str, lang: &str) -> Result<plcopen::Parsed, SourceErrors> {
    let doc = plcopen::document(origin, text)?;
    let root = doc.root_element();
    let mut documentation = Vec::new();
    for tag in tags(&doc, lang) {
        if let Some(c) = &tag.comment {
            documentation.push((tag.name.clone(), c.clone()));
            for a in tag.addresses() {
                documentation.push((a, c.clone()));
            }
        }
    }
    for db in root
        .children()
        .filter(|c| c.has_tag_name("SW.Blocks.GlobalDB"))
    {
        if let Some(name) = block_name(db) {
            documentation.extend(interface_comments(db, &name, true, lang));
        }
    }
    let blocks: Vec<Node> = root
        .children()
        .filter(|c| BLOCKS.iter().any(|b| c.has_tag_name(*b)))
        .collect();
    if blocks.is_empty() {
        let (node, message) = match doc
            .descendants()
            .find(|n| n.has_tag_name("SW.Tags.PlcTagTable"))
        {
            Some(table) => (
                table,
                "this is a TIA Portal tag table, not a block: give it as the I/O list (--comments), and export the block (FC, FB or OB) to read its networks".to_string(),
            ),
            None => (
                root,
                "no TIA Portal block (SW.Blocks.FC, FB or OB) in this SimaticML document".to_string(),
            ),
        };
        return Err(SourceError::new(origin, at(&doc, node), message).into());
    }
    let mut out = Vec::new();
    let mut errors = Vec::new();
    for block in blocks {
        let name = block_name(block).unwrap_or_else(|| "?".into());
        documentation.extend(interface_comments(block, &name, false, lang));
        let units = child(block, "ObjectList")
            .into_iter()
            .flat_map(|o| o.children())
            .filter(|c| c.has_tag_name("SW.Blocks.CompileUnit"));
        for (n, unit) in units.enumerate() {
            let place = Place {
                block: name.clone(),
                network: n + 1,
            };
            let attrs = child(unit, "AttributeList");
            let language = attrs
                .and_then(|a| child(a, "ProgrammingLanguage"))
                .map(text_of)
                .unwrap_or_default();
            let Some(source) = attrs
                .and_then(|a| child(a, "NetworkSource"))
                .and_then(|s| s.children().find(Node::is_element))
            else {
                // An empty network.
                continue;
            };
            if source.has_tag_name("FlgNet") {
                let (ins, errs) = flgnet::Network::new(origin, &doc, &place, source).read();
                out.extend(ins);
                errors.extend(errs);
            } else {
                let here = at(&doc, source);
                let what = if language.is_empty() {
                    source.tag_name().name().to_string()
                } else {
                    language
                };
                out.push(Instruction::bare(
                    here,
                    format!("{place}: {what} network not read (LAD and FBD networks are)"),
                    what,
                    Operation::Outside(Outside::Unread),
                ));
            }
        }
        // Jumps and labels stay inside their block.
        let pos = doc.text_pos_at(block.range().end);
        let end = Location {
            line: pos.row as usize,
            col: pos.col as usize,
        };
        out.push(Instruction::bare(
            end,
            format!("end of block \"{name}\""),
            String::new(),
            Operation::EndBlock,
        ));
    }
    SourceErrors::or_ok(
        plcopen::Parsed {
            instructions: out,
            documentation,
        },
        errors,
    )
}

/// A block's `AttributeList/Name`.
fn block_name(block: Node<'_, '_>) -> Option<String> {
    child(block, "AttributeList")
        .and_then(|a| child(a, "Name"))
        .map(text_of)
        .filter(|n| !n.is_empty())
}

#[cfg(test)]
mod tests;
