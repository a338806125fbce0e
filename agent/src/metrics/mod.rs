//! Prometheus metrics and the `/metrics` endpoint.
//!
//! [`MetricsSink`] is the cell loop's side: it updates the metrics from
//! each step, incrementally (no metric is recomputed by a scan).
//!
//! Names follow Prometheus conventions (`_total` counters, base units,
//! `cellwatch_` prefix). Labels are bounded: cell, check id, alarm kind,
//! severity, machine state, command action and result; never a value or a
//! timestamp. Federation across hundreds of cells is Prometheus's own job:
//! every series carries `cell`.

mod labels;
mod modes;
mod oee;
mod probes;
mod sparkplug;

use labels::opts;
pub use labels::{COMMAND_RESULTS, REFUSED};
pub use modes::ModeMetrics;
pub use oee::OeeMetrics;
pub use sparkplug::{SparkplugMetrics, SPARKPLUG_KINDS};

use std::future::Future;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

use crate::health::{Health, STALLED_AFTER};
use crate::operator::Action;
use axum::http::header::CONTENT_TYPE;
use axum::routing::get;
use axum::Router;
use cellwatch_models::alarm::{AlarmKind, Severity};
use cellwatch_models::engine::MachineState;
use prometheus::{
    Counter, Encoder, Gauge, GaugeVec, Histogram, HistogramOpts, HistogramVec, IntCounter,
    IntCounterVec, IntGauge, IntGaugeVec, Registry, TextEncoder,
};

/// A value read when metrics are scraped.
pub type Sampler = Arc<dyn Fn() -> i64 + Send + Sync>;

/// Signatures made and the CPU seconds they took, read when metrics are
/// scraped.
pub type SigningSampler = Arc<dyn Fn() -> (u64, f64) + Send + Sync>;

/// Every metric of one agent, bound to its cell.
#[derive(Clone)]
pub struct Metrics {
    registry: Registry,
    /// Sessions open on the alarm server, sampled at each scrape.
    pub alarm_server_sessions: IntGauge,
    /// Where `alarm_server_sessions` is read from, once the server runs.
    alarm_server_sampler: Arc<OnceLock<Sampler>>,
    /// 1 while the OPC UA session is up.
    pub opcua_connected: IntGauge,
    /// Connections lost and re-established.
    pub opcua_reconnects: IntCounter,
    /// Connections to the PLC lost (any source).
    pub connection_losses: IntCounter,
    /// Tags that went from good to bad or uncertain quality.
    pub tags_gone_bad: IntCounter,
    /// Tag values received.
    pub tag_updates: IntCounter,
    /// Deliveries ignored as duplicates.
    pub duplicate_updates: IntCounter,
    /// Values whose source timestamp was earlier than one already seen.
    pub out_of_order: IntCounter,
    /// Gaps in the source's delivery: changes lost for good.
    pub source_gaps: IntCounter,
    /// Values the source knows it lost (dropped from a full queue).
    pub source_lost_values: IntCounter,
    /// Tags whose value is unknown now.
    pub tags_unknown: IntGauge,
    /// Changes fed to checks.
    pub check_evaluations: IntCounter,
    /// Source events waiting for the cell loop.
    pub source_queue_depth: IntGauge,
    active: IntGaugeVec,
    raised: IntCounterVec,
    state: IntGaugeVec,
    state_seconds: prometheus::CounterVec,
    /// Journal batch commit time.
    pub journal_write_seconds: Histogram,
    /// Rows committed to the journal.
    pub journal_rows: IntCounter,
    /// Journal batches that failed.
    pub journal_errors: IntCounter,
    /// Journal rows waiting to be written (the journal cannot write).
    pub journal_pending: IntGauge,
    /// Journal rows dropped because the queue of unwritten rows was full.
    pub journal_dropped: IntCounter,
    /// Zenoh puts and replies that failed.
    pub zenoh_publish_errors: IntCounter,
    /// Ed25519 signatures the agent made, and their CPU time, sampled from
    /// `signing_sampler` at each scrape (under `signing_lock`).
    signatures: IntCounter,
    signing_seconds: Counter,
    signing_sampler: Arc<OnceLock<SigningSampler>>,
    signing_lock: Arc<Mutex<()>>,
    /// The process's CPU time (user + system), sampled at each scrape.
    process_cpu: Counter,
    /// Queries refused, by service and reason.
    refused: IntCounterVec,
    /// Requests the OPC UA source made of the PLC, by service and result.
    pub opcua_requests: IntCounterVec,
    commands: IntCounterVec,
    /// Seconds since the last tag update.
    pub last_update_age: Gauge,
    /// Parts produced (rising edges of the part-done tag).
    pub parts: IntCounter,
    culprit: IntGaugeVec,
    elements: IntCounterVec,
    /// Transition durations, by timer check (filled by transition-timer checks).
    pub transition_seconds: HistogramVec,
    /// Learned transition windows, by timer check and bound.
    pub transition_window_seconds: GaugeVec,
    /// Where each transition's recent durations stand in its window (0 at
    /// the learned Δt, ±1 at its limits), by timer check.
    pub transition_window_position: GaugeVec,
    /// Values of the tags configured with `export = true`, by tag name.
    pub tag_value: GaugeVec,
    /// 1 while a supervised chart's step is active, by check, chart, step.
    pub sfc_step_active: IntGaugeVec,
    /// ISA-18.2: alarms raised in the last 10 minutes.
    pub alarm_rate_10m: IntGauge,
    /// 1 while a flood is on (`[kpi]`; ISA-18.2: begun above 10, ended below 5).
    pub alarm_flood: IntGauge,
    /// Time spent in flood.
    pub alarm_flood_seconds: prometheus::Counter,
    /// Alarms chattering now (`[kpi]`; ISA-18.2: 3+ raises within 60 s).
    pub alarms_chattering: IntGauge,
    /// Active occurrences older than 24 h.
    pub alarms_stale: IntGauge,
    /// Alarms shelved now.
    pub alarms_shelved: IntGauge,
    /// Alarms out of service now.
    pub alarms_out_of_service: IntGauge,
    /// Active alarms suppressed as consequences now.
    pub alarms_suppressed: IntGauge,
    /// Machine modes and designed suppression.
    pub modes: ModeMetrics,
    /// The current shift's OEE (`[oee]`).
    pub oee: OeeMetrics,
    /// The Sparkplug B edge node's figures (`[sparkplug]`).
    pub sparkplug: SparkplugMetrics,
    /// Alarms raised as the consequence of another active alarm.
    pub alarm_consequences: IntCounter,
    /// First-outs (raises that are no consequence) in the last 10 minutes.
    pub alarm_rate_first_outs_10m: IntGauge,
    /// 1 while the first-outs alone make a flood.
    pub alarm_flood_first_outs: IntGauge,
    /// Flight recordings journaled and published.
    pub recordings: IntCounter,
    /// Those holding less than their window (ring, changes, busy).
    pub recordings_cut: IntCounter,
    /// Time from raise to acknowledgement.
    pub alarm_ack_seconds: Histogram,
    /// Sends to Alertmanager, by result (`ok`, `failed`).
    alertmanager_sends: IntCounterVec,
    /// Alarms sent to Alertmanager as active alerts now.
    pub alertmanager_alerts: IntGauge,
    /// Alert changes not yet accepted by every Alertmanager.
    pub alertmanager_unsent: IntGauge,
    /// Time the agent adds: values received from the PLC → their alarm
    /// journaled and published.
    pub alarm_latency_seconds: Histogram,
}

impl Metrics {
    /// Registers every metric for `cell`.
    ///
    /// # Panics
    /// Never with the fixed names here (registration only fails on
    /// duplicates or invalid names).
    pub fn new(cell: &str) -> Metrics {
        let registry = Registry::new();
        macro_rules! reg {
            ($m:expr) => {{
                let m = $m.expect("valid metric");
                registry
                    .register(Box::new(m.clone()))
                    .expect("unique metric");
                m
            }};
        }
        let info = reg!(IntGaugeVec::new(
            opts(
                "cellwatch_agent_info",
                "Always 1; labels say which agent version runs the cell.",
                cell
            ),
            &["version"]
        ));
        info.with_label_values(&[env!("CARGO_PKG_VERSION")]).set(1);
        let active = reg!(IntGaugeVec::new(
            opts(
                "cellwatch_alarms_active",
                "Alarms whose condition holds (or latched), by kind and severity.",
                cell
            ),
            &["kind", "severity"]
        ));
        for k in AlarmKind::ALL {
            for s in Severity::ALL {
                active.with_label_values(&[k.as_str(), s.as_str()]).set(0);
            }
        }
        let state = reg!(IntGaugeVec::new(
            opts(
                "cellwatch_machine_state",
                "1 for the machine's current state, 0 for the others.",
                cell
            ),
            &["state"]
        ));
        let state_seconds = reg!(prometheus::CounterVec::new(
            opts(
                "cellwatch_machine_state_seconds_total",
                "Seconds spent in each machine state.",
                cell
            ),
            &["state"]
        ));
        for s in MachineState::NAMES {
            state.with_label_values(&[s]).set(0);
            state_seconds.with_label_values(&[s]).inc_by(0.0);
        }
        let raised = reg!(IntCounterVec::new(
            opts(
                "cellwatch_alarms_raised_total",
                "Alarms raised, by check, kind and severity.",
                cell
            ),
            &["check", "kind", "severity"]
        ));
        let commands = reg!(IntCounterVec::new(
            opts(
                "cellwatch_commands_total",
                "Operator commands, by action and result (accepted, refused).",
                cell
            ),
            &["action", "result"]
        ));
        for action in Action::ALL.map(Action::as_str) {
            for result in ["accepted", "refused"] {
                commands.with_label_values(&[action, result]).inc_by(0);
            }
        }
        let refused = reg!(IntCounterVec::new(
            opts(
                "cellwatch_requests_refused_total",
                "Queries refused: busy (too many at once), too_large (payload over the limit), invalid (not a request); commands refused before a known operator's signature was verified: unsigned, unknown_operator, bad_signature, malformed (a control character, a nonce out of format).",
                cell
            ),
            &["service", "reason"]
        ));
        let opcua_requests = reg!(IntCounterVec::new(
            opts(
                "cellwatch_opcua_requests_total",
                "Requests the OPC UA source made of the PLC, by service (Read, Republish, CreateMonitoredItems, TransferSubscriptions, ...) and result (good, or the status code's name: BadTimeout, BadMessageNotAvailable, ...). The client library's own Publish and keep-alive requests are not counted.",
                cell
            ),
            &["service", "result"]
        ));
        let alertmanager_sends = reg!(IntCounterVec::new(
            opts(
                "cellwatch_alertmanager_sends_total",
                "Sends of the cell's alerts to an Alertmanager, by result (ok, failed: refused, unreachable or timed out; retried with backoff).",
                cell
            ),
            &["result"]
        ));
        for result in ["ok", "failed"] {
            alertmanager_sends.with_label_values(&[result]).inc_by(0);
        }
        // Every series exists from the start, at 0, so that rates and
        // dashboards see the first refusal.
        for (service, reason) in REFUSED {
            refused.with_label_values(&[service, reason]).inc_by(0);
        }
        Metrics {
            opcua_connected: reg!(IntGauge::with_opts(opts(
                "cellwatch_opcua_connected",
                "1 while the OPC UA session to the PLC is up.",
                cell
            ))),
            opcua_reconnects: reg!(IntCounter::with_opts(opts(
                "cellwatch_opcua_reconnects_total",
                "OPC UA connections re-established after a loss.",
                cell
            ))),
            connection_losses: reg!(IntCounter::with_opts(opts(
                "cellwatch_connection_losses_total",
                "Connections to the PLC lost (OPC UA session or @ unit), each one, also those within one occurrence of the communication alarm.",
                cell
            ))),
            tags_gone_bad: reg!(IntCounter::with_opts(opts(
                "cellwatch_tags_gone_bad_total",
                "Tags that went from good to bad or uncertain quality, each time, also those within one occurrence of the tag-quality alarm.",
                cell
            ))),
            tag_updates: reg!(IntCounter::with_opts(opts(
                "cellwatch_tag_updates_total",
                "Tag values received from the PLC.",
                cell
            ))),
            duplicate_updates: reg!(IntCounter::with_opts(opts(
                "cellwatch_tag_duplicate_updates_total",
                "Tag values delivered again (after a subscription was recreated) and ignored.",
                cell
            ))),
            out_of_order: reg!(IntCounter::with_opts(opts(
                "cellwatch_out_of_order_readings_total",
                "Tag values whose source timestamp was earlier than one already seen, taken at the latest time seen (no duration measured through them).",
                cell
            ))),
            source_gaps: reg!(IntCounter::with_opts(opts(
                "cellwatch_source_gaps_total",
                "Gaps in what the PLC's server delivered: notifications it could no longer resend after a network cut, publishes with values dropped from a full queue. An alarm judged across one says \"trigger uncertain\".",
                cell
            ))),
            source_lost_values: reg!(IntCounter::with_opts(opts(
                "cellwatch_source_lost_values_total",
                "Tag values the server dropped from a full queue before publishing them (OPC UA overflow bit); raise opcua.queue_size if this grows.",
                cell
            ))),
            tags_unknown: reg!(IntGauge::with_opts(opts(
                "cellwatch_tags_unknown",
                "Tags whose value is unknown (bad quality or no connection).",
                cell
            ))),
            check_evaluations: reg!(IntCounter::with_opts(opts(
                "cellwatch_check_evaluations_total",
                "Signal changes fed to checks.",
                cell
            ))),
            source_queue_depth: reg!(IntGauge::with_opts(opts(
                "cellwatch_source_queue_depth",
                "Source events (publishes) waiting for the cell loop; at capacity the source waits.",
                cell
            ))),
            active,
            raised,
            state,
            state_seconds,
            journal_write_seconds: reg!(Histogram::with_opts(
                HistogramOpts::new(
                    "cellwatch_journal_write_seconds",
                    "Time to commit one batch to the SQLite journal."
                )
                .const_label("cell", cell)
                .buckets(vec![
                    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0
                ])
            )),
            journal_rows: reg!(IntCounter::with_opts(opts(
                "cellwatch_journal_rows_committed_total",
                "Rows committed to the SQLite journal since start.",
                cell
            ))),
            journal_errors: reg!(IntCounter::with_opts(opts(
                "cellwatch_journal_write_errors_total",
                "Journal batches that failed to commit.",
                cell
            ))),
            journal_pending: reg!(IntGauge::with_opts(opts(
                "cellwatch_journal_pending_rows",
                "Journal rows waiting to be written while the journal cannot write.",
                cell
            ))),
            journal_dropped: reg!(IntCounter::with_opts(opts(
                "cellwatch_journal_rows_dropped_total",
                "Journal rows dropped because the queue of unwritten rows was full.",
                cell
            ))),
            refused,
            opcua_requests,
            zenoh_publish_errors: reg!(IntCounter::with_opts(opts(
                "cellwatch_zenoh_publish_errors_total",
                "Zenoh publications and replies that failed.",
                cell
            ))),
            signatures: reg!(IntCounter::with_opts(opts(
                "cellwatch_bus_signatures_total",
                "Ed25519 signatures made to seal what the agent puts and answers on the bus (one per step's puts, one per answer).",
                cell
            ))),
            signing_seconds: reg!(Counter::with_opts(opts(
                "cellwatch_bus_signing_seconds_total",
                "CPU seconds the agent's threads spent making those signatures.",
                cell
            ))),
            signing_sampler: Arc::new(OnceLock::new()),
            signing_lock: Arc::new(Mutex::new(())),
            process_cpu: reg!(Counter::with_opts(opts(
                "process_cpu_seconds_total",
                "CPU seconds (user and system) of the whole agent process.",
                cell
            ))),
            commands,
            last_update_age: reg!(Gauge::with_opts(opts(
                "cellwatch_tag_last_update_age_seconds",
                "Seconds since the last tag value arrived.",
                cell
            ))),
            parts: reg!(IntCounter::with_opts(opts(
                "cellwatch_parts_produced_total",
                "Parts produced: rising edges of the part-done tag, or the increments of the counter tags.",
                cell
            ))),
            culprit: reg!(IntGaugeVec::new(
                opts(
                    "cellwatch_alarm_culprit",
                    "1 while a fault alarm is active with this first culprit (element).",
                    cell
                ),
                &["check", "severity", "fault_type", "element"]
            )),
            elements: reg!(IntCounterVec::new(
                opts(
                    "cellwatch_fault_elements_total",
                    "Fault alarms raised, by check and first culprit (element).",
                    cell
                ),
                &["check", "fault_type", "element"]
            )),
            transition_seconds: reg!(HistogramVec::new(
                HistogramOpts::new(
                    "cellwatch_transition_duration_seconds",
                    "Observed transition durations of transition-timer checks."
                )
                .const_label("cell", cell)
                .buckets(vec![
                    0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0, 30.0
                ]),
                &["check"]
            )),
            transition_window_seconds: reg!(GaugeVec::new(
                opts(
                    "cellwatch_transition_window_seconds",
                    "Learned window of each transition-timer check (bound: lo, hi).",
                    cell
                ),
                &["check", "bound"]
            )),
            transition_window_position: reg!(GaugeVec::new(
                opts(
                    "cellwatch_transition_window_position",
                    "Where each transition's moving mean duration stands in its learned window: 0 at the learned typical time, +1 at the upper limit (late), -1 at the lower (early); a drift warning at +-drift_fraction (0.5).",
                    cell
                ),
                &["check"]
            )),
            tag_value: reg!(GaugeVec::new(
                opts(
                    "cellwatch_tag_value",
                    "Current value of each tag configured with export = true (booleans as 0/1); absent while unknown.",
                    cell
                ),
                &["tag"]
            )),
            sfc_step_active: reg!(IntGaugeVec::new(
                opts(
                    "cellwatch_sfc_step_active",
                    "1 while the step of a supervised chart is active (its flag tag is on), 0 while not; absent while unknown.",
                    cell
                ),
                &["check", "chart", "step"]
            )),
            alarm_rate_10m: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarm_rate_10m",
                "ISA-18.2 alarm rate: alarms raised in the last 10 minutes (target about 1; more than 10 is a flood).",
                cell
            ))),
            alarm_flood: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarm_flood",
                "1 while an alarm flood is on: begun with more than kpi.flood_raises (10) raises in the last 10 minutes, ended when fewer than kpi.flood_ends_below (5) are left (ISA-18.2).",
                cell
            ))),
            alarm_flood_seconds: reg!(prometheus::Counter::with_opts(opts(
                "cellwatch_alarm_flood_seconds_total",
                "Time spent in alarm flood (target: under 1 % of the time).",
                cell
            ))),
            alarms_chattering: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarms_chattering",
                "Alarms chattering now: raised kpi.chatter_raises (3) or more times within kpi.chatter_window (60 s) (target 0).",
                cell
            ))),
            alarms_stale: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarms_stale",
                "Alarms active for longer than kpi.stale_after (24 hours) (target: fewer than 5).",
                cell
            ))),
            alarms_shelved: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarms_shelved",
                "Alarms shelved by an operator now.",
                cell
            ))),
            alarms_out_of_service: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarms_out_of_service",
                "Alarms out of service now.",
                cell
            ))),
            alarms_suppressed: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarms_suppressed",
                "Active alarms suppressed now: raised as the consequence of another active alarm in a cell that suppresses consequences (journaled and shown, not annunciated).",
                cell
            ))),
            alarm_consequences: reg!(IntCounter::with_opts(opts(
                "cellwatch_alarm_consequences_total",
                "Alarms raised as the consequence of another active alarm (derived from the PLC's logic and the cell's checks), suppressed or not.",
                cell
            ))),
            alarm_rate_first_outs_10m: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarm_rate_first_outs_10m",
                "First-outs raised in the last 10 minutes: the ISA-18.2 alarm rate with the consequences of other alarms left out.",
                cell
            ))),
            recordings: reg!(IntCounter::with_opts(opts(
                "cellwatch_recordings_total",
                "Flight recordings journaled and published: for each alarm raised, the signals its check reads from recorder.before before the raise to recorder.after after it.",
                cell
            ))),
            recordings_cut: reg!(IntCounter::with_opts(opts(
                "cellwatch_recordings_cut_total",
                "Flight recordings that hold less than their window: the ring had dropped older changes (recorder.capacity), a side had more than recorder.max_changes, or recorder.max_open recordings were under way.",
                cell
            ))),
            alarm_flood_first_outs: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarm_flood_first_outs",
                "1 while the first-outs alone make a flood (the rules of cellwatch_alarm_flood, consequences left out).",
                cell
            ))),
            alarm_ack_seconds: reg!(Histogram::with_opts(
                HistogramOpts::new(
                    "cellwatch_alarm_ack_seconds",
                    "Time from an alarm's raise to its acknowledgement."
                )
                .const_label("cell", cell)
                .buckets(vec![
                    1.0, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0, 14400.0
                ])
            )),
            alertmanager_sends,
            alertmanager_alerts: reg!(IntGauge::with_opts(opts(
                "cellwatch_alertmanager_alerts",
                "Alarms sent to Alertmanager as active alerts now (active, not shelved, in service).",
                cell
            ))),
            alarm_server_sessions: reg!(IntGauge::with_opts(opts(
                "cellwatch_alarm_server_sessions",
                "Sessions the alarm server's clients (SCADA, HMI) hold open now; 0 without [alarm_server].",
                cell
            ))),
            alarm_server_sampler: Arc::new(OnceLock::new()),
            alertmanager_unsent: reg!(IntGauge::with_opts(opts(
                "cellwatch_alertmanager_unsent",
                "Alert changes (raised, updated, ended) not yet accepted by every Alertmanager.",
                cell
            ))),
            alarm_latency_seconds: reg!(Histogram::with_opts(
                HistogramOpts::new(
                    "cellwatch_alarm_latency_seconds",
                    "Time the agent adds to an alarm: from the source receiving the values that raise or clear it to the alarm journaled and published."
                )
                .const_label("cell", cell)
                .buckets(vec![
                    0.000_05, 0.000_1, 0.000_25, 0.000_5, 0.000_75, 0.001, 0.001_5, 0.002,
                    0.002_5, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0
                ])
            )),
            modes: ModeMetrics::register(&registry, cell),
            oee: OeeMetrics::register(&registry, cell),
            sparkplug: SparkplugMetrics::register(&registry, cell),
            registry,
        }
    }

    /// An alarm of `check` was raised.
    pub fn raised(&self, check: &str, kind: AlarmKind, severity: Severity) {
        self.raised
            .with_label_values(&[check, kind.as_str(), severity.as_str()])
            .inc();
    }

    /// One more (`delta` 1) or one fewer (-1) active alarm of `kind` and
    /// `severity`.
    pub fn active_delta(&self, kind: AlarmKind, severity: Severity, delta: i64) {
        self.active
            .with_label_values(&[kind.as_str(), severity.as_str()])
            .add(delta);
    }

    /// The machine is now in `state`, having spent `seconds` in `previous`.
    pub fn state(&self, state: &str, previous: &str, seconds: f64) {
        for s in MachineState::NAMES {
            self.state
                .with_label_values(&[s])
                .set(i64::from(s == state));
        }
        self.add_state_time(previous, seconds);
    }

    /// Adds time spent in the current state.
    pub fn add_state_time(&self, state: &str, seconds: f64) {
        if seconds > 0.0 {
            self.state_seconds
                .with_label_values(&[state])
                .inc_by(seconds);
        }
    }

    /// A fault alarm of `check` is active with `element` first to blame
    /// (`None`: cleared); `previous` is the element it had.
    pub fn culprit(
        &self,
        check: &str,
        severity: &str,
        fault_type: &str,
        element: Option<&str>,
        previous: Option<&str>,
        raised: bool,
    ) {
        if let Some(p) = previous {
            self.culprit
                .with_label_values(&[check, severity, fault_type, p])
                .set(0);
        }
        if let Some(e) = element {
            self.culprit
                .with_label_values(&[check, severity, fault_type, e])
                .set(1);
            if raised {
                self.elements
                    .with_label_values(&[check, fault_type, e])
                    .inc();
            }
        }
    }

    /// An operator command was accepted or refused (`result` is one of
    /// [`COMMAND_RESULTS`]); `None`: the request was no command (`action`
    /// `other`).
    pub fn command(&self, action: Option<Action>, accepted: bool) {
        let action = action.map_or("other", Action::as_str);
        let result = COMMAND_RESULTS[usize::from(!accepted)];
        self.commands.with_label_values(&[action, result]).inc();
    }

    /// Reads `cellwatch_alarm_server_sessions` from `sessions` at each
    /// scrape.
    pub fn sample_alarm_server_sessions(&self, sessions: Sampler) {
        let _ = self.alarm_server_sampler.set(sessions);
    }

    /// Reads `cellwatch_bus_signatures_total` and
    /// `cellwatch_bus_signing_seconds_total` from `signing` at each scrape.
    pub fn sample_signing(&self, signing: SigningSampler) {
        let _ = self.signing_sampler.set(signing);
    }

    /// The text exposition of every metric.
    pub fn render(&self) -> String {
        if let Some(sessions) = self.alarm_server_sampler.get() {
            self.alarm_server_sessions.set(sessions());
        }
        if let Ok(_one_at_a_time) = self.signing_lock.lock() {
            let raise = |counter: &Counter, to: f64| {
                let more = to - counter.get();
                if more > 0.0 {
                    counter.inc_by(more);
                }
            };
            if let Some(signing) = self.signing_sampler.get() {
                let (made, seconds) = signing();
                self.signatures
                    .inc_by(made.saturating_sub(self.signatures.get()));
                raise(&self.signing_seconds, seconds);
            }
            raise(&self.process_cpu, process_cpu_seconds());
        }
        let mut buf = Vec::new();
        let _ = TextEncoder::new().encode(&self.registry.gather(), &mut buf);
        String::from_utf8(buf).unwrap_or_default()
    }
}

/// The process's CPU seconds so far, user and system (0 where unknown).
fn process_cpu_seconds() -> f64 {
    use nix::sys::resource::{getrusage, UsageWho};
    getrusage(UsageWho::RUSAGE_SELF).map_or(0.0, |u| {
        let seconds = |t: nix::sys::time::TimeVal| t.tv_sec() as f64 + t.tv_usec() as f64 / 1e6;
        seconds(u.user_time()) + seconds(u.system_time())
    })
}

impl crate::journal::CommitObserver for Metrics {
    fn committed(&self, rows: usize, took: Duration) {
        self.journal_rows.inc_by(rows as u64);
        self.journal_write_seconds.observe(took.as_secs_f64());
    }

    fn failed(&self, _error: &str) {
        self.journal_errors.inc();
    }

    fn pending(&self, rows: usize) {
        self.journal_pending.set(rows as i64);
    }

    fn dropped(&self, rows: usize) {
        self.journal_dropped.inc_by(rows as u64);
    }
}

impl Metrics {
    /// A send to an Alertmanager succeeded (`true`) or failed.
    pub fn alertmanager_sent(&self, ok: bool) {
        self.alertmanager_sends
            .with_label_values(&[if ok { "ok" } else { "failed" }])
            .inc();
    }

    /// A query to `service` refused for `reason`: one of [`REFUSED`].
    pub fn refused(&self, service: &str, reason: &str) {
        debug_assert!(
            REFUSED.contains(&(service, reason)),
            "{service}/{reason}: not in REFUSED (nor in docs/reference/metrics.md)"
        );
        self.refused.with_label_values(&[service, reason]).inc();
    }
}

/// Serves `GET /metrics`, `/healthz` (every cell loop of the process goes
/// round) and `/readyz` (every cell's source connected, bus session up,
/// journal writable) on `listener` until `shutdown` completes. The health
/// answers are 200 or 503, with one line per cell saying why.
///
/// # Errors
/// The server fails.
pub async fn serve(
    listener: tokio::net::TcpListener,
    metrics: Arc<Metrics>,
    health: Health,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let alive = health.clone();
    let app = Router::new()
        .route(
            "/metrics",
            get(move || {
                let m = metrics.clone();
                async move { ([(CONTENT_TYPE, "text/plain; version=0.0.4")], m.render()) }
            }),
        )
        .route(
            "/healthz",
            get(move || {
                let answer = alive.alive(std::time::Instant::now(), STALLED_AFTER);
                async move { probes::health_answer("ok", "not ok", answer) }
            }),
        )
        .route(
            "/readyz",
            get(move || {
                let health = health.clone();
                async move { probes::health_answer("ready", "not ready", health.ready().await) }
            }),
        );
    axum::serve(listener, app)
        .with_graceful_shutdown(shutdown)
        .await
}

/// Binds the metrics address.
///
/// # Errors
/// The address is in use or not local.
pub async fn bind(addr: SocketAddr) -> std::io::Result<tokio::net::TcpListener> {
    tokio::net::TcpListener::bind(addr).await
}
