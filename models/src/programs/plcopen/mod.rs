//! Programs from PLCopen XML (IEC 61131-3 TC6 XML 2.01): the ladder (LD),
//! function block diagram (FBD) and instruction-list (IL) bodies of every
//! POU, as IEC instructions.
//!
//! A TC6 ladder is a graph: each element names the elements before it
//! (`connectionPointIn` / `connection refLocalId`). The power flowing out
//! of an element is the OR of what flows into it (parallel branches
//! joining), ANDed with the element's own contact: series is AND,
//! parallel is OR. Where parallel branches join, the part they share from
//! the left is factored out, so `a · (b + c)` stays as drawn rather than
//! `a·b + a·c`. Coils pass their power on (`S`/`R` coils latch).
//! Function-block outputs (`T1.Q`) are leaves; edge contacts, functions,
//! jumps and returns are warnings whose coils are not derivable.
//!
//! The flow of each coil becomes instructions (`LD`, `AND`, `OR(` … `)`,
//! `ST`) located at the XML elements, so that the compiler builds the step
//! blocks the rung's structure gives — the same as the instruction list
//! the paper derives from its ladders. Flow is directed, as a PLC
//! evaluates it, so a network that is not series-parallel still gets the
//! function the PLC computes. An FBD body is the same graph without
//! rails: output variables are its coils, and the boxes AND, OR, XOR and
//! NOT are logic (De Morgan gives a negated box its flow); such a box read
//! by several connections is written once into an internal relay named
//! after the POU and the block (`#Main.AND28`), which each reads, as the
//! IL reads an internal relay: one step block read twice ([`shared`]). A
//! connection to a `localId` the body does not have is an error at the
//! connection. IL bodies are
//! read by the IEC lexer at their own lines; ST and SFC bodies are
//! warnings (charts are read by the chart reader, which reads drawn
//! transition conditions here).

mod flow;
mod graph;

use std::collections::{HashMap, HashSet};

use roxmltree::{Document, Node};

pub(super) use flow::MAX_DEPTH;
pub(crate) use flow::{emit, shared, Flow};
pub(crate) use graph::{connected_condition, graphical_condition};

use super::{iec, Instruction, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError, SourceErrors};
use graph::ladder;

/// The XML document `text`, without a DTD and at most a million nodes.
///
/// # Errors
/// XML that is not well-formed, at the place it stops being so.
pub(super) fn document<'i>(origin: &str, text: &'i str) -> Result<Document<'i>, SourceError> {
    let options = roxmltree::ParsingOptions {
        allow_dtd: false,
        nodes_limit: 1_000_000,
        ..roxmltree::ParsingOptions::default()
    };
    Document::parse_with_options(text, options).map_err(|e| {
        let pos = e.pos();
        SourceError::new(
            origin,
            Location {
                line: pos.row as usize,
                col: pos.col as usize,
            },
            format!("not well-formed XML: {e}"),
        )
    })
}

/// Reads every LD and IL body of the project `text` as instructions.
///
/// # Errors
/// XML that is not well-formed, or elements that cannot be read, each at
/// its line.
pub(crate) fn lex(origin: &str, text: &str) -> Result<Parsed, SourceErrors> {
    let doc = document(origin, text)?;
    let mut out = Vec::new();
    let mut errors = Vec::new();
    // The project's function blocks and functions, for every IL body.
    let mut units = iec::Declarations::default();
    for pou in doc.descendants().filter(|n| n.has_tag_name("pou")) {
        match (pou.attribute("name"), pou.attribute("pouType")) {
            (Some(name), Some("functionBlock")) => units.unit(name, false),
            (Some(name), Some("function")) => units.unit(name, true),
            _ => {}
        }
    }
    let mut documentation: Vec<(String, String)> = doc
        .descendants()
        .filter(|n| n.has_tag_name("variable"))
        .flat_map(|v| {
            let doc = variable_doc(v);
            let names = [v.attribute("name"), v.attribute("address")];
            names
                .into_iter()
                .flatten()
                .filter_map(move |n| doc.clone().map(|d| (n.to_string(), d)))
                .collect::<Vec<_>>()
        })
        .collect();
    // A POU's own variable whose name is declared elsewhere too is that
    // POU's: `POU.name` (two programs' `Reset` are two coils).
    let shared = shared_names(&doc);
    for pou in doc.descendants().filter(|n| n.has_tag_name("pou")) {
        let pou_id = pou.attribute("name").unwrap_or("?");
        // Upper case → as declared.
        let locals: HashMap<String, String> = own_variables(pou)
            .filter_map(|v| v.attribute("name"))
            .map(|n| (n.to_ascii_uppercase(), n.to_string()))
            .filter(|(upper, _)| shared.contains(upper))
            .collect();
        for v in own_variables(pou) {
            if let (Some(name), Some(doc)) = (v.attribute("name"), variable_doc(v)) {
                if locals.contains_key(&name.to_ascii_uppercase()) {
                    documentation.push((format!("{pou_id}.{name}"), doc));
                }
            }
        }
        let first = out.len();
        // The POU's body, and its SFC actions' and transitions' bodies.
        let bodies: Vec<(Node, String)> = pou
            .descendants()
            .filter(|n| n.has_tag_name("body"))
            .filter_map(|b| {
                let parent = b.parent()?;
                let pou_name = pou.attribute("name").unwrap_or("?");
                let name = parent.attribute("name").unwrap_or("?");
                match parent.tag_name().name() {
                    "pou" => Some((b, pou_name.to_string())),
                    "action" => Some((b, format!("{pou_name}, action {name}"))),
                    "transition" => Some((b, format!("{pou_name}, transition {name}"))),
                    _ => None,
                }
            })
            .collect();
        if bodies.is_empty() {
            continue;
        }
        let mut declared = units.clone();
        for v in pou
            .children()
            .filter(|c| c.has_tag_name("interface"))
            .flat_map(|i| i.descendants())
            .filter(|n| n.has_tag_name("variable"))
        {
            if let (Some(name), Some(ty)) = (v.attribute("name"), type_name(v)) {
                declared.variable(name, &ty);
            }
        }
        for (body, pou_name) in &bodies {
            let body = *body;
            for kind in body.children().filter(Node::is_element) {
                match kind.tag_name().name() {
                    "LD" | "FBD" => {
                        let (ins, errs) = ladder(origin, &doc, kind, &declared);
                        out.extend(ins);
                        errors.extend(errs);
                    }
                    "IL" => {
                        let text = kind
                            .descendants()
                            .filter(Node::is_text)
                            .map(|t| t.text().unwrap_or(""))
                            .collect::<String>();
                        let first = kind.descendants().find(Node::is_text).unwrap_or(kind);
                        let line0 = doc.text_pos_at(first.range().start).row as usize - 1;
                        match iec::lex_declared(origin, &text, declared.clone()) {
                            Ok(ins) => out.extend(ins.into_iter().map(|mut i| {
                                i.at.line += line0;
                                i.operand_at.line += line0;
                                i
                            })),
                            Err(e) => errors.extend(e.0.into_iter().map(|mut e| {
                                e.at.line += line0;
                                e
                            })),
                        }
                    }
                    other => {
                        let pos = doc.text_pos_at(kind.range().start);
                        let at = Location {
                            line: pos.row as usize,
                            col: pos.col as usize,
                        };
                        let why = match other {
                            "SFC" => format!("POU '{pou_name}': SFC body, read as a chart by [[checks.sfc]], not here"),
                            _ => format!("POU '{pou_name}': {other} body not read (ladder and IL bodies are)"),
                        };
                        out.push(Instruction::bare(
                            at,
                            why.clone(),
                            other.to_string(),
                            Operation::Outside(Outside::Unread),
                        ));
                    }
                }
            }
            // Jumps and labels stay inside their POU.
            let pos = doc.text_pos_at(body.range().end);
            let at = Location {
                line: pos.row as usize,
                col: pos.col as usize,
            };
            out.push(Instruction::bare(
                at,
                format!("end of POU '{pou_name}'"),
                String::new(),
                Operation::EndBlock,
            ));
        }
        for i in &mut out[first..] {
            qualify(i, pou_id, &locals);
        }
    }
    SourceErrors::or_ok(
        Parsed {
            instructions: out,
            documentation,
        },
        errors,
    )
}

/// A variable's documentation, its whitespace collapsed; `None` when it
/// has none.
fn variable_doc(v: Node<'_, '_>) -> Option<String> {
    v.children()
        .find(|c| c.has_tag_name("documentation"))
        .map(|d| {
            d.descendants()
                .filter(Node::is_text)
                .filter_map(|t| t.text())
                .collect::<Vec<_>>()
                .join(" ")
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" ")
        })
        .filter(|d| !d.is_empty())
}

/// A POU's own variables without a direct address: its inputs, outputs,
/// in-outs, locals and temporaries (not the globals it refers to, which
/// are the project's).
fn own_variables<'a, 'input>(pou: Node<'a, 'input>) -> impl Iterator<Item = Node<'a, 'input>> {
    pou.children()
        .filter(|c| c.has_tag_name("interface"))
        .flat_map(|i| i.children())
        .filter(|section| {
            matches!(
                section.tag_name().name(),
                "localVars" | "tempVars" | "inputVars" | "outputVars" | "inOutVars"
            )
        })
        .flat_map(|section| section.children())
        .filter(|v| v.has_tag_name("variable") && v.attribute("address").is_none())
}

/// The names (upper case: IEC names ignore case) declared in more than
/// one place: in two POUs' own variables, or in one's and in the
/// project's global variables.
fn shared_names(doc: &Document<'_>) -> HashSet<String> {
    let mut places: HashMap<String, usize> = HashMap::new();
    for pou in doc.descendants().filter(|n| n.has_tag_name("pou")) {
        let mine: HashSet<String> = own_variables(pou)
            .filter_map(|v| v.attribute("name"))
            .map(str::to_ascii_uppercase)
            .collect();
        for name in mine {
            *places.entry(name).or_default() += 1;
        }
    }
    let globals: HashSet<String> = doc
        .descendants()
        .filter(|n| n.has_tag_name("globalVars"))
        .flat_map(|g| g.children())
        .filter(|v| v.has_tag_name("variable"))
        .filter_map(|v| v.attribute("name"))
        .map(str::to_ascii_uppercase)
        .collect();
    for name in globals {
        *places.entry(name).or_default() += 1;
    }
    places
        .into_iter()
        .filter(|&(_, n)| n > 1)
        .map(|(name, _)| name)
        .collect()
}

/// Names `i`'s operand as POU `pou`'s own when it is one of `locals`
/// (upper case → as declared), or a member of one (`T1.Q` of a local
/// timer `T1`): `pou.T1.Q`, spelt as declared.
fn qualify(i: &mut Instruction, pou: &str, locals: &HashMap<String, String>) {
    if locals.is_empty() {
        return;
    }
    if let Some(Operand::Signal(s)) = &mut i.operand {
        let name = s.name();
        let (base, member) = match name.split_once('.') {
            Some((b, m)) => (b, Some(m)),
            None => (name, None),
        };
        if let Some(declared) = locals.get(&base.to_ascii_uppercase()) {
            let qualified = match member {
                Some(m) => format!("{pou}.{declared}.{m}"),
                None => format!("{pou}.{declared}"),
            };
            *s = Signal::new(&qualified);
        }
    }
}

/// A project's instructions and its variables' documentation.
pub(crate) struct Parsed {
    pub(crate) instructions: Vec<Instruction>,
    /// `(name or address, documentation)` of every declared variable that
    /// has some.
    pub(crate) documentation: Vec<(String, String)>,
}

/// A declared variable's type: `BOOL`, a derived type's name (`TON`),
/// `ARRAY`, `STRING`.
fn type_name(variable: Node<'_, '_>) -> Option<String> {
    let ty = variable.children().find(|c| c.has_tag_name("type"))?;
    let inner = ty.children().find(Node::is_element)?;
    Some(match inner.tag_name().name() {
        "derived" => inner.attribute("name")?.to_string(),
        "array" => "ARRAY".to_string(),
        "string" | "wstring" => "STRING".to_string(),
        other => other.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use crate::program::Program;
    use crate::signal::{Observability, Signal};
    use crate::switching::SwitchingFunction;

    fn project(body: &str) -> String {
        format!(
            "<?xml version=\"1.0\"?>\n<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\">\n<types><pous>\n\
             <pou name=\"p\" pouType=\"program\"><body><LD>\n{body}</LD></body></pou>\n\
             <pou name=\"q\" pouType=\"program\"><body><ST><xhtml:p xmlns:xhtml=\"http://www.w3.org/1999/xhtml\">x := 1;</xhtml:p></ST></body></pou>\n\
             </pous></types>\n</project>\n"
        )
    }

    fn el(tag: &str, id: u32, extra: &str, from: &[u32], var: &str) -> String {
        let conns: String = from
            .iter()
            .map(|f| format!("<connection refLocalId=\"{f}\"/>"))
            .collect();
        format!(
            "<{tag} localId=\"{id}\" {extra}><connectionPointIn>{conns}</connectionPointIn><variable>{var}</variable></{tag}>\n"
        )
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

    #[test]
    fn a_pous_own_variable_named_as_another_pous_is_its_own() {
        let rail = "<leftPowerRail localId=\"1\"><connectionPointOut/></leftPowerRail>\n";
        let p_body = rail.to_string()
            + &el("contact", 2, "", &[1], "Start")
            + &el("coil", 3, "", &[2], "Reset")
            + &el("contact", 4, "", &[1], "RESET")
            + &el("coil", 5, "", &[4], "Fault")
            + "<block localId=\"6\" typeName=\"TON\" instanceName=\"T1\"><inputVariables/><outputVariables/></block>\n"
            + "<contact localId=\"7\"><connectionPointIn><connection refLocalId=\"6\" formalParameter=\"Q\"/></connectionPointIn><variable>Start</variable></contact>\n"
            + &el("coil", 8, "", &[7], "Done");
        let q_body = rail.to_string()
            + &el("contact", 2, "", &[1], "Stop")
            + &el("coil", 3, "", &[2], "Reset")
            + "<block localId=\"6\" typeName=\"TON\" instanceName=\"T1\"><inputVariables/><outputVariables/></block>\n"
            + "<contact localId=\"7\"><connectionPointIn><connection refLocalId=\"6\" formalParameter=\"Q\"/></connectionPointIn><variable>Stop</variable></contact>\n"
            + &el("coil", 8, "", &[7], "Late");
        let var = |name: &str, doc: &str| {
            format!(
                "<variable name=\"{name}\"><type><BOOL/></type><documentation><xhtml:p xmlns:xhtml=\"http://www.w3.org/1999/xhtml\">{doc}</xhtml:p></documentation></variable>"
            )
        };
        let xml = format!(
            "<?xml version=\"1.0\"?>\n<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\">\n<types><pous>\n\
             <pou name=\"p\" pouType=\"program\"><interface><localVars>{}{}<variable name=\"T1\"><type><derived name=\"TON\"/></type></variable></localVars>\
             <externalVars><variable name=\"Start\"><type><BOOL/></type></variable></externalVars></interface>\
             <body><LD>\n{p_body}</LD></body></pou>\n\
             <pou name=\"q\" pouType=\"program\"><interface><localVars>{}<variable name=\"T1\"><type><derived name=\"TON\"/></type></variable></localVars></interface>\
             <body><LD>\n{q_body}</LD></body></pou>\n\
             </pous></types>\n<instances><configurations><configuration name=\"c\"><globalVars>{}</globalVars></configuration></configurations></instances>\n</project>\n",
            var("Reset", "conveyor reset"),
            var("Fault", "conveyor fault"),
            var("Reset", "lift reset"),
            var("Start", "start button"),
        );
        let p = Program::compile("p.xml", &xml, None).unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
        // Each program's Reset and T1 its own; Fault, declared once, and
        // the global Start keep their names.
        assert_eq!(names, ["p.Reset", "Fault", "Done", "q.Reset", "Late"]);
        assert_eq!(sf(&p, "Fault"), "p.Reset");
        assert_eq!(sf(&p, "p.Reset"), "Start");
        assert_eq!(sf(&p, "q.Reset"), "Stop");
        assert_eq!(sf(&p, "Done"), "p.T1.Q * Start");
        assert_eq!(sf(&p, "Late"), "q.T1.Q * Stop");
        let docs = p.documentation();
        assert_eq!(docs.get(&Signal::new("p.Reset")), Some("conveyor reset"));
        assert_eq!(docs.get(&Signal::new("q.Reset")), Some("lift reset"));
        assert_eq!(docs.get(&Signal::new("Start")), Some("start button"));
    }

    #[test]
    fn latches_blocks_edges_and_a_network_that_is_not_series_parallel() {
        let rail = "<leftPowerRail localId=\"1\"><connectionPointOut/></leftPowerRail>\n";
        let body = rail.to_string()
            // Set and reset coils: a latch.
            + &el("contact", 2, "", &[1], "Start")
            + &el("coil", 3, "storage=\"set\"", &[2], "Run")
            + &el("contact", 4, "negated=\"true\"", &[1], "Stop")
            + &el("coil", 5, "storage=\"reset\"", &[4], "Run")
            // A timer's output is a leaf.
            + "<block localId=\"6\" typeName=\"TON\" instanceName=\"T1\"><inputVariables/><outputVariables/></block>\n"
            + "<contact localId=\"7\"><connectionPointIn><connection refLocalId=\"6\" formalParameter=\"Q\"/></connectionPointIn><variable>Run</variable></contact>\n"
            + &el("coil", 8, "", &[7], "Done")
            // An edge contact: not derivable, a warning.
            + &el("contact", 9, "edge=\"rising\"", &[1], "Push")
            + &el("coil", 10, "", &[9], "Pulse")
            // a feeds two branches that join in different places:
            // X = a·b + c, Y = (a·b + c)·d + a·e — not series-parallel.
            + &el("contact", 11, "", &[1], "a")
            + &el("contact", 12, "", &[11], "b")
            + &el("contact", 13, "", &[1], "c")
            + &el("coil", 14, "", &[12, 13], "X")
            + &el("contact", 15, "", &[14], "d")
            + &el("contact", 16, "", &[11], "e")
            + &el("coil", 17, "", &[15, 16], "Y");
        let p = Program::compile("p.xml", &project(&body), None).unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
        assert_eq!(names, ["Run", "Done", "Pulse", "X", "Y"]);
        assert_eq!(sf(&p, "Run"), "Stop * (Start + Run)");
        assert_eq!(sf(&p, "Done"), "T1.Q * Run");
        assert_eq!(sf(&p, "X"), "(a * b) + c");
        assert_eq!(sf(&p, "Y"), "(((a * b) + c) * d) + (a * e)");
        let pulse = p.coil(&Signal::new("Pulse")).unwrap();
        assert!(pulse.definition.is_err());
        let warnings: Vec<String> = p
            .warnings()
            .iter()
            .map(|w| format!("{}: {}", w.at, w.message))
            .collect();
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(
            warnings[0].contains("edge contact on 'Push'"),
            "{warnings:?}"
        );
        assert!(
            warnings[1].ends_with("POU 'q': ST body not read (ladder and IL bodies are)"),
            "{warnings:?}"
        );
    }

    #[test]
    fn bad_ladders_are_refused_at_their_element() {
        let body = "<leftPowerRail localId=\"1\"><connectionPointOut/></leftPowerRail>\n"
            .to_string()
            + &el("contact", 2, "", &[1], "%ZX1")
            + &el("coil", 3, "", &[2, 9], "Out");
        let e = Program::compile("p.xml", &project(&body), None).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.xml:6:1: malformed address '%ZX1': a direct address starts with %I, %Q or %M\n\
             p.xml:7:67: coil 3 is connected to element 9, which is not in POU 'p'"
        );
        let e = Program::compile(
            "p.xml",
            "<?xml version=\"1.0\"?>\n<project>\n<pou>\n</project>\n",
            None,
        )
        .unwrap_err();
        assert!(
            e.to_string().starts_with("p.xml:4:1: not well-formed XML"),
            "{e}"
        );
        let e = Program::compile("p.xml", &project(""), Some(crate::programs::Dialect::Iec))
            .unwrap_err();
        assert!(e.to_string().contains("leave --dialect out"), "{e}");
    }

    /// A function box: `AND`, `OR`, `XOR`, `NOT`, inputs `from` by local id
    /// (an id ending in `~` is a negated input), the output perhaps negated.
    fn func(ty: &str, id: u32, from: &[&str], out_negated: bool, extra: &str) -> String {
        let inputs: String = from
            .iter()
            .enumerate()
            .map(|(n, f)| {
                let (f, neg) = f.strip_suffix('~').map_or((*f, ""), |f| (f, " negated=\"true\""));
                let param = if f.starts_with("EN:") { "EN".to_string() } else { format!("IN{}", n + 1) };
                let f = f.trim_start_matches("EN:");
                format!(
                    "<variable formalParameter=\"{param}\"{neg}><connectionPointIn><connection refLocalId=\"{f}\"/></connectionPointIn></variable>"
                )
            })
            .collect();
        let neg = if out_negated { " negated=\"true\"" } else { "" };
        format!(
            "<block localId=\"{id}\" typeName=\"{ty}\" {extra}><inputVariables>{inputs}</inputVariables><inOutVariables/>\
             <outputVariables><variable formalParameter=\"OUT\"{neg}><connectionPointOut/></variable></outputVariables></block>\n"
        )
    }

    fn input(id: u32, expr: &str) -> String {
        format!("<inVariable localId=\"{id}\"><connectionPointOut/><expression>{expr}</expression></inVariable>\n")
    }

    fn output(id: u32, from: u32, param: &str, expr: &str) -> String {
        format!(
            "<outVariable localId=\"{id}\"><connectionPointIn><connection refLocalId=\"{from}\" formalParameter=\"{param}\"/></connectionPointIn><expression>{expr}</expression></outVariable>\n"
        )
    }

    #[test]
    fn function_block_diagrams_are_read_as_logic() {
        let body = input(1, "a")
            + &input(2, "b")
            + &input(3, "c")
            + &input(4, "TRUE")
            // Interlock = (a AND NOT b) OR c
            + &func("AND", 10, &["1", "2~"], false, "")
            + &func("OR", 11, &["10", "3"], false, "")
            + &output(12, 11, "OUT", "Interlock")
            // Fault = NOT (a OR b): De Morgan, ¬a·¬b
            + &func("OR", 13, &["1", "2"], true, "")
            + &output(14, 13, "OUT", "Fault")
            // Odd = a XOR b XOR c
            + &func("xor", 15, &["1", "2", "3"], false, "")
            + &output(16, 15, "OUT", "Odd")
            // NOT of a constant, enabled from the rail: Never = NOT TRUE.
            + &func("NOT", 17, &["EN:4", "4"], false, "")
            + &output(18, 17, "OUT", "Never")
            // An arithmetic function and an enabled box: not derivable.
            + &func("ADD", 19, &["1", "2"], false, "")
            + &output(20, 19, "OUT", "Sum")
            + &func("AND", 21, &["EN:3", "1", "2"], false, "")
            + &output(22, 21, "OUT", "Gated")
            // A function block's output is a leaf; a negated output variable.
            + "<block localId=\"23\" typeName=\"SR\" instanceName=\"Latch\"><inputVariables/><outputVariables/></block>\n"
            + "<outVariable localId=\"24\" negated=\"true\"><connectionPointIn><connection refLocalId=\"23\" formalParameter=\"Q1\"/></connectionPointIn><expression>Released</expression></outVariable>\n";
        let text = project("").replace("<LD>\n</LD>", &format!("<FBD>\n{body}</FBD>"));
        let p = Program::compile("p.xml", &text, None).unwrap_or_else(|e| panic!("{e}"));
        let names: Vec<&str> = p.coils().iter().map(|c| c.signal.name()).collect();
        assert_eq!(
            names,
            [
                "Interlock",
                "Fault",
                "Odd",
                "Never",
                "Sum",
                "Gated",
                "Released"
            ]
        );
        assert_eq!(sf(&p, "Interlock"), "(a * -b) + c");
        assert_eq!(sf(&p, "Fault"), "-a * -b");
        assert_eq!(
            sf(&p, "Odd"),
            "(((a * -b) + (-a * b)) * -c) + ((-a + b) * (a + -b) * c)"
        );
        for opaque in ["Sum", "Gated"] {
            assert!(p.coil(&Signal::new(opaque)).unwrap().definition.is_err());
        }
        assert_eq!(sf(&p, "Released"), "-Latch.Q1");
        let never = p.coil(&Signal::new("Never")).unwrap();
        assert!(never.definition.is_ok(), "{:?}", never.definition);
    }
}
