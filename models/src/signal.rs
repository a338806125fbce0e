//! PLC signals: their names, address classes and which of them are observable.
//!
//! A [`Signal`] is one boolean in the PLC's memory, named by its canonical
//! address (`X0.07`, `%IX0.0.3`) or symbol (`Start`, `T1.Q`). This module
//! parses and canonicalises addresses for both dialects and decides which
//! signals a switching function may stop at ([`Observability`]), and owns
//! [`AddressError`], the error of every dialect's address reader. It knows
//! nothing of programs.

use std::fmt;
use std::sync::Arc;

pub use crate::programs::{class_of, Observability};

/// One boolean PLC signal, by canonical name.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Signal(Arc<str>);

impl Signal {
    /// A signal with this exact (already canonical) name.
    pub fn new(name: &str) -> Self {
        Signal(Arc::from(name))
    }

    /// The canonical name.
    pub fn name(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for Signal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl serde::Serialize for Signal {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.0)
    }
}

/// An address or an address class written wrong, in any dialect; each
/// variant quotes the text as written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AddressError {
    /// A PMC address that does not start with its class letters.
    #[error(
        "malformed address '{text}': it must start with a signal class letter (X, Y, R, F, G, ...)"
    )]
    PmcClass {
        /// The address as written.
        text: String,
    },
    /// A PMC address with no decimal byte number after its class.
    #[error("malformed address '{text}': expected a decimal byte number after '{class}'")]
    PmcByte {
        /// The address as written.
        text: String,
        /// The class letters read, upper case.
        class: String,
    },
    /// A PMC address whose byte number does not fit 32 bits.
    #[error("malformed address '{text}': byte number too large")]
    PmcByteTooLarge {
        /// The address as written.
        text: String,
    },
    /// A PMC address whose bit is not one hex digit 0..F.
    #[error(
        "malformed address '{text}': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)"
    )]
    PmcBit {
        /// The address as written.
        text: String,
    },
    /// An IEC direct address in no area (`%I`, `%Q`, `%M`).
    #[error("malformed address '{text}': a direct address starts with %I, %Q or %M")]
    IecArea {
        /// The address as written.
        text: String,
    },
    /// An IEC direct address without its numbers after the area.
    #[error(
        "malformed address '{text}': expected numbers separated by '.' after the area, as in %IX0.0.3"
    )]
    IecNumbers {
        /// The address as written.
        text: String,
    },
    /// An IEC operand that is neither a direct address nor a name.
    #[error("malformed operand '{text}': expected a direct address (%IX0.0) or a name")]
    IecOperand {
        /// The operand as written.
        text: String,
    },
    /// An STL block's local named through a block that is no block name.
    #[error("malformed block name in '{text}': expected \"name\".#local or FB 10.#local")]
    StlBlockName {
        /// The operand as written.
        text: String,
    },
    /// An STL member of a global data block written wrong.
    #[error("malformed member {text}: expected \"DB\".member")]
    StlMember {
        /// The operand as written.
        text: String,
    },
    /// An STL symbol with its quotes unbalanced or nothing inside them.
    #[error("malformed symbol {text}: expected \"name\"")]
    StlSymbol {
        /// The operand as written.
        text: String,
    },
    /// An STL local (`#name`) with an empty or unreadable part.
    #[error("malformed local name '{text}'")]
    StlLocal {
        /// The operand as written.
        text: String,
    },
    /// An STL operand that is no address, symbol or local.
    #[error(
        "malformed operand '{text}': expected an address (E 0.0, A 4.0, M 10.1), a \"symbol\" or a #local"
    )]
    StlOperand {
        /// The operand as written.
        text: String,
    },
    /// An STL bit address without `byte.bit`, or with a bit past 7.
    #[error("malformed address '{text}': expected byte.bit with a bit 0..7, as in {area} 0.0")]
    StlBit {
        /// The address as written.
        text: String,
        /// Its area (`E`, `M`, `DBX`), upper case.
        area: String,
    },
    /// An STL operand that is well formed but not a bit (`MW 10`, `5`).
    #[error("'{text}' is not a bit address (E 0.0, A 4.0, M 10.1)")]
    StlNotABit {
        /// The operand as written.
        text: String,
    },
    /// An STL tag address that is neither a bit nor a word.
    #[error("'{text}' is not an address (E 0.0, MW 10, DB1.DBW 4, \"symbol\")")]
    StlNotAnAddress {
        /// The address as written.
        text: String,
    },
    /// An IEC address class other than `%I`, `%Q` or `%M`.
    #[error("unknown address class '{text}': use %I, %Q or %M")]
    UnknownClass {
        /// The class as written.
        text: String,
    },
}

/// Parses a FANUC-PMC style address (`X0.07`, `R1024.00`, `X1`) into its
/// canonical form: class letters upper case, byte in decimal, bit as two
/// upper-case hex digits (`x0.a` → `X0.0A`).
///
/// # Errors
/// [`AddressError`] quoting the text and saying which part is wrong.
pub fn pmc_address(text: &str) -> Result<Signal, AddressError> {
    let letters = text.chars().take_while(|c| c.is_ascii_alphabetic()).count();
    if letters == 0 {
        return Err(AddressError::PmcClass { text: text.into() });
    }
    let class = text[..letters].to_ascii_uppercase();
    let rest = &text[letters..];
    let (byte, bit) = match rest.split_once('.') {
        Some((byte, bit)) => (byte, Some(bit)),
        None => (rest, None),
    };
    if byte.is_empty() || !byte.chars().all(|c| c.is_ascii_digit()) {
        return Err(AddressError::PmcByte {
            text: text.into(),
            class,
        });
    }
    let byte: u32 = byte
        .parse()
        .map_err(|_| AddressError::PmcByteTooLarge { text: text.into() })?;
    match bit {
        None => Ok(Signal::new(&format!("{class}{byte}"))),
        Some(bit) => {
            let valid =
                !bit.is_empty() && bit.len() <= 2 && bit.chars().all(|c| c.is_ascii_hexdigit());
            let value = if valid {
                u8::from_str_radix(bit, 16).ok()
            } else {
                None
            };
            match value {
                Some(v) if v <= 0x0F => Ok(Signal::new(&format!("{class}{byte}.{v:02X}"))),
                _ => Err(AddressError::PmcBit { text: text.into() }),
            }
        }
    }
}

/// Parses an IEC 61131-3 direct address (`%IX0.0.3`, `%QX1.2`, `%MX10.1`)
/// into upper case.
///
/// # Errors
/// [`AddressError`] quoting the text when it is not a direct address.
pub fn iec_direct_address(text: &str) -> Result<Signal, AddressError> {
    let upper = text.to_ascii_uppercase();
    let mut chars = upper.chars().skip(1).peekable();
    let area = chars.next();
    if !matches!(area, Some('I' | 'Q' | 'M')) {
        return Err(AddressError::IecArea { text: text.into() });
    }
    if matches!(chars.peek(), Some('X' | 'B' | 'W' | 'D' | 'L')) {
        chars.next();
    }
    let numbers: String = chars.collect();
    let ok = !numbers.is_empty()
        && numbers
            .split('.')
            .all(|n| !n.is_empty() && n.chars().all(|c| c.is_ascii_digit()));
    if !ok {
        return Err(AddressError::IecNumbers { text: text.into() });
    }
    Ok(Signal::new(&upper))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pmc_addresses_are_canonical() {
        assert_eq!(pmc_address("X0.07").unwrap().name(), "X0.07");
        assert_eq!(pmc_address("x0.a").unwrap().name(), "X0.0A");
        assert_eq!(pmc_address("R1024.00").unwrap().name(), "R1024.00");
        assert_eq!(pmc_address("X1").unwrap().name(), "X1");
        assert_eq!(pmc_address("G0008.2").unwrap().name(), "G8.02");
    }

    #[test]
    fn pmc_address_errors_quote_the_text() {
        assert_eq!(
            pmc_address("X0.0G").unwrap_err().to_string(),
            "malformed address 'X0.0G': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)"
        );
        assert!(pmc_address("X0.1F").is_err());
        assert!(pmc_address("0X1").is_err());
        assert!(pmc_address("X.1").is_err());
        assert!(pmc_address("X1.").is_err());
    }

    #[test]
    fn every_address_error_quotes_the_text() {
        use crate::programs::{Dialect, Observability};
        let cases: [(Result<Signal, AddressError>, &str); 16] = [
            (Dialect::Pmc.signal("1X"), "malformed address '1X': it must start with a signal class letter (X, Y, R, F, G, ...)"),
            (Dialect::Pmc.signal("x.1"), "malformed address 'x.1': expected a decimal byte number after 'X'"),
            (Dialect::Pmc.signal("X99999999999"), "malformed address 'X99999999999': byte number too large"),
            (Dialect::Pmc.signal("X0.10"), "malformed address 'X0.10': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)"),
            (Dialect::Iec.signal("%ZX1"), "malformed address '%ZX1': a direct address starts with %I, %Q or %M"),
            (Dialect::Iec.signal("%IX1..2"), "malformed address '%IX1..2': expected numbers separated by '.' after the area, as in %IX0.0.3"),
            (Dialect::Iec.signal("a-b"), "malformed operand 'a-b': expected a direct address (%IX0.0) or a name"),
            (Dialect::Stl.signal("\"Band.#Reset"), "malformed block name in '\"Band.#Reset': expected \"name\".#local or FB 10.#local"),
            (Dialect::Stl.signal("\"Line_DB\".Re-ady"), "malformed member \"Line_DB\".Re-ady: expected \"DB\".member"),
            (Dialect::Stl.signal("\"Start"), "malformed symbol \"Start: expected \"name\""),
            (Dialect::Stl.signal("#a..b"), "malformed local name '#a..b'"),
            (Dialect::Stl.signal("?x"), "malformed operand '?x': expected an address (E 0.0, A 4.0, M 10.1), a \"symbol\" or a #local"),
            (Dialect::Stl.signal("E 0.8"), "malformed address 'E 0.8': expected byte.bit with a bit 0..7, as in E 0.0"),
            (Dialect::Stl.signal("MW 10"), "'MW 10' is not a bit address (E 0.0, A 4.0, M 10.1)"),
            (Dialect::Stl.tag_signal("5"), "'5' is not an address (E 0.0, MW 10, DB1.DBW 4, \"symbol\")"),
            (Observability::parse(Dialect::Iec, "%I, %Z").map(|_| Signal::new("")), "unknown address class '%Z': use %I, %Q or %M"),
        ];
        for (got, want) in cases {
            assert_eq!(got.unwrap_err().to_string(), want);
        }
        assert_eq!(
            Dialect::Stl.signal("E 0.8").unwrap_err(),
            AddressError::StlBit {
                text: "E 0.8".into(),
                area: "E".into()
            }
        );
    }

    #[test]
    fn iec_addresses() {
        assert_eq!(iec_direct_address("%ix0.0.3").unwrap().name(), "%IX0.0.3");
        assert_eq!(iec_direct_address("%QX1.2").unwrap().name(), "%QX1.2");
        assert!(iec_direct_address("%ZX1").is_err());
        assert!(iec_direct_address("%IX").is_err());
        assert!(iec_direct_address("%IX1..2").is_err());
    }
}
