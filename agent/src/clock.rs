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
pub struct Clock(Option<std::sync::Arc<std::sync::atomic::AtomicU64>>);

impl Clock {
    /// The system clock.
    pub fn system() -> Clock {
        Clock(None)
    }

    /// A clock standing at `ms` until [`Clock::set`] moves it.
    pub fn manual(ms: u64) -> Clock {
        Clock(Some(std::sync::Arc::new(ms.into())))
    }

    /// Moves a manual clock to `ms` (never backwards); the system clock
    /// ignores it.
    pub fn set(&self, ms: u64) {
        if let Some(t) = &self.0 {
            t.fetch_max(ms, std::sync::atomic::Ordering::SeqCst);
        }
    }

    /// Now, in ms since the Unix epoch.
    pub fn now_ms(&self) -> u64 {
        match &self.0 {
            None => now_ms(),
            Some(t) => t.load(std::sync::atomic::Ordering::SeqCst),
        }
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

    use super::Every;

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
}
