//! A source whose events are handed in through a channel: tests drive the
//! cell loop with it, with no PLC, and it shows how small a source can be.

use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::sync::mpsc;

use super::{Source, SourceError, SourceEvent, SourceSender};

/// Forwards what is sent on its script channel to the cell loop.
pub struct ScriptedSource {
    /// Events from the script's writer, forwarded in order.
    script: mpsc::Receiver<SourceEvent>,
}

impl ScriptedSource {
    /// A source and the sender its script is written to. The source ends
    /// when the sender is dropped or the cell loop shuts it down.
    pub fn new() -> (ScriptedSource, mpsc::Sender<SourceEvent>) {
        let (tx, script) = mpsc::channel(super::QUEUE_CAPACITY);
        (ScriptedSource { script }, tx)
    }
}

impl Source for ScriptedSource {
    fn describe(&self) -> String {
        "scripted".into()
    }

    fn run(
        mut self: Box<Self>,
        tx: SourceSender,
        shutdown: BoxFuture<'static, ()>,
    ) -> BoxFuture<'static, Result<(), SourceError>> {
        async move {
            tokio::pin!(shutdown);
            loop {
                tokio::select! {
                    _ = &mut shutdown => return Ok(()),
                    ev = self.script.recv() => match ev {
                        Some(ev) => if tx.send(ev).await.is_err() { return Ok(()) },
                        None => return Ok(()),
                    },
                }
            }
        }
        .boxed()
    }
}
