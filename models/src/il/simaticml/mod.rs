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
//! English (`I`), the way Openness writes areas.
//!
//! # Comments
//! A block's interface members (`Section/Member/Comment`) and a tag
//! table's tags (`Comment`) carry comments in several languages; the
//! `en-US` text is taken, else the first language that has one.

mod flgnet;

use std::fmt;

use roxmltree::{Document, Node};

use super::{plcopen, Instruction, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError, SourceErrors};

/// The comment language taken when a text has it.
pub(crate) const LANGUAGE: &str = "en-US";

/// A network of a block, as messages name it.
#[derive(Debug, Clone)]
pub(super) struct Place {
    block: String,
    network: usize,
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "block \"{}\" network {}", self.block, self.network)
    }
}

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

pub(super) fn at(doc: &Document<'_>, node: Node<'_, '_>) -> Location {
    let pos = doc.text_pos_at(node.range().start);
    Location {
        line: pos.row as usize,
        col: pos.col as usize,
    }
}

/// The first child element named `name`.
pub(super) fn child<'a, 'i>(node: Node<'a, 'i>, name: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(name))
}

/// An element's text, trimmed.
pub(super) fn text_of(node: Node<'_, '_>) -> String {
    node.text().unwrap_or("").trim().to_string()
}

/// The signal an `Access` (or a part's `Instance`) names, and whether it
/// may be a bit (`false`: a word or byte address).
///
/// # Errors
/// Why it is not read: an indexed or sliced access, an unknown area.
pub(super) fn access_signal(
    place: &Place,
    scope: &str,
    access: Node<'_, '_>,
) -> Result<(Signal, bool), String> {
    if let Some(symbol) = child(access, "Symbol") {
        let mut names = Vec::new();
        for c in symbol.children().filter(|c| c.has_tag_name("Component")) {
            let name = c.attribute("Name").unwrap_or("");
            let indexed = c.children().any(|i| i.is_element())
                || c.attributes()
                    .any(|a| a.name().ends_with("AccessModifier") && a.value() != "None");
            if indexed {
                return Err(format!(
                    "indexed or sliced access '{name}' (known only at run time)"
                ));
            }
            if name.is_empty() {
                return Err("a symbol without a name".into());
            }
            names.push(name);
        }
        if names.is_empty() {
            return Err("a symbol without a name".into());
        }
        let joined = names.join(".");
        return Ok(match scope {
            "LocalVariable" => (Signal::new(&format!("{}.#{joined}", place.block)), true),
            _ => (Signal::new(&joined), true),
        });
    }
    if let Some(address) = child(access, "Address") {
        let area = match address.attribute("Area").unwrap_or("") {
            "Input" => "I",
            "Output" => "Q",
            "Memory" => "M",
            "Local" => "L",
            "PeripheryInput" => "PI",
            "PeripheryOutput" => "PQ",
            "DB" => "DB",
            other => return Err(format!("address in area '{other}'")),
        };
        let offset: u64 = address
            .attribute("BitOffset")
            .and_then(|b| b.parse().ok())
            .ok_or("an address without a bit offset")?;
        let ty = address.attribute("Type").unwrap_or("Bool");
        let (byte, bit) = (offset / 8, offset % 8);
        let prefix = if area == "DB" {
            let n = address.attribute("BlockNumber").unwrap_or("?");
            format!("DB{n}.DB")
        } else {
            area.to_string()
        };
        if ty.eq_ignore_ascii_case("Bool") {
            let x = if area == "DB" { "X" } else { "" };
            return Ok((Signal::new(&format!("{prefix}{x}{byte}.{bit}")), true));
        }
        let size = match ty.to_ascii_uppercase().as_str() {
            "BYTE" | "SINT" | "USINT" | "CHAR" => "B",
            "WORD" | "INT" | "UINT" => "W",
            _ => "D",
        };
        return Ok((Signal::new(&format!("{prefix}{size}{byte}")), false));
    }
    Err("an operand without a symbol or an address".into())
}

/// The text of `texts` (`(language, text)`) in [`LANGUAGE`], else the
/// first that is not empty; whitespace collapsed.
fn pick<'a>(texts: impl Iterator<Item = (&'a str, String)>) -> Option<String> {
    let texts: Vec<(&str, String)> = texts
        .map(|(l, t)| (l, t.split_whitespace().collect::<Vec<_>>().join(" ")))
        .filter(|(_, t)| !t.is_empty())
        .collect();
    texts
        .iter()
        .find(|(l, _)| l.eq_ignore_ascii_case(LANGUAGE))
        .or_else(|| texts.first())
        .map(|(_, t)| t.clone())
}

/// An interface member's comment (`<Comment><MultiLanguageText Lang=..>`).
fn member_comment(member: Node<'_, '_>) -> Option<String> {
    let comment = child(member, "Comment")?;
    pick(
        comment
            .children()
            .filter(|c| c.has_tag_name("MultiLanguageText"))
            .map(|c| (c.attribute("Lang").unwrap_or(""), text_of(c))),
    )
}

/// An object's comment (`<MultilingualText CompositionName="Comment">`
/// with its items' `Culture` and `Text`).
fn object_comment(object: Node<'_, '_>) -> Option<String> {
    let text = child(object, "ObjectList")?.children().find(|c| {
        c.has_tag_name("MultilingualText") && c.attribute("CompositionName") == Some("Comment")
    })?;
    pick(
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
fn members(parent: Node<'_, '_>, prefix: &str, depth: usize, out: &mut Vec<(String, String)>) {
    if depth > MAX_MEMBER_DEPTH {
        return;
    }
    for m in parent.children().filter(|c| c.has_tag_name("Member")) {
        let Some(name) = m.attribute("Name") else {
            continue;
        };
        let path = format!("{prefix}{name}");
        if let Some(c) = member_comment(m) {
            out.push((path.clone(), c));
        }
        members(m, &format!("{path}."), depth + 1, out);
    }
}

/// The comments of a block's or a global DB's interface, named as STL
/// names them: `"Valve".#Release`, `"Line_DB".Ready`.
fn interface_comments(block: Node<'_, '_>, name: &str, db: bool) -> Vec<(String, String)> {
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
        members(section, &prefix, 0, &mut out);
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

/// The tags of every tag table in `doc`.
fn tags(doc: &Document<'_>) -> Vec<Tag> {
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
                comment: object_comment(tag),
                at: at(doc, tag),
            })
        })
        .collect()
}

/// The tags of the tag table `text` (a SimaticML document).
///
/// # Errors
/// XML that is not well-formed; a document with no tag table.
pub(crate) fn tag_table(origin: &str, text: &str) -> Result<Vec<Tag>, SourceError> {
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
    Ok(tags(&doc))
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
pub(crate) fn lex(origin: &str, text: &str) -> Result<plcopen::Parsed, SourceErrors> {
    let doc = plcopen::document(origin, text)?;
    let root = doc.root_element();
    let mut documentation = Vec::new();
    for tag in tags(&doc) {
        if let Some(c) = &tag.comment {
            documentation.push((tag.name.clone(), c.clone()));
            if let Some(a) = &tag.address {
                documentation.push((a.clone(), c.clone()));
            }
        }
    }
    for db in root
        .children()
        .filter(|c| c.has_tag_name("SW.Blocks.GlobalDB"))
    {
        if let Some(name) = block_name(db) {
            documentation.extend(interface_comments(db, &name, true));
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
        documentation.extend(interface_comments(block, &name, false));
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
                out.push(Instruction {
                    at: here,
                    text: format!("{place}: {what} network not read (LAD and FBD networks are)"),
                    mnemonic: what,
                    operation: Operation::Outside(Outside::Unread),
                    operand: None,
                    operand_at: here,
                });
            }
        }
        // Jumps and labels stay inside their block.
        let pos = doc.text_pos_at(block.range().end);
        let end = Location {
            line: pos.row as usize,
            col: pos.col as usize,
        };
        out.push(Instruction {
            at: end,
            text: format!("end of block \"{name}\""),
            mnemonic: String::new(),
            operation: Operation::EndBlock,
            operand: None,
            operand_at: end,
        });
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
