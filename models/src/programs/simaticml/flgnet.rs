//! One LAD or FBD network of a TIA Portal block (`FlgNet`): its parts and
//! wires read as a power-flow graph, each coil written as the instructions
//! that compute it, located at the coil's part.
//!
//! A wire joins one source to its sinks: the power rail, an operand
//! (`IdentCon`) or a part's output pin (`out`, `eno`, `Q`) feeds the
//! parts' input pins (`in`, `in1`, `operand`, `pre`). What flows out of a
//! contact is what flows in ANDed with its operand; an `O` part (LAD
//! parallel branches, FBD OR box) is the OR of its inputs, `A` the AND,
//! `X` the exclusive OR; a `<Negated Name="pin"/>` negates a pin. Coils
//! (`Coil`, `SCoil`, `RCoil`) and `Sr`/`Rs` boxes write their operand;
//! an IEC timer's or counter's `Q` is a leaf (`"DB".Q`), a comparator
//! (`Gt`, `Eq`, ...) of a tag with a number or another tag is a
//! comparison contact. Edges, other boxes and calls are warnings at their
//! part; this module does not read the block around the network, nor
//! tag comments (that is [`super`]'s job).
//!
//! A box (`A`, `O`, `X`, `Not`) whose output feeds several parts that
//! read logic is written once, before the first coil that reads it, into
//! an internal relay named after the block, network and part
//! (`#Conveyor.NW3.A25`), which each of those parts reads: one step block
//! read twice, as the IL reads an internal relay (paper 000's CSD: steps
//! 6 and 7 share step 5). A wire naming a part the network does not have
//! is an error at that end of the wire.

use std::collections::HashMap;

use roxmltree::{Document, Node};

use super::super::plcopen::{emit, shared, Flow, MAX_DEPTH};
use super::access::{access_signal, at, child, text_of, Place};
use crate::programs::{Instruction, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::{Location, SourceError};
use crate::value::{CmpOp, Comparison};

/// What an operand (`Access`) reads.
#[derive(Debug, Clone)]
enum Value {
    /// A bit or a tag of unknown type: a contact's operand.
    Var(Signal),
    /// A word, byte or number address: only compared.
    Word(Signal),
    /// `TRUE` / `FALSE`.
    Bool(bool),
    /// A number as written.
    Number(String),
    /// Not readable: why.
    Other(String),
}

/// A network being read.
pub(super) struct Network<'a, 'i> {
    origin: &'a str,
    doc: &'a Document<'i>,
    place: &'a Place,
    /// Access, Part and Call elements by UId.
    parts: HashMap<u64, Node<'a, 'i>>,
    /// The wires touching each pin (`""` for an operand's IdentCon).
    wires: HashMap<(u64, String), Vec<Node<'a, 'i>>>,
    memo: HashMap<(u64, String), Flow>,
    /// How many input pins each output pin feeds: a box that feeds more
    /// than one is written once, into an internal relay.
    consumers: HashMap<(u64, String), usize>,
    /// Shared boxes' relays written while reading the coil at hand: they
    /// go before it.
    relays: Vec<Instruction>,
    errors: Vec<SourceError>,
}

/// Whether `pin` is an output of a part (where power or a value leaves).
fn is_output(pin: &str) -> bool {
    let pin = pin.to_ascii_lowercase();
    matches!(
        pin.as_str(),
        "out" | "eno" | "q" | "qu" | "qd" | "et" | "cv" | "ret_val"
    ) || pin
        .strip_prefix("out")
        .is_some_and(|n| n.chars().all(|c| c.is_ascii_digit()))
}

/// Whether `part` reads its inputs as logic (what else reads a box's
/// output makes what it feeds not derivable anyway).
fn reads_logic(part: Node<'_, '_>) -> bool {
    part.has_tag_name("Part")
        && matches!(
            part.attribute("Name").unwrap_or(""),
            "A" | "O"
                | "X"
                | "Not"
                | "NOT"
                | "Contact"
                | "Coil"
                | "SCoil"
                | "RCoil"
                | "Sr"
                | "Rs"
                | "Eq"
                | "Ne"
                | "Gt"
                | "Ge"
                | "Lt"
                | "Le"
        )
}

/// The `Section` and `Type` of parameter `pin` of a `Call` part, where
/// the call's block gives a value back: `Output` or `InOut`.
fn call_output<'a>(part: Node<'a, '_>, pin: &str) -> Option<(&'a str, &'a str)> {
    if !part.has_tag_name("Call") {
        return None;
    }
    child(part, "CallInfo")?
        .children()
        .filter(|p| p.has_tag_name("Parameter"))
        .find(|p| p.attribute("Name") == Some(pin))
        .and_then(|p| Some((p.attribute("Section")?, p.attribute("Type").unwrap_or(""))))
        .filter(|(section, _)| matches!(*section, "Output" | "InOut"))
}

fn uid(node: Node<'_, '_>) -> Option<u64> {
    node.attribute("UId").and_then(|v| v.parse().ok())
}

/// Whether part `node` has `<Negated Name="pin"/>`.
fn negated(node: Node<'_, '_>, pin: &str) -> bool {
    node.children()
        .any(|c| c.has_tag_name("Negated") && c.attribute("Name") == Some(pin))
}

impl<'a, 'i> Network<'a, 'i> {
    /// A reader over `flgnet` (the `FlgNet` element).
    pub(super) fn new(
        origin: &'a str,
        doc: &'a Document<'i>,
        place: &'a Place,
        flgnet: Node<'a, 'i>,
    ) -> Self {
        let mut n = Network {
            origin,
            doc,
            place,
            parts: HashMap::new(),
            wires: HashMap::new(),
            memo: HashMap::new(),
            consumers: HashMap::new(),
            relays: Vec::new(),
            errors: Vec::new(),
        };
        for part in child(flgnet, "Parts")
            .into_iter()
            .flat_map(|p| p.children())
            .filter(Node::is_element)
        {
            if let Some(id) = uid(part) {
                n.parts.entry(id).or_insert(part);
            }
        }
        for wire in child(flgnet, "Wires")
            .into_iter()
            .flat_map(|w| w.children())
            .filter(|w| w.has_tag_name("Wire"))
        {
            let (mut outputs, mut inputs) = (Vec::new(), 0);
            for end in wire.children().filter(Node::is_element) {
                let pin = match end.tag_name().name() {
                    "NameCon" => end.attribute("Name").unwrap_or("").to_string(),
                    "IdentCon" => String::new(),
                    _ => continue,
                };
                let Some(id) = uid(end) else {
                    continue;
                };
                if !n.parts.contains_key(&id) {
                    let name = wire.attribute("UId").unwrap_or("?");
                    n.error(
                        end,
                        format!("wire {name} names part {id}, which is not in this network"),
                    );
                    continue;
                }
                if end.has_tag_name("NameCon") {
                    let call = n.parts.get(&id).and_then(|p| call_output(*p, &pin));
                    if is_output(&pin) || call.is_some() {
                        outputs.push((id, pin.clone()));
                    } else if n.parts.get(&id).is_some_and(|p| reads_logic(*p)) {
                        inputs += 1;
                    }
                }
                n.wires.entry((id, pin)).or_default().push(wire);
            }
            for pin in outputs {
                *n.consumers.entry(pin).or_default() += inputs;
            }
        }
        n
    }

    fn error(&mut self, node: Node<'_, '_>, message: String) {
        let at = at(self.doc, node);
        let message = format!("{}: {message}", self.place);
        self.errors.push(SourceError::new(self.origin, at, message));
    }

    fn opaque(&self, node: Node<'_, '_>, why: String) -> Flow {
        Flow::Opaque(format!("{}: {why}", self.place), at(self.doc, node))
    }

    fn part_name(node: Node<'_, '_>) -> String {
        match node.tag_name().name() {
            "Part" => node.attribute("Name").unwrap_or("?").to_string(),
            "Call" => format!(
                "call of {}",
                child(node, "CallInfo")
                    .and_then(|c| c.attribute("Name"))
                    .unwrap_or("?")
            ),
            other => other.to_string(),
        }
    }

    /// What flows into pin `pin` of part `id`: the OR of the sources its
    /// wires join; `None` when nothing feeds it.
    fn sources(&mut self, id: u64, pin: &str, depth: usize) -> Option<Flow> {
        let wires = self.wires.get(&(id, pin.to_string()))?.clone();
        let mut branches = Vec::new();
        for wire in wires {
            for end in wire.children().filter(Node::is_element) {
                // A part the network does not have: said where it is named.
                let other = uid(end).filter(|u| self.parts.contains_key(u));
                match end.tag_name().name() {
                    "Powerrail" => branches.push(Flow::True),
                    "IdentCon" => {
                        if let Some(other) = other {
                            branches.push(self.operand_flow(other, end));
                        }
                    }
                    "NameCon" => {
                        let name = end.attribute("Name").unwrap_or("");
                        if other == Some(id) && name == pin {
                            continue;
                        }
                        let from_call = |o: &u64| {
                            self.parts
                                .get(o)
                                .is_some_and(|p| call_output(*p, name).is_some())
                        };
                        if let Some(other) = other.filter(|o| is_output(name) || from_call(o)) {
                            branches.push(self.output(other, name, end, depth + 1));
                        }
                    }
                    _ => {}
                }
            }
        }
        (!branches.is_empty()).then(|| Flow::or(branches))
    }

    /// What flows into `pin` of `node`, perhaps negated there.
    fn input(&mut self, node: Node<'a, 'i>, pin: &str, depth: usize) -> Flow {
        let id = uid(node).unwrap_or(0);
        match self.sources(id, pin, depth) {
            Some(f) if negated(node, pin) => f.not(),
            Some(f) => f,
            None => self.opaque(
                node,
                format!(
                    "part '{}' has nothing wired to '{pin}'",
                    Self::part_name(node)
                ),
            ),
        }
    }

    /// What the operand wired to `pin` of `node` reads.
    fn operand_of(&mut self, node: Node<'a, 'i>, pin: &str) -> Option<(Value, Node<'a, 'i>)> {
        let id = uid(node)?;
        let wires = self.wires.get(&(id, pin.to_string()))?.clone();
        let access = wires
            .iter()
            .flat_map(|w| w.children())
            .filter(|e| e.has_tag_name("IdentCon"))
            .find_map(|e| uid(e).and_then(|u| self.parts.get(&u).copied()))?;
        Some((self.value(access), access))
    }

    /// What an `Access` reads.
    fn value(&self, access: Node<'_, '_>) -> Value {
        if !access.has_tag_name("Access") {
            return Value::Other(format!("'{}' is not an operand", Self::part_name(access)));
        }
        let scope = access.attribute("Scope").unwrap_or("");
        if let Some(constant) = child(access, "Constant") {
            if let Some(name) = constant.attribute("Name") {
                return Value::Other(format!("named constant '{name}'"));
            }
            let value = child(constant, "ConstantValue")
                .map(text_of)
                .unwrap_or_default();
            let bare = value.rsplit('#').next().unwrap_or("").trim();
            return match bare.to_ascii_uppercase().as_str() {
                "TRUE" | "1" if value.to_ascii_uppercase().starts_with("BOOL#") => {
                    Value::Bool(true)
                }
                "FALSE" | "0" if value.to_ascii_uppercase().starts_with("BOOL#") => {
                    Value::Bool(false)
                }
                "TRUE" => Value::Bool(true),
                "FALSE" => Value::Bool(false),
                _ if !value.contains('#') && value.trim().parse::<f64>().is_ok() => {
                    Value::Number(value.trim().to_string())
                }
                _ => Value::Other(format!("constant '{}'", value.trim())),
            };
        }
        match access_signal(self.place, scope, access) {
            Ok((signal, true)) => Value::Var(signal),
            Ok((signal, false)) => Value::Word(signal),
            Err(why) => Value::Other(why.to_string()),
        }
    }

    /// An operand as a source of power (FBD: a tag wired to a box input).
    fn operand_flow(&mut self, id: u64, end: Node<'_, '_>) -> Flow {
        let Some(access) = self.parts.get(&id).copied() else {
            self.error(
                end,
                format!("wire to part {id}, which this network does not have"),
            );
            return Flow::True;
        };
        match self.value(access) {
            Value::Var(s) => Flow::Lit(s, false, id),
            Value::Bool(b) => {
                if b {
                    Flow::True
                } else {
                    Flow::False
                }
            }
            Value::Word(s) => self.opaque(access, format!("'{s}' is not a bit")),
            Value::Number(n) => self.opaque(access, format!("the number {n} is not a bit")),
            Value::Other(why) => self.opaque(access, why),
        }
    }

    /// What flows out of pin `pin` of part `id`.
    fn output(&mut self, id: u64, pin: &str, from: Node<'_, '_>, depth: usize) -> Flow {
        let key = (id, pin.to_string());
        if let Some(f) = self.memo.get(&key) {
            return f.clone();
        }
        let Some(node) = self.parts.get(&id).copied() else {
            self.error(
                from,
                format!("wire to part {id}, which this network does not have"),
            );
            return Flow::True;
        };
        if depth > MAX_DEPTH {
            self.error(
                node,
                format!("the network chains deeper than {MAX_DEPTH} parts, or loops"),
            );
            return Flow::True;
        }
        // Guards a loop in the graph while this part is being read.
        let looped = self.opaque(node, "the network loops back".into());
        self.memo.insert(key.clone(), looped);
        let flow = self.part(node, pin, depth);
        let flow = if negated(node, pin) { flow.not() } else { flow };
        let flow = self.shared(node, pin, flow);
        self.memo.insert(key, flow.clone());
        flow
    }

    /// The flow out of `pin` of a box (`A`, `O`, `X`, `Not`) that feeds
    /// several inputs: written once into a relay named after the block,
    /// network and part (`#Conveyor.NW3.A25`), which each input reads.
    fn shared(&mut self, node: Node<'a, 'i>, pin: &str, flow: Flow) -> Flow {
        let id = uid(node).unwrap_or(0);
        let name = node.attribute("Name").unwrap_or("");
        let shared_box = node.has_tag_name("Part")
            && matches!(name, "A" | "O" | "X" | "Not" | "NOT")
            && self
                .consumers
                .get(&(id, pin.to_string()))
                .is_some_and(|&n| n > 1);
        if !shared_box {
            return flow;
        }
        let relay = Signal::new(&format!(
            "#{}.NW{}.{name}{id}",
            self.place.block, self.place.network
        ));
        let here = at(self.doc, node);
        shared(flow, relay, id, here, "=", &mut self.relays)
    }

    /// What flows out of `pin` of `node`.
    fn part(&mut self, node: Node<'a, 'i>, pin: &str, depth: usize) -> Flow {
        let id = uid(node).unwrap_or(0);
        if let Some((_, ty)) = call_output(node, pin) {
            return self.call_output_flow(node, pin, ty, id);
        }
        if !node.has_tag_name("Part") {
            return self.opaque(
                node,
                format!("output '{pin}' of {} is not read", Self::part_name(node)),
            );
        }
        let name = node.attribute("Name").unwrap_or("?");
        match name {
            "Contact" => {
                let input = self.input(node, "in", depth);
                let operand = self.contact_operand(node);
                Flow::and(vec![input, operand])
            }
            // Power passes through a coil and an S/R coil.
            "Coil" | "SCoil" | "RCoil" => self.input(node, "in", depth),
            "Not" | "NOT" => self.input(node, "in", depth).not(),
            "Sr" | "Rs" => match self.operand_of(node, "operand") {
                Some((Value::Var(s), _)) => Flow::Lit(s, false, id),
                _ => self.opaque(node, format!("part '{name}' without a bit to latch")),
            },
            "A" | "O" | "X" => {
                let mut inputs = Vec::new();
                let mut n = 1;
                while self.wires.contains_key(&(id, format!("in{n}"))) {
                    inputs.push(self.input(node, &format!("in{n}"), depth));
                    n += 1;
                }
                if inputs.is_empty() {
                    return self.opaque(node, format!("box '{name}' has no input wired"));
                }
                match name {
                    "A" => Flow::and(inputs),
                    "O" => Flow::or(inputs),
                    _ => {
                        let mut it = inputs.into_iter();
                        let first = it.next().unwrap_or(Flow::False);
                        it.fold(first, Flow::xor)
                    }
                }
            }
            "Eq" | "Ne" | "Gt" | "Ge" | "Lt" | "Le" => self.comparator(node, name, depth),
            "TON" | "TOF" | "TP" | "TONR" | "CTU" | "CTD" | "CTUD" => {
                let upper = pin.to_ascii_uppercase();
                if !matches!(upper.as_str(), "Q" | "QU" | "QD") {
                    return self.opaque(
                        node,
                        format!("output '{pin}' of {name} is a number, not a bit"),
                    );
                }
                let instance = child(node, "Instance")
                    .map(|i| access_signal(self.place, i.attribute("Scope").unwrap_or(""), i));
                match instance {
                    Some(Ok((s, _))) => {
                        Flow::Lit(Signal::new(&format!("{}.{upper}", s.name())), false, id)
                    }
                    Some(Err(why)) => self.opaque(node, why.to_string()),
                    None => self.opaque(node, format!("{name} without an instance")),
                }
            }
            "PContact" | "NContact" | "PBox" | "NBox" | "PCoil" | "NCoil" | "R_TRIG" | "F_TRIG" => {
                let on = match self
                    .operand_of(node, "operand")
                    .or_else(|| self.operand_of(node, "bit"))
                {
                    Some((Value::Var(s), _)) => format!(" on '{s}'"),
                    _ => String::new(),
                };
                self.opaque(
                    node,
                    format!("edge '{name}'{on} (a pulse, not a function of the signals)"),
                )
            }
            other => self.opaque(
                node,
                format!("output '{pin}' of part '{other}' is not read"),
            ),
        }
    }

    /// Output `pin` of a function block call: the instance's member
    /// (`Motor_DB.Running`, `Line.#Motor.Running`), a leaf the block's own
    /// logic writes. A function (FC) has no instance: its output is not
    /// derivable.
    fn call_output_flow(&mut self, node: Node<'a, 'i>, pin: &str, ty: &str, id: u64) -> Flow {
        let name = Self::part_name(node);
        if !ty.eq_ignore_ascii_case("Bool") {
            return self.opaque(
                node,
                format!("output '{pin}' of {name} is a {ty}, not a bit"),
            );
        }
        let instance = child(node, "CallInfo")
            .and_then(|c| child(c, "Instance"))
            .map(|i| access_signal(self.place, i.attribute("Scope").unwrap_or(""), i));
        match instance {
            Some(Ok((s, _))) => Flow::Lit(Signal::new(&format!("{}.{pin}", s.name())), false, id),
            Some(Err(why)) => self.opaque(node, why.to_string()),
            None => self.opaque(
                node,
                format!("output '{pin}' of {name}, a function without an instance"),
            ),
        }
    }

    /// The operands a call's Bool outputs are wired to, each written with
    /// the output (`#Open := "Valve_DB".Open`), when the call runs: every
    /// scan when its `en` is powered, else not derivable. A number output
    /// writes no bit.
    fn call_assignments(&mut self, part: Node<'a, 'i>, out: &mut Vec<Instruction>) {
        let Some(id) = uid(part) else {
            return;
        };
        let here = at(self.doc, part);
        let pins: Vec<String> = child(part, "CallInfo")
            .into_iter()
            .flat_map(|c| c.children())
            .filter(|p| p.has_tag_name("Parameter"))
            .filter_map(|p| p.attribute("Name"))
            .filter(|pin| {
                call_output(part, pin).is_some_and(|(_, ty)| ty.eq_ignore_ascii_case("Bool"))
            })
            .map(str::to_string)
            .collect();
        for pin in pins {
            let Some((Value::Var(target), _)) = self.operand_of(part, &pin) else {
                continue;
            };
            let value = self.part(part, &pin, 0);
            let runs = match self.sources(id, "en", 0) {
                None | Some(Flow::True) => Flow::True,
                Some(_) => self.opaque(
                    part,
                    format!(
                        "{} runs only while its 'en' is on, so '{target}' may not be written every scan",
                        Self::part_name(part)
                    ),
                ),
            };
            out.append(&mut self.relays);
            emit(&Flow::and(vec![runs, value]), here, out);
            out.push(write(
                here,
                Operation::Write { negated: false },
                "=",
                target,
            ));
        }
    }

    /// A contact's operand: a literal, perhaps negated.
    fn contact_operand(&mut self, node: Node<'a, 'i>) -> Flow {
        let id = uid(node).unwrap_or(0);
        let negated = negated(node, "operand");
        match self.operand_of(node, "operand") {
            Some((Value::Var(s), _)) => Flow::Lit(s, negated, id),
            Some((Value::Bool(b), _)) => {
                if b != negated {
                    Flow::True
                } else {
                    Flow::False
                }
            }
            Some((Value::Word(s), _)) => self.opaque(node, format!("contact on '{s}', not a bit")),
            Some((Value::Number(n), _)) => self.opaque(node, format!("contact on the number {n}")),
            Some((Value::Other(why), _)) => self.opaque(node, format!("contact on {why}")),
            None => self.opaque(node, "contact without an operand".into()),
        }
    }

    /// A comparator: `in1 OP in2` as a comparison contact, ANDed with the
    /// power on `pre` (LAD; FBD has none).
    fn comparator(&mut self, node: Node<'a, 'i>, name: &str, depth: usize) -> Flow {
        let id = uid(node).unwrap_or(0);
        let op = match name {
            "Eq" => CmpOp::Eq,
            "Ne" => CmpOp::Ne,
            "Gt" => CmpOp::Gt,
            "Ge" => CmpOp::Ge,
            "Lt" => CmpOp::Lt,
            _ => CmpOp::Le,
        };
        let pre = match self.sources(id, "pre", depth) {
            Some(f) => f,
            None => Flow::True,
        };
        let side = |v: Option<(Value, Node)>| match v {
            Some((Value::Var(s) | Value::Word(s), _)) if !s.name().contains(' ') => {
                Some((s.name().to_string(), false))
            }
            Some((Value::Number(n), _)) => Some((n, true)),
            _ => None,
        };
        let a = self.operand_of(node, "in1");
        let b = self.operand_of(node, "in2");
        // A comparison contact is written `LHS OP RHS`: a name with a
        // space in it (a block or DB named `Program Logic`) cannot stand in
        // one, and is said as such.
        let spaced = [&a, &b].into_iter().find_map(|v| match v {
            Some((Value::Var(s) | Value::Word(s), _)) if s.name().contains(' ') => {
                Some(s.name().to_string())
            }
            _ => None,
        });
        if let Some(spaced) = spaced {
            return self.opaque(
                node,
                format!(
                    "comparator '{name}' of '{spaced}', a name with a space, which a comparison contact cannot name"
                ),
            );
        }
        let (lhs, op, rhs) = match (side(a), side(b)) {
            (Some((l, false)), Some((r, _))) => (l, op, r),
            // `80 < TEMP` is `TEMP > 80`.
            (Some((l, true)), Some((r, false))) => {
                let flipped = match op {
                    CmpOp::Gt => CmpOp::Lt,
                    CmpOp::Ge => CmpOp::Le,
                    CmpOp::Lt => CmpOp::Gt,
                    CmpOp::Le => CmpOp::Ge,
                    other => other,
                };
                (r, flipped, l)
            }
            _ => {
                return self.opaque(
                    node,
                    format!(
                    "comparator '{name}' of operands that are not a tag and a number or two tags"
                ),
                )
            }
        };
        let signal = Comparison {
            lhs: Signal::new(&lhs),
            op,
            rhs: crate::value::operand(&rhs),
        }
        .signal();
        Flow::and(vec![pre, Flow::Lit(signal, false, id)])
    }

    /// Every coil of the network, in the order of its parts, as
    /// instructions; parts that are not read as warnings.
    pub(super) fn read(mut self) -> (Vec<Instruction>, Vec<SourceError>) {
        let mut out = Vec::new();
        let mut parts: Vec<Node> = self.parts.values().copied().collect();
        parts.sort_by_key(|n| n.range().start);
        for part in parts {
            let here = at(self.doc, part);
            let name = part.attribute("Name").unwrap_or("");
            match (part.tag_name().name(), name) {
                ("Access", _) => {}
                ("Part", "Coil" | "SCoil" | "RCoil") => {
                    let Some(target) = self.coil_target(part) else {
                        continue;
                    };
                    let flow = self.input(part, "in", 0);
                    out.append(&mut self.relays);
                    emit(&flow, here, &mut out);
                    let (operation, mnemonic) = match name {
                        "SCoil" => (Operation::Set, "S"),
                        "RCoil" => (Operation::Reset, "R"),
                        _ if negated(part, "operand") => (Operation::Write { negated: true }, "=N"),
                        _ => (Operation::Write { negated: false }, "="),
                    };
                    out.push(write(here, operation, mnemonic, target));
                }
                ("Part", "Sr" | "Rs") => {
                    let Some(target) = self.coil_target(part) else {
                        continue;
                    };
                    // The input that wins comes last.
                    let order: [(&str, Operation, &str); 2] = if name == "Sr" {
                        [("s", Operation::Set, "S"), ("r1", Operation::Reset, "R")]
                    } else {
                        [("r", Operation::Reset, "R"), ("s1", Operation::Set, "S")]
                    };
                    for (pin, operation, mnemonic) in order {
                        let flow = self.input(part, pin, 0);
                        out.append(&mut self.relays);
                        emit(&flow, here, &mut out);
                        out.push(write(here, operation, mnemonic, target.clone()));
                    }
                }
                (
                    "Part",
                    "Contact" | "O" | "A" | "X" | "Not" | "NOT" | "Eq" | "Ne" | "Gt" | "Ge" | "Lt"
                    | "Le" | "TON" | "TOF" | "TP" | "TONR" | "CTU" | "CTD" | "CTUD" | "PContact"
                    | "NContact" | "PBox" | "NBox",
                ) => {}
                _ => {
                    if part.has_tag_name("Call") {
                        self.call_assignments(part, &mut out);
                    }
                    let what = match part.tag_name().name() {
                        "Part" => format!("part '{name}'"),
                        _ => Self::part_name(part),
                    };
                    let text = format!("{}: {what} is not read", self.place);
                    out.push(Instruction::bare(
                        here,
                        text,
                        what,
                        Operation::Outside(Outside::Unread),
                    ));
                }
            }
        }
        self.errors.sort_by_key(|e| e.at);
        (out, self.errors)
    }

    /// The bit a coil or latch box writes; an error at it when there is
    /// none.
    fn coil_target(&mut self, part: Node<'a, 'i>) -> Option<Signal> {
        let name = part.attribute("Name").unwrap_or("?").to_string();
        match self.operand_of(part, "operand") {
            Some((Value::Var(s), _)) => Some(s),
            Some((Value::Word(s), _)) => {
                self.error(part, format!("{name} on '{s}', which is not a bit"));
                None
            }
            Some((Value::Other(why), _)) => {
                self.error(part, format!("{name} on {why}"));
                None
            }
            Some((Value::Bool(_) | Value::Number(_), _)) => {
                self.error(part, format!("{name} on a constant"));
                None
            }
            None => {
                self.error(part, format!("{name} without an operand"));
                None
            }
        }
    }
}

/// A write of `target` at `at`.
fn write(at: Location, operation: Operation, mnemonic: &str, target: Signal) -> Instruction {
    Instruction {
        at,
        text: format!("{mnemonic} {target}"),
        mnemonic: mnemonic.to_string(),
        operation,
        operand: Some(Operand::Signal(target)),
        operand_at: at,
    }
}
