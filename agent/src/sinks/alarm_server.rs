//! The alarm server's sink: hands each step to the OPC UA alarm server
//! (`services::alarm_server`), which changes the conditions of its alarm
//! transitions and sends their events, and follows its machine state. Nothing on the alarm's path waits for a
//! client: events are queued per subscription by the server.

use std::sync::Arc;

use futures_util::future::BoxFuture;
use futures_util::FutureExt;

use crate::sinks::Sink;
use crate::step::CellStep;

/// Feeds the alarm server.
pub(crate) struct AlarmServerSink {
    /// Takes one step (`AlarmServer::feed`).
    feed: Arc<dyn Fn(&CellStep) + Send + Sync>,
}

impl AlarmServerSink {
    /// A sink handing every step to `feed`.
    pub(crate) fn new(feed: Arc<dyn Fn(&CellStep) + Send + Sync>) -> AlarmServerSink {
        AlarmServerSink { feed }
    }
}

impl Sink for AlarmServerSink {
    fn name(&self) -> &'static str {
        "alarm_server"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        (self.feed)(step);
        async {}.boxed()
    }
}
