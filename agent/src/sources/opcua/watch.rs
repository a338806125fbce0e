//! A subscription in place, watched by the session's supervisor until it
//! must be replaced: its gaps filled (`resume`), its monitored items
//! tended (`tend`), a cycle held for the rest of it handed on in time, its
//! silence judged. The filling and the tending run side by side, so that
//! neither waits for the other: a `Read` held up by a stalled connection
//! does not keep a missing publish from being asked for, and a recovery
//! under way does not keep a node deleted and added again from being found.

use std::time::{Duration, Instant};

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use opcua::client::Session;

use super::context::{Context, Live};
use super::resume::{self, Unfilled};
use super::tend::{Tended, Tending};

/// Keep-alive periods without any publish before a subscription is called
/// silent and recreated.
pub const SILENT_KEEP_ALIVES: u32 = 3;

/// Watches a subscription in place: fills every gap found in its
/// publishes, tends its monitored items, and says why it must be
/// replaced — the server closed it, or it went silent (no data, no
/// keep-alive) and held nothing to send again.
pub(super) async fn watch(session: &Session, ctx: &Context, l: &Live) -> String {
    let sub = &l.subscription;
    let limit = sub.keep_alive * SILENT_KEEP_ALIVES;
    let period = (sub.keep_alive / 2).max(Duration::from_millis(50));
    // The tending, and its turn under way (which holds it meanwhile).
    let mut tending = Some(Tending::new(&ctx.config));
    let mut turn: Option<BoxFuture<'_, (Tending, Instant)>> = None;
    let mut next = Instant::now();
    // The gaps being filled, and whether silence asked for it (then the
    // subscription is judged once it ends), and when silence last did.
    let mut filling: Option<BoxFuture<'_, Result<(), Unfilled>>> = None;
    let mut for_silence = false;
    let mut asked_at: Option<Instant> = None;
    // When a cycle held for the rest of it is handed on anyway.
    let mut held: Option<Instant> = None;
    loop {
        let now = Instant::now();
        // A turn under way is awaited, not timed.
        let tend_in = match tending {
            Some(_) => next.saturating_duration_since(now),
            None => period,
        };
        let wait = period
            .min(tend_in)
            .min(held.map_or(period, |at| at.saturating_duration_since(now)));
        tokio::select! {
            () = tokio::time::sleep(wait) => {
                if held.is_some_and(|at| at <= Instant::now()) {
                    held = l.shared.lock().flush_stale();
                }
            }
            (t, at) = async { turn.as_mut().expect("guarded").await }, if turn.is_some() => {
                turn = None;
                tending = Some(t);
                next = at;
            }
            filled = async { filling.as_mut().expect("guarded").await }, if filling.is_some() => {
                filling = None;
                let silence = std::mem::take(&mut for_silence);
                match filled {
                    Err(Unfilled::Gone(status)) => {
                        return format!("the server dropped subscription {} ({status}): subscribing again", sub.id);
                    }
                    // A request that fails (a stalled connection) leaves
                    // the subscription alone: the session's keep-alive
                    // judges the connection, and a subscription deleted now
                    // would drop what arrives once the traffic flows again.
                    Err(Unfilled::Failed(status)) if silence => {
                        tracing::debug!(subscription = sub.id, %status, "silent, and cannot be asked for what it holds: waiting");
                    }
                    Err(Unfilled::Failed(status)) => {
                        tracing::debug!(subscription = sub.id, %status, "a missing publish cannot be asked for now: later");
                    }
                    Ok(()) if silence && l.heard.silent_for() > limit => {
                        return format!(
                            "subscription silent for {:.1} s (no data, no keep-alive) while the session lives",
                            l.heard.silent_for().as_secs_f64()
                        );
                    }
                    Ok(()) => {}
                }
            }
            () = l.shared.held.notified() => held = l.shared.lock().flush_stale(),
            () = l.shared.failed.notified() => next = Instant::now(),
            () = l.shared.missing.notified(), if filling.is_none() => {
                filling = Some(resume::fill(session, sub.id, &l.shared, &ctx.requests).boxed());
            }
        }
        if let Some(status) = l.heard.closed() {
            return format!(
                "the server dropped subscription {} ({status}): subscribing again",
                sub.id
            );
        }
        if let Some(mut t) = tending.take_if(|_| next <= Instant::now()) {
            turn = Some(
                async move {
                    let at = t
                        .tend(&Tended {
                            session,
                            sub: sub.id,
                            config: &ctx.config,
                            uses: &ctx.uses,
                            nodes: &l.nodes,
                            shared: &l.shared,
                            heard: &l.heard,
                            tx: &ctx.tx,
                            requests: &ctx.requests,
                        })
                        .await;
                    (t, at)
                }
                .boxed(),
            );
        }
        // Silent: whatever the server sent and the agent never got is
        // asked for again, once a period at most.
        let due = asked_at.is_none_or(|at| at.elapsed() >= period);
        if filling.is_none() && due && l.heard.silent_for() > limit {
            asked_at = Some(Instant::now());
            for_silence = true;
            filling = Some(resume::catch_up(session, sub.id, &l.shared, &ctx.requests).boxed());
        }
    }
}
