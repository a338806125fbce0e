//! Signal values at one instant: a snapshot of the PLC's contacts.
//!
//! Two textual forms: inline `X0.06=0,X0.07=1` (as typed on a command line),
//! and a file with one pair a line, either `X0.06=0` or CSV `X0.06,0` (a
//! header `address,value` and `#` comment lines are allowed). Values are
//! `0`/`1`, `true`/`false` or `on`/`off`. This module parses text; it opens
//! no file.

use std::collections::HashMap;

use crate::signal::{AddressError, Signal};
use crate::source::{column, Location, SourceError};

/// Signal values, each given once.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Values {
    values: HashMap<Signal, bool>,
}

impl Values {
    /// An empty snapshot.
    pub fn new() -> Self {
        Self::default()
    }

    /// Sets one value.
    pub fn set(&mut self, signal: Signal, value: bool) {
        self.values.insert(signal, value);
    }

    /// The value of `signal`, if given.
    pub fn get(&self, signal: &Signal) -> Option<bool> {
        self.values.get(signal).copied()
    }

    /// How many signals have a value.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Whether no signal has a value.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Parses the inline form `A=1,B=0`. `origin` names it in messages
    /// (the option, `--snapshot`); `resolve` canonicalises an address (its
    /// error is the message at the pair's column).
    ///
    /// # Errors
    /// The first malformed pair, with its column.
    pub fn parse_inline(
        origin: &str,
        text: &str,
        resolve: impl Fn(&str) -> Result<Signal, AddressError>,
    ) -> Result<Values, SourceError> {
        let mut out = Values::new();
        let mut seen = HashMap::new();
        let mut offset = 0;
        for pair in text.split(',') {
            let start = offset + (pair.len() - pair.trim_start().len());
            offset += pair.len() + 1;
            if pair.trim().is_empty() {
                continue;
            }
            let at = Location {
                line: 1,
                col: column(text, start),
            };
            let (addr, value) = pair.split_once('=').ok_or_else(|| {
                SourceError::new(
                    origin,
                    at,
                    format!("malformed pair '{}': expected ADDRESS=VALUE", pair.trim()),
                )
            })?;
            let value_at = Location {
                line: 1,
                col: column(text, start + pair.trim_start().find('=').unwrap_or(0) + 1),
            };
            out.insert(origin, at, value_at, addr, value, &resolve, &mut seen)?;
        }
        Ok(out)
    }

    /// Parses a file of pairs, `A=1` or `A,1`, one a line; `resolve`
    /// canonicalises an address (its error is the message at the line).
    ///
    /// # Errors
    /// The first malformed line, as `ORIGIN:LINE:COL: message`.
    pub fn parse_file(
        origin: &str,
        text: &str,
        resolve: impl Fn(&str) -> Result<Signal, AddressError>,
    ) -> Result<Values, SourceError> {
        let mut out = Values::new();
        let mut seen = HashMap::new();
        let mut first = true;
        for (n, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let indent = raw.len() - raw.trim_start().len();
            let at = Location {
                line: n + 1,
                col: column(raw, indent),
            };
            let split = line.split_once('=').or_else(|| line.split_once(','));
            let Some((addr, value)) = split else {
                return Err(SourceError::new(
                    origin,
                    at,
                    format!("malformed line '{line}': expected ADDRESS=VALUE or ADDRESS,VALUE"),
                ));
            };
            if first && addr.trim().eq_ignore_ascii_case("address") {
                first = false;
                continue;
            }
            first = false;
            let value_at = Location {
                line: n + 1,
                col: column(raw, indent + addr.len() + 1),
            };
            out.insert(origin, at, value_at, addr, value, &resolve, &mut seen)?;
        }
        if out.is_empty() {
            return Err(SourceError::new(
                origin,
                Location::line_start(1),
                "no values: the snapshot is empty",
            ));
        }
        Ok(out)
    }

    #[allow(clippy::too_many_arguments)]
    fn insert(
        &mut self,
        origin: &str,
        at: Location,
        value_at: Location,
        addr: &str,
        value: &str,
        resolve: &impl Fn(&str) -> Result<Signal, AddressError>,
        seen: &mut HashMap<Signal, Location>,
    ) -> Result<(), SourceError> {
        let signal =
            resolve(addr.trim()).map_err(|e| SourceError::new(origin, at, e.to_string()))?;
        let v = match value.trim().to_ascii_lowercase().as_str() {
            "1" | "true" | "on" => true,
            "0" | "false" | "off" => false,
            _ => {
                return Err(SourceError::new(
                    origin,
                    value_at,
                    format!(
                        "value '{}' for {signal} is not 0, 1, true, false, on or off",
                        value.trim()
                    ),
                ))
            }
        };
        if let Some(first) = seen.insert(signal.clone(), at) {
            return Err(SourceError::new(
                origin,
                at,
                format!("{signal} is given twice (first at {first})"),
            ));
        }
        self.set(signal, v);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::pmc_address;

    #[test]
    fn inline_and_file_forms() {
        let v = Values::parse_inline("--snapshot", "X0.06=0, x0.7=1", pmc_address).unwrap();
        assert_eq!(v.get(&Signal::new("X0.06")), Some(false));
        assert_eq!(v.get(&Signal::new("X0.07")), Some(true));
        let f = Values::parse_file(
            "s.txt",
            "address,value\nX0.06,0\n# c\n  X0.07 = on\n",
            pmc_address,
        )
        .unwrap();
        assert_eq!(f, v);
    }

    #[test]
    fn bad_snapshots_are_pinned() {
        let e = Values::parse_inline("--snapshot", "X0.06=0,X0.07", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "--snapshot:1:9: malformed pair 'X0.07': expected ADDRESS=VALUE"
        );
        let e = Values::parse_file("s.txt", "X0.06=0\nX0.07 1\n", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.txt:2:1: malformed line 'X0.07 1': expected ADDRESS=VALUE or ADDRESS,VALUE"
        );
        let e = Values::parse_file("s.txt", "X0.06=2\n", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.txt:1:7: value '2' for X0.06 is not 0, 1, true, false, on or off"
        );
        let e = Values::parse_file("s.txt", "X0.06=1\nX0.6=0\n", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.txt:2:1: X0.06 is given twice (first at 1:1)"
        );
        let e = Values::parse_file("s.txt", "Q=1\n", pmc_address).unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.txt:1:1: malformed address 'Q': expected a decimal byte number after 'Q'"
        );
        let e = Values::parse_file("s.txt", "\n# only\n", pmc_address).unwrap_err();
        assert_eq!(e.to_string(), "s.txt:1:1: no values: the snapshot is empty");
    }
}
