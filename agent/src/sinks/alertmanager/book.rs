//! What the cell owes Alertmanager: each alarm as an alert (its labels,
//! annotations and times), the active ones and the ended ones until every
//! Alertmanager has taken them, and the steps of escalation an
//! unacknowledged alarm reaches. Pure: the pusher (`mod.rs`) sends it.

use std::collections::BTreeMap;
use std::time::Duration;

use cellwatch_models::alarm::AlarmState;
use serde::Serialize;

use crate::payload::AlarmPayload;
use crate::sinks::alertmanager::config::AlertmanagerConfig;

/// An alert as Alertmanager's API v2 takes it (`postableAlert`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Alert {
    /// What identifies it: `alertname`, `alarm`, `cell`, `area`,
    /// `priority`, `kind`.
    pub labels: BTreeMap<&'static str, String>,
    /// What people read: `summary`, `culprits` (each culprit's line, as
    /// the CLI prints it, joined by `; `), `acknowledged`, `console`.
    pub annotations: BTreeMap<&'static str, String>,
    /// When the occurrence was raised (RFC 3339).
    #[serde(rename = "startsAt")]
    pub starts_at: String,
    /// When it ended, or until when it holds unless sent again.
    #[serde(rename = "endsAt")]
    pub ends_at: String,
    /// The alarm's page on the console.
    #[serde(rename = "generatorURL", skip_serializing_if = "Option::is_none")]
    pub generator_url: Option<String>,
}

/// The labels and links every alert of the cell carries.
#[derive(Debug, Clone)]
pub(crate) struct Labels {
    cell: String,
    area: Option<String>,
    console: Option<String>,
}

impl Labels {
    /// For `cell`, from its configuration.
    pub(crate) fn new(cell: &str, config: &AlertmanagerConfig) -> Labels {
        Labels {
            cell: cell.into(),
            area: config.area.clone(),
            console: config.console.clone(),
        }
    }

    /// The alert for `alarm` (its `endsAt` set when it is sent or ended).
    fn alert(&self, alarm: &AlarmPayload) -> Alert {
        let mut labels = BTreeMap::from([
            ("alertname", alarm.id.clone()),
            ("alarm", alarm.id.clone()),
            ("cell", self.cell.clone()),
            ("priority", alarm.severity.as_str().to_string()),
            ("kind", alarm.kind.as_str().to_string()),
            (
                "acknowledged",
                (alarm.state == AlarmState::ActiveAcknowledged).to_string(),
            ),
        ]);
        if let Some(area) = &self.area {
            labels.insert("area", area.clone());
        }
        if let Some(c) = &alarm.consequence {
            labels.insert("consequence_of", c.cause.clone());
            labels.insert("first_out", c.first_out.clone());
        }
        let mut annotations = BTreeMap::from([("summary", alarm.message.clone())]);
        if let Some(c) = &alarm.consequence {
            annotations.insert("consequence", c.why());
        }
        // The same line the CLI and the console show for each culprit.
        let culprits: Vec<String> = alarm
            .culprits
            .iter()
            .map(|c| c.line().trim_end().to_string())
            .collect();
        if !culprits.is_empty() {
            annotations.insert("culprits", culprits.join("; "));
        }
        if let Some(by) = &alarm.acked_by {
            let said = alarm
                .ack_comment
                .as_ref()
                .map_or_else(String::new, |c| format!(": {c}"));
            annotations.insert("acknowledged", format!("by {by}{said}"));
        }
        // The master alarm database's guidance, where the cell has it.
        if let Some(g) = &alarm.guidance {
            for (key, text) in [
                ("corrective_action", &g.corrective_action),
                ("consequence_of_inaction", &g.consequence_of_inaction),
            ] {
                if !text.is_empty() {
                    annotations.insert(key, text.clone());
                }
            }
            if let Some(t) = &g.response_time {
                annotations.insert("response_time", t.clone());
            }
        }
        let generator_url = self
            .console
            .as_ref()
            .map(|c| format!("{c}/#/alarm/{}/{}", self.cell, alarm.id));
        if let Some(link) = &generator_url {
            annotations.insert("console", link.clone());
        }
        Alert {
            labels,
            annotations,
            starts_at: alarm.raised_at.clone(),
            ends_at: String::new(),
            generator_url,
        }
    }
}

/// What is to be sent, per alarm: active alerts, and ended ones until
/// every Alertmanager has taken them. Pure: no I/O, no clock (times are
/// handed in).
///
/// An alert's labels are its identity in Alertmanager: when an alarm's
/// change its labels (acknowledged, a step of escalation reached), the
/// alert under the old labels ends as the new one begins, so that a route
/// on `acknowledged="false"` or `unacknowledged_for` stops notifying.
#[derive(Debug, Default)]
pub(crate) struct AlertBook {
    active: BTreeMap<String, Active>,
    /// Ended alerts, by their labels, and the Alertmanagers (bits by
    /// index) still owed them.
    ended: BTreeMap<String, (Alert, u64)>,
    /// The Alertmanagers (bits) with a change they have not been sent.
    changed: u64,
    /// Every Alertmanager's bit.
    all: u64,
    /// The steps of `unacknowledged_for`: its value, from how long (ms).
    steps: Vec<(String, u64)>,
}

/// An alarm's active alert.
#[derive(Debug)]
struct Active {
    alert: Alert,
    /// When it was raised (ms), while nobody acknowledged it.
    unacknowledged_since: Option<u64>,
    /// When it is overdue (ms): unacknowledged past its response time.
    overdue_from: Option<u64>,
}

/// One send's content for one Alertmanager.
#[derive(Debug)]
pub(crate) struct AlertBatch {
    /// The Alertmanager's index.
    pub to: usize,
    /// The alerts, active ones with `endsAt` set.
    pub alerts: Vec<Alert>,
    /// The ended alerts in it (their labels).
    ended: Vec<String>,
}

/// An alert's labels as one text: its identity.
fn identity(alert: &Alert) -> String {
    let mut text = String::new();
    for (k, v) in &alert.labels {
        text.push_str(k);
        text.push('=');
        text.push_str(v);
        text.push('\n');
    }
    text
}

impl AlertBook {
    /// A book for `alertmanagers` Alertmanagers (at most 64), marking an
    /// alarm unacknowledged for a step of `escalation` once that long
    /// has passed since its raise.
    pub(crate) fn new(alertmanagers: usize, escalation: &[(String, Duration)]) -> AlertBook {
        let all = if alertmanagers >= 64 {
            u64::MAX
        } else {
            (1u64 << alertmanagers) - 1
        };
        AlertBook {
            all,
            steps: escalation
                .iter()
                .map(|(name, d)| {
                    (
                        name.clone(),
                        u64::try_from(d.as_millis()).unwrap_or(u64::MAX),
                    )
                })
                .collect(),
            ..AlertBook::default()
        }
    }

    /// The step of escalation reached `for_ms` after a raise, if any.
    fn step(&self, for_ms: u64) -> Option<&str> {
        self.steps
            .iter()
            .rev()
            .find(|(_, from)| for_ms >= *from)
            .map(|(name, _)| name.as_str())
    }

    /// `alert` with the `unacknowledged_for` label of `now` (none before
    /// the first step, nor once acknowledged), and the `overdue`
    /// annotation once past its response time.
    fn escalated(&self, mut alert: Alert, active: &Active, now: u64) -> Alert {
        let since = active.unacknowledged_since;
        match since.and_then(|t| self.step(now.saturating_sub(t))) {
            Some(step) => alert.labels.insert("unacknowledged_for", step.to_string()),
            None => alert.labels.remove("unacknowledged_for"),
        };
        if active.overdue_from.is_some_and(|from| now >= from) {
            let within = alert.annotations.get("response_time").cloned();
            let text = match within {
                Some(t) => format!("unacknowledged past its response time ({t})"),
                None => "unacknowledged past its response time".to_string(),
            };
            alert.annotations.insert("overdue", text);
        } else {
            alert.annotations.remove("overdue");
        }
        alert
    }

    /// Takes `alarm`'s latest payload, at `now` (ms): whether anything is
    /// to be sent.
    pub(crate) fn take(&mut self, labels: &Labels, alarm: &AlarmPayload, now: u64) -> bool {
        let alerting = matches!(
            alarm.state,
            AlarmState::ActiveUnacknowledged | AlarmState::ActiveAcknowledged
        ) && alarm.shelved.is_none()
            && alarm.out_of_service.is_none()
            && !alarm.consequence.as_ref().is_some_and(|c| c.suppressed)
            && alarm.suppressed_by_design.is_none();
        if alerting {
            let since = (alarm.state == AlarmState::ActiveUnacknowledged).then(|| {
                humantime::parse_rfc3339_weak(&alarm.raised_at)
                    .ok()
                    .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                    .map_or(now, |d| u64::try_from(d.as_millis()).unwrap_or(now))
            });
            let mut active = Active {
                alert: labels.alert(alarm),
                unacknowledged_since: since,
                overdue_from: alarm.overdue_from(),
            };
            let alert = self.escalated(active.alert.clone(), &active, now);
            if self.active.get(&alarm.id).is_some_and(|a| a.alert == alert) {
                return false;
            }
            self.ended.remove(&identity(&alert));
            active.alert = alert.clone();
            let before = self.active.insert(alarm.id.clone(), active);
            if let Some(before) = before.filter(|b| b.alert.labels != alert.labels) {
                self.end(before.alert, &alarm.at);
            }
        } else {
            let Some(active) = self.active.remove(&alarm.id) else {
                return false;
            };
            // It ended when it cleared, was shelved or taken out of
            // service: this payload's time.
            self.end(active.alert, &alarm.at);
        }
        self.changed = self.all;
        true
    }

    /// `alert` ended at `at` (RFC 3339): owed to every Alertmanager.
    fn end(&mut self, mut alert: Alert, at: &str) {
        at.clone_into(&mut alert.ends_at);
        self.ended.insert(identity(&alert), (alert, self.all));
    }

    /// Time reached `now` (ms): the alerts unacknowledged long enough for
    /// their next step of escalation get it, and those past their response
    /// time the `overdue` annotation. Whether anything changed.
    pub(crate) fn escalate(&mut self, now: u64) -> bool {
        let mut moved = Vec::new();
        for (id, a) in &self.active {
            let alert = self.escalated(a.alert.clone(), a, now);
            if alert != a.alert {
                moved.push((id.clone(), alert));
            }
        }
        if moved.is_empty() {
            return false;
        }
        let at = crate::clock::rfc3339(now);
        for (id, alert) in moved {
            if let Some(a) = self.active.get_mut(&id) {
                let relabelled = alert.labels != a.alert.labels;
                let before = std::mem::replace(&mut a.alert, alert);
                // The same labels: the same alert, sent again with its new
                // annotations.
                if relabelled {
                    self.end(before, &at);
                }
            }
        }
        self.changed = self.all;
        true
    }

    /// When (ms) an alert unacknowledged now reaches its next step of
    /// escalation or becomes overdue, the earliest of them.
    pub(crate) fn next_escalation(&self, now: u64) -> Option<u64> {
        let steps = self
            .active
            .values()
            .filter_map(|a| a.unacknowledged_since)
            .filter_map(|since| {
                self.steps
                    .iter()
                    .map(|(_, from)| since.saturating_add(*from))
                    .find(|at| *at > now)
            });
        let overdue = self
            .active
            .values()
            .filter_map(|a| a.overdue_from)
            .filter(|at| *at > now);
        steps.chain(overdue).min()
    }

    /// Alertmanager `to` has a change it was not sent (one that came
    /// while a batch was on its way).
    pub(super) fn mark_changed(&mut self, to: usize) {
        self.changed |= 1 << to;
    }

    /// Whether Alertmanager `to` has a change it was not sent.
    pub(crate) fn changed(&self, to: usize) -> bool {
        self.changed & (1 << to) != 0
    }

    /// What to send to Alertmanager `to`: every active alert, holding
    /// until `holds_until` (RFC 3339), and the ended ones it is owed.
    pub(crate) fn batch(&self, to: usize, holds_until: &str) -> AlertBatch {
        let bit = 1 << to;
        let mut alerts: Vec<Alert> = self
            .active
            .values()
            .map(|a| Alert {
                ends_at: holds_until.to_string(),
                ..a.alert.clone()
            })
            .collect();
        let mut ended = Vec::new();
        for (id, (alert, owed)) in &self.ended {
            if owed & bit != 0 {
                alerts.push(alert.clone());
                ended.push(id.clone());
            }
        }
        AlertBatch { to, alerts, ended }
    }
    /// Alertmanager `batch.to` took `batch`.
    pub(crate) fn sent(&mut self, batch: &AlertBatch) {
        let bit = 1 << batch.to;
        for id in &batch.ended {
            if let Some((_, owed)) = self.ended.get_mut(id) {
                *owed &= !bit;
                if *owed == 0 {
                    self.ended.remove(id);
                }
            }
        }
        // A change after the batch was made is in the book, not in the
        // batch: only a batch with everything clears the flag (the caller
        // makes and sends batches with the book's lock released, so it
        // marks the change again if one came: see `Pusher`).
        self.changed &= !bit;
    }

    /// Alerts active now.
    pub(crate) fn active(&self) -> usize {
        self.active.len()
    }

    /// Changes not yet taken by every Alertmanager: ended alerts owed,
    /// plus the active ones while any Alertmanager has a change unsent.
    pub(crate) fn unsent(&self) -> usize {
        let active = if self.changed == 0 {
            0
        } else {
            self.active.len()
        };
        self.ended.len() + active
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cellwatch_models::alarm::{AlarmKind, Severity, Transition};

    fn payload(id: &str, state: AlarmState, at: &str) -> AlarmPayload {
        let mut p: AlarmPayload = serde_json::from_value(serde_json::json!({
            "schema": "cellwatch.alarm.v1", "cell": "m01", "id": id,
            "kind": "switching", "severity": "high", "state": "normal",
            "transition": "raised", "at": at, "raised_at": "2026-11-26T10:00:00.000Z",
            "cleared_at": null, "acked_by": null, "fault_type": "ESE", "fault_step": 3,
            "culprits": [{"address": "X0.06", "value": false, "expected": true,
                          "comment": "Emergency stop", "trigger": true}],
            "message": "Emergency stop error",
        }))
        .unwrap();
        p.state = state;
        p.kind = AlarmKind::Switching;
        p.severity = Severity::High;
        p.transition = Transition::Raised;
        p
    }

    /// 2026-11-26T10:00:30Z, ms.
    const NOW: u64 = 1_795_687_230_000;

    fn labels() -> Labels {
        Labels {
            cell: "m01".into(),
            area: Some("press shop".into()),
            console: Some("https://console:8470".into()),
        }
    }

    #[test]
    fn a_consequence_is_an_alert_naming_its_cause_unless_suppressed() {
        let mut book = AlertBook::new(1, &[]);
        let l = labels();
        let mut csd = payload(
            "csd",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        csd.consequence = Some(crate::payload::ConsequencePayload {
            cause: "ese".into(),
            first_out: "ese".into(),
            suppressed: false,
            through: vec![crate::payload::ThroughPayload {
                signal: "G8.02".into(),
                value: true,
            }],
        });
        assert!(book.take(&l, &csd, NOW));
        let b = book.batch(0, "2026-11-26T10:04:00.000Z");
        assert_eq!(b.alerts[0].labels["consequence_of"], "ese");
        assert_eq!(b.alerts[0].labels["first_out"], "ese");
        assert_eq!(
            b.alerts[0].annotations["consequence"],
            "follows from ese: G8.02 = 1 (0 without ese's fault)"
        );
        // Suppressed: no alert (and the one sent ends).
        let mut book = AlertBook::new(1, &[]);
        if let Some(c) = csd.consequence.as_mut() {
            c.suppressed = true;
        }
        assert!(!book.take(&l, &csd, NOW));
        assert!(book.batch(0, "2026-11-26T10:04:00.000Z").alerts.is_empty());
    }

    #[test]
    fn an_alarm_with_guidance_carries_it_as_annotations() {
        let mut book = AlertBook::new(1, &[]);
        let mut ese = payload(
            "ese",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        ese.guidance = Some(crate::payload::GuidancePayload {
            class: "safety".into(),
            consequence_of_inaction: "the machine stays stopped".into(),
            corrective_action: "Drive the axis off its limit switch in JOG".into(),
            response_time: Some("5m".into()),
        });
        assert!(book.take(&labels(), &ese, NOW));
        let b = book.batch(0, "x");
        let a = &b.alerts[0].annotations;
        assert_eq!(
            a["corrective_action"],
            "Drive the axis off its limit switch in JOG"
        );
        assert_eq!(a["consequence_of_inaction"], "the machine stays stopped");
        assert_eq!(a["response_time"], "5m");
    }

    #[test]
    fn an_alarm_unacknowledged_past_its_response_time_is_marked_overdue_until_acknowledged() {
        let mut book = AlertBook::new(1, &[]);
        let l = labels();
        // Raised at 10:00:00 with two minutes to act; taken at 10:00:30.
        let mut ese = payload(
            "ese",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        ese.guidance = Some(crate::payload::GuidancePayload {
            class: "safety".into(),
            consequence_of_inaction: String::new(),
            corrective_action: "Release the emergency stop".into(),
            response_time: Some("2m".into()),
        });
        let raised_ms = NOW - 30_000;
        assert!(book.take(&l, &ese, NOW));
        let overdue = |book: &AlertBook| {
            book.batch(0, "x").alerts[0]
                .annotations
                .get("overdue")
                .cloned()
        };
        assert_eq!(overdue(&book), None);
        assert_eq!(book.next_escalation(NOW), Some(raised_ms + 120_000));
        book.sent(&book.batch(0, "x"));
        // At its response time: the same alert (its labels unchanged, none
        // ended), sent again with the annotation.
        assert!(!book.escalate(raised_ms + 119_999));
        assert!(book.escalate(raised_ms + 120_000));
        let b = book.batch(0, "x");
        assert_eq!(b.alerts.len(), 1);
        assert_eq!(
            b.alerts[0].annotations["overdue"],
            "unacknowledged past its response time (2m)"
        );
        book.sent(&b);
        assert_eq!(book.next_escalation(raised_ms + 120_000), None);
        // A restart after the response time: overdue at once.
        let mut later = AlertBook::new(1, &[]);
        assert!(later.take(&l, &ese, raised_ms + 600_000));
        assert!(overdue(&later).is_some());
        // Acknowledged: no longer overdue.
        let mut acked = ese.clone();
        acked.state = AlarmState::ActiveAcknowledged;
        acked.acked_by = Some("kim".into());
        assert!(book.take(&l, &acked, raised_ms + 200_000));
        assert_eq!(overdue(&book), None);
        // Shelved alarms are nobody's to act on: never overdue.
        let mut shelved = ese.clone();
        shelved.shelved = Some(crate::payload::ShelfPayload {
            by: "kim".into(),
            reason: "sensor replaced".into(),
            at: "2026-11-26T10:00:10.000Z".into(),
            until: None,
        });
        assert_eq!(shelved.overdue_from(), None);
        assert_eq!(ese.overdue_from(), Some(raised_ms + 120_000));
    }

    #[test]
    fn an_alarm_suppressed_by_design_is_no_alert_until_its_mode_ends() {
        let mut book = AlertBook::new(1, &[]);
        let l = labels();
        let mut ese = payload(
            "ese",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        ese.suppressed_by_design = Some(crate::payload::DesignedPayload {
            mode: "setup".into(),
            since: "2026-11-26T10:00:00.000Z".into(),
        });
        assert!(!book.take(&l, &ese, NOW));
        assert_eq!(book.active(), 0);
        // The mode ends with the alarm active: an alert now.
        ese.suppressed_by_design = None;
        ese.transition = cellwatch_models::alarm::Transition::Unsuppressed;
        assert!(book.take(&l, &ese, NOW));
        assert_eq!(book.batch(0, "x").alerts.len(), 1);
    }

    #[test]
    fn an_alarm_is_an_alert_while_active_unshelved_and_in_service() {
        let mut book = AlertBook::new(2, &[]);
        let l = labels();
        let raised = payload(
            "ese",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        assert!(book.take(&l, &raised, NOW));
        assert!(book.changed(0) && book.changed(1));
        let b = book.batch(0, "2026-11-26T10:04:00.000Z");
        assert_eq!(b.alerts.len(), 1);
        let a = &b.alerts[0];
        assert_eq!(a.labels["alertname"], "ese");
        assert_eq!(a.labels["cell"], "m01");
        assert_eq!(a.labels["area"], "press shop");
        assert_eq!(a.labels["priority"], "high");
        assert_eq!(a.labels["kind"], "switching");
        assert_eq!(
            a.annotations["culprits"],
            "X0.06 = 0 (expected 1): Emergency stop   <- trigger"
        );
        assert_eq!(a.annotations["summary"], "Emergency stop error");
        assert_eq!(a.starts_at, "2026-11-26T10:00:00.000Z");
        assert_eq!(a.ends_at, "2026-11-26T10:04:00.000Z");
        assert_eq!(
            a.generator_url.as_deref(),
            Some("https://console:8470/#/alarm/m01/ese")
        );
        book.sent(&b);
        assert!(!book.changed(0) && book.changed(1));
        // The same payload again changes nothing; an acknowledgement does.
        assert!(!book.take(&l, &raised, NOW));
        let mut acked = payload(
            "ese",
            AlarmState::ActiveAcknowledged,
            "2026-11-26T10:01:00.000Z",
        );
        acked.acked_by = Some("kim".into());
        acked.ack_comment = Some("tool changed".into());
        assert!(book.take(&l, &acked, NOW));
        // Acknowledged: a new alert; the one not acknowledged ends then.
        let b = book.batch(0, "x");
        assert_eq!(b.alerts.len(), 2);
        assert_eq!(b.alerts[0].labels["acknowledged"], "true");
        assert_eq!(
            b.alerts[0].annotations["acknowledged"],
            "by kim: tool changed"
        );
        assert_eq!(b.alerts[1].labels["acknowledged"], "false");
        assert_eq!(b.alerts[1].ends_at, "2026-11-26T10:01:00.000Z");
        book.sent(&b);
        book.sent(&book.batch(1, "x"));
        assert_eq!(book.unsent(), 0);

        // Shelved: ended at the shelf's time, owed to both.
        let mut shelved = acked.clone();
        shelved.at = "2026-11-26T10:02:00.000Z".into();
        shelved.shelved = Some(serde_json::from_value(serde_json::json!({
            "by": "kim", "reason": "sensor swap", "at": "2026-11-26T10:02:00.000Z", "until": null
        })).unwrap());
        assert!(book.take(&l, &shelved, NOW));
        assert_eq!(book.active(), 0);
        let b0 = book.batch(0, "x");
        assert_eq!(b0.alerts.len(), 1);
        assert_eq!(b0.alerts[0].ends_at, "2026-11-26T10:02:00.000Z");
        book.sent(&b0);
        // Owed to the second Alertmanager until it takes it.
        assert!(book.batch(0, "x").alerts.is_empty());
        assert_eq!(book.unsent(), 1);
        let b1 = book.batch(1, "x");
        assert_eq!(b1.alerts.len(), 1);
        book.sent(&b1);
        assert_eq!(book.unsent(), 0);

        // Unshelved while active: an alert again; cleared: ended again.
        assert!(book.take(&l, &acked, NOW));
        assert_eq!(book.active(), 1);
        let cleared = payload(
            "ese",
            AlarmState::ClearedUnacknowledged,
            "2026-11-26T10:05:00.000Z",
        );
        assert!(book.take(&l, &cleared, NOW));
        assert_eq!(
            book.batch(1, "x").alerts[0].ends_at,
            "2026-11-26T10:05:00.000Z"
        );
        // Out of service: never an alert.
        let mut removed = raised.clone();
        removed.id = "door".into();
        removed.out_of_service = Some(
            serde_json::from_value(serde_json::json!({
                "by": "kim", "reason": "rebuild", "at": "2026-11-26T10:06:00.000Z"
            }))
            .unwrap(),
        );
        assert!(!book.take(&l, &removed, NOW));
        assert_eq!(book.active(), 0);
    }

    #[test]
    fn an_alarm_nobody_acknowledges_escalates_step_by_step_until_acknowledged() {
        let minutes = |m: u64| Duration::from_secs(60 * m);
        let steps = [
            ("5m".to_string(), minutes(5)),
            ("15m".to_string(), minutes(15)),
            ("1h".to_string(), minutes(60)),
        ];
        let mut book = AlertBook::new(1, &steps);
        let l = labels();
        // Raised at 10:00:00, taken at 10:00:30.
        let raised = payload(
            "ese",
            AlarmState::ActiveUnacknowledged,
            "2026-11-26T10:00:00.000Z",
        );
        let raised_ms = NOW - 30_000;
        assert!(book.take(&l, &raised, NOW));
        let label = |book: &AlertBook| {
            book.batch(0, "x").alerts[0]
                .labels
                .get("unacknowledged_for")
                .cloned()
        };
        assert_eq!(label(&book), None);
        assert_eq!(book.next_escalation(NOW), Some(raised_ms + 300_000));
        book.sent(&book.batch(0, "x"));
        // Nothing before the step; at it, the label, and the alert under
        // the old labels ends then.
        assert!(!book.escalate(raised_ms + 299_999));
        assert!(book.escalate(raised_ms + 300_000));
        let b = book.batch(0, "x");
        assert_eq!(b.alerts.len(), 2);
        assert_eq!(b.alerts[0].labels["unacknowledged_for"], "5m");
        assert!(!b.alerts[1].labels.contains_key("unacknowledged_for"));
        assert_eq!(b.alerts[1].ends_at, "2026-11-26T10:05:00.000Z");
        book.sent(&b);
        assert_eq!(
            book.next_escalation(raised_ms + 300_000),
            Some(raised_ms + 900_000)
        );
        // A restart that took the alarm back an hour and more after its
        // raise: the last step at once, no step after it.
        let mut later = AlertBook::new(1, &steps);
        assert!(later.take(&l, &raised, raised_ms + 3_700_000));
        assert_eq!(label(&later).as_deref(), Some("1h"));
        assert_eq!(later.next_escalation(raised_ms + 3_700_000), None);
        // Acknowledged at 10:20: no step any more, the escalated alert
        // ends, and nothing escalates again.
        assert!(book.escalate(raised_ms + 900_000));
        book.sent(&book.batch(0, "x"));
        let mut acked = payload(
            "ese",
            AlarmState::ActiveAcknowledged,
            "2026-11-26T10:20:00.000Z",
        );
        acked.acked_by = Some("kim".into());
        assert!(book.take(&l, &acked, raised_ms + 1_200_000));
        let b = book.batch(0, "x");
        assert_eq!(b.alerts[0].labels["acknowledged"], "true");
        assert!(!b.alerts[0].labels.contains_key("unacknowledged_for"));
        let ended: Vec<_> = b.alerts[1..]
            .iter()
            .map(|a| (a.labels["unacknowledged_for"].as_str(), a.ends_at.as_str()))
            .collect();
        assert_eq!(ended, [("15m", "2026-11-26T10:20:00.000Z")]);
        assert_eq!(book.next_escalation(raised_ms + 1_200_000), None);
        assert!(!book.escalate(raised_ms + 7_200_000));
    }
}
