//! Forced transitions and the stop switch (paper 004): the only writes to
//! an OPC UA PLC.
//!
//! A `force` names a transition (`F1.t3`); the loop checks, in order and
//! journaling each: the operator's signature and permission (the gate),
//! then [`cellwatch_models::sfc::force::check`] (the transition exists, is
//! declared forcible, leaves a step whose stuck alarm is active, and its
//! condition holds now). Only then is the force switch pulsed; the loop
//! waits for every step the transition leads to to become active, and
//! answers the operator with the outcome. A force that does not arrive
//! within `force_timeout` raises the alarm `force-<chart>-<transition>`,
//! cleared when the chart gets there or leaves the stuck step another
//! way. A `stop` names a chart and pulses its stop switch: permission is
//! its only check.

use cellwatch_models::engine::{EngineStep, Value};
use cellwatch_models::sfc::force;
use cellwatch_models::signal::Signal;
use tokio::sync::oneshot;

use super::forcing::{ForceSet, Pending};
use crate::step::CommandOutcome;

use super::{
    CellLoop, CommandError, CommandRecord, Input, Stage, Then, Written, RECORD_FIELD_BYTES,
    WRITE_TIMEOUT,
};
use crate::operator::{clip, Action, Command};
use crate::sources::Write;

impl CellLoop {
    /// Journals one row of a command (and hands it to every sink).
    async fn record(&mut self, record: CommandRecord) {
        let now = self.clock.now_ms();
        self.dispatch(now, Input::Command(record), EngineStep::default(), 0)
            .await;
    }

    /// A `force` or `stop`: every check journaled, the switch pulsed only
    /// if all hold.
    pub(super) async fn switch_command(
        &mut self,
        cmd: Command,
        gate: Result<(), CommandError>,
        reply: oneshot::Sender<CommandOutcome>,
        now: u64,
    ) {
        let target = clip(cmd.value.as_deref().unwrap_or(""), RECORD_FIELD_BYTES);
        let base = CommandRecord {
            verified: gate.is_ok(),
            ..CommandRecord::of(&cmd, &target, Stage::Request)
        };
        let row = |stage: Stage, accepted: bool, detail: String| CommandRecord {
            stage,
            ..base.clone().saying(accepted, &detail)
        };
        // Taken up (its nonce used) only when its operator may ask for it.
        self.record(row(
            Stage::Request,
            gate.is_ok(),
            format!("{} {target} asked by {}", cmd.action, base.operator),
        ))
        .await;
        let checks = match gate {
            Err(why) => Err(("operator", why)),
            Ok(()) if !cmd.alarm.is_empty() || cmd.tag.is_some() || cmd.reason.is_some() => {
                Err(("request", CommandError::SwitchNamesMore(cmd.action)))
            }
            Ok(()) => Ok(format!(
                "operator: {} may {} (signature verified)",
                base.operator, cmd.action
            )),
        };
        let refuse =
            |why: CommandError| (row(Stage::Result, false, format!("refused: {why}")), why);
        let refused = match checks {
            Err((name, why)) => {
                self.record(row(Stage::Check, false, format!("{name}: {why}")))
                    .await;
                Some(refuse(why))
            }
            Ok(passed) => {
                self.record(row(Stage::Check, true, passed)).await;
                match cmd.action {
                    Action::Force => self.force(&target, now, &row).await.err(),
                    _ => self.stop(&target, &row).await.err(),
                }
                .map(refuse)
            }
        };
        match refused {
            Some((result, why)) => {
                tracing::warn!(operator = %base.operator, action = %cmd.action, target = %target, "refused: {why}");
                self.record(result).await;
                let _ = reply.send(CommandOutcome::new(false, why.to_string()));
            }
            None => self.send_pulse(&cmd, &target, base, reply).await,
        }
    }

    /// The checks of a force; `Err(why)` at the first that fails.
    async fn force(
        &mut self,
        target: &str,
        now: u64,
        row: &(dyn Fn(Stage, bool, String) -> CommandRecord + Sync),
    ) -> Result<(), CommandError> {
        let Some((chart, transition)) = target.split_once('.') else {
            let why = CommandError::NotATransition(target.into());
            self.record(row(Stage::Check, false, format!("transition: {why}")))
                .await;
            return Err(why);
        };
        if let Some(p) = self
            .forcing
            .pending
            .as_ref()
            .filter(|p| p.writing || p.reply.is_some())
        {
            let why = CommandError::ForceUnderWay {
                transition: p.transition.clone(),
                operator: p.operator.clone(),
            };
            self.record(row(Stage::Check, false, format!("busy: {why}")))
                .await;
            return Err(why);
        }
        let verdict = match self.forcing.set_of(chart) {
            None => force::ForceVerdict {
                checks: vec![force::ForceCheck {
                    name: "transition",
                    passed: false,
                    detail: CommandError::NoChart(chart.into()).to_string(),
                }],
                targets: Vec::new(),
            },
            Some(set) => {
                let bad: std::collections::HashSet<usize> = self.engine.bad_tags().collect();
                let engine = &self.engine;
                let value = |s: &Signal| {
                    let i = engine.tag_index(s)?;
                    match engine.value(i) {
                        Some(Value::Bool(b)) if !bad.contains(&i) => Some(b),
                        _ => None,
                    }
                };
                force::check(
                    &set.sfc,
                    chart,
                    transition,
                    |c, t| set.forcible.iter().any(|(fc, ft)| fc == c && ft == t),
                    |r| {
                        let id = set.sfc_alarm(r);
                        let active = engine
                            .alarms()
                            .any(|a| a.id == id && a.active && a.out_of_service.is_none());
                        (id, active)
                    },
                    value,
                    &set.comments,
                )
            }
        };
        for c in &verdict.checks {
            self.record(row(
                Stage::Check,
                c.passed,
                format!("{}: {}", c.name, c.detail),
            ))
            .await;
        }
        if let Some(failed) = verdict.refusal() {
            return Err(CommandError::CheckFailed {
                check: failed.name,
                detail: failed.detail.clone(),
            });
        }
        let set = self.forcing.set_of(chart).expect("checked above");
        let flag = |r| {
            let step = set.sfc.step(r);
            (set.sfc.step_name(r), self.engine.tag_index(&step.flag))
        };
        let (_, t) = set
            .sfc
            .transition(chart, transition)
            .expect("checked above");
        let targets: Vec<(String, usize)> = verdict
            .targets
            .iter()
            .filter_map(|&r| {
                let (name, tag) = flag(r);
                Some((name, tag?))
            })
            .collect();
        let sources: Vec<usize> = t.from.iter().filter_map(|&r| flag(r).1).collect();
        let timeout = set.timeout.as_millis() as u64;
        // Replaced: an overdue force still watched.
        if let Some(old) = self.forcing.pending.take() {
            self.settle(old, now, "superseded by a new force").await;
        }
        self.forcing.pending = Some(Pending {
            operator: String::new(),
            nonce: String::new(),
            digest: None,
            transition: target.to_string(),
            seen: vec![false; targets.len()],
            targets,
            sources,
            since: now,
            deadline: now + timeout,
            reply: None,
            writing: true,
            overdue: false,
        });
        Ok(())
    }

    /// The check of a stop: the chart has a stop switch.
    async fn stop(
        &mut self,
        chart: &str,
        row: &(dyn Fn(Stage, bool, String) -> CommandRecord + Sync),
    ) -> Result<(), CommandError> {
        let found = match self.forcing.set_of(chart) {
            None => Err(CommandError::NoChart(chart.into())),
            Some(set) if set.stop_switch.is_none() => Err(CommandError::NoStopSwitch(chart.into())),
            Some(_) => Ok(format!("chart {chart} has a stop switch")),
        };
        let (passed, detail) = match &found {
            Ok(d) => (true, d.clone()),
            Err(d) => (false, d.to_string()),
        };
        self.record(row(Stage::Check, passed, format!("switch: {detail}")))
            .await;
        found.map(|_| ())
    }

    /// Hands the switch's pulse to the source; the outcome comes back as
    /// a [`Written`] (at once when nothing could be sent).
    async fn send_pulse(
        &mut self,
        cmd: &Command,
        target: &str,
        base: CommandRecord,
        reply: oneshot::Sender<CommandOutcome>,
    ) {
        let chart = target.split('.').next().unwrap_or("");
        let (force_switch, stop_switch, pulse) = self
            .forcing
            .set_of(chart)
            .map(|s| (s.force_switch, s.stop_switch, s.pulse))
            .expect("checked");
        let (switch, then) = match (cmd.action, self.forcing.pending.as_mut()) {
            (Action::Force, Some(pending)) => {
                pending.operator = base.operator.clone();
                pending.nonce = base.nonce.clone();
                pending.digest = base.digest.clone();
                (force_switch, Then::Force)
            }
            _ => (stop_switch, Then::Stop),
        };
        let record = CommandRecord {
            stage: Stage::Write,
            ..base
        };
        let back = self.written_tx.clone();
        let done = move |accepted: bool, detail: String| Written {
            record: record.saying(accepted, &detail),
            reply,
            then,
        };
        let Some(switch) = switch else {
            let w = done(false, CommandError::NoWrites.to_string());
            return self.written(w).await;
        };
        // The request row, with the nonce, is on disk before the switch
        // is touched.
        let written =
            self.write_when_journaled(Some(switch), Write::Pulse(pulse), WRITE_TIMEOUT + pulse);
        self.start_task(async move {
            let w = match written.await {
                Ok(d) => done(true, d),
                Err(d) => done(false, d.to_string()),
            };
            let _ = back.send(w).await;
        });
    }

    /// A write came back: journal it, then answer or wait for the chart.
    pub(super) async fn written(&mut self, w: Written) {
        let Written {
            record,
            reply,
            then,
        } = w;
        if !record.accepted {
            tracing::warn!(detail = %record.detail, "write not done");
        }
        let now = self.clock.now_ms();
        let outcome = CommandOutcome::new(record.accepted, record.detail.clone());
        let result = |detail: String, accepted| CommandRecord {
            stage: Stage::Result,
            ..record.clone().saying(accepted, &detail)
        };
        let ok = record.accepted;
        let failed = result(format!("not done: {}", record.detail), false);
        let stopped = result(format!("stop switch pressed: {}", record.detail), true);
        self.record(record).await;
        match then {
            Then::Answer => {
                let _ = reply.send(outcome);
            }
            Then::Acknowledge(comment) => {
                if ok {
                    self.acknowledged_at_plc(&failed, comment.as_deref()).await;
                }
                let _ = reply.send(outcome);
            }
            Then::Stop | Then::Force if !ok => {
                if matches!(then, Then::Force) {
                    self.forcing.pending = None;
                }
                self.record(failed).await;
                let _ = reply.send(outcome);
            }
            Then::Stop => {
                self.record(stopped).await;
                let _ = reply.send(outcome);
            }
            Then::Force => {
                if let Some(pending) = self.forcing.pending.as_mut() {
                    // The target steps' time starts with the pulse done.
                    let timeout = pending.deadline - pending.since;
                    pending.writing = false;
                    pending.reply = Some(reply);
                    pending.since = now;
                    pending.deadline = now + timeout;
                }
                self.follow_force(now).await;
            }
        }
    }

    /// After readings: has the forced transition arrived (or the chart
    /// left its source steps another way)?
    pub(super) async fn follow_force(&mut self, now: u64) {
        let engine = &self.engine;
        let on = |tag: usize| engine.value(tag) == Some(Value::Bool(true));
        let Some(p) = self.forcing.pending.as_mut() else {
            return;
        };
        for (seen, &(_, t)) in p.seen.iter_mut().zip(&p.targets) {
            *seen |= on(t);
        }
        // The write is journaled before the result.
        if p.writing {
            return;
        }
        let arrived = !p.targets.is_empty() && p.seen.iter().all(|&s| s);
        let left = p.overdue && !p.sources.iter().any(|&t| on(t));
        if !arrived && !left {
            return;
        }
        let p = self.forcing.pending.take().expect("checked above");
        let detail = if arrived {
            format!(
                "{} active {:.1} s after the force{}",
                p.targets
                    .iter()
                    .map(|(n, _)| n.as_str())
                    .collect::<Vec<_>>()
                    .join(" + "),
                now.saturating_sub(p.since) as f64 / 1000.0,
                if p.overdue { " (late)" } else { "" }
            )
        } else {
            "the chart left the stuck step another way".to_string()
        };
        self.settle(p, now, &detail).await;
    }

    /// After a tick: a force whose targets are late raises its alarm and
    /// answers the operator.
    pub(super) async fn force_overdue(&mut self, now: u64) {
        let Some(p) = self.forcing.pending.as_mut() else {
            return;
        };
        if p.reply.is_none() || now < p.deadline {
            return;
        }
        let waited = (p.deadline - p.since) as f64 / 1000.0;
        let missing: Vec<&str> = p
            .targets
            .iter()
            .zip(&p.seen)
            .filter(|(_, &seen)| !seen)
            .map(|((n, _), _)| n.as_str())
            .collect();
        let why = format!(
            "{} forced by {}: {} not active {waited:.1} s after the force",
            p.transition,
            p.operator,
            missing.join(" + ")
        );
        p.overdue = true;
        let reply = p.reply.take();
        let alarm = p.alarm();
        let record = CommandRecord {
            operator: p.operator.clone(),
            action: Some(Action::Force),
            alarm: p.transition.clone(),
            nonce: p.nonce.clone(),
            accepted: false,
            verified: true,
            detail: clip(&format!("failed: {why}"), 4 * RECORD_FIELD_BYTES),
            stage: Stage::Result,
            source: String::new(),
            count: 1,
            digest: p.digest.clone(),
        };
        self.record(record).await;
        let step = self.engine.on_system(&alarm, Some(&why), now);
        self.dispatch(now, Input::System, step, 0).await;
        if let Some(reply) = reply {
            let _ = reply.send(CommandOutcome::new(false, format!("failed: {why}")));
        }
    }

    /// Ends a force: its result row, its overdue alarm cleared, the
    /// operator answered if still waiting.
    async fn settle(&mut self, p: Pending, now: u64, detail: &str) {
        let accepted = !p.overdue && p.reply.is_some();
        let record = CommandRecord {
            operator: p.operator.clone(),
            action: Some(Action::Force),
            alarm: p.transition.clone(),
            nonce: p.nonce.clone(),
            accepted,
            verified: true,
            detail: clip(detail, 4 * RECORD_FIELD_BYTES),
            // An overdue force had its result; this is what came after.
            stage: if p.overdue {
                Stage::Check
            } else {
                Stage::Result
            },
            source: String::new(),
            count: 1,
            digest: p.digest.clone(),
        };
        self.record(record).await;
        if p.overdue {
            let step = self.engine.on_system(&p.alarm(), None, now);
            self.dispatch(now, Input::System, step, 0).await;
        }
        if let Some(reply) = p.reply {
            let _ = reply.send(CommandOutcome::new(
                accepted,
                format!("{} forced: {detail}", p.transition),
            ));
        }
    }
}

impl ForceSet {
    /// The stuck alarm id of step `r`.
    fn sfc_alarm(&self, r: cellwatch_models::sfc::StepRef) -> String {
        format!(
            "{}-{}-{}",
            self.id,
            self.sfc.charts[r.chart].name,
            self.sfc.step(r).name
        )
    }
}
