//! Each monitored item's standing on the server: the id the server gave
//! it, what it last said, and whether it must be created again. Shared by
//! the notification callback, which hears every item, and the supervisor
//! (`tend`), which creates failed items again with backoff and verifies
//! the others.
//!
//! A node can go away under a subscription (a PLC download that recreates
//! a data block, a server whose configuration changed) and come back. A
//! server that says so sends `BadNodeIdUnknown` (or `BadNodeIdInvalid`)
//! for the item; one that has no value for it sends `GoodNoData` and then
//! may send nothing more. Such an item is created again, 1 s after, then
//! 2 s, 4 s… at most [`LAST_RETRY`] apart, until the server takes it and it
//! says a value.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use opcua::types::{DataValue, StatusCode, Variant};

use crate::backoff::Backoff;

/// The first wait before a failed item is created again.
pub(super) const FIRST_RETRY: Duration = Duration::from_secs(1);
/// The longest wait between two attempts.
pub(super) const LAST_RETRY: Duration = Duration::from_secs(30);

/// The monitored items of one subscription, by node (client handle
/// `i + 1`): twenty bytes a node.
#[derive(Debug)]
pub(super) struct Items {
    /// The server's id of node `i`'s item, 0 while it has none.
    ids: Vec<u32>,
    /// What node `i`'s item last said.
    said: Vec<Said>,
    /// The items to create again, by node.
    failed: BTreeMap<u32, Retry>,
}

/// What an item last said, and how many times it spoke (wrapping).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) struct Said {
    pub(super) value: Print,
    pub(super) spoke: u32,
}

/// A value as the verification compares it: a number as itself (so that a
/// deadband can be allowed for), anything else hashed, with the code of its
/// status (not the info bits, such as a queue overflow).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) struct Print {
    /// A number's `f64` bits, or a hash of the value.
    bits: u64,
    /// The status code's upper half; bit 0 set when `bits` is a number.
    code: u32,
}

impl Print {
    /// The number it is, if it is one.
    fn number(self) -> Option<f64> {
        (self.code & 1 == 1).then(|| f64::from_bits(self.bits))
    }

    /// Whether `self` and `other` differ by more than `deadband` (an
    /// absolute one; none when `None`).
    pub(super) fn differs(self, other: Print, deadband: Option<f64>) -> bool {
        match (deadband, self.number(), other.number()) {
            (Some(d), Some(a), Some(b)) if self.code == other.code => (a - b).abs() > d,
            _ => self != other,
        }
    }
}

/// A failed item: why, and when it is next created again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Retry {
    /// What the server said.
    pub(super) status: StatusCode,
    /// When it is created again; `None` once created, until it says a
    /// value (or fails again).
    pub(super) due: Option<Instant>,
    /// The waits before the attempts after this one.
    pub(super) backoff: Backoff,
}

/// What an item's value says of the item.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Standing {
    /// A value, as usual.
    Value,
    /// The node is gone, or the server has no value for it: the item is
    /// created again.
    Failed,
}

impl Items {
    /// `nodes` items, none created yet.
    pub(super) fn new(nodes: usize) -> Items {
        Items {
            ids: vec![0; nodes],
            said: vec![Said::default(); nodes],
            failed: BTreeMap::new(),
        }
    }

    /// The server created node `i`'s item with `id`; the id it replaces,
    /// if any.
    pub(super) fn created(&mut self, i: usize, id: u32) -> Option<u32> {
        let old = std::mem::replace(self.ids.get_mut(i)?, id);
        if let Some(r) = self.failed.get_mut(&(i as u32)) {
            r.due = None;
        }
        (old != 0 && old != id).then_some(old)
    }

    /// Node `i`'s item failed with `status` at `now`: created again after
    /// its backoff. An item already waiting keeps its time.
    pub(super) fn fail(&mut self, i: usize, status: StatusCode, now: Instant) {
        if i >= self.ids.len() {
            return;
        }
        let r = self.failed.entry(i as u32).or_insert(Retry {
            status,
            due: None,
            backoff: Backoff::new(FIRST_RETRY, LAST_RETRY),
        });
        r.status = status;
        if r.due.is_none() {
            r.due = Some(now + r.backoff.next_wait());
        }
    }

    /// Node `i`'s item is to be created again at once (it went deaf: the
    /// server no longer tells it what its node holds).
    pub(super) fn renew(&mut self, i: usize, now: Instant) {
        if i < self.ids.len() {
            let r = self.failed.entry(i as u32).or_insert(Retry {
                status: StatusCode::Good,
                due: None,
                backoff: Backoff::new(FIRST_RETRY, LAST_RETRY),
            });
            r.due = Some(now);
        }
    }

    /// Node `i`'s item said `value`. The hot path: one fingerprint and
    /// two stores, and a look-up only while some item is failed.
    pub(super) fn heard(&mut self, i: usize, value: &DataValue) -> Standing {
        let Some(said) = self.said.get_mut(i) else {
            return Standing::Value;
        };
        *said = Said {
            value: print(value),
            spoke: said.spoke.wrapping_add(1),
        };
        if gone(value) {
            return Standing::Failed;
        }
        if !self.failed.is_empty() {
            self.failed.remove(&(i as u32));
        }
        Standing::Value
    }

    /// What node `i`'s item last said.
    pub(super) fn said(&self, i: usize) -> Option<Said> {
        self.said.get(i).copied()
    }

    /// Whether node `i`'s item is failed.
    pub(super) fn is_failed(&self, i: usize) -> bool {
        self.failed.contains_key(&(i as u32))
    }

    /// The failed items due at `now`, with why they failed: taken, they
    /// are due no more until they fail again.
    pub(super) fn take_due(&mut self, now: Instant) -> Vec<(usize, StatusCode)> {
        let mut due = Vec::new();
        for (&i, r) in &mut self.failed {
            if r.due.is_some_and(|d| d <= now) {
                r.due = None;
                due.push((i as usize, r.status));
            }
        }
        due
    }

    /// When the next failed item is due.
    pub(super) fn next_due(&self) -> Option<Instant> {
        self.failed.values().filter_map(|r| r.due).min()
    }

    /// Node `i`'s retry, if it is failed.
    #[cfg(test)]
    pub(super) fn retry(&self, i: usize) -> Option<Retry> {
        self.failed.get(&(i as u32)).copied()
    }
}

/// The node is gone, or the server has nothing for it.
pub(super) fn gone(value: &DataValue) -> bool {
    match value.status {
        Some(s) if is_gone(s) => true,
        Some(s) if s.is_bad() => false,
        // A good or uncertain status without a value: `GoodNoData`.
        _ => value.value.is_none() || matches!(value.value, Some(Variant::Empty)),
    }
}

/// A status that says the node is not there (any more).
pub(super) fn is_gone(status: StatusCode) -> bool {
    let code = status.bits() & 0xFFFF_0000;
    code == StatusCode::BadNodeIdUnknown.bits() || code == StatusCode::BadNodeIdInvalid.bits()
}

/// How a value is compared ([`Print`]).
pub(super) fn print(value: &DataValue) -> Print {
    let code = value.status.map_or(0, |s| s.bits() & 0xFFFF_0000);
    let number = |x: f64| Print {
        bits: x.to_bits(),
        code: code | 1,
    };
    let hashed = |h: u64| Print {
        bits: h.wrapping_mul(0x9e37_79b9_7f4a_7c15),
        code,
    };
    match &value.value {
        None | Some(Variant::Empty) => hashed(0x5bd1_e995),
        Some(Variant::Boolean(b)) => hashed(1 + u64::from(*b)),
        Some(Variant::SByte(x)) => number(f64::from(*x)),
        Some(Variant::Byte(x)) => number(f64::from(*x)),
        Some(Variant::Int16(x)) => number(f64::from(*x)),
        Some(Variant::UInt16(x)) => number(f64::from(*x)),
        Some(Variant::Int32(x)) => number(f64::from(*x)),
        Some(Variant::UInt32(x)) => number(f64::from(*x)),
        Some(Variant::Int64(x)) => number(*x as f64),
        Some(Variant::UInt64(x)) => number(*x as f64),
        Some(Variant::Float(x)) => number(f64::from(*x)),
        Some(Variant::Double(x)) => number(*x),
        Some(Variant::DateTime(t)) => hashed(t.checked_ticks() as u64),
        Some(Variant::String(s)) => hashed(
            s.value()
                .as_deref()
                .unwrap_or("")
                .bytes()
                .fold(0xcbf2_9ce4_8422_2325, |h, b| {
                    (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
                }),
        ),
        // Other types are not read by cellwatch: their kind only.
        Some(other) => hashed(0x1000 + other.scalar_type_id().map_or(0, |t| t as u64)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value(v: impl Into<Variant>) -> DataValue {
        DataValue::new_now(v)
    }

    fn status(s: StatusCode) -> DataValue {
        let mut v = DataValue::null();
        v.status = Some(s);
        v
    }

    #[test]
    fn a_node_gone_is_created_again_with_a_growing_wait() {
        let t0 = Instant::now();
        let mut items = Items::new(3);
        assert_eq!(items.created(1, 7), None);
        assert_eq!(
            items.heard(1, &status(StatusCode::BadNodeIdUnknown)),
            Standing::Failed
        );
        items.fail(1, StatusCode::BadNodeIdUnknown, t0);
        assert!(items.take_due(t0).is_empty());
        assert_eq!(items.next_due(), Some(t0 + FIRST_RETRY));
        let t1 = t0 + FIRST_RETRY;
        assert_eq!(items.take_due(t1), [(1, StatusCode::BadNodeIdUnknown)]);
        assert_eq!(items.next_due(), None);
        // Refused again: twice the wait, from then.
        items.fail(1, StatusCode::BadNodeIdUnknown, t1);
        // Failing again while waiting does not push the time.
        items.fail(1, StatusCode::BadNodeIdUnknown, t1);
        assert_eq!(items.next_due(), Some(t1 + FIRST_RETRY * 2));
        let mut t = t1 + FIRST_RETRY * 2;
        for _ in 0..10 {
            assert_eq!(items.take_due(t).len(), 1);
            items.fail(1, StatusCode::BadNodeIdUnknown, t);
            t = items.next_due().unwrap();
        }
        // At the cap: the wait after this one is the last retry's too.
        let t = items.next_due().unwrap();
        assert_eq!(items.take_due(t).len(), 1);
        items.fail(1, StatusCode::BadNodeIdUnknown, t);
        assert_eq!(items.next_due(), Some(t + LAST_RETRY));
        // Taken, and a value: no longer failed; the old item is to be
        // deleted.
        assert_eq!(items.created(1, 9), Some(7));
        assert_eq!(items.retry(1).unwrap().due, None);
        assert_eq!(items.heard(1, &value(true)), Standing::Value);
        assert!(!items.is_failed(1));
        assert_eq!(items.created(1, 11), Some(9));
    }

    #[test]
    fn no_data_and_an_invalid_node_fail_a_bad_value_does_not() {
        let mut items = Items::new(1);
        assert_eq!(items.heard(0, &DataValue::null()), Standing::Failed);
        assert_eq!(
            items.heard(0, &status(StatusCode::GoodNoData)),
            Standing::Failed
        );
        assert_eq!(
            items.heard(0, &status(StatusCode::BadNodeIdInvalid)),
            Standing::Failed
        );
        assert_eq!(
            items.heard(0, &status(StatusCode::BadSensorFailure)),
            Standing::Value
        );
        assert_eq!(items.heard(0, &value(1.5f64)), Standing::Value);
        // Out of range: nothing.
        assert_eq!(items.heard(5, &DataValue::null()), Standing::Value);
    }

    #[test]
    fn values_are_told_apart_but_for_overflow_bits_and_within_a_deadband() {
        let a = print(&value(true));
        assert!(a.differs(print(&value(false)), None));
        assert!(print(&value(1.0f64)).differs(print(&value(1.5f64)), None));
        assert!(print(&value("a")).differs(print(&value("b")), None));
        let mut flagged = value(true);
        flagged.status = Some(StatusCode::Good.set_overflow(true));
        assert!(!print(&flagged).differs(a, None));
        assert!(print(&status(StatusCode::BadNodeIdUnknown)).differs(a, None));
        // Within an absolute deadband, a number has not changed.
        let (t80, t81) = (print(&value(80.0f64)), print(&value(81.0f32)));
        assert!(t80.differs(t81, None));
        assert!(!t80.differs(t81, Some(2.0)));
        assert!(t80.differs(print(&value(120i32)), Some(2.0)));
        // A bad status is a change whatever the deadband.
        let mut bad80 = value(80.0f64);
        bad80.status = Some(StatusCode::BadSensorFailure);
        assert!(t80.differs(print(&bad80), Some(2.0)));
        let mut items = Items::new(1);
        items.heard(0, &value(true));
        items.heard(0, &flagged);
        assert_eq!(items.said(0), Some(Said { value: a, spoke: 2 }));
    }

    #[test]
    fn a_deaf_item_is_renewed_at_once() {
        let t0 = Instant::now();
        let mut items = Items::new(2);
        items.renew(0, t0);
        items.renew(9, t0);
        assert_eq!(items.take_due(t0), [(0, StatusCode::Good)]);
    }
}
