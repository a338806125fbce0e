//! The cell's Sparkplug metrics: every metric the device declares in its
//! birth (the machine state, each alarm's state, priority and
//! acknowledgement, the parts produced, the current shift's OEE, the
//! exported tags), each with its alias and current value; the changes that
//! wait to be published, bounded; whether the device is alive (its PLC
//! link up) and where its death falls among the changes; and the payloads
//! built from them (births, data, deaths). No I/O and no clock: the
//! session (`session.rs`) sends what it is given and stamps it with the
//! time it passes in. The OEE metrics and their deadbands are in
//! `book/oee.rs`.

use std::collections::{HashMap, VecDeque};

use cellwatch_models::alarm::{Alarm, AlarmKind, Severity};
use cellwatch_models::engine::MachineState;

use super::store::HeldRow;
use super::tahu::{
    DataType, Metric, Payload, PropertySet, PropertyValue, PropertyValueKind, Value,
};
pub(crate) use super::value::MetricValue;
use crate::step::{CellStep, Input};

mod oee;

/// The node's birth/death sequence metric.
pub(crate) const BD_SEQ: &str = "bdSeq";

/// The node's rebirth control: a host writes `true` to it (NCMD) to have
/// the node and its device born again.
pub(crate) const REBIRTH: &str = "Node Control/Rebirth";

/// [`REBIRTH`]'s alias.
pub(crate) const REBIRTH_ALIAS: u64 = 1;

/// The first alias of the device's metrics (the node's are below).
const FIRST_DEVICE_ALIAS: u64 = 16;

/// Where the machine state's metrics are among the device's.
const STATE: usize = 0;
const FAULT_TYPE: usize = 1;
const FAULT_ELEMENT: usize = 2;

/// An alarm's metrics, in order after its first.
const ALARM_METRICS: [(&str, DataType); 4] = [
    ("Active", DataType::Boolean),
    ("Acknowledged", DataType::Boolean),
    ("Priority", DataType::String),
    ("Shelved", DataType::Boolean),
];

/// The most alarms the device declares: alarms first seen running (the
/// PLC's conditions) are added up to this many, each adding a rebirth.
const MAX_ALARMS: usize = 10_000;

/// One of the device's metrics.
#[derive(Debug)]
struct Entry {
    name: String,
    datatype: DataType,
    /// `None`: null (unknown).
    value: Option<MetricValue>,
    /// When it took its value, ms since the epoch (0: never).
    at: u64,
    /// Said in the birth only.
    properties: Option<PropertySet>,
}

/// Where the OEE metrics are among the device's (`book/oee.rs` declares
/// and sets them), and the shift their values are of.
#[derive(Debug, Clone, Copy)]
struct OeeMetrics {
    /// The first (`OEE/Shift`).
    first: usize,
    /// The start of the shift last set, ms since the epoch.
    shift_start: Option<u64>,
}

/// A change waiting to be published.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct MetricChange {
    /// Which metric (its index among the device's).
    entry: usize,
    /// The new value; `None`: null.
    value: Option<MetricValue>,
    /// When, ms since the epoch.
    at: u64,
}

/// An alarm the device declares from the start.
#[derive(Debug, Clone)]
pub(crate) struct Declared {
    /// Its id.
    pub id: String,
    /// What raises it.
    pub kind: AlarmKind,
    /// Its priority as configured.
    pub severity: Severity,
    /// Its fault type in the machine-state history.
    pub fault_type: String,
}

/// The alarms of an engine's catalogue, as the device declares them.
pub(crate) fn declared(catalogue: &[cellwatch_models::engine::CatalogueEntry]) -> Vec<Declared> {
    catalogue
        .iter()
        .map(|e| Declared {
            id: e.id.clone(),
            kind: e.kind,
            severity: e.severity,
            fault_type: e.fault_type.clone(),
        })
        .collect()
}

/// The device's metrics and what waits to be published.
#[derive(Debug)]
pub(crate) struct MetricBook {
    entries: Vec<Entry>,
    /// Per metric name: its index (for changes read back from the store).
    names: HashMap<String, usize>,
    /// Per alarm id: its first metric.
    alarms: HashMap<String, usize>,
    /// Per exported tag (its index in the configuration): its metric.
    tags: HashMap<usize, usize>,
    /// The parts produced metric, when the cell counts parts, and the
    /// count since the agent started.
    parts: Option<(usize, u64)>,
    /// The OEE metrics, with `[oee]`.
    oee: Option<OeeMetrics>,
    /// The PLC link is up as the steps last said (the device is alive).
    up: bool,
    /// The link went down since the device was last born: how many of the
    /// held changes came before (they go out before its DDEATH).
    death: Option<usize>,
    /// The changes not yet published, oldest first, at most `max_held`.
    held: VecDeque<MetricChange>,
    max_held: usize,
    /// Changes dropped past `max_held` not yet counted.
    dropped: u64,
    /// A metric was added since the last birth: the device must be born
    /// again before its data names it.
    grown: bool,
}

impl MetricBook {
    /// The metrics of a device with alarms `alarms`, exported tags `tags`
    /// (index in the configuration, name), parts counted or not, OEE
    /// judged or not; at most `max_held` changes wait. The device is alive
    /// until a step says its PLC link went down.
    pub(crate) fn new(
        alarms: &[Declared],
        tags: &[(usize, String)],
        counts_parts: bool,
        judges_oee: bool,
        max_held: usize,
    ) -> MetricBook {
        let mut book = MetricBook {
            entries: Vec::new(),
            names: HashMap::new(),
            alarms: HashMap::new(),
            tags: HashMap::new(),
            parts: None,
            oee: None,
            up: true,
            death: None,
            held: VecDeque::new(),
            max_held,
            dropped: 0,
            grown: false,
        };
        for name in [
            "Machine/State",
            "Machine/Fault Type",
            "Machine/Fault Element",
        ] {
            book.add(name.to_string(), DataType::String, None);
        }
        if counts_parts {
            let at = book.add(
                "Production/Parts Produced".into(),
                DataType::UInt64,
                Some(MetricValue::UInt64(0)),
            );
            book.parts = Some((at, 0));
        }
        if judges_oee {
            book.declare_oee();
        }
        for (tag, name) in tags {
            let at = book.add(format!("Tags/{name}"), DataType::Double, None);
            book.tags.insert(*tag, at);
        }
        for a in alarms {
            book.alarm(&a.id, a.kind, a.severity, &a.fault_type);
        }
        book.grown = false;
        book
    }

    fn add(&mut self, name: String, datatype: DataType, value: Option<MetricValue>) -> usize {
        self.names.insert(name.clone(), self.entries.len());
        self.entries.push(Entry {
            name,
            datatype,
            value,
            at: 0,
            properties: None,
        });
        self.entries.len() - 1
    }

    /// The first metric of alarm `id`, added (normal, acknowledged) if new
    /// and there is room.
    fn alarm(
        &mut self,
        id: &str,
        kind: AlarmKind,
        severity: Severity,
        fault_type: &str,
    ) -> Option<usize> {
        if let Some(&at) = self.alarms.get(id) {
            return Some(at);
        }
        if self.alarms.len() >= MAX_ALARMS {
            return None;
        }
        let first = self.entries.len();
        let initial = [
            MetricValue::Boolean(false),
            MetricValue::Boolean(true),
            MetricValue::Text(severity.as_str().into()),
            MetricValue::Boolean(false),
        ];
        for ((name, datatype), value) in ALARM_METRICS.into_iter().zip(initial) {
            self.add(format!("Alarms/{id}/{name}"), datatype, Some(value));
        }
        self.entries[first].properties = Some(properties(&[
            ("kind", kind.as_str()),
            ("faultType", fault_type),
        ]));
        self.alarms.insert(id.to_string(), first);
        self.grown = true;
        Some(first)
    }

    /// Sets metric `entry` to `value` at `at`; a change if it differs
    /// (whether it did).
    fn set(&mut self, entry: usize, value: Option<MetricValue>, at: u64) -> bool {
        let e = &mut self.entries[entry];
        if e.value == value {
            return false;
        }
        e.value = value.clone();
        e.at = at;
        if self.held.len() >= self.max_held {
            self.held.pop_front();
            self.dropped += 1;
            if let Some(before) = &mut self.death {
                *before = before.saturating_sub(1);
            }
        }
        self.held.push_back(MetricChange { entry, value, at });
        true
    }

    /// Takes what `step` changed; whether anything did (a change of the
    /// PLC link counts).
    pub(crate) fn apply(&mut self, step: &CellStep) -> bool {
        let before = (self.held.len(), self.dropped, self.up);
        for (state, _, at) in step.engine.states() {
            let (fault_type, element) = match state {
                MachineState::Fault {
                    fault_type,
                    element,
                } => (Some(fault_type.clone()), element.clone()),
                _ => (None, None),
            };
            self.set(STATE, Some(MetricValue::Text(state.name().into())), at);
            self.set(FAULT_TYPE, fault_type.map(MetricValue::Text), at);
            self.set(FAULT_ELEMENT, element.map(MetricValue::Text), at);
        }
        if let Some((entry, mut total)) = self.parts {
            for &(at, n) in &step.engine.parts {
                total += n;
                self.set(entry, Some(MetricValue::UInt64(total)), at);
            }
            self.parts = Some((entry, total));
        }
        for &(tag, value) in &step.engine.exported {
            if let Some(&entry) = self.tags.get(&tag) {
                self.set(entry, value.map(MetricValue::Double), step.at);
            }
        }
        for (alarm, _, at) in step.engine.alarms() {
            self.alarm_changed(alarm, at);
        }
        if let Input::Connection { up, .. } = step.input {
            if self.up && !up {
                self.death.get_or_insert(self.held.len());
            }
            self.up = up;
        }
        (self.held.len(), self.dropped, self.up) != before
    }

    /// Whether the device is alive: its PLC link up.
    pub(crate) fn device_up(&self) -> bool {
        self.up
    }

    /// Whether the device died since it was last born (its DDEATH is
    /// due).
    pub(crate) fn died(&self) -> bool {
        self.death.is_some()
    }

    /// The changes that came before the device's death, to be sent before
    /// its DDEATH; the death is taken as told.
    pub(crate) fn take_before_death(&mut self) -> Vec<MetricChange> {
        let n = self.death.take().unwrap_or(0).min(self.held.len());
        self.held.drain(..n).collect()
    }

    fn alarm_changed(&mut self, alarm: &Alarm, at: u64) {
        let Some(first) = self.alarm(&alarm.id, alarm.kind, alarm.severity, &alarm.fault_type)
        else {
            return;
        };
        let values = [
            MetricValue::Boolean(alarm.active),
            MetricValue::Boolean(alarm.acknowledged),
            MetricValue::Text(alarm.severity.as_str().into()),
            MetricValue::Boolean(alarm.shelved.is_some()),
        ];
        for (i, v) in values.into_iter().enumerate() {
            self.set(first + i, Some(v), at);
        }
    }

    /// Whether a metric was added since the last birth.
    pub(crate) fn grown(&self) -> bool {
        self.grown
    }

    /// How many changes wait.
    pub(crate) fn held(&self) -> usize {
        self.held.len()
    }

    /// The changes dropped past the bound since the last call.
    pub(crate) fn take_dropped(&mut self) -> u64 {
        std::mem::take(&mut self.dropped)
    }

    /// Takes at most `n` of the waiting changes, oldest first; none from
    /// after the device's death while it is not yet told.
    pub(crate) fn take_changes(&mut self, n: usize) -> Vec<MetricChange> {
        let mut n = n.min(self.held.len());
        if let Some(before) = &mut self.death {
            n = n.min(*before);
            *before -= n;
        }
        self.held.drain(..n).collect()
    }

    /// Takes every waiting change, oldest first (to be kept on disk: the
    /// node cannot publish, and its next birth tells the device anew).
    pub(crate) fn take_all(&mut self) -> Vec<MetricChange> {
        self.death = None;
        self.held.drain(..).collect()
    }

    /// Puts `changes`, taken but not published, back before the waiting
    /// ones.
    pub(crate) fn hold_again(&mut self, changes: Vec<MetricChange>) {
        if let Some(before) = &mut self.death {
            *before += changes.len();
        }
        for c in changes.into_iter().rev() {
            self.held.push_front(c);
        }
    }

    /// `changes` as the store keeps them: by metric name.
    pub(crate) fn to_rows(&self, changes: Vec<MetricChange>) -> Vec<HeldRow> {
        changes
            .into_iter()
            .map(|c| HeldRow {
                id: 0,
                metric: self.entries[c.entry].name.clone(),
                value: c.value,
                at: c.at,
            })
            .collect()
    }

    /// Rows read back from the store as changes of this run's metrics;
    /// with how many name a metric the device no longer declares (an
    /// exported tag taken out of the configuration, an alarm first seen
    /// in an earlier run).
    pub(crate) fn changes_of(&self, rows: Vec<HeldRow>) -> (Vec<MetricChange>, u64) {
        let mut unknown = 0;
        let changes = rows
            .into_iter()
            .filter_map(|r| match self.names.get(&r.metric) {
                Some(&entry) => Some(MetricChange {
                    entry,
                    value: r.value,
                    at: r.at,
                }),
                None => {
                    unknown += 1;
                    None
                }
            })
            .collect();
        (changes, unknown)
    }

    /// The node's birth: sequence 0, `bd_seq`, the rebirth control. It
    /// tells the device anew: a death not yet told is forgotten.
    pub(crate) fn node_birth(&mut self, bd_seq: u64, now: u64) -> Payload {
        self.death = None;
        Payload {
            timestamp: Some(now),
            seq: Some(0),
            metrics: vec![
                bd_seq_metric(bd_seq, now),
                Metric {
                    name: Some(REBIRTH.into()),
                    alias: Some(REBIRTH_ALIAS),
                    timestamp: Some(now),
                    datatype: Some(DataType::Boolean as u32),
                    value: Some(Value::BooleanValue(false)),
                    ..Metric::default()
                },
            ],
            ..Payload::default()
        }
    }

    /// The device's birth at sequence `seq`: every metric with its name,
    /// alias, type and current value. The changes waiting until now are
    /// older than it: they are handed back to be sent as history.
    pub(crate) fn device_birth(&mut self, seq: u64, now: u64) -> (Payload, Vec<MetricChange>) {
        self.grown = false;
        self.death = None;
        let metrics = self
            .entries
            .iter()
            .enumerate()
            .map(|(i, e)| Metric {
                name: Some(e.name.clone()),
                alias: Some(alias(i)),
                timestamp: Some(if e.at == 0 { now } else { e.at }),
                datatype: Some(e.datatype as u32),
                is_null: e.value.is_none().then_some(true),
                properties: e.properties.clone(),
                value: e.value.clone().map(MetricValue::into_value),
                ..Metric::default()
            })
            .collect();
        let held = self.held.drain(..).collect();
        (
            Payload {
                timestamp: Some(now),
                seq: Some(seq),
                metrics,
                ..Payload::default()
            },
            held,
        )
    }

    /// Data at sequence `seq`: `changes` by alias, flagged historical or
    /// not.
    pub(crate) fn data(
        &self,
        changes: Vec<MetricChange>,
        seq: u64,
        now: u64,
        historical: bool,
    ) -> Payload {
        let metrics = changes
            .into_iter()
            .map(|c| Metric {
                alias: Some(alias(c.entry)),
                timestamp: Some(c.at),
                datatype: Some(self.entries[c.entry].datatype as u32),
                is_historical: historical.then_some(true),
                is_null: c.value.is_none().then_some(true),
                value: c.value.map(MetricValue::into_value),
                ..Metric::default()
            })
            .collect();
        Payload {
            timestamp: Some(now),
            seq: Some(seq),
            metrics,
            ..Payload::default()
        }
    }
}

/// The alias of the device's metric `entry`.
fn alias(entry: usize) -> u64 {
    FIRST_DEVICE_ALIAS + entry as u64
}

fn bd_seq_metric(bd_seq: u64, now: u64) -> Metric {
    Metric {
        name: Some(BD_SEQ.into()),
        timestamp: Some(now),
        datatype: Some(DataType::Int64 as u32),
        value: Some(Value::LongValue(bd_seq)),
        ..Metric::default()
    }
}

/// The node's death (its MQTT will): `bd_seq`, no sequence number.
pub(crate) fn node_death(bd_seq: u64, now: u64) -> Payload {
    Payload {
        timestamp: Some(now),
        metrics: vec![bd_seq_metric(bd_seq, now)],
        ..Payload::default()
    }
}

/// The device's death at sequence `seq`: no metric, the host takes every
/// metric of the device as stale until its next birth.
pub(crate) fn device_death(seq: u64, now: u64) -> Payload {
    Payload {
        timestamp: Some(now),
        seq: Some(seq),
        ..Payload::default()
    }
}

/// Whether a node command asks for a rebirth: [`REBIRTH`] (by name or
/// alias) set to `true`.
pub(crate) fn asks_rebirth(command: &Payload) -> bool {
    command.metrics.iter().any(|m| {
        (m.name.as_deref() == Some(REBIRTH) || m.alias == Some(REBIRTH_ALIAS))
            && m.value == Some(Value::BooleanValue(true))
    })
}

/// A property set of string properties.
fn properties(pairs: &[(&str, &str)]) -> PropertySet {
    PropertySet {
        keys: pairs.iter().map(|(k, _)| (*k).to_string()).collect(),
        values: pairs
            .iter()
            .map(|(_, v)| PropertyValue {
                r#type: Some(DataType::String as u32),
                value: Some(PropertyValueKind::StringValue((*v).to_string())),
                ..PropertyValue::default()
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests;
