//! Siemens STL (AWL): the bit logic of S7 statement lists, German (`U`,
//! `UN`, `E 0.0`, `A 4.0`) and English (`A`, `AN`, `I 0.0`, `Q 4.0`)
//! mnemonics, read into the same instruction set as the other dialects.
//!
//! STL has no load: the first check after an assignment (`=`, `S`, `R`)
//! starts a new result, which the compiler follows ("first check").
//! `O` alone ORs the AND groups around it (`U a / U b / O / U c / U d` is
//! `a·b + c·d`); `O x` ORs `x` into the result so far. Blocks, networks,
//! titles and declarations are skipped; word instructions (`L`, `T`,
//! arithmetic), comparisons, timers, counters, edges, calls and jumps are
//! read and become warnings where they leave boolean logic.

use super::{words, Instruction, Op, Operand, Operation, Outside};
use crate::signal::{AddressError, Signal};
use crate::source::{column, Location, SourceError, SourceErrors};

/// The two mnemonic sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Language {
    German,
    English,
}

/// Whether a line's first word is STL only, for dialect detection.
pub(super) fn is_stl_only(upper: &str) -> bool {
    matches!(
        upper,
        "U" | "UN"
            | "U("
            | "UN("
            | "A"
            | "AN"
            | "A("
            | "AN("
            | "O("
            | "ON("
            | "X"
            | "XN"
            | "X("
            | "XN("
            | "O"
            | "ON"
            | "="
            | "CLR"
            | "NETWORK"
            | "TITLE"
            | "ORGANIZATION_BLOCK"
            | "SPA"
            | "SPB"
            | "SPBN"
            | "BEA"
            | "BEB"
            | "BE"
            | "L"
            | "T"
    )
}

/// Lines skipped wholly (block structure and attributes).
const HEADERS: &[&str] = &[
    "ORGANIZATION_BLOCK",
    "END_ORGANIZATION_BLOCK",
    "FUNCTION_BLOCK",
    "END_FUNCTION_BLOCK",
    "FUNCTION",
    "END_FUNCTION",
    "BEGIN",
    "NETWORK",
    "TITLE",
    "VERSION",
    "AUTHOR",
    "FAMILY",
    "NAME",
    "KNOW_HOW_PROTECT",
    "CODE_VERSION1",
];

/// Sections skipped up to their end.
const SECTIONS: &[(&str, &str)] = &[
    ("VAR", "END_VAR"),
    ("VAR_INPUT", "END_VAR"),
    ("VAR_OUTPUT", "END_VAR"),
    ("VAR_IN_OUT", "END_VAR"),
    ("VAR_TEMP", "END_VAR"),
    ("VAR_STAT", "END_VAR"),
    ("DATA_BLOCK", "END_DATA_BLOCK"),
    ("TYPE", "END_TYPE"),
];

fn operation(upper: &str, lang: Language) -> Option<(Operation, Kind)> {
    use Kind::{Bit, Coil, Nothing as No, Text};
    use Operation as O;
    let check = |op, negated| O::Logic { op, negated };
    let open = |op, negated| O::Open { op, negated };
    let (and, andn, and_open, andn_open) = match lang {
        Language::German => ("U", "UN", "U(", "UN("),
        Language::English => ("A", "AN", "A(", "AN("),
    };
    Some(match upper {
        u if u == and => (check(Op::And, false), Bit),
        u if u == andn => (check(Op::And, true), Bit),
        u if u == and_open => (open(Some(Op::And), false), No),
        u if u == andn_open => (open(Some(Op::And), true), No),
        "O" => (check(Op::Or, false), Bit),
        "ON" => (check(Op::Or, true), Bit),
        "O(" => (open(Some(Op::Or), false), No),
        "ON(" => (open(Some(Op::Or), true), No),
        "X" => (O::Xor { negated: false }, Bit),
        "XN" => (O::Xor { negated: true }, Bit),
        "X(" => (open(None, false), No),
        "XN(" => (open(None, true), No),
        ")" => (O::Close, No),
        "NOT" => (O::Not, No),
        "SET" => (O::Constant(true), No),
        "CLR" => (O::Constant(false), No),
        "=" => (O::Write { negated: false }, Coil),
        "S" => (O::Set, Coil),
        "R" => (O::Reset, Coil),
        "SAVE" | "BE" | "NOP" | "BLD" => (O::Nothing, Text),
        // Jumps, conditional block ends, the master control relay.
        "SPA" | "SPB" | "SPBN" | "SPBB" | "SPBNB" | "SPBI" | "SPBIN" | "SPZ" | "SPN" | "SPP"
        | "SPM" | "SPPZ" | "SPMZ" | "SPU" | "SPO" | "SPS" | "SPL" | "JU" | "JC" | "JCN" | "JCB"
        | "JNB" | "JBI" | "JNBI" | "JZ" | "JN" | "JP" | "JM" | "JPZ" | "JMZ" | "JUO" | "JO"
        | "JOS" | "JL" | "LOOP" | "BEA" | "BEB" | "BEU" | "MCRA" | "MCRD" | "MCR(" | ")MCR" => {
            (O::Outside(Outside::Jump), Text)
        }
        // Calls and what consumes the result: timers, counters, edges.
        "CALL" | "UC" | "CC" | "FP" | "FN" | "SI" | "SV" | "SE" | "SS" | "SA" | "SP" | "SD"
        | "SF" | "FR" | "ZV" | "ZR" | "CU" | "CD" | "LC" => (O::Outside(Outside::Call), Text),
        // Comparisons set the result from the accumulators.
        c if c.len() >= 2 && c.starts_with(['=', '<', '>']) && c.ends_with(['I', 'D', 'R']) => {
            (O::Outside(Outside::Arithmetic), No)
        }
        // Accumulator and word instructions: they leave the result alone.
        "L" | "T" | "+I" | "-I" | "*I" | "/I" | "+D" | "-D" | "*D" | "/D" | "MOD" | "+R" | "-R"
        | "*R" | "/R" | "+" | "INC" | "DEC" | "TAK" | "PUSH" | "POP" | "ENT" | "LEAVE" | "UW"
        | "OW" | "XOW" | "UD" | "OD" | "XOD" | "AW" | "AD" | "INVI" | "INVD" | "NEGI" | "NEGD"
        | "NEGR" | "ABS" | "SQR" | "SQRT" | "EXP" | "LN" | "SIN" | "COS" | "TAN" | "ASIN"
        | "ACOS" | "ATAN" | "BTI" | "ITB" | "BTD" | "DTB" | "ITD" | "DTR" | "RND" | "RND+"
        | "RND-" | "TRUNC" | "CAW" | "CAD" | "SLW" | "SRW" | "SLD" | "SRD" | "RLD" | "RRD"
        | "RLDA" | "RRDA" | "SSI" | "SSD" | "AUF" | "OPN" | "TDB" | "LAR1" | "LAR2" | "TAR1"
        | "TAR2" | "CAR" | "+AR1" | "+AR2" | "TAD" | "TAW" | "TAR" | "CDB" | "INVR" => {
            (O::Outside(Outside::Word), Text)
        }
        _ => return None,
    })
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Nothing,
    /// A bit operand, or none (`O` alone).
    Bit,
    /// A bit to write.
    Coil,
    /// Free text.
    Text,
}

/// A bit operand in canonical form: `E 0.0` → `E0.0`, `"Motor an"` →
/// `Motor an`, `#flag`, `DB1.DBX 2.3` → `DB1.DBX2.3`, `T 1` → `T1`.
/// `Ok(None)`: a well-formed operand that is not a bit (`MW 10`, `5`).
fn bit_operand(text: &str) -> Result<Option<Signal>, AddressError> {
    // A block's local as named outside it: `Betriebsarten.#Reset`,
    // `"Schrittkette 1".#T1_2`, `FB 10.#flag`.
    if let Some((block, local)) = text.split_once(".#") {
        let Some(block) = block_name(block) else {
            return Err(AddressError::StlBlockName { text: text.into() });
        };
        return match bit_operand(&format!("#{local}"))? {
            Some(local) => Ok(Some(in_block(Some(&block), local))),
            None => Ok(None),
        };
    }
    // A member of a global DB: `"Line_DB".Ready` → `Line_DB.Ready`.
    if let Some((db, member)) = text
        .strip_prefix('"')
        .and_then(|inner| inner.split_once("\"."))
    {
        let ok = !db.is_empty()
            && !db.contains('"')
            && member
                .split('.')
                .all(|p| !p.is_empty() && p.chars().all(|c| c.is_alphanumeric() || c == '_'));
        return if ok {
            Ok(Some(Signal::new(&format!("{db}.{member}"))))
        } else {
            Err(AddressError::StlMember { text: text.into() })
        };
    }
    if let Some(inner) = text.strip_prefix('"') {
        return match inner.strip_suffix('"') {
            Some(name) if !name.is_empty() && !name.contains('"') => Ok(Some(Signal::new(name))),
            _ => Err(AddressError::StlSymbol { text: text.into() }),
        };
    }
    if let Some(local) = text.strip_prefix('#') {
        let ok = !local.is_empty()
            && local
                .split('.')
                .all(|p| !p.is_empty() && p.chars().all(|c| c.is_alphanumeric() || c == '_'));
        return if ok {
            Ok(Some(Signal::new(text)))
        } else {
            Err(AddressError::StlLocal { text: text.into() })
        };
    }
    // TIA Portal writes addresses with a `%`: `%I0.0` is `I 0.0`.
    let text = text.strip_prefix('%').unwrap_or(text);
    let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    // Typed constants (S5T#5S, W#16#FF, L#5, P#M1.0), strings, numbers.
    if compact.contains('#')
        || compact.starts_with('\'')
        || compact.starts_with(['+', '-'])
        || compact.chars().all(|c| c.is_ascii_digit() || c == '.')
    {
        return Ok(None);
    }
    let upper = compact.to_ascii_uppercase();
    // DB1.DBX2.3, DBX2.3, DIX2.3
    let (prefix, rest) = match upper.split_once(".DB") {
        Some((db, rest)) if db.starts_with("DB") => (format!("{db}.DB"), rest.to_string()),
        _ => (String::new(), upper.clone()),
    };
    let area_len = rest.chars().take_while(char::is_ascii_alphabetic).count();
    let (area, number) = rest.split_at(area_len);
    let bit_area = matches!(
        area,
        "E" | "A" | "I" | "Q" | "M" | "L" | "X" | "DBX" | "DIX" | "PE" | "PA" | "PI" | "PQ"
    ) || (!prefix.is_empty() && area == "X");
    let timer = matches!(area, "T" | "Z" | "C");
    if area.is_empty() {
        return Err(AddressError::StlOperand { text: text.into() });
    }
    if timer && !number.is_empty() && number.chars().all(|c| c.is_ascii_digit()) {
        return Ok(Some(Signal::new(&format!("{area}{number}"))));
    }
    if bit_area {
        let ok = number.split_once('.').is_some_and(|(byte, bit)| {
            !byte.is_empty()
                && byte.chars().all(|c| c.is_ascii_digit())
                && bit.len() == 1
                && matches!(bit.as_bytes()[0], b'0'..=b'7')
        });
        return if ok {
            Ok(Some(Signal::new(&format!("{prefix}{area}{number}"))))
        } else {
            Err(AddressError::StlBit {
                text: text.into(),
                area: area.into(),
            })
        };
    }
    if area.chars().all(|c| c.is_ascii_alphabetic()) && number.chars().all(|c| c.is_ascii_digit()) {
        // MW 10, EB 0, DBW 4, PEW 256: words and bytes.
        return Ok(None);
    }
    Err(AddressError::StlOperand { text: text.into() })
}

/// A block's name in canonical form: `"Betriebsarten"` → `Betriebsarten`,
/// `FB 10` → `FB10`; `None` if empty or malformed.
fn block_name(text: &str) -> Option<String> {
    let text = text.trim();
    if let Some(inner) = text.strip_prefix('"') {
        let name = inner.strip_suffix('"')?;
        return (!name.is_empty() && !name.contains('"')).then(|| name.to_string());
    }
    let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    let ok = !compact.is_empty()
        && compact
            .chars()
            .all(|c| c.is_alphanumeric() || c == '_' || c == '.');
    ok.then(|| {
        // `FB 10`, `fc3`, `OB 1`: a block number reads as written in Step 7.
        let letters = compact
            .chars()
            .take_while(char::is_ascii_alphabetic)
            .count();
        let upper = compact[..letters].to_ascii_uppercase();
        if matches!(upper.as_str(), "OB" | "FB" | "FC" | "SFB" | "SFC")
            && letters < compact.len()
            && compact[letters..].chars().all(|c| c.is_ascii_digit())
        {
            format!("{upper}{}", &compact[letters..])
        } else {
            compact
        }
    })
}

/// The name of the block a header line opens (`FUNCTION_BLOCK
/// "Betriebsarten"`, `FUNCTION FC 3 : VOID`, `ORGANIZATION_BLOCK OB 1`).
fn opened_block(line: &str) -> Option<String> {
    let rest = line.trim_start();
    let keyword_len = rest.find(char::is_whitespace)?;
    let upper = rest[..keyword_len].to_ascii_uppercase();
    if !matches!(
        upper.as_str(),
        "ORGANIZATION_BLOCK" | "FUNCTION_BLOCK" | "FUNCTION"
    ) {
        return None;
    }
    let name = rest[keyword_len..].trim().trim_end_matches(';');
    // `FUNCTION "Name" : VOID`: the return type is not part of the name.
    let name = if let Some(inner) = name.strip_prefix('"') {
        match inner.find('"') {
            Some(end) => &name[..end + 2],
            None => name,
        }
    } else {
        name.split(':').next().unwrap_or(name)
    };
    block_name(name)
}

/// A local (`#Reset`) is its block's own: `Betriebsarten.#Reset`. Outside
/// any block (a bare network list) it stays `#Reset`.
fn in_block(block: Option<&str>, signal: Signal) -> Signal {
    match block {
        Some(block) if signal.name().starts_with('#') => {
            Signal::new(&format!("{block}.{}", signal.name()))
        }
        _ => signal,
    }
}

/// The canonical signal for an STL address typed by a user (`E 0.0`,
/// `"Start"`).
///
/// # Errors
/// [`AddressError`]: a malformed address, or one that is not a bit.
pub(crate) fn operand_signal(text: &str) -> Result<Signal, AddressError> {
    bit_operand(text.trim())?.ok_or_else(|| AddressError::StlNotABit { text: text.into() })
}

/// The canonical signal for a tag's STL address: a bit (`E 0.0` →
/// `E0.0`, `"Start"`, `Band.#Reset`) or a word or byte a numeric tag reads
/// (`MW 10` → `MW10`, `DB1.DBW 4` → `DB1.DBW4`, `PEW 256`).
///
/// # Errors
/// [`AddressError`]: a malformed address, or a constant.
pub(crate) fn tag_signal(text: &str) -> Result<Signal, AddressError> {
    let text = text.trim();
    if let Some(bit) = bit_operand(text)? {
        return Ok(bit);
    }
    let text = text.strip_prefix('%').unwrap_or(text);
    let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    let upper = compact.to_ascii_uppercase();
    let (db, rest) = match upper.split_once('.') {
        Some((db, rest)) if db.starts_with("DB") => (Some(db), rest),
        _ => (None, upper.as_str()),
    };
    let letters = rest.chars().take_while(char::is_ascii_alphabetic).count();
    let word = letters > 0
        && letters < rest.len()
        && rest[letters..].chars().all(|c| c.is_ascii_digit())
        && db.is_none_or(|db| db.len() > 2 && db[2..].chars().all(|c| c.is_ascii_digit()));
    if word {
        Ok(Signal::new(&upper))
    } else {
        Err(AddressError::StlNotAnAddress { text: text.into() })
    }
}

/// The comments written beside declarations of locals (`RESET : BOOL ;
/// // Reset the chain`), as `(#name, comment)`.
pub(crate) fn documentation(source: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut section: Option<&str> = None;
    let mut block: Option<String> = None;
    for raw in source.lines() {
        let line = code(raw);
        let Some(first) = line.split_whitespace().next() else {
            continue;
        };
        let upper = first.to_ascii_uppercase();
        if section.is_none() {
            if let Some(name) = opened_block(line) {
                block = Some(name);
                continue;
            }
            if upper.starts_with("END_") && HEADERS.contains(&upper.as_str()) {
                block = None;
                continue;
            }
        }
        match section {
            None => {
                section = SECTIONS
                    .iter()
                    .find(|(s, _)| *s == upper && s.starts_with("VAR"))
                    .map(|(_, end)| *end);
            }
            Some(end) if upper.trim_end_matches(';') == end => section = None,
            Some(_) => {
                let comment = raw[line.len()..].trim_start_matches('/').trim();
                if let (Some((name, _)), false) = (line.split_once(':'), comment.is_empty()) {
                    let local = Signal::new(&format!("#{}", name.trim()));
                    let local = in_block(block.as_deref(), local);
                    out.push((local.name().to_string(), comment.to_string()));
                }
            }
        }
    }
    out
}

/// Splits off a `//` comment, outside a quoted symbol.
fn code(line: &str) -> &str {
    let mut quoted = false;
    let bytes = line.as_bytes();
    for i in 0..bytes.len() {
        match bytes[i] {
            b'"' => quoted = !quoted,
            b'/' if !quoted && bytes.get(i + 1) == Some(&b'/') => return &line[..i],
            _ => {}
        }
    }
    line
}

/// Which mnemonic set a program uses: the first `U`/`UN` or `A`/`AN` as a
/// line's mnemonic decides; German if neither appears.
fn language(source: &str) -> Language {
    for line in source.lines() {
        let mut w = words(code(line)).into_iter().map(|(_, w)| w);
        let mut first = w.next().unwrap_or("");
        if first.ends_with(':') {
            first = w.next().unwrap_or("");
        }
        match first.to_ascii_uppercase().trim_end_matches('(') {
            "U" | "UN" => return Language::German,
            "A" | "AN" => return Language::English,
            _ => {}
        }
    }
    Language::German
}

/// Reads an STL program, reporting every bad line.
pub(super) fn lex(origin: &str, source: &str) -> Result<Vec<Instruction>, SourceErrors> {
    let lang = language(source);
    let mut out = Vec::new();
    let mut errors = Vec::new();
    let mut section: Option<&str> = None;
    let mut in_call = false;
    // The block being read: its locals are its own.
    let mut block: Option<String> = None;
    for (n, raw) in source.lines().enumerate() {
        let line_no = n + 1;
        let line = code(raw);
        let mut toks = words(line);
        let Some(&(_, first)) = toks.first() else {
            continue;
        };
        let first_upper = first.to_ascii_uppercase();
        if let Some(end) = section {
            if first_upper.trim_end_matches(';') == end {
                section = None;
            }
            continue;
        }
        if let Some((_, end)) = SECTIONS.iter().find(|(s, _)| *s == first_upper) {
            section = Some(end);
            continue;
        }
        if in_call {
            // A call's parameter list: `CALL FB 1, DB 1 (` ... `)`.
            in_call = !line
                .trim_end()
                .trim_end_matches(';')
                .trim_end()
                .ends_with(')');
            continue;
        }
        if HEADERS.contains(&first_upper.as_str()) || first_upper.starts_with("TITLE") {
            if let Some(name) = opened_block(line) {
                block = Some(name);
            }
            if matches!(
                first_upper.as_str(),
                "END_ORGANIZATION_BLOCK" | "END_FUNCTION_BLOCK" | "END_FUNCTION"
            ) {
                block = None;
                let at = Location {
                    line: line_no,
                    col: column(raw, toks[0].0),
                };
                out.push(Instruction {
                    at,
                    text: first_upper.clone(),
                    mnemonic: first.to_string(),
                    operation: Operation::EndBlock,
                    operand: None,
                    operand_at: at,
                });
            }
            continue;
        }
        // A call's parameter lines (`IN1 := E 0.0`) belong to the CALL.
        if line.contains(":=") {
            continue;
        }
        let loc = |off: usize| Location {
            line: line_no,
            col: column(raw, off),
        };
        let err = |off: usize, msg: String| SourceError::new(origin, loc(off), msg);
        // A label: `M001: U E 0.0`, or `M001:U E 0.0`.
        if let Some(colon) = first.find(':') {
            let label = &first[..colon];
            let ok = !label.is_empty()
                && label.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
                && label.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !ok {
                errors.push(err(toks[0].0, format!("malformed label '{first}'")));
                continue;
            }
            out.push(Instruction {
                at: loc(toks[0].0),
                text: format!("{label}:"),
                mnemonic: format!("{label}:"),
                operation: Operation::Label(label.to_ascii_uppercase()),
                operand: None,
                operand_at: loc(toks[0].0),
            });
            let (off, word) = toks.remove(0);
            let rest = &word[colon + 1..];
            if !rest.is_empty() {
                toks.insert(0, (off + colon + 1, rest));
            }
        }
        let Some(&(m_off, mnemonic)) = toks.first() else {
            continue;
        };
        // `U(` may be written `U (`.
        let mut upper = mnemonic.to_ascii_uppercase();
        let mut operand_from = 1;
        if toks.get(1).is_some_and(|&(_, w)| w == "(") && !upper.ends_with('(') {
            upper.push('(');
            operand_from = 2;
        }
        if matches!(upper.as_str(), "CALL" | "UC" | "CC")
            && line
                .trim_end()
                .trim_end_matches(';')
                .trim_end()
                .ends_with('(')
        {
            in_call = true;
        }
        let Some((operation, kind)) = operation(&upper, lang) else {
            errors.push(err(m_off, format!("unknown instruction '{mnemonic}'")));
            continue;
        };
        let operand_words = &toks[operand_from.min(toks.len())..];
        let operand_text = operand_words
            .iter()
            .map(|&(_, w)| w)
            .collect::<Vec<_>>()
            .join(" ");
        let operand_text = operand_text.trim_end_matches(';').trim().to_string();
        let at = loc(m_off);
        let operand_at = operand_words.first().map_or(at, |&(off, _)| loc(off));
        let text = if operand_text.is_empty() {
            upper.clone()
        } else {
            format!("{upper} {operand_text}")
        };
        let operand = match kind {
            Kind::Nothing if operand_text.is_empty() => None,
            Kind::Nothing => {
                errors.push(err(
                    operand_words[0].0,
                    format!("'{upper}' takes no operand, found '{operand_text}'"),
                ));
                continue;
            }
            Kind::Text if operand_text.is_empty() => None,
            Kind::Text => Some(Operand::Other(operand_text)),
            // `O` alone: the OR of AND groups.
            Kind::Bit if operand_text.is_empty() && upper == "O" => {
                out.push(Instruction {
                    at,
                    text,
                    mnemonic: mnemonic.to_string(),
                    operation: Operation::OrGroups,
                    operand: None,
                    operand_at,
                });
                continue;
            }
            Kind::Bit | Kind::Coil if operand_text.is_empty() => {
                errors.push(err(m_off, format!("'{upper}' needs an operand")));
                continue;
            }
            Kind::Bit => match bit_operand(&operand_text) {
                Ok(Some(s)) => Some(Operand::Signal(in_block(block.as_deref(), s))),
                Ok(None) => Some(Operand::Other(operand_text)),
                Err(e) => {
                    errors.push(err(operand_words[0].0, e.to_string()));
                    continue;
                }
            },
            Kind::Coil => match bit_operand(&operand_text) {
                // `R T 1`, `S Z 1`: a timer or counter, not a latch.
                Ok(Some(s))
                    if matches!(operation, Operation::Set | Operation::Reset)
                        && is_timer_or_counter(&s) =>
                {
                    out.push(Instruction {
                        at,
                        text,
                        mnemonic: mnemonic.to_string(),
                        operation: Operation::Outside(Outside::Call),
                        operand: Some(Operand::Other(operand_text)),
                        operand_at,
                    });
                    continue;
                }
                Ok(Some(s)) => Some(Operand::Signal(in_block(block.as_deref(), s))),
                // `= [AR1,P#6.0]`, `= M [MD 10]`: the bit is chosen at run
                // time.
                Ok(None) | Err(_) if operand_text.contains('[') => {
                    out.push(Instruction {
                        at,
                        text,
                        mnemonic: mnemonic.to_string(),
                        operation: Operation::Outside(Outside::Indirect),
                        operand: Some(Operand::Other(operand_text)),
                        operand_at,
                    });
                    continue;
                }
                Ok(None) | Err(_) => {
                    errors.push(err(
                        operand_words[0].0,
                        format!("cannot write '{upper}' to '{operand_text}': not a bit address"),
                    ));
                    continue;
                }
            },
        };
        out.push(Instruction {
            at,
            text,
            mnemonic: mnemonic.to_string(),
            operation,
            operand,
            operand_at,
        });
    }
    SourceErrors::or_ok(out, errors)
}

fn is_timer_or_counter(s: &Signal) -> bool {
    let name = s.name();
    let area = name.trim_end_matches(|c: char| c.is_ascii_digit());
    matches!(area, "T" | "Z" | "C") && area.len() < name.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn operands_are_canonical() {
        let s = |t| bit_operand(t).unwrap().unwrap().name().to_string();
        assert_eq!(s("E 0.0"), "E0.0");
        assert_eq!(s("a 4.7"), "A4.7");
        assert_eq!(s("I0.1"), "I0.1");
        assert_eq!(s("DB1.DBX 2.3"), "DB1.DBX2.3");
        assert_eq!(s("T 1"), "T1");
        assert_eq!(s("\"Motor an\""), "Motor an");
        assert_eq!(s("#flag"), "#flag");
        assert_eq!(bit_operand("MW 10").unwrap(), None);
        assert_eq!(bit_operand("S5T#5S").unwrap(), None);
        assert_eq!(
            bit_operand("E 0.8").unwrap_err().to_string(),
            "malformed address 'E 0.8': expected byte.bit with a bit 0..7, as in E 0.0"
        );
    }

    #[test]
    fn tag_addresses_take_words_too() {
        let s = |t| tag_signal(t).unwrap().name().to_string();
        assert_eq!(s("E 0.0"), "E0.0");
        assert_eq!(s("MW 10"), "MW10");
        assert_eq!(s("db1.dbw 4"), "DB1.DBW4");
        assert_eq!(s("PEW256"), "PEW256");
        assert_eq!(s("\"Temperatur\""), "Temperatur");
        assert_eq!(s("Band.#Reset"), "Band.#Reset");
        assert!(tag_signal("5").is_err());
        assert!(tag_signal("S5T#5S").is_err());
        assert!(tag_signal("E 0.9").is_err());
    }

    #[test]
    fn locals_belong_to_their_block() {
        let src =
            "FUNCTION_BLOCK \"Band 1\"\nVAR\n  Reset : BOOL ; // Band 1 zurücksetzen\nEND_VAR\n\
                   BEGIN\nU E 0.0\n= #Reset\nEND_FUNCTION_BLOCK\n\
                   FUNCTION FC 3 : VOID\nVAR_TEMP\n  Reset : BOOL ; // FC3's own\nEND_VAR\n\
                   BEGIN\nU #Reset\n= A 4.0\nEND_FUNCTION\n\
                   U #Reset\n= A 4.1\n";
        let signals: Vec<String> = lex("t.awl", src)
            .unwrap()
            .into_iter()
            .filter_map(|i| match i.operand {
                Some(Operand::Signal(s)) => Some(s.name().to_string()),
                _ => None,
            })
            .collect();
        assert_eq!(
            signals,
            [
                "E0.0",
                "Band 1.#Reset",
                "FC3.#Reset",
                "A4.0",
                "#Reset",
                "A4.1"
            ]
        );
        assert_eq!(
            documentation(src),
            [
                (
                    "Band 1.#Reset".to_string(),
                    "Band 1 zurücksetzen".to_string()
                ),
                ("FC3.#Reset".to_string(), "FC3's own".to_string()),
            ]
        );
        // Named from outside the block, as in an observability list.
        assert_eq!(
            operand_signal("\"Band 1\".#Reset").unwrap().name(),
            "Band 1.#Reset"
        );
        assert_eq!(operand_signal("fc 3.#Reset").unwrap().name(), "FC3.#Reset");
        assert_eq!(
            operand_signal("Betriebsarten.#a.b").unwrap().name(),
            "Betriebsarten.#a.b"
        );
        assert!(operand_signal("\"Band.#Reset").is_err());
        assert_eq!(opened_block("ORGANIZATION_BLOCK OB 1"), Some("OB1".into()));
        assert_eq!(
            opened_block("FUNCTION \"Zähler : neu\" : VOID"),
            Some("Zähler : neu".into())
        );
    }

    #[test]
    fn german_and_english_read_alike() {
        let ops = |src: &str| -> Vec<Operation> {
            lex("t.awl", src)
                .unwrap()
                .into_iter()
                .map(|i| i.operation)
                .collect()
        };
        let de = ops("NETWORK\nTITLE = Förderband\nU E 0.0 // Start\nUN( \nO M 1.0\n)\n= A 4.0\n");
        let en = ops("A I 0.0\nAN(\nO M 1.0\n)\n= Q 4.0\n");
        assert_eq!(de, en);
        assert_eq!(
            de[1],
            Operation::Open {
                op: Some(Op::And),
                negated: true
            }
        );
    }

    #[test]
    fn bad_lines_are_located() {
        let err = lex("p.awl", "U E 0.9\nFOO M 1.0\n= MW 2\nU\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "p.awl:1:3: malformed address 'E 0.9': expected byte.bit with a bit 0..7, as in E 0.0\n\
             p.awl:2:1: unknown instruction 'FOO'\n\
             p.awl:3:3: cannot write '=' to 'MW 2': not a bit address\n\
             p.awl:4:1: 'U' needs an operand"
        );
    }
}
