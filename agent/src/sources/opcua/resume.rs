//! Nothing lost across a network cut: a subscription taken over by the
//! session that replaces a lost one (`TransferSubscriptions`), and every
//! publish the server still holds sent again (`Republish`) in order.
//!
//! A server keeps a subscription for its lifetime without a client
//! (`opcua.subscription_lifetime`), queues the changes meanwhile, and keeps
//! every publish it sent until the client acknowledges it. Whatever it can
//! no longer send is said as a gap: the alarms judged across it say
//! "trigger uncertain".

use opcua::client::Session;
use opcua::types::StatusCode;

use super::delivery::Shared;
use super::sequence::succ;

/// How a gap could not be filled.
#[derive(Debug)]
pub(super) enum Unfilled {
    /// The server no longer has the subscription.
    Gone(StatusCode),
    /// The request failed (the connection is down or slow): try again
    /// later.
    Failed(StatusCode),
}

/// Asks the server again for every publish found missing, in order; one it
/// no longer has is lost, said once per run.
///
/// # Errors
/// The subscription is gone, or a request failed.
pub(super) async fn fill(session: &Session, id: u32, shared: &Shared) -> Result<(), Unfilled> {
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
        match session.republish(id, seq).await {
            Ok(m) => {
                let mut d = shared.lock();
                if let Some(l) = lost.take() {
                    gone(&mut d, l);
                }
                d.arrived(m);
            }
            Err(e) if e.status() == StatusCode::BadMessageNotAvailable => lost = Some(seq),
            Err(e) if is_gone(e.status()) => break Err(Unfilled::Gone(e.status())),
            Err(e) => break Err(Unfilled::Failed(e.status())),
        }
    };
    if let Some(l) = lost {
        gone(&mut shared.lock(), l);
    }
    result
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

/// After the session was reactivated: every publish the server sent while
/// the connection was down is asked for again, from the next one expected
/// until the server has no more.
///
/// # Errors
/// The subscription is gone, or a request failed.
pub(super) async fn catch_up(session: &Session, id: u32, shared: &Shared) -> Result<(), Unfilled> {
    // Is it still there? (A server may answer a republish for a
    // subscription it dropped as if it merely had nothing to resend.)
    match session.set_publishing_mode(&[id], true).await {
        Ok(r) => match r.first() {
            Some(s) if !s.is_good() => return Err(Unfilled::Gone(*s)),
            _ => {}
        },
        Err(e) if is_gone(e.status()) => return Err(Unfilled::Gone(e.status())),
        Err(e) => return Err(Unfilled::Failed(e.status())),
    }
    shared.lock().resume();
    loop {
        fill(session, id, shared).await?;
        let next = shared.lock().sequence.next();
        let Some(seq) = next else { return Ok(()) };
        match session.republish(id, seq).await {
            Ok(m) => shared.lock().arrived(m),
            // Not sent yet: nothing more to catch up.
            Err(e) if e.status() == StatusCode::BadMessageNotAvailable => return Ok(()),
            Err(e) if is_gone(e.status()) => return Err(Unfilled::Gone(e.status())),
            Err(e) => return Err(Unfilled::Failed(e.status())),
        }
    }
}

/// Takes the subscription over into a new session, asking the server to
/// send every value again after what it still holds, then fills the gaps.
///
/// # Errors
/// Why it could not be taken over (the server dropped it, refuses the
/// transfer, or does not offer the service).
pub(super) async fn transfer(session: &Session, id: u32, shared: &Shared) -> Result<(), String> {
    let results = session
        .transfer_subscriptions(&[id], true)
        .await
        .map_err(|e| e.to_string())?;
    let result = results
        .into_iter()
        .next()
        .ok_or("the server answered nothing")?;
    if !result.status_code.is_good() {
        return Err(result.status_code.to_string());
    }
    {
        let mut d = shared.lock();
        d.resume();
        if let Some(last) = result.available_sequence_numbers.iter().flatten().max() {
            d.sequence.sent(*last);
        }
    }
    match fill(session, id, shared).await {
        Ok(()) | Err(Unfilled::Failed(_)) => Ok(()),
        Err(Unfilled::Gone(status)) => Err(status.to_string()),
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
