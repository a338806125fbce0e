//! Switching functions (SF) and their step blocks (SSF), paper 000 §3.
//!
//! [`SwitchingFunction::expand`] writes one coil's logic in observable
//! signals: every coil that is not observable is replaced by the logic that
//! writes it, recursively; signals the program never writes are leaves; a
//! coil that depends on itself (self-holding circuit, `SET`/`RST` latch)
//! stays a leaf holding its own last value. The result's blocks are the step
//! blocks, numbered bottom-up (children before parents), so step 1 is
//! evaluated first and the last step is the coil. Printing flattens nested
//! blocks of the same operator for reading; the blocks keep the structure.

use std::collections::{HashMap, HashSet};
use std::fmt;

use crate::expr::Expr;
use crate::logic::{Block, BlockId, Term};
use crate::program::{NotDerivable, Program};
use crate::programs::Op;
use crate::signal::{Observability, Signal};

/// How deep relays and blocks may nest in one switching function.
const MAX_DEPTH: usize = 2000;

/// Why a coil has no switching function.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SfError {
    /// The program does not write that coil.
    #[error(
        "{origin}: unknown coil '{coil}': the program writes {}",
        list(written)
    )]
    UnknownCoil {
        /// The program's name.
        origin: String,
        /// The coil asked for.
        coil: Signal,
        /// What it does write.
        written: Vec<Signal>,
    },
    /// The coil, or a relay it depends on, is not boolean logic.
    #[error("{origin}:{}: {coil} is not derivable: {}{cause}", cause.at.line, via_text(via))]
    NotDerivable {
        /// The program's name.
        origin: String,
        /// The coil asked for.
        coil: Signal,
        /// The relays from the coil down to the one that is not derivable.
        via: Vec<Signal>,
        /// What makes it so.
        cause: Box<NotDerivable>,
    },
    /// Relays nest deeper than [`MAX_DEPTH`].
    #[error("{origin}: {coil}: its logic nests deeper than {limit} blocks")]
    TooDeep {
        /// The program's name.
        origin: String,
        /// The coil asked for.
        coil: Signal,
        /// The limit.
        limit: usize,
    },
}

fn list(signals: &[Signal]) -> String {
    if signals.is_empty() {
        return "no coil".into();
    }
    let shown: Vec<&str> = signals.iter().take(12).map(Signal::name).collect();
    let more = signals.len().saturating_sub(12);
    if more > 0 {
        format!("{} and {more} more", shown.join(", "))
    } else {
        shown.join(", ")
    }
}

fn via_text(via: &[Signal]) -> String {
    match via.last() {
        Some(last) if via.len() > 1 => format!("it reads {last}, which is "),
        _ => String::new(),
    }
}

/// Up to this many unknown signals, [`SwitchingFunction::certain`] tries
/// every completion (256 evaluations at most).
pub const EXACT_UNKNOWNS: usize = 8;

/// One coil's switching function over observable signals, as step blocks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SwitchingFunction {
    /// The coil.
    pub coil: Signal,
    /// The coil's value: usually the last step block.
    pub root: Term,
    /// Step blocks; `steps[i]` is step `i + 1`. Block terms refer to
    /// earlier steps by index.
    pub steps: Vec<Block>,
}

impl SwitchingFunction {
    /// The switching function of `coil` in `program`, over the signals
    /// `observable` allows.
    ///
    /// # Errors
    /// [`SfError`]: an unknown coil, a coil that is not derivable or reads a
    /// relay that is not, logic nested too deep.
    pub fn expand(
        program: &Program,
        coil: &Signal,
        observable: &Observability,
    ) -> Result<SwitchingFunction, SfError> {
        let origin = program.origin().to_string();
        let definition = match program.coil(coil) {
            Some(c) => c.definition.clone(),
            None => {
                return Err(SfError::UnknownCoil {
                    origin,
                    coil: coil.clone(),
                    written: program.coils().iter().map(|c| c.signal.clone()).collect(),
                })
            }
        };
        let definition = definition.map_err(|cause| SfError::NotDerivable {
            origin: origin.clone(),
            coil: coil.clone(),
            via: vec![coil.clone()],
            cause: Box::new(cause),
        })?;
        let mut x = Expander {
            program,
            observable,
            arena: Vec::new(),
            relays: HashMap::new(),
            blocks: HashMap::new(),
            expanding: vec![coil.clone()],
            depth: 0,
        };
        let root = x.term(&definition).map_err(|e| match e {
            Failure::NotDerivable { via, cause } => SfError::NotDerivable {
                origin: origin.clone(),
                coil: coil.clone(),
                via,
                cause: Box::new(cause),
            },
            Failure::TooDeep => SfError::TooDeep {
                origin: origin.clone(),
                coil: coil.clone(),
                limit: MAX_DEPTH,
            },
        })?;
        let (root, steps) = number_bottom_up(root, x.arena);
        Ok(SwitchingFunction {
            coil: coil.clone(),
            root,
            steps,
        })
    }

    /// A switching function for a plain expression (a condition written in
    /// a configuration, say), with one block per AND/OR node.
    pub fn from_expr(coil: Signal, expr: &Expr) -> SwitchingFunction {
        fn build(e: &Expr, arena: &mut Vec<Block>) -> Term {
            match e {
                Expr::Const(v) => Term::Const(*v),
                Expr::Lit(s, n) => Term::signal(s.clone(), *n),
                Expr::Not(inner) => build(inner, arena).negate(),
                Expr::And(es) | Expr::Or(es) if es.len() == 1 => build(&es[0], arena),
                Expr::And(es) | Expr::Or(es) => {
                    let op = if matches!(e, Expr::And(_)) {
                        Op::And
                    } else {
                        Op::Or
                    };
                    let terms = es.iter().map(|c| build(c, arena)).collect();
                    arena.push(Block { op, terms });
                    Term::Block {
                        id: arena.len() - 1,
                        negated: false,
                    }
                }
            }
        }
        let mut arena = Vec::new();
        let root = build(expr, &mut arena);
        let (root, steps) = number_bottom_up(root, arena);
        SwitchingFunction { coil, root, steps }
    }

    /// The distinct signals it reads, in order of first appearance from
    /// step 1 up.
    pub fn leaves(&self) -> Vec<Signal> {
        let mut seen = HashSet::new();
        let mut out = Vec::new();
        let terms = self
            .steps
            .iter()
            .flat_map(|b| b.terms.iter())
            .chain(std::iter::once(&self.root));
        for t in terms {
            if let Term::Signal { signal, .. } = t {
                if seen.insert(signal.clone()) {
                    out.push(signal.clone());
                }
            }
        }
        out
    }

    /// The coil's value and every step's value for the given signal values.
    pub fn evaluate(&self, value: impl Fn(&Signal) -> bool) -> (bool, Vec<bool>) {
        let mut steps = Vec::with_capacity(self.steps.len());
        for b in &self.steps {
            let v = b.value(&value, &steps);
            steps.push(v);
        }
        (self.root.value(&value, &steps), steps)
    }

    /// The coil's value and every step's value in three-valued (Kleene)
    /// logic, `None` being unknown: a value is known when every completion
    /// of the unknown signals gives it.
    pub fn evaluate3(
        &self,
        value: impl Fn(&Signal) -> Option<bool>,
    ) -> (Option<bool>, Vec<Option<bool>>) {
        let mut steps = Vec::with_capacity(self.steps.len());
        for b in &self.steps {
            let v = b.value3(&value, &steps);
            steps.push(v);
        }
        (self.root.value3(&value, &steps), steps)
    }

    /// The coil's value if every completion of the unknown signals gives
    /// the same one, `None` if they disagree. Kleene logic decides most
    /// cases at once; when it cannot (a contact read twice, `X + -X`) and
    /// at most [`EXACT_UNKNOWNS`] signals are unknown, every completion is
    /// tried. Beyond that it stays with Kleene's answer, which is never
    /// wrong but may be unknown where an exhaustive check would decide.
    pub fn certain(&self, value: impl Fn(&Signal) -> Option<bool>) -> Option<bool> {
        if let Some(v) = self.evaluate3(&value).0 {
            return Some(v);
        }
        let unknown: Vec<Signal> = self
            .leaves()
            .into_iter()
            .filter(|s| value(s).is_none())
            .collect();
        if unknown.is_empty() || unknown.len() > EXACT_UNKNOWNS {
            return None;
        }
        let mut seen = [false; 2];
        for bits in 0u32..1 << unknown.len() {
            let completed = |s: &Signal| {
                value(s).unwrap_or_else(|| {
                    unknown
                        .iter()
                        .position(|u| u == s)
                        .is_some_and(|i| bits >> i & 1 == 1)
                })
            };
            seen[usize::from(self.evaluate(completed).0)] = true;
            if seen[0] && seen[1] {
                return None;
            }
        }
        Some(seen[1])
    }

    /// The step blocks re-assembled into one expression tree.
    pub fn to_expr(&self) -> Expr {
        let mut built: Vec<Expr> = Vec::with_capacity(self.steps.len());
        for b in &self.steps {
            let children = b.terms.iter().map(|t| term_expr(t, &built)).collect();
            built.push(match b.op {
                Op::And => Expr::And(children),
                Op::Or => Expr::Or(children),
            });
        }
        term_expr(&self.root, &built)
    }

    /// The SF in the paper's notation: `X4 * -Y2 * ((X1 * -X2) + -X3) * -Y1`.
    pub fn notation(&self) -> String {
        self.print(&PAPER)
    }

    /// The SF in words: `X4 AND NOT Y2 AND ((X1 AND NOT X2) OR NOT X3) AND NOT Y1`.
    pub fn readable(&self) -> String {
        self.print(&WORDS)
    }

    /// Step `index` (1-based) in the paper's notation, earlier steps named
    /// `SSFn`: `SSF2 * -X200.00`.
    ///
    /// # Panics
    /// If `index` is not a step of this SF.
    pub fn step_notation(&self, index: usize) -> String {
        let block = &self.steps[index - 1];
        let sep = match block.op {
            Op::And => PAPER.and,
            Op::Or => PAPER.or,
        };
        let parts: Vec<String> = block
            .terms
            .iter()
            .map(|t| match t {
                Term::Block { id, negated } => {
                    format!("{}SSF{}", if *negated { "-" } else { "" }, id + 1)
                }
                other => leaf_text(other, &PAPER),
            })
            .collect();
        parts.join(sep)
    }

    fn print(&self, style: &Style) -> String {
        let mut out = String::new();
        self.print_term(&self.root, None, style, &mut out);
        out
    }

    fn print_term(&self, term: &Term, parent: Option<Op>, style: &Style, out: &mut String) {
        match term {
            Term::Block { id, negated } => {
                let block = &self.steps[*id];
                let flatten = !negated && parent == Some(block.op);
                let parens = !flatten && (parent.is_some() || *negated);
                if *negated {
                    out.push_str(style.not);
                }
                if parens {
                    out.push('(');
                }
                let sep = match block.op {
                    Op::And => style.and,
                    Op::Or => style.or,
                };
                for (i, t) in block.terms.iter().enumerate() {
                    if i > 0 {
                        out.push_str(sep);
                    }
                    self.print_term(t, Some(block.op), style, out);
                }
                if parens {
                    out.push(')');
                }
            }
            leaf => out.push_str(&leaf_text(leaf, style)),
        }
    }
}

impl fmt::Display for SwitchingFunction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} = {}", self.coil, self.notation())
    }
}

struct Style {
    and: &'static str,
    or: &'static str,
    not: &'static str,
}

const PAPER: Style = Style {
    and: " * ",
    or: " + ",
    not: "-",
};
const WORDS: Style = Style {
    and: " AND ",
    or: " OR ",
    not: "NOT ",
};

fn leaf_text(term: &Term, style: &Style) -> String {
    match term {
        Term::Const(v) => (if *v { "TRUE" } else { "FALSE" }).to_string(),
        Term::Signal {
            signal,
            negated: true,
        } => format!("{}{signal}", style.not),
        Term::Signal {
            signal,
            negated: false,
        } => signal.to_string(),
        Term::Block { id, .. } => format!("SSF{}", id + 1),
    }
}

fn term_expr(term: &Term, built: &[Expr]) -> Expr {
    let (e, negated) = match term {
        Term::Const(v) => return Expr::Const(*v),
        Term::Signal { signal, negated } => return Expr::Lit(signal.clone(), *negated),
        Term::Block { id, negated } => (built[*id].clone(), *negated),
    };
    if negated {
        Expr::Not(Box::new(e))
    } else {
        e
    }
}

enum Failure {
    NotDerivable {
        via: Vec<Signal>,
        cause: NotDerivable,
    },
    TooDeep,
}

struct Expander<'a> {
    program: &'a Program,
    observable: &'a Observability,
    /// Blocks of the SF, in creation order (renumbered at the end).
    arena: Vec<Block>,
    /// Relays already expanded: one block however often they are read.
    relays: HashMap<Signal, Term>,
    /// Program blocks already copied.
    blocks: HashMap<BlockId, Term>,
    /// The coils being expanded, outermost first: reading one of them again
    /// is a self-holding circuit.
    expanding: Vec<Signal>,
    depth: usize,
}

impl Expander<'_> {
    fn term(&mut self, term: &Term) -> Result<Term, Failure> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(Failure::TooDeep);
        }
        let out = match term {
            Term::Const(_) => Ok(term.clone()),
            Term::Signal { signal, negated } => self.signal(signal).map(|t| t.negate_if(*negated)),
            Term::Block { id, negated } => self.block(*id).map(|t| t.negate_if(*negated)),
        };
        self.depth -= 1;
        out
    }

    fn signal(&mut self, signal: &Signal) -> Result<Term, Failure> {
        let leaf = Term::signal(signal.clone(), false);
        let Some(coil) = self.program.coil(signal) else {
            return Ok(leaf);
        };
        if self.observable.is_observable(signal) || self.expanding.contains(signal) {
            return Ok(leaf);
        }
        if let Some(t) = self.relays.get(signal) {
            return Ok(t.clone());
        }
        let definition = coil
            .definition
            .clone()
            .map_err(|cause| Failure::NotDerivable {
                via: self
                    .expanding
                    .iter()
                    .cloned()
                    .chain([signal.clone()])
                    .collect(),
                cause,
            })?;
        self.expanding.push(signal.clone());
        // A relay is its own block: a block it shares with the coil's own
        // logic must not be merged with it.
        let saved = std::mem::take(&mut self.blocks);
        let expanded = self.term(&definition);
        self.blocks = saved;
        self.expanding.pop();
        let expanded = expanded?;
        self.relays.insert(signal.clone(), expanded.clone());
        Ok(expanded)
    }

    fn block(&mut self, id: BlockId) -> Result<Term, Failure> {
        if let Some(t) = self.blocks.get(&id) {
            return Ok(t.clone());
        }
        let source = &self.program.blocks()[id];
        let op = source.op;
        let mut terms = Vec::with_capacity(source.terms.len());
        for t in &source.terms {
            terms.push(self.term(t)?);
        }
        self.arena.push(Block { op, terms });
        let t = Term::Block {
            id: self.arena.len() - 1,
            negated: false,
        };
        self.blocks.insert(id, t.clone());
        Ok(t)
    }
}

/// Renumbers the blocks reachable from `root` in post-order (children
/// first), so that step `n` only reads steps before it.
fn number_bottom_up(root: Term, arena: Vec<Block>) -> (Term, Vec<Block>) {
    let mut new_id: Vec<Option<usize>> = vec![None; arena.len()];
    let mut order = Vec::new();
    if let Term::Block { id, .. } = root {
        // Iterative post-order: (block, next child to visit).
        let mut stack = vec![(id, 0usize)];
        while let Some((b, child)) = stack.pop() {
            if new_id[b].is_some() {
                continue;
            }
            let next = arena[b].terms[child..]
                .iter()
                .position(|t| matches!(t, Term::Block { id, .. } if new_id[*id].is_none()));
            match next {
                Some(offset) => {
                    let at = child + offset;
                    let Term::Block { id: c, .. } = arena[b].terms[at] else {
                        continue;
                    };
                    stack.push((b, at + 1));
                    stack.push((c, 0));
                }
                None => {
                    new_id[b] = Some(order.len());
                    order.push(b);
                }
            }
        }
    }
    let remap = |t: &Term| match t {
        Term::Block { id, negated } => Term::Block {
            id: new_id[*id].unwrap_or(*id),
            negated: *negated,
        },
        other => other.clone(),
    };
    let steps = order
        .iter()
        .map(|&b| Block {
            op: arena[b].op,
            terms: arena[b].terms.iter().map(remap).collect(),
        })
        .collect();
    (remap(&root), steps)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::programs::Dialect;

    const FIG6: &str =
        "RD X1\nANDN X2\nRDNS X3\nORS\nANDN Y1\nWR R1\nRD X4\nANDN Y2\nAND R1\nWR G0.00\n";

    fn sf(src: &str, coil: &str) -> SwitchingFunction {
        let p = Program::compile("t.il", src, None).unwrap();
        SwitchingFunction::expand(
            &p,
            &Signal::new(coil),
            &Observability::default_for(p.dialect()),
        )
        .unwrap()
    }

    #[test]
    fn fig6_prints_as_the_paper() {
        assert_eq!(sf(FIG6, "R1").notation(), "((X1 * -X2) + -X3) * -Y1");
        let g = sf(FIG6, "G0.00");
        assert_eq!(g.notation(), "X4 * -Y2 * ((X1 * -X2) + -X3) * -Y1");
        assert_eq!(
            g.readable(),
            "X4 AND NOT Y2 AND ((X1 AND NOT X2) OR NOT X3) AND NOT Y1"
        );
        // Three AND nodes and one OR node.
        let ands = g.steps.iter().filter(|b| b.op == Op::And).count();
        assert_eq!((ands, g.steps.len()), (3, 4));
        assert_eq!(g.step_notation(4), "X4 * -Y2 * SSF3");
    }

    #[test]
    fn self_holding_coil_stays_a_leaf() {
        // Start/stop circuit: R1 = (X1 + R1) * -X2, read through relay R2.
        let s = sf(
            "RD X1\nOR R1\nANDN X2\nWRT R1\nRD R1\nWRT R2\nRD R2\nAND X3\nWRT Y1",
            "Y1",
        );
        assert_eq!(s.notation(), "(X1 + R1) * -X2 * X3");
        let latch = sf("RD X1\nSET R5\nRD X2\nRST R5\nRD R5\nWRT Y0", "Y0");
        assert_eq!(latch.notation(), "-X2 * (X1 + R5)");
    }

    #[test]
    fn observable_list_stops_expansion() {
        let p = Program::compile("t.il", FIG6, None).unwrap();
        let o = Observability::parse(Dialect::Pmc, "X,Y,G,R").unwrap();
        let s = SwitchingFunction::expand(&p, &Signal::new("G0.00"), &o).unwrap();
        assert_eq!(s.notation(), "X4 * -Y2 * R1");
    }

    #[test]
    fn unknown_and_not_derivable_coils() {
        let p = Program::compile(
            "p.il",
            "RD X1\nWRT R1\nRD X2\nTMR 1\nWRT R2\nRD R2\nAND R1\nWRT Y1",
            None,
        )
        .unwrap();
        let o = Observability::default_for(Dialect::Pmc);
        let e = SwitchingFunction::expand(&p, &Signal::new("Y9"), &o).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.il: unknown coil 'Y9': the program writes R1, R2, Y1"
        );
        let e = SwitchingFunction::expand(&p, &Signal::new("Y1"), &o).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.il:4: Y1 is not derivable: it reads R2, which is computed by an instruction outside boolean logic (arithmetic, comparison, timer or counter) ('TMR 1' at line 4)"
        );
    }

    #[test]
    fn relay_read_twice_is_one_block() {
        let s = sf(
            "RD X1\nOR X2\nWRT R1\nRD R1\nAND X3\nRD.STK R1\nAND X4\nOR.STK\nWRT Y1",
            "Y1",
        );
        assert_eq!(s.steps.len(), 4);
        assert_eq!(s.step_notation(1), "X1 + X2");
        assert_eq!(s.step_notation(2), "SSF1 * X3");
        assert_eq!(s.step_notation(3), "SSF1 * X4");
    }
}
