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
mod tests {
    use crate::comments::CommentDb;
    use crate::program::Program;
    use crate::signal::{Observability, Signal};
    use crate::switching::SwitchingFunction;

    /// A block `Conveyor` with one network per `(language, parts, wires)`.
    fn block(networks: &[(&str, &str, &str)]) -> String {
        let units: String = networks
            .iter()
            .enumerate()
            .map(|(i, (lang, parts, wires))| {
                let source = if *lang == "STL" {
                    "<StatementList xmlns=\"http://www.siemens.com/automation/Openness/SW/NetworkSource/StatementList/v4\"/>".to_string()
                } else {
                    format!(
                        "<FlgNet xmlns=\"http://www.siemens.com/automation/Openness/SW/NetworkSource/FlgNet/v{}\">\n<Parts>\n{parts}</Parts>\n<Wires>\n{wires}</Wires>\n</FlgNet>",
                        i % 5 + 1
                    )
                };
                format!(
                    "<SW.Blocks.CompileUnit ID=\"{i}\" CompositionName=\"CompileUnits\"><AttributeList><NetworkSource>{source}</NetworkSource>\n<ProgrammingLanguage>{lang}</ProgrammingLanguage></AttributeList></SW.Blocks.CompileUnit>\n"
                )
            })
            .collect();
        format!(
            "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<Document>\n<Engineering version=\"V18\" />\n<SW.Blocks.FB ID=\"0\"><AttributeList>\
             <Interface><Sections xmlns=\"http://www.siemens.com/automation/Openness/SW/Interface/v5\"><Section Name=\"Static\">\
             <Member Name=\"Busy\" Datatype=\"Bool\"><Comment><MultiLanguageText Lang=\"de-DE\">Belegt</MultiLanguageText></Comment></Member>\
             </Section></Sections></Interface><Name>Conveyor</Name><ProgrammingLanguage>LAD</ProgrammingLanguage></AttributeList>\n<ObjectList>\n{units}</ObjectList></SW.Blocks.FB>\n</Document>\n"
        )
    }

    fn tag(uid: u32, name: &str) -> String {
        format!("<Access Scope=\"GlobalVariable\" UId=\"{uid}\"><Symbol><Component Name=\"{name}\"/></Symbol></Access>\n")
    }

    fn local(uid: u32, name: &str) -> String {
        format!("<Access Scope=\"LocalVariable\" UId=\"{uid}\"><Symbol><Component Name=\"{name}\"/></Symbol></Access>\n")
    }

    fn number(uid: u32, value: &str) -> String {
        format!("<Access Scope=\"LiteralConstant\" UId=\"{uid}\"><Constant><ConstantType>Int</ConstantType><ConstantValue>{value}</ConstantValue></Constant></Access>\n")
    }

    fn part(uid: u32, name: &str, inner: &str) -> String {
        format!("<Part Name=\"{name}\" UId=\"{uid}\">{inner}</Part>\n")
    }

    /// A wire: `rail`, an operand's UId, or `UId.pin`.
    fn wire(ends: &[&str]) -> String {
        let ends: String = ends
            .iter()
            .map(|e| match e.split_once('.') {
                _ if *e == "rail" => "<Powerrail/>".to_string(),
                Some((u, pin)) => format!("<NameCon UId=\"{u}\" Name=\"{pin}\"/>"),
                None => format!("<IdentCon UId=\"{e}\"/>"),
            })
            .collect();
        format!("<Wire UId=\"99\">{ends}</Wire>\n")
    }

    fn sf(p: &Program, coil: &str) -> String {
        SwitchingFunction::expand(
            p,
            &Signal::new(coil),
            &Observability::everything(p.dialect()),
        )
        .unwrap_or_else(|e| panic!("{e}"))
        .notation()
    }

    fn warnings(p: &Program) -> Vec<String> {
        p.warnings()
            .iter()
            .map(|w| format!("{}: {}", w.at, w.message))
            .collect()
    }

    #[test]
    fn latches_timers_comparators_locals_and_edges() {
        // 1: Sr latch of Run (reset wins), Rs of Hold (set wins).
        let latch = tag(21, "Start")
            + &tag(22, "Stop")
            + &tag(23, "Run")
            + &part(24, "Contact", "")
            + &part(25, "Contact", "")
            + &part(26, "Sr", "")
            + &part(27, "Rs", "")
            + &tag(28, "Hold")
            + &part(29, "Coil", "")
            + &tag(30, "Running");
        let latch_wires = wire(&["rail", "24.in", "25.in"])
            + &wire(&["21", "24.operand"])
            + &wire(&["22", "25.operand"])
            + &wire(&["24.out", "26.s", "27.s1"])
            + &wire(&["25.out", "26.r1", "27.r"])
            + &wire(&["23", "26.operand"])
            + &wire(&["28", "27.operand"])
            + &wire(&["26.q", "29.in"])
            + &wire(&["30", "29.operand"]);
        // 2: a TON's Q in series with a comparison `Speed > 80`, into a
        // local; a negated coil.
        let timer = tag(21, "Speed")
            + &number(22, "80")
            + &part(23, "TON", "<Instance Scope=\"GlobalVariable\" UId=\"24\"><Component Name=\"T1_DB\"/></Instance>")
            + &part(25, "Gt", "")
            + &local(26, "Busy")
            + &part(27, "Coil", "")
            + &part(28, "Coil", "<Negated Name=\"operand\"/>")
            + &tag(29, "Idle");
        let timer_wires = wire(&["rail", "23.IN"])
            + &wire(&["23.Q", "25.pre"])
            + &wire(&["21", "25.in1"])
            + &wire(&["22", "25.in2"])
            + &wire(&["25.out", "27.in", "28.in"])
            + &wire(&["26", "27.operand"])
            + &wire(&["29", "28.operand"]);
        // 3 (FBD): an edge into an AND box, and a box that is not read.
        let edge = tag(21, "Push")
            + &tag(22, "Pulse")
            + &part(23, "PBox", "")
            + &part(
                24,
                "A",
                "<TemplateValue Name=\"Card\" Type=\"Cardinality\">2</TemplateValue>",
            )
            + &part(25, "Coil", "")
            + &part(26, "Calc", "")
            + &tag(27, "Run")
            + &tag(28, "Mem");
        let edge_wires = wire(&["21", "23.in"])
            + &wire(&["28", "23.bit"])
            + &wire(&["23.out", "24.in1"])
            + &wire(&["27", "24.in2"])
            + &wire(&["24.out", "25.in"])
            + &wire(&["22", "25.operand"]);
        let text = block(&[
            ("LAD", &latch, &latch_wires),
            ("LAD", &timer, &timer_wires),
            ("FBD", &edge, &edge_wires),
            ("STL", "", ""),
        ]);
        let p = Program::compile("c.xml", &text, None).unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
        assert_eq!(
            names,
            ["Run", "Hold", "Running", "Conveyor.#Busy", "Idle", "Pulse"]
        );
        assert_eq!(sf(&p, "Run"), "-Stop * (Start + Run)");
        assert_eq!(sf(&p, "Hold"), "Start + (-Stop * Hold)");
        assert_eq!(sf(&p, "Running"), "Run");
        assert_eq!(sf(&p, "Conveyor.#Busy"), "T1_DB.Q * Speed > 80");
        assert_eq!(sf(&p, "Idle"), "-(T1_DB.Q * Speed > 80)");
        assert!(p.coil(&Signal::new("Pulse")).unwrap().definition.is_err());
        assert_eq!(
            warnings(&p),
            [
                "58:1: 'block \"Conveyor\" network 3: edge 'PBox' on 'Mem' (a pulse, not a function of the signals)': a call, timer, counter, edge or function, not boolean logic: the coils it feeds are not derivable",
                "61:1: block \"Conveyor\" network 3: part 'Calc' is not read",
                "75:92: block \"Conveyor\" network 4: STL network not read (LAD and FBD networks are)",
            ]
        );
        // A local's comment: the only language there is.
        assert_eq!(
            p.documentation().get(&Signal::new("Conveyor.#Busy")),
            Some("Belegt")
        );
        assert_eq!(
            p.resolve("\"Conveyor\".#Busy").unwrap().name(),
            "Conveyor.#Busy"
        );
        assert_eq!(p.resolve("\"T1_DB\".Q").unwrap().name(), "T1_DB.Q");
        assert_eq!(p.resolve("%I0.0").unwrap().name(), "I0.0");
    }

    #[test]
    fn bad_networks_are_refused_at_their_part() {
        let parts = tag(21, "Start")
            + &part(22, "Contact", "")
            + &part(23, "Coil", "")
            + &number(24, "5")
            + &part(25, "Coil", "")
            + &part(26, "Contact", "");
        let wires = wire(&["rail", "22.in", "26.in"])
            + &wire(&["21", "22.operand"])
            + &wire(&["22.out", "23.in"])
            + &wire(&["24", "23.operand"])
            + &wire(&["30.out", "25.in"])
            + &wire(&["21", "25.operand"]);
        let e = Program::compile("c.xml", &block(&[("LAD", &parts, &wires)]), None).unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.xml:10:1: block \"Conveyor\" network 1: Coil on a constant\n\
             c.xml:20:16: block \"Conveyor\" network 1: wire 99 names part 30, which is not in this network"
        );
        let e = Program::compile(
            "t.xml",
            "<?xml version=\"1.0\"?>\n<Document>\n<SW.Blocks.FC>\n</Document>\n",
            None,
        )
        .unwrap_err();
        assert!(
            e.to_string().starts_with("t.xml:4:1: not well-formed XML"),
            "{e}"
        );
        let tags = "<?xml version=\"1.0\"?>\n<Document>\n  <SW.Tags.PlcTagTable ID=\"0\"><AttributeList><Name>IO</Name></AttributeList></SW.Tags.PlcTagTable>\n</Document>\n";
        let e = Program::compile("io.xml", tags, None).unwrap_err();
        assert_eq!(
            e.to_string(),
            "io.xml:3:3: this is a TIA Portal tag table, not a block: give it as the I/O list (--comments), and export the block (FC, FB or OB) to read its networks"
        );
        let e = Program::compile(
            "c.xml",
            &block(&[("STL", "", "")]),
            Some(crate::il::Dialect::Stl),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "c.xml:1:1: this is a TIA Portal export (SimaticML), not an instruction list: leave --dialect out, and its LAD and FBD networks are read"
        );
        let e = CommentDb::parse("b.xml", &block(&[]), |a| crate::il::Dialect::Stl.signal(a))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "b.xml:2:1: this SimaticML document has no tag table (SW.Tags.PlcTagTable): export the PLC tag table, not a block"
        );
    }

    #[test]
    fn german_addresses_in_english_mnemonics() {
        for (german, english) in [
            ("E0.0", Some("I0.0")),
            ("A4.1", Some("Q4.1")),
            ("EW10", Some("IW10")),
            ("AB2", Some("QB2")),
            ("PEW256", Some("PIW256")),
            ("PAD4", Some("PQD4")),
            ("Z3", Some("C3")),
            ("M10.1", None),
            ("MW10", None),
            ("T1", None),
            ("I0.0", None),
            ("Q4.0", None),
            ("DB1.DBX2.3", None),
            ("Alarm", None),
            ("EZ1", None),
        ] {
            assert_eq!(super::english(german).as_deref(), english, "{german}");
        }
    }

    #[test]
    fn tag_tables_take_the_english_comment_and_the_project_s_mnemonics() {
        let item = |c: &str, t: &str| {
            format!("<MultilingualTextItem><AttributeList><Culture>{c}</Culture><Text>{t}</Text></AttributeList></MultilingualTextItem>")
        };
        let tag = |name: &str, address: &str, texts: &str| {
            format!(
                "<SW.Tags.PlcTag><AttributeList><LogicalAddress>{address}</LogicalAddress><Name>{name}</Name></AttributeList>\
                 <ObjectList><MultilingualText CompositionName=\"Comment\"><ObjectList>{texts}</ObjectList></MultilingualText></ObjectList></SW.Tags.PlcTag>\n"
            )
        };
        let table = format!(
            "<?xml version=\"1.0\"?>\n<Document>\n<SW.Tags.PlcTagTable><ObjectList>\n{}{}{}{}</ObjectList></SW.Tags.PlcTagTable>\n</Document>\n",
            tag("Start", "%E0.0", &(item("de-DE", "Starttaster") + &item("en-US", "Start button"))),
            tag("Speed", "%MW10", &item("it-IT", "Velocità")),
            tag("Lamp", "%Q4.0", &(item("en-US", "") + &item("de-DE", "Lampe"))),
            tag("Bad", "%Q4.9", &item("en-US", "bad")),
        );
        let stl = |a: &str| crate::il::Dialect::Stl.signal(a);
        let e = CommentDb::parse("io.xml", &table, stl);
        // The bit 4.9 is no address: the tag's name carries the comment.
        let db = e.unwrap();
        assert_eq!(db.get(&Signal::new("Start")), Some("Start button"));
        assert_eq!(db.get(&Signal::new("E0.0")), Some("Start button"));
        // A block's absolute operand is English: `%E0.0` is `I0.0` too.
        assert_eq!(db.get(&Signal::new("I0.0")), Some("Start button"));
        assert_eq!(db.get(&Signal::new("Speed")), Some("Velocità"));
        assert_eq!(db.get(&Signal::new("Lamp")), Some("Lampe"));
        assert_eq!(db.get(&Signal::new("Q4.0")), Some("Lampe"));
        assert_eq!(db.get(&Signal::new("Bad")), Some("bad"));
        assert_eq!(db.len(), 7);
        // In the language asked for, where a text has it; else the first.
        let de = CommentDb::parse_in("io.xml", &table, stl, Some("de-DE")).unwrap();
        assert_eq!(de.get(&Signal::new("Start")), Some("Starttaster"));
        assert_eq!(de.get(&Signal::new("Lamp")), Some("Lampe"));
        assert_eq!(de.get(&Signal::new("Speed")), Some("Velocità"));
        assert_eq!(de.get(&Signal::new("Bad")), Some("bad"));
        let pmc = CommentDb::parse("io.xml", &table, crate::signal::pmc_address).unwrap_err();
        assert_eq!(
            pmc.to_string(),
            "io.xml:4:1: malformed address '\"Start\"': it must start with a signal class letter (X, Y, R, F, G, ...)"
        );
    }
}
