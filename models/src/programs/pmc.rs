//! The FANUC PMC dialect: `RD`, `RD.NOT`/`RDN`, `RD.STK`/`RDS`, ... with
//! addresses such as `X0.07`; comments run from `;` to the end of the line.

use super::{words, Instruction, Op, Operand, Operation, Outside};
use crate::signal::pmc_address;
use crate::source::{column, Location, SourceError, SourceErrors};

/// Mnemonics that belong to PMC only, for dialect detection.
pub(super) fn is_pmc_only(upper: &str) -> bool {
    upper.starts_with("RD")
        || upper.starts_with("WR")
        || matches!(
            upper,
            "ANDS" | "ORS" | "AND.STK" | "OR.STK" | "AND.NOT" | "OR.NOT" | "SET" | "RST"
        )
}

/// What a mnemonic does, and whether it takes a signal operand.
fn operation(upper: &str) -> Option<(Operation, OperandKind)> {
    use OperandKind::{Nothing as No, Number, Signal as Sig};
    use Operation as O;
    let logic = |op, negated| O::Logic { op, negated };
    Some(match upper {
        "RD" => (
            O::Load {
                negated: false,
                push: false,
            },
            Sig,
        ),
        "RD.NOT" | "RDN" => (
            O::Load {
                negated: true,
                push: false,
            },
            Sig,
        ),
        "RD.STK" | "RDS" => (
            O::Load {
                negated: false,
                push: true,
            },
            Sig,
        ),
        "RD.NOT.STK" | "RDNS" => (
            O::Load {
                negated: true,
                push: true,
            },
            Sig,
        ),
        "AND" => (logic(Op::And, false), Sig),
        "AND.NOT" | "ANDN" => (logic(Op::And, true), Sig),
        "OR" => (logic(Op::Or, false), Sig),
        "OR.NOT" | "ORN" => (logic(Op::Or, true), Sig),
        "AND.STK" | "ANDS" => (O::Combine(Op::And), No),
        "OR.STK" | "ORS" => (O::Combine(Op::Or), No),
        "WRT" | "WR" => (O::Write { negated: false }, Sig),
        "WRT.NOT" | "WRN" => (O::Write { negated: true }, Sig),
        "SET" => (O::Set, Sig),
        "RST" => (O::Reset, Sig),
        "END1" | "END2" | "END3" | "END" | "NOP" => (O::Nothing, No),
        "LBL" => (O::Label(String::new()), Number),
        "JMP" | "JMPB" | "JMPC" | "COM" | "COME" | "JMPE" => (O::Outside(Outside::Jump), Number),
        "CALL" | "CALLU" | "SP" | "SPE" => (O::Outside(Outside::Call), Number),
        "SUB" | "TMR" | "TMRB" | "TMRC" | "CTR" | "CTRB" | "DEC" | "DECB" | "COD" | "CODB"
        | "MOVE" | "MOVOR" | "MOVB" | "MOVW" | "MOVN" | "COMP" | "COMPB" | "COIN" | "ADDB"
        | "SUBB" | "MULB" | "DIVB" | "NUMEB" | "PARI" | "DSCH" | "XMOV" | "ROT" | "ROTB"
        | "DCNV" | "DCNVB" | "ADD" | "MUL" | "DIV" | "NUME" | "DISPB" | "EXIN" | "WINDR"
        | "WINDW" => (O::Outside(Outside::Arithmetic), Number),
        _ => return None,
    })
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum OperandKind {
    Nothing,
    Signal,
    /// A number or label: kept as text, not checked.
    Number,
}

/// Reads a PMC program, reporting every bad line.
pub(super) fn lex(origin: &str, source: &str) -> Result<Vec<Instruction>, SourceErrors> {
    let mut out = Vec::new();
    let mut errors = Vec::new();
    for (n, raw) in source.lines().enumerate() {
        let line_no = n + 1;
        let code = raw.split(';').next().unwrap_or("");
        let ws = words(code);
        let Some(&(m_off, mnemonic)) = ws.first() else {
            continue;
        };
        let at = Location {
            line: line_no,
            col: column(raw, m_off),
        };
        let err = |col_off: usize, msg: String| {
            SourceError::new(
                origin,
                Location {
                    line: line_no,
                    col: column(raw, col_off),
                },
                msg,
            )
        };
        let upper = mnemonic.to_ascii_uppercase();
        let Some((operation, kind)) = operation(&upper) else {
            errors.push(err(m_off, format!("unknown instruction '{mnemonic}'")));
            continue;
        };
        let operand_word = ws.get(1).copied();
        if let Some(&(off, extra)) = ws.get(2) {
            errors.push(err(
                off,
                format!("unexpected '{extra}' after '{mnemonic} {}'", ws[1].1),
            ));
            continue;
        }
        let operand_at = operand_word.map_or(at, |(off, _)| Location {
            line: line_no,
            col: column(raw, off),
        });
        let operand = match (kind, operand_word) {
            (OperandKind::Nothing, None) => None,
            (OperandKind::Nothing, Some((off, w))) => {
                errors.push(err(
                    off,
                    format!("'{mnemonic}' takes no operand, found '{w}'"),
                ));
                continue;
            }
            (OperandKind::Signal, None) => {
                errors.push(err(m_off, format!("'{mnemonic}' needs an address operand")));
                continue;
            }
            (OperandKind::Signal, Some((off, w))) => match pmc_address(w) {
                Ok(s) => Some(Operand::Signal(s)),
                Err(e) => {
                    errors.push(err(off, e.to_string()));
                    continue;
                }
            },
            (OperandKind::Number, w) => w.map(|(_, w)| Operand::Other(w.to_string())),
        };
        let operation = match operation {
            Operation::Label(_) => {
                Operation::Label(operand_word.map_or(String::new(), |w| w.1.to_string()))
            }
            other => other,
        };
        out.push(Instruction {
            at,
            text: code.split_whitespace().collect::<Vec<_>>().join(" "),
            mnemonic: mnemonic.to_string(),
            operation,
            operand,
            operand_at,
        });
    }
    SourceErrors::or_ok(out, errors)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ops(src: &str) -> Vec<Operation> {
        lex("t.il", src)
            .unwrap()
            .into_iter()
            .map(|i| i.operation)
            .collect()
    }

    #[test]
    fn long_and_short_forms_agree() {
        let long = ops("RD.NOT.STK X1\nAND.NOT X2\nOR.NOT X3\nAND.STK\nOR.STK\nWRT.NOT Y1\nRD.STK X1\nRD.NOT X1");
        let short = ops("RDNS X1\nANDN X2\nORN X3\nANDS\nORS\nWRN Y1\nRDS X1\nRDN X1");
        assert_eq!(long, short);
    }

    #[test]
    fn every_bad_line_is_reported() {
        let err = lex(
            "p.il",
            "RD X0.07\nFOO X1\nAND\nWRT Y0.0G\nANDS X1\nOR X1 X2 ; c",
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "p.il:2:1: unknown instruction 'FOO'\n\
             p.il:3:1: 'AND' needs an address operand\n\
             p.il:4:5: malformed address 'Y0.0G': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)\n\
             p.il:5:6: 'ANDS' takes no operand, found 'X1'\n\
             p.il:6:7: unexpected 'X2' after 'OR X1'"
        );
    }

    #[test]
    fn comments_and_positions() {
        let i = lex("t.il", "; header\n   rd   x0.7   ; load\n").unwrap();
        assert_eq!(i.len(), 1);
        assert_eq!(i[0].at, Location { line: 2, col: 4 });
        assert_eq!(i[0].operand_at, Location { line: 2, col: 9 });
        assert_eq!(
            i[0].operand,
            Some(Operand::Signal(crate::signal::Signal::new("X0.07")))
        );
        assert_eq!(i[0].text, "rd x0.7");
    }
}
