//! The per-cell engine: tag state, checks, alarms and machine state.
//!
//! [`CellEngine`] is fed tag values (with their quality), connection changes,
//! the passing of time and operator commands. Each input returns one
//! [`Step`]: the alarm transitions and machine-state changes it caused, the
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
pub mod checks;
mod conditions;
pub mod recorder;
pub mod state;
pub mod switching;
mod tag;

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

pub use checks::{CheckSet, Declared, Finding, Observation, WindowPosition};
pub use conditions::{PlcCondition, ACKED_AT_PLC};
pub use recorder::{
    Cut, RecordedSignal, RecorderConfig, RecorderFill, Recording, Sample, Truncated,
};
pub use state::{HistoryKind, MachineState, StateName, StateRules};
pub use switching::{SwitchingCheck, SwitchingChecks};
pub use tag::{Tag, Value};

use crate::alarm::Consequence;
use crate::alarm::{Alarm, AlarmKind, CommandRefused, Severity, Transition};
use crate::comments::CommentDb;
use crate::consequence::Relation;
use crate::signal::Signal;
use crate::value::{Comparison, Counter, Num, Operand, ValueType};
use alarms::AlarmBook;
use recorder::{Read, Recorder};

/// How often the `tag-quality` alarm's text is brought up to date while
/// other tags go bad or good and it stays active, ms.
const QUALITY_UPDATE_MS: u64 = 10_000;

/// How many bad tags the `tag-quality` alarm names.
const QUALITY_NAMED: usize = 20;

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
}

/// Everything one input to the engine did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Step {
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

impl Step {
    /// Whether nothing the sinks care about happened.
    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
            && self.observations.is_empty()
            && self.readings == 0
            && self.unknown_delta == 0
            && self.parts.is_empty()
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
            EngineEvent::State { .. } => None,
        })
    }

    /// The machine-state changes.
    pub fn states(&self) -> impl Iterator<Item = (&MachineState, HistoryKind, u64)> {
        self.events.iter().filter_map(|e| match e {
            EngineEvent::State { state, kind, at } => Some((state, *kind, *at)),
            EngineEvent::Alarm { .. } => None,
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

/// Tags whose changes may have been lost, and the latest gap's reason.
#[derive(Debug, Clone)]
struct Lost {
    tags: Vec<bool>,
    why: String,
}

/// Marks a finding judged across a gap: no contact is named its trigger,
/// and the message says why.
fn uncertain_trigger(f: &mut Finding, why: &str) {
    if matches!(f.kind, AlarmKind::Communication | AlarmKind::System) {
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

/// The name of a non-finite number, or `None` for a finite one.
fn not_finite(reading: &Reading) -> Option<&'static str> {
    match reading {
        Reading::Number(Num::Float(x)) if x.is_nan() => Some("NaN"),
        Reading::Number(Num::Float(x)) if x.is_infinite() && *x > 0.0 => Some("+inf"),
        Reading::Number(Num::Float(x)) if x.is_infinite() => Some("-inf"),
        _ => None,
    }
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
    /// Per tag: whether the running rule reads it.
    running_reads: Vec<bool>,
    alarms: AlarmBook,
    /// `None` until the source first says.
    connected: Option<bool>,
    rules: StateRules,
    state: MachineState,
    last_fault: Option<FaultMark>,
    parts: PartCounting,
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
    /// The agent's clock at the readings being handled (ms): the flight
    /// recorder keeps their changes at the time their alarms are stamped
    /// with, so that a PLC clock not believed leaves no recording empty.
    clock: u64,
}

impl CellEngine {
    /// An engine for `cell` over `tags`, running `sets`. Starts offline
    /// with every tag unknown.
    ///
    /// # Errors
    /// A check set or the running rule reads an address no tag has.
    pub fn new(
        cell: &str,
        tags: Vec<Tag>,
        sets: Vec<Box<dyn CheckSet>>,
        rules: StateRules,
    ) -> Result<Self, EngineError> {
        let configured = tags.len();
        let mut tags = tags;
        let mut by_address: HashMap<Signal, usize> = tags
            .iter()
            .enumerate()
            .map(|(i, t)| (t.address.clone(), i))
            .collect();
        // Comparison contacts become tags of their own, computed here.
        let mut derived = Vec::new();
        let mut wanted: Vec<(String, Signal)> = Vec::new();
        for (k, set) in sets.iter().enumerate() {
            for s in set.inputs().into_iter().chain(set.number_inputs()) {
                wanted.push((format!("check set {}", k + 1), s));
            }
        }
        if let Some(expr) = &rules.running {
            for s in expr.signals() {
                wanted.push(("the running rule".into(), s));
            }
        }
        for (reader, s) in &wanted {
            if by_address.contains_key(s) {
                continue;
            }
            let Some(c) = Comparison::of_signal(s) else {
                return Err(EngineError::MissingTag {
                    reader: reader.clone(),
                    address: s.clone(),
                });
            };
            let find = |a: &Signal| {
                by_address
                    .get(a)
                    .copied()
                    .filter(|&t| t < configured)
                    .ok_or_else(|| EngineError::MissingTag {
                        reader: reader.clone(),
                        address: a.clone(),
                    })
            };
            let lhs = find(&c.lhs)?;
            let rhs = match &c.rhs {
                Operand::Const(n) => Rhs::Const(*n),
                Operand::Tag(a) => Rhs::Tag(find(a)?),
            };
            let tag = tags.len();
            tags.push(Tag {
                name: s.to_string(),
                address: s.clone(),
            });
            by_address.insert(s.clone(), tag);
            derived.push(Derived {
                tag,
                lhs,
                op: c.op,
                rhs,
            });
        }
        let n = tags.len();
        let mut pairs = Vec::new();
        for (i, d) in derived.iter().enumerate() {
            pairs.push((d.lhs, i));
            if let Rhs::Tag(t) = d.rhs {
                if t != d.lhs {
                    pairs.push((t, i));
                }
            }
        }
        let compared_in = PerTag::build(n, &pairs);
        let (mut read, mut read_as_number) = (Vec::new(), Vec::new());
        for (k, set) in sets.iter().enumerate() {
            for s in set.inputs() {
                read.push((by_address[&s], k));
            }
            for s in set.number_inputs() {
                read_as_number.push((by_address[&s], k));
            }
        }
        let readers = PerTag::build(n, &read);
        let number_readers = PerTag::build(n, &read_as_number);
        let mut running_reads = vec![false; n];
        if let Some(expr) = &rules.running {
            for s in expr.signals() {
                running_reads[by_address[&s]] = true;
            }
        }
        drop(by_address);
        let mut by_address: Vec<u32> = (0..n as u32).collect();
        by_address
            .sort_unstable_by(|&a, &b| tags[a as usize].address.cmp(&tags[b as usize].address));
        let alarms = AlarmBook::declaring(sets.iter().flat_map(|s| s.alarms()));
        let mut facts = Vec::new();
        for set in &sets {
            set.facts(&mut facts);
        }
        let relation = Relation::derive(&facts);
        Ok(CellEngine {
            relation,
            suppress: false,
            state_at: 0,
            cell: cell.to_string(),
            tags,
            configured,
            by_address,
            values: vec![None; n],
            others: vec![None; n],
            timestamps: vec![None; n],
            latest: None,
            untimed: false,
            lost: None,
            lost_now: None,
            at_cut: None,
            source_trust: 0,
            bad: BTreeMap::new(),
            losses: 0,
            went_bad: 0,
            quality_said: 0,
            quality_unsaid: false,
            unknown: configured,
            sets,
            readers,
            number_readers,
            derived,
            compared_in,
            running_reads,
            alarms,
            connected: None,
            rules,
            state: MachineState::Offline,
            last_fault: None,
            parts: PartCounting::None,
            exported: vec![false; configured],
            delays: HashMap::new(),
            comments: CommentDb::default(),
            pending: BTreeMap::new(),
            order_tags: (None, None),
            order: Order::default(),
            recorder: None,
            conditions: Vec::new(),
            clock: 0,
        })
    }

    /// Which alarms may follow from which, as derived from the checks
    /// ([`crate::consequence`]).
    pub fn relation(&self) -> &Relation {
        &self.relation
    }

    /// Takes `relation` as the cell's (the derived one with the
    /// configuration's edges added or removed); with `suppress`, an alarm
    /// raised as a consequence is not annunciated (journaled and shown as
    /// suppressed).
    #[must_use]
    pub fn relating(mut self, relation: Relation, suppress: bool) -> Self {
        self.relation = relation;
        self.suppress = suppress;
        self
    }

    /// Counts rising edges of tag `tag` as parts produced
    /// ([`Step::parts`]).
    #[must_use]
    pub fn counting_parts(self, tag: Option<usize>) -> Self {
        self.counting(tag.map_or(PartCounting::None, PartCounting::Edge))
    }

    /// Reports the changes of these tags in [`Step::exported`].
    #[must_use]
    pub fn exporting(mut self, tags: impl IntoIterator<Item = usize>) -> Self {
        for t in tags {
            if let Some(e) = self.exported.get_mut(t) {
                *e = true;
            }
        }
        self
    }

    /// The tags' comments (the I/O list), by address: the `tag-quality`
    /// alarm names each bad tag with its comment.
    #[must_use]
    pub fn commenting(mut self, comments: CommentDb) -> Self {
        self.comments = comments;
        self
    }

    /// Stamps an alarm judged on a value with the time the source sampled
    /// it, rather than when it arrived, when that time is at most `trust`
    /// ms behind the agent's clock and not ahead of it: a change delivered
    /// late (after a network cut, republished, in a batch) raises its
    /// alarm at the time it happened. A source clock off by more than
    /// `trust` is not believed.
    #[must_use]
    pub fn trusting_source_time(mut self, trust: u64) -> Self {
        self.source_trust = trust;
        self
    }

    /// Delays alarm `id`: its condition must hold `on_delay` ms before it
    /// is raised, and be gone `off_delay` ms before it clears (ISA-18.2);
    /// a condition that does not last is never announced.
    #[must_use]
    pub fn delaying(mut self, id: &str, on_delay: u64, off_delay: u64) -> Self {
        if on_delay > 0 || off_delay > 0 {
            self.delays.insert(id.to_string(), (on_delay, off_delay));
        }
        self
    }

    /// Follows the work order: tag `item` gives the item code (a string or
    /// a number), tag `target` the target quantity; their changes are
    /// [`Step::order`].
    #[must_use]
    pub fn ordering(mut self, item: Option<usize>, target: Option<usize>) -> Self {
        let fits = |t: Option<usize>| t.filter(|&t| t < self.configured);
        self.order_tags = (fits(item), fits(target));
        self
    }

    /// The work order now (item code, target quantity).
    pub fn order(&self) -> &Order {
        &self.order
    }

    /// Counts parts as `how` says ([`Step::parts`]).
    #[must_use]
    pub fn counting(mut self, how: PartCounting) -> Self {
        let valid = match &how {
            PartCounting::None => true,
            PartCounting::Edge(t) => *t < self.configured,
            PartCounting::Counters(cs) => cs.iter().all(|(t, _)| *t < self.configured),
        };
        self.parts = if valid { how } else { PartCounting::None };
        self
    }

    /// The cell's id.
    pub fn cell(&self) -> &str {
        &self.cell
    }

    /// The configured tags, in configuration order.
    pub fn tags(&self) -> &[Tag] {
        &self.tags[..self.configured]
    }

    /// The tag with this address.
    pub fn tag_index(&self, address: &Signal) -> Option<usize> {
        self.by_address
            .binary_search_by(|&t| self.tags[t as usize].address.cmp(address))
            .ok()
            .map(|i| self.by_address[i] as usize)
    }

    /// Current boolean values of the configured tags, `None` where unknown
    /// or not a boolean.
    pub fn values(&self) -> &[Option<bool>] {
        &self.values[..self.configured]
    }

    /// Tag `tag`'s current value, whatever its type.
    pub fn value(&self, tag: usize) -> Option<Value> {
        match self.values.get(tag).copied().flatten() {
            Some(b) => Some(Value::Bool(b)),
            None => self.others.get(tag).cloned().flatten(),
        }
    }

    /// Every configured tag's current value.
    pub fn all_values(&self) -> Vec<Option<Value>> {
        (0..self.configured).map(|t| self.value(t)).collect()
    }

    /// How many tags are unknown now.
    pub fn unknown_tags(&self) -> usize {
        self.unknown
    }

    /// Tags whose quality is bad.
    pub fn bad_tags(&self) -> impl Iterator<Item = usize> + '_ {
        self.bad.keys().copied()
    }

    /// Every alarm the engine knows, by id.
    pub fn alarms(&self) -> impl Iterator<Item = &Alarm> {
        self.alarms.iter()
    }

    /// The machine state.
    pub fn state(&self) -> &MachineState {
        &self.state
    }

    /// Whether the PLC connection is up.
    pub fn connected(&self) -> bool {
        self.connected == Some(true)
    }

    /// The values at the last switching, timer, limit or step fault
    /// (costs one look per tag: for the snapshot service).
    pub fn last_fault(&self) -> Option<FaultValues> {
        let mark = self.last_fault.as_ref()?;
        let mut values = self.all_values();
        for &(tag, value) in &mark.undo_bools {
            values[tag as usize] = value.map(Value::Bool);
        }
        for (tag, value) in &mark.undo_others {
            values[*tag as usize] = value.clone();
        }
        Some(FaultValues {
            alarm: mark.alarm.clone(),
            at: mark.at,
            values,
        })
    }

    /// Logs `tag`'s value before it changes, the first time it changes
    /// after the last fault.
    fn remember(&mut self, tag: usize) {
        // A comparison contact's tag is not in the snapshot: it follows
        // the numbers it reads.
        if tag >= self.configured {
            return;
        }
        if let Some(mark) = &mut self.last_fault {
            if mark.first_change(tag) {
                match (self.values[tag], &self.others[tag]) {
                    (Some(b), _) => mark.undo_bools.push((tag as u32, Some(b))),
                    (None, None) => mark.undo_bools.push((tag as u32, None)),
                    (None, other) => mark.undo_others.push((tag as u32, other.clone())),
                }
            }
        }
    }

    /// Where each tracked transition's recent durations lie in its window
    /// (timer checks with drift tracking on), in the checks' order.
    pub fn window_positions(&self) -> Vec<WindowPosition> {
        let mut out = Vec::new();
        for set in &self.sets {
            set.window_positions(&mut out);
        }
        out
    }

    /// Whether this engine can raise alarm `id`: one its checks declared,
    /// `communication` or `tag-quality`, or a PLC condition of a prefix it
    /// takes ([`CellEngine::taking_conditions`]). (System alarms are the
    /// agent's: [`CellEngine::on_system`] takes any id.)
    pub fn can_raise(&self, id: &str) -> bool {
        self.can_raise_own(id) || self.is_condition(id)
    }

    /// [`CellEngine::can_raise`] but for the PLC's conditions.
    fn can_raise_own(&self, id: &str) -> bool {
        matches!(id, "communication" | "tag-quality") || self.alarms.is_declared(id)
    }

    /// Puts back the alarms that were not back to normal when the agent
    /// stopped, and the machine state, before any input. Each alarm comes
    /// back with its `raised_at`, acknowledgement and culprits, and is
    /// reported once as [`Transition::Restored`] (not a new raise). Fresh
    /// values then decide: a non-latched alarm clears or stays as its check
    /// says; a latched one waits for a reset as before.
    pub fn restore(&mut self, alarms: Vec<Alarm>, state: Option<MachineState>, now: u64) -> Step {
        let mut step = Step::default();
        for alarm in alarms {
            let id = alarm.id.clone();
            if alarm.active {
                for set in &mut self.sets {
                    set.restored(&alarm);
                }
            }
            self.alarms.restore(alarm);
            if let Some(alarm) = self.alarms.get(&id) {
                step.events.push(EngineEvent::Alarm {
                    alarm: alarm.clone(),
                    transition: Transition::Restored,
                    at: now,
                });
            }
        }
        if let Some(state) = state {
            self.state = state;
        }
        step
    }

    /// What a reload carries from this engine into the one built from the
    /// new configuration ([`CellEngine::take_over`]).
    pub fn carry_over(&self) -> Carried {
        let readings = (0..self.configured)
            .filter_map(|t| {
                let reading = match self.bad.get(&t) {
                    Some(BadQuality::WrongType(expected, received)) => Reading::WrongType {
                        expected: *expected,
                        received: *received,
                    },
                    Some(BadQuality::NotFinite(name)) => Reading::Number(Num::Float(match *name {
                        "+inf" => f64::INFINITY,
                        "-inf" => f64::NEG_INFINITY,
                        _ => f64::NAN,
                    })),
                    Some(BadQuality::Status) => Reading::Bad,
                    None => match self.value(t)? {
                        Value::Bool(b) => Reading::Good(b),
                        Value::Num(n) => Reading::Number(n),
                        Value::Text(text) => Reading::Text(text),
                    },
                };
                let at = self.timestamps[t].or(self.latest).unwrap_or(0);
                Some((self.tags[t].address.clone(), reading, at))
            })
            .collect();
        Carried {
            alarms: self
                .alarms
                .iter()
                .filter(|a| {
                    a.active || !a.acknowledged || a.shelved.is_some() || a.out_of_service.is_some()
                })
                .cloned()
                .collect(),
            state: self.state.clone(),
            connected: self.connected,
            readings,
        }
    }

    /// Takes over from the engine a reload replaces (`carried`), before
    /// any other input: its alarms as they were (acknowledgements, shelves
    /// and removals kept; the alarms of checks no longer configured
    /// dropped, the agent's own kept), each reported once as
    /// [`Transition::Restored`]; its machine state; its connection; then
    /// the tags' values as they were, at their source times, which the new
    /// checks judge: an alarm whose condition no longer holds clears, a
    /// new check's condition that holds raises. What was under way is
    /// started again from here: a condition waiting out its delay, a
    /// transition being timed, a step's supervision time.
    pub fn take_over(&mut self, carried: Carried, now: u64) -> Vec<Step> {
        let Carried {
            alarms,
            state,
            connected,
            readings,
        } = carried;
        let alarms = alarms
            .into_iter()
            .filter(|a| a.kind == AlarmKind::System || self.can_raise(&a.id))
            .collect();
        let mut steps = vec![self.restore(alarms, Some(state), now)];
        if let Some(up) = connected {
            steps.push(self.on_connection(up, now));
        }
        let mut values: Vec<TagReading> = readings
            .into_iter()
            .filter_map(|(address, reading, source_time)| {
                let tag = self.tag_index(&address).filter(|&t| t < self.configured)?;
                Some(TagReading {
                    tag,
                    reading,
                    source_time,
                })
            })
            .collect();
        values.sort_by_key(|r| r.source_time);
        if !values.is_empty() {
            steps.push(self.on_readings(&values, now));
        }
        steps
    }

    /// The source lost changes for good (`why`): of `tags`, or of any tag
    /// (`None`: a sequence gap says nothing of what was in it); `values`
    /// of them when it knows how many. Until each such tag's next value,
    /// an alarm raised or cleared on it carries "trigger uncertain" and
    /// names no trigger: the change that tripped it may be among the lost.
    pub fn on_gap(&mut self, tags: Option<&[usize]>, values: u64, why: &str) -> Step {
        let n = self.tags.len();
        let lost = self.lost.get_or_insert_with(|| Lost {
            tags: vec![false; n],
            why: String::new(),
        });
        lost.why = why.to_string();
        match tags {
            None => {
                lost.tags.iter_mut().for_each(|t| *t = true);
                // Not resumed: what was before the cut is no longer known.
                self.at_cut = None;
            }
            Some(tags) => {
                for &t in tags {
                    if let Some(t) = lost.tags.get_mut(t) {
                        *t = true;
                    }
                }
            }
        }
        // Verdicts waiting out a delay across the gap say so when they come.
        let signals: Option<Vec<Signal>> = tags.map(|ts| {
            ts.iter()
                .filter_map(|&t| self.tags.get(t))
                .map(|t| t.address.clone())
                .collect()
        });
        for set in &mut self.sets {
            set.on_gap(signals.as_deref(), why);
        }
        let waiting: Vec<String> = self.pending.keys().cloned().collect();
        let gone: Option<std::collections::HashSet<&Signal>> =
            signals.as_ref().map(|s| s.iter().collect());
        for id in waiting {
            let touched = gone.as_ref().is_none_or(|gone| {
                let mut reads = Vec::new();
                for set in &self.sets {
                    set.reads(&id, &mut reads);
                }
                reads.iter().any(|r| gone.contains(r))
            });
            if let Some((_, _, f)) = self.pending.get_mut(&id).filter(|_| touched) {
                if !f.message.contains("(trigger uncertain") {
                    uncertain_trigger(f, why);
                }
            }
        }
        Step {
            gaps: 1,
            lost_values: values,
            ..Step::default()
        }
    }

    /// The source took up where the lost connection left off, losing
    /// nothing (the server kept the subscription and sends every change
    /// made meanwhile, in order): each tag not heard since the cut is again
    /// what it was then, so that the changes that follow are judged
    /// against it — a contact that opened during the cut is a trigger,
    /// not a value out of nowhere. Call it before those changes.
    pub fn on_resumed(&mut self, now: u64) -> Step {
        self.clock = now;
        let mut step = Step::default();
        let Some(cut) = self.at_cut.take() else {
            return step;
        };
        let mut findings = Vec::new();
        // Back to what was, at the last time seen: no timer measures
        // through it.
        let at = self.latest.unwrap_or(now);
        self.untimed = true;
        for t in 0..cut.values.len().min(self.configured) {
            if self.timestamps[t].is_some() {
                // Heard since: its own value stands.
                continue;
            }
            match (cut.values[t], &cut.others[t]) {
                (Some(v), _) => {
                    self.set_value(t, Some(v), at, &mut findings, &mut step);
                }
                (None, Some(v)) => {
                    self.set_other(t, Some(v.clone()), at, &mut findings, &mut step);
                }
                (None, None) => continue,
            }
            self.timestamps[t] = cut.timestamps[t];
        }
        self.untimed = false;
        for f in findings {
            self.apply(f, now, &mut step);
        }
        self.update_state(now, &mut step);
        self.collect_observations(&mut step);
        step
    }

    /// Why `tag`'s changes may have been lost, if they may; the mark is
    /// taken off: its value is here.
    fn take_lost(&mut self, tag: usize) -> Option<String> {
        let lost = self.lost.as_mut()?;
        if !std::mem::take(lost.tags.get_mut(tag)?) {
            return None;
        }
        let why = lost.why.clone();
        if !lost.tags.iter().any(|&t| t) {
            self.lost = None;
        }
        Some(why)
    }

    /// Why the trigger of `f` is uncertain, if it is: the reading that
    /// judged it, or a contact it names, may have lost changes.
    fn uncertain(&self, f: &Finding) -> Option<String> {
        if let Some(why) = &self.lost_now {
            return Some(why.clone());
        }
        let lost = self.lost.as_ref()?;
        let marked = |t: usize| lost.tags.get(t).copied().unwrap_or(false);
        f.culprits.iter().find_map(|c| {
            let t = self.tag_index(&c.address)?;
            let hit = marked(t)
                || self.derived.iter().any(|d| {
                    d.tag == t && (marked(d.lhs) || matches!(d.rhs, Rhs::Tag(r) if marked(r)))
                });
            hit.then(|| lost.why.clone())
        })
    }

    /// A condition of the agent itself (`journal`: it cannot write) began
    /// (`problem` is why) or ended.
    pub fn on_system(&mut self, id: &str, problem: Option<&str>, now: u64) -> Step {
        let mut step = Step::default();
        let finding = Finding {
            at: None,
            id: id.into(),
            kind: AlarmKind::System,
            severity: Severity::High,
            fault_type: id.to_uppercase(),
            latched: false,
            active: problem.is_some(),
            fault_step: None,
            culprits: Vec::new(),
            message: match problem {
                Some(why) => format!("{id}: {why}"),
                None => format!("{id}: back to normal"),
            },
        };
        self.apply(finding, now, &mut step);
        step
    }

    /// The connection to the PLC came up or went down.
    pub fn on_connection(&mut self, up: bool, now: u64) -> Step {
        self.clock = now;
        let mut step = Step::default();
        if Some(up) == self.connected {
            return step;
        }
        self.connected = Some(up);
        // Up: what the source resumes with, or a new subscription's
        // values, is here.
        self.at_cut = None;
        // One occurrence while the connection keeps going (the alarm's
        // off-delay): its losses are counted in its text.
        let occurring = self.is_active("communication");
        if !up {
            // A condition waiting out its delay is no longer seen to hold.
            self.pending.clear();
            self.losses = if occurring { self.losses + 1 } else { 1 };
        }
        let losses = match self.losses {
            0 | 1 => String::new(),
            n => format!(" ({n} losses since it was raised)"),
        };
        let finding = Finding {
            at: None,
            id: "communication".into(),
            kind: AlarmKind::Communication,
            severity: Severity::High,
            fault_type: "COMM".into(),
            latched: false,
            active: !up,
            fault_step: None,
            culprits: Vec::new(),
            message: if up {
                format!("communication restored{losses}")
            } else {
                format!("communication lost: every tag is unknown{losses}")
            },
        };
        if !up {
            self.at_cut = Some(Box::new(AtCut {
                values: self.values[..self.configured].to_vec(),
                others: self.others[..self.configured].to_vec(),
                timestamps: self.timestamps[..self.configured].to_vec(),
            }));
            // Every value is now unknown; checks hold their verdicts.
            let mut ignored = Vec::new();
            for t in 0..self.configured {
                self.set_unknown(t, now, &mut ignored, &mut step);
            }
            self.timestamps.iter_mut().for_each(|t| *t = None);
        }
        self.apply(finding, now, &mut step);
        if up && self.bad.is_empty() {
            // A `tag-quality` alarm restored from the journal clears once
            // the PLC is back and no tag is bad.
            let quality = self.quality_finding();
            self.apply(quality, now, &mut step);
        }
        self.update_state(now, &mut step);
        self.collect_observations(&mut step);
        step
    }

    /// A value (or bad quality) for tag `tag`, with its source timestamp.
    pub fn on_reading(&mut self, tag: usize, reading: Reading, source_time: u64, now: u64) -> Step {
        self.on_readings(
            &[TagReading {
                tag,
                reading,
                source_time,
            }],
            now,
        )
    }

    /// Values delivered together (one publish), in source-time order: one
    /// step for all.
    pub fn on_readings(&mut self, readings: &[TagReading], now: u64) -> Step {
        self.readings(readings, now, false).0
    }

    /// Values delivered together, in source-time order, up to and
    /// including the first that changes an alarm: one step for those, and
    /// how many readings it took (at least one, unless `readings` is
    /// empty). The caller publishes the alarm at once and hands the rest
    /// in again, so an alarm never waits for the changes behind it.
    pub fn on_readings_to_alarm(&mut self, readings: &[TagReading], now: u64) -> (Step, usize) {
        self.readings(readings, now, true)
    }

    fn readings(&mut self, readings: &[TagReading], now: u64, to_alarm: bool) -> (Step, usize) {
        self.clock = now;
        let mut step = Step::default();
        let mut findings = Vec::new();
        let mut used = 0;
        for r in readings {
            used += 1;
            if r.tag >= self.configured {
                continue;
            }
            step.readings += 1;
            let events = step.events.len();
            // The state follows each reading, so that a fault raised and
            // cleared within one publish still leaves its history rows.
            if self.reading(r, now, &mut findings, &mut step) || step.events.len() > events {
                // At the time the change was sampled, as the alarms judged
                // on it are (when the source's clock is trusted).
                let at = self.latest.map_or(now, |t| self.stamp(t, now));
                self.update_state(at, &mut step);
                if to_alarm && step.alarms().next().is_some() {
                    break;
                }
            }
        }
        self.collect_observations(&mut step);
        (step, used)
    }

    /// One reading; true if the machine state may have changed.
    fn reading(
        &mut self,
        r: &TagReading,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut Step,
    ) -> bool {
        let tag = r.tag;
        if tag >= self.configured {
            return false;
        }
        if self.lost.is_some() {
            self.lost_now = self.take_lost(tag);
        }
        if let Some(last) = self.timestamps[tag] {
            let same = match &r.reading {
                Reading::Good(v) => self.values[tag] == Some(*v),
                Reading::Number(n) => {
                    matches!(&self.others[tag], Some(Value::Num(m)) if m == n)
                }
                Reading::Text(t) => {
                    matches!(&self.others[tag], Some(Value::Text(u)) if u == t)
                }
                Reading::Bad | Reading::WrongType { .. } | Reading::Unreachable => false,
            };
            if same && r.source_time <= last {
                step.duplicates += 1;
                self.lost_now = None;
                return false;
            }
        }
        self.timestamps[tag] = Some(r.source_time);
        // A number that is not one (NaN, ±inf) is bad quality, as a bad
        // status is: no limit is judged on it.
        let non_finite = not_finite(&r.reading);
        let why = match (&r.reading, non_finite) {
            (_, Some(name)) => Some(BadQuality::NotFinite(name)),
            (Reading::Bad, None) => Some(BadQuality::Status),
            (Reading::WrongType { expected, received }, None) => {
                Some(BadQuality::WrongType(*expected, *received))
            }
            _ => None,
        };
        let quality_changed = match why {
            Some(why) => {
                let was = self.bad.insert(tag, why);
                if was.is_none() {
                    step.went_bad += 1;
                    // One occurrence while tags keep going bad (the
                    // alarm's off-delay): counted in its text.
                    let occurring = self.bad.len() > 1 || self.is_active("tag-quality");
                    self.went_bad = if occurring { self.went_bad + 1 } else { 1 };
                }
                was != Some(why)
            }
            None => self.bad.remove(&tag).is_some(),
        };
        findings.clear();
        // Checks time events by when the PLC saw them, not when they
        // arrived: delivery jitter is not motion time. One earlier than
        // the latest seen is taken at the latest, and said to be out of
        // order.
        let at = match self.latest {
            Some(latest) if r.source_time < latest => {
                step.out_of_order += 1;
                self.untimed = true;
                latest
            }
            _ => {
                self.latest = Some(r.source_time);
                r.source_time
            }
        };
        let ring_at = self.ring_time(at);
        if let Some(recorder) = &mut self.recorder {
            recorder.pass(ring_at);
        }
        // Delays that ran out before this value was sampled (values sampled
        // over a while and delivered together, late or republished) are
        // over first, at their own time: a condition that lasted its delay
        // is announced before the value that ends it.
        if !self.pending.is_empty() {
            // One ending just as this value comes is judged on it.
            let before = step.events.len();
            self.run_out(at.saturating_sub(1), true, now, step);
            // The state follows them, at their time.
            let ran_out = step.events[before..].iter().rev().find_map(|e| match e {
                EngineEvent::Alarm { at, .. } => Some(*at),
                EngineEvent::State { .. } => None,
            });
            if let Some(t) = ran_out {
                self.update_state(t, step);
            }
        }
        let changed = match &r.reading {
            _ if non_finite.is_some() => self.set_unknown(tag, at, findings, step),
            Reading::Good(v) => self.set_value(tag, Some(*v), at, findings, step),
            Reading::Number(n) => self.set_other(tag, Some(Value::Num(*n)), at, findings, step),
            Reading::Text(t) => {
                self.set_other(tag, Some(Value::Text(t.clone())), at, findings, step)
            }
            Reading::Bad | Reading::WrongType { .. } | Reading::Unreachable => {
                self.set_unknown(tag, at, findings, step)
            }
        };
        self.untimed = false;
        if quality_changed {
            // Raised, cleared (or its clear called off) at once; a text
            // that only names other tags at most every QUALITY_UPDATE_MS.
            let (active, bad) = (self.is_active("tag-quality"), !self.bad.is_empty());
            if active && bad && self.pending.remove("tag-quality").is_some() {
                // Bad again before its clear was announced: the same
                // occurrence goes on.
                self.quality_unsaid = true;
            } else if bad != active || now >= self.quality_said.saturating_add(QUALITY_UPDATE_MS) {
                findings.push(self.quality_finding());
                if bad {
                    self.quality_said = now;
                }
                self.quality_unsaid = false;
            } else {
                self.quality_unsaid = true;
            }
        }
        if findings.len() > 1 && !self.relation.is_empty() {
            // Causes first: within one change, an alarm that may follow
            // from another found with it is judged after it.
            let ids: Vec<String> = findings.iter().map(|f| f.id.clone()).collect();
            findings.sort_by_key(|f| {
                self.relation
                    .causes_of(&f.id)
                    .iter()
                    .filter(|(c, _)| ids.contains(c))
                    .count()
            });
        }
        for f in findings.drain(..) {
            self.apply_at(f, at, now, step);
        }
        self.lost_now = None;
        changed
    }

    /// Announces the delayed findings whose delay ended by `at`: by the
    /// clock (`source` false) or in source time (`source` true).
    fn run_out(&mut self, at: u64, source: bool, now: u64, step: &mut Step) {
        let due: Vec<String> = self
            .pending
            .iter()
            .filter(|(id, (by_clock, by_source, f))| {
                let (on, off) = self.delays.get(*id).copied().unwrap_or_default();
                let since = if source { *by_source } else { *by_clock };
                at >= since.saturating_add(if f.active { on } else { off })
            })
            .map(|(id, _)| id.clone())
            .collect();
        for id in due {
            if let Some((_, by_source, f)) = self.pending.remove(&id) {
                // Ran out between values delivered together: at the source
                // time it ran out, if the source's clock is trusted.
                let stamp = if source {
                    let (on, off) = self.delays.get(&id).copied().unwrap_or_default();
                    self.stamp(
                        by_source.saturating_add(if f.active { on } else { off }),
                        now,
                    )
                } else {
                    now
                };
                self.announce(f, stamp, step);
            }
        }
    }

    /// The earliest time at which [`CellEngine::advance`] has something to
    /// do — a timer or a step supervision running out, a delayed alarm
    /// whose delay ends, a shelf that expires — if any. Costs one look per
    /// check kind, and one per alarm waiting out its delay.
    pub fn next_deadline(&self) -> Option<u64> {
        let sets = self.sets.iter().filter_map(|s| s.next_deadline());
        let delayed = self.pending.iter().map(|(id, (since, _, f))| {
            let (on, off) = self.delays.get(id).copied().unwrap_or_default();
            since.saturating_add(if f.active { on } else { off })
        });
        let quality = self
            .quality_unsaid
            .then(|| self.quality_said.saturating_add(QUALITY_UPDATE_MS));
        let recording = self.recorder.as_ref().and_then(|r| r.next_deadline());
        sets.chain(delayed)
            .chain(quality)
            .chain(self.alarms.next_expiry())
            .chain(recording)
            .min()
    }

    /// Time passed: timers fire.
    pub fn advance(&mut self, now: u64) -> Step {
        let mut findings = Vec::new();
        for set in &mut self.sets {
            set.advance(now, &mut findings);
        }
        let mut step = Step::default();
        for f in findings {
            self.apply(f, now, &mut step);
        }
        // Delayed findings whose condition lasted.
        self.run_out(now, false, now, &mut step);
        // The bad tags' text, held back while they kept changing.
        if self.quality_unsaid && now >= self.quality_said.saturating_add(QUALITY_UPDATE_MS) {
            self.quality_unsaid = false;
            self.quality_said = now;
            if self.is_active("tag-quality") && !self.bad.is_empty() {
                let f = self.quality_finding();
                self.apply(f, now, &mut step);
            }
        }
        // Shelves that expired: the alarms are announced again as they are.
        for alarm in self.alarms.expire(now) {
            step.events.push(EngineEvent::Alarm {
                alarm,
                transition: Transition::Unshelved,
                at: now,
            });
        }
        if !step.events.is_empty() {
            self.update_state(now, &mut step);
        }
        if let Some(recorder) = &mut self.recorder {
            recorder.finish_due(now);
        }
        self.collect_observations(&mut step);
        step
    }

    /// An operator acknowledges an alarm, saying `comment` if anything
    /// (kept with the occurrence, gone when it is raised again).
    ///
    /// # Errors
    /// No such alarm, or nothing to acknowledge.
    pub fn acknowledge(
        &mut self,
        id: &str,
        operator: &str,
        comment: Option<&str>,
        now: u64,
    ) -> Result<Step, CommandRefused> {
        let alarm = self.alarms.acknowledge(id, operator, comment)?.clone();
        if self.is_condition(id) {
            self.alarms.forget_if_normal(id);
        }
        Ok(Step {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Acknowledged,
                at: now,
            }],
            ..Step::default()
        })
    }

    /// An operator shelves alarm `id`: until `until` (ms), or with `None`
    /// one-shot, until the alarm clears. It is still evaluated and
    /// journaled; its payloads say it is shelved.
    ///
    /// # Errors
    /// No such alarm, or a one-shot shelf on an alarm not active.
    pub fn shelve(
        &mut self,
        id: &str,
        operator: &str,
        reason: &str,
        until: Option<u64>,
        now: u64,
    ) -> Result<Step, CommandRefused> {
        let shelf = crate::alarm::Shelf {
            by: operator.to_string(),
            reason: reason.to_string(),
            at: now,
            until,
        };
        let alarm = self.alarms.shelve(id, shelf)?.clone();
        Ok(Step {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Shelved,
                at: now,
            }],
            ..Step::default()
        })
    }

    /// An operator ends the shelf on alarm `id`.
    ///
    /// # Errors
    /// No such alarm, or it is not shelved.
    pub fn unshelve(&mut self, id: &str, now: u64) -> Result<Step, CommandRefused> {
        let alarm = self.alarms.unshelve(id)?.clone();
        Ok(Step {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Unshelved,
                at: now,
            }],
            ..Step::default()
        })
    }

    /// An operator takes alarm `id` out of service (ISA-18.2): whatever its
    /// condition it is not raised until it is back in service; an active
    /// occurrence ends now. Any alarm the checks can raise may be taken out,
    /// raised before or not.
    ///
    /// # Errors
    /// No such alarm, or it is out of service already.
    pub fn take_out_of_service(
        &mut self,
        id: &str,
        operator: &str,
        reason: &str,
        now: u64,
    ) -> Result<Step, CommandRefused> {
        let removal = crate::alarm::Removal {
            by: operator.to_string(),
            reason: reason.to_string(),
            at: now,
        };
        let alarm = self.alarms.take_out_of_service(id, removal, now)?.clone();
        self.pending.remove(id);
        for set in &mut self.sets {
            set.reset(id);
        }
        let mut step = Step {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::OutOfService,
                at: now,
            }],
            ..Step::default()
        };
        self.update_state(now, &mut step);
        Ok(step)
    }

    /// An operator puts alarm `id` back in service: raised at once if its
    /// condition holds (after its on-delay, if it has one).
    ///
    /// # Errors
    /// No such alarm, or it is not out of service.
    pub fn return_to_service(&mut self, id: &str, now: u64) -> Result<Step, CommandRefused> {
        let (alarm, held) = self.alarms.return_to_service(id)?;
        let mut step = Step {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::InService,
                at: now,
            }],
            ..Step::default()
        };
        if let Some(f) = held {
            self.apply(f, now, &mut step);
        }
        self.update_state(now, &mut step);
        Ok(step)
    }

    /// An operator resets a latched alarm whose condition is gone.
    ///
    /// # Errors
    /// No such alarm, not latched, not active, or its condition still holds.
    pub fn reset(&mut self, id: &str, operator: &str, now: u64) -> Result<Step, CommandRefused> {
        let alarm = self.alarms.reset(id, operator, now)?.clone();
        for set in &mut self.sets {
            set.reset(id);
        }
        let mut step = Step {
            events: vec![EngineEvent::Alarm {
                alarm,
                transition: Transition::Cleared,
                at: now,
            }],
            ..Step::default()
        };
        self.update_state(now, &mut step);
        Ok(step)
    }

    fn collect_observations(&mut self, step: &mut Step) {
        for set in &mut self.sets {
            set.take_observations(&mut step.observations);
        }
        if let Some(recorder) = &mut self.recorder {
            recorder.take_done(&mut step.recordings);
        }
    }

    /// Counts tag `tag` known or unknown.
    fn known_changed(&mut self, tag: usize, was: bool, is: bool, step: &mut Step) {
        if tag >= self.configured || was == is {
            return;
        }
        if is {
            self.unknown -= 1;
            step.unknown_delta -= 1;
        } else {
            self.unknown += 1;
            step.unknown_delta += 1;
        }
    }

    /// Makes tag `tag` unknown, whatever its type; true if the machine
    /// state may have changed.
    fn set_unknown(
        &mut self,
        tag: usize,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut Step,
    ) -> bool {
        if self.others[tag].is_some() {
            self.set_other(tag, None, now, findings, step)
        } else {
            self.set_value(tag, None, now, findings, step)
        }
    }

    /// Sets boolean tag `tag`'s value; true if the machine state may have
    /// changed.
    fn set_value(
        &mut self,
        tag: usize,
        value: Option<bool>,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut Step,
    ) -> bool {
        if value.is_some() && self.others[tag].is_some() {
            // A number or string tag now sends booleans: forget the
            // other value first.
            self.set_other(tag, None, now, findings, step);
        }
        let before = self.values[tag];
        if before == value {
            return false;
        }
        self.known_changed(tag, before.is_some(), value.is_some(), step);
        if self.parts == PartCounting::Edge(tag) && before == Some(false) && value == Some(true) {
            step.parts.push((now, 1));
        }
        self.remember(tag);
        self.values[tag] = value;
        let ring_at = self.ring_time(now);
        if let Some(recorder) = &mut self.recorder {
            recorder.change_bool(tag, ring_at, before, value);
        }
        step.evaluations += 1;
        if self.exported.get(tag) == Some(&true) {
            step.exported
                .push((tag, value.map(|b| f64::from(u8::from(b)))));
        }
        let address = &self.tags[tag].address;
        for &k in self.readers.of(tag) {
            let set = &mut self.sets[k as usize];
            if self.untimed {
                set.on_change_out_of_order(address, value, before, now, findings);
            } else {
                set.on_change(address, value, before, now, findings);
            }
        }
        self.running_reads[tag]
    }

    /// Sets number or string tag `tag`'s value; true if the machine state
    /// may have changed.
    fn set_other(
        &mut self,
        tag: usize,
        value: Option<Value>,
        now: u64,
        findings: &mut Vec<Finding>,
        step: &mut Step,
    ) -> bool {
        if self.values[tag].is_some() {
            // A boolean tag now sends numbers (or the reverse): forget
            // the boolean first.
            self.set_value(tag, None, now, findings, step);
        }
        if self.others[tag] == value {
            return false;
        }
        self.remember(tag);
        let before = std::mem::replace(&mut self.others[tag], value);
        let ring_at = self.ring_time(now);
        if let Some(recorder) = &mut self.recorder {
            recorder.change(tag, ring_at, &before, &self.others[tag]);
        }
        self.known_changed(tag, before.is_some(), self.others[tag].is_some(), step);
        step.evaluations += 1;
        let number = |v: &Option<Value>| match v {
            Some(Value::Num(n)) => Some(*n),
            _ => None,
        };
        let (was, is) = (number(&before), number(&self.others[tag]));
        if self.exported.get(tag) == Some(&true) {
            step.exported.push((tag, is.map(Num::as_f64)));
        }
        if let PartCounting::Counters(counters) = &mut self.parts {
            for (_, counter) in counters.iter_mut().filter(|(t, _)| *t == tag) {
                if let Some(n) = is.and_then(Num::as_count) {
                    let made = counter.next(n);
                    if made > 0 {
                        step.parts.push((now, made));
                    }
                }
            }
        }
        if Some(tag) == self.order_tags.0 || Some(tag) == self.order_tags.1 {
            self.order_changed(step);
        }
        if was != is {
            let address = &self.tags[tag].address;
            for &k in self.number_readers.of(tag) {
                self.sets[k as usize].on_number(address, is, now, findings);
            }
        }
        let mut state = self.running_reads[tag];
        for i in 0..self.compared_in.of(tag).len() {
            let d = &self.derived[self.compared_in.of(tag)[i] as usize];
            let value = self.compare(d);
            let t = d.tag;
            state |= self.set_value(t, value, now, findings, step);
        }
        state
    }

    /// Recomputes the work order from its tags; a change goes to `step`.
    /// An unknown value (unit out of reach) keeps the last known one.
    fn order_changed(&mut self, step: &mut Step) {
        let (item, target) = self.order_tags;
        let mut order = self.order.clone();
        match item.and_then(|t| self.others[t].as_ref()) {
            Some(Value::Text(s)) => order.item = Some(s.trim().to_string()),
            Some(v) => order.item = Some(v.to_string()),
            None => {}
        }
        if let Some(Value::Num(n)) = target.and_then(|t| self.others[t].as_ref()) {
            order.target = n.as_count();
        }
        if order != self.order {
            self.order = order.clone();
            step.order = Some(order);
        }
    }

    /// Tag `t`'s value as a number (a contact as 0 or 1); `None` while
    /// unknown or text.
    fn number(&self, t: usize) -> Option<Num> {
        match (&self.others[t], self.values[t]) {
            (Some(Value::Num(n)), _) => Some(*n),
            (_, Some(b)) => Some(Num::UInt(u64::from(b))),
            _ => None,
        }
    }

    /// A comparison's value now: unknown while an operand is.
    fn compare(&self, d: &Derived) -> Option<bool> {
        let lhs = self.number(d.lhs)?;
        let rhs = match d.rhs {
            Rhs::Const(n) => n,
            Rhs::Tag(t) => self.number(t)?,
        };
        Some(d.op.holds(lhs, rhs))
    }

    /// Whether alarm `id` is active now (raised, or its clear waiting out
    /// its off-delay).
    fn is_active(&self, id: &str) -> bool {
        self.alarms.get(id).is_some_and(|a| a.active)
    }

    fn quality_finding(&self) -> Finding {
        let mut names: Vec<String> = self
            .bad
            .iter()
            .take(QUALITY_NAMED)
            .map(|(&t, why)| {
                let Tag { name, address } = &self.tags[t];
                let tag = match self.comments.get(address) {
                    Some(comment) => format!("{address} ({name}: {comment})"),
                    None => format!("{address} ({name})"),
                };
                match why {
                    BadQuality::Status => tag,
                    BadQuality::WrongType(expected, received) => format!(
                        "{tag}: {} received where {expected} is expected",
                        received.map_or("a value cellwatch does not read", |r| r.as_str())
                    ),
                    BadQuality::NotFinite(name) => format!("{tag}: {name} received, not a number"),
                }
            })
            .collect();
        if self.bad.len() > names.len() {
            names.push(format!("... ({} tags in all)", self.bad.len()));
        }
        Finding {
            at: None,
            id: "tag-quality".into(),
            kind: AlarmKind::TagQuality,
            severity: Severity::Medium,
            fault_type: "QUALITY".into(),
            latched: false,
            active: !self.bad.is_empty(),
            fault_step: None,
            culprits: Vec::new(),
            message: match (names.is_empty(), self.went_bad) {
                (true, 0 | 1) => "all tags good".into(),
                (true, n) => format!("all tags good ({n} went bad since it was raised)"),
                (false, 0 | 1) => format!(
                    "bad or uncertain quality, checks reading them suspended: {}",
                    names.join(", ")
                ),
                (false, n) => format!(
                    "bad or uncertain quality, checks reading them suspended: {} ({n} went bad since it was raised)",
                    names.join(", ")
                ),
            },
        }
    }

    fn apply(&mut self, f: Finding, now: u64, step: &mut Step) {
        self.apply_at(f, now, now, step);
    }

    /// [`CellEngine::apply`] of a finding whose condition began at `at`
    /// (source time) and is taken at `now` (the clock): its delay runs from
    /// both, each compared only with its own kind of time.
    fn apply_at(&mut self, mut f: Finding, at: u64, now: u64, step: &mut Step) {
        let at = f.at.unwrap_or(at);
        if self.lost.is_some() || self.lost_now.is_some() {
            if let Some(why) = self.uncertain(&f) {
                uncertain_trigger(&mut f, &why);
            }
        }
        if let Some(&(on, off)) = self.delays.get(&f.id) {
            let active = self.alarms.get(&f.id).is_some_and(|a| a.active);
            if f.active == active {
                // Back to what is announced before the delay ran out.
                self.pending.remove(&f.id);
            } else if (if f.active { on } else { off }) > 0 {
                let since = match self.pending.get(&f.id) {
                    Some((by_clock, by_source, p)) if p.active == f.active => {
                        (*by_clock, *by_source)
                    }
                    _ => (now, at),
                };
                self.pending.insert(f.id.clone(), (since.0, since.1, f));
                return;
            }
        }
        let stamp = self.stamp(at, now);
        self.announce(f, stamp, step);
    }

    /// The time the flight recorder keeps a change sampled at `at` with:
    /// the time an alarm judged on it is stamped with.
    fn ring_time(&self, at: u64) -> u64 {
        if self.clock == 0 {
            at
        } else {
            self.stamp(at, self.clock)
        }
    }

    /// When a change the source sampled at `source` happened, for alarms
    /// judged on it: `source`, if the source's clock is trusted and `source`
    /// is neither ahead of the agent's clock `now` nor further behind it
    /// than the trust allows; otherwise `now`.
    fn stamp(&self, source: u64, now: u64) -> u64 {
        if source <= now && now - source <= self.source_trust {
            source
        } else {
            now
        }
    }

    /// Applies a finding to the alarm book and reports the transition, at
    /// `now` (never before the alarm's last transition).
    fn announce(&mut self, mut f: Finding, now: u64, step: &mut Step) {
        let now = match self.alarms.get(&f.id) {
            Some(a) => now.max(a.raised_at).max(a.cleared_at.unwrap_or(0)),
            None => now,
        };
        if !self.derived.is_empty() {
            // A comparison a check could not show with its numbers: the
            // engine's, and the compared variable's comment.
            // A comment the check gave stays.
            let number = |s: &Signal| self.tag_index(s).and_then(|t| self.number(t));
            for c in &mut f.culprits {
                let given = c.comment.take();
                crate::explain::read_comparisons(std::slice::from_mut(c), number, &self.comments);
                if given.is_some() {
                    c.comment = given;
                }
            }
        }
        let id = f.id.clone();
        let applied = self.alarms.apply(f, now);
        let Some(transition) = applied.transition else {
            return;
        };
        if transition == Transition::Raised {
            if let Some(c) = self.consequence_of(&id) {
                self.alarms.set_consequence(&id, c);
            }
        }
        self.recording_starts(&id, transition, now);
        let Some(alarm) = self.alarms.get(&id) else {
            return;
        };
        if transition == Transition::Raised
            && matches!(
                alarm.kind,
                AlarmKind::Switching | AlarmKind::Timer | AlarmKind::Limit | AlarmKind::Step
            )
        {
            self.last_fault
                .get_or_insert_with(FaultMark::default)
                .restart(id, now, self.configured);
        }
        step.events.push(EngineEvent::Alarm {
            alarm: alarm.clone(),
            transition,
            at: now,
        });
    }

    /// Whether alarm `id`, just raised, follows from an active alarm: the
    /// communication alarm while the link is down (every tag unknown), an
    /// active cause in the relation that explains its culprits, or the
    /// tag-quality alarm when every culprit is a tag of bad quality.
    fn consequence_of(&self, id: &str) -> Option<Consequence> {
        let alarm = self.alarms.get(id)?;
        if matches!(
            alarm.kind,
            AlarmKind::Communication | AlarmKind::System | AlarmKind::TagQuality
        ) {
            return None;
        }
        let active = |c: &str| self.alarms.get(c).filter(|a| a.active);
        let cut = self.connected == Some(false);
        let bad = |s: &Signal| self.tag_index(s).is_some_and(|t| self.bad.contains_key(&t));
        let cause = cut
            .then(|| active("communication"))
            .flatten()
            .or_else(|| {
                self.relation.cause_of(
                    id,
                    &alarm.culprits,
                    |c| self.alarms.get(c),
                    |c| self.would_still_hold(id, c),
                )
            })
            .or_else(|| {
                (!alarm.culprits.is_empty() && alarm.culprits.iter().all(|c| bad(&c.address)))
                    .then(|| active("tag-quality"))
                    .flatten()
            })?;
        Some(Consequence {
            through: self.through(id, &cause.id),
            cause: cause.id.clone(),
            first_out: cause
                .consequence
                .as_ref()
                .map_or_else(|| cause.id.clone(), |c| c.first_out.clone()),
            suppressed: self.suppress,
        })
    }

    /// Whether alarm `effect`'s fault would still hold with what alarm
    /// `cause`'s fault holds taken back to its normal values; `None` when
    /// the check sets cannot say (then the culprits decide).
    fn would_still_hold(&self, effect: &str, cause: &str) -> Option<bool> {
        let normal = self.held_normal(cause)?;
        self.sets.iter().find_map(|s| s.would_hold(effect, &normal))
    }

    /// What alarm `cause`'s fault holds, each signal with its value
    /// without the fault ([`CheckSet::without`]), re-derived from the
    /// cell's values now.
    fn held_normal(&self, cause: &str) -> Option<Vec<(Signal, bool)>> {
        let now = |s: &Signal| self.tag_index(s).and_then(|t| self.values[t]);
        self.sets.iter().find_map(|s| s.without(cause, &now))
    }

    /// The signals `cause`'s fault holds that alarm `effect`'s check
    /// reads and that differ now from their values without the fault, each
    /// with its value now.
    fn through(&self, effect: &str, cause: &str) -> Vec<(Signal, bool)> {
        let Some(normal) = self.held_normal(cause) else {
            return Vec::new();
        };
        let mut reads = Vec::new();
        for set in &self.sets {
            set.reads(effect, &mut reads);
        }
        normal
            .into_iter()
            .filter(|(s, _)| reads.contains(s))
            .filter_map(|(s, without)| {
                let now = self.tag_index(&s).and_then(|t| self.values[t])?;
                (now != without).then_some((s, now))
            })
            .collect()
    }

    fn update_state(&mut self, now: u64, step: &mut Step) {
        let fault = self
            .alarms
            .active_faults()
            .find(|a| a.severity >= self.rules.fault_severity);
        let next = if !self.connected() {
            MachineState::Offline
        } else if let Some(a) = fault {
            MachineState::Fault {
                fault_type: a.fault_type.clone(),
                element: a.element().map(str::to_string),
            }
        } else if self.running() {
            MachineState::Running
        } else {
            MachineState::Idle
        };
        if next == self.state {
            return;
        }
        let kind = HistoryKind::between(&self.state, &next);
        self.state = next.clone();
        // Never before the last row.
        let at = now.max(self.state_at);
        self.state_at = at;
        step.events.push(EngineEvent::State {
            state: next,
            kind,
            at,
        });
    }

    /// Whether the running rule holds; false while any tag it reads is
    /// unknown.
    fn running(&self) -> bool {
        let Some(expr) = &self.rules.running else {
            return false;
        };
        let value = |s: &Signal| self.tag_index(s).and_then(|t| self.values[t]);
        if !expr.signals().iter().all(|s| value(s).is_some()) {
            return false;
        }
        expr.eval(&|s: &Signal| value(s).unwrap_or(false))
    }
}

/// The engine's side: the recorder is built over the tags the checks read,
/// fed by `set_value`/`set_other`, started by `announce` and emptied into
/// each [`Step`].
impl CellEngine {
    /// Keeps, for every alarm raised whose check reads signals, the changes
    /// of those signals around its raise, by `config` (the recorder is off
    /// until this is called); each is handed out in
    /// [`Step::recordings`] once its window is over.
    #[must_use]
    pub fn recording(mut self, config: RecorderConfig) -> Self {
        let watched = (0..self.tags.len())
            .map(|t| !self.readers.of(t).is_empty() || !self.number_readers.of(t).is_empty())
            .collect();
        self.recorder = Some(Box::new(Recorder::new(config, watched)));
        self
    }

    /// Ends every flight recording under way at `now` — the agent stops,
    /// or a reload replaces this engine — so that none is lost: each holds
    /// what came until then (`truncated.end` [`Cut::Stopped`]).
    pub fn end_recordings(&mut self, now: u64) -> Step {
        let mut step = Step::default();
        if let Some(recorder) = &mut self.recorder {
            recorder.finish_all(now);
            recorder.take_done(&mut step.recordings);
        }
        step
    }

    /// What the flight recorder's ring holds now, if it is on.
    pub fn recorder_fill(&self) -> Option<RecorderFill> {
        self.recorder.as_ref().map(|r| r.fill())
    }

    /// Starts the flight recording of alarm `id` if `transition` raised
    /// it: the signals its check reads, around `now`.
    fn recording_starts(&mut self, id: &str, transition: Transition, now: u64) {
        if transition != Transition::Raised || self.recorder.is_none() {
            return;
        }
        let mut signals = Vec::new();
        for set in &self.sets {
            set.reads(id, &mut signals);
        }
        let mut reads: Vec<Read> = Vec::new();
        for s in signals {
            let Some(t) = self.tag_index(&s) else {
                continue;
            };
            if reads.iter().any(|r| r.tag == t) {
                continue;
            }
            let Tag { name, address } = &self.tags[t];
            let address = address.to_string();
            reads.push(Read {
                tag: t,
                name: (*name != address).then(|| name.clone()),
                address,
                value: self.value(t),
            });
        }
        if let Some(r) = &mut self.recorder {
            r.start(id, now, reads);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::AlarmState;
    use crate::comments::CommentDb;
    use crate::explain::Polarity;
    use crate::expr::Expr;
    use crate::program::Program;
    use crate::signal::Observability;
    use crate::switching::SwitchingFunction;

    const ESE: &str = include_str!("../../../config/cnc/ese.il");
    const NORMAL: &str = include_str!("../../../config/cnc/ese-normal.values");

    fn engine() -> CellEngine {
        engine_with(&[], "G0.00 * F0.00")
    }

    /// The ESE check over its contacts' tags, then `extra` tags, with
    /// `running` as the running rule.
    fn engine_with(extra: &[Tag], running: &str) -> CellEngine {
        let p = Program::compile("ese.il", ESE, None).unwrap();
        let sf = SwitchingFunction::expand(
            &p,
            &Signal::new("G8.02"),
            &Observability::default_for(p.dialect()),
        )
        .unwrap();
        let mut tags: Vec<Tag> = sf
            .leaves()
            .into_iter()
            .map(|s| Tag {
                name: s.name().to_lowercase(),
                address: s,
            })
            .collect();
        tags.extend_from_slice(extra);
        let check = SwitchingCheck {
            forces: Vec::new(),
            text: None,
            id: "ese".into(),
            sf,
            polarity: Polarity::On,
            severity: Severity::Critical,
            fault_type: "ESE".into(),
            comments: CommentDb::default(),
            armed_when: None,
        };
        let rules = StateRules {
            running: Some(Expr::parse(running).unwrap()),
            fault_severity: Severity::High,
        };
        CellEngine::new(
            "m01",
            tags,
            vec![Box::new(SwitchingChecks::new(vec![check]))],
            rules,
        )
        .unwrap()
    }

    fn load_normal(e: &mut CellEngine, at: u64) -> Vec<EngineEvent> {
        let mut out = Vec::new();
        for line in NORMAL
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
        {
            let (a, v) = line.split_once(',').unwrap();
            let t = e.tag_index(&Signal::new(a)).unwrap();
            out.extend(e.on_reading(t, Reading::Good(v == "1"), at, at).events);
        }
        out
    }

    fn alarm_transitions(events: &[EngineEvent]) -> Vec<(String, Transition)> {
        events
            .iter()
            .filter_map(|e| match e {
                EngineEvent::Alarm {
                    alarm, transition, ..
                } => Some((alarm.id.clone(), *transition)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn fault_raises_with_culprit_and_clears() {
        let mut e = engine();
        let ev = e.on_connection(true, 1).events;
        assert_eq!(alarm_transitions(&ev), []);
        let ev = load_normal(&mut e, 2);
        assert!(alarm_transitions(&ev).is_empty());
        assert_eq!(e.state(), &MachineState::Running);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Raised)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.fault_step, Some(6));
        assert_eq!(alarm.culprits[0].address.name(), "X0.06");
        assert!(alarm.culprits[0].trigger);
        assert_eq!(
            e.state(),
            &MachineState::Fault {
                fault_type: "ESE".into(),
                element: Some("X0.06".into())
            }
        );
        assert!(matches!(
            ev.last(),
            Some(EngineEvent::State {
                kind: HistoryKind::Fault,
                ..
            })
        ));
        // Delivered again after a subscription is recreated: ignored.
        let dup = e.on_reading(x006, Reading::Good(false), 10, 11);
        assert!(dup.events.is_empty());
        assert_eq!(dup.duplicates, 1);
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Cleared)]
        );
        assert!(matches!(
            ev.last(),
            Some(EngineEvent::State {
                kind: HistoryKind::Recovery,
                state: MachineState::Running,
                ..
            })
        ));
        let a = e.alarms().next().unwrap();
        assert_eq!(a.state(), AlarmState::ClearedUnacknowledged);
        let ev = e
            .acknowledge("ese", "kim", Some("limit switch re-seated"), 30)
            .unwrap()
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Acknowledged)]
        );
        let a = e.alarms().next().unwrap();
        assert_eq!(a.state(), AlarmState::Normal);
        assert_eq!(
            (a.acked_by.as_deref(), a.ack_comment.as_deref()),
            (Some("kim"), Some("limit switch re-seated"))
        );
        assert_eq!(
            e.acknowledge("ese", "kim", None, 31),
            Err(CommandRefused::NothingToAcknowledge("ese".into()))
        );
        assert!(e.reset("ese", "kim", 32).is_err());
        // Raised again: the last occurrence's comment is not this one's.
        e.on_reading(x006, Reading::Good(false), 40, 40);
        let a = e.alarms().next().unwrap();
        assert_eq!(a.state(), AlarmState::ActiveUnacknowledged);
        assert_eq!(
            (a.acked_by.as_deref(), a.ack_comment.as_deref()),
            (None, None)
        );
    }

    #[test]
    fn an_alarm_judged_across_a_gap_names_no_trigger_until_each_tag_is_heard_again() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // Changes of any tag lost (a sequence gap): counted, and the next
        // alarm on a tag not heard since names no trigger.
        let gap = e.on_gap(None, 0, "publishes 7 to 9 lost");
        assert_eq!((gap.gaps, gap.lost_values), (1, 0));
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert!(alarm.culprits.iter().all(|c| !c.trigger), "{alarm:?}");
        assert!(
            alarm
                .message
                .ends_with("(trigger uncertain: publishes 7 to 9 lost)"),
            "{}",
            alarm.message
        );
        // Heard again: the clear names its trigger as usual.
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert!(!alarm.message.contains("uncertain"), "{}", alarm.message);
        // A gap of other tags leaves this one's alarms alone; every mark
        // goes once each of them is heard.
        let others: Vec<usize> = (0..e.tags().len()).filter(|&t| t != x006).collect();
        let gap = e.on_gap(Some(&others), 3, "3 values lost in a full queue");
        assert_eq!((gap.gaps, gap.lost_values), (1, 3));
        let ev = e.on_reading(x006, Reading::Good(false), 30, 30).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        // X0.06 is the only culprit: certain.
        assert!(alarm.culprits[0].trigger, "{alarm:?}");
        assert!(!alarm.message.contains("uncertain"), "{}", alarm.message);
        for &t in &others {
            let v = e.values()[t];
            e.on_reading(t, Reading::Good(v.unwrap_or(false)), 40, 40);
        }
        assert!(e.lost.is_none());
    }

    #[test]
    fn a_fault_made_during_a_cut_the_source_resumed_from_has_its_trigger() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_connection(false, 5);
        assert!(e.values().iter().all(Option::is_none), "{:?}", e.values());
        // Resumed: the values are back, with no alarm of their own.
        let back = e.on_resumed(8);
        assert!(alarm_transitions(&back.events).is_empty(), "{back:?}");
        assert!(e.values().iter().all(Option::is_some));
        // The change made during the cut, delivered after it.
        let ev = e.on_reading(x006, Reading::Good(false), 6, 9).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!("{ev:?}")
        };
        assert!(alarm.culprits[0].trigger, "{alarm:?}");
        assert!(!alarm.message.contains("unknown"), "{}", alarm.message);
        // Not resumed (a new subscription): nothing comes back.
        e.on_connection(true, 10);
        e.on_connection(false, 10);
        e.on_gap(None, 0, "subscription replaced");
        e.on_resumed(11);
        assert!(e.values().iter().all(Option::is_none));
    }

    #[test]
    fn the_values_at_a_fault_stay_as_they_were_whatever_changes_after() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        assert_eq!(e.last_fault(), None);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        let at_fault = e.all_values();
        let first = e.last_fault().unwrap();
        assert_eq!((first.alarm.as_str(), first.at), ("ese", 10));
        assert_eq!(first.values, at_fault);
        // Every other tag changes, some twice, one becomes unknown, one
        // sends a number: the values at the fault do not move.
        let n = e.tags().len();
        for t in (0..n).filter(|&t| t != x006) {
            let v = at_fault[t] == Some(Value::Bool(true));
            e.on_reading(t, Reading::Good(!v), 11, 11);
            if t % 2 == 0 {
                e.on_reading(t, Reading::Good(v), 12, 12);
            }
        }
        e.on_reading(0, Reading::Bad, 13, 13);
        e.on_reading(1, Reading::Number(Num::Int(7)), 14, 14);
        assert_ne!(e.all_values(), at_fault);
        assert_eq!(e.last_fault().unwrap(), first);
        // The next fault starts over from the values then.
        e.on_connection(true, 20);
        load_normal(&mut e, 21);
        e.on_reading(x006, Reading::Good(true), 22, 22);
        assert!(
            e.alarms().all(|a| !a.active),
            "{:?}",
            e.alarms().collect::<Vec<_>>()
        );
        e.on_reading(x006, Reading::Good(false), 30, 30);
        let second = e.last_fault().unwrap();
        assert_eq!(second.at, 30);
        assert_eq!(second.values, e.all_values());
        e.on_reading(x006, Reading::Good(true), 31, 31);
        assert_eq!(e.last_fault().unwrap(), second);
    }

    #[test]
    fn a_comparison_changing_after_a_fault_leaves_the_values_at_it_alone() {
        // The running rule reads a comparison: its contact is a tag of its
        // own past the configured ones, set as TEMP crosses 80.
        let temp_tag = Tag {
            name: "temp".into(),
            address: Signal::new("TEMP"),
        };
        let mut e = engine_with(&[temp_tag], "G0.00 * F0.00 * TEMP > 80");
        let temp = e.tags().len() - 1;
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let number = |n| Reading::Number(Num::Float(n));
        e.on_reading(temp, number(70.0), 3, 3);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        let at_fault = e.last_fault().unwrap();
        assert_eq!(at_fault.values.len(), temp + 1);
        // The comparison's contact flips both ways; TEMP itself changes.
        e.on_reading(temp, number(90.0), 11, 11);
        e.on_reading(temp, number(60.0), 12, 12);
        assert_eq!(e.last_fault().unwrap(), at_fault);
        assert_eq!(at_fault.values[temp], Some(Value::Num(Num::Float(70.0))));
    }

    #[test]
    fn a_publish_is_cut_after_each_alarm_and_comes_to_the_same() {
        let mut whole = engine();
        let mut cut = engine();
        for e in [&mut whole, &mut cut] {
            e.on_connection(true, 1);
            load_normal(e, 2);
        }
        let x006 = whole.tag_index(&Signal::new("X0.06")).unwrap();
        let other = (0..whole.tags().len()).find(|&t| t != x006).unwrap();
        let r = |tag, v, at| TagReading {
            tag,
            reading: Reading::Good(v),
            source_time: at,
        };
        let publish = [
            r(other, false, 10),
            r(x006, false, 11),
            r(other, true, 12),
            r(x006, true, 13),
            r(other, false, 14),
        ];
        let all = whole.on_readings(&publish, 20);
        assert_eq!(alarm_transitions(&all.events).len(), 2);
        let mut rest = &publish[..];
        let mut parts = Vec::new();
        while !rest.is_empty() {
            let (step, used) = cut.on_readings_to_alarm(rest, 20);
            rest = &rest[used..];
            parts.push((used, step));
        }
        let used: Vec<usize> = parts.iter().map(|(n, _)| *n).collect();
        assert_eq!(used, [2, 2, 1], "cut after the raise and after the clear");
        let alarms = |p: &(usize, Step)| alarm_transitions(&p.1.events);
        assert_eq!(alarms(&parts[0]), [("ese".to_string(), Transition::Raised)]);
        assert_eq!(
            alarms(&parts[1]),
            [("ese".to_string(), Transition::Cleared)]
        );
        assert!(alarms(&parts[2]).is_empty());
        let events: Vec<EngineEvent> = parts.iter().flat_map(|(_, s)| s.events.clone()).collect();
        assert_eq!(events, all.events);
        let readings: u64 = parts.iter().map(|(_, s)| s.readings).sum();
        assert_eq!(readings, all.readings);
        assert_eq!(cut.all_values(), whole.all_values());
        assert_eq!(cut.on_readings_to_alarm(&[], 21).1, 0);
    }

    #[test]
    fn lost_connection_is_one_alarm_and_no_process_alarm() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let ev = e.on_connection(false, 5).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Raised)]
        );
        assert_eq!(e.state(), &MachineState::Offline);
        assert!(e.values().iter().all(Option::is_none));
        // Reconnected: values come back one by one; while the unknown ones
        // could still decide, the check holds, so a half-loaded normal
        // image raises nothing.
        let ev = e.on_connection(true, 6).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Cleared)]
        );
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        assert!(
            alarm_transitions(&e.on_reading(x006, Reading::Good(true), 7, 7).events).is_empty()
        );
        let ev = load_normal(&mut e, 8);
        assert!(alarm_transitions(&ev).is_empty(), "{ev:?}");
    }

    /// The alarm `id`'s transitions and texts in `events`.
    fn said(events: &[EngineEvent], id: &str) -> Vec<(Transition, String)> {
        events
            .iter()
            .filter_map(|e| match e {
                EngineEvent::Alarm {
                    alarm, transition, ..
                } if alarm.id == id => Some((*transition, alarm.message.clone())),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_flapping_connection_is_one_communication_alarm_its_losses_counted() {
        let mut e = engine().delaying("communication", 0, 10_000);
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let lost = "communication lost: every tag is unknown";
        assert_eq!(
            said(&e.on_connection(false, 1_000).events, "communication"),
            [(Transition::Raised, lost.to_string())]
        );
        // Back, and lost again before the off-delay ran out: the same
        // occurrence, its text counting the losses.
        assert!(said(&e.on_connection(true, 2_000).events, "communication").is_empty());
        assert_eq!(e.next_deadline(), Some(12_000));
        assert_eq!(
            said(&e.on_connection(false, 3_000).events, "communication"),
            [(
                Transition::Updated,
                format!("{lost} (2 losses since it was raised)")
            )]
        );
        assert!(said(&e.on_connection(true, 4_000).events, "communication").is_empty());
        load_normal(&mut e, 4_001);
        assert!(said(&e.advance(13_999).events, "communication").is_empty());
        assert_eq!(
            said(&e.advance(14_000).events, "communication"),
            [(
                Transition::Cleared,
                "communication restored (2 losses since it was raised)".to_string()
            )]
        );
        // The next loss is a new occurrence, counted from one.
        assert_eq!(
            said(&e.on_connection(false, 20_000).events, "communication"),
            [(Transition::Raised, lost.to_string())]
        );
    }

    #[test]
    fn a_flapping_sensor_is_one_tag_quality_alarm_its_text_brought_up_to_date_at_most_every_ten_seconds(
    ) {
        let mut e = engine().delaying("tag-quality", 0, 10_000);
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let x004 = e.tag_index(&Signal::new("X0.04")).unwrap();
        let step = e.on_reading(x006, Reading::Bad, 1_000, 1_000);
        assert_eq!(step.went_bad, 1);
        assert_eq!(
            said(&step.events, "tag-quality"),
            [(
                Transition::Raised,
                "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06)"
                    .to_string()
            )]
        );
        // Good, bad, good again every 100 ms: nothing said (the clear
        // waits out its off-delay; coming back calls it off).
        for k in 1..=20u64 {
            let at = 1_000 + k * 100;
            let r = if k % 2 == 1 {
                Reading::Good(true)
            } else {
                Reading::Bad
            };
            let step = e.on_reading(x006, r, at, at);
            assert!(
                said(&step.events, "tag-quality").is_empty(),
                "{k}: {step:?}"
            );
        }
        // Another tag goes bad within 10 s of the last text: held back...
        let step = e.on_reading(x004, Reading::Bad, 3_100, 3_100);
        assert!(said(&step.events, "tag-quality").is_empty(), "{step:?}");
        assert_eq!(e.next_deadline(), Some(11_000));
        // ... and said when 10 s have passed, with both tags and the count.
        assert_eq!(
            said(&e.advance(11_000).events, "tag-quality"),
            [(
                Transition::Updated,
                "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06), X0.04 (x0.04) (12 went bad since it was raised)".to_string()
            )]
        );
        // Both good: cleared once the off-delay has run out.
        e.on_reading(x004, Reading::Good(true), 12_000, 12_000);
        let step = e.on_reading(x006, Reading::Good(true), 12_100, 12_100);
        assert!(said(&step.events, "tag-quality").is_empty());
        assert!(said(&e.advance(22_099).events, "tag-quality").is_empty());
        assert_eq!(
            said(&e.advance(22_100).events, "tag-quality"),
            [(
                Transition::Cleared,
                "all tags good (12 went bad since it was raised)".to_string()
            )]
        );
    }

    #[test]
    fn the_tag_quality_alarm_names_twenty_bad_tags_and_counts_the_rest() {
        let tags: Vec<Tag> = (0..30)
            .map(|i| Tag {
                name: format!("n{i:02}"),
                address: Signal::new(&format!("D{i:02}")),
            })
            .collect();
        let mut e = engine_with(&tags, "G0.00 * F0.00");
        e.on_connection(true, 1);
        let readings: Vec<TagReading> = (0..30)
            .map(|i| TagReading {
                tag: e.tag_index(&Signal::new(&format!("D{i:02}"))).unwrap(),
                reading: Reading::Bad,
                source_time: 2,
            })
            .collect();
        let step = e.on_readings(&readings, 2);
        assert_eq!(step.went_bad, 30);
        // Raised on the first; the other 29 within 10 s wait.
        assert_eq!(said(&step.events, "tag-quality").len(), 1);
        let text = &said(&e.advance(10_002).events, "tag-quality")[0].1;
        assert!(
            text.contains("D19 (n19), ... (30 tags in all) (30 went bad since it was raised)"),
            "{text}"
        );
        assert!(!text.contains("D20"), "{text}");
    }

    #[test]
    fn unreachable_from_the_start_is_one_alarm() {
        let mut e = engine();
        let ev = e.on_connection(false, 1).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Raised)]
        );
        assert!(e.on_connection(false, 2).events.is_empty());
    }

    #[test]
    fn bad_quality_suspends_and_is_reported() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e.on_reading(x006, Reading::Bad, 3, 3).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("tag-quality".to_string(), Transition::Raised)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(
            alarm.message,
            "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06)"
        );
        // Another contact of the same OR opens while X0.06 is unknown: the
        // fault is certain whatever X0.06 holds, so ESE is raised, naming
        // the unknown contact and blaming only known ones.
        let x004 = e.tag_index(&Signal::new("X0.04")).unwrap();
        let ev = e.on_reading(x004, Reading::Good(false), 4, 4).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Raised)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.culprits.len(), 1, "{:?}", alarm.culprits);
        assert_eq!(alarm.culprits[0].address.name(), "X0.04");
        assert!(
            alarm.message.ends_with("(unknown: X0.06)"),
            "{}",
            alarm.message
        );
        // X0.04 closes again: X0.06 could still hold the fault, so nothing
        // is cleared on an unknown value.
        let ev = e.on_reading(x004, Reading::Good(true), 5, 5).events;
        assert_eq!(alarm_transitions(&ev), []);
        // X0.06 good again and closed: the check clears on known values.
        let ev = e.on_reading(x006, Reading::Good(true), 6, 6).events;
        let t = alarm_transitions(&ev);
        assert!(
            t.contains(&("ese".to_string(), Transition::Cleared)),
            "{t:?}"
        );
        assert!(
            t.contains(&("tag-quality".to_string(), Transition::Cleared)),
            "{t:?}"
        );
    }

    fn restored(id: &str, latched: bool) -> Alarm {
        Alarm {
            id: id.into(),
            kind: if latched {
                AlarmKind::Timer
            } else {
                AlarmKind::Switching
            },
            severity: Severity::Critical,
            fault_type: "ESE".into(),
            active: true,
            acknowledged: !latched,
            latched,
            raised_at: 1_000,
            cleared_at: None,
            acked_by: (!latched).then(|| "kim".to_string()),
            ack_comment: None,
            fault_step: Some(6),
            culprits: Vec::new(),
            message: "ESE".into(),
            shelved: None,
            out_of_service: None,
            consequence: None,
        }
    }

    #[test]
    fn an_engine_can_raise_its_checks_alarms_and_its_own_only() {
        let e = engine();
        for id in ["ese", "communication", "tag-quality"] {
            assert!(e.can_raise(id), "{id}");
        }
        for id in ["ese2", "tmr-001", "journal", ""] {
            assert!(!e.can_raise(id), "{id}");
        }
    }

    #[test]
    fn restored_alarms_come_back_as_they_were_and_follow_fresh_values() {
        let mut e = engine();
        let fault = MachineState::Fault {
            fault_type: "ESE".into(),
            element: Some("X0.06".into()),
        };
        let step = e.restore(
            vec![restored("ese", false), restored("tmr-001", true)],
            Some(fault.clone()),
            5_000,
        );
        assert_eq!(
            alarm_transitions(&step.events),
            [
                ("ese".to_string(), Transition::Restored),
                ("tmr-001".to_string(), Transition::Restored)
            ]
        );
        assert_eq!(e.state(), &fault);
        let ese = e.alarms().find(|a| a.id == "ese").unwrap();
        assert_eq!(
            (ese.state(), ese.raised_at, ese.acked_by.as_deref()),
            (AlarmState::ActiveAcknowledged, 1_000, Some("kim"))
        );
        e.on_connection(true, 5_001);
        // ESE still there: its check confirms it, no new raise.
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e
            .on_reading(x006, Reading::Good(false), 5_002, 5_002)
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Updated)]
        );
        // The normal image: ESE clears by the values, already acknowledged.
        let ev = load_normal(&mut e, 5_004);
        assert!(alarm_transitions(&ev).contains(&("ese".to_string(), Transition::Cleared)));
        let ese = e.alarms().find(|a| a.id == "ese").unwrap();
        assert_eq!(ese.state(), AlarmState::Normal);
        // The latched timer alarm waits for its reset, which works.
        let tmr = e.alarms().find(|a| a.id == "tmr-001").unwrap();
        assert!(tmr.active);
        let ev = e.reset("tmr-001", "kim", 5_006).unwrap().events;
        assert_eq!(
            alarm_transitions(&ev),
            [("tmr-001".to_string(), Transition::Cleared)]
        );
    }

    fn shelf_of(e: &CellEngine, id: &str) -> Option<crate::alarm::Shelf> {
        e.alarms()
            .find(|a| a.id == id)
            .and_then(|a| a.shelved.as_deref().cloned())
    }

    #[test]
    fn a_shelf_lasts_its_time_in_virtual_time_and_survives_a_restart() {
        const MIN: u64 = 60_000;
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        // Shelved for 30 minutes: its updates say so.
        let ev = e
            .shelve("ese", "kim", "sensor cable", Some(10 + 30 * MIN), 10)
            .unwrap()
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Shelved)]
        );
        assert_eq!(shelf_of(&e, "ese").unwrap().until, Some(10 + 30 * MIN));
        assert!(alarm_transitions(&e.advance(10 + 30 * MIN - 1).events).is_empty());
        // A restart in the meantime keeps the shelf and its expiry.
        let saved: Vec<Alarm> = e.alarms().cloned().collect();
        let mut e = engine();
        e.restore(saved, None, 20 * MIN);
        assert_eq!(shelf_of(&e, "ese").unwrap().reason, "sensor cable");
        assert!(alarm_transitions(&e.advance(10 + 30 * MIN - 1).events).is_empty());
        // At expiry, announced again as it is: still active.
        let ev = e.advance(10 + 30 * MIN).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Unshelved)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert!(alarm.active && alarm.shelved.is_none());
        assert!(alarm_transitions(&e.advance(40 * MIN).events).is_empty());
        // Unshelving what is not shelved is refused.
        assert!(e.unshelve("ese", 40 * MIN).is_err());
    }

    #[test]
    fn a_one_shot_shelf_ends_when_the_alarm_clears() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // Not for an alarm that is not active, nor an unknown one.
        assert!(e.shelve("ese", "kim", "noise", None, 3).is_err());
        e.on_reading(x006, Reading::Good(false), 10, 10);
        e.shelve("ese", "kim", "known trouble", None, 11).unwrap();
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Cleared)]
        );
        assert_eq!(shelf_of(&e, "ese"), None);
        // The next occurrence is announced.
        let ev = e.on_reading(x006, Reading::Good(false), 30, 30).events;
        let EngineEvent::Alarm {
            alarm, transition, ..
        } = &ev[0]
        else {
            panic!()
        };
        assert_eq!(
            (*transition, alarm.shelved.is_none()),
            (Transition::Raised, true)
        );
        // A timed shelf does outlive an occurrence.
        e.shelve("ese", "kim", "known trouble", Some(1_000), 31)
            .unwrap();
        e.on_reading(x006, Reading::Good(true), 40, 40);
        let ev = e.on_reading(x006, Reading::Good(false), 50, 50).events;
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.shelved.as_ref().and_then(|s| s.until), Some(1_000));
        assert!(e.shelve("nope", "kim", "x", None, 60).is_err());
    }

    #[test]
    fn out_of_service_raises_nothing_and_back_in_service_raises_what_holds() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        // Never raised yet, but the check declares it: it can be taken out.
        let ev = e
            .take_out_of_service("ese", "kim", "switch replaced", 5)
            .unwrap()
            .events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::OutOfService)]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[0] else {
            panic!()
        };
        assert_eq!(alarm.state(), AlarmState::Normal);
        assert_eq!(alarm.out_of_service.as_ref().unwrap().by, "kim");
        assert!(e.take_out_of_service("ese", "kim", "again", 6).is_err());
        assert!(e.take_out_of_service("nope", "kim", "x", 6).is_err());
        // The condition becomes true: nothing raised, the machine not at
        // fault.
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10).events;
        assert_eq!(alarm_transitions(&ev), []);
        assert_eq!(e.state(), &MachineState::Running);
        // A restart keeps it out of service.
        let saved: Vec<Alarm> = e.alarms().cloned().collect();
        let mut e = engine();
        e.on_connection(true, 11);
        e.restore(saved, None, 11);
        load_normal(&mut e, 12);
        let ev = e.on_reading(x006, Reading::Good(false), 13, 13).events;
        assert_eq!(alarm_transitions(&ev), []);
        // Back in service while the condition holds: raised, with its
        // culprit.
        let ev = e.return_to_service("ese", 20).unwrap().events;
        assert_eq!(
            alarm_transitions(&ev),
            [
                ("ese".to_string(), Transition::InService),
                ("ese".to_string(), Transition::Raised)
            ]
        );
        let EngineEvent::Alarm { alarm, .. } = &ev[1] else {
            panic!()
        };
        assert_eq!(alarm.culprits[0].address.name(), "X0.06");
        assert_eq!(alarm.raised_at, 20);
        assert!(matches!(e.state(), MachineState::Fault { .. }));
        assert!(e.return_to_service("ese", 21).is_err());
        // Taken out while active: the occurrence ends, the fault with it;
        // back in service after the condition went, nothing is raised.
        let ev = e.take_out_of_service("ese", "kim", "again", 30).unwrap();
        let EngineEvent::Alarm { alarm, .. } = &ev.events[0] else {
            panic!()
        };
        assert_eq!(
            (alarm.state(), alarm.cleared_at),
            (AlarmState::Normal, Some(30))
        );
        assert_eq!(e.state(), &MachineState::Running);
        e.on_reading(x006, Reading::Good(true), 40, 40);
        let ev = e.return_to_service("ese", 50).unwrap().events;
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::InService)]
        );
    }

    #[test]
    fn an_unknown_contact_that_could_decide_suspends() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        // Step 5's OR: X0.07 unknown, every other term normal: the fault
        // depends on X0.07, nothing is raised.
        let x007 = e.tag_index(&Signal::new("X0.07")).unwrap();
        let ev = e.on_reading(x007, Reading::Bad, 3, 3).events;
        assert_eq!(
            alarm_transitions(&ev),
            [("tag-quality".to_string(), Transition::Raised)]
        );
        // And it is raised once X0.07 is known open.
        let ev = e.on_reading(x007, Reading::Good(false), 4, 4).events;
        let t = alarm_transitions(&ev);
        assert!(
            t.contains(&("ese".to_string(), Transition::Raised)),
            "{t:?}"
        );
    }
}

#[cfg(test)]
mod counters {
    use super::*;

    fn engine(n: usize) -> CellEngine {
        let tags = (0..n)
            .map(|i| Tag {
                name: format!("t{i}"),
                address: Signal::new(&format!("X{i}.00")),
            })
            .collect();
        CellEngine::new("c", tags, Vec::new(), StateRules::default())
            .unwrap()
            .counting_parts(Some(1))
    }

    #[test]
    fn unknown_count_is_kept_incrementally_and_matches_a_scan() {
        let mut e = engine(5);
        let mut unknown = 5i64;
        assert_eq!(e.unknown_tags(), 5);
        unknown += e.on_connection(true, 0).unknown_delta;
        let script = [
            (0, Reading::Good(true)),
            (1, Reading::Good(false)),
            (0, Reading::Bad),
            (2, Reading::Good(true)),
            (0, Reading::Good(false)),
            (4, Reading::Bad),
            (2, Reading::Bad),
        ];
        for (k, (tag, r)) in script.into_iter().enumerate() {
            unknown += e
                .on_reading(tag, r, k as u64 + 1, k as u64 + 1)
                .unknown_delta;
            let scanned = e.values().iter().filter(|v| v.is_none()).count();
            assert_eq!(e.unknown_tags(), scanned);
            assert_eq!(unknown, scanned as i64);
        }
        unknown += e.on_connection(false, 100).unknown_delta;
        assert_eq!(unknown, 5);
        assert_eq!(e.unknown_tags(), 5);
    }

    #[test]
    fn rising_edges_of_the_part_done_tag_are_parts() {
        let mut e = engine(2);
        e.on_connection(true, 0);
        // The first value is no edge: the part may have been counted before.
        assert!(e.on_reading(1, Reading::Good(true), 1, 1).parts.is_empty());
        assert!(e.on_reading(1, Reading::Good(false), 2, 2).parts.is_empty());
        assert_eq!(e.on_reading(1, Reading::Good(true), 3, 3).parts, [(3, 1)]);
        // Unknown, then true again: not a counted edge.
        e.on_reading(1, Reading::Bad, 4, 4);
        assert!(e.on_reading(1, Reading::Good(true), 5, 5).parts.is_empty());
        let batch = [
            TagReading {
                tag: 1,
                reading: Reading::Good(false),
                source_time: 6,
            },
            TagReading {
                tag: 1,
                reading: Reading::Good(true),
                source_time: 7,
            },
            TagReading {
                tag: 0,
                reading: Reading::Good(true),
                source_time: 7,
            },
            TagReading {
                tag: 1,
                reading: Reading::Good(true),
                source_time: 7,
            },
        ];
        let step = e.on_readings(&batch, 8);
        assert_eq!(step.parts, [(7, 1)]);
        assert_eq!(step.readings, 4);
        assert_eq!(step.duplicates, 1);
    }
}

#[cfg(test)]
mod armed {
    use super::*;
    use crate::comments::CommentDb;
    use crate::explain::Polarity;
    use crate::expr::Expr;
    use crate::program::Program;
    use crate::signal::Observability;
    use crate::switching::SwitchingFunction;

    #[test]
    fn csd_faults_only_while_cycle_start_is_pressed() {
        let p =
            Program::compile("csd.il", include_str!("../../../config/cnc/csd.il"), None).unwrap();
        let sf = SwitchingFunction::expand(
            &p,
            &Signal::new("G9.00"),
            &Observability::default_for(p.dialect()),
        )
        .unwrap();
        let tags: Vec<Tag> = sf
            .leaves()
            .into_iter()
            .map(|s| Tag {
                name: s.name().into(),
                address: s,
            })
            .collect();
        let check = SwitchingCheck {
            forces: Vec::new(),
            text: None,
            id: "csd".into(),
            sf,
            polarity: Polarity::On,
            severity: Severity::High,
            fault_type: "CSD".into(),
            comments: CommentDb::default(),
            armed_when: Some(SwitchingFunction::from_expr(
                Signal::new("armed"),
                &Expr::parse("X200.01").unwrap(),
            )),
        };
        let mut e = CellEngine::new(
            "m",
            tags,
            vec![Box::new(SwitchingChecks::new(vec![check]))],
            StateRules::default(),
        )
        .unwrap();
        e.on_connection(true, 0);
        let mut raised = Vec::new();
        for line in include_str!("../../../config/cnc/csd-normal.values")
            .lines()
            .filter(|l| l.contains(',') && !l.starts_with("address") && !l.starts_with('#'))
        {
            let (a, v) = line.split_once(',').unwrap();
            let t = e.tag_index(&Signal::new(a)).unwrap();
            raised.extend(e.on_reading(t, Reading::Good(v == "1"), 1, 1).events);
        }
        // Cycle start released: the paper's SF is true (-X200.01) but nothing is wrong.
        assert!(
            !raised
                .iter()
                .any(|ev| matches!(ev, EngineEvent::Alarm { .. })),
            "{raised:?}"
        );
        let set = |e: &mut CellEngine, a: &str, v: bool, t: u64| {
            let i = e.tag_index(&Signal::new(a)).unwrap();
            e.on_reading(i, Reading::Good(v), t, t).events
        };
        set(&mut e, "X201.02", false, 2);
        set(&mut e, "X201.06", true, 3);
        let ev = set(&mut e, "X200.01", true, 4);
        let EngineEvent::Alarm {
            alarm,
            transition: Transition::Raised,
            ..
        } = &ev[0]
        else {
            panic!("{ev:?}")
        };
        assert_eq!(alarm.fault_step, Some(3));
        assert_eq!(alarm.culprits[0].address.name(), "X200.01");
        let ev = set(&mut e, "X200.01", false, 5);
        assert!(
            matches!(
                &ev[0],
                EngineEvent::Alarm {
                    transition: Transition::Cleared,
                    ..
                }
            ),
            "{ev:?}"
        );
    }
}
