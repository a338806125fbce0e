//! What the engine holds, read back: the cell, its tags and their values,
//! the alarms, the machine state, the connection, the work order and the
//! drift windows, and the values at the last fault for the snapshot
//! service (kept as each tag's first change since the fault, `remember`).
//! Nothing here judges a value.

use super::{CellEngine, FaultValues, MachineState, Order, Tag, Value, WindowPosition};
use crate::alarm::Alarm;
use crate::signal::Signal;

impl CellEngine {
    /// The work order now (item code, target quantity).
    pub fn order(&self) -> &Order {
        &self.order
    }

    /// The cell's id.
    pub fn cell(&self) -> &str {
        &self.cell
    }

    /// The configured tags, in configuration order.
    pub fn tags(&self) -> &[Tag] {
        &self.tags[..self.configured]
    }

    /// The tag with this address.
    pub fn tag_index(&self, address: &Signal) -> Option<usize> {
        self.by_address
            .binary_search_by(|&t| self.tags[t as usize].address.cmp(address))
            .ok()
            .map(|i| self.by_address[i] as usize)
    }

    /// Current boolean values of the configured tags, `None` where unknown
    /// or not a boolean.
    pub fn values(&self) -> &[Option<bool>] {
        &self.values[..self.configured]
    }

    /// Tag `tag`'s current value, whatever its type.
    pub fn value(&self, tag: usize) -> Option<Value> {
        match self.values.get(tag).copied().flatten() {
            Some(b) => Some(Value::Bool(b)),
            None => self.others.get(tag).cloned().flatten(),
        }
    }

    /// Every configured tag's current value.
    pub fn all_values(&self) -> Vec<Option<Value>> {
        (0..self.configured).map(|t| self.value(t)).collect()
    }

    /// How many tags are unknown now.
    pub fn unknown_tags(&self) -> usize {
        self.unknown
    }

    /// Tags whose quality is bad.
    pub fn bad_tags(&self) -> impl Iterator<Item = usize> + '_ {
        self.bad.keys().copied()
    }

    /// Every alarm the engine knows, by id.
    pub fn alarms(&self) -> impl Iterator<Item = &Alarm> {
        self.alarms.iter()
    }

    /// The machine state.
    pub fn state(&self) -> &MachineState {
        &self.state
    }

    /// Whether the PLC connection is up.
    pub fn connected(&self) -> bool {
        self.connected == Some(true)
    }

    /// The values at the last switching, timer, limit or step fault
    /// (costs one look per tag: for the snapshot service).
    pub fn last_fault(&self) -> Option<FaultValues> {
        let mark = self.last_fault.as_ref()?;
        let mut values = self.all_values();
        for &(tag, value) in &mark.undo_bools {
            values[tag as usize] = value.map(Value::Bool);
        }
        for (tag, value) in &mark.undo_others {
            values[*tag as usize] = value.clone();
        }
        Some(FaultValues {
            alarm: mark.alarm.clone(),
            at: mark.at,
            values,
        })
    }

    /// Logs `tag`'s value before it changes, the first time it changes
    /// after the last fault.
    pub(super) fn remember(&mut self, tag: usize) {
        // A comparison contact's tag is not in the snapshot: it follows
        // the numbers it reads.
        if tag >= self.configured {
            return;
        }
        if let Some(mark) = &mut self.last_fault {
            if mark.first_change(tag) {
                match (self.values[tag], &self.others[tag]) {
                    (Some(b), _) => mark.undo_bools.push((tag as u32, Some(b))),
                    (None, None) => mark.undo_bools.push((tag as u32, None)),
                    (None, other) => mark.undo_others.push((tag as u32, other.clone())),
                }
            }
        }
    }

    /// Where each tracked transition's recent durations lie in its window
    /// (timer checks with drift tracking on), in the checks' order.
    pub fn window_positions(&self) -> Vec<WindowPosition> {
        let mut out = Vec::new();
        for set in &self.sets {
            set.window_positions(&mut out);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fixture::*;
    use crate::engine::Reading;
    use crate::value::Num;

    #[test]
    fn the_values_at_a_fault_stay_as_they_were_whatever_changes_after() {
        let mut e = engine();
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        assert_eq!(e.last_fault(), None);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        let at_fault = e.all_values();
        let first = e.last_fault().unwrap();
        assert_eq!((first.alarm.as_str(), first.at), ("ese", 10));
        assert_eq!(first.values, at_fault);
        // Every other tag changes, some twice, one becomes unknown, one
        // sends a number: the values at the fault do not move.
        let n = e.tags().len();
        for t in (0..n).filter(|&t| t != x006) {
            let v = at_fault[t] == Some(Value::Bool(true));
            e.on_reading(t, Reading::Good(!v), 11, 11);
            if t % 2 == 0 {
                e.on_reading(t, Reading::Good(v), 12, 12);
            }
        }
        e.on_reading(0, Reading::Bad, 13, 13);
        e.on_reading(1, Reading::Number(Num::Int(7)), 14, 14);
        assert_ne!(e.all_values(), at_fault);
        assert_eq!(e.last_fault().unwrap(), first);
        // The next fault starts over from the values then.
        e.on_connection(true, 20);
        load_normal(&mut e, 21);
        e.on_reading(x006, Reading::Good(true), 22, 22);
        assert!(
            e.alarms().all(|a| !a.active),
            "{:?}",
            e.alarms().collect::<Vec<_>>()
        );
        e.on_reading(x006, Reading::Good(false), 30, 30);
        let second = e.last_fault().unwrap();
        assert_eq!(second.at, 30);
        assert_eq!(second.values, e.all_values());
        e.on_reading(x006, Reading::Good(true), 31, 31);
        assert_eq!(e.last_fault().unwrap(), second);
    }

    #[test]
    fn a_comparison_changing_after_a_fault_leaves_the_values_at_it_alone() {
        // The running rule reads a comparison: its contact is a tag of its
        // own past the configured ones, set as TEMP crosses 80.
        let temp_tag = Tag {
            name: "temp".into(),
            address: Signal::new("TEMP"),
        };
        let mut e = engine_with(&[temp_tag], "G0.00 * F0.00 * TEMP > 80");
        let temp = e.tags().len() - 1;
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let number = |n| Reading::Number(Num::Float(n));
        e.on_reading(temp, number(70.0), 3, 3);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        e.on_reading(x006, Reading::Good(false), 10, 10);
        let at_fault = e.last_fault().unwrap();
        assert_eq!(at_fault.values.len(), temp + 1);
        // The comparison's contact flips both ways; TEMP itself changes.
        e.on_reading(temp, number(90.0), 11, 11);
        e.on_reading(temp, number(60.0), 12, 12);
        assert_eq!(e.last_fault().unwrap(), at_fault);
        assert_eq!(at_fault.values[temp], Some(Value::Num(Num::Float(70.0))));
    }
}
