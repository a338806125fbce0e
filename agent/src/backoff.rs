//! Exponential backoff: the wait before the next try doubles from a first
//! wait up to a cap, and starts over once a try succeeds. Every retry of
//! the agent (connecting to a PLC, opening the `@` bus, reading a server's
//! namespaces, subscribing, creating a failed item again, pushing to an
//! Alertmanager) waits by one.

use std::time::Duration;

/// The waits of one thing tried again and again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Backoff {
    first: Duration,
    cap: Duration,
    next: Duration,
}

impl Backoff {
    /// Waits from `first`, doubling up to `cap`.
    pub(crate) const fn new(first: Duration, cap: Duration) -> Backoff {
        Backoff {
            first,
            cap,
            next: first,
        }
    }

    /// The wait before the next try: the one after it is doubled, up to
    /// the cap.
    pub(crate) fn next_wait(&mut self) -> Duration {
        let wait = self.next;
        self.next = self.next.saturating_mul(2).min(self.cap);
        wait
    }

    /// The wait before the next try, without counting a try.
    pub(crate) fn peek(&self) -> Duration {
        self.next
    }

    /// A try succeeded: the next failure waits the first wait again.
    pub(crate) fn reset(&mut self) {
        self.next = self.first;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_double_up_to_the_cap_and_start_over_after_a_success() {
        let mut b = Backoff::new(Duration::from_millis(250), Duration::from_secs(1));
        let waits: Vec<u128> = (0..5).map(|_| b.next_wait().as_millis()).collect();
        assert_eq!(waits, [250, 500, 1000, 1000, 1000]);
        b.reset();
        assert_eq!(b.peek(), Duration::from_millis(250));
        assert_eq!(b.next_wait(), Duration::from_millis(250));
    }
}
