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

use std::collections::{HashMap, HashSet};

use roxmltree::{Document, Node};

use super::{iec, Instruction, Op, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError, SourceErrors};

/// How deep a rung's connections may chain.
pub(super) const MAX_DEPTH: usize = 512;

/// What flows out of an element (a TIA Portal part too: `simaticml`).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Flow {
    True,
    False,
    /// A contact: its variable, negated, the element (for identity).
    Lit(Signal, bool, u64),
    And(Vec<Flow>),
    Or(Vec<Flow>),
    /// Not boolean logic: why, and where.
    Opaque(String, Location),
}

impl Flow {
    /// The flow as a series of parts (an AND's children, or itself).
    fn series(self) -> Vec<Flow> {
        match self {
            Flow::True => Vec::new(),
            Flow::And(parts) => parts,
            other => vec![other],
        }
    }

    /// The flow negated: a contact's negation flips, AND and OR swap (De
    /// Morgan); what is not boolean logic stays so.
    pub(super) fn not(self) -> Flow {
        match self {
            Flow::True => Flow::False,
            Flow::False => Flow::True,
            Flow::Lit(s, negated, id) => Flow::Lit(s, !negated, id),
            Flow::And(parts) => Flow::or(parts.into_iter().map(Flow::not).collect()),
            Flow::Or(parts) => Flow::and(parts.into_iter().map(Flow::not).collect()),
            opaque @ Flow::Opaque(..) => opaque,
        }
    }

    /// Exclusive OR of two flows: `a·¬b + ¬a·b`.
    pub(super) fn xor(a: Flow, b: Flow) -> Flow {
        Flow::or(vec![
            Flow::and(vec![a.clone(), b.clone().not()]),
            Flow::and(vec![a.not(), b]),
        ])
    }

    pub(crate) fn and(parts: Vec<Flow>) -> Flow {
        let mut out = Vec::new();
        for p in parts {
            out.extend(p.series());
        }
        match out.len() {
            0 => Flow::True,
            1 => out.pop().unwrap_or(Flow::True),
            _ => Flow::And(out),
        }
    }

    /// Parallel branches joining: their common start factored out.
    pub(crate) fn or(branches: Vec<Flow>) -> Flow {
        if branches.len() == 1 {
            return branches.into_iter().next().unwrap_or(Flow::True);
        }
        let series: Vec<Vec<Flow>> = branches.into_iter().map(Flow::series).collect();
        let mut common = 0;
        while series
            .iter()
            .all(|s| s.len() > common && s[common] == series[0][common])
        {
            common += 1;
        }
        let prefix: Vec<Flow> = series[0][..common].to_vec();
        let mut rest = Vec::new();
        for s in &series {
            let tail = Flow::and(s[common..].to_vec());
            if tail == Flow::True {
                // A branch that bypasses the rest: the OR is true.
                return Flow::and(prefix);
            }
            match tail {
                Flow::Or(inner) => rest.extend(inner),
                t => rest.push(t),
            }
        }
        let mut all = prefix;
        all.push(Flow::Or(rest));
        Flow::and(all)
    }
}

struct Reader<'a, 'i> {
    origin: &'a str,
    doc: &'a Document<'i>,
    /// The elements of the body being read, by local id.
    elements: HashMap<u64, Node<'a, 'i>>,
    /// Named connectors (`connector` / `continuation`).
    connectors: HashMap<String, Node<'a, 'i>>,
    memo: HashMap<(u64, String), Flow>,
    /// How many connections read each element (a body's, not a chart's
    /// condition): a boolean function read more than once is written
    /// once, into an internal relay.
    consumers: HashMap<u64, usize>,
    /// The relays' names start `#` and this: the POU (and action or
    /// transition) the body is.
    scope: String,
    /// Shared boxes' relays written while reading the coil at hand: they
    /// go before it.
    relays: Vec<Instruction>,
    /// The shared boxes written, by local id: a box read as `OUT` and as
    /// its first output (no `formalParameter`) is written once.
    written: HashMap<u64, Flow>,
    /// Every connection was checked against the elements beforehand, and
    /// a dangling one said there.
    checked: bool,
    errors: Vec<SourceError>,
}

impl<'a, 'i> Reader<'a, 'i> {
    /// A reader over `elements` (a body's, or a chart's with what is
    /// drawn in it), indexed by local id and connector name; the first
    /// element of an id wins.
    fn new(
        origin: &'a str,
        doc: &'a Document<'i>,
        elements: impl Iterator<Item = Node<'a, 'i>>,
    ) -> Self {
        let mut r = Reader {
            origin,
            doc,
            elements: HashMap::new(),
            connectors: HashMap::new(),
            memo: HashMap::new(),
            consumers: HashMap::new(),
            scope: String::new(),
            relays: Vec::new(),
            written: HashMap::new(),
            checked: false,
            errors: Vec::new(),
        };
        for e in elements.filter(Node::is_element) {
            if let Some(id) = local_id(e) {
                r.elements.entry(id).or_insert(e);
            }
            if e.has_tag_name("connector") {
                if let Some(n) = e.attribute("name") {
                    r.connectors.insert(n.to_string(), e);
                }
            }
        }
        r
    }

    fn at(&self, node: Node<'_, '_>) -> Location {
        let pos = self.doc.text_pos_at(node.range().start);
        Location {
            line: pos.row as usize,
            col: pos.col as usize,
        }
    }

    fn error(&mut self, node: Node<'_, '_>, message: String) {
        let at = self.at(node);
        self.errors.push(SourceError::new(self.origin, at, message));
    }

    /// What flows into `node`: the OR of its connections.
    fn input(&mut self, node: Node<'a, 'i>, depth: usize) -> Flow {
        let Some(point) = node
            .children()
            .find(|c| c.has_tag_name("connectionPointIn"))
        else {
            return Flow::Opaque("nothing connected to its input".into(), self.at(node));
        };
        let branches: Vec<Flow> = point
            .children()
            .filter(|c| c.has_tag_name("connection"))
            .map(|c| {
                let id = c.attribute("refLocalId").and_then(|v| v.parse().ok());
                let param = c.attribute("formalParameter").unwrap_or("").to_string();
                match id {
                    Some(id) => self.output(id, &param, c, depth + 1),
                    None => {
                        self.error(c, "connection without a refLocalId".into());
                        Flow::True
                    }
                }
            })
            .collect();
        if branches.is_empty() {
            return Flow::Opaque("nothing connected to its input".into(), self.at(node));
        }
        Flow::or(branches)
    }

    /// What flows out of element `id` (output `param` of a block).
    fn output(&mut self, id: u64, param: &str, from: Node<'_, '_>, depth: usize) -> Flow {
        let key = (id, param.to_string());
        if let Some(f) = self.memo.get(&key) {
            return f.clone();
        }
        let Some(&node) = self.elements.get(&id) else {
            if !self.checked {
                self.error(
                    from,
                    format!("connection to element {id}, which this body does not have"),
                );
            }
            return Flow::True;
        };
        if depth > MAX_DEPTH {
            self.error(
                node,
                format!("the rung chains deeper than {MAX_DEPTH} elements, or loops"),
            );
            return Flow::True;
        }
        // Guards a loop in the graph while this element is being read.
        self.memo.insert(
            key.clone(),
            Flow::Opaque("the rung loops back".into(), self.at(node)),
        );
        let flow = self.element(node, param, depth);
        let flow = self.shared(node, id, flow);
        self.memo.insert(key, flow.clone());
        flow
    }

    /// The flow out of a boolean function (`AND`, `OR`, `XOR`, `NOT`)
    /// that several connections read: written once into a relay named
    /// after the POU and the block (`#Main.AND28`), which each reads.
    fn shared(&mut self, node: Node<'a, 'i>, id: u64, flow: Flow) -> Flow {
        let ty = node.attribute("typeName").unwrap_or("");
        let shared_box = node.has_tag_name("block")
            && node.attribute("instanceName").is_none()
            && ["AND", "OR", "XOR", "NOT"]
                .iter()
                .any(|k| k.eq_ignore_ascii_case(ty))
            && self.consumers.get(&id).is_some_and(|&n| n > 1);
        if !shared_box {
            return flow;
        }
        if let Some(read) = self.written.get(&id) {
            return read.clone();
        }
        let relay = Signal::new(&format!("#{}.{ty}{id}", self.scope));
        let at = self.at(node);
        let read = shared(flow, relay, id, at, "ST", &mut self.relays);
        self.written.insert(id, read.clone());
        read
    }

    /// Checks every connection of the body against its elements, each
    /// that names an element the body does not have an error at the
    /// connection; and counts how often each element is read.
    fn check_connections(&mut self, body: Node<'a, 'i>) {
        for c in body.descendants().filter(|c| c.has_tag_name("connection")) {
            let Some(id) = c
                .attribute("refLocalId")
                .and_then(|v| v.parse::<u64>().ok())
            else {
                continue;
            };
            if self.elements.contains_key(&id) {
                let eno = c
                    .attribute("formalParameter")
                    .is_some_and(|p| p.eq_ignore_ascii_case("ENO"));
                // What reads it as logic: what else reads it is not
                // derivable anyway.
                let logic = c
                    .ancestors()
                    .find(|a| local_id(*a).is_some())
                    .is_some_and(reads_logic);
                if !eno && logic {
                    *self.consumers.entry(id).or_default() += 1;
                }
                continue;
            }
            let reader = c
                .ancestors()
                .find(|a| local_id(*a).is_some())
                .map(|a| {
                    let pin = c
                        .ancestors()
                        .find(|v| v.has_tag_name("variable"))
                        .and_then(|v| v.attribute("formalParameter"))
                        .map(|p| format!(" input {p}"))
                        .unwrap_or_default();
                    format!(
                        "{} {}{pin}",
                        a.tag_name().name(),
                        a.attribute("localId").unwrap_or("?")
                    )
                })
                .unwrap_or_else(|| "a connection".into());
            self.error(
                c,
                format!(
                    "{reader} is connected to element {id}, which is not in POU '{}'",
                    self.scope
                ),
            );
        }
        self.checked = true;
    }

    fn element(&mut self, node: Node<'a, 'i>, param: &str, depth: usize) -> Flow {
        match node.tag_name().name() {
            "leftPowerRail" => Flow::True,
            "contact" => {
                let input = self.input(node, depth);
                let Some(var) = variable(node) else {
                    self.error(node, "contact without a variable".into());
                    return input;
                };
                if node.attribute("edge").is_some_and(|e| e != "none") {
                    let why =
                        format!("edge contact on '{var}' (a pulse, not a function of the signals)");
                    return Flow::and(vec![input, Flow::Opaque(why, self.at(node))]);
                }
                match iec::operand_signal(&var) {
                    Ok(s) => {
                        let id = local_id(node).unwrap_or(0);
                        let negated = node.attribute("negated") == Some("true");
                        Flow::and(vec![input, Flow::Lit(s, negated, id)])
                    }
                    Err(m) => {
                        self.error(node, m);
                        input
                    }
                }
            }
            // Power passes through a coil.
            "coil" => self.input(node, depth),
            "block" => {
                let instance = node.attribute("instanceName");
                let ty = node.attribute("typeName").unwrap_or("?");
                match instance {
                    Some(i) if !param.is_empty() => {
                        match iec::operand_signal(&format!("{i}.{param}")) {
                            Ok(s) => Flow::Lit(s, false, local_id(node).unwrap_or(0)),
                            Err(m) => Flow::Opaque(m, self.at(node)),
                        }
                    }
                    _ => self.function(node, ty, param, depth),
                }
            }
            "inVariable" | "inOutVariable" => {
                let expr = child_text(node, "expression").unwrap_or_default();
                let negated = node.attribute("negated") == Some("true");
                match expr.trim().to_ascii_uppercase().as_str() {
                    "TRUE" => return if negated { Flow::False } else { Flow::True },
                    "FALSE" => return if negated { Flow::True } else { Flow::False },
                    _ => {}
                }
                match iec::operand_signal(expr.trim()) {
                    Ok(s) => Flow::Lit(
                        s,
                        node.attribute("negated") == Some("true"),
                        local_id(node).unwrap_or(0),
                    ),
                    Err(_) => Flow::Opaque(format!("variable '{}'", expr.trim()), self.at(node)),
                }
            }
            "continuation" => {
                let name = node.attribute("name").unwrap_or_default().to_string();
                match self.connectors.get(&name).copied() {
                    Some(c) => self.input(c, depth),
                    None => {
                        self.error(
                            node,
                            format!("continuation '{name}' has no connector of that name"),
                        );
                        Flow::True
                    }
                }
            }
            other => Flow::Opaque(format!("element '{other}'"), self.at(node)),
        }
    }

    /// The output `param` of a function box: the boolean functions AND,
    /// OR, XOR and NOT (of any number of inputs, each perhaps negated, and
    /// the output perhaps negated) are logic; any other function's output
    /// is not derivable.
    fn function(&mut self, node: Node<'a, 'i>, ty: &str, param: &str, depth: usize) -> Flow {
        let kind = ty.to_ascii_uppercase();
        let opaque = |r: &Self| Flow::Opaque(format!("output of function '{ty}'"), r.at(node));
        if !matches!(kind.as_str(), "AND" | "OR" | "XOR" | "NOT") {
            return opaque(self);
        }
        let variables = |list: &'static str| {
            node.children()
                .filter(move |c| c.has_tag_name(list))
                .flat_map(|l| l.children().filter(|v| v.has_tag_name("variable")))
        };
        let outputs: Vec<Node> = variables("outputVariables").collect();
        let output = outputs
            .iter()
            .find(|v| v.attribute("formalParameter") == Some(param))
            .or_else(|| outputs.first().filter(|_| param.is_empty()));
        let Some(output) = output.copied() else {
            // ENO, or an output the box does not have.
            return opaque(self);
        };
        let mut inputs = Vec::new();
        for v in variables("inputVariables") {
            let flow = self.input(v, depth);
            if v.attribute("formalParameter")
                .is_some_and(|p| p.eq_ignore_ascii_case("EN"))
            {
                // Enabled by the rail: always runs. Otherwise its output
                // holds while disabled: not a function of the inputs.
                if flow != Flow::True {
                    return opaque(self);
                }
                continue;
            }
            inputs.push(if v.attribute("negated") == Some("true") {
                flow.not()
            } else {
                flow
            });
        }
        let flow = match (kind.as_str(), inputs.len()) {
            (_, 0) => return opaque(self),
            ("NOT", 1) => inputs.pop().unwrap_or(Flow::True).not(),
            ("NOT", _) => return opaque(self),
            ("AND", _) => Flow::and(inputs),
            ("OR", _) => Flow::or(inputs),
            _ => {
                let mut it = inputs.into_iter();
                let first = it.next().unwrap_or(Flow::False);
                it.fold(first, Flow::xor)
            }
        };
        if output.attribute("negated") == Some("true") {
            flow.not()
        } else {
            flow
        }
    }
}

/// Whether `element` reads its inputs as logic: a contact, a coil, an
/// output variable, a connector, a boolean function.
fn reads_logic(element: Node<'_, '_>) -> bool {
    match element.tag_name().name() {
        "contact" | "coil" | "outVariable" | "inOutVariable" | "connector" => true,
        "block" => {
            let ty = element.attribute("typeName").unwrap_or("");
            element.attribute("instanceName").is_none()
                && ["AND", "OR", "XOR", "NOT"]
                    .iter()
                    .any(|k| k.eq_ignore_ascii_case(ty))
        }
        _ => false,
    }
}

fn local_id(node: Node<'_, '_>) -> Option<u64> {
    node.attribute("localId").and_then(|v| v.parse().ok())
}

fn child_text(node: Node<'_, '_>, name: &str) -> Option<String> {
    node.children()
        .find(|c| c.has_tag_name(name))
        .map(|c| c.text().unwrap_or_default().to_string())
}

fn variable(node: Node<'_, '_>) -> Option<String> {
    child_text(node, "variable").map(|v| v.trim().to_string())
}

/// Emits the instructions that compute `flow`, starting a new result.
pub(crate) fn emit(flow: &Flow, at: Location, out: &mut Vec<Instruction>) {
    let ins = |operation: Operation, operand: Option<Operand>, text: String| Instruction {
        at,
        text: text.clone(),
        mnemonic: text.split(' ').next().unwrap_or("").to_string(),
        operation,
        operand,
        operand_at: at,
    };
    match flow {
        Flow::True => out.push(ins(
            Operation::Load {
                negated: false,
                push: false,
            },
            Some(Operand::Const(true)),
            "LD TRUE".into(),
        )),
        Flow::False => out.push(ins(
            Operation::Load {
                negated: false,
                push: false,
            },
            Some(Operand::Const(false)),
            "LD FALSE".into(),
        )),
        Flow::Lit(s, negated, _) => out.push(ins(
            Operation::Load {
                negated: *negated,
                push: false,
            },
            Some(Operand::Signal(s.clone())),
            format!("{} {s}", if *negated { "LDN" } else { "LD" }),
        )),
        Flow::Opaque(why, where_) => out.push(Instruction {
            at: *where_,
            text: why.clone(),
            mnemonic: why.clone(),
            operation: Operation::Outside(Outside::Call),
            operand: None,
            operand_at: *where_,
        }),
        Flow::And(parts) | Flow::Or(parts) => {
            let op = if matches!(flow, Flow::And(_)) {
                Op::And
            } else {
                Op::Or
            };
            let name = if op == Op::And { "AND" } else { "OR" };
            let Some((first, rest)) = parts.split_first() else {
                return;
            };
            emit(first, at, out);
            for p in rest {
                match p {
                    Flow::Lit(s, negated, _) => out.push(ins(
                        Operation::Logic {
                            op,
                            negated: *negated,
                        },
                        Some(Operand::Signal(s.clone())),
                        format!("{name}{} {s}", if *negated { "N" } else { "" }),
                    )),
                    other => {
                        out.push(ins(
                            Operation::Open {
                                op: Some(op),
                                negated: false,
                            },
                            None,
                            format!("{name}("),
                        ));
                        emit(other, at, out);
                        out.push(ins(Operation::Close, None, ")".into()));
                    }
                }
            }
        }
    }
}

/// Whether `flow` is boolean logic through and through (no part of it
/// opaque): what a shared box's relay may hold.
fn is_logic(flow: &Flow) -> bool {
    match flow {
        Flow::True | Flow::False | Flow::Lit(..) => true,
        Flow::And(parts) | Flow::Or(parts) => parts.iter().all(is_logic),
        Flow::Opaque(..) => false,
    }
}

/// A box whose output feeds several inputs, read as the IL reads an
/// internal relay: its logic written once into `relay` (at `at`, with
/// `mnemonic`, `ST` or `=`), each input reading the relay, so that the
/// switching function has one step block read twice, not two copies.
/// A single contact or a constant needs no relay, and logic that is not
/// boolean stays where it is read, so that it is said there.
pub(crate) fn shared(
    flow: Flow,
    relay: Signal,
    id: u64,
    at: Location,
    mnemonic: &str,
    out: &mut Vec<Instruction>,
) -> Flow {
    if !matches!(flow, Flow::And(_) | Flow::Or(_)) || !is_logic(&flow) {
        return flow;
    }
    emit(&flow, at, out);
    out.push(Instruction {
        at,
        text: format!("{mnemonic} {relay}"),
        mnemonic: mnemonic.to_string(),
        operation: Operation::Write { negated: false },
        operand: Some(Operand::Signal(relay.clone())),
        operand_at: at,
    });
    Flow::Lit(relay, false, id)
}

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

/// The logic a graphical body (`LD` or `FBD`, as in an SFC's named
/// transition) writes to `name`, as ST text (`(a AND NOT b) OR c`): the
/// coil or output variable of that name, else the body's only one.
///
/// # Errors
/// Where and why: no such output, or logic that is not boolean (a
/// function, an edge), at the element's byte offset.
pub(crate) fn graphical_condition(
    doc: &Document<'_>,
    body: Node<'_, '_>,
    name: &str,
) -> Result<String, (usize, String)> {
    let outputs: Vec<(Node, String)> = body
        .descendants()
        .filter(|c| c.has_tag_name("coil") || c.has_tag_name("outVariable"))
        .filter_map(|c| {
            let var = if c.has_tag_name("coil") {
                variable(c)
            } else {
                child_text(c, "expression").map(|v| v.trim().to_string())
            };
            Some((c, var?))
        })
        .collect();
    let output = match outputs.iter().find(|(_, v)| v.eq_ignore_ascii_case(name)) {
        Some(o) => o.0,
        None if outputs.len() == 1 => outputs[0].0,
        None => {
            return Err((
                body.range().start,
                format!("no coil or output variable '{name}' gives the condition in this body"),
            ))
        }
    };
    connected_condition(doc, body, output)
}

/// The logic flowing into `sink` (a coil, an output variable, or an SFC
/// transition's `condition` wired to contacts and boxes drawn in the
/// chart), read over the elements of `scope`, as ST text.
///
/// # Errors
/// Where and why: logic that is not boolean (a function, an edge), a
/// dangling connection.
pub(crate) fn connected_condition(
    doc: &Document<'_>,
    scope: Node<'_, '_>,
    sink: Node<'_, '_>,
) -> Result<String, (usize, String)> {
    let mut r = Reader::new("", doc, scope.descendants());
    let flow = r.input(sink, 0);
    if let Some(e) = r.errors.first() {
        return Err((sink.range().start, e.message.clone()));
    }
    let flow = match sink.attribute("negated") {
        Some("true") => flow.not(),
        _ => flow,
    };
    let mut text = String::new();
    st_text(&flow, &mut text).map_err(|why| (sink.range().start, why))?;
    Ok(text)
}

/// Writes `flow` as an ST expression.
fn st_text(flow: &Flow, out: &mut String) -> Result<(), String> {
    match flow {
        Flow::True => out.push_str("TRUE"),
        Flow::False => out.push_str("FALSE"),
        Flow::Lit(s, negated, _) => {
            if *negated {
                out.push_str("NOT ");
            }
            out.push_str(s.name());
        }
        Flow::And(parts) | Flow::Or(parts) => {
            let op = if matches!(flow, Flow::And(_)) {
                " AND "
            } else {
                " OR "
            };
            out.push('(');
            for (i, p) in parts.iter().enumerate() {
                if i > 0 {
                    out.push_str(op);
                }
                st_text(p, out)?;
            }
            out.push(')');
        }
        Flow::Opaque(why, _) => {
            return Err(format!("the condition is not boolean logic: {why}"));
        }
    }
    Ok(())
}

/// The POU a body (`LD`, `FBD`) is of, and its action or transition:
/// `Main`, `Main.Fill`.
fn scope(body: Node<'_, '_>) -> String {
    let mut names: Vec<&str> = body
        .ancestors()
        .filter(|a| matches!(a.tag_name().name(), "pou" | "action" | "transition"))
        .filter_map(|a| a.attribute("name"))
        .collect();
    names.reverse();
    names.join(".")
}

/// One LD body: each coil, in document order, as the instructions that
/// compute and write it.
fn ladder<'a, 'i>(
    origin: &'a str,
    doc: &'a Document<'i>,
    body: Node<'a, 'i>,
    declared: &iec::Declarations,
) -> (Vec<Instruction>, Vec<SourceError>) {
    let mut r = Reader::new(origin, doc, body.children());
    r.scope = scope(body);
    r.check_connections(body);
    let mut out = Vec::new();
    // Coils, and output variables a rung may end in instead (what writes
    // them is read the same way: a block's output is not derivable).
    for coil in body
        .children()
        .filter(|c| c.has_tag_name("coil") || c.has_tag_name("outVariable"))
    {
        let at = r.at(coil);
        let var = if coil.has_tag_name("coil") {
            variable(coil)
        } else {
            child_text(coil, "expression").map(|v| v.trim().to_string())
        };
        let Some(var) = var else {
            r.error(
                coil,
                format!("{} without a variable", coil.tag_name().name()),
            );
            continue;
        };
        // An output variable of another type (`Out : INT`) is data flow.
        if coil.has_tag_name("outVariable") && declared.not_boolean(&var) {
            continue;
        }
        let signal = match iec::operand_signal(&var) {
            Ok(s) => s,
            Err(m) => {
                r.error(coil, m);
                continue;
            }
        };
        let flow = r.input(coil, 0);
        out.append(&mut r.relays);
        emit(&flow, at, &mut out);
        let negated = coil.attribute("negated") == Some("true");
        let (operation, mnemonic) = match coil.attribute("storage") {
            Some("set") => (Operation::Set, "S"),
            Some("reset") => (Operation::Reset, "R"),
            _ if negated => (Operation::Write { negated: true }, "STN"),
            _ => (Operation::Write { negated: false }, "ST"),
        };
        out.push(Instruction {
            at,
            text: format!("{mnemonic} {signal}"),
            mnemonic: mnemonic.into(),
            operation,
            operand: Some(Operand::Signal(signal)),
            operand_at: at,
        });
    }
    r.errors.sort_by_key(|e| e.at);
    (out, r.errors)
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
        let e = Program::compile("p.xml", &project(""), Some(crate::il::Dialect::Iec)).unwrap_err();
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
