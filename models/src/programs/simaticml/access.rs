//! The parts of a SimaticML document both the block reader and the
//! network reader use: a network's place in messages, an element's
//! location and text, and the signal an operand (`Access`) names, or why
//! it names none ([`AccessError`]).

use std::fmt;

use roxmltree::{Document, Node};

use crate::signal::Signal;
use crate::source::Location;

/// A network of a block, as messages name it.
#[derive(Debug, Clone)]
pub(super) struct Place {
    pub(super) block: String,
    pub(super) network: usize,
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "block \"{}\" network {}", self.block, self.network)
    }
}

/// Where `node` starts in the document.
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

/// Why an operand (`Access`) names no signal the reader can use.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(super) enum AccessError {
    /// A component indexed or sliced, known only at run time.
    #[error("indexed or sliced access '{name}' (known only at run time)")]
    Indexed {
        /// The component's name.
        name: String,
    },
    /// A symbol, or one of its components, without a name.
    #[error("a symbol without a name")]
    Unnamed,
    /// An absolute address in an area the reader does not know.
    #[error("address in area '{area}'")]
    Area {
        /// The `Area` attribute as written.
        area: String,
    },
    /// An absolute address without a readable `BitOffset`.
    #[error("an address without a bit offset")]
    NoBitOffset,
    /// An operand with neither a symbol nor an address.
    #[error("an operand without a symbol or an address")]
    Empty,
}

/// The signal an `Access` (or a part's `Instance`) names, and whether it
/// may be a bit (`false`: a word or byte address).
///
/// # Errors
/// [`AccessError`]: why it is not read, such as an indexed or sliced
/// access or an unknown area.
pub(super) fn access_signal(
    place: &Place,
    scope: &str,
    access: Node<'_, '_>,
) -> Result<(Signal, bool), AccessError> {
    // A part's `Instance` holds its components itself.
    let symbol = child(access, "Symbol").or_else(|| {
        (access.has_tag_name("Instance") && child(access, "Component").is_some()).then_some(access)
    });
    if let Some(symbol) = symbol {
        let mut names = Vec::new();
        for c in symbol.children().filter(|c| c.has_tag_name("Component")) {
            let name = c.attribute("Name").unwrap_or("");
            let indexed = c.children().any(|i| i.is_element())
                || c.attributes()
                    .any(|a| a.name().ends_with("AccessModifier") && a.value() != "None");
            if indexed {
                return Err(AccessError::Indexed { name: name.into() });
            }
            if name.is_empty() {
                return Err(AccessError::Unnamed);
            }
            names.push(name);
        }
        if names.is_empty() {
            return Err(AccessError::Unnamed);
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
            other => return Err(AccessError::Area { area: other.into() }),
        };
        let offset: u64 = address
            .attribute("BitOffset")
            .and_then(|b| b.parse().ok())
            .ok_or(AccessError::NoBitOffset)?;
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
    Err(AccessError::Empty)
}
