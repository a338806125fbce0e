//! The compiler from instructions to the logic of every coil.
//!
//! [`Program::compile`] runs the instruction list as a PLC would, but on
//! expressions instead of values: the result register holds a [`Term`], the
//! stack holds saved terms, and every write defines a coil. Step blocks are
//! built the way the paper draws them: consecutive instructions with the
//! same operator extend a block; an operator change, a stack operation or a
//! write starts a new one.
//!
//! Semantics worth knowing:
//! - several writes to one coil: the last in scan order wins;
//! - `SET c` makes `c = result + c`, `RST c` makes `c = -result * c`, where
//!   `c` on the right is the coil's value so far in the scan (its own last
//!   value if nothing wrote it before);
//! - instructions outside boolean logic make the coils they affect *not
//!   derivable*: arithmetic, timers and calls poison the result until the
//!   next load; after a jump or conditional region, every later write is
//!   not derivable, since it may not run every scan.
//!
//! Expanding a coil into observable signals is [`crate::switching`]'s job.

mod compile;

use crate::comments::CommentDb;
use std::collections::HashMap;
use std::fmt;

use crate::logic::{Block, Term};
use crate::programs::Dialect;
use crate::signal::{AddressError, Signal};
use crate::source::Location;

/// Why a coil's logic cannot be derived from the program.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotDerivable {
    /// The instruction responsible.
    pub at: Location,
    /// That instruction as written.
    pub instruction: String,
    /// Why it breaks the derivation.
    pub reason: String,
}

impl fmt::Display for NotDerivable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} ('{}' at line {})",
            self.reason, self.instruction, self.at.line
        )
    }
}

/// A coil the program writes, with its logic as the program states it
/// (internal relays not yet expanded).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Coil {
    /// The coil.
    pub signal: Signal,
    /// Its logic, or why there is none.
    pub definition: Result<Term, NotDerivable>,
    /// Every write, in scan order; the last one defines the coil.
    pub writes: Vec<Location>,
}

/// A warning about an instruction that does not stop compilation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    /// Where.
    pub at: Location,
    /// What, quoting the instruction.
    pub message: String,
}

/// A compiled instruction list: every coil's logic over one block arena.
#[derive(Debug, Clone)]
pub struct Program {
    origin: String,
    dialect: Dialect,
    blocks: Vec<Block>,
    coils: Vec<Coil>,
    index: HashMap<Signal, usize>,
    warnings: Vec<Warning>,
    documentation: CommentDb,
}

impl Program {
    /// The comments the program's own declarations carry (`Start : BOOL;
    /// (* Start button *)`, PLCopen XML variables' documentation): an I/O
    /// database a CSV file may add to and override.
    pub fn documentation(&self) -> &CommentDb {
        &self.documentation
    }

    /// The name the program was compiled under.
    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// The dialect it is written in.
    pub fn dialect(&self) -> Dialect {
        self.dialect
    }

    /// Every coil written, in order of first write.
    pub fn coils(&self) -> &[Coil] {
        &self.coils
    }

    /// The coil `signal`, if the program writes it.
    pub fn coil(&self, signal: &Signal) -> Option<&Coil> {
        self.index.get(signal).map(|&i| &self.coils[i])
    }

    /// The block arena the coils' terms refer to.
    pub fn blocks(&self) -> &[Block] {
        &self.blocks
    }

    /// Warnings about instructions outside boolean logic.
    pub fn warnings(&self) -> &[Warning] {
        &self.warnings
    }

    /// The canonical signal for a name as a user types it: the dialect's
    /// address form, and for IEC symbols the program's own spelling.
    ///
    /// # Errors
    /// [`AddressError`] quoting a malformed address.
    pub fn resolve(&self, text: &str) -> Result<Signal, AddressError> {
        let signal = self.dialect.signal(text.trim())?;
        if self.dialect == Dialect::Iec {
            if let Some(s) = self.spelled(&signal) {
                return Ok(s);
            }
        }
        Ok(signal)
    }

    fn spelled(&self, signal: &Signal) -> Option<Signal> {
        let mut seen = self
            .coils
            .iter()
            .map(|c| &c.signal)
            .chain(self.blocks.iter().flat_map(|b| {
                b.terms.iter().filter_map(|t| match t {
                    Term::Signal { signal, .. } => Some(signal),
                    _ => None,
                })
            }));
        seen.find(|s| s.name().eq_ignore_ascii_case(signal.name()))
            .cloned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::programs::Op;

    fn compile(src: &str) -> Program {
        Program::compile("t.il", src, None).unwrap()
    }

    fn err(src: &str) -> String {
        Program::compile("p.il", src, None).unwrap_err().to_string()
    }

    #[test]
    fn same_operator_extends_a_block() {
        let p = compile("RD X1\nAND X2\nAND.NOT X3\nWRT Y1");
        assert_eq!(p.blocks().len(), 1);
        assert_eq!(p.blocks()[0].terms.len(), 3);
    }

    #[test]
    fn operator_change_and_stack_start_new_blocks() {
        let p = compile("RD X1\nAND X2\nOR X3\nRD.STK X4\nOR X5\nAND.STK\nAND X6\nWRT Y1");
        // AND(X1,X2); OR(b0,X3); OR(X4,X5); AND(b1,b2,X6)
        assert_eq!(p.blocks().len(), 4);
        assert_eq!(p.blocks()[3].terms.len(), 3);
    }

    #[test]
    fn last_write_wins() {
        let p = compile("RD X1\nWRT Y1\nRD X2\nWRT Y1");
        let c = p.coil(&Signal::new("Y1")).unwrap();
        assert_eq!(c.definition, Ok(Term::signal(Signal::new("X2"), false)));
        assert_eq!(c.writes.len(), 2);
    }

    #[test]
    fn set_and_reset_latch_on_the_coils_own_value() {
        let p = compile("RD X1\nSET R1\nRD X2\nRST R1");
        let c = p.coil(&Signal::new("R1")).unwrap();
        // R1 = -X2 * (X1 + R1)
        let Ok(Term::Block { id, negated: false }) = c.definition.clone() else {
            panic!()
        };
        assert_eq!(p.blocks()[id].op, Op::And);
        assert_eq!(
            p.blocks()[id].terms[0],
            Term::signal(Signal::new("X2"), true)
        );
    }

    #[test]
    fn structural_errors_are_pinned() {
        assert_eq!(
            err("AND.STK\n"),
            "p.il:1:1: 'AND.STK' with nothing on the stack: no RD.STK before it"
        );
        assert_eq!(
            err("WRT Y1\n"),
            "p.il:1:1: 'WRT Y1' with no result to write: no load (RD/LD) before it"
        );
        assert_eq!(
            err("AND X1\nWRT Y1"),
            "p.il:1:1: 'AND X1' with no result to combine: no load (RD/LD) before it"
        );
        assert_eq!(
            err("RD X1\nRD.STK X2\nWRT Y1"),
            "p.il:3:1: unbalanced stack at 'WRT Y1': 'RD.STK X2' at line 2 pushed a result that is never combined (AND.STK/OR.STK)"
        );
        assert_eq!(
            err("RD X1\nRD.STK X2\n"),
            "p.il:2:1: unbalanced stack: 'RD.STK X2' pushes a result that is never combined (AND.STK/OR.STK)"
        );
        assert_eq!(err("LD a\n)\nST b"), "p.il:2:1: ')' closes no '('");
        assert_eq!(
            err("LD a\nAND( b\nST c"),
            "p.il:3:1: unbalanced parentheses at 'ST c': 'AND( b' at line 2 is never closed with ')'"
        );
        assert_eq!(
            err("LD a\nAND( b\n"),
            "p.il:2:1: unbalanced parentheses: 'AND( b' is never closed with ')'"
        );
    }

    #[test]
    fn outside_boolean_logic_is_not_derivable() {
        let p = compile("LD a\nST b\nLD %MW1\nGT 5\nST c\nLD x\nST d\nJMPC skip\nLD y\nST e\nskip: LD z\nST b\n");
        let d = |n: &str| p.coil(&Signal::new(n)).unwrap().definition.clone();
        assert!(d("d").is_ok());
        let c = d("c").unwrap_err();
        assert_eq!(c.instruction, "GT 5");
        assert_eq!(d("e").unwrap_err().instruction, "JMPC skip");
        // b is written again after the jump.
        assert!(d("b").is_err());
        assert_eq!(p.warnings().len(), 2);
        assert_eq!(
            p.warnings()[0].message,
            "'GT 5': instruction outside boolean logic: the coils it feeds are not derivable"
        );
    }

    #[test]
    fn iec_parentheses_and_xor() {
        let p = compile("LD a\nANDN( b\nOR c\n)\nXOR d\nST q");
        assert!(p.coil(&Signal::new("q")).unwrap().definition.is_ok());
        // AND(a, -OR(b,c)) then XOR expansion: 3 blocks more.
        assert_eq!(p.blocks().len(), 5);
    }
}
