//! Time in the engine: findings waiting out their on- and off-delays
//! (ISA-18.2), each counted by the clock and in source time and never the
//! one against the other; the time an alarm is stamped with (the source's,
//! when it is trusted); the next deadline the agent wakes for; and time
//! passing (`advance`: timers fire, delays run out, the `tag-quality` text
//! held back is said, shelves expire, recordings end). What a finding
//! does once its delay is over is `announce.rs`'s.

use super::{uncertain_trigger, CellEngine, EngineEvent, EngineStep, Finding, QUALITY_UPDATE_MS};
use crate::alarm::Transition;

impl CellEngine {
    /// Announces the delayed findings whose delay ended by `at`: by the
    /// clock (`source` false) or in source time (`source` true).
    pub(super) fn run_out(&mut self, at: u64, source: bool, now: u64, step: &mut EngineStep) {
        let due: Vec<String> = self
            .pending
            .iter()
            .filter(|(id, (by_clock, by_source, f))| {
                let (on, off) = self.delays.get(*id).copied().unwrap_or_default();
                let since = if source { *by_source } else { *by_clock };
                at >= since.saturating_add(if f.active { on } else { off })
            })
            .map(|(id, _)| id.clone())
            .collect();
        for id in due {
            if let Some((_, by_source, f)) = self.pending.remove(&id) {
                // Ran out between values delivered together: at the source
                // time it ran out, if the source's clock is trusted.
                let stamp = if source {
                    let (on, off) = self.delays.get(&id).copied().unwrap_or_default();
                    self.stamp(
                        by_source.saturating_add(if f.active { on } else { off }),
                        now,
                    )
                } else {
                    now
                };
                self.announce(f, stamp, step);
            }
        }
    }

    /// The earliest time at which [`CellEngine::advance`] has something to
    /// do — a timer or a step supervision running out, a delayed alarm
    /// whose delay ends, a shelf that expires — if any. Costs one look per
    /// check kind, and one per alarm waiting out its delay.
    pub fn next_deadline(&self) -> Option<u64> {
        let sets = self.sets.iter().filter_map(|s| s.next_deadline());
        let delayed = self.pending.iter().map(|(id, (since, _, f))| {
            let (on, off) = self.delays.get(id).copied().unwrap_or_default();
            since.saturating_add(if f.active { on } else { off })
        });
        let quality = self
            .quality_unsaid
            .then(|| self.quality_said.saturating_add(QUALITY_UPDATE_MS));
        let recording = self.recorder.as_ref().and_then(|r| r.next_deadline());
        sets.chain(delayed)
            .chain(quality)
            .chain(self.alarms.next_expiry())
            .chain(recording)
            .chain(self.settling_deadline())
            .min()
    }

    /// Time passed: timers fire.
    pub fn advance(&mut self, now: u64) -> EngineStep {
        let mut findings = Vec::new();
        for set in &mut self.sets {
            set.advance(now, &mut findings);
        }
        let mut step = EngineStep::default();
        for f in findings {
            self.apply(f, now, &mut step);
        }
        // The first values' wait, up.
        self.settle(now, &mut step);
        // Delayed findings whose condition lasted.
        self.run_out(now, false, now, &mut step);
        // The bad tags' text, held back while they kept changing.
        if self.quality_unsaid && now >= self.quality_said.saturating_add(QUALITY_UPDATE_MS) {
            self.quality_unsaid = false;
            self.quality_said = now;
            if self.is_active("tag-quality") && !self.bad.is_empty() {
                let f = self.quality_finding();
                self.apply(f, now, &mut step);
            }
        }
        // Shelves that expired: the alarms are announced again as they are.
        for alarm in self.alarms.expire(now) {
            step.events.push(EngineEvent::Alarm {
                alarm,
                transition: Transition::Unshelved,
                at: now,
            });
        }
        if !step.events.is_empty() {
            self.update_state(now, &mut step);
        }
        if let Some(recorder) = &mut self.recorder {
            recorder.finish_due(now);
        }
        self.collect_observations(&mut step);
        step
    }

    pub(super) fn apply(&mut self, f: Finding, now: u64, step: &mut EngineStep) {
        self.apply_at(f, now, now, step);
    }

    /// [`CellEngine::apply`] of a finding whose condition began at `at`
    /// (source time) and is taken at `now` (the clock): its delay runs from
    /// both, each compared only with its own kind of time.
    pub(super) fn apply_at(&mut self, mut f: Finding, at: u64, now: u64, step: &mut EngineStep) {
        let at = f.at.unwrap_or(at);
        if self.lost.is_some() || self.lost_now.is_some() {
            if let Some(why) = self.uncertain(&f) {
                uncertain_trigger(&mut f, &why);
            }
        }
        if let Some(&(on, off)) = self.delays.get(&f.id) {
            let active = self.alarms.get(&f.id).is_some_and(|a| a.active);
            if f.active == active {
                // Back to what is announced before the delay ran out.
                self.pending.remove(&f.id);
            } else if (if f.active { on } else { off }) > 0 {
                let since = match self.pending.get(&f.id) {
                    Some((by_clock, by_source, p)) if p.active == f.active => {
                        (*by_clock, *by_source)
                    }
                    _ => (now, at),
                };
                self.pending.insert(f.id.clone(), (since.0, since.1, f));
                return;
            }
        }
        let stamp = self.stamp(at, now);
        self.announce(f, stamp, step);
    }

    /// When a change the source sampled at `source` happened, for alarms
    /// judged on it: `source`, if the source's clock is trusted and `source`
    /// is neither ahead of the agent's clock `now` nor further behind it
    /// than the trust allows; otherwise `now`.
    pub(super) fn stamp(&self, source: u64, now: u64) -> u64 {
        if source <= now && now - source <= self.source_trust {
            source
        } else {
            now
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fixture::*;
    use crate::engine::Reading;
    use crate::signal::Signal;

    #[test]
    fn a_flapping_connection_is_one_communication_alarm_its_losses_counted() {
        let mut e = engine().delaying("communication", 0, 10_000);
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let lost = "communication lost: every tag is unknown";
        assert_eq!(
            said(&e.on_connection(false, 1_000).events, "communication"),
            [(Transition::Raised, lost.to_string())]
        );
        // Back, and lost again before the off-delay ran out: the same
        // occurrence, its text counting the losses.
        assert!(said(&e.on_connection(true, 2_000).events, "communication").is_empty());
        assert_eq!(e.next_deadline(), Some(12_000));
        assert_eq!(
            said(&e.on_connection(false, 3_000).events, "communication"),
            [(
                Transition::Updated,
                format!("{lost} (2 losses since it was raised)")
            )]
        );
        assert!(said(&e.on_connection(true, 4_000).events, "communication").is_empty());
        load_normal(&mut e, 4_001);
        assert!(said(&e.advance(13_999).events, "communication").is_empty());
        assert_eq!(
            said(&e.advance(14_000).events, "communication"),
            [(
                Transition::Cleared,
                "communication restored (2 losses since it was raised)".to_string()
            )]
        );
        // The next loss is a new occurrence, counted from one.
        assert_eq!(
            said(&e.on_connection(false, 20_000).events, "communication"),
            [(Transition::Raised, lost.to_string())]
        );
    }

    #[test]
    fn a_flapping_sensor_is_one_tag_quality_alarm_its_text_brought_up_to_date_at_most_every_ten_seconds(
    ) {
        let mut e = engine().delaying("tag-quality", 0, 10_000);
        e.on_connection(true, 1);
        load_normal(&mut e, 2);
        let x006 = e.tag_index(&Signal::new("X0.06")).unwrap();
        let x004 = e.tag_index(&Signal::new("X0.04")).unwrap();
        let step = e.on_reading(x006, Reading::Bad, 1_000, 1_000);
        assert_eq!(step.went_bad, 1);
        assert_eq!(
            said(&step.events, "tag-quality"),
            [(
                Transition::Raised,
                "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06)"
                    .to_string()
            )]
        );
        // Good, bad, good again every 100 ms: nothing said (the clear
        // waits out its off-delay; coming back calls it off).
        for k in 1..=20u64 {
            let at = 1_000 + k * 100;
            let r = if k % 2 == 1 {
                Reading::Good(true)
            } else {
                Reading::Bad
            };
            let step = e.on_reading(x006, r, at, at);
            assert!(
                said(&step.events, "tag-quality").is_empty(),
                "{k}: {step:?}"
            );
        }
        // Another tag goes bad within 10 s of the last text: held back...
        let step = e.on_reading(x004, Reading::Bad, 3_100, 3_100);
        assert!(said(&step.events, "tag-quality").is_empty(), "{step:?}");
        assert_eq!(e.next_deadline(), Some(11_000));
        // ... and said when 10 s have passed, with both tags and the count.
        assert_eq!(
            said(&e.advance(11_000).events, "tag-quality"),
            [(
                Transition::Updated,
                "bad or uncertain quality, checks reading them suspended: X0.06 (x0.06), X0.04 (x0.04) (12 went bad since it was raised)".to_string()
            )]
        );
        // Both good: cleared once the off-delay has run out.
        e.on_reading(x004, Reading::Good(true), 12_000, 12_000);
        let step = e.on_reading(x006, Reading::Good(true), 12_100, 12_100);
        assert!(said(&step.events, "tag-quality").is_empty());
        assert!(said(&e.advance(22_099).events, "tag-quality").is_empty());
        assert_eq!(
            said(&e.advance(22_100).events, "tag-quality"),
            [(
                Transition::Cleared,
                "all tags good (12 went bad since it was raised)".to_string()
            )]
        );
    }
}
