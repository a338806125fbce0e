//! Tags: what each reads and how it is written, and how addresses are read.

use std::time::Duration;

use cellwatch_models::expr::Expr;
use cellwatch_models::machinery::StateMachine;
use cellwatch_models::programs::Dialect;
use cellwatch_models::signal::{AddressError, Signal};
use cellwatch_models::value::{CmpOperand, Comparison, ValueType};

/// A tag: a node on the server and the PLC address the models use.
#[derive(Debug, Clone, PartialEq)]
pub struct TagConfig {
    /// Plant name.
    pub name: String,
    /// OPC UA node id (`nsu=urn:plc;s=X0.06` or `ns=2;s=X0.06`), as written.
    pub node_id: String,
    /// PLC address (`X0.06`).
    pub address: Signal,
    /// Comment.
    pub comment: Option<String>,
    /// The node's data type (`type`, default Boolean).
    pub value_type: ValueType,
    /// One bit of an integer word (`bit = 7`): the tag is that contact.
    pub bit: Option<u8>,
    /// Sampling interval for this tag, instead of `opcua.sampling_interval`.
    pub sampling_interval: Option<Duration>,
    /// Data-change filter deadband for this tag.
    pub deadband: Option<Deadband>,
    /// Export the value as the `cellwatch_tag_value` gauge.
    pub export: bool,
    /// The largest value of a counter before it wraps to 0 (default: the
    /// type's maximum).
    pub max: Option<u64>,
    /// The node is the `CurrentState/Id` of this state machine of OPC UA
    /// for Machinery (`states`): read as the state's number (a `UInt32`).
    pub states: Option<StateMachine>,
}

impl TagConfig {
    /// A Boolean tag with defaults for everything else.
    pub fn boolean(name: &str, node_id: &str, address: Signal) -> TagConfig {
        TagConfig {
            name: name.into(),
            node_id: node_id.into(),
            address,
            comment: None,
            value_type: ValueType::Boolean,
            bit: None,
            sampling_interval: None,
            deadband: None,
            export: false,
            max: None,
            states: None,
        }
    }

    /// Whether the tag is a contact (a Boolean, or one bit of a word).
    pub fn is_contact(&self) -> bool {
        self.value_type == ValueType::Boolean || self.bit.is_some()
    }

    /// How the tag is used, for messages: `Boolean`, `bit 7 of a UInt16`.
    pub fn usage(&self) -> String {
        match self.bit {
            Some(b) => format!("bit {b} of a {}", self.value_type),
            None => self.value_type.to_string(),
        }
    }
}

/// The OPC UA data-change filter's deadband: a change smaller than this is
/// not reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Deadband {
    /// In the tag's unit.
    Absolute(f64),
    /// In percent of the node's `EURange`.
    Percent(f64),
}

/// The tag a timer model's signal names: by tag name, else by address.
pub fn timer_signal(addressing: Addressing, tags: &[TagConfig], name: &str) -> Option<Signal> {
    tags.iter()
        .find(|t| t.name == name)
        .or_else(|| {
            addressing
                .signal(name)
                .ok()
                .and_then(|a| tags.iter().find(|t| t.address == a))
        })
        .map(|t| t.address.clone())
}

/// Whether `id` can be a chunk of a Zenoh key and part of a file name as
/// it is: not empty, letters and digits (of any script), `-` and `_` only
/// (no `/`, no wildcard, no `.` that `CHART.STEP` would split, no space or
/// control character).
pub fn key_chunk(id: &str) -> bool {
    !id.is_empty()
        && id
            .chars()
            .all(|c| c.is_alphanumeric() || c == '-' || c == '_')
}

/// A tag's PLC address: a PMC address (`X0.06`), an IEC direct address
/// (`%IX0.0.3`) or an IEC symbol (`Start`).
///
/// # Errors
/// [`AddressError`] quoting the text, when it is none of these.
pub fn tag_address(text: &str) -> Result<Signal, AddressError> {
    if text.starts_with('%') {
        return Dialect::Iec.signal(text);
    }
    Dialect::Pmc
        .signal(text)
        .or_else(|_| Dialect::Iec.signal(text))
}

/// How a cell's tag addresses, and the conditions over them, are written:
/// in its PLC's dialect (`cell.dialect`), or by default a PMC address or an
/// IEC address or name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addressing {
    /// A PMC address (`X0.07`, `D100`), else an IEC direct address or name.
    PmcOrIec,
    /// The PLC's own dialect only: `pmc` (or a plain name), `iec`, `stl`
    /// (`E 0.0`, `MW 10`, `"Start"`, `Band.#Reset`, or a plain name).
    In(Dialect),
}

impl Addressing {
    /// The canonical signal for a tag address written in the cell's
    /// configuration.
    ///
    /// # Errors
    /// [`AddressError`] quoting the malformed address.
    pub fn signal(self, text: &str) -> Result<Signal, AddressError> {
        match self {
            Addressing::PmcOrIec => tag_address(text),
            Addressing::In(Dialect::Iec) => Dialect::Iec.tag_signal(text),
            // A plain name (`Temperatur`) is a symbol in any dialect.
            Addressing::In(d) => d.tag_signal(text).or_else(|e| {
                if text.starts_with('%') {
                    return Err(e);
                }
                Dialect::Iec.tag_signal(text).map_err(|_| e)
            }),
        }
    }
}

/// The expression with its addresses in canonical form (`x0.6` → `X0.06`).
pub(crate) fn canonical_expr(addressing: Addressing, e: Expr) -> Expr {
    map_signals(e, &|s| {
        addressing.signal(s.name()).unwrap_or_else(|_| s.clone())
    })
}

/// `e` with every signal it reads (both sides of a comparison) put
/// through `f`.
pub(crate) fn map_signals(e: Expr, f: &dyn Fn(&Signal) -> Signal) -> Expr {
    match e {
        Expr::Lit(s, n) => match Comparison::of_signal(&s) {
            Some(mut c) => {
                c.lhs = f(&c.lhs);
                if let CmpOperand::Tag(t) = &c.rhs {
                    c.rhs = CmpOperand::Tag(f(t));
                }
                Expr::Lit(c.signal(), n)
            }
            None => Expr::Lit(f(&s), n),
        },
        Expr::Not(inner) => Expr::Not(Box::new(map_signals(*inner, f))),
        Expr::And(es) => Expr::And(es.into_iter().map(|e| map_signals(e, f)).collect()),
        Expr::Or(es) => Expr::Or(es.into_iter().map(|e| map_signals(e, f)).collect()),
        c @ Expr::Const(_) => c,
    }
}
