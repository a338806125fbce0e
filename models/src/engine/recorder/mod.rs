//! The flight recorder: for each alarm raised, the changes of the signals
//! its check reads, from `before` ms before the raise to `after` ms after
//! it, so that the sequence that led to the fault is seen, not only its end
//! state ([`Recording`]; drawn as a timing chart by
//! [`Recording::timeline`]).
//!
//! It owns the ring of recent changes, the recordings under way and their
//! bounds. It does not own which signals a check reads
//! ([`super::CheckSet::reads`]), the tags' values (the engine hands each
//! change in, with the value before it) or where a recording goes (the
//! agent journals and publishes [`super::Step::recordings`]).
//!
//! # What is kept, and its bounds
//! - The ring keeps the changes of the tags some check reads — no other
//!   tag's — each with its source time, its tag, its value and the value
//!   before it (so that the value at a window's start is known without a
//!   copy of every tag). It holds the changes of the last `2 × before` ms
//!   (twice the window, for an alarm stamped earlier than the latest
//!   change: a delayed alarm announced when its delay ran out) and at most
//!   [`RecorderConfig::capacity`] of them: a flood of changes drops the
//!   oldest, and a window reaching back past them says so
//!   ([`Recording::holds_from`], [`Cut::Ring`]).
//! - A recording takes at most [`RecorderConfig::max_changes`] changes
//!   before the raise (the latest ones; [`Cut::Changes`] at its start) and
//!   as many after it (it ends at the first change past them;
//!   [`Cut::Changes`] at its end).
//! - At most [`RecorderConfig::max_open`] recordings follow the changes
//!   after their raise at once. An alarm raised while they all do gets what
//!   the ring holds up to its raise and is complete at once
//!   ([`Cut::Busy`] at its end): in an alarm flood the first alarms, the
//!   likely cause, keep their whole window.
//!
//! # Cost
//! A change of a tag no check reads costs one look at a flag. Any other
//! costs one push into the ring (O(1) amortised, nothing allocated once
//! the ring is full) and one look at a per-tag bit set of the recordings
//! that read the tag: an unrelated tag costs nothing more whatever is
//! recording, a read one one append per recording reading it. Starting a
//! recording walks back the read signals' own chains of changes in the
//! ring, merged newest first, and stops once it has the
//! [`RecorderConfig::max_changes`] latest before the raise: its cost is in
//! what the recording keeps (O(its changes × log its signals)), whatever
//! the ring holds.
//!
//! # Time
//! Changes come at their source time; one earlier than the latest kept is
//! taken at the latest (the ring stays in time order, as the engine's
//! checks do). A recording ends when a change comes from past its end, or
//! when the engine's clock passes it ([`super::CellEngine::advance`]): a
//! change of its window delivered later than that is not in it.

mod recording;
mod ring;
mod timeline;

#[cfg(test)]
mod tests;

pub use recording::{Cut, RecordedSignal, Recording, Sample, Truncated};
pub use ring::RecorderFill;
pub(crate) use ring::{Read, Recorder};

/// How many recordings may follow their changes at once, at most.
pub const MAX_OPEN: usize = 32;

/// What the flight recorder keeps ([`super::CellEngine::recording`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecorderConfig {
    /// How far before the raise a recording starts, ms.
    pub before: u64,
    /// How far after the raise it ends, ms.
    pub after: u64,
    /// How many changes the ring holds at most (at least 1). At 64 bytes a
    /// change, the default 65,536 is 4 MiB.
    pub capacity: usize,
    /// How many changes a recording takes at most on each side of the raise.
    pub max_changes: usize,
    /// How many recordings follow their changes at once, at most
    /// [`MAX_OPEN`].
    pub max_open: usize,
}

impl Default for RecorderConfig {
    /// 10 s before, 5 s after, 65,536 changes in the ring, 1,000 changes on
    /// each side of a raise, 16 recordings under way.
    fn default() -> Self {
        RecorderConfig {
            before: 10_000,
            after: 5_000,
            capacity: 65_536,
            max_changes: 1_000,
            max_open: 16,
        }
    }
}
