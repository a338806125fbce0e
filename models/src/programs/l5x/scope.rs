//! The bindings of one Add-On Instruction call (`aoi.rs` makes and reads
//! them): data only, so that the readers holding a call's scope (`mod.rs`,
//! `fbd.rs`) need nothing of the expansion itself.

use std::cell::RefCell;
use std::collections::{HashMap, HashSet};

/// The names an Add-On Instruction's logic uses, bound for one call.
pub(super) struct Scope {
    /// The instance tag's signal name (`Perm1`, `Program:Main.Perm1`).
    pub(super) instance: String,
    /// Lower-case parameter or local tag name → what it stands for.
    pub(super) bound: HashMap<String, Binding>,
    /// Inputs the logic has written (lower case): read from the member
    /// since.
    pub(super) written: RefCell<HashSet<String>>,
}

/// What a parameter or local tag of a definition stands for in one call.
pub(super) enum Binding {
    /// A member of the instance, by its path under it (`Out`,
    /// `LocalBool`, or an alias parameter's target).
    Member(String),
    /// An input given an operand: read as that operand until the logic
    /// writes the member.
    Input { member: String, argument: Argument },
    /// An `InOut`: the caller's tag itself, by reference.
    Reference(String),
}

/// An input's operand.
pub(super) enum Argument {
    /// The caller's tag, as a signal name.
    Signal(String),
    /// A number (`1`, `0`).
    Number(String),
}

/// Whether a name is read or written (an input's member is written,
/// never its operand).
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Access {
    /// Read.
    Read,
    /// Written.
    Write,
}
