//! The alarm server's sink: hands each alarm transition of a step to the
//! OPC UA alarm server (`services::alarm_server`), which changes its
//! condition and sends its event. Nothing on the alarm's path waits for a
//! client: events are queued per subscription by the server.

use std::sync::Arc;

use futures_util::future::BoxFuture;
use futures_util::FutureExt;

use crate::payload::AlarmPayload;
use crate::sinks::Sink;
use crate::step::CellStep;

/// Feeds the alarm server.
pub struct AlarmServerSink {
    /// Takes one alarm transition (`AlarmServer::feed`).
    feed: Arc<dyn Fn(&AlarmPayload) + Send + Sync>,
}

impl AlarmServerSink {
    /// A sink handing every alarm transition to `feed`.
    pub fn new(feed: Arc<dyn Fn(&AlarmPayload) + Send + Sync>) -> AlarmServerSink {
        AlarmServerSink { feed }
    }
}

impl Sink for AlarmServerSink {
    fn name(&self) -> &'static str {
        "alarm_server"
    }

    fn handle<'a>(&'a mut self, step: &'a CellStep) -> BoxFuture<'a, ()> {
        for a in &step.alarms {
            (self.feed)(&a.payload);
        }
        async {}.boxed()
    }
}
