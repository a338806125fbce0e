//! The alarm book: every alarm of a cell, turned from check findings into
//! ISA-18.2 transitions, and the operator's acknowledge and reset.
//!
//! It keeps, incrementally, what the machine state needs (the active fault
//! alarms, newest last) so that no step scans every alarm.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use super::checks::{Declared, Finding};
use crate::alarm::{
    Alarm, AlarmKind, CommandRefused, Consequence, DesignedSuppression, Removal, Shelf, Transition,
};

/// Alarms by id, with the conditions behind them.
#[derive(Debug, Default)]
pub(crate) struct AlarmBook {
    alarms: BTreeMap<String, Alarm>,
    /// Per alarm: whether its condition holds now (a latched alarm can be
    /// active with its condition gone).
    conditions: HashMap<String, bool>,
    /// Active switching and timer alarms, by (raised_at, id): the newest is
    /// the machine's fault.
    faults: BTreeSet<(u64, String)>,
    /// Timed shelves by (until, id), so that expiry is no scan.
    expiries: BTreeSet<(u64, String)>,
    /// The alarms the checks can raise, by id: known before they ever are.
    declared: HashMap<String, Declared>,
    /// Per alarm out of service: the last finding while it was, so that
    /// back in service it is raised if its condition still holds.
    held: HashMap<String, Finding>,
}

/// What applying a finding did.
pub(crate) struct Applied {
    /// The transition, if the alarm changed.
    pub(crate) transition: Option<Transition>,
}

fn is_fault(kind: AlarmKind) -> bool {
    matches!(
        kind,
        AlarmKind::Switching | AlarmKind::Timer | AlarmKind::Step
    )
}

impl AlarmBook {
    /// A book for alarms the checks `declared`.
    pub(crate) fn declaring(declared: impl IntoIterator<Item = Declared>) -> AlarmBook {
        AlarmBook {
            declared: declared.into_iter().map(|d| (d.id.clone(), d)).collect(),
            ..AlarmBook::default()
        }
    }

    /// Whether a check set declared alarm `id`.
    pub(crate) fn is_declared(&self, id: &str) -> bool {
        self.declared.contains_key(id)
    }

    /// The ids of the alarms the checks declared.
    pub(crate) fn declared_ids(&self) -> impl Iterator<Item = &str> {
        self.declared.keys().map(String::as_str)
    }

    pub(crate) fn get(&self, id: &str) -> Option<&Alarm> {
        self.alarms.get(id)
    }

    pub(crate) fn iter(&self) -> impl Iterator<Item = &Alarm> {
        self.alarms.values()
    }

    /// Active fault alarms, newest first.
    pub(crate) fn active_faults(&self) -> impl Iterator<Item = &Alarm> {
        self.faults
            .iter()
            .rev()
            .filter_map(|(_, id)| self.alarms.get(id))
    }

    fn set_active(&mut self, id: &str, active: bool) {
        let Some(a) = self.alarms.get_mut(id) else {
            return;
        };
        if !is_fault(a.kind) {
            a.active = active;
            return;
        }
        let key = (a.raised_at, a.id.clone());
        a.active = active;
        if active {
            self.faults.insert(key);
        } else {
            self.faults.remove(&key);
        }
    }

    /// Applies a check's finding at `now`.
    pub(crate) fn apply(&mut self, f: Finding, now: u64) -> Applied {
        self.conditions.insert(f.id.clone(), f.active);
        if self
            .alarms
            .get(&f.id)
            .is_some_and(|a| a.out_of_service.is_some())
        {
            self.held.insert(f.id.clone(), f);
            return Applied { transition: None };
        }
        let existing = self.alarms.get_mut(&f.id);
        let transition = match (existing, f.active) {
            (Some(a), true) if a.active => {
                a.culprits = f.culprits;
                a.fault_step = f.fault_step;
                a.message = f.message;
                Some(Transition::Updated)
            }
            (Some(a), false) if a.active && !a.latched => {
                a.cleared_at = Some(now);
                a.message = f.message;
                // A one-shot shelf ends with the occurrence it was for.
                if a.shelved.as_ref().is_some_and(|s| s.until.is_none()) {
                    a.shelved = None;
                }
                self.set_active(&f.id, false);
                Some(Transition::Cleared)
            }
            (Some(_), false) | (None, false) => None,
            (_, true) => {
                let alarm = Alarm {
                    id: f.id.clone(),
                    kind: f.kind,
                    severity: f.severity,
                    fault_type: f.fault_type,
                    active: false,
                    acknowledged: false,
                    latched: f.latched,
                    raised_at: now,
                    cleared_at: None,
                    acked_by: None,
                    ack_comment: None,
                    fault_step: f.fault_step,
                    culprits: f.culprits,
                    message: f.message,
                    // A shelf outlives occurrences until it expires.
                    shelved: self.alarms.get(&f.id).and_then(|a| a.shelved.clone()),
                    out_of_service: None,
                    consequence: None,
                    designed: None,
                    guidance: None,
                };
                self.alarms.insert(f.id.clone(), alarm);
                self.set_active(&f.id, true);
                Some(Transition::Raised)
            }
        };
        Applied { transition }
    }

    /// Marks alarm `id`'s occurrence as a consequence.
    pub(crate) fn set_consequence(&mut self, id: &str, c: Consequence) {
        if let Some(a) = self.alarms.get_mut(id) {
            a.consequence = Some(Box::new(c));
        }
    }

    /// Sets (or ends, with `None`) alarm `id`'s designed suppression; the
    /// alarm after it.
    pub(crate) fn set_designed(
        &mut self,
        id: &str,
        designed: Option<Box<DesignedSuppression>>,
    ) -> Option<&Alarm> {
        let a = self.alarms.get_mut(id)?;
        a.designed = designed;
        Some(a)
    }

    /// Gives alarm `id`'s occurrence its guidance.
    pub(crate) fn set_guidance(
        &mut self,
        id: &str,
        guidance: std::sync::Arc<crate::madb::Guidance>,
    ) {
        if let Some(a) = self.alarms.get_mut(id) {
            a.guidance = Some(guidance);
        }
    }

    /// Puts back an alarm as it was before a restart. Its condition is
    /// unknown until the checks say.
    pub(crate) fn restore(&mut self, alarm: Alarm) {
        let id = alarm.id.clone();
        let active = alarm.active;
        if let Some(until) = alarm.shelved.as_ref().and_then(|s| s.until) {
            self.expiries.insert((until, id.clone()));
        }
        self.alarms.insert(
            id.clone(),
            Alarm {
                active: false,
                ..alarm
            },
        );
        self.set_active(&id, active);
    }

    /// An operator shelves alarm `id` until `until` (`None`: one-shot,
    /// until it clears).
    pub(crate) fn shelve(&mut self, id: &str, shelf: Shelf) -> Result<&Alarm, CommandRefused> {
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        if shelf.until.is_none() && !alarm.active {
            return Err(CommandRefused::Shelving {
                id: id.into(),
                what: "shelved",
                why: "a one-shot shelf is for an active alarm".into(),
            });
        }
        if let Some(until) = alarm.shelved.as_ref().and_then(|s| s.until) {
            self.expiries.remove(&(until, id.to_string()));
        }
        if let Some(until) = shelf.until {
            self.expiries.insert((until, id.to_string()));
        }
        alarm.shelved = Some(Box::new(shelf));
        Ok(alarm)
    }

    /// Ends the shelf on alarm `id`.
    pub(crate) fn unshelve(&mut self, id: &str) -> Result<&Alarm, CommandRefused> {
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        let Some(shelf) = alarm.shelved.take() else {
            return Err(CommandRefused::Shelving {
                id: id.into(),
                what: "unshelved",
                why: "it is not shelved".into(),
            });
        };
        if let Some(until) = shelf.until {
            self.expiries.remove(&(until, id.to_string()));
        }
        Ok(alarm)
    }

    /// An operator takes alarm `id` out of service: an active occurrence
    /// ends (no longer annunciated, nothing left to acknowledge), a shelf
    /// on it ends, and it is not raised until it is back in service. An
    /// alarm never raised yet (one the checks declared) gets a record of
    /// its own, normal, `raised_at` the time it was taken out.
    pub(crate) fn take_out_of_service(
        &mut self,
        id: &str,
        removal: Removal,
        now: u64,
    ) -> Result<&Alarm, CommandRefused> {
        if !self.alarms.contains_key(id) {
            let d = self
                .declared
                .get(id)
                .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
            self.alarms.insert(
                id.to_string(),
                Alarm {
                    id: id.to_string(),
                    kind: d.kind,
                    severity: d.severity,
                    fault_type: d.fault_type.clone(),
                    active: false,
                    acknowledged: true,
                    latched: d.latched,
                    raised_at: now,
                    cleared_at: None,
                    acked_by: None,
                    ack_comment: None,
                    fault_step: None,
                    culprits: Vec::new(),
                    message: String::new(),
                    shelved: None,
                    out_of_service: None,
                    consequence: None,
                    designed: None,
                    guidance: None,
                },
            );
        }
        let alarm = &self.alarms[id];
        if alarm.out_of_service.is_some() {
            return Err(CommandRefused::Service {
                id: id.into(),
                why: "is already out of service",
            });
        }
        if let Some(until) = alarm.shelved.as_ref().and_then(|s| s.until) {
            self.expiries.remove(&(until, id.to_string()));
        }
        let was_active = alarm.active;
        if was_active {
            // What it was raised for, should its condition still hold when
            // it is back.
            if self.conditions.get(id).copied().unwrap_or(false) {
                self.held.insert(
                    id.to_string(),
                    Finding {
                        at: None,
                        id: alarm.id.clone(),
                        kind: alarm.kind,
                        severity: alarm.severity,
                        fault_type: alarm.fault_type.clone(),
                        latched: alarm.latched,
                        active: true,
                        fault_step: alarm.fault_step,
                        culprits: alarm.culprits.clone(),
                        message: alarm.message.clone(),
                    },
                );
            }
            self.set_active(id, false);
        }
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        if was_active {
            alarm.cleared_at = Some(now);
        }
        alarm.acknowledged = true;
        alarm.shelved = None;
        alarm.out_of_service = Some(Box::new(removal));
        Ok(alarm)
    }

    /// Puts alarm `id` back in service; the last finding while it was out,
    /// to apply (it raises the alarm if its condition holds).
    pub(crate) fn return_to_service(
        &mut self,
        id: &str,
    ) -> Result<(Alarm, Option<Finding>), CommandRefused> {
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        if alarm.out_of_service.take().is_none() {
            return Err(CommandRefused::Service {
                id: id.into(),
                why: "is not out of service",
            });
        }
        Ok((alarm.clone(), self.held.remove(id)))
    }

    /// When the next shelf expires.
    pub(crate) fn next_expiry(&self) -> Option<u64> {
        self.expiries.first().map(|(until, _)| *until)
    }

    /// Ends the shelves that expire by `now`; the alarms unshelved.
    pub(crate) fn expire(&mut self, now: u64) -> Vec<Alarm> {
        let mut out = Vec::new();
        while let Some((until, id)) = self.expiries.first().cloned() {
            if until > now {
                break;
            }
            self.expiries.pop_first();
            if let Some(a) = self.alarms.get_mut(&id) {
                a.shelved = None;
                out.push(a.clone());
            }
        }
        out
    }

    /// An operator acknowledges alarm `id`, saying `comment` if anything.
    pub(crate) fn acknowledge(
        &mut self,
        id: &str,
        operator: &str,
        comment: Option<&str>,
    ) -> Result<&Alarm, CommandRefused> {
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        if alarm.acknowledged {
            return Err(CommandRefused::NothingToAcknowledge(id.into()));
        }
        alarm.acknowledged = true;
        alarm.acked_by = Some(operator.to_string());
        alarm.ack_comment = comment.map(str::to_string);
        Ok(alarm)
    }

    /// Forgets alarm `id` if it has nothing left to show (cleared,
    /// acknowledged, neither shelved nor out of service) and is no fault:
    /// for alarms whose ids are not known beforehand (the PLC's own), so
    /// that the book holds the ones that matter, not every one ever seen.
    pub(crate) fn forget_if_normal(&mut self, id: &str) {
        let normal = self.alarms.get(id).is_some_and(|a| {
            !a.active
                && a.acknowledged
                && a.shelved.is_none()
                && a.out_of_service.is_none()
                && !is_fault(a.kind)
        });
        if normal {
            self.alarms.remove(id);
            self.conditions.remove(id);
            self.held.remove(id);
        }
    }

    /// An operator resets latched alarm `id`, whose condition must be gone.
    pub(crate) fn reset(
        &mut self,
        id: &str,
        operator: &str,
        now: u64,
    ) -> Result<&Alarm, CommandRefused> {
        let alarm = self
            .alarms
            .get(id)
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
        self.set_active(id, false);
        let alarm = self
            .alarms
            .get_mut(id)
            .ok_or_else(|| CommandRefused::UnknownAlarm(id.into()))?;
        alarm.cleared_at = Some(now);
        if alarm.acked_by.is_none() {
            alarm.acked_by = Some(operator.to_string());
        }
        alarm.acknowledged = true;
        Ok(alarm)
    }
}
