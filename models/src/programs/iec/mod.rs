//! The IEC 61131-3 instruction-list dialect: `LD`, `ANDN`, `AND(` ... `)`,
//! `ST`, `S`, `R`, labels, `(* comments *)`, direct addresses (`%IX0.0.3`)
//! and symbols. Symbols keep the spelling of their first use and match
//! without regard to case, as IEC 61131-3 identifiers do.
//!
//! The `VAR` ... `END_VAR` declarations give types: a variable that is not
//! `BOOL` is not a contact and not a coil, and a function-block instance
//! (`TON`, `SR`, ... or a `FUNCTION_BLOCK` of the file) takes `S`, `R`,
//! `ST inst.PT` as its inputs, never as latches or coils. Standard and
//! declared functions used as operators (`MAX 5`, `BCD_TO_INT`), calls
//! without `CAL` (`T1(IN := x)`), formal calls over several lines, array
//! operands and string literals are read; where they are not boolean they
//! are warnings, never errors.

mod declarations;

use std::collections::HashMap;

use super::{words, Instruction, Op, Operand, Operation, Outside};
use crate::signal::{iec_direct_address, AddressError, Signal};
use crate::source::{column, Location, SourceError, SourceErrors};

pub(crate) use declarations::Declarations;
use declarations::SKIPPED_BLOCKS;

/// Mnemonics that belong to IEC only, for dialect detection.
pub(super) fn is_iec_only(upper: &str) -> bool {
    matches!(
        upper.trim_end_matches('('),
        "LD" | "LDN"
            | "ST"
            | "STN"
            | "S"
            | "R"
            | "XOR"
            | "XORN"
            | "NOT"
            | "JMPC"
            | "JMPCN"
            | "CAL"
            | "CALC"
            | "CALCN"
            | "RET"
            | "PROGRAM"
            | "VAR"
            | "FUNCTION_BLOCK"
    ) || upper.ends_with('(')
}

/// The signal an IEC operand names: a direct address or a symbol
/// (`Start`, `T1.Q`).
///
/// # Errors
/// [`AddressError`] quoting a malformed address or name.
pub(crate) fn operand_signal(text: &str) -> Result<Signal, AddressError> {
    if text.starts_with('%') {
        return iec_direct_address(text);
    }
    let ident = |p: &str| {
        let mut c = p.chars();
        c.next()
            .is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
            && c.all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if text.split('.').all(ident) {
        Ok(Signal::new(text))
    } else {
        Err(AddressError::IecOperand { text: text.into() })
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum OperandKind {
    Nothing,
    /// A boolean operand: a signal or TRUE/FALSE; numbers are kept as
    /// [`Operand::Other`] so that the compiler can call them non-boolean.
    Value,
    /// A coil to write.
    Coil,
    /// Free text (jump label, call arguments).
    Text,
}

fn operation(upper: &str) -> Option<(Operation, OperandKind)> {
    use OperandKind::{Coil, Nothing as No, Text, Value};
    use Operation as O;
    let logic = |op, negated| O::Logic { op, negated };
    Some(match upper {
        "LD" => (
            O::Load {
                negated: false,
                push: false,
            },
            Value,
        ),
        "LDN" => (
            O::Load {
                negated: true,
                push: false,
            },
            Value,
        ),
        "AND" | "&" => (logic(Op::And, false), Value),
        "ANDN" | "&N" => (logic(Op::And, true), Value),
        "OR" => (logic(Op::Or, false), Value),
        "ORN" => (logic(Op::Or, true), Value),
        "XOR" => (O::Xor { negated: false }, Value),
        "XORN" => (O::Xor { negated: true }, Value),
        "AND(" | "&(" => (
            O::Open {
                op: Some(Op::And),
                negated: false,
            },
            Value,
        ),
        "ANDN(" | "&N(" => (
            O::Open {
                op: Some(Op::And),
                negated: true,
            },
            Value,
        ),
        "OR(" => (
            O::Open {
                op: Some(Op::Or),
                negated: false,
            },
            Value,
        ),
        "ORN(" => (
            O::Open {
                op: Some(Op::Or),
                negated: true,
            },
            Value,
        ),
        "XOR(" => (
            O::Open {
                op: None,
                negated: false,
            },
            Value,
        ),
        "XORN(" => (
            O::Open {
                op: None,
                negated: true,
            },
            Value,
        ),
        ")" => (O::Close, No),
        "NOT" => (O::Not, No),
        "ST" => (O::Write { negated: false }, Coil),
        "STN" => (O::Write { negated: true }, Coil),
        "S" => (O::Set, Coil),
        "R" => (O::Reset, Coil),
        "JMP" | "JMPC" | "JMPCN" | "RET" | "RETC" | "RETCN" => (O::Outside(Outside::Jump), Text),
        "CAL" | "CALC" | "CALCN" | "S1" | "R1" | "CLK" | "CU" | "CD" | "PV" | "IN" | "PT" => {
            (O::Outside(Outside::Call), Text)
        }
        "ADD" | "SUB" | "MUL" | "DIV" | "MOD" | "GT" | "GE" | "EQ" | "NE" | "LE" | "LT"
        | "ADD(" | "SUB(" | "MUL(" | "DIV(" | "MOD(" | "GT(" | "GE(" | "EQ(" | "NE(" | "LE("
        | "LT(" => (O::Outside(Outside::Arithmetic), Text),
        _ => return None,
    })
}

/// Replaces every `(* ... *)` comment with spaces, keeping line breaks so
/// that positions stay right.
fn blank_comments(origin: &str, source: &str) -> Result<String, SourceError> {
    let mut out = String::with_capacity(source.len());
    let mut rest = source;
    let mut consumed = 0;
    while let Some(start) = rest.find("(*") {
        out.push_str(&rest[..start]);
        let after = &rest[start + 2..];
        let Some(end) = after.find("*)") else {
            let pos = consumed + start;
            let line = source[..pos].matches('\n').count() + 1;
            let line_start = source[..pos].rfind('\n').map_or(0, |i| i + 1);
            let col = column(&source[line_start..], pos - line_start);
            return Err(SourceError::new(
                origin,
                Location { line, col },
                "comment '(*' is never closed with '*)'",
            ));
        };
        let comment = &rest[start..start + 2 + end + 2];
        out.extend(comment.chars().map(|c| if c == '\n' { '\n' } else { ' ' }));
        consumed += start + 2 + end + 2;
        rest = &rest[start + 2 + end + 2..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The comments written beside declarations (`Start : BOOL; (* Start
/// button *)`), as `(name, comment)`: the program's own I/O database.
pub(crate) fn documentation(source: &str) -> Vec<(String, String)> {
    let Ok(clean) = blank_comments("", source) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut in_var = false;
    for (raw, line) in source.lines().zip(clean.lines()) {
        let Some(first) = line.split_whitespace().next() else {
            continue;
        };
        let upper = first.to_ascii_uppercase();
        let mut line = line;
        if !in_var {
            in_var = SKIPPED_BLOCKS.contains(&upper.as_str());
            if !in_var {
                continue;
            }
            // `VAR_INPUT AUTO_CMD : BOOL; (* ... *)` on the keyword's line.
            line = &line[line.find(first).unwrap_or(0) + first.len()..];
        } else if upper.starts_with("END_VAR") {
            in_var = false;
            continue;
        }
        let (Some((names, _)), Some(open)) = (line.split_once(':'), raw.find("(*")) else {
            continue;
        };
        let text = &raw[open + 2..];
        let comment = text.split("*)").next().unwrap_or(text).trim();
        if comment.is_empty() {
            continue;
        }
        for name in names.split(',') {
            if let Some(name) = name.split_whitespace().next() {
                out.push((name.to_string(), comment.to_string()));
            }
        }
    }
    out
}

/// Splits a line's words so that `AND(` and `(` forms read alike:
/// `AND(x`, `AND (x` and `AND( x` all give `["AND(", "x"]`.
fn tokens(line: &str) -> Vec<(usize, String)> {
    let mut out: Vec<(usize, String)> = Vec::new();
    let mut quoted: Option<(usize, String)> = None;
    for (off, w) in words(line) {
        // A string literal with spaces is one token.
        if let Some((start, mut text)) = quoted.take() {
            text.push(' ');
            text.push_str(w);
            if w.ends_with('\'') {
                out.push((start, text));
            } else {
                quoted = Some((start, text));
            }
            continue;
        }
        if w.starts_with('\'') && (w.len() == 1 || !w.ends_with('\'')) {
            quoted = Some((off, w.to_string()));
            continue;
        }
        if w == "(" {
            if let Some(last) = out.last_mut() {
                last.1.push('(');
                continue;
            }
        }
        if let Some(rest) = w.strip_prefix('(') {
            if let Some(last) = out.last_mut() {
                if !last.1.ends_with('(') {
                    last.1.push('(');
                    if !rest.is_empty() {
                        out.push((off + 1, rest.to_string()));
                    }
                    continue;
                }
            }
        }
        match w.find('(') {
            Some(p) if p > 0 && p + 1 < w.len() && out.is_empty() => {
                out.push((off, w[..=p].to_string()));
                out.push((off + p + 1, w[p + 1..].to_string()));
            }
            _ => out.push((off, w.to_string())),
        }
    }
    if let Some(q) = quoted {
        out.push(q);
    }
    out
}

const SKIPPED_LINES: &[&str] = &[
    "PROGRAM",
    "END_PROGRAM",
    "FUNCTION_BLOCK",
    "END_FUNCTION_BLOCK",
    "FUNCTION",
    "END_FUNCTION",
];

/// Reads an IEC program, reporting every bad line.
pub(super) fn lex(origin: &str, source: &str) -> Result<Vec<Instruction>, SourceErrors> {
    lex_declared(origin, source, Declarations::default())
}

/// Reads an IEC program body whose declarations stand elsewhere (a PLCopen
/// XML POU's interface), reporting every bad line.
pub(super) fn lex_declared(
    origin: &str,
    source: &str,
    declared: Declarations,
) -> Result<Vec<Instruction>, SourceErrors> {
    let clean = blank_comments(origin, source)?;
    let mut decls = Declarations::read(&clean);
    decls.vars.extend(declared.vars);
    decls.blocks.extend(declared.blocks);
    decls.functions.extend(declared.functions);
    let mut out = Vec::new();
    let mut errors = Vec::new();
    let mut in_var = false;
    // Open parentheses of a formal call whose parameters run on.
    let mut in_call = 0i64;
    let mut spellings: HashMap<String, Signal> = HashMap::new();
    for (n, raw) in clean.lines().enumerate() {
        let line_no = n + 1;
        let mut toks = tokens(raw);
        let Some(first) = toks.first() else { continue };
        let first_upper = first.1.to_ascii_uppercase();
        if in_var {
            in_var = !first_upper.starts_with("END_VAR");
            continue;
        }
        if in_call > 0 {
            in_call += parens(raw);
            continue;
        }
        if SKIPPED_BLOCKS.contains(&first_upper.as_str()) {
            in_var = true;
            continue;
        }
        if SKIPPED_LINES.contains(&first_upper.as_str()) {
            if first_upper.starts_with("END_") {
                let at = Location {
                    line: line_no,
                    col: column(raw, first.0),
                };
                out.push(Instruction {
                    at,
                    text: first_upper.clone(),
                    mnemonic: first.1.to_string(),
                    operation: Operation::EndBlock,
                    operand: None,
                    operand_at: at,
                });
            }
            continue;
        }
        let err = |off: usize, msg: String| {
            SourceError::new(
                origin,
                Location {
                    line: line_no,
                    col: column(raw, off),
                },
                msg,
            )
        };
        // A label, alone or glued to its instruction (`next:LD a`).
        let glued = first
            .1
            .find(':')
            .filter(|&c| c + 1 < first.1.len() && !first.1[c..].starts_with(":="));
        if first.1.ends_with(':') || glued.is_some() {
            let colon = glued.unwrap_or(first.1.len() - 1);
            let (off, label) = (first.0, first.1[..colon].to_string());
            if operand_signal(&label).is_err() || label.contains('.') {
                errors.push(err(off, format!("malformed label '{label}:'")));
                continue;
            }
            out.push(Instruction {
                at: Location {
                    line: line_no,
                    col: column(raw, off),
                },
                text: format!("{label}:"),
                mnemonic: format!("{label}:"),
                operation: Operation::Label(label.to_ascii_uppercase()),
                operand: None,
                operand_at: Location {
                    line: line_no,
                    col: column(raw, off),
                },
            });
            let (off, word) = toks.remove(0);
            if glued.is_some() {
                let rest = word[colon + 1..].to_string();
                toks.insert(0, (off + colon + 1, rest));
            }
        }
        let Some((m_off, mnemonic)) = toks.first().cloned() else {
            continue;
        };
        let at = Location {
            line: line_no,
            col: column(raw, m_off),
        };
        let upper = mnemonic.to_ascii_uppercase();
        let base = upper.trim_end_matches('(');
        let (operation, kind) = match operation(&upper) {
            Some(found) => found,
            // A function as an operator: `MAX 5`, `BCD_TO_INT`, `LIMIT(`.
            None if decls.is_function(base) => {
                (Operation::Outside(Outside::Arithmetic), OperandKind::Text)
            }
            // A call without CAL: `T1(IN := x, PT := T#5s)`.
            None if upper.ends_with('(') && (decls.is_instance(base) || raw.contains(":=")) => {
                (Operation::Outside(Outside::Call), OperandKind::Text)
            }
            None => {
                errors.push(err(m_off, format!("unknown instruction '{mnemonic}'")));
                continue;
            }
        };
        let text = toks
            .iter()
            .map(|t| t.1.as_str())
            .collect::<Vec<_>>()
            .join(" ");
        if matches!(operation, Operation::Outside(Outside::Call)) {
            in_call = parens(raw).max(0);
        }
        let operand_tok = toks.get(1).cloned();
        if kind != OperandKind::Text {
            if let Some((off, extra)) = toks.get(2) {
                errors.push(err(
                    *off,
                    format!("unexpected '{extra}' after '{mnemonic} {}'", toks[1].1),
                ));
                continue;
            }
        }
        let operand_at = operand_tok.as_ref().map_or(at, |(off, _)| Location {
            line: line_no,
            col: column(raw, *off),
        });
        let mut signal = |w: &str| {
            operand_signal(w).map(|s| {
                spellings
                    .entry(s.name().to_ascii_uppercase())
                    .or_insert(s)
                    .clone()
            })
        };
        // A write to what is not a coil: an instance's input operator
        // (`R FF1`), a block input (`ST T1.PT`), a variable of another type.
        if kind == OperandKind::Coil {
            if let Some((_, w)) = &operand_tok {
                let to_block = decls.is_instance(w) || decls.is_block_input(w);
                if to_block || decls.not_boolean(w) {
                    out.push(Instruction {
                        at,
                        text,
                        mnemonic,
                        operation: Operation::Outside(if to_block {
                            Outside::BlockInput
                        } else {
                            Outside::Word
                        }),
                        operand: Some(Operand::Other(w.clone())),
                        operand_at,
                    });
                    continue;
                }
            }
        }
        let operand = match (kind, operand_tok) {
            (OperandKind::Nothing, None) => None,
            (OperandKind::Nothing, Some((off, w))) => {
                errors.push(err(
                    off,
                    format!("'{mnemonic}' takes no operand, found '{w}'"),
                ));
                continue;
            }
            (OperandKind::Value | OperandKind::Coil, None) => {
                if matches!(operation, Operation::Open { .. }) {
                    None
                } else {
                    errors.push(err(m_off, format!("'{mnemonic}' needs an operand")));
                    continue;
                }
            }
            (OperandKind::Value, Some((off, w))) => match w.to_ascii_uppercase().as_str() {
                "TRUE" => Some(Operand::Const(true)),
                "FALSE" => Some(Operand::Const(false)),
                _ if w.starts_with(|c: char| {
                    c.is_ascii_digit() || c == '-' || c == '+' || c == '\''
                }) || w.contains('#')
                    || decls.not_boolean(&w) =>
                {
                    Some(Operand::Other(w))
                }
                _ => match signal(&w) {
                    Ok(s) => Some(Operand::Signal(s)),
                    Err(e) => {
                        errors.push(err(off, e.to_string()));
                        continue;
                    }
                },
            },
            (OperandKind::Coil, Some((off, w))) => match signal(&w) {
                Ok(s) => Some(Operand::Signal(s)),
                Err(_) => {
                    errors.push(err(
                        off,
                        format!(
                            "cannot write '{mnemonic}' to '{w}': not a boolean address or name"
                        ),
                    ));
                    continue;
                }
            },
            (OperandKind::Text, w) => w.map(|_| {
                Operand::Other(
                    toks[1..]
                        .iter()
                        .map(|t| t.1.as_str())
                        .collect::<Vec<_>>()
                        .join(" "),
                )
            }),
        };
        out.push(Instruction {
            at,
            text,
            mnemonic,
            operation,
            operand,
            operand_at,
        });
    }
    SourceErrors::or_ok(out, errors)
}

/// Opening minus closing parentheses on a line, outside string literals.
fn parens(line: &str) -> i64 {
    let mut quoted = false;
    let mut depth = 0;
    for c in line.chars() {
        match c {
            '\'' => quoted = !quoted,
            '(' if !quoted => depth += 1,
            ')' if !quoted => depth -= 1,
            _ => {}
        }
    }
    depth
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ops(src: &str) -> Vec<(Operation, Option<Operand>)> {
        lex("t.il", src)
            .unwrap()
            .into_iter()
            .map(|i| (i.operation, i.operand))
            .collect()
    }

    #[test]
    fn parenthesis_spellings_agree() {
        let a = ops("AND( x\n)");
        assert_eq!(a, ops("AND(x\n)"));
        assert_eq!(a, ops("AND (x\n)"));
        assert_eq!(a, ops("AND ( x\n)"));
        assert_eq!(
            a[0].0,
            Operation::Open {
                op: Some(Op::And),
                negated: false
            }
        );
        assert_eq!(
            ops("ORN(\nLD a\n)")[0],
            (
                Operation::Open {
                    op: Some(Op::Or),
                    negated: true
                },
                None
            )
        );
    }

    #[test]
    fn comments_labels_and_declarations() {
        let src = "PROGRAM p\nVAR\n  a : BOOL; (* in *)\nEND_VAR\n(* one\n two *) LD %ix0.0.3 (* x *)\nnext: ST Motor\nEND_PROGRAM\n";
        let i = lex("t.il", src).unwrap();
        assert_eq!(i.len(), 4);
        assert_eq!(i[0].at, Location { line: 6, col: 9 });
        assert_eq!(i[0].operand, Some(Operand::Signal(Signal::new("%IX0.0.3"))));
        assert_eq!(i[1].operation, Operation::Label("NEXT".into()));
        assert_eq!(i[2].operand, Some(Operand::Signal(Signal::new("Motor"))));
        assert_eq!(i[3].operation, Operation::EndBlock);
        assert_eq!(i[3].at, Location { line: 8, col: 1 });
    }

    #[test]
    fn symbols_keep_their_first_spelling() {
        let i = lex("t.il", "LD Start\nST motor\nLD START\nST Motor").unwrap();
        assert_eq!(i[2].operand, Some(Operand::Signal(Signal::new("Start"))));
        assert_eq!(i[3].operand, Some(Operand::Signal(Signal::new("motor"))));
    }

    #[test]
    fn function_block_outputs_and_numbers() {
        assert_eq!(
            ops("LD T1.Q")[0].1,
            Some(Operand::Signal(Signal::new("T1.Q")))
        );
        assert_eq!(ops("LD 5")[0].1, Some(Operand::Other("5".into())));
        assert_eq!(ops("LD TRUE")[0].1, Some(Operand::Const(true)));
        assert_eq!(
            ops("CAL T1(IN := x, PT := T#5s)")[0].0,
            Operation::Outside(Outside::Call)
        );
    }

    #[test]
    fn bad_lines() {
        let err = lex("p.il", "LD %ZX1\nFOO a\nST\nST 5\n(* open").unwrap_err();
        assert_eq!(
            err.to_string(),
            "p.il:5:1: comment '(*' is never closed with '*)'"
        );
        let err = lex("p.il", "LD %ZX1\nFOO a\nST\nST 5\nLD a b").unwrap_err();
        assert_eq!(
            err.to_string(),
            "p.il:1:4: malformed address '%ZX1': a direct address starts with %I, %Q or %M\n\
             p.il:2:1: unknown instruction 'FOO'\n\
             p.il:3:1: 'ST' needs an operand\n\
             p.il:4:4: cannot write 'ST' to '5': not a boolean address or name\n\
             p.il:5:6: unexpected 'b' after 'LD a'"
        );
    }
}
