//! The plant as the console knows it: every cell (its machine state, its
//! agent's presence, its last fault) and every alarm an operator must see,
//! kept from what the cells' agents signed.
//!
//! Events arrive out of order and twice (a late joiner's cache, a
//! snapshot asked while events flow): an alarm event is taken only if it
//! is not older than what is known of that alarm, nor sealed before the
//! cell's last snapshot was taken, so that an old "raised" never brings
//! back an alarm that has since ended. Against a snapshot an event is
//! judged by when its agent sealed it, not by when its fault happened: a
//! fault that happened before the snapshot but reached the agent after it
//! is not in it, and is taken. Times are the agents' RFC 3339 UTC
//! strings, which sort as they read. What is kept is bounded: `max_alarms`
//! alarms at most.

use std::collections::{BTreeMap, HashMap};

use serde::Serialize;

use crate::payload::{AlarmPayload, LastFault, SnapshotPayload, StatePayload};
use cellwatch_models::alarm::{AlarmState, Transition};

/// One cell, as the overview shows it.
#[derive(Debug, Clone, Default, Serialize, PartialEq, Eq)]
pub(crate) struct Cell {
    /// The cell's id.
    pub cell: String,
    /// Its area, when the console's configuration names one.
    pub area: Option<String>,
    /// Whether its agent's session is on the bus (its liveliness token).
    pub agent: bool,
    /// Whether the agent is connected to its PLC, from the last snapshot;
    /// `None` before one was had.
    pub connected: Option<bool>,
    /// The last machine state it published.
    pub state: Option<StatePayload>,
    /// The last fault raised.
    pub last_fault: Option<Fault>,
    /// When the agent's last snapshot was taken (its clock).
    pub synced_at: Option<String>,
}

/// A cell's last fault.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub(crate) struct Fault {
    /// The alarm raised.
    pub alarm: String,
    /// When.
    pub at: String,
    /// Its message, when the console saw it raised.
    pub message: Option<String>,
}

/// A change the pages are told of.
#[derive(Debug, Clone, Serialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub(crate) enum Change {
    /// An alarm's new state; a `normal` alarm neither shelved nor out of
    /// service is no longer shown.
    Alarm {
        /// The event.
        alarm: Box<AlarmPayload>,
    },
    /// A cell's new view.
    Cell {
        /// The cell.
        cell: Box<Cell>,
    },
}

/// Everything at once: what a page starts from.
#[derive(Debug, Serialize)]
pub(crate) struct View<'a> {
    /// `snapshot`.
    #[serde(rename = "type")]
    pub kind: &'static str,
    /// Every cell.
    pub cells: Vec<&'a Cell>,
    /// Every alarm shown.
    pub alarms: Vec<&'a AlarmPayload>,
    /// The areas, in order.
    pub areas: Vec<&'a str>,
    /// Alarms not kept because `max_alarms` were already.
    pub dropped: u64,
}

/// The plant's cells and alarms.
pub(crate) struct Plant {
    cells: BTreeMap<String, Cell>,
    alarms: BTreeMap<(String, String), AlarmPayload>,
    area_of: HashMap<String, String>,
    areas: Vec<String>,
    max_alarms: usize,
    dropped: u64,
    /// When each alarm no longer shown ended (its last event), so that a
    /// replayed older event does not bring it back before the cell's next
    /// snapshot: at most `max_alarms`, the oldest forgotten first.
    ended: HashMap<(String, String), String>,
    ended_order: std::collections::VecDeque<(String, String)>,
    /// When the agent sealed the event each shown alarm was last taken
    /// from (none: from a snapshot), so that a snapshot taken before it
    /// does not remove it.
    sealed: HashMap<(String, String), String>,
}

/// Whether an operator must see `a`: active or unacknowledged, shelved or
/// out of service.
pub(crate) fn shown(a: &AlarmPayload) -> bool {
    a.state != AlarmState::Normal || a.shelved.is_some() || a.out_of_service.is_some()
}

impl Plant {
    /// A plant of the cells in `trusted` (the trust file's), grouped by
    /// `areas`, keeping at most `max_alarms` alarms.
    pub(crate) fn new<'a>(
        trusted: impl IntoIterator<Item = &'a str>,
        areas: &BTreeMap<String, Vec<String>>,
        max_alarms: usize,
    ) -> Plant {
        let area_of: HashMap<String, String> = areas
            .iter()
            .flat_map(|(area, cells)| cells.iter().map(move |c| (c.clone(), area.clone())))
            .collect();
        let mut plant = Plant {
            cells: BTreeMap::new(),
            alarms: BTreeMap::new(),
            area_of,
            areas: areas.keys().cloned().collect(),
            max_alarms,
            dropped: 0,
            ended: HashMap::new(),
            ended_order: std::collections::VecDeque::new(),
            sealed: HashMap::new(),
        };
        for cell in trusted {
            plant.cell_mut(cell);
        }
        plant
    }

    fn cell_mut(&mut self, cell: &str) -> &mut Cell {
        let area = self.area_of.get(cell).cloned();
        self.cells.entry(cell.to_string()).or_insert_with(|| Cell {
            cell: cell.to_string(),
            area,
            ..Cell::default()
        })
    }

    /// Everything, for a page that starts.
    pub(crate) fn view(&self) -> View<'_> {
        View {
            kind: "snapshot",
            cells: self.cells.values().collect(),
            alarms: self.alarms.values().collect(),
            areas: self.areas.iter().map(String::as_str).collect(),
            dropped: self.dropped,
        }
    }

    /// The alarm `id` of `cell`, if shown.
    #[cfg(test)]
    pub(crate) fn alarm(&self, cell: &str, id: &str) -> Option<&AlarmPayload> {
        self.alarms.get(&(cell.to_string(), id.to_string()))
    }

    /// The cell `cell`, if known.
    pub(crate) fn cell(&self, cell: &str) -> Option<&Cell> {
        self.cells.get(cell)
    }

    /// How many alarms are shown.
    #[cfg(test)]
    pub(crate) fn alarm_count(&self) -> usize {
        self.alarms.len()
    }

    /// Takes an alarm event its cell's agent signed, at `sealed` (its
    /// clock, RFC 3339); returns what changed.
    pub(crate) fn alarm_event(&mut self, a: AlarmPayload, sealed: &str) -> Vec<Change> {
        let mut changes = Vec::new();
        if self.stale(&a) {
            return changes;
        }
        let cell = self.cell_mut(&a.cell);
        if cell.synced_at.as_deref().is_some_and(|s| sealed < s) {
            return changes;
        }
        if a.transition == Transition::Raised {
            cell.last_fault = Some(Fault {
                alarm: a.id.clone(),
                at: a.at.clone(),
                message: Some(a.message.clone()),
            });
            changes.push(Change::Cell {
                cell: Box::new(cell.clone()),
            });
        }
        if let Some(change) = self.take(a, Some(sealed)) {
            changes.push(change);
        }
        changes
    }

    /// Keeps or drops `a` unless what is known of it is newer. A clear, an
    /// acknowledgement, a shelf or a removal of the occurrence known keeps
    /// that occurrence's diagnosis (message, culprits, step): the table
    /// shows what the alarm is, not "cleared".
    fn take(&mut self, mut a: AlarmPayload, sealed: Option<&str>) -> Option<Change> {
        let key = (a.cell.clone(), a.id.clone());
        if self.ended.get(&key).is_some_and(|at| *at > a.at) {
            return None;
        }
        if let Some(known) = self.alarms.get(&key) {
            if known.at > a.at {
                return None;
            }
            let of_its_occurrence = matches!(
                a.transition,
                Transition::Cleared
                    | Transition::Acknowledged
                    | Transition::Shelved
                    | Transition::Unshelved
                    | Transition::OutOfService
                    | Transition::InService
            );
            if of_its_occurrence && known.raised_at == a.raised_at {
                a.message.clone_from(&known.message);
                a.culprits.clone_from(&known.culprits);
                a.fault_step = known.fault_step;
                a.fault_type.clone_from(&known.fault_type);
            }
        }
        if shown(&a) {
            if !self.alarms.contains_key(&key) && self.alarms.len() >= self.max_alarms {
                self.dropped += 1;
                if self.dropped.is_power_of_two() {
                    tracing::warn!(
                        max = self.max_alarms,
                        dropped = self.dropped,
                        "more alarms than console.max_alarms: the newest are not shown"
                    );
                }
                return None;
            }
            if self.ended.remove(&key).is_some() {
                self.ended_order.retain(|k| *k != key);
            }
            match sealed {
                Some(sealed) => self.sealed.insert(key.clone(), sealed.to_string()),
                None => self.sealed.remove(&key),
            };
            self.alarms.insert(key, a.clone());
        } else {
            self.alarms.remove(&key);
            self.sealed.remove(&key);
            self.end(key, &a.at);
        }
        Some(Change::Alarm { alarm: Box::new(a) })
    }

    /// Whether what is known of `a`'s alarm (shown, or ended) is newer.
    fn stale(&self, a: &AlarmPayload) -> bool {
        let key = (a.cell.clone(), a.id.clone());
        self.ended.get(&key).is_some_and(|at| *at > a.at)
            || self.alarms.get(&key).is_some_and(|known| known.at > a.at)
    }

    /// Remembers when the alarm `key` ended.
    fn end(&mut self, key: (String, String), at: &str) {
        match self.ended.get_mut(&key) {
            Some(known) => at.clone_into(known),
            None => {
                if self.ended.len() >= self.max_alarms {
                    if let Some(oldest) = self.ended_order.pop_front() {
                        self.ended.remove(&oldest);
                    }
                }
                self.ended.insert(key.clone(), at.to_string());
                self.ended_order.push_back(key);
            }
        }
    }

    /// Takes a cell's machine state; returns the cell's new view unless an
    /// older state than the one known.
    pub(crate) fn state(&mut self, s: StatePayload) -> Option<Change> {
        let cell = self.cell_mut(&s.cell);
        if cell.state.as_ref().is_some_and(|known| known.at > s.at) {
            return None;
        }
        cell.state = Some(s);
        Some(Change::Cell {
            cell: Box::new(cell.clone()),
        })
    }

    /// A cell's agent came (`true`) or went; a cell outside the trust
    /// file is not taken from a token (tokens are not signed).
    pub(crate) fn agent(&mut self, cell: &str, up: bool) -> Option<Change> {
        let c = self.cells.get_mut(cell)?;
        if c.agent == up {
            return None;
        }
        c.agent = up;
        Some(Change::Cell {
            cell: Box::new(c.clone()),
        })
    }

    /// Takes a cell's snapshot: its alarms replace those known that are
    /// not newer than it; returns what changed.
    pub(crate) fn snapshot(&mut self, s: SnapshotPayload) -> Vec<Change> {
        let mut changes = Vec::new();
        let name = s.cell.clone();
        let cell = self.cell_mut(&name);
        if cell.synced_at.as_ref().is_some_and(|known| known > &s.at) {
            return changes;
        }
        cell.synced_at = Some(s.at.clone());
        cell.connected = Some(s.connected);
        if let Some(LastFault { alarm, at, .. }) = &s.last_fault {
            if cell.last_fault.as_ref().is_none_or(|f| &f.at < at) {
                cell.last_fault = Some(Fault {
                    alarm: alarm.clone(),
                    at: at.clone(),
                    message: None,
                });
            }
        }
        changes.push(Change::Cell {
            cell: Box::new(cell.clone()),
        });
        let listed: std::collections::HashSet<&str> =
            s.alarms.iter().map(|a| a.id.as_str()).collect();
        let gone: Vec<AlarmPayload> = self
            .alarms
            .range((name.clone(), String::new())..)
            .take_while(|((c, _), _)| *c == name)
            .filter(|(key, a)| {
                !listed.contains(key.1.as_str())
                    && a.at <= s.at
                    && self.sealed.get(*key).is_none_or(|sealed| *sealed < s.at)
            })
            .map(|(_, a)| a.clone())
            .collect();
        for mut a in gone {
            let key = (a.cell.clone(), a.id.clone());
            self.alarms.remove(&key);
            self.sealed.remove(&key);
            self.end(key, &s.at);
            // Said to the pages as an alarm that ended.
            a.state = AlarmState::Normal;
            a.shelved = None;
            a.out_of_service = None;
            a.at.clone_from(&s.at);
            changes.push(Change::Alarm { alarm: Box::new(a) });
        }
        for a in s.alarms {
            if a.cell == name {
                changes.extend(self.take(a, None));
            }
        }
        changes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cellwatch_models::alarm::{AlarmKind, Severity};

    fn alarm(id: &str, at: &str, state: AlarmState, transition: Transition) -> AlarmPayload {
        AlarmPayload {
            schema: crate::payload::ALARM_SCHEMA.into(),
            cell: "m1".into(),
            id: id.into(),
            kind: AlarmKind::Switching,
            severity: Severity::High,
            state,
            transition,
            at: at.into(),
            raised_at: at.into(),
            cleared_at: None,
            acked_by: None,
            ack_comment: None,
            latched: false,
            fault_type: "ESE".into(),
            fault_step: Some(6),
            culprits: Vec::new(),
            message: format!("{id} at {at}"),
            shelved: None,
            out_of_service: None,
            consequence: None,
            suppressed_by_design: None,
            guidance: None,
        }
    }

    fn snapshot(at: &str, alarms: Vec<AlarmPayload>) -> SnapshotPayload {
        SnapshotPayload {
            schema: crate::payload::SNAPSHOT_SCHEMA.into(),
            cell: "m1".into(),
            at: at.into(),
            connected: true,
            state: cellwatch_models::engine::StateName::Running,
            tags: Vec::new(),
            alarms,
            last_fault: None,
            charts: Vec::new(),
            timers: Vec::new(),
            oee: None,
        }
    }

    /// Takes `a` as sealed when it says it happened.
    fn event(p: &mut Plant, a: AlarmPayload) -> Vec<Change> {
        let sealed = a.at.clone();
        p.alarm_event(a, &sealed)
    }

    const T1: &str = "2026-11-26T08:00:01.000Z";
    const T2: &str = "2026-11-26T08:00:02.000Z";
    const T3: &str = "2026-11-26T08:00:03.000Z";

    fn plant() -> Plant {
        Plant::new(["m1", "m2"], &BTreeMap::new(), 100)
    }

    #[test]
    fn a_raised_alarm_is_shown_and_its_cell_gets_the_fault() {
        let mut p = plant();
        let changes = event(
            &mut p,
            alarm(
                "ese",
                T1,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        assert_eq!(changes.len(), 2);
        assert_eq!(p.alarm_count(), 1);
        assert_eq!(
            p.cell("m1")
                .and_then(|c| c.last_fault.clone())
                .map(|f| f.alarm),
            Some("ese".into())
        );
    }

    #[test]
    fn an_older_event_never_overrides_a_newer_one() {
        let mut p = plant();
        event(
            &mut p,
            alarm("ese", T2, AlarmState::Normal, Transition::Acknowledged),
        );
        assert_eq!(p.alarm_count(), 0);
        event(
            &mut p,
            alarm(
                "ese",
                T3,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        event(
            &mut p,
            alarm("ese", T1, AlarmState::Normal, Transition::Cleared),
        );
        assert_eq!(
            p.alarm("m1", "ese").map(|a| a.state),
            Some(AlarmState::ActiveUnacknowledged)
        );
    }

    #[test]
    fn a_snapshot_ends_what_it_does_not_list_and_old_events_stay_out() {
        let mut p = plant();
        event(
            &mut p,
            alarm(
                "a",
                T1,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        event(
            &mut p,
            alarm(
                "b",
                T1,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        let changes = p.snapshot(snapshot(
            T2,
            vec![alarm(
                "b",
                T1,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            )],
        ));
        assert!(p.alarm("m1", "a").is_none());
        assert!(p.alarm("m1", "b").is_some());
        assert!(changes.iter().any(|c| matches!(c, Change::Alarm { alarm } if alarm.id == "a" && alarm.state == AlarmState::Normal)));
        // A cached event from before the snapshot does not bring it back.
        event(
            &mut p,
            alarm(
                "a",
                T1,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        assert!(p.alarm("m1", "a").is_none());
        // A new one does.
        event(
            &mut p,
            alarm(
                "a",
                T3,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        assert!(p.alarm("m1", "a").is_some());
    }

    #[test]
    fn a_clear_keeps_the_diagnosis_of_its_occurrence() {
        let mut p = plant();
        let mut raised = alarm(
            "ese",
            T1,
            AlarmState::ActiveUnacknowledged,
            Transition::Raised,
        );
        raised.culprits = vec![crate::payload::CulpritPayload {
            address: "X0.06".into(),
            value: false,
            expected: true,
            comment: Some("Y limit".into()),
            trigger: true,
            compared: None,
        }];
        event(&mut p, raised.clone());
        let mut cleared = alarm(
            "ese",
            T2,
            AlarmState::ClearedUnacknowledged,
            Transition::Cleared,
        );
        cleared.raised_at = T1.into();
        cleared.message = "ESE cleared".into();
        event(&mut p, cleared);
        let kept = p.alarm("m1", "ese").unwrap();
        assert_eq!(kept.state, AlarmState::ClearedUnacknowledged);
        assert_eq!(
            (kept.message.as_str(), kept.culprits.len()),
            (raised.message.as_str(), 1)
        );
        // A new occurrence brings its own.
        let mut again = alarm(
            "ese",
            T3,
            AlarmState::ActiveUnacknowledged,
            Transition::Raised,
        );
        again.message = "ESE again".into();
        event(&mut p, again);
        assert_eq!(p.alarm("m1", "ese").unwrap().message, "ESE again");
    }

    #[test]
    fn at_most_max_alarms_are_kept_and_the_rest_counted() {
        let mut p = Plant::new(["m1"], &BTreeMap::new(), 3);
        for i in 0..5 {
            event(
                &mut p,
                alarm(
                    &format!("a{i}"),
                    T1,
                    AlarmState::ActiveUnacknowledged,
                    Transition::Raised,
                ),
            );
        }
        assert_eq!(p.alarm_count(), 3);
        assert_eq!(p.view().dropped, 2);
        // One that is known still changes.
        event(
            &mut p,
            alarm(
                "a0",
                T2,
                AlarmState::ActiveAcknowledged,
                Transition::Acknowledged,
            ),
        );
        assert_eq!(
            p.alarm("m1", "a0").map(|a| a.state),
            Some(AlarmState::ActiveAcknowledged)
        );
    }

    #[test]
    fn cells_take_their_area_and_agents_come_and_go() {
        let areas = BTreeMap::from([("press".to_string(), vec!["m2".to_string()])]);
        let mut p = Plant::new(["m1", "m2"], &areas, 10);
        assert_eq!(
            p.cell("m2").and_then(|c| c.area.clone()),
            Some("press".into())
        );
        assert!(p.agent("m1", true).is_some());
        assert!(p.agent("m1", true).is_none(), "no change, nothing said");
        assert!(p.cell("m1").is_some_and(|c| c.agent));
        // A token of a cell outside the trust file adds nothing.
        assert!(p.agent("stranger", true).is_none());
        assert!(p.cell("stranger").is_none());
    }

    #[test]
    fn a_replayed_raise_of_an_alarm_that_ended_does_not_bring_it_back() {
        let mut p = plant();
        let raised = alarm(
            "ese",
            T1,
            AlarmState::ActiveUnacknowledged,
            Transition::Raised,
        );
        event(&mut p, raised.clone());
        event(
            &mut p,
            alarm("ese", T2, AlarmState::Normal, Transition::Acknowledged),
        );
        assert_eq!(p.alarm_count(), 0);
        // The genuine, signed raise, replayed after the alarm ended.
        assert!(event(&mut p, raised).is_empty());
        assert_eq!(p.alarm_count(), 0);
        // A new raise after it is shown.
        event(
            &mut p,
            alarm(
                "ese",
                T3,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            ),
        );
        assert_eq!(p.alarm_count(), 1);
    }

    #[test]
    fn a_fault_that_reached_its_agent_after_a_snapshot_is_taken_either_way() {
        let raised = || {
            alarm(
                "ese",
                T1,
                AlarmState::ActiveUnacknowledged,
                Transition::Raised,
            )
        };
        // The fault happened at T1; the agent took its snapshot at T2,
        // before the change reached it, and sealed the raise at T3.
        let mut p = plant();
        p.snapshot(snapshot(T2, vec![]));
        assert_eq!(p.alarm_event(raised(), T3).len(), 2);
        assert!(p.alarm("m1", "ese").is_some());
        // The same, the raise arriving before the snapshot's answer.
        let mut p = plant();
        p.alarm_event(raised(), T3);
        p.snapshot(snapshot(T2, vec![]));
        assert!(
            p.alarm("m1", "ese").is_some(),
            "kept: sealed after the snapshot"
        );
        // A raise sealed before the snapshot that does not list it has
        // ended since: not shown, whichever comes first.
        let mut p = plant();
        p.snapshot(snapshot(T2, vec![]));
        assert!(p.alarm_event(raised(), T1).is_empty());
        let mut p = plant();
        p.alarm_event(raised(), T1);
        p.snapshot(snapshot(T2, vec![]));
        assert!(p.alarm("m1", "ese").is_none());
    }
}
