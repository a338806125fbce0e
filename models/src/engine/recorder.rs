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
//! recording walks back each read signal's own chain of changes in the
//! ring: its cost is in the signals and their changes, not in the ring.
//!
//! # Time
//! Changes come at their source time; one earlier than the latest kept is
//! taken at the latest (the ring stays in time order, as the engine's
//! checks do). A recording ends when a change comes from past its end, or
//! when the engine's clock passes it ([`super::CellEngine::advance`]): a
//! change of its window delivered later than that is not in it.

mod timeline;

use std::collections::VecDeque;
use std::fmt;

use serde::{Deserialize, Serialize};

use super::tag::Value;
use crate::value::Num;

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

/// A recorded value: serialized as plain JSON (`true`, `1650`, `-3`,
/// `72.5`, `"A-113"`); an unknown one is `None` (`null`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Sample {
    /// A contact.
    Bool(bool),
    /// A whole number of zero or more.
    UInt(u64),
    /// A negative whole number.
    Int(i64),
    /// A number with a fraction (written with its `.0` when whole).
    Float(f64),
    /// A string.
    Text(String),
}

impl From<&Value> for Sample {
    fn from(v: &Value) -> Sample {
        match v {
            Value::Bool(b) => Sample::Bool(*b),
            Value::Num(Num::Int(n)) => match u64::try_from(*n) {
                Ok(n) => Sample::UInt(n),
                Err(_) => Sample::Int(*n),
            },
            Value::Num(Num::UInt(n)) => Sample::UInt(*n),
            Value::Num(Num::Float(x)) => Sample::Float(*x),
            Value::Text(t) => Sample::Text(t.to_string()),
        }
    }
}

impl fmt::Display for Sample {
    /// A contact as `1` or `0`, a number as the PLC gave it, a string as it
    /// is.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Sample::Bool(b) => write!(f, "{}", u8::from(*b)),
            Sample::UInt(n) => write!(f, "{n}"),
            Sample::Int(n) => write!(f, "{n}"),
            Sample::Float(x) => write!(f, "{x}"),
            Sample::Text(t) => f.write_str(t),
        }
    }
}

/// One signal of a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordedSignal {
    /// Its address as the models name it (`X0.06`, `D100 > 5`).
    pub address: String,
    /// The tag's name in the plant, when it is not the address.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Its value at [`Recording::holds_from`] (`None`: unknown).
    pub start: Option<Sample>,
    /// Its changes after that, in order: `(source time ms, value)`.
    pub changes: Vec<(u64, Option<Sample>)>,
}

/// Why a recording holds less than its window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cut {
    /// The ring had dropped the older changes (its capacity).
    Ring,
    /// The recording's own bound on changes
    /// ([`RecorderConfig::max_changes`]).
    Changes,
    /// As many recordings were under way as may be
    /// ([`RecorderConfig::max_open`]): nothing after the raise was followed.
    Busy,
    /// The agent stopped, or read its configuration again, before the
    /// window's end: what came until then.
    Stopped,
}

/// Where a recording holds less than its window, and why.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Truncated {
    /// Its start: nothing before [`Recording::holds_from`].
    pub start: Option<Cut>,
    /// Its end: nothing after [`Recording::holds_to`].
    pub end: Option<Cut>,
}

/// The changes of the signals an alarm's check reads around its raise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Recording {
    /// The alarm's id.
    pub alarm: String,
    /// When it was raised, ms since the epoch (the alarm's `raised_at`).
    pub raised_at: u64,
    /// The window's start: `raised_at - before`.
    pub from: u64,
    /// The window's end: `raised_at + after`.
    pub to: u64,
    /// From when every change of its signals is in: `from`, unless
    /// [`Truncated::start`] says why later.
    pub holds_from: u64,
    /// Until when every change of its signals is in: `to`, unless
    /// [`Truncated::end`] says why earlier.
    pub holds_to: u64,
    /// Where it holds less than its window.
    pub truncated: Truncated,
    /// The signals its check reads, in the order the check gives them.
    pub signals: Vec<RecordedSignal>,
}

impl Recording {
    /// Signal `signal`'s value at `at` (`Some(None)`: unknown then); `None`
    /// when the recording does not hold `at` (outside
    /// [`Recording::holds_from`]..=[`Recording::holds_to`]) or has no such
    /// signal.
    pub fn value_at(&self, signal: usize, at: u64) -> Option<Option<&Sample>> {
        let s = self.signals.get(signal)?;
        if at < self.holds_from || at > self.holds_to {
            return None;
        }
        let k = s.changes.partition_point(|(t, _)| *t <= at);
        Some(match k {
            0 => s.start.as_ref(),
            k => s.changes[k - 1].1.as_ref(),
        })
    }

    /// How many changes it holds.
    pub fn changes(&self) -> usize {
        self.signals.iter().map(|s| s.changes.len()).sum()
    }

    /// An estimate of the memory it takes, bytes: its parts and what they
    /// point to.
    pub fn bytes(&self) -> usize {
        let sample = |s: &Option<Sample>| match s {
            Some(Sample::Text(t)) => t.capacity(),
            _ => 0,
        };
        std::mem::size_of::<Recording>()
            + self.alarm.capacity()
            + self
                .signals
                .iter()
                .map(|s| {
                    std::mem::size_of::<RecordedSignal>()
                        + s.address.capacity()
                        + s.name.as_ref().map_or(0, String::capacity)
                        + sample(&s.start)
                        + s.changes.capacity() * std::mem::size_of::<(u64, Option<Sample>)>()
                        + s.changes.iter().map(|(_, v)| sample(v)).sum::<usize>()
                })
                .sum::<usize>()
    }
}

/// What the ring holds now ([`super::CellEngine::recorder_fill`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecorderFill {
    /// Changes in the ring.
    pub changes: usize,
    /// How many it may hold.
    pub capacity: usize,
    /// The memory the ring and its per-tag indices take, bytes.
    pub bytes: usize,
    /// Recordings under way.
    pub open: usize,
}

/// A signal a recording is to follow, as the engine knows it.
#[derive(Debug, Clone)]
pub(crate) struct Read {
    /// The tag's index.
    pub(crate) tag: usize,
    /// Its address.
    pub(crate) address: String,
    /// The tag's name, when it is not the address.
    pub(crate) name: Option<String>,
    /// Its value now.
    pub(crate) value: Option<Value>,
}

/// One change in the ring.
#[derive(Debug, Clone)]
struct Change {
    at: u64,
    tag: u32,
    /// How many changes back the tag's previous change in the ring is (0:
    /// none, or too far back to say).
    back: u32,
    value: Option<Value>,
    before: Option<Value>,
}

/// A recording following the changes after its raise.
#[derive(Debug)]
struct Open {
    recording: Recording,
    /// `(tag, its signal in the recording)`, by tag.
    tags: Vec<(u32, usize)>,
    /// Changes taken after the raise.
    after: usize,
}

/// The ring of recent changes and the recordings under way.
#[derive(Debug)]
pub(crate) struct Recorder {
    config: RecorderConfig,
    ring: VecDeque<Change>,
    /// How many changes were ever pushed: the last one in the ring is
    /// number `pushed - 1`.
    pushed: u64,
    /// Per tag: whether some check reads it (only those are kept).
    watched: Vec<bool>,
    /// Per tag: its latest change's number + 1 (0: none yet).
    last: Vec<u64>,
    /// Per tag: one bit per slot of `open` whose recording reads it.
    members: Vec<u32>,
    /// The latest change's time.
    newest: Option<u64>,
    /// The time of the latest change dropped from the ring: every change
    /// after it is in.
    dropped: Option<u64>,
    /// The recordings under way, in their slots.
    open: Vec<Option<Open>>,
    /// The earliest end of those.
    next_end: Option<u64>,
    /// Recordings complete, until the engine hands them out.
    done: Vec<Recording>,
}

impl Recorder {
    /// A recorder by `config` (capacity raised to 1, `max_open` cut to
    /// [`MAX_OPEN`]) over tags of which `watched` are read by some check.
    pub(crate) fn new(mut config: RecorderConfig, watched: Vec<bool>) -> Recorder {
        config.capacity = config.capacity.max(1);
        config.max_open = config.max_open.min(MAX_OPEN);
        let n = watched.len();
        Recorder {
            ring: VecDeque::new(),
            pushed: 0,
            watched,
            last: vec![0; n],
            members: vec![0; n],
            newest: None,
            dropped: None,
            open: (0..config.max_open).map(|_| None).collect(),
            next_end: None,
            done: Vec::new(),
            config,
        }
    }

    /// Whether a check reads tag `tag` (only its changes are kept).
    pub(crate) fn watches(&self, tag: usize) -> bool {
        self.watched.get(tag).copied().unwrap_or(false)
    }

    /// Boolean tag `tag` went from `before` to `value` at `at`.
    pub(crate) fn change_bool(
        &mut self,
        tag: usize,
        at: u64,
        before: Option<bool>,
        value: Option<bool>,
    ) {
        if self.watches(tag) {
            self.push(tag, at, before.map(Value::Bool), value.map(Value::Bool));
        }
    }

    /// Tag `tag` went from `before` to `value` at `at`.
    pub(crate) fn change(
        &mut self,
        tag: usize,
        at: u64,
        before: &Option<Value>,
        value: &Option<Value>,
    ) {
        if self.watches(tag) {
            self.push(tag, at, before.clone(), value.clone());
        }
    }

    fn push(&mut self, tag: usize, at: u64, before: Option<Value>, value: Option<Value>) {
        let at = self.newest.map_or(at, |n| n.max(at));
        self.pass(at);
        self.newest = Some(at);
        let keep = self.config.before.saturating_mul(2);
        while let Some(front) = self.ring.front() {
            if front.at.saturating_add(keep) >= at && self.ring.len() < self.config.capacity {
                break;
            }
            self.dropped = Some(front.at);
            self.ring.pop_front();
        }
        if self.ring.len() == self.ring.capacity() {
            // Grow as a vector does, but never past the capacity.
            let room = self
                .ring
                .len()
                .max(64)
                .min(self.config.capacity - self.ring.len());
            self.ring.reserve_exact(room);
        }
        let back = match self.last[tag] {
            0 => 0,
            last => u32::try_from(self.pushed + 1 - last).unwrap_or(0),
        };
        let sample = (!self.members_of(tag).is_empty()).then(|| value.as_ref().map(Sample::from));
        self.ring.push_back(Change {
            at,
            tag: tag as u32,
            back,
            value,
            before,
        });
        self.pushed += 1;
        self.last[tag] = self.pushed;
        if let Some(sample) = sample {
            self.follow(tag, at, sample);
        }
    }

    /// The slots of the recordings that read `tag`, as bits.
    fn members_of(&self, tag: usize) -> Bits {
        Bits(self.members[tag])
    }

    /// Adds `tag`'s change at `at` to the recordings that read it.
    fn follow(&mut self, tag: usize, at: u64, sample: Option<Sample>) {
        for k in self.members_of(tag) {
            let Some(open) = self.open[k].as_mut() else {
                continue;
            };
            if open.after == self.config.max_changes {
                let holds_to = at.saturating_sub(1).max(open.recording.raised_at);
                self.complete(k, holds_to, Some(Cut::Changes));
                continue;
            }
            if let Ok(i) = open.tags.binary_search_by_key(&(tag as u32), |&(t, _)| t) {
                let signal = &mut open.recording.signals[open.tags[i].1];
                signal.changes.push((at, sample.clone()));
                open.after += 1;
            }
        }
    }

    /// Time reached `at` in the source's time: the recordings that end
    /// before it are complete.
    pub(crate) fn pass(&mut self, at: u64) {
        if self.next_end.is_some_and(|end| end < at) {
            self.finish(|to| to < at);
        }
    }

    /// The clock reached `now`: the recordings that end by then are
    /// complete.
    pub(crate) fn finish_due(&mut self, now: u64) {
        if self.next_end.is_some_and(|end| end <= now) {
            self.finish(|to| to <= now);
        }
    }

    fn finish(&mut self, due: impl Fn(u64) -> bool) {
        for k in 0..self.open.len() {
            if let Some(to) = self.open[k].as_ref().map(|o| o.recording.to) {
                if due(to) {
                    self.complete(k, to, None);
                }
            }
        }
    }

    /// Every recording under way ends at `now` (the agent stops, or its
    /// engine is replaced), each holding what came until then.
    pub(crate) fn finish_all(&mut self, now: u64) {
        for k in 0..self.open.len() {
            if let Some(to) = self.open[k].as_ref().map(|o| o.recording.to) {
                let holds_to = now.min(to);
                let cut = (holds_to < to).then_some(Cut::Stopped);
                self.complete(k, holds_to, cut);
            }
        }
    }

    /// The earliest time a recording under way ends, if any.
    pub(crate) fn next_deadline(&self) -> Option<u64> {
        self.next_end
    }

    /// Moves the complete recordings into `out`.
    pub(crate) fn take_done(&mut self, out: &mut Vec<Recording>) {
        out.append(&mut self.done);
    }

    /// What the ring holds now.
    pub(crate) fn fill(&self) -> RecorderFill {
        RecorderFill {
            changes: self.ring.len(),
            capacity: self.config.capacity,
            bytes: self.ring.capacity() * std::mem::size_of::<Change>()
                + self.watched.len()
                    * (std::mem::size_of::<bool>()
                        + std::mem::size_of::<u64>()
                        + std::mem::size_of::<u32>()),
            open: self.open.iter().flatten().count(),
        }
    }

    /// Alarm `alarm` was raised at `raised_at`: records `reads` (those a
    /// check reads; others are left out) from the ring, and follows them
    /// until its end. Nothing to read, nothing recorded.
    pub(crate) fn start(&mut self, alarm: &str, raised_at: u64, reads: Vec<Read>) {
        let reads: Vec<Read> = reads.into_iter().filter(|r| self.watches(r.tag)).collect();
        if reads.is_empty() {
            return;
        }
        let from = raised_at.saturating_sub(self.config.before);
        let to = raised_at.saturating_add(self.config.after);
        let mut truncated = Truncated::default();
        let mut holds_from = from;
        if let Some(dropped) = self.dropped.filter(|&d| d >= from) {
            holds_from = dropped + 1;
            truncated.start = Some(Cut::Ring);
        }
        // Each signal's changes since `holds_from`, walked back along its
        // own chain, then merged in the order they came.
        let first = self.pushed - self.ring.len() as u64;
        let mut picked: Vec<(u64, usize)> = Vec::new();
        for (i, r) in reads.iter().enumerate() {
            let mut n = self.last[r.tag];
            while n > first {
                let c = &self.ring[(n - 1 - first) as usize];
                debug_assert_eq!(c.tag as usize, r.tag, "a tag's chain holds its own changes");
                if c.at < holds_from {
                    break;
                }
                picked.push((n - 1, i));
                n = match c.back {
                    0 => 0,
                    back => n - u64::from(back),
                };
            }
        }
        picked.sort_unstable();
        let change = |n: u64| &self.ring[(n - first) as usize];
        // At most `max_changes` before the raise: the latest.
        let before = picked.partition_point(|&(n, _)| change(n).at <= raised_at);
        let mut skip = 0;
        if before > self.config.max_changes {
            let cut = change(picked[before - self.config.max_changes - 1].0).at;
            skip = picked.partition_point(|&(n, _)| change(n).at <= cut);
            holds_from = cut + 1;
            truncated.start = Some(Cut::Changes);
        }
        let picked = &picked[skip..];
        let mut start: Vec<Option<Option<Sample>>> = vec![None; reads.len()];
        for &(n, i) in picked {
            if start[i].is_none() {
                start[i] = Some(change(n).before.as_ref().map(Sample::from));
            }
        }
        let mut signals: Vec<RecordedSignal> = reads
            .iter()
            .zip(start)
            .map(|(r, start)| RecordedSignal {
                address: r.address.clone(),
                name: r.name.clone(),
                start: start.unwrap_or_else(|| r.value.as_ref().map(Sample::from)),
                changes: Vec::new(),
            })
            .collect();
        let mut after = 0;
        let mut cut_end = None;
        for &(n, i) in picked {
            let c = change(n);
            if c.at > to {
                break;
            }
            if c.at > raised_at {
                if after == self.config.max_changes {
                    cut_end = Some(c.at.saturating_sub(1).max(raised_at));
                    break;
                }
                after += 1;
            }
            signals[i]
                .changes
                .push((c.at, c.value.as_ref().map(Sample::from)));
        }
        let recording = Recording {
            alarm: alarm.to_string(),
            raised_at,
            from,
            to,
            holds_from,
            holds_to: to,
            truncated,
            signals,
        };
        let newest = self.newest.unwrap_or(raised_at);
        let slot = self.open.iter().position(Option::is_none);
        let mut tags: Vec<(u32, usize)> = reads
            .iter()
            .enumerate()
            .map(|(i, r)| (r.tag as u32, i))
            .collect();
        tags.sort_unstable();
        let open = Open {
            recording,
            tags,
            after,
        };
        match (cut_end, slot) {
            (Some(holds_to), _) => self.close(open, holds_to, Some(Cut::Changes)),
            (None, _) if newest > to => self.close(open, to, None),
            (None, None) => self.close(open, newest.max(raised_at).min(to), Some(Cut::Busy)),
            (None, Some(k)) => {
                for &(t, _) in &open.tags {
                    self.members[t as usize] |= 1 << k;
                }
                self.next_end = Some(self.next_end.map_or(to, |e| e.min(to)));
                self.open[k] = Some(open);
            }
        }
    }

    /// The recording in slot `k` is complete, holding changes up to
    /// `holds_to` (`cut`: why not up to its end).
    fn complete(&mut self, k: usize, holds_to: u64, cut: Option<Cut>) {
        let Some(open) = self.open[k].take() else {
            return;
        };
        for &(t, _) in &open.tags {
            self.members[t as usize] &= !(1 << k);
        }
        self.next_end = self.open.iter().flatten().map(|o| o.recording.to).min();
        self.close(open, holds_to, cut);
    }

    fn close(&mut self, open: Open, holds_to: u64, cut: Option<Cut>) {
        let mut recording = open.recording;
        recording.holds_to = holds_to;
        recording.truncated.end = cut;
        self.done.push(recording);
    }
}

/// The slots set in a bit set, lowest first.
struct Bits(u32);

impl Bits {
    fn is_empty(&self) -> bool {
        self.0 == 0
    }
}

impl Iterator for Bits {
    type Item = usize;

    fn next(&mut self) -> Option<usize> {
        if self.0 == 0 {
            return None;
        }
        let k = self.0.trailing_zeros() as usize;
        self.0 &= self.0 - 1;
        Some(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::{Severity, Transition};
    use crate::comments::CommentDb;
    use crate::engine::{
        CellEngine, CheckSet, Reading, StateRules, Step, SwitchingCheck, SwitchingChecks, Tag,
    };
    use crate::explain::Polarity;
    use crate::limit::{Level, LimitCheck, LimitChecks, LimitLevel};
    use crate::program::Program;
    use crate::signal::{Observability, Signal};
    use crate::switching::SwitchingFunction;

    const NORMAL: &str = include_str!("../../../config/cnc/ese-normal.values");

    fn config(before: u64, after: u64) -> RecorderConfig {
        RecorderConfig {
            before,
            after,
            ..RecorderConfig::default()
        }
    }

    /// The ESE check of paper 000 over its contacts (named in lower case),
    /// then a tag no check reads (`M9.00`), then with `limit` a number
    /// `TEMP` with a limit check (H above 80), recording by `config`.
    fn ese_engine(limit: bool, config: RecorderConfig) -> CellEngine {
        let p =
            Program::compile("ese.il", include_str!("../../../config/cnc/ese.il"), None).unwrap();
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
        tags.push(Tag {
            name: "spare".into(),
            address: Signal::new("M9.00"),
        });
        let mut sets: Vec<Box<dyn CheckSet>> =
            vec![Box::new(SwitchingChecks::new(vec![SwitchingCheck {
                forces: Vec::new(),
                text: None,
                id: "ese".into(),
                sf,
                polarity: Polarity::On,
                severity: Severity::Critical,
                fault_type: "ESE".into(),
                comments: CommentDb::default(),
                armed_when: None,
            }]))];
        if limit {
            tags.push(Tag {
                name: "spindle temperature".into(),
                address: Signal::new("TEMP"),
            });
            sets.push(Box::new(LimitChecks::new(vec![LimitCheck {
                comment: None,
                id: "temp".into(),
                tag: Signal::new("TEMP"),
                label: "spindle temperature".into(),
                unit: "°C".into(),
                deadband: 1.0,
                on_delay: 0,
                off_delay: 0,
                levels: vec![LimitLevel {
                    level: Level::H,
                    limit: 80.0,
                    severity: Severity::High,
                }],
            }])));
        }
        let mut e = CellEngine::new("m01", tags, sets, StateRules::default())
            .unwrap()
            .recording(config);
        e.on_connection(true, 0);
        e
    }

    fn load_normal(e: &mut CellEngine, at: u64) {
        for line in NORMAL
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
        {
            let (a, v) = line.split_once(',').unwrap();
            let t = e.tag_index(&Signal::new(a)).unwrap();
            e.on_reading(t, Reading::Good(v == "1"), at, at);
        }
    }

    fn set(e: &mut CellEngine, address: &str, reading: Reading, at: u64) -> Step {
        let t = e.tag_index(&Signal::new(address)).unwrap();
        e.on_reading(t, reading, at, at)
    }

    fn raised(step: &Step) -> Vec<String> {
        step.alarms()
            .filter(|(_, t, _)| *t == Transition::Raised)
            .map(|(a, _, _)| a.id.clone())
            .collect()
    }

    fn bool_changes(s: &RecordedSignal) -> Vec<(u64, Option<bool>)> {
        s.changes
            .iter()
            .map(|(at, v)| match v {
                Some(Sample::Bool(b)) => (*at, Some(*b)),
                None => (*at, None),
                other => panic!("{other:?}"),
            })
            .collect()
    }

    #[test]
    fn an_ese_fault_is_recorded_with_its_contacts_from_before_to_after_the_raise() {
        let mut e = ese_engine(false, config(10_000, 5_000));
        load_normal(&mut e, 1_000);
        // Inside the window, before the raise: R1024.00 (machine ready)
        // drops and comes back, which alone is no fault.
        set(&mut e, "R1024.00", Reading::Good(false), 4_000);
        set(&mut e, "R1024.00", Reading::Good(true), 6_000);
        // A tag no check reads: not kept.
        set(&mut e, "M9.00", Reading::Good(true), 8_000);
        let step = set(&mut e, "X0.06", Reading::Good(false), 12_000);
        assert_eq!(raised(&step), ["ese"]);
        assert!(step.recordings.is_empty());
        assert_eq!(e.next_deadline(), Some(17_000));
        // After the raise, up to its end.
        set(&mut e, "X0.06", Reading::Good(true), 13_000);
        set(&mut e, "R1024.00", Reading::Bad, 15_000);
        assert!(set(&mut e, "R1024.00", Reading::Good(false), 17_000)
            .recordings
            .is_empty());
        // The first change past the end completes it, without that change.
        let step = set(&mut e, "R1024.00", Reading::Good(true), 17_001);
        assert!(!step.is_empty());
        let [r] = &step.recordings[..] else {
            panic!("{:?}", step.recordings)
        };
        assert_eq!(e.next_deadline(), None);
        assert_eq!(
            (r.alarm.as_str(), r.raised_at, r.from, r.to),
            ("ese", 12_000, 2_000, 17_000)
        );
        assert_eq!((r.holds_from, r.holds_to), (2_000, 17_000));
        assert_eq!(r.truncated, Truncated::default());
        // Exactly the ESE's contacts, in the check's order.
        let leaves: Vec<String> = e.tags()[..e.tags().len() - 1]
            .iter()
            .map(|t| t.address.to_string())
            .collect();
        let addresses: Vec<&str> = r.signals.iter().map(|s| s.address.as_str()).collect();
        assert_eq!(addresses, leaves);
        let normal: Vec<(String, bool)> = NORMAL
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
            .map(|l| {
                let (a, v) = l.split_once(',').unwrap();
                (a.to_string(), v == "1")
            })
            .collect();
        for s in &r.signals {
            assert_eq!(s.name.as_deref(), Some(s.address.to_lowercase().as_str()));
            let v = normal.iter().find(|(a, _)| *a == s.address).unwrap().1;
            assert_eq!(s.start, Some(Sample::Bool(v)), "{}", s.address);
            let expected: Vec<(u64, Option<bool>)> = match s.address.as_str() {
                "R1024.00" => vec![
                    (4_000, Some(false)),
                    (6_000, Some(true)),
                    (15_000, None),
                    (17_000, Some(false)),
                ],
                "X0.06" => vec![(12_000, Some(false)), (13_000, Some(true))],
                _ => Vec::new(),
            };
            assert_eq!(bool_changes(s), expected, "{}", s.address);
        }
        // As a timing chart, 500 ms a column, the raise in column 20.
        let chart = r.timeline(30);
        let row = |a: &str| {
            let line = chart.lines().find(|l| l.starts_with(a)).unwrap();
            line.rsplit(' ').next().unwrap().to_string()
        };
        assert_eq!(row("X0.06 "), "▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔╲▁╱▔▔▔▔▔▔▔");
        assert_eq!(row("R1024.00 "), "▔▔▔▔╲▁▁▁╱▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔▔░░░░");
        // The ring holds the 21 contacts' changes, none of the spare tag.
        let fill = e.recorder_fill().unwrap();
        assert_eq!((fill.changes, fill.open), (21 + 7, 0));
    }

    #[test]
    fn the_value_at_the_window_start_comes_from_the_change_that_left_it() {
        let mut e = ese_engine(false, config(3_000, 1_000));
        load_normal(&mut e, 1_000);
        // R1024.00 left its normal value long before the window, then
        // changed inside it: its value at the start is the one before that.
        set(&mut e, "R1024.00", Reading::Good(false), 2_000);
        set(&mut e, "R1024.00", Reading::Good(true), 8_000);
        set(&mut e, "X0.06", Reading::Good(false), 10_000);
        let step = e.advance(11_000);
        let [r] = &step.recordings[..] else {
            panic!("{step:?}")
        };
        assert_eq!((r.from, r.to), (7_000, 11_000));
        let s = r.signals.iter().find(|s| s.address == "R1024.00").unwrap();
        assert_eq!(s.start, Some(Sample::Bool(false)));
        assert_eq!(bool_changes(s), [(8_000, Some(true))]);
        assert_eq!(r.value_at(0, 6_999), None);
        let i = r
            .signals
            .iter()
            .position(|s| s.address == "R1024.00")
            .unwrap();
        assert_eq!(r.value_at(i, 7_999), Some(Some(&Sample::Bool(false))));
        assert_eq!(r.value_at(i, 8_000), Some(Some(&Sample::Bool(true))));
    }

    /// A PLC whose clock is an hour ahead is not believed: its alarm is
    /// stamped by the agent's clock, and so are the changes recorded
    /// around it — the recording holds the fault, not an empty window.
    #[test]
    fn a_plc_clock_not_believed_still_gives_the_fault_its_recording() {
        const AHEAD: u64 = 3_600_000;
        let mut e = ese_engine(false, config(3_000, 1_000)).trusting_source_time(60_000);
        let at = |e: &mut CellEngine, address: &str, v: bool, now: u64| {
            let t = e.tag_index(&Signal::new(address)).unwrap();
            e.on_reading(t, Reading::Good(v), now + AHEAD, now)
        };
        for line in NORMAL
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
        {
            let (a, v) = line.split_once(',').unwrap();
            at(&mut e, a, v == "1", 1_000);
        }
        let step = at(&mut e, "X0.06", false, 10_000);
        let (_, _, raised_at) = step.alarms().next().unwrap();
        assert_eq!(raised_at, 10_000, "stamped by the agent's clock");
        let step = e.advance(11_000);
        let [r] = &step.recordings[..] else {
            panic!("{step:?}")
        };
        assert_eq!((r.raised_at, r.from, r.to), (10_000, 7_000, 11_000));
        let y = r.signals.iter().position(|s| s.address == "X0.06").unwrap();
        assert_eq!(r.value_at(y, 9_999), Some(Some(&Sample::Bool(true))));
        assert_eq!(r.value_at(y, 10_000), Some(Some(&Sample::Bool(false))));
    }

    #[test]
    fn a_limit_alarm_records_its_number_and_a_lost_connection_as_unknown() {
        let mut e = ese_engine(true, config(3_000, 4_000));
        load_normal(&mut e, 1_000);
        let n = |x: f64| Reading::Number(Num::Float(x));
        set(&mut e, "TEMP", n(50.0), 1_000);
        set(&mut e, "TEMP", n(70.0), 3_000);
        let step = set(&mut e, "TEMP", n(85.0), 5_000);
        assert_eq!(raised(&step), ["temp-h"]);
        set(&mut e, "TEMP", Reading::Number(Num::Int(90)), 6_000);
        e.on_connection(false, 7_000);
        let step = e.advance(9_000);
        let [r] = &step.recordings[..] else {
            panic!("{step:?}")
        };
        assert_eq!((r.alarm.as_str(), r.from, r.to), ("temp-h", 2_000, 9_000));
        let [s] = &r.signals[..] else { panic!("{r:?}") };
        assert_eq!(
            (s.address.as_str(), s.name.as_deref(), &s.start),
            (
                "TEMP",
                Some("spindle temperature"),
                &Some(Sample::Float(50.0))
            )
        );
        assert_eq!(
            s.changes,
            [
                (3_000, Some(Sample::Float(70.0))),
                (5_000, Some(Sample::Float(85.0))),
                (6_000, Some(Sample::UInt(90))),
                (7_000, None)
            ]
        );
    }

    #[test]
    fn a_timer_alarm_records_its_transition_signals() {
        use crate::timer::checks::TimerChecks;
        use crate::timer::learn::{Edge, Event, TimerModel, Transition, MODEL_VERSION};
        let model = TimerModel {
            version: MODEL_VERSION,
            method: "common".into(),
            signals: vec!["move".into(), "arrived".into(), "other".into()],
            transitions: vec![Transition {
                id: 7,
                from: vec![],
                event: Event {
                    tag: "arrived".into(),
                    edge: Edge::Rise,
                },
                to: vec![],
                delta_ms: 6000,
                min_ms: 5950,
                max_ms: 6050,
                support: 4,
                window_ms: [5700, 6300],
                from_numbered: None,
                trigger: Some(Event {
                    tag: "move".into(),
                    edge: Edge::Rise,
                }),
            }],
        };
        let tags: Vec<Tag> = [("move", "Y1.00"), ("arrived", "X1.00"), ("other", "X1.01")]
            .into_iter()
            .map(|(n, a)| Tag {
                name: n.into(),
                address: Signal::new(a),
            })
            .collect();
        let checks = TimerChecks::new("line", &model, Severity::High, |n| {
            tags.iter().find(|t| t.name == n).map(|t| t.address.clone())
        })
        .unwrap();
        let mut e = CellEngine::new("c", tags, vec![Box::new(checks)], StateRules::default())
            .unwrap()
            .recording(config(7_000, 2_000));
        e.on_connection(true, 0);
        for t in 0..3 {
            e.on_reading(t, Reading::Good(false), 0, 0);
        }
        e.on_reading(0, Reading::Good(true), 1_000, 1_000);
        e.on_reading(2, Reading::Good(true), 2_000, 2_000);
        let step = e.advance(7_300);
        assert_eq!(raised(&step), ["line-007"]);
        // The recording ends 2 s after the raise, by the clock.
        assert_eq!(e.next_deadline(), Some(9_300));
        e.on_reading(1, Reading::Good(true), 8_000, 8_000);
        let step = e.advance(9_300);
        let [r] = &step.recordings[..] else {
            panic!("{step:?}")
        };
        let y100 = RecordedSignal {
            address: "Y1.00".into(),
            name: Some("move".into()),
            start: Some(Sample::Bool(false)),
            changes: vec![(1_000, Some(Sample::Bool(true)))],
        };
        let x100 = RecordedSignal {
            address: "X1.00".into(),
            name: Some("arrived".into()),
            start: Some(Sample::Bool(false)),
            changes: vec![(8_000, Some(Sample::Bool(true)))],
        };
        assert_eq!(r.signals, [y100, x100]);
        assert_eq!((r.from, r.to, r.holds_to), (300, 9_300, 9_300));
    }

    /// A recorder over `n` tags, all read by a check.
    fn recorder(n: usize, config: RecorderConfig) -> Recorder {
        Recorder::new(config, vec![true; n])
    }

    fn read(tag: usize) -> Read {
        Read {
            tag,
            address: format!("X{tag}.00"),
            name: None,
            value: Some(Value::Bool(false)),
        }
    }

    #[test]
    fn a_flood_over_100_000_tags_keeps_the_ring_and_the_recordings_at_their_bounds() {
        let config = RecorderConfig {
            before: 60_000,
            after: 60_000,
            ..RecorderConfig::default()
        };
        let (capacity, max_changes) = (config.capacity, config.max_changes);
        let mut r = recorder(100_000, config);
        let mut v = vec![false; 100_000];
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut started = false;
        for k in 0..1_000_000u64 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            // Tag 7 changes one time in eight, the others at random.
            let tag = if k % 8 == 0 {
                7
            } else {
                (x % 100_000) as usize
            };
            v[tag] = !v[tag];
            r.change_bool(tag, k / 100, Some(!v[tag]), Some(v[tag]));
            if k == 500_000 {
                // One recording of tags that change seldom, one of tag 7.
                r.start("seldom", k / 100, vec![read(8), read(9)]);
                r.start("often", k / 100, vec![read(7)]);
                started = true;
            }
            assert!(r.ring.len() <= capacity);
        }
        assert!(started);
        let fill = r.fill();
        assert_eq!((fill.changes, fill.capacity), (capacity, capacity));
        assert_eq!(r.ring.capacity(), capacity);
        assert_eq!(
            fill.bytes,
            capacity * std::mem::size_of::<Change>() + 100_000 * 13
        );
        assert_eq!(std::mem::size_of::<Change>(), 64);
        let mut done = Vec::new();
        r.take_done(&mut done);
        // Tag 7's: its 8,000 changes in the ring before the raise cut to
        // the latest 1,000, and complete at 1,000 after it.
        let [often] = &done[..] else {
            panic!("{}", done.len())
        };
        assert_eq!(often.alarm, "often");
        assert_eq!(
            often.truncated,
            Truncated {
                start: Some(Cut::Changes),
                end: Some(Cut::Changes)
            }
        );
        let after = |rec: &Recording| {
            rec.signals
                .iter()
                .flat_map(|s| &s.changes)
                .filter(|(at, _)| *at > rec.raised_at)
                .count()
        };
        // Changes in the raise's millisecond may be on either side of it;
        // those that share the cut's millisecond go with it.
        assert!(after(often) <= max_changes);
        assert!(
            (2 * max_changes - 20..=2 * max_changes).contains(&often.changes()),
            "{}",
            often.changes()
        );
        assert!(
            often.bytes() < 2 * max_changes * 48 + 1_000,
            "{}",
            often.bytes()
        );
        // The other's: the ring held the last 655 ms before the raise (at
        // 5 s) of the 60 s asked; complete at its end.
        r.finish_due(5_000 + 60_000);
        r.take_done(&mut done);
        let seldom = &done[1];
        assert_eq!(seldom.alarm, "seldom");
        assert_eq!(
            seldom.truncated,
            Truncated {
                start: Some(Cut::Ring),
                end: None
            }
        );
        assert_eq!(seldom.from, 0);
        assert!(
            (4_300..4_400).contains(&seldom.holds_from),
            "{}",
            seldom.holds_from
        );
        assert_eq!(seldom.holds_to, seldom.to);
    }

    #[test]
    fn the_latest_changes_before_the_raise_are_kept_to_the_bound() {
        let mut r = recorder(
            2,
            RecorderConfig {
                max_changes: 3,
                ..config(10_000, 0)
            },
        );
        for (k, at) in [1_000u64, 2_000, 3_000, 3_000, 4_000, 5_000]
            .into_iter()
            .enumerate()
        {
            let v = k % 2 == 0;
            r.change_bool(0, at, Some(!v), Some(v));
        }
        r.start("a", 5_000, vec![read(0)]);
        let mut done = Vec::new();
        r.finish_due(5_000);
        r.take_done(&mut done);
        let rec = &done[0];
        // Three kept; the two at 3 s cannot be told apart: both go.
        assert_eq!(rec.truncated.start, Some(Cut::Changes));
        assert_eq!(rec.holds_from, 3_001);
        assert_eq!(rec.signals[0].start, Some(Sample::Bool(false)));
        assert_eq!(
            bool_changes(&rec.signals[0]),
            [(4_000, Some(true)), (5_000, Some(false))]
        );
    }

    #[test]
    fn past_the_open_bound_an_alarm_gets_its_before_part_at_once() {
        let mut r = recorder(
            3,
            RecorderConfig {
                max_open: 1,
                ..config(10_000, 5_000)
            },
        );
        r.change_bool(0, 1_000, None, Some(true));
        r.change_bool(1, 2_000, None, Some(true));
        r.start("first", 2_000, vec![read(0)]);
        r.start("second", 3_000, vec![read(1)]);
        let mut done = Vec::new();
        r.take_done(&mut done);
        let [second] = &done[..] else {
            panic!("{done:?}")
        };
        assert_eq!(second.alarm, "second");
        assert_eq!(
            (second.truncated.end, second.holds_to),
            (Some(Cut::Busy), 3_000)
        );
        assert_eq!(bool_changes(&second.signals[0]), [(2_000, Some(true))]);
        // The first goes on, and a tag it does not read costs it nothing.
        r.change_bool(2, 4_000, None, Some(true));
        r.change_bool(0, 5_000, Some(true), Some(false));
        assert_eq!(r.next_deadline(), Some(7_000));
        r.pass(7_001);
        r.take_done(&mut done);
        let first = &done[1];
        assert_eq!(first.alarm, "first");
        assert_eq!(
            bool_changes(&first.signals[0]),
            [(1_000, Some(true)), (5_000, Some(false))]
        );
        assert_eq!(first.signals[0].start, None);
        assert_eq!(r.fill().open, 0);
    }

    #[test]
    fn a_change_stamped_before_the_latest_is_kept_at_the_latest() {
        let mut r = recorder(1, config(10_000, 5_000));
        r.change_bool(0, 5_000, None, Some(true));
        r.change_bool(0, 4_000, Some(true), Some(false));
        r.start("a", 5_000, vec![read(0)]);
        r.finish_due(10_000);
        let mut done = Vec::new();
        r.take_done(&mut done);
        assert_eq!(
            bool_changes(&done[0].signals[0]),
            [(5_000, Some(true)), (5_000, Some(false))]
        );
    }

    #[test]
    fn a_recording_is_plain_json_and_comes_back_the_same() {
        let rec = Recording {
            alarm: "temp-h".into(),
            raised_at: 5_000,
            from: 2_000,
            to: 9_000,
            holds_from: 2_000,
            holds_to: 7_000,
            truncated: Truncated {
                start: None,
                end: Some(Cut::Busy),
            },
            signals: vec![
                RecordedSignal {
                    address: "TEMP".into(),
                    name: Some("spindle temperature".into()),
                    start: Some(Sample::Float(50.0)),
                    changes: vec![
                        (3_000, Some(Sample::UInt(90))),
                        (4_000, Some(Sample::Int(-3))),
                        (5_000, None),
                        (6_000, Some(Sample::Text("A-113".into()))),
                    ],
                },
                RecordedSignal {
                    address: "X0.06".into(),
                    name: None,
                    start: Some(Sample::Bool(true)),
                    changes: vec![(5_000, Some(Sample::Bool(false)))],
                },
            ],
        };
        let json = serde_json::to_string(&rec).unwrap();
        assert_eq!(
            json,
            r#"{"alarm":"temp-h","raised_at":5000,"from":2000,"to":9000,"holds_from":2000,"holds_to":7000,"truncated":{"start":null,"end":"busy"},"signals":[{"address":"TEMP","name":"spindle temperature","start":50.0,"changes":[[3000,90],[4000,-3],[5000,null],[6000,"A-113"]]},{"address":"X0.06","start":true,"changes":[[5000,false]]}]}"#
        );
        assert_eq!(serde_json::from_str::<Recording>(&json).unwrap(), rec);
    }

    mod model {
        use super::*;
        use proptest::prelude::*;

        #[derive(Debug, Clone)]
        enum Op {
            /// A tag's reading, `dt` ms after the last (or before it, when
            /// `back`).
            Read {
                tag: usize,
                value: u8,
                dt: u64,
                back: bool,
            },
            /// The connection drops and comes back.
            Cut { dt: u64 },
            /// Time passes.
            Wait { dt: u64 },
        }

        fn op() -> impl Strategy<Value = Op> {
            prop_oneof![
                6 => (0usize..24, 0u8..6, 0u64..400, prop::bool::weighted(0.05))
                    .prop_map(|(tag, value, dt, back)| Op::Read { tag, value, dt, back }),
                1 => (0u64..400).prop_map(|dt| Op::Cut { dt }),
                1 => (0u64..3_000).prop_map(|dt| Op::Wait { dt }),
            ]
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(64))]

            /// The value a recording says a signal had at any time it holds
            /// is the value the engine held then.
            #[test]
            fn a_recording_says_what_the_engine_held(
                ops in prop::collection::vec(op(), 1..300),
                capacity in 20usize..400,
                max_changes in 2usize..60,
            ) {
                let mut e = ese_engine(true, RecorderConfig {
                    capacity,
                    max_changes,
                    max_open: 2,
                    ..config(1_500, 800)
                });
                let n = e.tags().len();
                let (x006, temp) = (
                    e.tag_index(&Signal::new("X0.06")).unwrap(),
                    e.tag_index(&Signal::new("TEMP")).unwrap(),
                );
                load_normal(&mut e, 1);
                // The latest time of anything; the engine's latest source
                // time; the recorder's latest change; the clock's latest
                // look (no reading goes back past it: a change delivered
                // after its window was closed by the clock is not in it).
                let (mut clock, mut source_latest, mut kept, mut floor) = (1u64, 1u64, 1u64, 0u64);
                // Per tag: (time, value) after each change.
                let mut held: Vec<Vec<(u64, Option<Value>)>> =
                    (0..n).map(|tag| vec![(0, None), (1, e.value(tag))]).collect();
                let mut recordings = Vec::new();
                for op in ops {
                    let step = match op {
                        Op::Read { tag, value, dt, back } => {
                            // Most readings are of X0.06 and TEMP, which
                            // raise alarms.
                            let tag = match tag {
                                0..=5 => x006,
                                6..=11 => temp,
                                t => t % n,
                            };
                            let source = if back {
                                clock.saturating_sub(dt).max(floor)
                            } else {
                                clock + dt
                            };
                            let reading = match (tag == temp, value) {
                                (_, 0) => Reading::Bad,
                                (true, v) => Reading::Number(Num::Float(f64::from(v) * 20.0)),
                                (false, v) => Reading::Good(v % 2 == 1),
                            };
                            let was = e.value(tag);
                            let step = e.on_reading(tag, reading, source, source.max(clock));
                            source_latest = source_latest.max(source);
                            clock = clock.max(source);
                            if e.value(tag) != was {
                                kept = kept.max(source_latest);
                                held[tag].push((kept, e.value(tag)));
                            }
                            step
                        }
                        Op::Cut { dt } => {
                            clock += dt;
                            floor = clock;
                            kept = clock;
                            let mut step = e.on_connection(false, clock);
                            step.recordings.extend(e.on_connection(true, clock).recordings);
                            for (tag, h) in held.iter_mut().enumerate() {
                                h.push((clock, e.value(tag)));
                            }
                            step
                        }
                        Op::Wait { dt } => {
                            clock += dt;
                            floor = clock;
                            e.advance(clock)
                        }
                    };
                    recordings.extend(step.recordings);
                }
                recordings.extend(e.advance(clock + 10_000).recordings);
                prop_assert_eq!(e.recorder_fill().unwrap().open, 0);
                for rec in &recordings {
                    for (i, s) in rec.signals.iter().enumerate() {
                        let tag = e.tag_index(&Signal::new(&s.address)).unwrap();
                        let mut times: Vec<u64> = held[tag].iter().map(|(at, _)| *at).collect();
                        times.extend([rec.holds_from, rec.holds_to]);
                        for at in times {
                            for at in [at.saturating_sub(1), at] {
                                let Some(said) = rec.value_at(i, at) else { continue };
                                let k = held[tag].partition_point(|(h, _)| *h <= at);
                                let was = held[tag][k - 1].1.as_ref().map(Sample::from);
                                prop_assert_eq!(
                                    said, was.as_ref(),
                                    "{} at {} in {:?}", s.address, at, rec
                                );
                            }
                        }
                        prop_assert!(s.changes.windows(2).all(|w| w[0].0 <= w[1].0));
                    }
                    // Changes in the raise's millisecond may be on either
                    // side of it.
                    let before = rec.signals.iter().flat_map(|s| &s.changes)
                        .filter(|(at, _)| *at < rec.raised_at).count();
                    prop_assert!(before <= max_changes);
                    prop_assert!(rec.changes() <= 2 * max_changes);
                }
            }
        }
    }
}
