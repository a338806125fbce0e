//! What flows through a drawn network ([`Flow`]: contacts, series as AND,
//! parallel branches as OR with their common start factored out, what is
//! not boolean logic) and how a flow becomes IEC instructions ([`emit`];
//! a box read several times written once into a relay, [`shared`]) or ST
//! text (`st_text`, or why not: [`NotBoolean`]). It owns the flow, not how a body's connection graph
//! is walked to get it (`graph.rs`); the Rockwell and TIA Portal readers
//! build flows too.

use crate::programs::{Instruction, Op, Operand, Operation, Outside};
use crate::signal::Signal;
use crate::source::Location;

/// How deep a rung's connections may chain.
pub(crate) const MAX_DEPTH: usize = 512;

/// What flows out of an element (a TIA Portal part too: `simaticml`).
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Flow {
    True,
    False,
    /// A contact: its variable, negated, the element (for identity).
    Lit(Signal, bool, u64),
    And(Vec<Flow>),
    Or(Vec<Flow>),
    /// Not boolean logic: why, and where.
    Opaque(String, Location),
}

impl Flow {
    /// The flow as a series of parts (an AND's children, or itself).
    fn series(self) -> Vec<Flow> {
        match self {
            Flow::True => Vec::new(),
            Flow::And(parts) => parts,
            other => vec![other],
        }
    }

    /// The flow negated: a contact's negation flips, AND and OR swap (De
    /// Morgan); what is not boolean logic stays so.
    pub(crate) fn not(self) -> Flow {
        match self {
            Flow::True => Flow::False,
            Flow::False => Flow::True,
            Flow::Lit(s, negated, id) => Flow::Lit(s, !negated, id),
            Flow::And(parts) => Flow::or(parts.into_iter().map(Flow::not).collect()),
            Flow::Or(parts) => Flow::and(parts.into_iter().map(Flow::not).collect()),
            opaque @ Flow::Opaque(..) => opaque,
        }
    }

    /// Exclusive OR of two flows: `a·¬b + ¬a·b`.
    pub(crate) fn xor(a: Flow, b: Flow) -> Flow {
        Flow::or(vec![
            Flow::and(vec![a.clone(), b.clone().not()]),
            Flow::and(vec![a.not(), b]),
        ])
    }

    pub(crate) fn and(parts: Vec<Flow>) -> Flow {
        let mut out = Vec::new();
        for p in parts {
            out.extend(p.series());
        }
        match out.len() {
            0 => Flow::True,
            1 => out.pop().unwrap_or(Flow::True),
            _ => Flow::And(out),
        }
    }

    /// Parallel branches joining: their common start factored out.
    pub(crate) fn or(branches: Vec<Flow>) -> Flow {
        if branches.len() == 1 {
            return branches.into_iter().next().unwrap_or(Flow::True);
        }
        let series: Vec<Vec<Flow>> = branches.into_iter().map(Flow::series).collect();
        let mut common = 0;
        while series
            .iter()
            .all(|s| s.len() > common && s[common] == series[0][common])
        {
            common += 1;
        }
        let prefix: Vec<Flow> = series[0][..common].to_vec();
        let mut rest = Vec::new();
        for s in &series {
            let tail = Flow::and(s[common..].to_vec());
            if tail == Flow::True {
                // A branch that bypasses the rest: the OR is true.
                return Flow::and(prefix);
            }
            match tail {
                Flow::Or(inner) => rest.extend(inner),
                t => rest.push(t),
            }
        }
        let mut all = prefix;
        all.push(Flow::Or(rest));
        Flow::and(all)
    }
}

/// Emits the instructions that compute `flow`, starting a new result.
pub(crate) fn emit(flow: &Flow, at: Location, out: &mut Vec<Instruction>) {
    let ins = |operation: Operation, operand: Option<Operand>, text: String| Instruction {
        at,
        text: text.clone(),
        mnemonic: text.split(' ').next().unwrap_or("").to_string(),
        operation,
        operand,
        operand_at: at,
    };
    match flow {
        Flow::True => out.push(ins(
            Operation::Load {
                negated: false,
                push: false,
            },
            Some(Operand::Const(true)),
            "LD TRUE".into(),
        )),
        Flow::False => out.push(ins(
            Operation::Load {
                negated: false,
                push: false,
            },
            Some(Operand::Const(false)),
            "LD FALSE".into(),
        )),
        Flow::Lit(s, negated, _) => out.push(ins(
            Operation::Load {
                negated: *negated,
                push: false,
            },
            Some(Operand::Signal(s.clone())),
            format!("{} {s}", if *negated { "LDN" } else { "LD" }),
        )),
        Flow::Opaque(why, where_) => out.push(Instruction {
            at: *where_,
            text: why.clone(),
            mnemonic: why.clone(),
            operation: Operation::Outside(Outside::Call),
            operand: None,
            operand_at: *where_,
        }),
        Flow::And(parts) | Flow::Or(parts) => {
            let op = if matches!(flow, Flow::And(_)) {
                Op::And
            } else {
                Op::Or
            };
            let name = if op == Op::And { "AND" } else { "OR" };
            let Some((first, rest)) = parts.split_first() else {
                return;
            };
            emit(first, at, out);
            for p in rest {
                match p {
                    Flow::Lit(s, negated, _) => out.push(ins(
                        Operation::Logic {
                            op,
                            negated: *negated,
                        },
                        Some(Operand::Signal(s.clone())),
                        format!("{name}{} {s}", if *negated { "N" } else { "" }),
                    )),
                    other => {
                        out.push(ins(
                            Operation::Open {
                                op: Some(op),
                                negated: false,
                            },
                            None,
                            format!("{name}("),
                        ));
                        emit(other, at, out);
                        out.push(ins(Operation::Close, None, ")".into()));
                    }
                }
            }
        }
    }
}

/// Whether `flow` is boolean logic through and through (no part of it
/// opaque): what a shared box's relay may hold.
fn is_logic(flow: &Flow) -> bool {
    match flow {
        Flow::True | Flow::False | Flow::Lit(..) => true,
        Flow::And(parts) | Flow::Or(parts) => parts.iter().all(is_logic),
        Flow::Opaque(..) => false,
    }
}

/// A box whose output feeds several inputs, read as the IL reads an
/// internal relay: its logic written once into `relay` (at `at`, with
/// `mnemonic`, `ST` or `=`), each input reading the relay, so that the
/// switching function has one step block read twice, not two copies.
/// A single contact or a constant needs no relay, and logic that is not
/// boolean stays where it is read, so that it is said there.
pub(crate) fn shared(
    flow: Flow,
    relay: Signal,
    id: u64,
    at: Location,
    mnemonic: &str,
    out: &mut Vec<Instruction>,
) -> Flow {
    if !matches!(flow, Flow::And(_) | Flow::Or(_)) || !is_logic(&flow) {
        return flow;
    }
    emit(&flow, at, out);
    out.push(Instruction {
        at,
        text: format!("{mnemonic} {relay}"),
        mnemonic: mnemonic.to_string(),
        operation: Operation::Write { negated: false },
        operand: Some(Operand::Signal(relay.clone())),
        operand_at: at,
    });
    Flow::Lit(relay, false, id)
}

/// A flow that ST text cannot say: a part of it is not boolean logic.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the condition is not boolean logic: {why}")]
pub(super) struct NotBoolean {
    /// Why that part is not boolean logic, naming it.
    pub(super) why: String,
}

/// Writes `flow` as an ST expression.
///
/// # Errors
/// [`NotBoolean`] for a flow with a part that is not boolean logic.
pub(super) fn st_text(flow: &Flow, out: &mut String) -> Result<(), NotBoolean> {
    match flow {
        Flow::True => out.push_str("TRUE"),
        Flow::False => out.push_str("FALSE"),
        Flow::Lit(s, negated, _) => {
            if *negated {
                out.push_str("NOT ");
            }
            out.push_str(s.name());
        }
        Flow::And(parts) | Flow::Or(parts) => {
            let op = if matches!(flow, Flow::And(_)) {
                " AND "
            } else {
                " OR "
            };
            out.push('(');
            for (i, p) in parts.iter().enumerate() {
                if i > 0 {
                    out.push_str(op);
                }
                st_text(p, out)?;
            }
            out.push(')');
        }
        Flow::Opaque(why, _) => {
            return Err(NotBoolean { why: why.clone() });
        }
    }
    Ok(())
}
