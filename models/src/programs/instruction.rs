//! The one instruction set every dialect is lexed into.

use crate::signal::Signal;
use crate::source::Location;

/// A binary logic operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Op {
    /// Conjunction (`*` in the paper's notation).
    And,
    /// Disjunction (`+`).
    Or,
}

/// What an operand names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Operand {
    /// A boolean signal.
    Signal(Signal),
    /// `TRUE` or `FALSE`.
    Const(bool),
    /// Anything that is not a boolean (a number, a timer number, a label).
    Other(String),
}

/// Why an instruction leaves boolean logic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outside {
    /// A jump or conditional region: what follows may not run every scan.
    Jump,
    /// Arithmetic, comparison, timers, counters: the result is not a
    /// function of boolean signals.
    Arithmetic,
    /// A call of a function block or subroutine.
    Call,
    /// A word or accumulator instruction (STL `L`, `T`, `+I`): not
    /// boolean, but it leaves the boolean result alone.
    Word,
    /// A part of the program not read (an ST or FBD body); the
    /// instruction's text says which.
    Unread,
    /// A write to a function block instance's input (`ST T1.PT`, `S1 FF`,
    /// `R FF`): not a coil; the result is left as it is.
    BlockInput,
    /// A write through an indirect address (STL `= [AR1,P#6.0]`): some
    /// bit is written, which one is known only at run time. The result
    /// is left as it is.
    Indirect,
    /// A word instruction writing a number whose bits are coils (Logix
    /// `MOV(-1, Fail.Failures)` with `Fail.Overload` a BIT of it): the
    /// next write gives that coil a value that is not boolean logic.
    Bits,
}

/// One instruction, in either dialect.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Operation {
    /// Start a new result from the operand (`RD`, `LD`); `push` saves the
    /// current result on the stack first (`RD.STK`).
    Load {
        /// Load the operand's negation.
        negated: bool,
        /// Save the current result on the stack first.
        push: bool,
    },
    /// Combine the current result with the operand (`AND`, `ORN`, ...).
    Logic {
        /// The operator.
        op: Op,
        /// Use the operand's negation.
        negated: bool,
    },
    /// Exclusive or with the operand (IEC `XOR`, `XORN`).
    Xor {
        /// Use the operand's negation.
        negated: bool,
    },
    /// Pop the stack and combine it with the current result (`AND.STK`).
    Combine(Op),
    /// IEC deferred operation `AND(`, `ORN(`, `XOR(` ...: the operator waits
    /// for the matching `)`. An operand on the same line starts the inner
    /// result.
    Open {
        /// The deferred operator; `None` is exclusive or.
        op: Option<Op>,
        /// Negate the inner result before combining.
        negated: bool,
    },
    /// IEC `)`.
    Close,
    /// Negate the current result (IEC `NOT`).
    Not,
    /// Set the result to a constant (STL `SET`, `CLR`).
    Constant(bool),
    /// STL `O` alone: the result so far is one AND group of an OR; the
    /// next check starts the next group.
    OrGroups,
    /// Write the current result to a coil (`WRT`, `ST`); `negated` writes
    /// its negation (`WRT.NOT`, `STN`).
    Write {
        /// Write the negation.
        negated: bool,
    },
    /// Latch a coil on when the result is true (`SET`, `S`).
    Set,
    /// Latch a coil off when the result is true (`RST`, `R`).
    Reset,
    /// A jump target (IEC `label:`, PMC `LBL`).
    Label(String),
    /// An instruction outside boolean logic.
    Outside(Outside),
    /// An instruction with no effect on logic (PMC `END1`).
    Nothing,
    /// The end of a program organisation unit or Step 7 block
    /// (`END_FUNCTION_BLOCK`): jumps and labels stay inside it, and the
    /// next block starts with nothing loaded.
    EndBlock,
}

/// One parsed instruction and where it stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Instruction {
    /// Where the mnemonic starts.
    pub at: Location,
    /// The instruction as written, for messages (`AND.NOT X0.06`).
    pub text: String,
    /// The mnemonic as written.
    pub mnemonic: String,
    /// What it does.
    pub operation: Operation,
    /// Its operand, if it has one.
    pub operand: Option<Operand>,
    /// Where the operand starts.
    pub operand_at: Location,
}

impl Instruction {
    /// An instruction without an operand (a block's end, a part of the
    /// program not read), its operand placed where it stands.
    pub(crate) fn bare(at: Location, text: String, mnemonic: String, operation: Operation) -> Self {
        Instruction {
            at,
            text,
            mnemonic,
            operation,
            operand: None,
            operand_at: at,
        }
    }
}

/// Splits a line into whitespace-separated words with their byte offsets.
pub(crate) fn words(line: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, c) in line.char_indices() {
        match (c.is_whitespace(), start) {
            (true, Some(s)) => {
                out.push((s, &line[s..i]));
                start = None;
            }
            (false, None) => start = Some(i),
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, &line[s..]));
    }
    out
}
