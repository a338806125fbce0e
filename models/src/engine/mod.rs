//! The per-cell engine: tag state, checks, alarms and machine state.
//!
//! [`CellEngine`] is fed tag values (with their quality), connection changes,
//! the passing of time and operator commands. Each input returns one
//! [`EngineStep`]: the alarm transitions and machine-state changes it caused, the
//! measurements the checks made, duplicates ignored, the change in the
//! number of unknown tags and the parts produced. The agent never reads the
//! engine back to learn what changed.
//!
//! # Layout
//! - [`checks`]: the [`CheckSet`] trait every check kind implements.
//! - [`switching`]: switching-function checks (paper 000).
//! - `alarms`: the alarm book (findings → ISA-18.2 transitions).
//! - [`recorder`]: the flight recorder (the changes around each raise).
//! - [`state`]: machine state and history-row kinds.
//!
//! This file holds the engine's types; [`CellEngine`]'s methods are split
//! by concern, one room a file:
//! - `build`: building the engine from its tags, check sets and rules, and
//!   the settings that follow (`relating`, `counting`, `delaying`, …).
//! - `reading`: taking the values the source delivers (duplicates, time
//!   order, quality), one or a publish at a time.
//! - `changes`: what a tag's value changing does (unknown count, parts,
//!   exported gauges, work order, comparisons, the checks fed).
//! - `connection`: the connection up and down, gaps, a resumed source.
//! - `delays`: on- and off-delays, alarm time stamps, the next deadline and
//!   time passing (`advance`).
//! - `announce`: findings applied to the alarm book and put in the step,
//!   consequences, the engine's own alarms, the machine state.
//! - `operators`: acknowledge, shelve, out of service, reset.
//! - `restore`: what a restart or a reload takes back.
//! - `snapshot`: what the engine holds, read back (values, alarms, the
//!   values at the last fault).
//! - `recording`: the engine's side of the flight recorder.
//! - `conditions`: the PLC's own alarms ([`PlcCondition`]).
//! - `catalogue`: every alarm the engine can raise, described for the
//!   master alarm database ([`CatalogueEntry`]).
//! - `rationale`: the master alarm database's priorities and guidance
//!   ([`crate::madb::Rationalised`]).
//! - `modes`: machine modes and the alarms each suppresses by design
//!   ([`Mode`]).
//!
//! Rules that keep alarms honest:
//! - a tag whose value is unknown (bad or uncertain quality, or the
//!   connection is down) is a third value: a switching check raises only a
//!   fault that is certain whatever the unknown contacts hold (naming
//!   them), clears only on known values, and otherwise holds its verdict;
//!   timers suspend on unknown signals they read;
//! - a lost connection is one `communication` alarm, not one per tag;
//! - a value delivered twice (the same value with the same or an older
//!   source timestamp, as after a subscription is recreated) is ignored;
//! - a reading whose source timestamp is earlier than one already seen
//!   (out of order: publishes crossing, a PLC clock set back) is taken at
//!   the latest time seen, so that no check sees time go back, and counted
//!   ([`Step::out_of_order`]); checks that measure time between changes
//!   measure nothing through it ([`CheckSet::on_change_out_of_order`]).
//!
//! Every counter the agent reports (unknown tags, duplicates, active fault
//! alarms) is kept incrementally: the cost of a reading does not grow with
//! the number of tags or alarms.
//!
//! Time is a count of milliseconds since the Unix epoch, passed in.

mod alarms;
mod announce;
mod build;
mod catalogue;
mod changes;
pub mod checks;
mod conditions;
mod connection;
mod delays;
#[cfg(test)]
mod fixture;
mod modes;
mod operators;
mod rationale;
mod reading;
pub mod recorder;
mod recording;
mod restore;
mod settling;
mod snapshot;
pub mod state;
pub mod switching;
mod tag;

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

pub use crate::alarm::AlarmPattern;
pub use catalogue::CatalogueEntry;
pub use checks::{CheckSet, Declared, Finding, Observation, WindowPosition};
pub use conditions::{PlcCondition, ACKED_AT_PLC};
pub use modes::Mode;
pub use recorder::{
    Cut, RecordedSignal, RecorderConfig, RecorderFill, Recording, Sample, Truncated,
};
pub use state::{HistoryKind, MachineState, StateName, StateRules};
pub use switching::{SwitchingCheck, SwitchingChecks};
pub use tag::{Tag, Value};

use crate::alarm::{Alarm, AlarmKind, Transition};
use crate::comments::CommentDb;
use crate::consequence::Relation;
use crate::signal::Signal;
use crate::value::{Counter, Num, ValueType};
use alarms::AlarmBook;
use recorder::Recorder;

/// How often the `tag-quality` alarm's text is brought up to date while
/// other tags go bad or good and it stays active, ms.
const QUALITY_UPDATE_MS: u64 = 10_000;

/// A tag's value as delivered by the source.
#[derive(Debug, Clone, PartialEq)]
pub enum Reading {
    /// A good boolean (a contact, or one bit of an integer word).
    Good(bool),
    /// A good number.
    Number(Num),
    /// A good string.
    Text(Arc<str>),
    /// Bad or uncertain quality: the value is not to be trusted.
    Bad,
    /// Out of reach (a unit on a serial bus that stopped answering): the
    /// value is unknown, and the source's own communication alarm says
    /// why, so it is not a quality problem of the tag.
    Unreachable,
    /// A value of another type than the tag is used as: bad quality, and
    /// the `tag-quality` alarm says what came.
    WrongType {
        /// The type the tag is configured with.
        expected: ValueType,
        /// The type the server sent (`None`: one cellwatch does not read,
        /// such as an array).
        received: Option<ValueType>,
    },
}

/// One delivered value: which tag, what, and when the PLC saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct TagReading {
    /// Index into the engine's tags.
    pub tag: usize,
    /// The value, or bad quality.
    pub reading: Reading,
    /// Source timestamp, ms since the epoch.
    pub source_time: u64,
}

/// What one change tells the sinks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EngineEvent {
    /// An alarm changed.
    Alarm {
        /// The alarm after the change.
        alarm: Alarm,
        /// What changed.
        transition: Transition,
        /// When, ms since the epoch.
        at: u64,
    },
    /// The machine state changed.
    State {
        /// The new state.
        state: MachineState,
        /// The history row kind.
        kind: HistoryKind,
        /// When.
        at: u64,
    },
    /// A machine mode began (`entered`) or ended ([`Mode`]).
    Mode {
        /// The mode's id.
        mode: String,
        /// Whether it began.
        entered: bool,
        /// When.
        at: u64,
    },
}

/// Everything one input to the engine did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EngineStep {
    /// Alarm transitions and state changes, in order.
    pub events: Vec<EngineEvent>,
    /// Measurements the checks made (transition durations).
    pub observations: Vec<Observation>,
    /// Values received (including duplicates).
    pub readings: u64,
    /// Values ignored as duplicates.
    pub duplicates: u64,
    /// Values whose source timestamp was earlier than one already seen,
    /// taken at the latest time seen.
    pub out_of_order: u64,
    /// Changes of value (or to unknown) fed to the checks.
    pub evaluations: u64,
    /// Change in the number of tags whose value is unknown.
    pub unknown_delta: i64,
    /// Parts produced, `(source time, how many)`: rising edges of the
    /// part-done tag (one each), or a counter tag's increments.
    pub parts: Vec<(u64, u64)>,
    /// Parts rejected, `(source time, how many)`: rising edges of the
    /// reject tag, or its counter's increments.
    pub rejects: Vec<(u64, u64)>,
    /// New values of the tags exported as gauges (`None`: unknown).
    pub exported: Vec<(usize, Option<f64>)>,
    /// The work order changed (item code or target quantity): the new one.
    pub order: Option<Order>,
    /// Gaps in the source's delivery: changes lost for good (a sequence
    /// gap the server could not fill, a queue that overflowed).
    pub gaps: u64,
    /// Values the source knows were lost (dropped from a full queue).
    pub lost_values: u64,
    /// Tags that went from good to bad or uncertain quality.
    pub went_bad: u64,
    /// Flight recordings complete ([`CellEngine::recording`]): one per
    /// alarm raised whose check reads signals, once its window is over.
    pub recordings: Vec<Recording>,
}

/// What the cell is making: the item (mould, product) code and the target
/// quantity, as the machine says (paper 002's `RJ` / `RT`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Order {
    /// The item code, if known.
    pub item: Option<String>,
    /// The target quantity, if known.
    pub target: Option<u64>,
}

impl EngineStep {
    /// Whether nothing the sinks care about happened.
    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
            && self.observations.is_empty()
            && self.readings == 0
            && self.unknown_delta == 0
            && self.parts.is_empty()
            && self.rejects.is_empty()
            && self.exported.is_empty()
            && self.order.is_none()
            && self.recordings.is_empty()
    }

    /// The alarm transitions.
    pub fn alarms(&self) -> impl Iterator<Item = (&Alarm, Transition, u64)> {
        self.events.iter().filter_map(|e| match e {
            EngineEvent::Alarm {
                alarm,
                transition,
                at,
            } => Some((alarm, *transition, *at)),
            EngineEvent::State { .. } | EngineEvent::Mode { .. } => None,
        })
    }

    /// The machine-state changes.
    pub fn states(&self) -> impl Iterator<Item = (&MachineState, HistoryKind, u64)> {
        self.events.iter().filter_map(|e| match e {
            EngineEvent::State { state, kind, at } => Some((state, *kind, *at)),
            EngineEvent::Alarm { .. } | EngineEvent::Mode { .. } => None,
        })
    }

    /// The machine modes entered (`true`) or left, with their time.
    pub fn modes(&self) -> impl Iterator<Item = (&str, bool, u64)> {
        self.events.iter().filter_map(|e| match e {
            EngineEvent::Mode { mode, entered, at } => Some((mode.as_str(), *entered, *at)),
            EngineEvent::Alarm { .. } | EngineEvent::State { .. } => None,
        })
    }
}

/// Why the engine cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EngineError {
    /// A check or rule reads an address no tag provides.
    #[error("{reader} reads {address}, but no tag has that address")]
    MissingTag {
        /// The check or rule.
        reader: String,
        /// The address.
        address: Signal,
    },
}

/// The values at the last fault, for the snapshot service.
#[derive(Debug, Clone, PartialEq)]
pub struct FaultValues {
    /// The alarm raised.
    pub alarm: String,
    /// When.
    pub at: u64,
    /// Every tag's value then (`None`: unknown).
    pub values: Vec<Option<Value>>,
}

/// The last fault, kept as what has changed since: raising a fault costs
/// nothing per tag, and each tag's first change afterwards logs the value
/// it had (at most one entry per tag). The values at the fault are the
/// current ones with the log undone ([`CellEngine::last_fault`]).
#[derive(Debug, Clone, Default)]
struct FaultMark {
    alarm: String,
    at: u64,
    /// Each changed boolean tag's value at the fault (8 bytes an entry,
    /// nothing to drop: starting over is free however many there are).
    undo_bools: Vec<(u32, Option<bool>)>,
    /// Each other changed tag's value at the fault.
    undo_others: Vec<(u32, Option<Value>)>,
    /// Per tag, one bit: whether the log has it.
    logged: Vec<u64>,
}

impl FaultMark {
    /// Starts over for a fault `alarm` raised at `at`, keeping the
    /// allocations: one bit a tag to clear (12.5 kB at 100,000 tags),
    /// whatever changed since the last fault.
    fn restart(&mut self, alarm: String, at: u64, tags: usize) {
        self.logged.clear();
        self.logged.resize(tags.div_ceil(64), 0);
        self.undo_bools.clear();
        self.undo_others.clear();
        self.alarm = alarm;
        self.at = at;
    }

    /// Whether `tag` still needs its value at the fault logged (and marks
    /// it logged).
    fn first_change(&mut self, tag: usize) -> bool {
        let (word, bit) = (tag / 64, 1u64 << (tag % 64));
        let fresh = self.logged[word] & bit == 0;
        self.logged[word] |= bit;
        fresh
    }
}

/// How the engine counts parts.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum PartCounting {
    /// It does not.
    #[default]
    None,
    /// Each rising edge of this boolean tag is one part.
    Edge(usize),
    /// These integer tags count parts (one per machine of the cell); the
    /// parts are the sum of their increments, wrap-around and resets
    /// recognised.
    Counters(Vec<(usize, Counter)>),
}

/// The configured tags' values and times when the connection was lost.
#[derive(Debug, Clone)]
struct AtCut {
    values: Vec<Option<bool>>,
    others: Vec<Option<Value>>,
    timestamps: Vec<Option<u64>>,
}

/// The wait for the first values after a connection (`settling.rs`).
#[derive(Debug, Clone)]
struct Settling {
    /// The clock time the wait ends at the latest.
    until: u64,
    /// The faults found meanwhile, in the order found.
    held: Vec<Held>,
}

/// A fault found while the first values come, held until they have.
#[derive(Debug, Clone)]
struct Held {
    finding: Finding,
    /// The source time it was first seen at.
    at: u64,
    /// The clock time it was first seen at.
    seen: u64,
    /// Why its trigger is uncertain, if it was judged across lost changes.
    uncertain: Option<String>,
}

/// Tags whose changes may have been lost, and the latest gap's reason.
#[derive(Debug, Clone)]
struct Lost {
    tags: Vec<bool>,
    why: String,
}

/// Marks a finding judged across a gap: no contact is named its trigger,
/// and the message says why.
fn uncertain_trigger(f: &mut Finding, why: &str) {
    if matches!(f.kind, AlarmKind::Communication | AlarmKind::System)
        || f.message.contains("(trigger uncertain")
    {
        return;
    }
    for c in &mut f.culprits {
        c.trigger = false;
    }
    f.message = format!("{} (trigger uncertain: {why})", f.message);
}

/// A comparison contact computed from numeric tags.
#[derive(Debug, Clone)]
struct Derived {
    /// Its own (boolean) tag index.
    tag: usize,
    lhs: usize,
    op: crate::value::CmpOp,
    rhs: Rhs,
}

#[derive(Debug, Clone)]
enum Rhs {
    Const(Num),
    Tag(usize),
}

/// A list of indices per tag, kept flat: tag `t`'s are
/// `items[starts[t]..starts[t + 1]]`. A tag costs one `u32`, not a vector.
#[derive(Debug, Clone, Default)]
struct PerTag {
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl PerTag {
    /// The lists of `n` tags from `(tag, item)` pairs; each tag's items in
    /// the order given.
    fn build(n: usize, pairs: &[(usize, usize)]) -> PerTag {
        let mut starts = vec![0u32; n + 1];
        for &(t, _) in pairs {
            starts[t + 1] += 1;
        }
        for t in 0..n {
            starts[t + 1] += starts[t];
        }
        let mut next = starts.clone();
        let mut items = vec![0u32; pairs.len()];
        for &(t, item) in pairs {
            items[next[t] as usize] = item as u32;
            next[t] += 1;
        }
        PerTag { starts, items }
    }

    /// Tag `t`'s items.
    fn of(&self, t: usize) -> &[u32] {
        &self.items[self.starts[t] as usize..self.starts[t + 1] as usize]
    }
}

/// Why a tag's quality is bad.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BadQuality {
    /// The source said so (a bad or uncertain status).
    Status,
    /// A value of another type than the tag is used as: the type the tag
    /// is configured with, and the one that came.
    WrongType(ValueType, Option<ValueType>),
    /// A number that is not one: `NaN`, `+inf` or `-inf`.
    NotFinite(&'static str),
}

/// What a reload carries from one engine to the next
/// ([`CellEngine::carry_over`], [`CellEngine::take_over`]).
#[derive(Debug, Clone)]
pub struct Carried {
    /// Every alarm not back to normal, shelved or out of service.
    pub alarms: Vec<Alarm>,
    /// The machine state.
    pub state: MachineState,
    /// The connection, if the source has said.
    pub connected: Option<bool>,
    /// Each known tag's value (or bad quality) by address, with its source
    /// time.
    pub readings: Vec<(Signal, Reading, u64)>,
}

/// One cell's engine.
pub struct CellEngine {
    cell: String,
    /// The configured tags, then one per comparison contact.
    tags: Vec<Tag>,
    /// How many tags are configured (the rest are comparisons).
    configured: usize,
    /// Every tag's index, ordered by address (found by binary search).
    by_address: Vec<u32>,
    /// Booleans: the fast path.
    values: Vec<Option<bool>>,
    /// Numbers and strings (`None` for boolean tags).
    others: Vec<Option<Value>>,
    timestamps: Vec<Option<u64>>,
    /// The latest source timestamp seen: the checks' time never goes
    /// back from it.
    latest: Option<u64>,
    /// The reading being handled came out of time order.
    untimed: bool,
    /// Tags whose changes may have been lost, until their next value.
    lost: Option<Lost>,
    /// Why the tag of the reading being handled may have lost changes.
    lost_now: Option<String>,
    /// The values and their times when the connection was lost, for a
    /// source that resumes without losing a change.
    at_cut: Option<Box<AtCut>>,
    /// How far behind the agent's clock a source time is trusted as the
    /// time of an alarm judged on it, ms (0: alarms are stamped by the
    /// agent's clock).
    source_trust: u64,
    /// Tags of bad quality, and why.
    bad: BTreeMap<usize, BadQuality>,
    /// Connection losses in the `communication` alarm's occurrence (or
    /// the last loss, while it is not active).
    losses: u64,
    /// Tags that went bad in the `tag-quality` alarm's occurrence.
    went_bad: u64,
    /// When the `tag-quality` alarm was last said (clock, ms), and whether
    /// its tags changed since: its text is brought up to date at most
    /// every [`QUALITY_UPDATE_MS`].
    quality_said: u64,
    quality_unsaid: bool,
    /// How many tags are unknown now.
    unknown: usize,
    sets: Vec<Box<dyn CheckSet>>,
    /// Per tag: the check sets that read it.
    readers: PerTag,
    /// Per tag: the check sets that read it as a number.
    number_readers: PerTag,
    /// Comparison contacts.
    derived: Vec<Derived>,
    /// Per tag: the comparisons that read it.
    compared_in: PerTag,
    /// Per tag: whether the running rule or a mode reads it.
    running_reads: Vec<bool>,
    /// Per mode of `rules.modes`: whether it holds.
    modes_on: Vec<bool>,
    /// The cell's master alarm database: priorities and guidance.
    rationale: crate::madb::Rationalisation,
    alarms: AlarmBook,
    /// `None` until the source first says.
    connected: Option<bool>,
    rules: StateRules,
    state: MachineState,
    last_fault: Option<FaultMark>,
    parts: PartCounting,
    /// How rejects are counted (OEE's quality).
    rejects: PartCounting,
    /// Per configured tag: whether its changes go to [`Step::exported`].
    exported: Vec<bool>,
    /// Per alarm id: how long its condition must hold to raise and be gone
    /// to clear, ms.
    delays: HashMap<String, (u64, u64)>,
    /// Findings waiting out their delay, by alarm id, with since when.
    /// (since when by the clock, since when in source time, finding): the
    /// clock decides when nothing arrives (`advance`), source time between
    /// values delivered together (`run_out`): neither is compared with the
    /// other, so a PLC clock off the agent's bends no delay.
    pending: BTreeMap<String, (u64, u64, Finding)>,
    /// The tags of the item code and the target quantity.
    order_tags: (Option<usize>, Option<usize>),
    /// The work order now.
    order: Order,
    /// The tags' comments (I/O list), by address, for messages.
    comments: CommentDb,
    /// Which alarms may follow from which ([`crate::consequence`]).
    relation: Relation,
    /// Consequences are not annunciated (journaled, shown as suppressed).
    suppress: bool,
    /// The flight recorder, if configured.
    recorder: Option<Box<Recorder>>,
    /// When the machine state last changed (its history row's time).
    state_at: u64,
    /// The PLC's conditions are alarms whose ids start with one of these
    /// (`<prefix>-`).
    conditions: Vec<String>,
    /// Configured tags not heard (a value or a bad status) since the
    /// connection came up.
    unheard: usize,
    /// The wait for the first values after a connection
    /// (`settling.rs`), while it lasts.
    settling: Option<Box<Settling>>,
    /// Built, or the connection lost: the next link's first sign begins
    /// the wait for its first values.
    awaiting_first: bool,
    /// The agent's clock at the readings being handled (ms): the flight
    /// recorder keeps their changes at the time their alarms are stamped
    /// with, so that a PLC clock not believed leaves no recording empty.
    clock: u64,
}
