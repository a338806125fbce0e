//! The recorder itself: the ring of recent changes of the tags some check
//! reads, the recordings under way and their bounds, and what the ring
//! holds ([`RecorderFill`]). It owns keeping and following changes; what a
//! recording holds is `recording.rs`'s, the bounds' settings are
//! [`super::RecorderConfig`].

use std::collections::{BinaryHeap, VecDeque};

use super::recording::{Cut, RecordedSignal, Recording, Sample, Truncated};
use super::{RecorderConfig, MAX_OPEN};
use crate::engine::tag::Value;

/// What the ring holds now ([`CellEngine::recorder_fill`](crate::engine::CellEngine::recorder_fill)).
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
    /// Changes looked at in the ring by starting recordings, ever.
    walked: u64,
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
            walked: 0,
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
                // Changes at `at` are dropped: the recording holds up to
                // just before them, even if that is before its raise.
                let holds_to = at.saturating_sub(1);
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

    /// The clock reached `now`: the recordings that end before it are
    /// complete. One that ends at `now` stays open: a change stamped in
    /// that millisecond may still be on its way, as after
    /// [`Recorder::pass`].
    pub(crate) fn finish_due(&mut self, now: u64) {
        if self.next_end.is_some_and(|end| end < now) {
            self.finish(|to| to < now);
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

    /// The earliest time the clock completes a recording under way (the
    /// millisecond after its end), if any.
    pub(crate) fn next_deadline(&self) -> Option<u64> {
        self.next_end.map(|end| end.saturating_add(1))
    }

    /// Changes looked at in the ring by starting recordings, ever.
    #[cfg(test)]
    pub(crate) fn walked(&self) -> u64 {
        self.walked
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
        // The signals' changes merged as they came, walked back from the
        // latest along each signal's own chain: changes after the raise,
        // then at most `max_changes` up to it (the latest). The walk stops
        // there, so its cost is in what the recording keeps, not in what
        // the ring holds.
        let first = self.pushed - self.ring.len() as u64;
        let change = |n: u64| &self.ring[(n - first) as usize];
        let mut heads: BinaryHeap<(u64, usize)> = reads
            .iter()
            .enumerate()
            .filter(|(_, r)| self.last[r.tag] > first)
            .map(|(i, r)| (self.last[r.tag] - 1, i))
            .collect();
        let mut picked: Vec<(u64, usize)> = Vec::new();
        let mut before = 0;
        let mut walked = 0;
        while let Some((n, i)) = heads.pop() {
            walked += 1;
            let c = change(n);
            debug_assert_eq!(
                c.tag as usize, reads[i].tag,
                "a tag's chain holds its own changes"
            );
            if c.at < holds_from {
                break;
            }
            if c.at <= raised_at {
                if before == self.config.max_changes {
                    // Changes at the cut's time are left out with it.
                    let cut = c.at;
                    while picked.last().is_some_and(|&(m, _)| change(m).at <= cut) {
                        picked.pop();
                    }
                    holds_from = cut + 1;
                    truncated.start = Some(Cut::Changes);
                    break;
                }
                before += 1;
            }
            picked.push((n, i));
            let back = u64::from(c.back);
            if back != 0 && n + 1 - back > first {
                heads.push((n - back, i));
            }
        }
        picked.reverse();
        let picked = &picked[..];
        self.walked += walked;
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
                    cut_end = Some(c.at.saturating_sub(1));
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
            // Not followed: later changes stamped in the raise's (or the
            // newest change's) millisecond may still come, so the recording
            // holds up to just before it.
            (None, None) => {
                let holds_to = newest.max(raised_at).saturating_sub(1).min(to);
                self.close(open, holds_to, Some(Cut::Busy));
            }
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
    use super::super::tests::{bool_changes, config};
    use super::*;

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
        r.finish_due(5_000 + 60_000 + 1);
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
        r.finish_due(5_001);
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
    fn a_raise_looks_at_what_its_recording_keeps_whatever_the_ring_holds() {
        // 32 signals changing 6.4 times a millisecond for 10 s: 64,000
        // changes in the ring, all inside the window before the raise.
        let config = config(10_000, 5_000);
        let max_changes = config.max_changes;
        let mut r = recorder(32, config);
        let mut v = [false; 32];
        for k in 0..64_000u64 {
            let tag = (k % 32) as usize;
            v[tag] = !v[tag];
            r.change_bool(tag, k * 10 / 64, Some(!v[tag]), Some(v[tag]));
        }
        assert_eq!(r.fill().changes, 64_000);
        r.start("flood", 10_000, (0..32).map(read).collect());
        // The latest 1,000 and the one that says where they start.
        assert!(r.walked() <= max_changes as u64 + 1, "{}", r.walked());
        r.finish_due(15_001);
        let mut done = Vec::new();
        r.take_done(&mut done);
        let rec = &done[0];
        // The latest 1,000, less those stamped in the cut's millisecond
        // (at most 6 more of them: 6.4 changes a millisecond).
        assert!(
            (max_changes - 6..=max_changes).contains(&rec.changes()),
            "{}",
            rec.changes()
        );
        assert_eq!(rec.truncated.start, Some(Cut::Changes));
        // Each signal starts at the value its first kept change left.
        for s in &rec.signals {
            let (_, first) = &s.changes[0];
            assert_ne!(s.start.as_ref(), first.as_ref(), "{s:?}");
        }
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
            (Some(Cut::Busy), 2_999)
        );
        assert_eq!(bool_changes(&second.signals[0]), [(2_000, Some(true))]);
        // The first goes on, and a tag it does not read costs it nothing.
        r.change_bool(2, 4_000, None, Some(true));
        r.change_bool(0, 5_000, Some(true), Some(false));
        assert_eq!(r.next_deadline(), Some(7_001));
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
        r.finish_due(10_001);
        let mut done = Vec::new();
        r.take_done(&mut done);
        assert_eq!(
            bool_changes(&done[0].signals[0]),
            [(5_000, Some(true)), (5_000, Some(false))]
        );
    }
}
