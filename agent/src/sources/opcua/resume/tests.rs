//! A missing publish asked for again: what the server answers ends its
//! recovery in a few requests at most, the loss said before what follows.

use std::collections::BTreeMap;
use std::sync::Mutex;

use opcua::types::{NotificationMessage, StatusCode};

use super::{fill, Retransmission, Unfilled};
use crate::sources::opcua::delivery::tests::{cell, publish};
use crate::sources::opcua::republishes::TRIES;
use crate::sources::opcua::requests::Requests;
use crate::sources::SourceEvent;

/// A server's retransmission queue, written out: what it answers a
/// `Republish` of each number (none: `BadMessageNotAvailable`), and the
/// numbers asked for, in order.
#[derive(Default)]
struct Queue {
    answers: BTreeMap<u32, Result<NotificationMessage, StatusCode>>,
    asked: Mutex<Vec<u32>>,
}

impl Retransmission for Queue {
    async fn republish(
        &self,
        _id: u32,
        seq: u32,
    ) -> Result<NotificationMessage, opcua::types::Error> {
        self.asked.lock().unwrap().push(seq);
        match self.answers.get(&seq) {
            Some(Ok(m)) => Ok(m.clone()),
            Some(Err(status)) => Err(opcua::types::Error::new(*status, "")),
            None => Err(opcua::types::Error::new(
                StatusCode::BadMessageNotAvailable,
                "",
            )),
        }
    }
}

const T: i64 = 1_800_000_000_000;

/// What the delivery handed on: `lost` for a gap, `a=v` for a reading of
/// tag `a`.
fn told(rx: &mut tokio::sync::mpsc::Receiver<SourceEvent>) -> Vec<String> {
    let mut out = Vec::new();
    while let Ok(e) = rx.try_recv() {
        match e {
            SourceEvent::Gap {
                tags: None, why, ..
            } => out.push(format!("lost: {why}")),
            SourceEvent::Readings(b) => out.extend(
                b.readings
                    .iter()
                    .map(|r| format!("{}={:?}", r.tag, r.reading)),
            ),
            other => out.push(format!("{other:?}")),
        }
    }
    out
}

#[tokio::test]
async fn a_publish_the_server_no_longer_has_is_asked_for_once_and_said_lost() {
    let (shared, mut rx, _dir) = cell();
    shared.lock().id = 7;
    shared.lock().arrived(publish(1, T, &[(1, true, T)]));
    shared
        .lock()
        .arrived(publish(3, T + 200, &[(1, false, T + 200)]));
    assert_eq!(told(&mut rx), ["0=Good(true)"]);
    let server = Queue::default();
    fill(&server, 7, &shared, &Requests::default())
        .await
        .unwrap();
    assert_eq!(*server.asked.lock().unwrap(), [2]);
    assert_eq!(
        told(&mut rx),
        [
            "lost: publish 2 of subscription 7 lost: the server no longer had them to send again",
            "0=Good(false)"
        ]
    );
    assert!(shared.lock().flowing());
    // Nothing more to ask.
    fill(&server, 7, &shared, &Requests::default())
        .await
        .unwrap();
    assert_eq!(server.asked.lock().unwrap().len(), 1);
}

#[tokio::test]
async fn an_answer_without_the_publish_asked_for_ends_its_recovery_as_one_that_says_so() {
    let (shared, mut rx, _dir) = cell();
    shared.lock().arrived(publish(1, T, &[(1, true, T)]));
    shared
        .lock()
        .arrived(publish(4, T + 300, &[(1, false, T + 300)]));
    // Python asyncua answers what it does not hold with an empty message;
    // another server sends the wrong one.
    let mut server = Queue::default();
    server.answers.insert(2, Ok(NotificationMessage::default()));
    server
        .answers
        .insert(3, Ok(publish(9, T + 900, &[(2, true, T + 900)])));
    fill(&server, 7, &shared, &Requests::default())
        .await
        .unwrap();
    assert_eq!(*server.asked.lock().unwrap(), [2, 3]);
    let seen = told(&mut rx);
    assert_eq!(seen.len(), 3, "{seen:?}");
    assert!(
        seen[1].starts_with("lost: publishes 2 to 3 of subscription"),
        "{seen:?}"
    );
    assert_eq!(seen[2], "0=Good(false)");
}

#[tokio::test]
async fn a_request_that_keeps_failing_is_tried_a_few_times_then_the_publish_is_said_lost() {
    let (shared, mut rx, _dir) = cell();
    shared.lock().arrived(publish(1, T, &[(1, true, T)]));
    shared
        .lock()
        .arrived(publish(3, T + 200, &[(1, false, T + 200)]));
    let mut server = Queue::default();
    server.answers.insert(2, Err(StatusCode::BadTimeout));
    // Asked again each time the supervisor is woken (each publish while
    // one is missing), and never more than a few times.
    for _ in 1..TRIES {
        let failed = fill(&server, 7, &shared, &Requests::default()).await;
        assert!(
            matches!(failed, Err(Unfilled::Failed(StatusCode::BadTimeout))),
            "{failed:?}"
        );
        assert!(!shared.lock().flowing());
    }
    fill(&server, 7, &shared, &Requests::default())
        .await
        .unwrap();
    for _ in 0..10 {
        fill(&server, 7, &shared, &Requests::default())
            .await
            .unwrap();
    }
    assert_eq!(server.asked.lock().unwrap().len(), usize::from(TRIES));
    let seen = told(&mut rx);
    assert!(
        seen[1].starts_with("lost: publish 2 of subscription"),
        "{seen:?}"
    );
    assert_eq!(seen[2], "0=Good(false)");
    assert!(shared.lock().flowing());
}

#[tokio::test]
async fn a_republish_answered_subscription_id_invalid_gives_the_whole_subscription_up_at_once() {
    let (shared, _rx, _dir) = cell();
    shared.lock().id = 7;
    shared.lock().arrived(publish(1, T, &[(1, true, T)]));
    shared
        .lock()
        .arrived(publish(4, T + 300, &[(1, false, T + 300)]));
    let mut server = Queue::default();
    for seq in [2, 3] {
        server
            .answers
            .insert(seq, Err(StatusCode::BadSubscriptionIdInvalid));
    }
    // Gone: the supervisor replaces the subscription (`watch`); the
    // second missing publish is not asked for.
    let filled = fill(&server, 7, &shared, &Requests::default()).await;
    assert!(
        matches!(
            filled,
            Err(Unfilled::Gone(StatusCode::BadSubscriptionIdInvalid))
        ),
        "{filled:?}"
    );
    assert_eq!(*server.asked.lock().unwrap(), [2]);
}
