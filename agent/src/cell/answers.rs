//! The outcomes of recent verified commands, by nonce: a client that sends
//! the same signed command again (its answer lost on the way, the agent
//! restarted meanwhile) is told it was a replay and what the first sending
//! came to ([`CommandOutcome::replayed`]), never carried out twice, and a
//! retry that arrives while the original is still being carried out waits
//! for it. Only the same command gets that answer: another command with
//! the same nonce is refused as a replay, with nobody's outcome. Kept as
//! long as a nonce is remembered ([`Gate::NONCE_WINDOW_MS`]), so memory is
//! bounded by the verified commands of that window; restored from the
//! journal at start, each command known by its digest
//! ([`Command::digest`], kept with its rows), so that after a restart too
//! only the same signed command gets its outcome.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use tokio::sync::oneshot;

use crate::journal::SavedOutcome;
use crate::operator::{clip, Command, Gate};
use crate::step::{CommandOutcome, RECORD_FIELD_BYTES};

/// Shared between the loop (which begins and looks up) and the tasks that
/// send outcomes once they are durable (which finish).
#[derive(Clone, Default)]
pub struct Answers {
    /// Each nonce's command, answer and when it was first seen (ms).
    inner: Arc<Mutex<HashMap<String, Entry>>>,
}

struct Entry {
    at: u64,
    command: Sent,
    answer: Answer,
}

/// Which command a nonce was first used by.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Sent {
    /// [`Command::digest`]: the same signed command, however its JSON
    /// was spaced; read back from the journal too.
    Signed([u8; 32]),
    /// Read back from rows journaled before the journal kept digests: its
    /// operator and action, as journaled.
    Journaled {
        /// Who signed it (clipped as journaled).
        operator: String,
        /// What it asked.
        action: String,
    },
}

impl Sent {
    /// The identity of `cmd`.
    pub fn of(cmd: &Command) -> Sent {
        Sent::Signed(cmd.digest())
    }

    /// The identity of a command read back from the journal: its digest,
    /// or, in rows written before digests were kept, its operator and
    /// action.
    pub fn journaled(saved: &SavedOutcome) -> Sent {
        let digest = saved.digest.as_deref().and_then(|d| hex::decode(d).ok());
        match digest.and_then(|d| <[u8; 32]>::try_from(d).ok()) {
            Some(d) => Sent::Signed(d),
            None => Sent::Journaled {
                operator: saved.operator.clone(),
                action: saved.action.clone(),
            },
        }
    }

    fn is(&self, cmd: &Command) -> bool {
        match self {
            Sent::Signed(_) => *self == Sent::of(cmd),
            Sent::Journaled { operator, action } => {
                *operator == clip(&cmd.operator, RECORD_FIELD_BYTES)
                    && action == cmd.action.as_str()
            }
        }
    }
}

enum Answer {
    /// Being carried out; these retries wait for its outcome.
    Pending(Vec<oneshot::Sender<CommandOutcome>>),
    /// Answered.
    Done(CommandOutcome),
}

/// What a retry of a known nonce gets.
pub enum Retry {
    /// Told it is a replay, with the original outcome, now.
    Now(CommandOutcome),
    /// The original is still under way: the reply was kept and is sent
    /// (as a replay) with its outcome.
    Later,
    /// Not a command this agent remembers answering (or another command
    /// with the same nonce).
    Unknown(oneshot::Sender<CommandOutcome>),
}

impl Answers {
    fn map(&self) -> std::sync::MutexGuard<'_, HashMap<String, Entry>> {
        self.inner
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The verified command `cmd` is being carried out at `now`.
    pub fn begin(&self, cmd: &Command, now: u64) {
        let mut map = self.map();
        map.retain(|_, e| e.at.saturating_add(Gate::NONCE_WINDOW_MS) >= now);
        map.entry(cmd.nonce.clone()).or_insert(Entry {
            at: now,
            command: Sent::of(cmd),
            answer: Answer::Pending(Vec::new()),
        });
    }

    /// The command `cmd` came to `outcome`: kept, and sent (as a replay) to
    /// every retry that waited. Nothing for a command not begun.
    pub fn finish(&self, cmd: &Command, outcome: &CommandOutcome) {
        let mut map = self.map();
        if let Some(entry) = map.get_mut(&cmd.nonce).filter(|e| e.command.is(cmd)) {
            if let Answer::Pending(waiting) = &mut entry.answer {
                for w in waiting.drain(..) {
                    let _ = w.send(outcome.replayed());
                }
                entry.answer = Answer::Done(outcome.clone());
            }
        }
    }

    /// The outcomes read back from the journal at start (its recent
    /// verified commands).
    pub fn restored(saved: Vec<SavedOutcome>) -> Answers {
        let answers = Answers::default();
        for s in saved {
            let outcome = match &s.outcome {
                Some((accepted, detail)) => CommandOutcome::new(*accepted, detail.clone()),
                None => CommandOutcome::new(
                    false,
                    "the agent stopped before this command's outcome was known: see its history",
                ),
            };
            let sent = Sent::journaled(&s);
            answers.restore(s.nonce, s.at, sent, outcome);
        }
        answers
    }

    /// An outcome read back from the journal at start.
    pub fn restore(&self, nonce: String, at: u64, command: Sent, outcome: CommandOutcome) {
        self.map().insert(
            nonce,
            Entry {
                at,
                command,
                answer: Answer::Done(outcome),
            },
        );
    }

    /// A command with a nonce already used, sent again: if it is the same
    /// command, told so with its original outcome, now or once known.
    pub fn retry(&self, cmd: &Command, reply: oneshot::Sender<CommandOutcome>) -> Retry {
        let mut map = self.map();
        match map.get_mut(&cmd.nonce).filter(|e| e.command.is(cmd)) {
            Some(Entry {
                answer: Answer::Done(outcome),
                ..
            }) => {
                let replayed = outcome.replayed();
                let _ = reply.send(replayed.clone());
                Retry::Now(replayed)
            }
            Some(Entry {
                answer: Answer::Pending(waiting),
                ..
            }) => {
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
    use crate::operator::Action;

    fn ack(nonce: &str, alarm: &str) -> Command {
        Command {
            action: Action::Ack,
            alarm: alarm.into(),
            tag: None,
            value: None,
            reason: None,
            operator: "kim".into(),
            nonce: nonce.into(),
            issued_at: 1_000,
            signature: "ab".repeat(64),
        }
    }

    #[test]
    fn a_retry_is_told_it_is_a_replay_with_the_original_outcome_now_or_when_it_comes() {
        let answers = Answers::default();
        let aa = ack("aa", "ese");
        answers.begin(&aa, 1_000);
        let (tx, mut rx) = oneshot::channel();
        assert!(matches!(answers.retry(&aa, tx), Retry::Later));
        assert!(rx.try_recv().is_err());
        answers.finish(&aa, &CommandOutcome::new(true, "ack ese by kim"));
        let replayed = rx.try_recv().unwrap();
        assert!(!replayed.accepted);
        assert_eq!(
            replayed.detail,
            "replayed command: sent before (accepted: ack ese by kim); not carried out again"
        );
        let first = replayed.replayed.unwrap();
        assert!(first.accepted);
        assert_eq!(first.detail, "ack ese by kim");
        let (tx, mut rx) = oneshot::channel();
        assert!(matches!(answers.retry(&aa, tx), Retry::Now(_)));
        assert!(rx.try_recv().unwrap().replayed.unwrap().accepted);
        // A later finish (a replay's answer) does not replace it.
        answers.finish(&aa, &CommandOutcome::new(false, "replayed command"));
        let (tx, mut rx) = oneshot::channel();
        answers.retry(&aa, tx);
        assert!(rx.try_recv().unwrap().replayed.unwrap().accepted);
        // Unknown nonces, and nonces past the window, are not answered.
        let (tx, _) = oneshot::channel();
        assert!(matches!(
            answers.retry(&ack("bb", "ese"), tx),
            Retry::Unknown(_)
        ));
        answers.begin(&ack("cc", "ese"), 1_000 + Gate::NONCE_WINDOW_MS + 1);
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry(&aa, tx), Retry::Unknown(_)));
    }

    #[test]
    fn another_command_with_the_same_nonce_gets_no_outcome_and_changes_none() {
        let answers = Answers::default();
        let first = ack("aa", "ese");
        answers.begin(&first, 1_000);
        let other = ack("aa", "csd");
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry(&other, tx), Retry::Unknown(_)));
        // Its refusal does not become the first command's outcome.
        answers.finish(&other, &CommandOutcome::new(false, "replayed command"));
        answers.finish(&first, &CommandOutcome::new(true, "ack ese by kim"));
        let (tx, _) = oneshot::channel();
        let Retry::Now(o) = answers.retry(&first, tx) else {
            panic!("the first command's outcome is kept")
        };
        assert_eq!(o.replayed.unwrap().detail, "ack ese by kim");
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry(&other, tx), Retry::Unknown(_)));
        // Read back from the journal: the same operator's same action only.
        answers.restore(
            "dd".into(),
            1_000,
            Sent::Journaled {
                operator: "kim".into(),
                action: "ack".into(),
            },
            CommandOutcome::new(true, "ack ese by kim"),
        );
        let (tx, _) = oneshot::channel();
        assert!(matches!(
            answers.retry(&ack("dd", "ese"), tx),
            Retry::Now(_)
        ));
        let mut reset = ack("dd", "ese");
        reset.action = Action::Reset;
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry(&reset, tx), Retry::Unknown(_)));
    }

    #[test]
    fn a_journaled_command_is_known_by_its_digest_or_in_older_rows_by_who_and_what() {
        let saved = |nonce: &str, digest: Option<String>| SavedOutcome {
            nonce: nonce.into(),
            operator: "kim".into(),
            action: "ack".into(),
            digest,
            at: 1_000,
            outcome: Some((true, "ack ese by kim".into())),
        };
        let first = ack("ee", "ese");
        let answers = Answers::restored(vec![
            saved("ee", Some(hex::encode(first.digest()))),
            saved("ff", None),
        ]);
        let (tx, _) = oneshot::channel();
        assert!(matches!(answers.retry(&first, tx), Retry::Now(_)));
        // Another ack of kim's with the same nonce: nobody's outcome.
        let (tx, _) = oneshot::channel();
        assert!(matches!(
            answers.retry(&ack("ee", "csd"), tx),
            Retry::Unknown(_)
        ));
        // A row from before digests were kept: kim's ack, as journaled.
        let (tx, _) = oneshot::channel();
        assert!(matches!(
            answers.retry(&ack("ff", "csd"), tx),
            Retry::Now(_)
        ));
        assert_eq!(
            Sent::journaled(&saved("gg", Some("not hex".into()))),
            Sent::Journaled {
                operator: "kim".into(),
                action: "ack".into()
            }
        );
    }
}
