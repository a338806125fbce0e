//! The logic graph: n-ary AND/OR blocks over signals, shared where the
//! program shares them.
//!
//! A [`Block`] is one step block of paper 000: one AND or OR node whose
//! terms are signals, constants or earlier blocks, each possibly negated.
//! Blocks are stored in an arena and referred to by index, so a relay used
//! twice is one block. This module owns the shapes and their evaluation; the
//! compiler that builds them is [`crate::program`].

pub use crate::programs::Op;
use crate::signal::Signal;

/// Index of a block in its arena.
pub type BlockId = usize;

/// One input of a block, or the root of a coil's logic.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Term {
    /// `TRUE` or `FALSE`.
    Const(bool),
    /// A signal, read as is or negated (a normally-closed contact).
    Signal {
        /// The signal read.
        signal: Signal,
        /// Read its negation.
        negated: bool,
    },
    /// An earlier block's value, as is or negated.
    Block {
        /// The block.
        id: BlockId,
        /// Read its negation.
        negated: bool,
    },
}

impl Term {
    /// A plain (normally-open) contact.
    pub fn signal(signal: Signal, negated: bool) -> Term {
        Term::Signal { signal, negated }
    }

    /// The same term, negated.
    #[must_use]
    pub fn negate(self) -> Term {
        match self {
            Term::Const(v) => Term::Const(!v),
            Term::Signal { signal, negated } => Term::Signal {
                signal,
                negated: !negated,
            },
            Term::Block { id, negated } => Term::Block {
                id,
                negated: !negated,
            },
        }
    }

    /// The term, negated when `negate` is true.
    #[must_use]
    pub fn negate_if(self, negate: bool) -> Term {
        if negate {
            self.negate()
        } else {
            self
        }
    }

    /// The term's value, given each signal's and each block's value.
    pub fn value(&self, signal: impl Fn(&Signal) -> bool, blocks: &[bool]) -> bool {
        match self {
            Term::Const(v) => *v,
            Term::Signal { signal: s, negated } => signal(s) != *negated,
            Term::Block { id, negated } => blocks[*id] != *negated,
        }
    }

    /// The term's value in three-valued (Kleene) logic: `None` is unknown.
    pub fn value3(
        &self,
        signal: impl Fn(&Signal) -> Option<bool>,
        blocks: &[Option<bool>],
    ) -> Option<bool> {
        match self {
            Term::Const(v) => Some(*v),
            Term::Signal { signal: s, negated } => signal(s).map(|v| v != *negated),
            Term::Block { id, negated } => blocks[*id].map(|v| v != *negated),
        }
    }
}

/// One AND or OR node: a step block.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Block {
    /// The operator joining the terms.
    pub op: Op,
    /// Its inputs, in program order; at least two.
    pub terms: Vec<Term>,
}

impl Block {
    /// The block's value given its terms' signal and block values.
    pub fn value(&self, signal: impl Fn(&Signal) -> bool, blocks: &[bool]) -> bool {
        match self.op {
            Op::And => self.terms.iter().all(|t| t.value(&signal, blocks)),
            Op::Or => self.terms.iter().any(|t| t.value(&signal, blocks)),
        }
    }

    /// The block's value in Kleene logic: an AND with a false term is
    /// false and an OR with a true term is true whatever the unknown terms
    /// hold; otherwise any unknown term makes it unknown.
    pub fn value3(
        &self,
        signal: impl Fn(&Signal) -> Option<bool>,
        blocks: &[Option<bool>],
    ) -> Option<bool> {
        // The value that decides the block on its own.
        let deciding = self.op == Op::Or;
        let mut unknown = false;
        for t in &self.terms {
            match t.value3(&signal, blocks) {
                Some(v) if v == deciding => return Some(deciding),
                Some(_) => {}
                None => unknown = true,
            }
        }
        (!unknown).then_some(!deciding)
    }
}
