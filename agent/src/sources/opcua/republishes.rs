//! The bounds on one subscription's `Republish` requests: each missing
//! publish asked for [`TRIES`] times at most, all of them at most
//! [`PER_SECOND`] a second after a burst of [`BURST`], and each kind of
//! answer that fills nothing warned of once a minute with how often.
//!
//! A server may never send a missing publish again, and say so in its
//! own way: `BadMessageNotAvailable` or `BadSequenceNumberUnknown` as the
//! standard asks, an empty message with a good status (Python asyncua), or
//! no answer in time. Whatever it says, the publish is given up as lost
//! after it, the gap said, and the subscription goes on. Pure: time comes
//! in as an argument.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use opcua::types::StatusCode;

use super::sequence::MAX_HELD;
use crate::clock::Every;

/// Requests for one missing publish, at most: one answer that it is not
/// to be had ends its recovery at once; a request that fails (no answer
/// in time, an error) is tried again up to this many times in all.
pub(super) const TRIES: u8 = 3;

/// Requests made at once, at most: a whole run of publishes held behind
/// missing ones asked for without waiting.
pub(super) const BURST: f64 = MAX_HELD as f64;

/// Requests a second, at most, past the burst.
pub(super) const PER_SECOND: f64 = 16.0;

/// How often each kind of answer that filled nothing is warned of.
const WARN_EVERY: Duration = Duration::from_secs(60);

/// Why a `Republish` brought nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Unserved {
    /// The server says it no longer holds the publish
    /// (`BadMessageNotAvailable`, `BadSequenceNumberUnknown`).
    NotAvailable(StatusCode),
    /// The answer carries another publish, or none (an empty message with
    /// a good status): the server does not hold the one asked for.
    Other {
        /// The sequence number the answer carried (0: none).
        carried: u32,
    },
    /// No answer in time, or an error: asked again, [`TRIES`] in all.
    Failed(StatusCode),
}

impl Unserved {
    fn kind(self) -> usize {
        match self {
            Unserved::NotAvailable(_) => 0,
            Unserved::Other { .. } => 1,
            Unserved::Failed(_) => 2,
        }
    }
}

/// Where the `Republish` requests of one subscription stand.
#[derive(Debug)]
pub(super) struct Republishes {
    /// Failed requests for each missing publish still asked for.
    tries: BTreeMap<u32, u8>,
    /// Requests that may be made now (a token bucket of [`BURST`]).
    tokens: f64,
    /// When the tokens were last counted.
    counted: Instant,
    /// Each kind of answer that filled nothing, warned of once a minute.
    unserved: [Every; 3],
}

impl Republishes {
    /// None asked yet, a whole burst allowed.
    pub(super) fn new(now: Instant) -> Republishes {
        Republishes {
            tries: BTreeMap::new(),
            tokens: BURST,
            counted: now,
            unserved: [
                Every::new(WARN_EVERY),
                Every::new(WARN_EVERY),
                Every::new(WARN_EVERY),
            ],
        }
    }

    /// A request is to be made: how long it must wait first (zero: it goes
    /// now). The wait is counted as taken.
    pub(super) fn turn(&mut self, now: Instant) -> Duration {
        let elapsed = now.saturating_duration_since(self.counted).as_secs_f64();
        self.counted = now;
        self.tokens = (self.tokens + elapsed * PER_SECOND).min(BURST) - 1.0;
        if self.tokens >= 0.0 {
            Duration::ZERO
        } else {
            Duration::from_secs_f64(-self.tokens / PER_SECOND)
        }
    }

    /// A request for publish `seq` brought nothing (`why`): whether
    /// `seq` may be asked for again (a failed request, tries left); if not,
    /// it is forgotten, to be given up as lost.
    pub(super) fn unserved(&mut self, seq: u32, why: Unserved) -> bool {
        if let Unserved::Failed(_) = why {
            let tries = self.tries.entry(seq).or_insert(0);
            *tries += 1;
            if *tries < TRIES {
                return true;
            }
        }
        self.tries.remove(&seq);
        // Bounded whatever the server does: numbers never settled (a
        // subscription given up meanwhile) go first.
        while self.tries.len() > MAX_HELD {
            self.tries.pop_first();
        }
        false
    }

    /// Publish `seq` came again: forgotten.
    pub(super) fn served(&mut self, seq: u32) {
        self.tries.remove(&seq);
    }

    /// `why` happened `at`: `Some(n)` if it is to be warned of now, `n`
    /// the times that kind happened since it was last warned of.
    pub(super) fn warn(&mut self, why: Unserved, at: Instant) -> Option<u64> {
        self.unserved[why.kind()].happened(at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burst_goes_at_once_then_the_rate_is_bounded() {
        let start = Instant::now();
        let mut r = Republishes::new(start);
        for _ in 0..MAX_HELD {
            assert_eq!(r.turn(start), Duration::ZERO);
        }
        let wait = r.turn(start);
        assert!(
            (wait.as_secs_f64() - 1.0 / PER_SECOND).abs() < 1e-9,
            "{wait:?}"
        );
        // A second later, a second's worth.
        let later = start + Duration::from_secs(1);
        let mut now_free = 0;
        while r.turn(later).is_zero() {
            now_free += 1;
        }
        assert_eq!(now_free, PER_SECOND as usize - 1);
    }

    #[test]
    fn a_publish_the_server_says_it_lacks_is_given_up_at_the_first_answer() {
        let mut r = Republishes::new(Instant::now());
        let lacks = Unserved::NotAvailable(StatusCode::BadMessageNotAvailable);
        assert!(!r.unserved(7, lacks));
        assert!(!r.unserved(8, Unserved::Other { carried: 0 }));
    }

    #[test]
    fn a_request_that_fails_is_tried_again_a_few_times_only() {
        let mut r = Republishes::new(Instant::now());
        let timeout = Unserved::Failed(StatusCode::BadTimeout);
        let again: Vec<bool> = (0..TRIES).map(|_| r.unserved(7, timeout)).collect();
        assert_eq!(again, [true, true, false]);
        // Forgotten once given up: a number used again starts afresh.
        assert!(r.unserved(7, timeout));
        r.served(7);
        assert!(r.tries.is_empty());
    }

    #[test]
    fn each_kind_of_unserved_answer_is_warned_of_once_a_minute_with_its_count() {
        let start = Instant::now();
        let mut r = Republishes::new(start);
        let other = Unserved::Other { carried: 0 };
        let lacks = Unserved::NotAvailable(StatusCode::BadSequenceNumberUnknown);
        assert_eq!(r.warn(other, start), Some(1));
        assert_eq!(r.warn(lacks, start), Some(1));
        for _ in 0..500 {
            assert_eq!(r.warn(other, start + Duration::from_secs(1)), None);
        }
        assert_eq!(r.warn(other, start + WARN_EVERY), Some(501));
    }
}
