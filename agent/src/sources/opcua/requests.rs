//! What the source asks of the server and how it is answered, counted by
//! OPC UA service and result (`cellwatch_opcua_requests_total{service,
//! result}`: `good`, or the status code's name). The counter is the
//! metrics registry's, handed to the source before it runs; a source run
//! without one (tests, `cellwatch discover`) counts nothing. The client
//! library's own requests, the `Publish` requests it keeps queued and the
//! session's keep-alive reads, are counted from its event loop's reports.

use opcua::client::{SessionActivity, SubscriptionActivity};
use opcua::types::StatusCode;
use prometheus::IntCounterVec;

/// The counter of requests, labelled `service` and `result`.
#[derive(Clone, Default)]
pub(super) struct Requests(Option<IntCounterVec>);

impl Requests {
    /// Counting into `counter`, if given.
    pub(super) fn new(counter: Option<IntCounterVec>) -> Requests {
        Requests(counter)
    }

    /// A `service` request was answered with `status`, its service result.
    pub(super) fn status(&self, service: &'static str, status: StatusCode) {
        if let Some(counter) = &self.0 {
            counter.with_label_values(&[service, result(status)]).inc();
        }
    }

    /// A `service` request ended with `answer`.
    pub(super) fn answered<T>(
        &self,
        service: &'static str,
        answer: &Result<T, opcua::types::Error>,
    ) {
        self.status(
            service,
            answer
                .as_ref()
                .map_or_else(|e| e.status(), |_| StatusCode::Good),
        );
    }

    /// A `Publish` the client library queued was answered (a failure it
    /// retries and a fatal one alike are counted with their status).
    pub(super) fn publish(&self, activity: &SubscriptionActivity) {
        let status = match activity {
            SubscriptionActivity::Publish => StatusCode::Good,
            SubscriptionActivity::PublishFailed(s) | SubscriptionActivity::FatalFailure(s) => *s,
        };
        self.status("Publish", status);
    }

    /// The client library's keep-alive read of the server's state was
    /// answered (a state other than running is its failure).
    pub(super) fn keep_alive(&self, activity: &SessionActivity) {
        let status = match activity {
            SessionActivity::KeepAliveSucceeded => StatusCode::Good,
            SessionActivity::KeepAliveFailed(s) => *s,
        };
        self.status("Read", status);
    }
}

/// The result label: `good`, or the status code's name (`BadTimeout`).
fn result(status: StatusCode) -> &'static str {
    if status.is_good() {
        "good"
    } else {
        status.sub_code().name()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_answer_is_counted_under_its_service_and_status_name() {
        let counter = IntCounterVec::new(
            prometheus::Opts::new("requests", "requests"),
            &["service", "result"],
        )
        .unwrap();
        let requests = Requests::new(Some(counter.clone()));
        requests.answered::<()>("Read", &Ok(()));
        requests.answered::<()>(
            "Republish",
            &Err(opcua::types::Error::new(
                StatusCode::BadMessageNotAvailable,
                "",
            )),
        );
        requests.status("Republish", StatusCode::BadMessageNotAvailable);
        assert_eq!(counter.with_label_values(&["Read", "good"]).get(), 1);
        assert_eq!(
            counter
                .with_label_values(&["Republish", "BadMessageNotAvailable"])
                .get(),
            2
        );
        // Without a counter, nothing to count into.
        Requests::default().status("Read", StatusCode::Good);
    }
}
