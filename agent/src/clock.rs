//! Wall-clock time for the agent: milliseconds since the Unix epoch, the
//! unit the models take, and RFC 3339 text for payloads; and the calling
//! thread's CPU time, for what the agent measures of its own work.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Now, in ms since the Unix epoch.
pub fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// The calling thread's CPU time, ns (0 where the clock cannot be read).
pub fn thread_cpu_ns() -> u64 {
    use nix::time::{clock_gettime, ClockId};
    clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(0, |t| {
        u64::try_from(t.tv_sec()).unwrap_or(0) * 1_000_000_000
            + u64::try_from(t.tv_nsec()).unwrap_or(0)
    })
}

/// `ms` since the epoch as RFC 3339 UTC with milliseconds.
pub fn rfc3339(ms: u64) -> String {
    humantime::format_rfc3339_millis(UNIX_EPOCH + Duration::from_millis(ms)).to_string()
}

/// A text that is neither a time nor a duration back from now (the text).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("'{0}' is neither a time (2026-11-21T10:00:00Z) nor a duration back from now (1h, 30m)")]
pub struct NotATime(pub String);

/// Parses RFC 3339 (`2026-11-21T10:00:00Z`) or a duration back from now
/// (`1h`, `30m`) into ms since the epoch.
///
/// # Errors
/// Neither form.
pub fn parse_time(text: &str, now: u64) -> Result<u64, NotATime> {
    if let Ok(d) = humantime::parse_duration(text) {
        return Ok(now.saturating_sub(d.as_millis() as u64));
    }
    humantime::parse_rfc3339_weak(text)
        .map(|t| {
            t.duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_millis() as u64)
        })
        .map_err(|_| NotATime(text.into()))
}

/// Where an agent's parts read the time: the system clock, or a clock a
/// test sets (virtual time: a simulated day in seconds).
#[derive(Debug, Clone, Default)]
pub struct Clock(Option<std::sync::Arc<tokio::sync::watch::Sender<u64>>>);

impl Clock {
    /// The system clock.
    pub fn system() -> Clock {
        Clock(None)
    }

    /// A clock standing at `ms` until [`Clock::set`] moves it.
    pub fn manual(ms: u64) -> Clock {
        Clock(Some(std::sync::Arc::new(tokio::sync::watch::Sender::new(
            ms,
        ))))
    }

    /// Moves a manual clock to `ms` (never backwards), waking whoever
    /// waits on its [`Moves`]; the system clock ignores it.
    pub fn set(&self, ms: u64) {
        if let Some(t) = &self.0 {
            t.send_if_modified(|now| {
                let moved = ms > *now;
                if moved {
                    *now = ms;
                }
                moved
            });
        }
    }

    /// Now, in ms since the Unix epoch.
    pub fn now_ms(&self) -> u64 {
        match &self.0 {
            None => now_ms(),
            Some(t) => *t.borrow(),
        }
    }

    /// The clock's moves from now on, for a part that sleeps to a deadline
    /// to look at the time again when a test moves it.
    pub fn moves(&self) -> Moves {
        Moves(self.0.as_ref().map(|t| t.subscribe()))
    }
}

/// The moves of a [`Clock`] (see [`Clock::moves`]).
#[derive(Debug)]
pub struct Moves(Option<tokio::sync::watch::Receiver<u64>>);

impl Moves {
    /// Completes when a manual clock has moved since the moves were taken
    /// or this last completed; never for the system clock (which moves on
    /// its own: a sleep sees it).
    pub async fn moved(&mut self) {
        if let Some(rx) = &mut self.0 {
            if rx.changed().await.is_ok() {
                return;
            }
            // The clock is gone: it will not move again.
            self.0 = None;
        }
        std::future::pending().await
    }
}

/// A warning that may recur as fast as the network sends its cause, said
/// at most once per period with how many times it happened since it was
/// last said: a log that stays readable and bounded on disk.
#[derive(Debug)]
pub struct Every {
    period: std::time::Duration,
    said: Option<std::time::Instant>,
    unsaid: u64,
}

impl Every {
    /// Said at most once per `period`.
    pub const fn new(period: std::time::Duration) -> Every {
        Every {
            period,
            said: None,
            unsaid: 0,
        }
    }

    /// It happened `at`: `Some(n)` if it is to be said now, `n` the times it
    /// happened since it was last said (this one included); `None` to keep
    /// quiet.
    pub fn happened(&mut self, at: std::time::Instant) -> Option<u64> {
        self.unsaid += 1;
        if self
            .said
            .is_some_and(|said| at.saturating_duration_since(said) < self.period)
        {
            return None;
        }
        self.said = Some(at);
        Some(std::mem::take(&mut self.unsaid))
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use super::{Clock, Every};

    #[test]
    fn a_recurring_warning_is_said_once_a_period_with_how_often_it_happened() {
        let mut every = Every::new(Duration::from_secs(60));
        let t = Instant::now();
        assert_eq!(every.happened(t), Some(1));
        for s in 1..60 {
            assert_eq!(every.happened(t + Duration::from_secs(s)), None);
        }
        assert_eq!(every.happened(t + Duration::from_secs(60)), Some(60));
        assert_eq!(every.happened(t + Duration::from_secs(61)), None);
        assert_eq!(every.happened(t + Duration::from_secs(500)), Some(2));
    }

    #[tokio::test]
    async fn a_manual_clock_wakes_its_watchers_when_it_moves_forward() {
        let clock = Clock::manual(1_000);
        let mut moves = clock.moves();
        {
            let mut moved = std::pin::pin!(moves.moved());
            // Set to the same time or back: no move.
            clock.set(1_000);
            clock.set(500);
            assert_eq!(clock.now_ms(), 1_000);
            assert!(futures_util::poll!(moved.as_mut()).is_pending());
            clock.set(2_000);
            assert!(futures_util::poll!(moved.as_mut()).is_ready());
            assert_eq!(clock.now_ms(), 2_000);
        }
        // Seen once; the next move (by any of its clones) wakes again.
        let mut moved = std::pin::pin!(moves.moved());
        assert!(futures_util::poll!(moved.as_mut()).is_pending());
        clock.clone().set(2_001);
        assert!(futures_util::poll!(moved.as_mut()).is_ready());
    }

    #[tokio::test]
    async fn the_system_clock_never_says_it_moved() {
        let mut moves = Clock::system().moves();
        let moved = std::pin::pin!(moves.moved());
        assert!(futures_util::poll!(moved).is_pending());
    }
}
