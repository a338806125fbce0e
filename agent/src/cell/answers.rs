//! The outcomes of recent verified commands, by nonce: a client that sends
//! the same signed command again (its answer lost on the way, the agent
//! restarted meanwhile) gets the original outcome, not "replayed", and a
//! retry that arrives while the original is still being carried out waits
//! for it. Kept as long as a nonce is remembered ([`Gate::NONCE_WINDOW_MS`]),
//! so memory is bounded by the verified commands of that window; restored
//! from the journal at start.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use tokio::sync::oneshot;

use crate::operator::Gate;
use crate::step::CommandOutcome;

/// Shared between the loop (which begins and looks up) and the tasks that
/// send outcomes once they are durable (which finish).
#[derive(Clone, Default)]
pub struct Answers {
    /// Each nonce's answer and when it was first seen (ms).
    inner: Arc<Mutex<HashMap<String, (u64, Answer)>>>,
}

enum Answer {
    /// Being carried out; these retries wait for its outcome.
    Pending(Vec<oneshot::Sender<CommandOutcome>>),
    /// Answered.
    Done(CommandOutcome),
}

/// What a retry of a known nonce gets.
pub enum Retry {
    /// The original outcome, to send now.
    Now(CommandOutcome),
    /// The original is still under way: the reply was kept and is sent
    /// with its outcome.
    Later,
    /// Not a command this agent remembers answering.
    Unknown(oneshot::Sender<CommandOutcome>),
}

impl Answers {
    fn map(&self) -> std::sync::MutexGuard<'_, HashMap<String, (u64, Answer)>> {
        self.inner
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// A verified command with `nonce` is being carried out at `now`.
    pub fn begin(&self, nonce: &str, now: u64) {
        let mut map = self.map();
        map.retain(|_, (at, _)| at.saturating_add(Gate::NONCE_WINDOW_MS) >= now);
        map.entry(nonce.to_string())
            .or_insert((now, Answer::Pending(Vec::new())));
    }

    /// The command with `nonce` came to `outcome`: kept, and sent to every
    /// retry that waited. Nothing for a nonce not begun.
    pub fn finish(&self, nonce: &str, outcome: &CommandOutcome) {
        let mut map = self.map();
        if let Some((_, answer)) = map.get_mut(nonce) {
            if let Answer::Pending(waiting) = answer {
                for w in waiting.drain(..) {
                    let _ = w.send(outcome.clone());
                }
                *answer = Answer::Done(outcome.clone());
            }
        }
    }

    /// An outcome read back from the journal at start.
    pub fn restore(&self, nonce: String, at: u64, outcome: CommandOutcome) {
        self.map().insert(nonce, (at, Answer::Done(outcome)));
    }

    /// A command with a nonce already used, sent again: its original
    /// outcome, now or once known.
    pub fn retry(&self, nonce: &str, reply: oneshot::Sender<CommandOutcome>) -> Retry {
        let mut map = self.map();
        match map.get_mut(nonce) {
            Some((_, Answer::Done(outcome))) => {
                let _ = reply.send(outcome.clone());
                Retry::Now(outcome.clone())
            }
            Some((_, Answer::Pending(waiting))) => {
                waiting.push(reply);
                Retry::Later
            }
            None => Retry::Unknown(reply),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_retry_gets_the_original_outcome_now_or_when_it_comes() {
        let answers = Answers::default();
        answers.begin("aa", 1_000);
        let (tx, mut rx) = oneshot::channel();
        assert!(matches!(answers.retry("aa", tx), Retry::Later));
        assert!(rx.try_recv().is_err());
        answers.finish("aa", &CommandOutcome::new(true, "ack ese by kim"));
        assert_eq!(rx.try_recv().unwrap().detail, "ack ese by kim");
        let (tx, mut rx) = oneshot::channel();
        assert!(matches!(answers.retry("aa", tx), Retry::Now(_)));
        assert!(rx.try_recv().unwrap().accepted);
        // A later finish (a replay's refusal) does not replace it.
        answers.finish("aa", &CommandOutcome::new(false, "replayed command"));
        let (tx, mut rx) = oneshot::channel();
        answers.retry("aa", tx);
        assert!(rx.try_recv().unwrap().accepted);
        // Unknown nonces, and nonces past the window, are not answered.
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry("bb", tx), Retry::Unknown(_)));
        answers.begin("cc", 1_000 + Gate::NONCE_WINDOW_MS + 1);
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry("aa", tx), Retry::Unknown(_)));
    }
}
