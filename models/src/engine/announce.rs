//! Announcing: a finding applied to the alarm book and its transition put
//! in the step (a raise marked a consequence of an active cause, the last
//! fault marked, its flight recording started); the engine's own alarms'
//! findings (`tag-quality`, the agent's system conditions); the machine
//! state that follows from the alarms and the running rule; and the
//! checks' observations and the finished recordings emptied into each step.
//! When a finding is due (its delay) is `delays.rs`'s.

use super::{
    BadQuality, CellEngine, EngineEvent, EngineStep, FaultMark, Finding, HistoryKind, MachineState,
    Tag,
};
use crate::alarm::{AlarmKind, Consequence, Severity, Transition};
use crate::signal::Signal;

/// How many bad tags the `tag-quality` alarm names.
const QUALITY_NAMED: usize = 20;

impl CellEngine {
    /// A condition of the agent itself (`journal`: it cannot write) began
    /// (`problem` is why) or ended.
    pub fn on_system(&mut self, id: &str, problem: Option<&str>, now: u64) -> EngineStep {
        let mut step = EngineStep::default();
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

    pub(super) fn collect_observations(&mut self, step: &mut EngineStep) {
        for set in &mut self.sets {
            set.take_observations(&mut step.observations);
        }
        if let Some(recorder) = &mut self.recorder {
            recorder.take_done(&mut step.recordings);
        }
    }

    /// Whether alarm `id` is active now (raised, or its clear waiting out
    /// its off-delay).
    pub(super) fn is_active(&self, id: &str) -> bool {
        self.alarms.get(id).is_some_and(|a| a.active)
    }

    pub(super) fn quality_finding(&self) -> Finding {
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

    /// Applies a finding to the alarm book and reports the transition, at
    /// `now` (never before the alarm's last transition).
    pub(super) fn announce(&mut self, mut f: Finding, now: u64, step: &mut EngineStep) {
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
        let f = self.prioritised(f);
        let id = f.id.clone();
        let applied = self.alarms.apply(f, now);
        let Some(transition) = applied.transition else {
            return;
        };
        if transition == Transition::Raised {
            if let Some(c) = self.consequence_of(&id) {
                self.alarms.set_consequence(&id, c);
            }
            if let Some(guidance) = self.guidance_of(&id) {
                self.alarms.set_guidance(&id, guidance);
            }
            if let Some(mode) = self.designed_for(&id) {
                let designed = crate::alarm::DesignedSuppression {
                    mode: mode.to_string(),
                    since: now,
                };
                self.alarms.set_designed(&id, Some(Box::new(designed)));
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
    /// without the fault ([`CheckSet::without`](super::CheckSet::without)),
    /// re-derived from the cell's values now.
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

    pub(super) fn update_state(&mut self, now: u64, step: &mut EngineStep) {
        if !self.rules.modes.is_empty() {
            self.update_modes(now, step);
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fixture::*;
    use crate::engine::{Reading, TagReading};

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
}
