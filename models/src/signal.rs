//! PLC signals: their names, address classes and which of them are observable.
//!
//! A [`Signal`] is one boolean in the PLC's memory, named by its canonical
//! address (`X0.07`, `%IX0.0.3`) or symbol (`Start`, `T1.Q`). This module
//! parses and canonicalises addresses for both dialects and decides which
//! signals a switching function may stop at ([`Observability`]). It knows
//! nothing of programs.

use std::fmt;
use std::sync::Arc;

pub use crate::il::{class_of, Observability};

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

/// Parses a FANUC-PMC style address (`X0.07`, `R1024.00`, `X1`) into its
/// canonical form: class letters upper case, byte in decimal, bit as two
/// upper-case hex digits (`x0.a` → `X0.0A`).
///
/// # Errors
/// A message quoting the text and saying which part is wrong.
pub fn pmc_address(text: &str) -> Result<Signal, String> {
    let letters = text.chars().take_while(|c| c.is_ascii_alphabetic()).count();
    if letters == 0 {
        return Err(format!(
            "malformed address '{text}': it must start with a signal class letter (X, Y, R, F, G, ...)"
        ));
    }
    let class = text[..letters].to_ascii_uppercase();
    let rest = &text[letters..];
    let (byte, bit) = match rest.split_once('.') {
        Some((byte, bit)) => (byte, Some(bit)),
        None => (rest, None),
    };
    if byte.is_empty() || !byte.chars().all(|c| c.is_ascii_digit()) {
        return Err(format!(
            "malformed address '{text}': expected a decimal byte number after '{class}'"
        ));
    }
    let byte: u32 = byte
        .parse()
        .map_err(|_| format!("malformed address '{text}': byte number too large"))?;
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
                _ => Err(format!(
                    "malformed address '{text}': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)"
                )),
            }
        }
    }
}

/// Parses an IEC 61131-3 direct address (`%IX0.0.3`, `%QX1.2`, `%MX10.1`)
/// into upper case.
///
/// # Errors
/// A message quoting the text when it is not a direct address.
pub fn iec_direct_address(text: &str) -> Result<Signal, String> {
    let upper = text.to_ascii_uppercase();
    let mut chars = upper.chars().skip(1).peekable();
    let area = chars.next();
    if !matches!(area, Some('I' | 'Q' | 'M')) {
        return Err(format!(
            "malformed address '{text}': a direct address starts with %I, %Q or %M"
        ));
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
        return Err(format!(
            "malformed address '{text}': expected numbers separated by '.' after the area, as in %IX0.0.3"
        ));
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
            pmc_address("X0.0G").unwrap_err(),
            "malformed address 'X0.0G': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)"
        );
        assert!(pmc_address("X0.1F").is_err());
        assert!(pmc_address("0X1").is_err());
        assert!(pmc_address("X.1").is_err());
        assert!(pmc_address("X1.").is_err());
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
