//! Which signals a switching function stops at, per dialect.

use std::collections::BTreeSet;

use super::dialect::Dialect;
use crate::signal::{pmc_address, AddressError, Signal};

/// The address class of a signal in a dialect: `X`, `R`, ... for PMC,
/// `%I`, `%Q`, `%M` for IEC direct addresses; `None` for IEC symbols.
pub fn class_of(dialect: Dialect, signal: &Signal) -> Option<&str> {
    let name = signal.name();
    match dialect {
        Dialect::Pmc => {
            let n = name.chars().take_while(|c| c.is_ascii_alphabetic()).count();
            (n > 0).then(|| &name[..n])
        }
        Dialect::Iec => (name.starts_with('%') && name.len() >= 2).then(|| &name[..2]),
        // `E0.0` → `E`, `DB1.DBX2.3` → `DB`; symbols and locals have none.
        Dialect::Stl => {
            let n = name.chars().take_while(|c| c.is_ascii_alphabetic()).count();
            (n > 0 && name[n..].starts_with(|c: char| c.is_ascii_digit())).then(|| &name[..n])
        }
    }
}

/// Which signals a switching function is written in.
///
/// A signal is observable if its class is listed or the signal itself is.
/// Coils that are not observable are expanded into the logic that writes
/// them; observable ones stay as leaves.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Observability {
    dialect: Dialect,
    classes: BTreeSet<String>,
    signals: BTreeSet<Signal>,
}

impl Observability {
    /// The default: PMC classes X, Y, F and G; IEC inputs `%I` and outputs `%Q`.
    pub fn default_for(dialect: Dialect) -> Self {
        let classes: &[&str] = match dialect {
            Dialect::Pmc => &["X", "Y", "F", "G"],
            Dialect::Iec => &["%I", "%Q"],
            Dialect::Stl => &["E", "A", "I", "Q"],
        };
        Observability {
            dialect,
            classes: classes.iter().map(|c| c.to_string()).collect(),
            signals: BTreeSet::new(),
        }
    }

    /// Every signal observable: a coil's logic exactly as the program
    /// writes it, with no relay expanded.
    pub fn everything(dialect: Dialect) -> Self {
        Observability {
            dialect,
            classes: BTreeSet::from([String::from("*")]),
            signals: BTreeSet::new(),
        }
    }

    /// Parses a comma-separated list of classes (`X,Y,F,G` or `%I,%Q`) and
    /// signals (`R1024.00`, `Motor`).
    ///
    /// # Errors
    /// [`AddressError`] naming the malformed entry.
    pub fn parse(dialect: Dialect, list: &str) -> Result<Self, AddressError> {
        let mut classes = BTreeSet::new();
        let mut signals = BTreeSet::new();
        for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            match dialect {
                Dialect::Pmc if item.chars().all(|c| c.is_ascii_alphabetic()) => {
                    classes.insert(item.to_ascii_uppercase());
                }
                Dialect::Pmc => {
                    signals.insert(pmc_address(item)?);
                }
                Dialect::Iec if item.len() == 2 && item.starts_with('%') => {
                    let class = item.to_ascii_uppercase();
                    if !matches!(class.as_str(), "%I" | "%Q" | "%M") {
                        return Err(AddressError::UnknownClass { text: item.into() });
                    }
                    classes.insert(class);
                }
                Dialect::Iec => {
                    signals.insert(crate::programs::iec::operand_signal(item)?);
                }
                Dialect::Stl
                    if item.len() <= 3 && item.chars().all(|c| c.is_ascii_alphabetic()) =>
                {
                    classes.insert(item.to_ascii_uppercase());
                }
                Dialect::Stl => {
                    signals.insert(crate::programs::stl::operand_signal(item)?);
                }
            }
        }
        Ok(Observability {
            dialect,
            classes,
            signals,
        })
    }

    /// Whether `signal` stays a leaf of a switching function.
    pub fn is_observable(&self, signal: &Signal) -> bool {
        self.classes.contains("*")
            || self.signals.contains(signal)
            || class_of(self.dialect, signal).is_some_and(|c| self.classes.contains(c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn observability_by_class_and_signal() {
        let o = Observability::default_for(Dialect::Pmc);
        assert!(o.is_observable(&Signal::new("X0.07")));
        assert!(!o.is_observable(&Signal::new("R1")));
        let o = Observability::parse(Dialect::Pmc, "X, R1").unwrap();
        assert!(o.is_observable(&Signal::new("R1")));
        assert!(!o.is_observable(&Signal::new("Y1")));
        let o = Observability::default_for(Dialect::Iec);
        assert!(o.is_observable(&Signal::new("%IX0.0.3")));
        assert!(!o.is_observable(&Signal::new("%MX1.0")));
        assert!(!o.is_observable(&Signal::new("Motor")));
    }
}
