//! Function block diagram (FBD) routines of an L5X export: the sheets'
//! elements and wires as a graph, each output reference (`ORef`) a coil
//! whose flow is what is wired into it. The routines, programs and tag
//! names around them are `l5x/mod.rs`'s and `names.rs`'s.
//!
//! A wire names its ends by element ID and pin (`<Wire FromID="2"
//! FromParam="Out" ToID="5" ToParam="In1"/>`; an `IRef` or `ICon` has no
//! `FromParam`, an `ORef` or `OCon` no `ToParam`). An input reference
//! (`IRef`) is a contact on its tag (`1` and `0` are constants); an `ICon`
//! carries what is wired into the `OCon` of its name, on any sheet. The
//! boolean blocks `BAND`, `BOR`, `BXOR` and `BNOT` (with a backing tag,
//! `<Block>`) and their functions (`BAND__F`, ..., `<Function>`) are
//! logic; an input pin that is not shown (not in `VisiblePins`) and not
//! wired keeps the value Logix gives it at download (1 for `BAND`, 0 for
//! `BOR`), which leaves the result as it is. A shown input that is not
//! wired (it holds what the tag holds), a wired `EnableIn`, a feedback
//! wire or a loop, an output pin other than `Out`, any other block
//! (`TONR`, `CMP`, `OSRI`, ...) and Add-On Instructions make what they feed
//! not derivable, each with a warning at its element. A `JSR` element
//! runs its routine. An `IRef` reads its tag as the routine starts (Logix
//! latches it), so a tag that an `ORef` of the same routine writes is read
//! as the coil it is, as a ladder contact on a coil written later in the
//! scan is.
//!
//! A boolean block or function whose `Out` feeds several pins that read
//! logic is written once into an internal relay named after the program,
//! routine, sheet and block (`#MainProgram.Main.1.BAND_03`), which each
//! pin reads: one step block read twice, as the IL reads an internal
//! relay. A wire whose `FromID` or `ToID` its sheet does not have is an
//! error at the wire.

use std::collections::{HashMap, HashSet};
use std::rc::Rc;

use roxmltree::Node;

use super::names::number;
use super::names::NotSignal;
use super::scope::{Access, Scope};
use super::{Frame, Reader, MAX_CALL_DEPTH};
use crate::programs::plcopen::{emit, shared, Flow, MAX_DEPTH};
use crate::programs::{Instruction, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError};

/// A pin: sheet index, element ID, pin name in upper case (`""` for a
/// reference's or connector's one pin).
type Pin = (usize, u64, String);

/// A wire into a pin: where it comes from.
#[derive(Clone, Copy)]
struct Wire<'d> {
    from: u64,
    param: &'d str,
    node: Node<'d, 'd>,
    /// A `FeedbackWire`: the value of the previous scan.
    feedback: bool,
}

/// One FBD routine being read.
struct Diagram<'d> {
    program: &'d str,
    /// The bindings of the Add-On Instruction whose logic this is.
    aoi: Option<Rc<Scope>>,
    routine: String,
    /// The sheets' numbers, by index.
    sheets: Vec<String>,
    /// Elements by sheet index and ID.
    elements: HashMap<(usize, u64), Node<'d, 'd>>,
    /// What is wired into each pin.
    wires: HashMap<Pin, Vec<Wire<'d>>>,
    /// `OCon`s by upper-case name.
    connectors: HashMap<String, Vec<(usize, u64)>>,
    /// What flows out of each output pin already read.
    memo: HashMap<Pin, Flow>,
    /// Output pins being read (a loop comes back to one).
    reading: HashSet<Pin>,
    /// Warnings given, so that each is given once.
    noted: HashSet<(Location, String)>,
    /// How many input pins each output pin feeds (through an `OCon`, as
    /// many as its `ICon`s): a boolean block that feeds more than one is
    /// written once, into an internal relay.
    consumers: HashMap<Pin, usize>,
    /// Shared blocks' relays written while reading the `ORef` at hand:
    /// they go before it.
    relays: Vec<Instruction>,
}

impl<'d> Diagram<'d> {
    fn where_(&self, sheet: usize) -> String {
        format!("routine {}, sheet {}", self.routine, self.sheets[sheet])
    }
}

/// How an element is named in a warning: `BAND block 'BAND_01'`,
/// `BNOT__F function (ID 11)`, `Add-On Instruction 'Valve' ('V1')`.
fn label(node: Node<'_, '_>) -> String {
    let id = node.attribute("ID").unwrap_or("?");
    let ty = node.attribute("Type").unwrap_or("?");
    match node.tag_name().name() {
        "Block" => match node.attribute("Operand") {
            Some(tag) => format!("{ty} block '{tag}'"),
            None => format!("{ty} block (ID {id})"),
        },
        "Function" => format!("{ty} function (ID {id})"),
        "AddOnInstruction" => format!(
            "Add-On Instruction '{}' ('{}')",
            node.attribute("Name").unwrap_or("?"),
            node.attribute("Operand").unwrap_or("?")
        ),
        "JSR" => format!(
            "JSR to routine '{}' (ID {id})",
            node.attribute("Routine").unwrap_or("?")
        ),
        reference @ ("IRef" | "ORef") => {
            format!("{reference} '{}'", node.attribute("Operand").unwrap_or("?"))
        }
        connector @ ("ICon" | "OCon") => {
            format!("{connector} '{}'", node.attribute("Name").unwrap_or("?"))
        }
        other => format!("{other} (ID {id})"),
    }
}

/// How an element is named where a coil is not derivable: `TONR(TONR_01)`,
/// `BXOR__F(ID 6)`, `IRef(100)`.
fn short(node: Node<'_, '_>) -> String {
    let id = node.attribute("ID").unwrap_or("?");
    let name = node.tag_name().name();
    let (head, arg) = match name {
        "Block" | "Function" => (node.attribute("Type"), node.attribute("Operand")),
        "AddOnInstruction" => (node.attribute("Name"), node.attribute("Operand")),
        "JSR" => (Some(name), node.attribute("Routine")),
        "ICon" | "OCon" => (Some(name), node.attribute("Name")),
        _ => (Some(name), node.attribute("Operand")),
    };
    match arg {
        Some(arg) => format!("{}({arg})", head.unwrap_or(name)),
        None => format!("{}(ID {id})", head.unwrap_or(name)),
    }
}

/// Input `name` of `node` in a warning: `input In2 of BAND block 'B1'`.
fn described(node: Node<'_, '_>, name: &str) -> String {
    if name.is_empty() {
        label(node)
    } else {
        format!("input {name} of {}", label(node))
    }
}

/// Input `name` of `node` where a coil is not derivable: `BAND(B1).In2`.
fn shortened(node: Node<'_, '_>, name: &str) -> String {
    if name.is_empty() {
        short(node)
    } else {
        format!("{}.{name}", short(node))
    }
}

/// The logic of a boolean block type (`BAND`, `BAND__F`), upper case.
fn boolean_kind(ty: &str) -> Option<&'static str> {
    let upper = ty.to_ascii_uppercase();
    let base = upper.strip_suffix("__F").unwrap_or(&upper);
    ["BAND", "BOR", "BXOR", "BNOT"]
        .into_iter()
        .find(|k| *k == base)
}

impl<'d> Reader<'_, 'd> {
    /// Reads an FBD routine: every `ORef` on every sheet, in file order,
    /// as the instructions that compute and write its tag; then the
    /// routines its `JSR` elements run.
    pub(super) fn fbd(
        &mut self,
        node: Node<'d, 'd>,
        frame: &Frame<'d>,
        reached: &mut HashSet<String>,
    ) {
        let sheets: Vec<Node> = node
            .children()
            .filter(|c| c.has_tag_name("FBDContent"))
            .flat_map(|c| c.children())
            .filter(|s| s.has_tag_name("Sheet"))
            .collect();
        let mut d = Diagram {
            program: frame.program,
            aoi: frame.aoi.clone(),
            routine: frame.routine.clone(),
            sheets: Vec::new(),
            elements: HashMap::new(),
            wires: HashMap::new(),
            connectors: HashMap::new(),
            memo: HashMap::new(),
            reading: HashSet::new(),
            noted: HashSet::new(),
            consumers: HashMap::new(),
            relays: Vec::new(),
        };
        for (k, sheet) in sheets.iter().enumerate() {
            d.sheets.push(
                sheet
                    .attribute("Number")
                    .map_or_else(|| (k + 1).to_string(), str::to_string),
            );
            for e in sheet.children().filter(Node::is_element) {
                let id = e.attribute("ID").and_then(|v| v.parse::<u64>().ok());
                if e.has_tag_name("OCon") {
                    if let (Some(id), Some(name)) = (id, e.attribute("Name")) {
                        d.connectors
                            .entry(name.to_ascii_uppercase())
                            .or_default()
                            .push((k, id));
                    }
                }
                if let Some(id) = id.filter(|_| !e.has_tag_name("Wire")) {
                    d.elements.entry((k, id)).or_insert(e);
                }
            }
        }
        // ICons by upper-case name: what an `OCon` feeds.
        let mut icons: HashMap<String, usize> = HashMap::new();
        for e in d.elements.values().filter(|e| e.has_tag_name("ICon")) {
            let name = e.attribute("Name").unwrap_or("").to_ascii_uppercase();
            *icons.entry(name).or_default() += 1;
        }
        for (k, sheet) in sheets.iter().enumerate() {
            for e in sheet.children().filter(Node::is_element) {
                match e.tag_name().name() {
                    "Wire" | "FeedbackWire" => {
                        let ends = (
                            e.attribute("FromID").and_then(|v| v.parse().ok()),
                            e.attribute("ToID").and_then(|v| v.parse::<u64>().ok()),
                        );
                        let (Some(from), Some(to)) = ends else {
                            let at = self.at(e.range().start);
                            self.errors.push(SourceError::new(
                                self.origin,
                                at,
                                format!("{}: a wire without a FromID and a ToID", d.where_(k)),
                            ));
                            continue;
                        };
                        let missing = [from, to]
                            .into_iter()
                            .find(|id| !d.elements.contains_key(&(k, *id)));
                        if let Some(missing) = missing {
                            let at = self.at(e.range().start);
                            self.errors.push(SourceError::new(
                                self.origin,
                                at,
                                format!(
                                    "{}: the wire from {from} to {to} names element {missing}, which is not on this sheet",
                                    d.where_(k)
                                ),
                            ));
                            continue;
                        }
                        let from_param =
                            e.attribute("FromParam").unwrap_or("").to_ascii_uppercase();
                        // Pins that read logic: what else reads it is
                        // not derivable anyway.
                        let fed = match d.elements.get(&(k, to)) {
                            Some(target) if target.has_tag_name("OCon") => {
                                let name = target.attribute("Name").unwrap_or("");
                                icons.get(&name.to_ascii_uppercase()).copied().unwrap_or(0)
                            }
                            Some(target) if target.has_tag_name("ORef") => 1,
                            Some(target) => usize::from(
                                boolean_kind(target.attribute("Type").unwrap_or("")).is_some(),
                            ),
                            None => 0,
                        };
                        *d.consumers.entry((k, from, from_param)).or_default() += fed;
                        let pin = e.attribute("ToParam").unwrap_or("").to_ascii_uppercase();
                        d.wires.entry((k, to, pin)).or_default().push(Wire {
                            from,
                            param: e.attribute("FromParam").unwrap_or(""),
                            node: e,
                            feedback: e.has_tag_name("FeedbackWire"),
                        });
                    }
                    _ => {}
                }
            }
        }
        let mut calls = Vec::new();
        for (k, sheet) in sheets.iter().enumerate() {
            for e in sheet.children().filter(Node::is_element) {
                match e.tag_name().name() {
                    "ORef" => self.output_reference(&mut d, k, e, frame),
                    "JSR" => calls.push((k, e)),
                    _ => {}
                }
            }
        }
        // Two JSRs of one routine write what it writes the same way.
        let mut called = HashSet::new();
        for (k, e) in calls {
            let target = e.attribute("Routine").unwrap_or("").to_ascii_uppercase();
            let id = e
                .attribute("ID")
                .and_then(|v| v.parse().ok())
                .unwrap_or(u64::MAX);
            let enabled = d.wires.contains_key(&(k, id, "ENABLEIN".to_string()));
            if called.insert((target, enabled)) {
                self.fbd_call(&mut d, k, e, frame, reached);
            }
        }
    }

    /// A located warning, once per place and text.
    fn fbd_note(&mut self, d: &mut Diagram<'d>, node: Node<'_, '_>, message: String) -> Location {
        let at = self.at(node.range().start);
        if d.noted.insert((at, message.clone())) {
            self.note_at(at, message);
        }
        at
    }

    /// An `ORef`: its tag written with what is wired into it.
    fn output_reference(
        &mut self,
        d: &mut Diagram<'d>,
        sheet: usize,
        node: Node<'d, 'd>,
        frame: &Frame<'d>,
    ) {
        let at = self.at(node.range().start);
        let Some(operand) = node.attribute("Operand") else {
            self.errors.push(SourceError::new(
                self.origin,
                at,
                format!("{}: an ORef without an Operand", d.where_(sheet)),
            ));
            return;
        };
        let text = short(node);
        let signal = match self.signal(frame, operand, Access::Write) {
            Ok(s) => Signal::new(&s),
            Err(NotSignal::Indirect(_) | NotSignal::Number(_)) => {
                return self.out.push(Instruction {
                    at,
                    text,
                    mnemonic: "ORef".into(),
                    operation: Operation::Outside(Outside::Indirect),
                    operand: None,
                    operand_at: at,
                });
            }
            Err(NotSignal::Malformed(why)) => {
                return self.errors.push(SourceError::new(
                    self.origin,
                    at,
                    format!("{}: {why}", d.where_(sheet)),
                ));
            }
        };
        let id = node
            .attribute("ID")
            .and_then(|v| v.parse().ok())
            .unwrap_or(u64::MAX);
        let flow = self.pin(d, (sheet, id, String::new()), node, "", 0);
        self.out.append(&mut d.relays);
        let mut parts = vec![frame.guard.clone()];
        parts.extend(self.cut.clone());
        parts.push(flow);
        emit(&Flow::and(parts), at, &mut self.out);
        self.out.push(Instruction {
            at,
            text: format!("ORef({signal})"),
            mnemonic: "ORef".into(),
            operation: Operation::Write { negated: false },
            operand: Some(Operand::Signal(signal)),
            operand_at: at,
        });
    }

    /// What is wired into input `name` of `node` (`""`: a reference's or
    /// connector's one pin) at `pin`; an unwired pin is not derivable.
    fn pin(
        &mut self,
        d: &mut Diagram<'d>,
        pin: Pin,
        node: Node<'d, 'd>,
        name: &str,
        depth: usize,
    ) -> Flow {
        match self.wired(d, &pin, node, name, depth) {
            Some(flow) => flow,
            None => {
                let why = format!(
                    "{}: {} is not wired: what it feeds is not derivable",
                    d.where_(pin.0),
                    described(node, name)
                );
                let at = self.fbd_note(d, node, why);
                Flow::Opaque(format!("{} (not wired)", shortened(node, name)), at)
            }
        }
    }

    /// What is wired into input `name` of `node` at `pin`, if anything is.
    fn wired(
        &mut self,
        d: &mut Diagram<'d>,
        pin: &Pin,
        node: Node<'d, 'd>,
        name: &str,
        depth: usize,
    ) -> Option<Flow> {
        let wires = d.wires.get(pin)?.clone();
        let sheet = pin.0;
        if wires.len() > 1 {
            let why = format!(
                "{}: {} has {} wires into it: what it feeds is not derivable",
                d.where_(sheet),
                described(node, name),
                wires.len()
            );
            let at = self.fbd_note(d, node, why);
            return Some(Flow::Opaque(
                format!("{} (wired twice)", shortened(node, name)),
                at,
            ));
        }
        let wire = wires[0];
        if wire.feedback {
            let why = format!(
                "{}: a feedback wire into {} carries the value of the previous scan: what it feeds is not derivable",
                d.where_(sheet),
                described(node, name)
            );
            let at = self.fbd_note(d, wire.node, why);
            return Some(Flow::Opaque(
                format!("{} (feedback wire)", shortened(node, name)),
                at,
            ));
        }
        Some(self.source(d, sheet, wire, depth + 1))
    }

    /// What flows out of the element a wire comes from.
    fn source(&mut self, d: &mut Diagram<'d>, sheet: usize, wire: Wire<'d>, depth: usize) -> Flow {
        let key = (sheet, wire.from, wire.param.to_ascii_uppercase());
        if let Some(f) = d.memo.get(&key) {
            return f.clone();
        }
        let Some(&node) = d.elements.get(&(sheet, wire.from)) else {
            let at = self.at(wire.node.range().start);
            self.errors.push(SourceError::new(
                self.origin,
                at,
                format!(
                    "{}: a wire from element {}, which this sheet does not have",
                    d.where_(sheet),
                    wire.from
                ),
            ));
            return Flow::Opaque(format!("element {}", wire.from), at);
        };
        if d.reading.contains(&key) || depth > MAX_DEPTH {
            let why = format!(
                "{}: {} is in a loop of wires (its output comes back to its input): what it feeds is not derivable",
                d.where_(sheet),
                label(node)
            );
            let at = self.fbd_note(d, node, why);
            return Flow::Opaque(format!("{} (in a loop)", short(node)), at);
        }
        d.reading.insert(key.clone());
        let flow = self.element(d, sheet, node, wire.param, depth);
        let flow = self.shared(d, &key, node, flow);
        d.reading.remove(&key);
        d.memo.insert(key, flow.clone());
        flow
    }

    /// The flow out of `Out` of a boolean block or function that feeds
    /// several pins: written once into a relay named after the program,
    /// routine, sheet and block (`#MainProgram.Main.1.BAND_03`, a
    /// function by type and ID: `BOR__F_ID7`), which each pin reads.
    fn shared(&mut self, d: &mut Diagram<'d>, key: &Pin, node: Node<'d, 'd>, flow: Flow) -> Flow {
        let ty = node.attribute("Type").unwrap_or("");
        let shared_box = matches!(node.tag_name().name(), "Block" | "Function")
            && boolean_kind(ty).is_some()
            && key.2 == "OUT"
            && d.consumers.get(key).is_some_and(|&n| n > 1);
        if !shared_box {
            return flow;
        }
        let name = match node.attribute("Operand") {
            Some(tag) => tag.to_string(),
            None => format!("{ty}_ID{}", key.1),
        };
        let relay = Signal::new(&format!(
            "#{}.{}.{}.{name}",
            d.program, d.routine, d.sheets[key.0]
        ));
        let at = self.at(node.range().start);
        self.ids += 1;
        shared(flow, relay, self.ids, at, "OTE", &mut d.relays)
    }

    /// What flows out of output `param` of `node`.
    fn element(
        &mut self,
        d: &mut Diagram<'d>,
        sheet: usize,
        node: Node<'d, 'd>,
        param: &str,
        depth: usize,
    ) -> Flow {
        let id = node
            .attribute("ID")
            .and_then(|v| v.parse().ok())
            .unwrap_or(u64::MAX);
        match node.tag_name().name() {
            "IRef" => self.input_reference(d, sheet, node),
            "ICon" => {
                let name = node.attribute("Name").unwrap_or("");
                let ocons = d
                    .connectors
                    .get(&name.to_ascii_uppercase())
                    .cloned()
                    .unwrap_or_default();
                match ocons.as_slice() {
                    [(s, oid)] => {
                        let ocon = d.elements.get(&(*s, *oid)).copied().unwrap_or(node);
                        self.pin(d, (*s, *oid, String::new()), ocon, "", depth)
                    }
                    _ => {
                        let why = format!(
                            "{}: ICon '{name}' has {} OCon of that name in this routine: what it feeds is not derivable",
                            d.where_(sheet),
                            if ocons.is_empty() { "no".to_string() } else { ocons.len().to_string() }
                        );
                        let at = self.fbd_note(d, node, why);
                        Flow::Opaque(short(node), at)
                    }
                }
            }
            "Block" | "Function" => {
                let ty = node.attribute("Type").unwrap_or("?");
                match boolean_kind(ty) {
                    Some(kind) if param.eq_ignore_ascii_case("Out") => {
                        self.boolean(d, sheet, id, node, kind, depth)
                    }
                    Some(_) => {
                        let why = format!(
                            "{}: output '{param}' of {} is not read: what it feeds is not derivable",
                            d.where_(sheet),
                            label(node)
                        );
                        let at = self.fbd_note(d, node, why);
                        Flow::Opaque(format!("{}.{param}", short(node)), at)
                    }
                    None => self.unread_element(d, sheet, node),
                }
            }
            _ => self.unread_element(d, sheet, node),
        }
    }

    /// An element whose output is not boolean logic.
    fn unread_element(&mut self, d: &mut Diagram<'d>, sheet: usize, node: Node<'d, 'd>) -> Flow {
        let why = format!(
            "{}: {} is not read: what it feeds is not derivable",
            d.where_(sheet),
            label(node)
        );
        let at = self.fbd_note(d, node, why);
        Flow::Opaque(short(node), at)
    }

    /// An `IRef`: a contact on its tag, or a constant.
    fn input_reference(&mut self, d: &mut Diagram<'d>, sheet: usize, node: Node<'d, 'd>) -> Flow {
        let at = self.at(node.range().start);
        let operand = node.attribute("Operand").unwrap_or("").trim();
        match operand {
            "0" => return Flow::False,
            "1" => return Flow::True,
            _ => {}
        }
        if number(operand).is_some() {
            let why = format!(
                "{}: IRef '{operand}' is a number, not a boolean: what it feeds is not derivable",
                d.where_(sheet)
            );
            self.fbd_note(d, node, why);
            return Flow::Opaque(short(node), at);
        }
        let scope = d.aoi.clone();
        match self.signal_in(d.program, scope.as_deref(), operand, Access::Read) {
            Ok(s) => {
                self.ids += 1;
                Flow::Lit(Signal::new(&s), false, self.ids)
            }
            Err(NotSignal::Number(n)) => match number(&n) {
                Some(v) if v != 0.0 => Flow::True,
                _ => Flow::False,
            },
            Err(NotSignal::Indirect(why)) => Flow::Opaque(format!("indirect address {why}"), at),
            Err(NotSignal::Malformed(why)) => {
                self.errors.push(SourceError::new(
                    self.origin,
                    at,
                    format!("{}: {why}", d.where_(sheet)),
                ));
                Flow::Opaque(short(node), at)
            }
        }
    }

    /// `Out` of a boolean block or function.
    fn boolean(
        &mut self,
        d: &mut Diagram<'d>,
        sheet: usize,
        id: u64,
        node: Node<'d, 'd>,
        kind: &str,
        depth: usize,
    ) -> Flow {
        let name = label(node);
        let enable = (sheet, id, "ENABLEIN".to_string());
        if let Some(flow) = self.wired(d, &enable, node, "EnableIn", depth) {
            if flow != Flow::True {
                let why = format!(
                    "{}: EnableIn of {name} is wired: while it is off the block holds its output, so what it feeds is not derivable",
                    d.where_(sheet)
                );
                let at = self.fbd_note(d, node, why);
                return Flow::Opaque(format!("{}.EnableIn (wired)", short(node)), at);
            }
        }
        let pins: Vec<String> = match kind {
            "BNOT" => vec!["In".into()],
            "BXOR" => vec!["In1".into(), "In2".into()],
            _ => (1..=8).map(|k| format!("In{k}")).collect(),
        };
        let shown: Vec<String> = match node.attribute("VisiblePins") {
            Some(v) => v.split_whitespace().map(str::to_ascii_uppercase).collect(),
            None => pins
                .iter()
                .take(2)
                .map(|p| p.to_ascii_uppercase())
                .collect(),
        };
        let mut inputs = Vec::new();
        for p in &pins {
            let upper = p.to_ascii_uppercase();
            let key = (sheet, id, upper.clone());
            if d.wires.contains_key(&key)
                || shown.contains(&upper)
                || kind != "BAND" && kind != "BOR"
            {
                inputs.push(self.pin(d, key, node, p, depth));
            }
        }
        match kind {
            "BNOT" => inputs.pop().unwrap_or(Flow::True).not(),
            "BAND" => Flow::and(inputs),
            "BOR" if inputs.is_empty() => Flow::False,
            "BOR" => Flow::or(inputs),
            _ => {
                let mut it = inputs.into_iter();
                let first = it.next().unwrap_or(Flow::False);
                it.fold(first, Flow::xor)
            }
        }
    }

    /// A `JSR` element: runs its routine, every scan unless its
    /// `EnableIn` is wired.
    fn fbd_call(
        &mut self,
        d: &mut Diagram<'d>,
        sheet: usize,
        node: Node<'d, 'd>,
        frame: &Frame<'d>,
        reached: &mut HashSet<String>,
    ) {
        let target = node.attribute("Routine").unwrap_or("");
        let upper = target.to_ascii_uppercase();
        let Some(&routine) = frame.routines.get(&upper) else {
            let why = format!(
                "{}: {}: routine '{target}' is not in this export",
                d.where_(sheet),
                label(node)
            );
            self.fbd_note(d, node, why);
            return;
        };
        if frame.calls.contains(&upper) || frame.calls.len() >= MAX_CALL_DEPTH {
            let why = format!(
                "{}: {}: routine '{target}' is already running (a JSR cycle, or calls deeper than {MAX_CALL_DEPTH}): not run again",
                d.where_(sheet),
                label(node)
            );
            self.fbd_note(d, node, why);
            return;
        }
        let id = node
            .attribute("ID")
            .and_then(|v| v.parse().ok())
            .unwrap_or(u64::MAX);
        let guard = if d.wires.contains_key(&(sheet, id, "ENABLEIN".to_string())) {
            let at = self.at(node.range().start);
            let why = format!(
                "{}: {} runs routine {target} only while its EnableIn is on, so what it writes may not be written every scan",
                d.where_(sheet),
                label(node)
            );
            Flow::and(vec![frame.guard.clone(), Flow::Opaque(why, at)])
        } else {
            frame.guard.clone()
        };
        let mut calls = frame.calls.clone();
        calls.push(upper);
        let inner = Frame {
            program: frame.program,
            routines: frame.routines.clone(),
            routine: routine.attribute("Name").unwrap_or(target).to_string(),
            calls,
            guard,
            aoi: frame.aoi.clone(),
        };
        self.routine(routine, &inner, reached);
    }
}
