//! Nothing lost across a network cut: a subscription taken over by the
//! session that replaces a lost one (`TransferSubscriptions`), and every
//! publish the server still holds sent again (`Republish`) in order.
//!
//! A server keeps a subscription for its lifetime without a client
//! (`opcua.subscription_lifetime`), queues the changes meanwhile, and keeps
//! every publish it sent until the client acknowledges it. Whatever it can
//! no longer send is said as a gap: the alarms judged across it say
//! "trigger uncertain". The requests are bounded (`republishes`): a few
//! for each missing publish, whatever the server answers, and a rate.

use std::time::Instant;

use opcua::client::Session;
use opcua::types::{NotificationMessage, StatusCode};

use super::delivery::Shared;
use super::republishes::{Unserved, TRIES};
use super::requests::Requests;
use super::sequence::{has_data, succ};
use super::OpcUaError;

/// How a gap could not be filled.
#[derive(Debug)]
pub(super) enum Unfilled {
    /// The server no longer has the subscription.
    Gone(StatusCode),
    /// The request failed (the connection is down or slow): try again
    /// later.
    Failed(StatusCode),
}

/// What one `Republish` brought.
enum Answer {
    /// The publish asked for.
    Got(NotificationMessage),
    /// Nothing: why.
    Unserved(Unserved),
    /// The server no longer has the subscription.
    Gone(StatusCode),
}

/// Where a missing publish is asked for again: the session's server.
pub(super) trait Retransmission: Sync {
    /// `Republish`: publish `seq` of subscription `id`, sent again.
    fn republish(
        &self,
        id: u32,
        seq: u32,
    ) -> impl std::future::Future<Output = Result<NotificationMessage, opcua::types::Error>> + Send;
}

impl Retransmission for Session {
    fn republish(
        &self,
        id: u32,
        seq: u32,
    ) -> impl std::future::Future<Output = Result<NotificationMessage, opcua::types::Error>> + Send
    {
        Session::republish(self, id, seq)
    }
}

/// Asks the server for publish `seq` of subscription `id` again, once its
/// turn comes (`Republishes::turn`); an answer that does not carry it is
/// none.
async fn ask(
    server: &impl Retransmission,
    id: u32,
    seq: u32,
    shared: &Shared,
    requests: &Requests,
) -> Answer {
    let wait = shared.republishes().turn(Instant::now());
    if !wait.is_zero() {
        tokio::time::sleep(wait).await;
    }
    let answer = server.republish(id, seq).await;
    requests.answered("Republish", &answer);
    match answer {
        Ok(m) if m.sequence_number == seq && has_data(&m) => Answer::Got(m),
        Ok(m) => Answer::Unserved(Unserved::Other {
            carried: m.sequence_number,
        }),
        Err(e) if is_gone(e.status()) => Answer::Gone(e.status()),
        Err(e) if not_available(e.status()) => Answer::Unserved(Unserved::NotAvailable(e.status())),
        Err(e) => Answer::Unserved(Unserved::Failed(e.status())),
    }
}

/// Asks the server again for every publish found missing, in order; one it
/// cannot send (it says it no longer has it, answers with another or none,
/// or a request fails [`TRIES`](super::republishes::TRIES) times) is lost,
/// said once per run.
///
/// # Errors
/// The subscription is gone, or a request failed and may be tried again.
pub(super) async fn fill(
    session: &impl Retransmission,
    id: u32,
    shared: &Shared,
    requests: &Requests,
) -> Result<(), Unfilled> {
    // The last of a run of lost publishes.
    let mut lost: Option<u32> = None;
    let result = loop {
        let seq = {
            let d = shared.lock();
            match lost {
                None => d.sequence.missing(),
                Some(l) => d.sequence.missing_from(succ(l)),
            }
        };
        let Some(seq) = seq else { break Ok(()) };
        match ask(session, id, seq, shared, requests).await {
            Answer::Got(m) => {
                shared.republishes().served(seq);
                let mut d = shared.lock();
                if let Some(l) = lost.take() {
                    gone(&mut d, l);
                }
                d.arrived(m);
            }
            Answer::Unserved(why) => {
                unserved(shared, id, seq, why);
                if shared.republishes().unserved(seq, why) {
                    let Unserved::Failed(status) = why else {
                        unreachable!("only a failed request is tried again")
                    };
                    break Err(Unfilled::Failed(status));
                }
                lost = Some(seq);
            }
            Answer::Gone(status) => break Err(Unfilled::Gone(status)),
        }
    };
    if let Some(l) = lost {
        gone(&mut shared.lock(), l);
    }
    result
}

/// Warns, at most once a minute for each kind, that a `Republish` of
/// publish `seq` brought nothing.
fn unserved(shared: &Shared, id: u32, seq: u32, why: Unserved) {
    let Some(times) = shared.republishes().warn(why, Instant::now()) else {
        return;
    };
    let said = match why {
        Unserved::NotAvailable(status) => format!("the server no longer has it ({status})"),
        Unserved::Other { carried: 0 } => {
            "the server answered with an empty message: it does not have it".into()
        }
        Unserved::Other { carried } => {
            format!("the server answered with publish {carried}: it does not have it")
        }
        Unserved::Failed(status) => {
            format!("the request failed ({status}); given up as lost after {TRIES} tries")
        }
    };
    tracing::warn!(
        subscription = id,
        publish = seq,
        "a publish asked for again (Republish) was not sent: {said} ({times} such \
         since the last warning, said at most once a minute)"
    );
}

fn gone(d: &mut super::delivery::Delivery, seq: u32) {
    let mut next = Vec::new();
    d.sequence.gone(seq, &mut next);
    d.handle(next);
}

fn is_gone(status: StatusCode) -> bool {
    matches!(
        status,
        StatusCode::BadSubscriptionIdInvalid | StatusCode::BadNoSubscription
    )
}

/// The server says it does not hold the publish asked for.
fn not_available(status: StatusCode) -> bool {
    matches!(
        status,
        StatusCode::BadMessageNotAvailable | StatusCode::BadSequenceNumberUnknown
    )
}

/// After the session was reactivated, or the subscription fell silent:
/// every publish the server sent and the agent never got is asked for
/// again, from the next one expected until the server has no more (it says
/// so, or answers with another or none).
///
/// # Errors
/// The subscription is gone, or a request failed.
pub(super) async fn catch_up(
    session: &Session,
    id: u32,
    shared: &Shared,
    requests: &Requests,
) -> Result<(), Unfilled> {
    // Is it still there? (A server may answer a republish for a
    // subscription it dropped as if it merely had nothing to resend.)
    let mode = session.set_publishing_mode(&[id], true).await;
    requests.answered("SetPublishingMode", &mode);
    match mode {
        Ok(r) => match r.first() {
            Some(s) if !s.is_good() => return Err(Unfilled::Gone(*s)),
            _ => {}
        },
        Err(e) if is_gone(e.status()) => return Err(Unfilled::Gone(e.status())),
        Err(e) => return Err(Unfilled::Failed(e.status())),
    }
    shared.lock().resume();
    loop {
        fill(session, id, shared, requests).await?;
        let next = shared.lock().sequence.next();
        let Some(seq) = next else { return Ok(()) };
        match ask(session, id, seq, shared, requests).await {
            Answer::Got(m) => shared.lock().arrived(m),
            // Not sent yet: nothing more to catch up.
            Answer::Unserved(Unserved::NotAvailable(_) | Unserved::Other { .. }) => return Ok(()),
            Answer::Unserved(Unserved::Failed(status)) => return Err(Unfilled::Failed(status)),
            Answer::Gone(status) => return Err(Unfilled::Gone(status)),
        }
    }
}

/// Takes the subscription over into a new session, asking the server to
/// send every value again after what it still holds, then fills the gaps.
///
/// # Errors
/// Why it could not be taken over (the server dropped it, refuses the
/// transfer, or does not offer the service).
pub(super) async fn transfer(
    session: &Session,
    id: u32,
    shared: &Shared,
    requests: &Requests,
) -> Result<(), OpcUaError> {
    let results = session.transfer_subscriptions(&[id], true).await;
    requests.answered("TransferSubscriptions", &results);
    let results = results.map_err(OpcUaError::Service)?;
    let result = results.into_iter().next().ok_or(OpcUaError::NoAnswer)?;
    if !result.status_code.is_good() {
        return Err(OpcUaError::Status(result.status_code));
    }
    {
        let mut d = shared.lock();
        d.resume();
        if let Some(last) = result.available_sequence_numbers.iter().flatten().max() {
            d.sequence.sent(*last);
        }
    }
    match fill(session, id, shared, requests).await {
        Ok(()) | Err(Unfilled::Failed(_)) => Ok(()),
        Err(Unfilled::Gone(status)) => Err(OpcUaError::Status(status)),
    }
}

/// The subscription is given up (gone, or replaced): what was held behind a
/// missing publish is delivered after the loss is said, and the changes
/// since the last publish delivered may be lost (`why`).
pub(super) fn give_up(shared: &Shared, why: String) {
    let mut d = shared.lock();
    let mut next = Vec::new();
    d.sequence.give_up(&mut next);
    d.handle(next);
    d.gap(why);
}

#[cfg(test)]
mod tests;
