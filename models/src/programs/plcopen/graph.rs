//! A graphical body read along its connection graph: each element names
//! the elements before it, and what flows out of it is the OR of what
//! flows in, ANDed with its own contact; FBD boxes are logic by De Morgan
//! ([`Reader`]). It owns walking an LD or FBD body into its coils'
//! instructions (`ladder`) and a drawn SFC transition's condition into ST
//! text ([`graphical_condition`], [`connected_condition`]); the flow itself
//! is `flow.rs`'s, the project around the bodies `mod.rs`'s.

use std::collections::HashMap;

use roxmltree::{Document, Node};

use super::flow::{emit, shared, st_text, Flow, MAX_DEPTH};
use crate::programs::{iec, Instruction, Operand, Operation};
use crate::signal::Signal;
use crate::source::{Location, SourceError};

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
                    Err(e) => {
                        self.error(node, e.to_string());
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
                            Err(e) => Flow::Opaque(e.to_string(), self.at(node)),
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
    st_text(&flow, &mut text).map_err(|why| (sink.range().start, why.to_string()))?;
    Ok(text)
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
pub(super) fn ladder<'a, 'i>(
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
            Err(e) => {
                r.error(coil, e.to_string());
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
