//! What a PLC program needs so that a transition can be forced (paper
//! 004, eq. (3)/(4)): the transition fires when its source steps are done
//! and its condition holds, *or* when the force switch is on and its
//! condition holds — `(S14 · t15) + (ForceSW · t15)` — written as IEC
//! 61131-3 Structured Text and Instruction List for the engineer to add.

use std::fmt::Write;

use super::{and, Sfc, SfcTransition};
use crate::expr::Expr;
use crate::signal::Signal;
use crate::value::{CmpOp, CmpOperand, Comparison};

/// The patch for transition `t` of chart `chart`, the force switch at
/// `force`: a comment, the ST assignment and the IL sequence, both to the
/// variable `<chart>_<id>_FIRE`.
pub fn patch(sfc: &Sfc, chart: usize, t: &SfcTransition, force: &Signal) -> String {
    let name = format!("{}_{}_FIRE", sfc.charts[chart].name, t.id);
    let from: Vec<String> = t.from.iter().map(|&r| sfc.step_name(r)).collect();
    let to: Vec<String> = t.to.iter().map(|&r| sfc.step_name(r)).collect();
    let about = super::about(t.comment.as_deref());
    let done = and(t
        .from
        .iter()
        .map(|&r| Expr::Lit(sfc.step(r).flag.clone(), false))
        .chain(std::iter::once(t.condition.clone())));
    let forced = and([Expr::Lit(force.clone(), false), t.condition.clone()]);
    let fire = Expr::Or(vec![done, forced]);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "(* {}.{}: {} -> {}{about}, forcible (paper 004, eq. (3)/(4)): it fires when\n   {} done and the condition holds, or when the force switch {force} is on and\n   the condition holds. *)",
        sfc.charts[chart].name,
        t.id,
        from.join(" + "),
        to.join(" + "),
        if from.len() == 1 { "its step is" } else { "its steps are" },
    );
    let _ = writeln!(out, "(* ST *)\n{name} := {};", st(&fire, true));
    let _ = writeln!(out, "(* IL *)");
    let mut lines = Vec::new();
    il(&fire, "LD", &mut lines);
    lines.push(format!("ST   {name}"));
    for l in lines {
        let _ = writeln!(out, "{l}");
    }
    out
}

fn cmp_st(op: CmpOp) -> &'static str {
    match op {
        CmpOp::Eq => "=",
        CmpOp::Ne => "<>",
        CmpOp::Lt => "<",
        CmpOp::Le => "<=",
        CmpOp::Gt => ">",
        CmpOp::Ge => ">=",
    }
}

fn cmp_il(op: CmpOp) -> &'static str {
    match op {
        CmpOp::Eq => "EQ",
        CmpOp::Ne => "NE",
        CmpOp::Lt => "LT",
        CmpOp::Le => "LE",
        CmpOp::Gt => "GT",
        CmpOp::Ge => "GE",
    }
}

fn operand(o: &CmpOperand) -> String {
    match o {
        CmpOperand::Const(n) => n.to_string(),
        CmpOperand::Tag(t) => t.name().to_string(),
    }
}

/// Structured Text; `top` leaves the outermost operation unbracketed.
fn st(e: &Expr, top: bool) -> String {
    let wrap = |s: String| if top { s } else { format!("({s})") };
    match e {
        Expr::Const(v) => if *v { "TRUE" } else { "FALSE" }.into(),
        Expr::Lit(s, negated) => {
            let text = match Comparison::of_signal(s) {
                Some(c) => format!("({} {} {})", c.lhs.name(), cmp_st(c.op), operand(&c.rhs)),
                None => s.name().to_string(),
            };
            if *negated {
                format!("NOT {text}")
            } else {
                text
            }
        }
        Expr::Not(inner) => format!("NOT {}", st(inner, false)),
        Expr::And(es) if es.len() == 1 => st(&es[0], top),
        Expr::Or(es) if es.len() == 1 => st(&es[0], top),
        Expr::And(es) => wrap(
            es.iter()
                .map(|x| st(x, false))
                .collect::<Vec<_>>()
                .join(" AND "),
        ),
        Expr::Or(es) => wrap(
            es.iter()
                .map(|x| st(x, false))
                .collect::<Vec<_>>()
                .join(" OR "),
        ),
    }
}

/// Instruction List: `e` combined into the current result with `op`
/// (`LD` to load it, `AND`, `OR`), deferred operations for anything but
/// a single contact.
fn il(e: &Expr, op: &str, out: &mut Vec<String>) {
    let simple = |e: &Expr| matches!(e, Expr::Lit(s, _) if Comparison::of_signal(s).is_none());
    match e {
        Expr::Const(v) => out.push(format!("{op:<4} {}", if *v { "TRUE" } else { "FALSE" })),
        Expr::Lit(s, negated) => match Comparison::of_signal(s) {
            None => {
                let op = if *negated {
                    format!("{op}N")
                } else {
                    op.to_string()
                };
                out.push(format!("{op:<4} {}", s.name()));
            }
            Some(c) => {
                let (open, close) = if op == "LD" {
                    (format!("LD   {}", c.lhs.name()), None)
                } else {
                    (
                        format!("{:<4} {}", format!("{op}("), c.lhs.name()),
                        Some(")"),
                    )
                };
                out.push(open);
                out.push(format!("{:<4} {}", cmp_il(c.op), operand(&c.rhs)));
                if *negated {
                    out.push("NOT".into());
                }
                if let Some(c) = close {
                    out.push(c.into());
                }
            }
        },
        Expr::Not(inner) => {
            if op == "LD" {
                il(inner, "LD", out);
                out.push("NOT".into());
            } else {
                out.push(format!("{op}N("));
                il(inner, "LD", out);
                out.push(")".into());
            }
        }
        Expr::And(es) | Expr::Or(es) if es.len() == 1 => il(&es[0], op, out),
        Expr::And(es) | Expr::Or(es) => {
            let inner = if matches!(e, Expr::And(_)) {
                "AND"
            } else {
                "OR"
            };
            // The same operation as the one combining it: no brackets.
            if op == "LD" || op == inner {
                il(&es[0], op, out);
                for x in &es[1..] {
                    il(x, inner, out);
                }
                return;
            }
            if simple(&es[0]) {
                // `OR( a` loads a inside the brackets.
                let mut first = Vec::new();
                il(&es[0], "LD", &mut first);
                let loaded = first[0]
                    .trim_start_matches("LDN")
                    .trim_start_matches("LD")
                    .trim();
                let negated = first[0].starts_with("LDN");
                if negated {
                    out.push(format!("{op}("));
                    out.extend(first);
                } else {
                    out.push(format!("{:<4} {loaded}", format!("{op}(")));
                }
            } else {
                out.push(format!("{op}("));
                il(&es[0], "LD", out);
            }
            for x in &es[1..] {
                il(x, inner, out);
            }
            out.push(")".into());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::super::robot;

    #[test]
    fn the_paper_term_for_t3_in_st_and_il() {
        let sfc = robot();
        let (c, t) = sfc.transition("F1", "t3").unwrap();
        let p = patch(&sfc, c, t, &Signal::new("%IX0.3.1"));
        assert!(
            p.contains("F1_t3_FIRE := (S2.X AND %IX0.0.3) OR (%IX0.3.1 AND %IX0.0.3);"),
            "{p}"
        );
        let il: Vec<&str> = p.lines().skip_while(|l| *l != "(* IL *)").skip(1).collect();
        assert_eq!(
            il,
            [
                "LD   S2.X",
                "AND  %IX0.0.3",
                "OR(  %IX0.3.1",
                "AND  %IX0.0.3",
                ")",
                "ST   F1_t3_FIRE"
            ]
        );
        // A convergence: every source step done, or forced.
        let (c, t) = sfc.transition("F2", "t12").unwrap();
        let p = patch(&sfc, c, t, &Signal::new("%IX0.3.1"));
        assert!(
            p.contains(
                "F2_t12_FIRE := (S6.X AND S9.X AND S12.X AND %IX0.1.3) OR (%IX0.3.1 AND %IX0.1.3);"
            ) && p.contains("F2.S6 + F2.S9 + F2.S12 -> F2.S13")
                && p.contains("its steps are done"),
            "{p}"
        );
    }

    #[test]
    fn a_negated_contact_a_comparison_and_a_step_number() {
        let text = r#"
[[chart]]
name = "F"
initial = "A"
step_word = "D300"
[[chart.step]]
name = "A"
number = 1
[[chart.step]]
name = "B"
number = 2
[[chart.transition]]
id = "t1"
from = "A"
to = "B"
condition = "-X1 * (X2 + D100 > 80)"
[[chart.transition]]
id = "t2"
from = "B"
to = "A"
condition = "X3"
"#;
        let sfc = super::super::text::parse("f.sfc.toml", text, &|_| true).unwrap();
        let (c, t) = sfc.transition("F", "t1").unwrap();
        let p = patch(&sfc, c, t, &Signal::new("FORCE"));
        assert!(
            p.contains(
                "F_t1_FIRE := ((D300 = 1) AND NOT X1 AND (X2 OR (D100 > 80))) OR (FORCE AND NOT X1 AND (X2 OR (D100 > 80)));"
            ),
            "{p}"
        );
        let il: Vec<&str> = p.lines().skip_while(|l| *l != "(* IL *)").skip(1).collect();
        assert_eq!(
            il,
            [
                "LD   D300",
                "EQ   1",
                "ANDN X1",
                "AND( X2",
                "OR(  D100",
                "GT   80",
                ")",
                ")",
                "OR(  FORCE",
                "ANDN X1",
                "AND( X2",
                "OR(  D100",
                "GT   80",
                ")",
                ")",
                ")",
                "ST   F_t1_FIRE"
            ]
        );
    }
}
