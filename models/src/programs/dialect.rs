//! The three spellings of an instruction list, by name, and the error for
//! a name that is none of them. What each means for an address or a
//! program is in `il/mod.rs` and the dialects' own modules.

use std::fmt;
use std::str::FromStr;

/// The spelling of an instruction list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dialect {
    /// FANUC PMC mnemonics (`RD`, `AND.NOT`, `WRT`, ...) and addresses (`X0.07`).
    Pmc,
    /// IEC 61131-3 instruction list (`LD`, `ANDN`, `ST`, ...).
    Iec,
    /// Siemens STL/AWL (`U`, `UN`, `=`; `E 0.0`, or `A`, `AN`; `I 0.0`).
    Stl,
}

impl fmt::Display for Dialect {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Dialect::Pmc => "pmc",
            Dialect::Iec => "iec",
            Dialect::Stl => "stl",
        })
    }
}

/// A dialect name that is none of `pmc`, `iec`, `stl` (or `awl`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown dialect '{text}': use pmc, iec or stl")]
pub struct UnknownDialect {
    /// The name as read, lower case.
    pub text: String,
}

impl FromStr for Dialect {
    type Err = UnknownDialect;

    fn from_str(s: &str) -> Result<Self, UnknownDialect> {
        match s.to_ascii_lowercase().as_str() {
            "pmc" => Ok(Dialect::Pmc),
            "iec" => Ok(Dialect::Iec),
            "stl" | "awl" => Ok(Dialect::Stl),
            other => Err(UnknownDialect { text: other.into() }),
        }
    }
}
