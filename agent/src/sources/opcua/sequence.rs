//! A subscription's publishes in sequence-number order.
//!
//! The server numbers every publish that carries data; a keep-alive
//! carries the number the next one will have. A publish lost on the way
//! (a network cut while it travelled, a session that had to be replaced)
//! shows as a number skipped: the publishes behind it are held, the source
//! asks the server to send the missing ones again (`Republish`, from its
//! retransmission queue), and the held ones follow in order. One the
//! server no longer has is lost for good: said once per run of them, and
//! what follows is delivered.

use std::collections::BTreeMap;

use opcua::types::NotificationMessage;

/// Publishes held behind a missing one, at most: past it, the missing
/// ones are given up as lost (a server that never fills the gap must not
/// hold the cell's data, nor grow without bound).
pub(super) const MAX_HELD: usize = 64;

/// What to do, in order.
#[derive(Debug)]
pub(super) enum Next {
    /// Hand these changes on.
    Deliver(NotificationMessage),
    /// The publishes `from..=to` are lost for good.
    Lost { from: u32, to: u32 },
}

/// The order of one subscription's publishes.
#[derive(Debug, Default)]
pub(super) struct Sequence {
    /// The number expected next; `None` before the first publish.
    next: Option<u32>,
    /// Publishes that came ahead of a missing one.
    held: BTreeMap<u32, NotificationMessage>,
    /// The highest number known to exist (a keep-alive's next number,
    /// minus one, or a held publish's).
    known: Option<u32>,
}

/// `m` carries notifications: a publish numbered for itself, not a
/// keep-alive.
pub(super) fn has_data(m: &NotificationMessage) -> bool {
    m.notification_data.as_ref().is_some_and(|d| !d.is_empty())
}

/// `a` comes after `b` (sequence numbers wrap around after `u32::MAX`).
fn after(a: u32, b: u32) -> bool {
    let d = a.wrapping_sub(b);
    d != 0 && d < u32::MAX / 2
}

/// The number before `n` (0 is never used).
fn pred(n: u32) -> u32 {
    match n.wrapping_sub(1) {
        0 => u32::MAX,
        m => m,
    }
}

/// The number after `n` (0 is never used).
pub(super) fn succ(n: u32) -> u32 {
    match n.wrapping_add(1) {
        0 => 1,
        m => m,
    }
}

impl Sequence {
    /// A publish from the server, data or keep-alive: what to do now.
    pub(super) fn arrived(&mut self, m: NotificationMessage, out: &mut Vec<Next>) {
        let seq = m.sequence_number;
        if !has_data(&m) {
            // A keep-alive: the number the next publish will have. A
            // keep-alive still goes through, so that the subscription is
            // seen alive.
            match self.next {
                None => self.next = Some(seq),
                Some(next) if after(seq, next) => self.exists(pred(seq)),
                Some(_) => {}
            }
            out.push(Next::Deliver(m));
            return;
        }
        match self.next {
            Some(next) if after(seq, next) => {
                self.exists(seq);
                self.held.insert(seq, m);
                if self.held.len() > MAX_HELD {
                    // Give up on everything missing before the first held.
                    let first = *self.held.keys().next().expect("held");
                    out.push(Next::Lost {
                        from: next,
                        to: pred(first),
                    });
                    self.next = Some(first);
                    self.drain(out);
                }
            }
            // Had already: a republish of what came after all.
            Some(next) if after(next, seq) => {}
            _ => {
                self.next = Some(succ(seq));
                out.push(Next::Deliver(m));
                self.drain(out);
            }
        }
    }

    /// The server says publish `seq` is gone: the run from the next
    /// expected number to `seq` is lost, and what was held behind it
    /// follows.
    pub(super) fn gone(&mut self, seq: u32, out: &mut Vec<Next>) {
        let Some(next) = self.next else { return };
        if after(next, seq) {
            return;
        }
        out.push(Next::Lost {
            from: next,
            to: seq,
        });
        self.next = Some(succ(seq));
        self.drain(out);
    }

    /// The first number missing, if one is: the next expected, while a
    /// later one is known to exist.
    pub(super) fn missing(&self) -> Option<u32> {
        let next = self.next?;
        let known = self.known?;
        (!after(next, known)).then_some(next)
    }

    /// How many publishes wait behind a missing one.
    #[cfg(test)]
    pub(super) fn held(&self) -> usize {
        self.held.len()
    }

    /// `seq`, if it is missing: known to exist, neither delivered nor
    /// held.
    pub(super) fn missing_from(&self, seq: u32) -> Option<u32> {
        let (next, known) = (self.next?, self.known?);
        let missing = !after(next, seq) && !after(seq, known) && !self.held.contains_key(&seq);
        missing.then_some(seq)
    }

    /// The number expected next, if one has come.
    pub(super) fn next(&self) -> Option<u32> {
        self.next
    }

    /// The server says publishes up to `seq` were sent (a transfer's
    /// available sequence numbers).
    pub(super) fn sent(&mut self, seq: u32) {
        if self.next.is_some_and(|next| !after(next, seq)) {
            self.exists(seq);
        }
    }

    /// Everything held is handed on, the missing before it given up: the
    /// subscription is gone, or replaced.
    pub(super) fn give_up(&mut self, out: &mut Vec<Next>) {
        if let Some(missing) = self.missing() {
            let to = self
                .held
                .keys()
                .next()
                .map_or(self.known.unwrap_or(missing), |&k| pred(k));
            self.gone(to, out);
        }
        self.next = None;
        self.known = None;
        out.extend(
            std::mem::take(&mut self.held)
                .into_values()
                .map(Next::Deliver),
        );
    }

    /// Publish `seq` was sent by the server.
    fn exists(&mut self, seq: u32) {
        if self.known.is_none_or(|k| after(seq, k)) {
            self.known = Some(seq);
        }
    }

    fn drain(&mut self, out: &mut Vec<Next>) {
        while let Some(next) = self.next {
            let Some(m) = self.held.remove(&next) else {
                break;
            };
            self.next = Some(succ(next));
            out.push(Next::Deliver(m));
        }
        // Nothing known beyond what was delivered: forgotten, so that a
        // number far behind never looks ahead after a wrap.
        if let (Some(next), Some(known)) = (self.next, self.known) {
            if after(next, known) {
                self.known = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::types::{DataChangeNotification, DateTime, ExtensionObject};

    fn data(seq: u32) -> NotificationMessage {
        NotificationMessage {
            sequence_number: seq,
            publish_time: DateTime::now(),
            notification_data: Some(vec![ExtensionObject::from_message(
                DataChangeNotification {
                    monitored_items: None,
                    diagnostic_infos: None,
                },
            )]),
        }
    }

    fn keep_alive(next: u32) -> NotificationMessage {
        NotificationMessage {
            sequence_number: next,
            publish_time: DateTime::now(),
            notification_data: None,
        }
    }

    fn seen(out: &[Next]) -> Vec<String> {
        out.iter()
            .map(|n| match n {
                Next::Deliver(m) if has_data(m) => format!("{}", m.sequence_number),
                Next::Deliver(m) => format!("ka{}", m.sequence_number),
                Next::Lost { from, to } => format!("lost {from}-{to}"),
            })
            .collect()
    }

    #[test]
    fn in_order_publishes_pass_straight_through() {
        let mut s = Sequence::default();
        let mut out = Vec::new();
        for n in 1..=3 {
            s.arrived(data(n), &mut out);
        }
        s.arrived(keep_alive(4), &mut out);
        assert_eq!(seen(&out), ["1", "2", "3", "ka4"]);
        assert_eq!(s.missing(), None);
    }

    #[test]
    fn a_publish_ahead_of_a_missing_one_waits_for_its_republish() {
        let mut s = Sequence::default();
        let mut out = Vec::new();
        s.arrived(data(1), &mut out);
        s.arrived(data(4), &mut out);
        s.arrived(data(5), &mut out);
        assert_eq!(seen(&out), ["1"]);
        assert_eq!(s.missing(), Some(2));
        // Republished, then the server no longer has 3.
        s.arrived(data(2), &mut out);
        assert_eq!(s.missing(), Some(3));
        s.gone(3, &mut out);
        assert_eq!(seen(&out), ["1", "2", "lost 3-3", "4", "5"]);
        assert_eq!(s.missing(), None);
        // A late duplicate is dropped.
        s.arrived(data(4), &mut out);
        assert_eq!(out.len(), 5);
    }

    #[test]
    fn a_keep_alive_that_skips_numbers_asks_for_them() {
        let mut s = Sequence::default();
        let mut out = Vec::new();
        s.arrived(data(7), &mut out);
        s.arrived(keep_alive(10), &mut out);
        assert_eq!(s.missing(), Some(8));
        s.arrived(data(8), &mut out);
        s.arrived(data(9), &mut out);
        assert_eq!(s.missing(), None);
        assert_eq!(seen(&out), ["7", "ka10", "8", "9"]);
    }

    #[test]
    fn held_publishes_are_bounded_and_then_given_up_on() {
        let mut s = Sequence::default();
        let mut out = Vec::new();
        s.arrived(data(1), &mut out);
        for n in 3..3 + MAX_HELD as u32 + 1 {
            s.arrived(data(n), &mut out);
        }
        assert_eq!(s.held(), 0);
        assert_eq!(seen(&out)[..3], ["1", "lost 2-2", "3"]);
        assert_eq!(out.len(), 2 + MAX_HELD + 1);
    }

    #[test]
    fn giving_up_delivers_what_was_held_after_saying_the_loss() {
        let mut s = Sequence::default();
        let mut out = Vec::new();
        s.arrived(data(1), &mut out);
        s.arrived(data(5), &mut out);
        s.give_up(&mut out);
        assert_eq!(seen(&out), ["1", "lost 2-4", "5"]);
        // A new subscription starts its own numbers.
        s.arrived(data(1), &mut out);
        assert_eq!(seen(&out).last().unwrap(), "1");
    }

    #[test]
    fn numbers_wrap_around_without_a_gap() {
        let mut s = Sequence::default();
        let mut out = Vec::new();
        s.arrived(data(u32::MAX), &mut out);
        s.arrived(data(1), &mut out);
        assert_eq!(seen(&out), [u32::MAX.to_string(), "1".into()]);
        assert_eq!(s.missing(), None);
    }
}
