//! Refused unauthenticated commands, summarised for the journal.
//!
//! A request refused before a known operator's signature is verified (not
//! JSON, too large, unsigned, unknown operator, bad signature, a control
//! character or a malformed nonce) says nothing about who sent it, and
//! anyone on the bus can send thousands a second. The journal keeps, per
//! source and reason and per minute ([`WINDOW_MS`]), the first such
//! refusal as a row of its own and how many more came as one row when the
//! minute ends: at most two rows per source, reason and minute, whatever
//! the rate. At most [`MAX_SOURCES`] sources are told apart in a minute;
//! the rest count as [`OTHER_SOURCES`]. What the journal does not keep is
//! counted in `cellwatch_requests_refused_total` by the caller.
//!
//! Pure: the time comes in as an argument, nothing is written here.

use std::collections::BTreeMap;

/// How long one summary counts, ms (minutes on the clock).
pub(crate) const WINDOW_MS: u64 = 60_000;
/// Sources told apart in one window; more are counted together.
pub(crate) const MAX_SOURCES: usize = 16;
/// The source of refusals beyond [`MAX_SOURCES`] in a window.
pub(crate) const OTHER_SOURCES: &str = "other";
/// The source of a query that does not say where it comes from.
pub(crate) const UNKNOWN_SOURCE: &str = "unknown";
/// What is kept of a source's name, at most (a Zenoh id is 32 hex digits).
pub(crate) const SOURCE_BYTES: usize = 64;

/// The refusals after the first of one source and reason in a window.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Summary {
    /// Who sent them ([`UNKNOWN_SOURCE`], [`OTHER_SOURCES`] or an id).
    pub source: String,
    /// The reason (`unsigned`, `bad_signature`, …).
    pub reason: &'static str,
    /// How many, after the first (which has a row of its own).
    pub count: u64,
    /// When the window began, ms since the epoch.
    pub window: u64,
}

impl Summary {
    /// The journal's text for it.
    pub(crate) fn detail(&self) -> String {
        let at = |ms: u64| {
            chrono::DateTime::from_timestamp_millis(ms as i64)
                .map(|t| t.format("%H:%M:%SZ").to_string())
                .unwrap_or_default()
        };
        format!(
            "{} more {} refused from {} between {} and {} (the first has a row of its own)",
            self.count,
            self.reason,
            self.source,
            at(self.window),
            at(self.window + WINDOW_MS)
        )
    }
}

/// The current window's counts; bounded by [`MAX_SOURCES`] + 1 sources
/// times the reasons.
#[derive(Debug, Default)]
pub(crate) struct Refusals {
    /// When the current window began, ms.
    window: u64,
    /// Per source and reason, the refusals after the first.
    counts: BTreeMap<(String, &'static str), u64>,
    /// Sources told apart in this window.
    sources: usize,
}

/// What to do with one refusal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Noted {
    /// The source it is journaled under.
    pub source: String,
    /// The first of its source and reason in this window: journal it as a
    /// row of its own (otherwise it is only counted).
    pub first: bool,
    /// Windows that ended before it, to journal first.
    pub ended: Vec<Summary>,
}

impl Refusals {
    /// Notes one refusal for `reason` from `source` at `now` (ms).
    pub(crate) fn note(&mut self, source: &str, reason: &'static str, now: u64) -> Noted {
        let ended = self.ended(now);
        let mut source = crate::operator::clip(source, SOURCE_BYTES);
        if source.is_empty() {
            source = UNKNOWN_SOURCE.into();
        }
        let known = self.counts.keys().any(|(s, _)| *s == source);
        if !known {
            if self.sources >= MAX_SOURCES {
                source = OTHER_SOURCES.into();
            } else {
                self.sources += 1;
            }
        }
        let mut first = false;
        self.counts
            .entry((source.clone(), reason))
            .and_modify(|n| *n += 1)
            .or_insert_with(|| {
                first = true;
                0
            });
        Noted {
            source,
            first,
            ended,
        }
    }

    /// The summaries of a window that has ended by `now` (those with more
    /// than the first refusal); the counts start over.
    pub(crate) fn ended(&mut self, now: u64) -> Vec<Summary> {
        let window = now - now % WINDOW_MS;
        if window == self.window {
            return Vec::new();
        }
        let ended = self.flush();
        self.window = window;
        ended
    }

    /// When (ms) the current window ends with a summary to give (a
    /// refusal counted after the first of its source and reason): the
    /// caller's [`Refusals::ended`] is due then. `None`: nothing to say,
    /// whenever the window ends.
    pub(crate) fn next_deadline(&self) -> Option<u64> {
        self.counts
            .values()
            .any(|&n| n > 0)
            .then(|| self.window.saturating_add(WINDOW_MS))
    }

    /// Every summary so far (the agent stops): the counts start over.
    pub(crate) fn flush(&mut self) -> Vec<Summary> {
        self.sources = 0;
        std::mem::take(&mut self.counts)
            .into_iter()
            .filter(|&(_, count)| count > 0)
            .map(|((source, reason), count)| Summary {
                source,
                reason,
                count,
                window: self.window,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_is_two_rows_per_source_reason_and_minute() {
        let mut r = Refusals::default();
        let t0 = 1_700_000_070_000;
        let mut firsts = 0;
        let mut summaries = Vec::new();
        // 2,000 a second for ten minutes, two reasons.
        for i in 0..1_200_000u64 {
            let reason = if i % 2 == 0 {
                "unsigned"
            } else {
                "bad_signature"
            };
            let noted = r.note("", reason, t0 + i / 2);
            firsts += u64::from(noted.first);
            summaries.extend(noted.ended);
        }
        summaries.extend(r.flush());
        // Ten minutes starting mid-minute touch eleven windows.
        assert_eq!(firsts, 22);
        assert_eq!(summaries.len(), 22);
        let counted: u64 = summaries.iter().map(|s| s.count).sum();
        assert_eq!(counted + firsts, 1_200_000);
        assert!(summaries.iter().all(|s| s.source == UNKNOWN_SOURCE));
    }

    #[test]
    fn sources_beyond_the_cap_count_together() {
        let mut r = Refusals::default();
        let sources: Vec<String> = (0..100).map(|i| format!("{i:032x}")).collect();
        for s in &sources {
            r.note(s, "unsigned", 5_000);
            r.note(s, "unsigned", 5_001);
        }
        let s = r.flush();
        assert_eq!(s.len(), MAX_SOURCES + 1);
        let other = s.iter().find(|s| s.source == OTHER_SOURCES).unwrap();
        // 84 sources' second refusals, and their firsts after the first.
        assert_eq!(other.count, 84 * 2 - 1);
        assert_eq!(
            s[0].detail(),
            format!(
                "1 more unsigned refused from {} between 00:00:00Z and 00:01:00Z (the first has a row of its own)",
                sources[0]
            )
        );
    }

    #[test]
    fn the_end_of_a_minute_with_a_summary_is_a_deadline() {
        let mut r = Refusals::default();
        let t0 = 1_700_000_070_000;
        let minute_end = t0 - t0 % WINDOW_MS + WINDOW_MS;
        // A first refusal alone has its row: nothing to summarise.
        assert!(r.note("a", "unsigned", t0).first);
        assert_eq!(r.next_deadline(), None);
        assert!(!r.note("a", "unsigned", t0 + 1).first);
        assert_eq!(r.next_deadline(), Some(minute_end));
        assert!(r.ended(minute_end - 1).is_empty());
        let ended = r.ended(minute_end);
        assert_eq!(ended.len(), 1);
        assert_eq!(
            (ended[0].count, ended[0].window),
            (1, minute_end - WINDOW_MS)
        );
        assert_eq!(r.next_deadline(), None);
    }
}
