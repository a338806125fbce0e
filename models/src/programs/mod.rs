//! The readers of PLC programs, in every format cellwatch reads, into one
//! instruction set: instruction lists in three dialects, PLCopen XML,
//! Rockwell Studio 5000 (L5X) and TIA Portal SimaticML.
//!
//! [`parse`] turns program text into [`Instruction`]s, each with the line and
//! column it came from. The dialects differ mostly in spelling (`pmc`: the
//! FANUC PMC mnemonics of paper 000; `iec`: IEC 61131-3 IL; `stl`: Siemens
//! STL/AWL, German or English), so the lexers produce the same
//! [`Operation`]s; STL's "first check" is the compiler's business. The
//! graphical formats are read into the same instructions: PLCopen XML
//! (`plcopen`, read as IEC), Rockwell Studio 5000 exports (`l5x`) and TIA
//! Portal SimaticML (`simaticml`, read as STL). What the instructions compute is the
//! job of [`crate::program`]; this module only reads text.

pub(crate) mod iec;
pub(crate) mod l5x;
pub(crate) mod plcopen;
mod pmc;
pub mod simaticml;
pub(crate) mod stl;

mod dialect;
mod instruction;
mod observability;

pub use dialect::{Dialect, UnknownDialect};
pub(crate) use instruction::words;
pub use instruction::{Instruction, Op, Operand, Operation, Outside};
pub use observability::{class_of, Observability};

use crate::signal::{AddressError, Signal};
use crate::source::{Location, SourceError, SourceErrors};

impl Dialect {
    /// The canonical signal for an address or symbol written in this dialect.
    ///
    /// # Errors
    /// [`AddressError`] quoting a malformed address.
    pub fn signal(self, text: &str) -> Result<Signal, AddressError> {
        match self {
            Dialect::Pmc => crate::signal::pmc_address(text),
            Dialect::Iec => logix_or(iec::operand_signal(text), text),
            Dialect::Stl => symbol_or(stl::operand_signal(text), text),
        }
    }

    /// The canonical signal for a tag's address in this dialect: a bit as
    /// [`Dialect::signal`] reads it, or a word a numeric tag reads (`D100`,
    /// `%MW10`, STL `MW 10` → `MW10`).
    ///
    /// # Errors
    /// [`AddressError`] quoting a malformed address.
    pub fn tag_signal(self, text: &str) -> Result<Signal, AddressError> {
        match self {
            Dialect::Pmc => crate::signal::pmc_address(text),
            Dialect::Iec => logix_or(iec::operand_signal(text), text),
            Dialect::Stl => symbol_or(stl::tag_signal(text), text),
        }
    }

    /// Guesses the dialect from the mnemonics a program uses.
    ///
    /// Mnemonics both dialects share (`AND`, `OR`, ...) do not count; the
    /// first one that belongs to only one dialect decides.
    pub fn detect(source: &str) -> Option<Dialect> {
        for line in source.lines() {
            let line = line.trim();
            if line.starts_with("(*") {
                return Some(Dialect::Iec);
            }
            if line.starts_with("//") {
                continue;
            }
            let line = line.split(';').next().unwrap_or("");
            let mut words = line.split_whitespace();
            let Some(mut word) = words.next() else {
                continue;
            };
            if word.ends_with(':') {
                match words.next() {
                    Some(w) => word = w,
                    None => continue,
                }
            }
            let upper = word.to_ascii_uppercase();
            // `FUNCTION_BLOCK FB 1`, `FUNCTION "Pump" : VOID`: a Step 7
            // block, named by its number or a quoted symbol.
            if matches!(upper.as_str(), "FUNCTION_BLOCK" | "FUNCTION")
                && words.next().is_some_and(|name| {
                    name.starts_with('"')
                        || matches!(
                            name.to_ascii_uppercase().as_str(),
                            "FB" | "FC" | "SFB" | "SFC"
                        )
                })
            {
                return Some(Dialect::Stl);
            }
            if pmc::is_pmc_only(&upper) {
                return Some(Dialect::Pmc);
            }
            if stl::is_stl_only(&upper) {
                return Some(Dialect::Stl);
            }
            if iec::is_iec_only(&upper) || line.contains('%') {
                return Some(Dialect::Iec);
            }
        }
        None
    }
}

/// An IEC name, or else a Logix tag name as an L5X export's programs use
/// them (`Local:1:I.Data.3`, `Program:Main.Start`, `Arr[2]`).
fn logix_or(iec: Result<Signal, AddressError>, text: &str) -> Result<Signal, AddressError> {
    iec.or_else(|e| {
        if l5x::is_tag_name(text) {
            Ok(Signal::new(text))
        } else {
            Err(e)
        }
    })
}

/// A vendor's XML export given with `--dialect`: refused, saying what it is.
fn refuse_dialect(
    origin: &str,
    dialect: Option<Dialect>,
    what: &str,
    read: &str,
) -> Result<(), SourceErrors> {
    match dialect {
        None => Ok(()),
        Some(_) => Err(SourceError::new(
            origin,
            Location::line_start(1),
            format!(
                "this is {what}, not an instruction list: leave --dialect out, and {read} are read"
            ),
        )
        .into()),
    }
}

/// An export with nothing but block ends in it: refused with `nothing`.
fn something(
    origin: &str,
    instructions: &[Instruction],
    nothing: &str,
) -> Result<(), SourceErrors> {
    if instructions
        .iter()
        .all(|i| i.operation == Operation::EndBlock)
    {
        return Err(SourceError::new(origin, Location::line_start(1), nothing).into());
    }
    Ok(())
}

/// An STL address, or else a symbol written without its quotes (`G0_00`
/// for `"G0_00"`), as `cellwatch sf` prints a TIA Portal tag's name.
fn symbol_or(stl: Result<Signal, AddressError>, text: &str) -> Result<Signal, AddressError> {
    stl.or_else(|e| {
        let mut chars = text.chars();
        let plain = chars.next().is_some_and(|c| c.is_alphabetic() || c == '_')
            && chars.all(|c| c.is_alphanumeric() || c == '_');
        if plain && !address_shaped(text) {
            Ok(Signal::new(text))
        } else {
            Err(e)
        }
    })
}

/// Whether `text` is an STL area and a number (`MW10`, `DB5`, `T1`): an
/// address written wrong, never taken for a symbol.
fn address_shaped(text: &str) -> bool {
    let digits = text.trim_start_matches(|c: char| c.is_ascii_alphabetic());
    let area = text[..text.len() - digits.len()].to_ascii_uppercase();
    let area = area
        .strip_suffix(['B', 'W', 'D', 'X'])
        .filter(|a| !a.is_empty() && *a != "D")
        .unwrap_or(&area);
    !digits.is_empty()
        && digits.bytes().all(|b| b.is_ascii_digit())
        && [
            "E", "A", "I", "Q", "M", "T", "Z", "C", "L", "P", "DB", "DI", "PE", "PA", "PI", "PQ",
        ]
        .contains(&area)
}

/// Parses a program in `dialect`, or in the detected dialect when `None`.
///
/// `origin` names the text in messages (usually the file name).
///
/// # Errors
/// Every line that cannot be read, each as `ORIGIN:LINE:COL: message`; an
/// empty program; a dialect that cannot be told.
pub fn parse(origin: &str, source: &str, dialect: Option<Dialect>) -> Result<Parsed, SourceErrors> {
    parse_in(origin, source, dialect, None)
}

/// [`parse`], a TIA Portal export's comments taken in `language` (`de-DE`)
/// where they have it; `None`: in `en-US` ([`simaticml::LANGUAGE`]). Else
/// in the first language that has a text.
///
/// # Errors
/// As [`parse`].
pub fn parse_in(
    origin: &str,
    source: &str,
    dialect: Option<Dialect>,
    language: Option<&str>,
) -> Result<Parsed, SourceErrors> {
    if l5x::is_l5x(source) {
        refuse_dialect(
            origin,
            dialect,
            "a Studio 5000 export (L5X)",
            "its ladder and FBD routines",
        )?;
        let project = l5x::lex(origin, source)?;
        something(
            origin,
            &project.instructions,
            "no routine with any rung or output reference (ORef) in it in this L5X export",
        )?;
        return Ok(Parsed {
            dialect: Dialect::Iec,
            first_checks: false,
            instructions: project.instructions,
            documentation: project.documentation,
        });
    }
    if simaticml::is_simaticml(source) {
        refuse_dialect(
            origin,
            dialect,
            "a TIA Portal export (SimaticML)",
            "its LAD and FBD networks",
        )?;
        let read = simaticml::lex(origin, source, language.unwrap_or(simaticml::LANGUAGE))?;
        something(
            origin,
            &read.instructions,
            "no LAD or FBD network with anything in it in this TIA Portal export",
        )?;
        return Ok(Parsed {
            dialect: Dialect::Stl,
            first_checks: false,
            instructions: read.instructions,
            documentation: read.documentation,
        });
    }
    if is_xml(source) {
        if dialect.is_some() {
            return Err(SourceError::new(
                origin,
                Location::line_start(1),
                "this is an XML file (PLCopen XML?), not an instruction list: leave --dialect out, and its ladder and IL bodies are read",
            )
            .into());
        }
        let project = plcopen::lex(origin, source)?;
        if project
            .instructions
            .iter()
            .all(|i| i.operation == Operation::EndBlock)
        {
            return Err(SourceError::new(
                origin,
                Location::line_start(1),
                "no ladder (LD), IL, ST, FBD or SFC body with anything in it in this XML file",
            )
            .into());
        }
        return Ok(Parsed {
            dialect: Dialect::Iec,
            first_checks: false,
            instructions: project.instructions,
            documentation: project.documentation,
        });
    }
    let dialect = match dialect {
        Some(d) => d,
        None => Dialect::detect(source).ok_or_else(|| {
            SourceError::new(
                origin,
                Location::line_start(1),
                if source.trim().is_empty() {
                    "the program is empty: no instructions".to_string()
                } else {
                    "cannot tell the dialect: no PMC (RD, WRT) or IEC (LD, ST) instruction found; pass --dialect pmc or --dialect iec".to_string()
                },
            )
        })?,
    };
    if let Some(hint) = wrong_format(source, dialect) {
        return Err(SourceError::new(origin, Location::line_start(1), hint).into());
    }
    let (instructions, documentation) = match dialect {
        Dialect::Pmc => (pmc::lex(origin, source)?, Vec::new()),
        Dialect::Iec => (iec::lex(origin, source)?, iec::documentation(source)),
        Dialect::Stl => (stl::lex(origin, source)?, stl::documentation(source)),
    };
    if instructions.is_empty() {
        return Err(SourceError::new(
            origin,
            Location::line_start(1),
            "the program is empty: no instructions",
        )
        .into());
    }
    Ok(Parsed {
        dialect,
        first_checks: dialect == Dialect::Stl,
        instructions,
        documentation,
    })
}

/// A program read: its dialect, instructions, and the comments its
/// declarations carry.
#[derive(Debug, Clone)]
pub struct Parsed {
    /// The dialect it was read in (PLCopen XML bodies read as IEC, TIA
    /// Portal networks as STL).
    pub dialect: Dialect,
    /// Whether the instructions rely on STL's first check (a check after
    /// a write starts a new result): STL text; not the instructions read
    /// from a drawn network, where every result starts with a load.
    pub first_checks: bool,
    /// Every instruction, in order.
    pub instructions: Vec<Instruction>,
    /// `(name or address, comment)` from the program's declarations: the
    /// comment beside `Start : BOOL; (* ... *)`, a PLCopen XML variable's
    /// documentation. Names as written; resolve them in the dialect.
    pub documentation: Vec<(String, String)>,
}

/// Whether a program is XML (a PLCopen XML project).
fn is_xml(source: &str) -> bool {
    let head = source.trim_start_matches('\u{FEFF}').trim_start();
    head.starts_with("<?xml") || head.starts_with("<project")
}

/// What a file given as an instruction list in `dialect` really is, when
/// it is plainly something else: one line instead of an error per line.
fn wrong_format(source: &str, dialect: Dialect) -> Option<String> {
    let guessed = Dialect::detect(source)?;
    (guessed != dialect && (guessed == Dialect::Stl || dialect == Dialect::Stl)).then(|| {
        let looks = match guessed {
            Dialect::Stl => "Siemens STL (U, UN, =)",
            Dialect::Iec => "IEC IL (LD, ST)",
            Dialect::Pmc => "PMC (RD, WRT)",
        };
        format!("this looks like {looks}, not {dialect}: pass --dialect {guessed}, or leave --dialect out")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_stl_symbol_may_be_written_without_its_quotes_an_address_never() {
        let stl = |t: &str| Dialect::Stl.signal(t).map(|s| s.to_string());
        assert_eq!(stl("G0_00").unwrap(), stl("\"G0_00\"").unwrap());
        assert_eq!(stl("Start").unwrap(), "Start");
        assert_eq!(stl("E 0.0").unwrap(), "E0.0");
        // An address written wrong stays an error, never a symbol.
        for wrong in ["MW10", "DB5", "m10", "DBX4", "E1", "Start button"] {
            assert!(Dialect::Stl.signal(wrong).is_err(), "{wrong}");
        }
    }

    #[test]
    fn detects_dialects() {
        assert_eq!(
            Dialect::detect("; fig 6\nRD X1\nANDN X2\n"),
            Some(Dialect::Pmc)
        );
        assert_eq!(Dialect::detect("AND X1\nWRT Y1"), Some(Dialect::Pmc));
        assert_eq!(Dialect::detect("(* a *)\nLD a\nST b"), Some(Dialect::Iec));
        assert_eq!(
            Dialect::detect("start: LD %IX0.0\nST %QX0.0"),
            Some(Dialect::Iec)
        );
        assert_eq!(Dialect::detect("AND X1\nOR X2"), None);
    }

    #[test]
    fn empty_program_is_an_error() {
        let err = parse("e.il", "  \n; nothing\n", Some(Dialect::Pmc)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "e.il:1:1: the program is empty: no instructions"
        );
        let err = parse("e.il", "", None).unwrap_err();
        assert_eq!(
            err.to_string(),
            "e.il:1:1: the program is empty: no instructions"
        );
    }
}
