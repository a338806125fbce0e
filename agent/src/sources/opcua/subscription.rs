//! The subscription: monitored items created in chunks the server accepts,
//! and each publish's changes passed on in source-time order.

use std::collections::HashMap;
use std::sync::Arc;

use cellwatch_models::engine::{Reading, TagReading};
use opcua::client::{
    MonitoredItem, MonitoredItemMap, OnSubscriptionNotification, OnSubscriptionNotificationCore,
    Session,
};
use opcua::types::{
    DataChangeFilter, DataChangeTrigger, DataValue, ExtensionObject, MonitoredItemCreateRequest,
    MonitoringMode, MonitoringParameters, NodeId, NotificationMessage, ReadValueId,
    TimestampsToReturn, Variant,
};
use tokio::sync::mpsc::error::TrySendError;

use crate::config::OpcUaConfig;
use crate::sources::{SourceEvent, SourceSender};

/// `Server_ServerCapabilities_OperationLimits_MaxMonitoredItemsPerCall`.
const MAX_MONITORED_ITEMS_PER_CALL: u32 = 11714;
/// Used when the server states no limit.
const DEFAULT_CHUNK: usize = 1000;

/// Creates the subscription and its monitored items in chunks.
pub(super) async fn subscribe(
    session: &Arc<Session>,
    config: &OpcUaConfig,
    by_node: &Arc<HashMap<NodeId, usize>>,
    tx: &SourceSender,
) -> bool {
    let callback = InTimeOrder {
        by_node: by_node.clone(),
        tx: tx.clone(),
    };
    let sub = match session
        .create_subscription(config.publishing_interval, 60, 10, 0, 0, true, callback)
        .await
    {
        Ok(id) => id,
        Err(e) => {
            tracing::error!(error = %e, "cannot create the OPC UA subscription");
            let _ = tx
                .send(SourceEvent::Disconnected(format!(
                    "cannot create subscription: {e}"
                )))
                .await;
            return false;
        }
    };
    let chunk = max_items_per_call(session).await;
    let sampling = config.sampling_interval.as_secs_f64() * 1000.0;
    let requests: Vec<MonitoredItemCreateRequest> = by_node
        .keys()
        .map(|n| {
            // Without a filter a server reports value changes only; quality
            // changes (a broken sensor wire) must be reported too.
            let filter = DataChangeFilter {
                trigger: DataChangeTrigger::StatusValue,
                deadband_type: 0,
                deadband_value: 0.0,
            };
            let params = MonitoringParameters {
                sampling_interval: sampling,
                queue_size: 10,
                discard_oldest: true,
                filter: ExtensionObject::from_message(filter),
                ..Default::default()
            };
            MonitoredItemCreateRequest::new(
                ReadValueId::from(n.clone()),
                MonitoringMode::Reporting,
                params,
            )
        })
        .collect();
    tracing::debug!(
        subscription = sub,
        items = requests.len(),
        chunk,
        "creating monitored items"
    );
    for part in requests.chunks(chunk) {
        match session
            .create_monitored_items(sub, TimestampsToReturn::Both, part.to_vec())
            .await
        {
            Ok(results) => {
                for (r, req) in results.iter().zip(part) {
                    if !r.result.status_code.is_good() {
                        tracing::error!(node = %req.item_to_monitor.node_id, status = %r.result.status_code, "monitored item refused");
                        if let Some(&tag) = by_node.get(&req.item_to_monitor.node_id) {
                            let _ = tx
                                .send(SourceEvent::Readings(vec![TagReading {
                                    tag,
                                    reading: Reading::Bad,
                                    source_time: crate::clock::now_ms(),
                                }]))
                                .await;
                        }
                    }
                }
            }
            Err(e) => tracing::error!(error = %e, "cannot create monitored items"),
        }
    }
    true
}

/// Passes each publish's data changes to the engine in source-time order.
///
/// A server sends the changes of one publish in no particular order; a
/// trigger processed before the change it depends on would leave a timer
/// unarmed. The library's own dispatch collects them ([`Collector`]), then
/// they are sorted by source timestamp (stable, so equal times keep the
/// server's order).
struct InTimeOrder {
    by_node: Arc<HashMap<NodeId, usize>>,
    tx: SourceSender,
}

struct Collector<'a> {
    by_node: &'a HashMap<NodeId, usize>,
    readings: Vec<TagReading>,
}

impl OnSubscriptionNotification for Collector<'_> {
    fn on_data_value(&mut self, value: DataValue, item: &MonitoredItem) {
        if let Some(&tag) = self.by_node.get(&item.item_to_monitor().node_id) {
            self.readings.push(TagReading {
                tag,
                reading: reading(&value),
                source_time: source_time(&value),
            });
        }
    }
}

impl OnSubscriptionNotificationCore for InTimeOrder {
    fn on_subscription_notification(
        &mut self,
        notification: NotificationMessage,
        items: MonitoredItemMap<'_>,
    ) {
        let mut c = Collector {
            by_node: &self.by_node,
            readings: Vec::new(),
        };
        c.on_subscription_notification(notification, items);
        if c.readings.is_empty() {
            return;
        }
        c.readings.sort_by_key(|r| r.source_time);
        send_blocking(&self.tx, SourceEvent::Readings(c.readings));
    }
}

/// Sends from the session's (synchronous) notification callback. When the
/// cell loop is behind and the channel full, the callback waits: the
/// session's event loop stops taking publishes, and the server's queues
/// hold the changes. Nothing is dropped here.
fn send_blocking(tx: &SourceSender, event: SourceEvent) {
    let event = match tx.try_send(event) {
        Ok(()) | Err(TrySendError::Closed(_)) => return,
        Err(TrySendError::Full(event)) => event,
    };
    match tokio::runtime::Handle::try_current().map(|h| h.runtime_flavor()) {
        Ok(tokio::runtime::RuntimeFlavor::CurrentThread) => {
            // A single-threaded runtime cannot block here without stopping
            // the loop that would empty the channel.
            tracing::error!(
                "the cell loop is behind on a single-threaded runtime; a publish is dropped"
            );
        }
        Ok(_) => {
            let _ = tokio::task::block_in_place(|| tx.blocking_send(event));
        }
        Err(_) => {
            let _ = tx.blocking_send(event);
        }
    }
}

/// The server's limit on monitored items per call, or [`DEFAULT_CHUNK`].
async fn max_items_per_call(session: &Session) -> usize {
    let node = NodeId::new(0, MAX_MONITORED_ITEMS_PER_CALL);
    match session
        .read(&[ReadValueId::from(node)], TimestampsToReturn::Neither, 0.0)
        .await
    {
        Ok(values) => match values.first().and_then(|v| v.value.as_ref()) {
            Some(Variant::UInt32(n)) if *n > 0 => *n as usize,
            _ => DEFAULT_CHUNK,
        },
        Err(_) => DEFAULT_CHUNK,
    }
}

/// A data value as the engine reads it.
pub fn reading(value: &DataValue) -> Reading {
    let good = value.status.is_none_or(|s| s.is_good());
    match (&value.value, good) {
        (Some(Variant::Boolean(b)), true) => Reading::Good(*b),
        _ => Reading::Bad,
    }
}

fn source_time(value: &DataValue) -> u64 {
    value
        .source_timestamp
        .or(value.server_timestamp)
        .map_or_else(crate::clock::now_ms, |t| {
            t.as_chrono().timestamp_millis().max(0) as u64
        })
}
