//! The `opcua-overflow` alarm: changes the server dropped from its full
//! queues, said as one occurrence while they go on.

use std::collections::BTreeSet;

use super::Names;

/// The `opcua-overflow` alarm as ISA-18.2 would have it: one occurrence
/// while changes keep being lost — raised at the first loss, its text
/// (tags, count) brought up to date at most every [`OVERFLOW_UPDATE`],
/// cleared once `clear_after` has passed without a loss — never a raise
/// and a clear per publish.
pub(super) struct Overflow {
    clear_after: std::time::Duration,
    /// Tags that lost changes since the alarm was raised.
    tags: BTreeSet<usize>,
    /// Values flagged as following a loss since then (each: one change
    /// lost or more).
    lost: u64,
    /// The last loss.
    last: Option<std::time::Instant>,
    /// When the alarm was last said (`None`: not raised).
    pub(super) said: Option<std::time::Instant>,
    /// Losses since it was last said.
    unsaid: bool,
}

/// How often a raised `opcua-overflow` alarm's text is brought up to date.
const OVERFLOW_UPDATE: std::time::Duration = std::time::Duration::from_secs(10);

impl Overflow {
    pub(super) fn new(clear_after: std::time::Duration) -> Overflow {
        Overflow {
            clear_after,
            tags: BTreeSet::new(),
            lost: 0,
            last: None,
            said: None,
            unsaid: false,
        }
    }

    /// A publish (or keep-alive) at `now` in which `tags` lost `lost`
    /// changes: whether the alarm is to be said again (raised, brought up
    /// to date, cleared).
    pub(super) fn publish(
        &mut self,
        tags: &BTreeSet<usize>,
        lost: u64,
        now: std::time::Instant,
    ) -> bool {
        if lost > 0 {
            self.tags.extend(tags);
            self.lost += lost;
            self.last = Some(now);
            self.unsaid = true;
        }
        match (self.said, self.last) {
            (None, Some(_)) if self.unsaid => true,
            (Some(_), Some(last)) if self.quiet_since(last, now) => true,
            (Some(said), _) => self.unsaid && now.duration_since(said) >= OVERFLOW_UPDATE,
            _ => false,
        }
    }

    /// Whether `clear_after` has passed since the loss at `last`, counted
    /// from a later publish than that loss's.
    fn quiet_since(&self, last: std::time::Instant, now: std::time::Instant) -> bool {
        now > last && now.duration_since(last) >= self.clear_after
    }

    /// The alarm as it stands now, and it is said: raised with the tags
    /// and count, or cleared (and forgotten) once no change was lost for
    /// `clear_after`.
    pub(super) fn say(
        &mut self,
        names: &Names,
        queue_size: u32,
        now: std::time::Instant,
    ) -> Option<String> {
        let over = self.last.is_none_or(|last| self.quiet_since(last, now));
        if over {
            *self = Overflow::new(self.clear_after);
            return None;
        }
        self.said = Some(now);
        self.unsaid = false;
        let mut shown: Vec<&str> = self.tags.iter().take(5).map(|&t| &names[t]).collect();
        if self.tags.len() > shown.len() {
            shown.push("...");
        }
        Some(format!(
            "changes lost in the server's queue (queue size {queue_size}) for {} ({} tag{}, {} loss{} so far): raise opcua.queue_size or sample less often",
            shown.join(", "),
            self.tags.len(),
            if self.tags.len() == 1 { "" } else { "s" },
            self.lost,
            if self.lost == 1 { "" } else { "es" },
        ))
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use super::*;

    #[test]
    fn losses_publish_after_publish_are_one_occurrence_cleared_after_a_quiet_while() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut o = Overflow::new(Duration::from_secs(10));
        let tag: BTreeSet<usize> = [3].into();
        let none = BTreeSet::new();
        // Nothing lost: nothing to say.
        assert!(!o.publish(&none, 0, at(0)));
        // The first loss raises.
        assert!(o.publish(&tag, 1, at(500)));
        o.said = Some(at(500));
        o.unsaid = false;
        // Publishes with and without losses within 10 s: nothing said
        // (no clear, no raise, no update before 10 s).
        for k in 1..19u64 {
            let lost = k % 2;
            assert!(!o.publish(&tag, lost, at(500 + k * 500)), "publish {k}");
        }
        // An update of the text at most every 10 s while losses go on.
        assert!(o.publish(&tag, 1, at(10_500)));
        o.said = Some(at(10_500));
        o.unsaid = false;
        // Quiet for 10 s after the last loss: the clear.
        assert!(!o.publish(&none, 0, at(20_499)));
        assert!(o.publish(&none, 0, at(20_500)));
        // With 0, the first later publish without a loss clears; never the
        // publish of the loss itself.
        let mut o = Overflow::new(Duration::ZERO);
        assert!(o.publish(&tag, 1, at(0)));
        o.said = Some(at(0));
        o.unsaid = false;
        assert!(!o.publish(&tag, 1, at(0)));
        assert!(o.publish(&none, 0, at(1)));
    }
}
