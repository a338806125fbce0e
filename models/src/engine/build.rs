//! Building the engine: [`CellEngine::new`] over the configured tags, the
//! check sets and the state rules (each comparison contact made a tag of its
//! own, the lists of who reads each tag), and the settings that follow it:
//! the relation between alarms, parts counting, exported tags, comments,
//! delays, the work order's tags and the trust in the source's clock.
//! Taking the PLC's conditions is `conditions.rs`'s, the flight recorder
//! `recording.rs`'s.

use std::collections::{BTreeMap, HashMap};

use super::alarms::AlarmBook;
use super::{
    CellEngine, CheckSet, Derived, EngineError, MachineState, Order, PartCounting, PerTag, Rhs,
    StateRules, Tag,
};
use crate::comments::CommentDb;
use crate::consequence::Relation;
use crate::signal::Signal;
use crate::value::{CmpOperand, Comparison};

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
        for mode in &rules.modes {
            for s in mode.when.signals() {
                wanted.push((format!("mode '{}'", mode.id), s));
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
                CmpOperand::Const(n) => Rhs::Const(*n),
                CmpOperand::Tag(a) => Rhs::Tag(find(a)?),
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
        let state_exprs = rules
            .running
            .iter()
            .chain(rules.modes.iter().map(|m| &m.when));
        for expr in state_exprs {
            for s in expr.signals() {
                running_reads[by_address[&s]] = true;
            }
        }
        let modes_on = vec![false; rules.modes.len()];
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
            modes_on,
            rationale: crate::madb::Rationalisation::default(),
            alarms,
            connected: None,
            rules,
            state: MachineState::Offline,
            last_fault: None,
            parts: PartCounting::None,
            rejects: PartCounting::None,
            exported: vec![false; configured],
            delays: HashMap::new(),
            comments: CommentDb::default(),
            pending: BTreeMap::new(),
            order_tags: (None, None),
            order: Order::default(),
            recorder: None,
            conditions: Vec::new(),
            clock: 0,
            unheard: configured,
            settling: None,
            awaiting_first: true,
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
    /// ([`Step::parts`](super::Step::parts)).
    #[must_use]
    pub fn counting_parts(self, tag: Option<usize>) -> Self {
        self.counting(tag.map_or(PartCounting::None, PartCounting::Edge))
    }

    /// Reports the changes of these tags in [`Step::exported`](super::Step::exported).
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
    /// [`Step::order`](super::Step::order).
    #[must_use]
    pub fn ordering(mut self, item: Option<usize>, target: Option<usize>) -> Self {
        let fits = |t: Option<usize>| t.filter(|&t| t < self.configured);
        self.order_tags = (fits(item), fits(target));
        self
    }

    /// Counts parts as `how` says ([`Step::parts`](super::Step::parts)).
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

    /// Counts rejected parts as `how` says
    /// ([`Step::rejects`](super::Step::rejects)).
    #[must_use]
    pub fn counting_rejects(mut self, how: PartCounting) -> Self {
        let parts = std::mem::replace(&mut self.parts, PartCounting::None);
        self = self.counting(how);
        self.rejects = std::mem::replace(&mut self.parts, parts);
        self
    }
}
