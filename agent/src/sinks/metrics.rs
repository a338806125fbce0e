//! The metrics as a sink: each step updates the counters and gauges it
//! touches, and nothing else.

use std::collections::HashMap;
use std::sync::Arc;

use cellwatch_models::alarm::{AlarmKind, Severity, Transition};
use cellwatch_models::kpi::{KpiRules, LiveKpis};
use futures_util::future::BoxFuture;
use futures_util::FutureExt;

use crate::metrics::Metrics;
use crate::sinks::Sink;
use crate::step::{CellStep, Input};

/// What the metrics sink reads of a cell's configuration.
#[derive(Debug, Clone, Default)]
pub struct MetricsSetup {
    /// How many tags the cell has (all unknown at start).
    pub tags: usize,
    /// The exported tags: index and name.
    pub exported: Vec<(usize, String)>,
    /// The ids of the cell's modes.
    pub modes: Vec<String>,
    /// Each learned transition's check (`line-007`) and window, ms.
    pub windows: Vec<(String, [u64; 2])>,
    /// Per tag that is a supervised step's flag: (check, chart, step) of
    /// each step it flags.
    pub steps: HashMap<usize, Vec<[String; 3]>>,
    /// The alarm-performance rules.
    pub kpi: KpiRules,
}

/// Metrics bookkeeping of one cell.
pub(crate) struct MetricsSink {
    metrics: Arc<Metrics>,
    /// Per alarm: kind, severity and whether it is counted as active.
    active: HashMap<String, (AlarmKind, Severity, bool)>,
    /// Per fault alarm: the element its culprit gauge is set for.
    culprits: HashMap<String, Option<String>>,
    /// The state whose time is being counted, and up to when it is.
    counted_state: &'static str,
    accounted_until: u64,
    /// When the last tag value arrived.
    last_update: Option<u64>,
    ever_connected: bool,
    /// The exported tags: each one's name and its `cellwatch_tag_value`
    /// gauge (absent while the value is unknown). Only those: a cell of
    /// 100,000 tags exporting ten keeps ten.
    exported: HashMap<usize, (String, Option<prometheus::Gauge>)>,
    /// Per tag that is a supervised step's flag: (check, chart, step) of
    /// each step it flags, for `cellwatch_sfc_step_active`.
    steps: HashMap<usize, Vec<[String; 3]>>,
    /// The ISA-18.2 figures.
    kpis: LiveKpis,
    /// Per alarm: whether it is counted shelved, out of service,
    /// suppressed (active), suppressed by design (active).
    kept: HashMap<String, (bool, bool, bool, bool)>,
    /// Flood time already added to its counter, ms.
    flood_counted: u64,
}

impl MetricsSink {
    /// A sink for a cell set up as `setup` says: sets the gauges known
    /// from the configuration (tags unknown at start, learned timer
    /// windows); time in each state is counted from `now`.
    pub(crate) fn new(metrics: Arc<Metrics>, setup: MetricsSetup, now: u64) -> MetricsSink {
        metrics.tags_unknown.set(setup.tags as i64);
        for mode in &setup.modes {
            metrics.modes.mode(mode, false);
        }
        for (check, window) in &setup.windows {
            for (bound, ms) in [("lo", window[0]), ("hi", window[1])] {
                metrics
                    .transition_window_seconds
                    .with_label_values(&[check.as_str(), bound])
                    .set(ms as f64 / 1000.0);
            }
        }
        let exported = setup
            .exported
            .into_iter()
            .map(|(i, name)| (i, (name, None)))
            .collect();
        MetricsSink {
            exported,
            steps: setup.steps,
            metrics,
            active: HashMap::new(),
            culprits: HashMap::new(),
            counted_state: "offline",
            accounted_until: now,
            last_update: None,
            ever_connected: false,
            kpis: LiveKpis::with_rules(setup.kpi),
            kept: HashMap::new(),
            flood_counted: 0,
        }
    }

    /// The ISA-18.2 figures after `step`.
    fn kpis(&mut self, step: &CellStep) {
        let m = &self.metrics;
        let mut any = false;
        for (alarm, transition, at) in step.engine.alarms() {
            any = true;
            let consequence = alarm.consequence.is_some();
            self.kpis.on_transition(
                &alarm.id,
                transition,
                (
                    alarm.raised_at,
                    alarm.active,
                    consequence,
                    alarm.is_suppressed_by_design(),
                ),
                at,
            );
            if transition == Transition::Raised && consequence {
                m.alarm_consequences.inc();
            }
            if transition == Transition::Acknowledged {
                m.alarm_ack_seconds
                    .observe(at.saturating_sub(alarm.raised_at) as f64 / 1000.0);
            }
            let now = (
                alarm.shelved.is_some(),
                alarm.out_of_service.is_some(),
                alarm.active && alarm.is_suppressed(),
                alarm.active && alarm.is_suppressed_by_design(),
            );
            let was = self.kept.insert(alarm.id.clone(), now).unwrap_or_default();
            m.alarms_shelved.add(i64::from(now.0) - i64::from(was.0));
            m.alarms_out_of_service
                .add(i64::from(now.1) - i64::from(was.1));
            m.alarms_suppressed.add(i64::from(now.2) - i64::from(was.2));
            m.modes
                .suppressed_by_design
                .add(i64::from(now.3) - i64::from(was.3));
        }
        for (mode, entered, _) in step.engine.modes() {
            m.modes.mode(mode, entered);
        }
        if !any && step.input != Input::Tick {
            return;
        }
        self.kpis.advance(step.at);
        let k = self.kpis.snapshot(step.at);
        m.alarm_rate_10m.set(k.raised_last_10m as i64);
        m.alarm_flood.set(i64::from(k.in_flood));
        m.alarm_rate_first_outs_10m
            .set(k.first_outs_last_10m as i64);
        m.alarm_flood_first_outs
            .set(i64::from(k.first_outs_in_flood));
        m.modes.rate_by_design_10m.set(k.by_design_last_10m as i64);
        m.alarm_flood_seconds
            .inc_by(k.flood_ms.saturating_sub(self.flood_counted) as f64 / 1000.0);
        self.flood_counted = self.flood_counted.max(k.flood_ms);
        m.alarms_chattering.set(k.chattering as i64);
        m.alarms_stale.set(k.stale as i64);
    }

    fn step(&mut self, step: &CellStep) {
        let m = &self.metrics;
        m.source_queue_depth.set(step.queue_depth as i64);
        for r in &step.engine.recordings {
            m.recordings.inc();
            if r.truncated.start.is_some() || r.truncated.end.is_some() {
                m.recordings_cut.inc();
            }
        }
        // The journal and the bus have had this step (they come first).
        if let Some(received) = step.received.filter(|_| !step.alarms.is_empty()) {
            let seconds = received.elapsed().as_secs_f64();
            for _ in &step.alarms {
                m.alarm_latency_seconds.observe(seconds);
            }
        }
        match &step.input {
            Input::Connection { up: true, .. } => {
                if self.ever_connected {
                    m.opcua_reconnects.inc();
                }
                self.ever_connected = true;
                m.opcua_connected.set(1);
            }
            Input::Connection { up: false, .. } => {
                // The first word from a source that never connected is no
                // loss.
                if self.ever_connected && m.opcua_connected.get() == 1 {
                    m.connection_losses.inc();
                }
                m.opcua_connected.set(0);
            }
            // A force or stop is journaled in several rows: counted once.
            Input::Command(c) if c.stage.is_final() => {
                m.command(c.action, c.accepted);
            }
            Input::Command(_) => {}
            Input::Tick => {
                m.add_state_time(
                    self.counted_state,
                    step.at.saturating_sub(self.accounted_until) as f64 / 1000.0,
                );
                self.accounted_until = self.accounted_until.max(step.at);
                if let Some(t) = self.last_update {
                    m.last_update_age
                        .set(step.at.saturating_sub(t) as f64 / 1000.0);
                }
            }
            Input::Readings
            | Input::StateBeat
            | Input::Restored
            | Input::Reloaded
            | Input::System => {}
        }
        let e = &step.engine;
        if e.readings > 0 {
            m.tag_updates.inc_by(e.readings);
            self.last_update = Some(step.at);
        }
        m.duplicate_updates.inc_by(e.duplicates);
        m.out_of_order.inc_by(e.out_of_order);
        m.source_gaps.inc_by(e.gaps);
        m.source_lost_values.inc_by(e.lost_values);
        m.tags_gone_bad.inc_by(e.went_bad);
        m.check_evaluations.inc_by(e.evaluations);
        if e.unknown_delta != 0 {
            m.tags_unknown.add(e.unknown_delta);
        }
        m.parts.inc_by(e.parts.iter().map(|&(_, n)| n).sum());
        for &(tag, value) in &e.exported {
            for [check, chart, step] in self.steps.get(&tag).into_iter().flatten() {
                let labels = [check.as_str(), chart.as_str(), step.as_str()];
                match value {
                    Some(v) => m
                        .sfc_step_active
                        .with_label_values(&labels)
                        .set(i64::from(v != 0.0)),
                    None => {
                        let _ = m.sfc_step_active.remove_label_values(&labels);
                    }
                }
            }
            let Some((name, gauge)) = self.exported.get_mut(&tag) else {
                continue;
            };
            match value {
                Some(v) => gauge
                    .get_or_insert_with(|| m.tag_value.with_label_values(&[name.as_str()]))
                    .set(v),
                // Unknown: no sample rather than a stale one.
                None => {
                    if gauge.take().is_some() {
                        let _ = m.tag_value.remove_label_values(&[name.as_str()]);
                    }
                }
            }
        }
        for o in &e.observations {
            m.transition_seconds
                .with_label_values(&[o.check.as_str()])
                .observe(o.ms as f64 / 1000.0);
        }
        for p in &step.positions {
            m.transition_window_position
                .with_label_values(&[p.check.as_str()])
                .set(p.position);
        }
        for (alarm, transition, _) in e.alarms() {
            if transition == Transition::Raised {
                m.raised(&alarm.id, alarm.kind, alarm.severity);
            }
            let counted = self
                .active
                .insert(alarm.id.clone(), (alarm.kind, alarm.severity, alarm.active));
            if let Some((kind, severity, true)) = counted {
                m.active_delta(kind, severity, -1);
            }
            if alarm.active {
                m.active_delta(alarm.kind, alarm.severity, 1);
            }
            if matches!(
                alarm.kind,
                AlarmKind::Switching | AlarmKind::Timer | AlarmKind::Step
            ) {
                let element = alarm
                    .active
                    .then(|| alarm.element().map(str::to_string))
                    .flatten();
                let previous = self
                    .culprits
                    .insert(alarm.id.clone(), element.clone())
                    .flatten();
                m.culprit(
                    &alarm.id,
                    alarm.severity.as_str(),
                    &alarm.fault_type,
                    element.as_deref(),
                    previous.as_deref(),
                    transition == Transition::Raised,
                );
            }
        }
        for (state, _, at) in e.states() {
            let previous = std::mem::replace(&mut self.counted_state, state.name());
            m.state(
                state.name(),
                previous,
                at.saturating_sub(self.accounted_until) as f64 / 1000.0,
            );
            self.accounted_until = self.accounted_until.max(at);
        }
        self.kpis(step);
    }
}

impl Sink for MetricsSink {
    fn name(&self) -> &'static str {
        "metrics"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        self.step(step);
        async {}.boxed()
    }
}
