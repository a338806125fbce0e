//! The per-cell engine: tag state, checks, alarms and machine state.
//!
//! [`CellEngine`] is fed tag values (with their quality), connection changes,
//! the passing of time and operator commands, and answers with
//! [`EngineEvent`]s: alarm transitions and machine-state changes. Checks
//! plug in through [`CheckSet`]: the switching-function checks
//! ([`SwitchingChecks`], compiled and incremental) are the first; transition
//! timers and SFC step supervision implement the same trait.
//!
//! Rules that keep alarms honest:
//! - a tag whose value is unknown (bad or uncertain quality, or the
//!   connection is down) suspends every check that reads it: no alarm is
//!   raised or cleared on a value nobody knows;
//! - a lost connection is one `communication` alarm, not one per tag;
//! - a value delivered twice (the same value with the same or an older
//!   source timestamp, as after a subscription is recreated) is ignored.
//!
//! Time is a count of milliseconds since the Unix epoch, passed in.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use crate::alarm::{Alarm, AlarmKind, CommandRefused, Severity, Transition};
use crate::comments::CommentDb;
use crate::compiled::CompiledCell;
use crate::explain::{explain, Culprit, Polarity};
use crate::expr::Expr;
use crate::signal::Signal;
use crate::switching::SwitchingFunction;

/// What a check found: its condition started or ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Finding {
    /// The alarm id (the check's id).
    pub id: String,
    /// The kind of check.
    pub kind: AlarmKind,
    /// How urgent.
    pub severity: Severity,
    /// The fault type for machine-state history.
    pub fault_type: String,
    /// Whether the alarm stays active until reset.
    pub latched: bool,
    /// The condition holds.
    pub active: bool,
    /// The step at which the fault formed.
    pub fault_step: Option<usize>,
    /// The contacts responsible.
    pub culprits: Vec<Culprit>,
    /// One line for people.
    pub message: String,
}

/// A family of checks sharing one view of the signals.
///
/// The engine tells it about every change of a signal it reads, with the
/// value before; `None` means the value is unknown and every check reading it
/// must hold its verdict.
pub trait CheckSet: Send + Sync {
    /// The signals it reads.
    fn inputs(&self) -> Vec<Signal>;

    /// A signal changed value or became unknown (`value` None); `before` is
    /// its last known value.
    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        before: Option<bool>,
        now: u64,
        out: &mut Vec<Finding>,
    );

    /// Time passed; timers fire here.
    fn advance(&mut self, _now: u64, _out: &mut Vec<Finding>) {}

    /// An operator reset a latched alarm of this set.
    fn reset(&mut self, _id: &str) {}

    /// Moves the measurements made since the last call into `out`.
    fn take_observations(&mut self, _out: &mut Vec<Observation>) {}
}

/// A measurement a check made: a transition's observed duration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Observation {
    /// Which check or transition (`line-007`).
    pub check: String,
    /// The duration, ms.
    pub ms: u64,
}

/// One switching-function check: a fault coil and its fault value.
#[derive(Debug, Clone)]
pub struct SwitchingCheck {
    /// Alarm id.
    pub id: String,
    /// The coil's switching function.
    pub sf: SwitchingFunction,
    /// Which coil value is the fault.
    pub polarity: Polarity,
    /// How urgent.
    pub severity: Severity,
    /// Fault type for history (`ESE`).
    pub fault_type: String,
    /// Comments for the culprits.
    pub comments: CommentDb,
    /// The check is armed only while this holds (CSD: cycle start pressed);
    /// `None`: always armed.
    pub armed_when: Option<SwitchingFunction>,
}

/// Switching-function checks compiled over one bitset.
///
/// Entry `c` of the compiled cell is check `c`'s switching function; entry
/// `n + k` is the arming condition of the `k`-th check that has one.
pub struct SwitchingChecks {
    checks: Vec<SwitchingCheck>,
    cell: CompiledCell,
    /// Per check: the compiled entry of its arming condition.
    arm_entry: Vec<Option<usize>>,
    known: Vec<bool>,
    /// Per signal: the checks that read it (function or arming condition).
    readers: Vec<Vec<usize>>,
    /// Per check: how many of its inputs are unknown.
    unknown_inputs: Vec<u32>,
    /// Per check: the verdict last reported.
    reported: Vec<bool>,
    changed: Vec<usize>,
}

impl SwitchingChecks {
    /// Compiles the checks. Every signal starts unknown, so every check
    /// starts suspended.
    pub fn new(checks: Vec<SwitchingCheck>) -> Self {
        let mut sfs: Vec<SwitchingFunction> = checks.iter().map(|c| c.sf.clone()).collect();
        let mut arm_entry = Vec::with_capacity(checks.len());
        for c in &checks {
            arm_entry.push(c.armed_when.as_ref().map(|a| {
                sfs.push(a.clone());
                sfs.len() - 1
            }));
        }
        let owner: Vec<usize> = (0..checks.len())
            .chain(
                arm_entry
                    .iter()
                    .enumerate()
                    .filter_map(|(c, e)| e.map(|_| c)),
            )
            .collect();
        let cell = CompiledCell::new(&sfs);
        let n = cell.signals().len();
        let mut readers = vec![Vec::new(); n];
        let mut unknown_inputs = vec![0u32; checks.len()];
        for (s, r) in readers.iter_mut().enumerate() {
            let mut owners: Vec<usize> = cell
                .readers(s as u32)
                .iter()
                .map(|&e| owner[e as usize])
                .collect();
            owners.sort_unstable();
            owners.dedup();
            for &c in &owners {
                unknown_inputs[c] += 1;
            }
            *r = owners;
        }
        SwitchingChecks {
            reported: vec![false; checks.len()],
            checks,
            cell,
            arm_entry,
            known: vec![false; n],
            readers,
            unknown_inputs,
            changed: Vec::new(),
        }
    }

    /// How many checks.
    pub fn len(&self) -> usize {
        self.checks.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.checks.is_empty()
    }
}

impl CheckSet for SwitchingChecks {
    fn inputs(&self) -> Vec<Signal> {
        self.cell.signals().to_vec()
    }

    fn on_change(
        &mut self,
        signal: &Signal,
        value: Option<bool>,
        before: Option<bool>,
        _now: u64,
        out: &mut Vec<Finding>,
    ) {
        let Some(s) = self.cell.signal_index(signal) else {
            return;
        };
        let si = s as usize;
        let Some(v) = value else {
            if self.known[si] {
                self.known[si] = false;
                for &c in &self.readers[si] {
                    self.unknown_inputs[c] += 1;
                }
            }
            return;
        };
        if !self.known[si] {
            self.known[si] = true;
            for &c in &self.readers[si] {
                self.unknown_inputs[c] -= 1;
            }
        }
        let mut changed = std::mem::take(&mut self.changed);
        changed.clear();
        self.cell.set(s, v, &mut changed);
        self.changed = changed;
        for k in 0..self.readers[si].len() {
            let c = self.readers[si][k];
            if self.unknown_inputs[c] > 0 {
                continue;
            }
            let check = &self.checks[c];
            let armed = self.arm_entry[c].is_none_or(|e| self.cell.output(e));
            let fault = armed && self.cell.output(c) == check.polarity.fault_value();
            if fault == self.reported[c] {
                continue;
            }
            self.reported[c] = fault;
            out.push(finding(check, fault, &self.cell, signal, before));
        }
    }
}

/// The finding of `check` going to `fault`, explained from the values in
/// `cell` (and `before` for the signal that just changed).
fn finding(
    check: &SwitchingCheck,
    fault: bool,
    cell: &CompiledCell,
    changed: &Signal,
    before: Option<bool>,
) -> Finding {
    let mut finding = Finding {
        id: check.id.clone(),
        kind: AlarmKind::Switching,
        severity: check.severity,
        fault_type: check.fault_type.clone(),
        latched: false,
        active: fault,
        fault_step: None,
        culprits: Vec::new(),
        message: format!("{} cleared", check.fault_type),
    };
    if !fault {
        return finding;
    }
    let now_values = |x: &Signal| cell.signal_index(x).map(|i| cell.value(i));
    let before_values = |x: &Signal| if x == changed { before } else { now_values(x) };
    if let Ok(e) = explain(
        &check.sf,
        now_values,
        Some(&before_values),
        check.polarity,
        &check.comments,
    ) {
        finding.fault_step = e.fault_step;
        finding.culprits = e.culprits;
    }
    finding.message = match (finding.fault_step, finding.culprits.first()) {
        (Some(step), Some(c)) => format!("{} at step {step}: {c}", check.fault_type),
        (None, Some(c)) => format!("{}: {c}", check.fault_type),
        _ => check.fault_type.clone(),
    };
    finding
}

/// A PLC tag as the engine knows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tag {
    /// The name used in the plant (`y_overtravel`).
    pub name: String,
    /// The PLC address the models use (`X0.06`).
    pub address: Signal,
}

/// A tag's value as delivered by the source.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reading {
    /// A good value.
    Good(bool),
    /// Bad or uncertain quality: the value is not to be trusted.
    Bad,
}

/// The state of the machine, as paper 000's remote service reports it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "state", rename_all = "lowercase")]
pub enum MachineState {
    /// Producing: the running rule holds.
    Running,
    /// Connected, no fault, not running.
    Idle,
    /// A fault alarm is active.
    Fault {
        /// Its fault type (`ESE`).
        fault_type: String,
        /// The faulty element, if known (`X0.06`).
        element: Option<String>,
    },
    /// No connection to the PLC.
    Offline,
}

impl MachineState {
    /// The state's name: `running`, `idle`, `fault`, `offline`.
    pub fn name(&self) -> &'static str {
        match self {
            MachineState::Running => "running",
            MachineState::Idle => "idle",
            MachineState::Fault { .. } => "fault",
            MachineState::Offline => "offline",
        }
    }

    /// All state names.
    pub const NAMES: [&'static str; 4] = ["running", "idle", "fault", "offline"];
}

/// The kind of a machine-state history row (paper 000, Fig. 13).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum HistoryKind {
    /// Running or idle, coming from running or idle.
    Normal,
    /// A fault, with its type and element.
    Fault,
    /// Back to running or idle after a fault or an outage.
    Recovery,
    /// The connection to the PLC is lost.
    Offline,
}

impl HistoryKind {
    /// The lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            HistoryKind::Normal => "normal",
            HistoryKind::Fault => "fault",
            HistoryKind::Recovery => "recovery",
            HistoryKind::Offline => "offline",
        }
    }
}

/// What the engine tells the sinks.
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

/// How the machine state is derived.
#[derive(Debug, Clone)]
pub struct StateRules {
    /// The machine is running when this holds (over tag addresses); idle
    /// otherwise. `None`: never running, only idle or fault.
    pub running: Option<Expr>,
    /// Alarms at or above this severity put the machine in `fault`.
    pub fault_severity: Severity,
}

impl Default for StateRules {
    fn default() -> Self {
        StateRules {
            running: None,
            fault_severity: Severity::High,
        }
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
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FaultValues {
    /// The alarm raised.
    pub alarm: String,
    /// When.
    pub at: u64,
    /// Every tag's value then (`None`: unknown).
    pub values: Vec<Option<bool>>,
}

/// One cell's engine.
pub struct CellEngine {
    cell: String,
    tags: Vec<Tag>,
    by_address: HashMap<Signal, usize>,
    values: Vec<Option<bool>>,
    timestamps: Vec<Option<u64>>,
    bad: BTreeSet<usize>,
    sets: Vec<Box<dyn CheckSet>>,
    /// Per tag: the check sets that read it.
    readers: Vec<Vec<usize>>,
    alarms: BTreeMap<String, Alarm>,
    /// Per alarm: whether its condition holds now (a latched alarm can be
    /// active with its condition gone).
    conditions: HashMap<String, bool>,
    /// `None` until the source first says.
    connected: Option<bool>,
    rules: StateRules,
    state: MachineState,
    last_fault: Option<FaultValues>,
    duplicates: u64,
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
        let by_address: HashMap<Signal, usize> = tags
            .iter()
            .enumerate()
            .map(|(i, t)| (t.address.clone(), i))
            .collect();
        let mut readers = vec![Vec::new(); tags.len()];
        for (k, set) in sets.iter().enumerate() {
            for s in set.inputs() {
                let Some(&t) = by_address.get(&s) else {
                    return Err(EngineError::MissingTag {
                        reader: format!("check set {}", k + 1),
                        address: s,
                    });
                };
                readers[t].push(k);
            }
        }
        if let Some(expr) = &rules.running {
            for s in expr.signals() {
                if !by_address.contains_key(&s) {
                    return Err(EngineError::MissingTag {
                        reader: "the running rule".into(),
                        address: s,
                    });
                }
            }
        }
        let n = tags.len();
        Ok(CellEngine {
            cell: cell.to_string(),
            tags,
            by_address,
            values: vec![None; n],
            timestamps: vec![None; n],
            bad: BTreeSet::new(),
            sets,
            readers,
            alarms: BTreeMap::new(),
            conditions: HashMap::new(),
            connected: None,
            rules,
            state: MachineState::Offline,
            last_fault: None,
            duplicates: 0,
        })
    }

    /// The cell's id.
    pub fn cell(&self) -> &str {
        &self.cell
    }

    /// The tags, in configuration order.
    pub fn tags(&self) -> &[Tag] {
        &self.tags
    }

    /// The tag with this address.
    pub fn tag_index(&self, address: &Signal) -> Option<usize> {
        self.by_address.get(address).copied()
    }

    /// Current values, `None` where unknown.
    pub fn values(&self) -> &[Option<bool>] {
        &self.values
    }

    /// Tags whose quality is bad.
    pub fn bad_tags(&self) -> impl Iterator<Item = usize> + '_ {
        self.bad.iter().copied()
    }

    /// Every alarm the engine knows, by id.
    pub fn alarms(&self) -> impl Iterator<Item = &Alarm> {
        self.alarms.values()
    }

    /// The machine state.
    pub fn state(&self) -> &MachineState {
        &self.state
    }

    /// Whether the PLC connection is up.
    pub fn connected(&self) -> bool {
        self.connected == Some(true)
    }

    /// The values at the last switching or timer fault.
    pub fn last_fault(&self) -> Option<&FaultValues> {
        self.last_fault.as_ref()
    }

    /// How many duplicate deliveries were ignored.
    pub fn duplicates(&self) -> u64 {
        self.duplicates
    }

    /// The connection to the PLC came up or went down.
    pub fn on_connection(&mut self, up: bool, now: u64) -> Vec<EngineEvent> {
        let mut events = Vec::new();
        if Some(up) == self.connected {
            return events;
        }
        self.connected = Some(up);
        let finding = Finding {
            id: "communication".into(),
            kind: AlarmKind::Communication,
            severity: Severity::High,
            fault_type: "COMM".into(),
            latched: false,
            active: !up,
            fault_step: None,
            culprits: Vec::new(),
            message: if up {
                "communication restored".into()
            } else {
                "communication lost: every tag is unknown".into()
            },
        };
        if !up {
            // Every value is now unknown; checks hold their verdicts.
            for t in 0..self.tags.len() {
                self.set_value(t, None, now, &mut Vec::new());
            }
            self.timestamps.iter_mut().for_each(|t| *t = None);
        }
        self.apply(finding, now, &mut events);
        self.update_state(now, &mut events);
        events
    }

    /// A value (or bad quality) for tag `tag`, with its source timestamp.
    pub fn on_reading(
        &mut self,
        tag: usize,
        reading: Reading,
        source_time: u64,
        now: u64,
    ) -> Vec<EngineEvent> {
        let mut events = Vec::new();
        let value = match reading {
            Reading::Good(v) => Some(v),
            Reading::Bad => None,
        };
        if let (Some(last), Some(v)) = (self.timestamps[tag], value) {
            if source_time <= last && self.values[tag] == Some(v) {
                self.duplicates += 1;
                return events;
            }
        }
        self.timestamps[tag] = Some(source_time);
        let quality_changed = match reading {
            Reading::Good(_) => self.bad.remove(&tag),
            Reading::Bad => self.bad.insert(tag),
        };
        let mut findings = Vec::new();
        // Checks time events by when the PLC saw them, not when they
        // arrived: delivery jitter is not motion time.
        self.set_value(tag, value, source_time, &mut findings);
        if quality_changed {
            findings.push(self.quality_finding());
        }
        for f in findings {
            self.apply(f, now, &mut events);
        }
        self.update_state(now, &mut events);
        events
    }

    /// The measurements the checks made since the last call.
    pub fn take_observations(&mut self) -> Vec<Observation> {
        let mut out = Vec::new();
        for set in &mut self.sets {
            set.take_observations(&mut out);
        }
        out
    }

    /// Time passed: timers fire.
    pub fn advance(&mut self, now: u64) -> Vec<EngineEvent> {
        let mut findings = Vec::new();
        for set in &mut self.sets {
            set.advance(now, &mut findings);
        }
        let mut events = Vec::new();
        for f in findings {
            self.apply(f, now, &mut events);
        }
        self.update_state(now, &mut events);
        events
    }

    /// An operator acknowledges an alarm.
    ///
    /// # Errors
    /// No such alarm, or nothing to acknowledge.
    pub fn acknowledge(
        &mut self,
        id: &str,
        operator: &str,
        now: u64,
    ) -> Result<Vec<EngineEvent>, CommandRefused> {
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        if alarm.acknowledged {
            return Err(CommandRefused::NothingToAcknowledge(id.into()));
        }
        alarm.acknowledged = true;
        alarm.acked_by = Some(operator.to_string());
        Ok(vec![EngineEvent::Alarm {
            alarm: alarm.clone(),
            transition: Transition::Acknowledged,
            at: now,
        }])
    }

    /// An operator resets a latched alarm whose condition is gone.
    ///
    /// # Errors
    /// No such alarm, not latched, not active, or its condition still holds.
    pub fn reset(
        &mut self,
        id: &str,
        operator: &str,
        now: u64,
    ) -> Result<Vec<EngineEvent>, CommandRefused> {
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        let refuse = |why: &str| CommandRefused::CannotReset {
            id: id.into(),
            why: why.into(),
        };
        if !alarm.latched {
            return Err(refuse("it is not latched; it clears by itself"));
        }
        if !alarm.active {
            return Err(refuse("it is not active"));
        }
        if self.conditions.get(id).copied().unwrap_or(false) {
            return Err(refuse("its condition still holds"));
        }
        alarm.active = false;
        alarm.cleared_at = Some(now);
        if alarm.acked_by.is_none() {
            alarm.acked_by = Some(operator.to_string());
        }
        alarm.acknowledged = true;
        let alarm = alarm.clone();
        for set in &mut self.sets {
            set.reset(id);
        }
        let mut events = vec![EngineEvent::Alarm {
            alarm,
            transition: Transition::Cleared,
            at: now,
        }];
        self.update_state(now, &mut events);
        Ok(events)
    }

    fn set_value(
        &mut self,
        tag: usize,
        value: Option<bool>,
        now: u64,
        findings: &mut Vec<Finding>,
    ) {
        let before = self.values[tag];
        if before == value {
            return;
        }
        self.values[tag] = value;
        let address = self.tags[tag].address.clone();
        for &k in &self.readers[tag] {
            self.sets[k].on_change(&address, value, before, now, findings);
        }
    }

    fn quality_finding(&self) -> Finding {
        let names: Vec<String> = self
            .bad
            .iter()
            .map(|&t| format!("{} ({})", self.tags[t].address, self.tags[t].name))
            .collect();
        Finding {
            id: "tag-quality".into(),
            kind: AlarmKind::TagQuality,
            severity: Severity::Medium,
            fault_type: "QUALITY".into(),
            latched: false,
            active: !self.bad.is_empty(),
            fault_step: None,
            culprits: Vec::new(),
            message: if names.is_empty() {
                "all tags good".into()
            } else {
                format!(
                    "bad or uncertain quality, checks reading them suspended: {}",
                    names.join(", ")
                )
            },
        }
    }

    fn apply(&mut self, f: Finding, now: u64, events: &mut Vec<EngineEvent>) {
        self.conditions.insert(f.id.clone(), f.active);
        let existing = self.alarms.get_mut(&f.id);
        let transition = match (existing, f.active) {
            (Some(a), true) if a.active => {
                a.culprits = f.culprits;
                a.fault_step = f.fault_step;
                a.message = f.message;
                Some(Transition::Updated)
            }
            (Some(a), false) if a.active && !a.latched => {
                a.active = false;
                a.cleared_at = Some(now);
                a.message = f.message;
                Some(Transition::Cleared)
            }
            (Some(_), false) | (None, false) => None,
            (_, true) => {
                let alarm = Alarm {
                    id: f.id.clone(),
                    kind: f.kind,
                    severity: f.severity,
                    fault_type: f.fault_type,
                    active: true,
                    acknowledged: false,
                    latched: f.latched,
                    raised_at: now,
                    cleared_at: None,
                    acked_by: None,
                    fault_step: f.fault_step,
                    culprits: f.culprits,
                    message: f.message,
                };
                if matches!(alarm.kind, AlarmKind::Switching | AlarmKind::Timer) {
                    self.last_fault = Some(FaultValues {
                        alarm: alarm.id.clone(),
                        at: now,
                        values: self.values.clone(),
                    });
                }
                self.alarms.insert(f.id.clone(), alarm);
                Some(Transition::Raised)
            }
        };
        if let Some(transition) = transition {
            let alarm = self.alarms[&f.id].clone();
            events.push(EngineEvent::Alarm {
                alarm,
                transition,
                at: now,
            });
        }
    }

    fn update_state(&mut self, now: u64, events: &mut Vec<EngineEvent>) {
        let fault = self
            .alarms
            .values()
            .filter(|a| a.active && matches!(a.kind, AlarmKind::Switching | AlarmKind::Timer))
            .filter(|a| a.severity >= self.rules.fault_severity)
            .max_by_key(|a| a.raised_at);
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
        let kind = match (&self.state, &next) {
            (_, MachineState::Offline) => HistoryKind::Offline,
            (_, MachineState::Fault { .. }) => HistoryKind::Fault,
            (MachineState::Fault { .. } | MachineState::Offline, _) => HistoryKind::Recovery,
            _ => HistoryKind::Normal,
        };
        self.state = next.clone();
        events.push(EngineEvent::State {
            state: next,
            kind,
            at: now,
        });
    }

    /// Whether the running rule holds; false while any tag it reads is
    /// unknown.
    fn running(&self) -> bool {
        let Some(expr) = &self.rules.running else {
            return false;
        };
        if !known_all(expr, &self.by_address, &self.values) {
            return false;
        }
        expr.eval(&|s: &Signal| {
            self.by_address
                .get(s)
                .and_then(|&t| self.values[t])
                .unwrap_or(false)
        })
    }
}

fn known_all(expr: &Expr, by_address: &HashMap<Signal, usize>, values: &[Option<bool>]) -> bool {
    expr.signals()
        .iter()
        .all(|s| by_address.get(s).is_some_and(|&t| values[t].is_some()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alarm::AlarmState;
    use crate::program::Program;
    use crate::signal::Observability;

    const ESE: &str = include_str!("../../config/cnc/ese.il");
    const NORMAL: &str = include_str!("../../config/cnc/ese-normal.values");

    fn engine() -> CellEngine {
        let p = Program::compile("ese.il", ESE, None).unwrap();
        let sf = SwitchingFunction::expand(
            &p,
            &Signal::new("G8.02"),
            &Observability::default_for(p.dialect()),
        )
        .unwrap();
        let tags: Vec<Tag> = sf
            .leaves()
            .into_iter()
            .map(|s| Tag {
                name: s.name().to_lowercase(),
                address: s,
            })
            .collect();
        let check = SwitchingCheck {
            id: "ese".into(),
            sf,
            polarity: Polarity::On,
            severity: Severity::Critical,
            fault_type: "ESE".into(),
            comments: CommentDb::default(),
            armed_when: None,
        };
        let rules = StateRules {
            running: Some(Expr::parse("G0.00 * F0.00").unwrap()),
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
            out.extend(e.on_reading(t, Reading::Good(v == "1"), at, at));
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
        let ev = e.on_connection(true, 1);
        assert_eq!(alarm_transitions(&ev), []);
        let ev = load_normal(&mut e, 2);
        assert!(alarm_transitions(&ev).is_empty());
        assert_eq!(e.state(), &MachineState::Running);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e.on_reading(x006, Reading::Good(false), 10, 10);
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
        assert!(e.on_reading(x006, Reading::Good(false), 10, 11).is_empty());
        assert_eq!(e.duplicates(), 1);
        let ev = e.on_reading(x006, Reading::Good(true), 20, 20);
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
        let ev = e.acknowledge("ese", "kim", 30).unwrap();
        assert_eq!(
            alarm_transitions(&ev),
            [("ese".to_string(), Transition::Acknowledged)]
        );
        assert_eq!(e.alarms().next().unwrap().state(), AlarmState::Normal);
        assert_eq!(
            e.acknowledge("ese", "kim", 31),
            Err(CommandRefused::NothingToAcknowledge("ese".into()))
        );
        assert!(e.reset("ese", "kim", 32).is_err());
    }

    #[test]
    fn lost_connection_is_one_alarm_and_no_process_alarm() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let ev = e.on_connection(false, 5);
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Raised)]
        );
        assert_eq!(e.state(), &MachineState::Offline);
        assert!(e.values().iter().all(Option::is_none));
        // Reconnected: values come back one by one; the check stays suspended
        // until every input is known, so a half-loaded image raises nothing.
        let ev = e.on_connection(true, 6);
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Cleared)]
        );
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        assert!(alarm_transitions(&e.on_reading(x006, Reading::Good(false), 7, 7)).is_empty());
        let ev = load_normal(&mut e, 8);
        // X0.06 is back to 1 in the normal image: no ESE was ever raised.
        assert!(alarm_transitions(&ev).is_empty(), "{ev:?}");
    }

    #[test]
    fn unreachable_from_the_start_is_one_alarm() {
        let mut e = engine();
        let ev = e.on_connection(false, 1);
        assert_eq!(
            alarm_transitions(&ev),
            [("communication".to_string(), Transition::Raised)]
        );
        assert!(e.on_connection(false, 2).is_empty());
    }

    #[test]
    fn bad_quality_suspends_and_is_reported() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let ev = e.on_reading(x006, Reading::Bad, 3, 3);
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
        // Another contact opens while X0.06 is unknown: the check is suspended.
        let x004 = e.tag_index(&Signal::new("X0.04")).unwrap();
        assert!(alarm_transitions(&e.on_reading(x004, Reading::Good(false), 4, 4)).is_empty());
        // X0.06 good again: the check resumes and sees X0.04 open.
        let ev = e.on_reading(x006, Reading::Good(true), 5, 5);
        let t = alarm_transitions(&ev);
        assert!(
            t.contains(&("ese".to_string(), Transition::Raised)),
            "{t:?}"
        );
        assert!(
            t.contains(&("tag-quality".to_string(), Transition::Cleared)),
            "{t:?}"
        );
    }
}

#[cfg(test)]
mod armed {
    use super::*;
    use crate::program::Program;
    use crate::signal::Observability;

    #[test]
    fn csd_faults_only_while_cycle_start_is_pressed() {
        let p = Program::compile("csd.il", include_str!("../../config/cnc/csd.il"), None).unwrap();
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
        for line in include_str!("../../config/cnc/csd-normal.values")
            .lines()
            .filter(|l| l.contains(',') && !l.starts_with("address") && !l.starts_with('#'))
        {
            let (a, v) = line.split_once(',').unwrap();
            let t = e.tag_index(&Signal::new(a)).unwrap();
            raised.extend(e.on_reading(t, Reading::Good(v == "1"), 1, 1));
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
            e.on_reading(i, Reading::Good(v), t, t)
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
