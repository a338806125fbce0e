//! The cell's snapshot, as the `snapshot` service answers it: every tag
//! with its value and quality, the alarms an operator must see, the values
//! at the last fault, the supervised charts, the timed transitions and the
//! current shift's OEE.

use cellwatch_models::alarm::Transition;
use cellwatch_models::engine::Value;

use super::CellLoop;
use crate::clock::rfc3339;
use crate::payload::{
    AlarmPayload, ChartPayload, LastFault, OeePayload, Quality, SnapshotPayload, TagValue,
    SNAPSHOT_SCHEMA,
};
use crate::step::OeeWatch;

impl CellLoop {
    /// Answers snapshots with the OEE `oee` holds.
    #[must_use]
    pub fn showing_oee(mut self, oee: OeeWatch) -> CellLoop {
        self.oee = Some(oee);
        self
    }

    /// The snapshot now.
    pub(super) fn snapshot(&self) -> SnapshotPayload {
        let tags = self.engine.tags();
        let bad: std::collections::HashSet<usize> = self.engine.bad_tags().collect();
        let value = |i: usize, v: Option<Value>, current: bool| TagValue {
            name: tags[i].name.clone(),
            address: tags[i].address.name().to_string(),
            quality: match (&v, current && bad.contains(&i)) {
                (_, true) => Quality::Bad,
                (Some(_), false) => Quality::Good,
                (None, false) => Quality::Unknown,
            },
            value: v.map(|v| crate::payload::json_value(&v)),
        };
        let now = self.clock.now_ms();
        // A contact's value now, by its address (the charts' signals);
        // unknown while its quality is bad.
        let contacts: std::collections::HashMap<&str, Option<bool>> = tags
            .iter()
            .zip(self.engine.all_values())
            .enumerate()
            .map(|(i, (t, v))| {
                let b = match v {
                    Some(Value::Bool(b)) if !bad.contains(&i) => Some(b),
                    _ => None,
                };
                (t.address.name(), b)
            })
            .collect();
        let contact =
            |s: &cellwatch_models::signal::Signal| contacts.get(s.name()).copied().flatten();
        SnapshotPayload {
            schema: SNAPSHOT_SCHEMA.into(),
            cell: self.cell.clone(),
            at: rfc3339(now),
            connected: self.engine.connected(),
            state: self.engine.state().state_name(),
            tags: self
                .engine
                .all_values()
                .into_iter()
                .enumerate()
                .map(|(i, v)| value(i, v, true))
                .collect(),
            alarms: self
                .engine
                .alarms()
                // What needs an operator, and what is kept from them.
                .filter(|a| {
                    a.active || !a.acknowledged || a.shelved.is_some() || a.out_of_service.is_some()
                })
                .map(|a| AlarmPayload::new(&self.cell, a, Transition::Updated, now))
                .collect(),
            last_fault: self.engine.last_fault().map(|f| LastFault {
                alarm: f.alarm.clone(),
                at: rfc3339(f.at),
                values: f
                    .values
                    .iter()
                    .enumerate()
                    .map(|(i, v)| value(i, v.clone(), false))
                    .collect(),
            }),
            charts: self
                .forcing
                .sets
                .iter()
                .flat_map(|s| ChartPayload::of(&s.id, &s.sfc, &s.forcible, &s.comments, &contact))
                .collect(),
            timers: self.timers.payload(),
            oee: self.oee.as_ref().and_then(|w| {
                let now = w.borrow();
                let now = now.as_ref()?;
                Some(OeePayload::new(&now.shift, &now.figures, now.at))
            }),
        }
    }
}
