//! What the OPC UA source's tasks share: what it reads of each tag
//! ([`TagTable`]), the [`Context`] every supervisor of a session needs, and
//! the subscription in place ([`Live`]).

use std::sync::Arc;

use super::conditions::Conditions;
use super::names::Names;
use super::requests::Requests;
use super::{delivery, subscription};
use crate::sources::opcua::config::OpcUaConfig;
use crate::sources::opcua::node::TagNode;
use crate::sources::SourceSender;
use crate::tags::TagConfig;

/// What every supervisor of this source needs.
pub(super) struct Context {
    /// The server read from (of a redundant set, the one chosen).
    endpoint: std::sync::Mutex<String>,
    pub(super) config: OpcUaConfig,
    /// Each tag's node, `None` when its node id cannot be read.
    pub(super) nodes: Arc<Vec<Option<TagNode>>>,
    pub(super) uses: Arc<subscription::Uses>,
    pub(super) names: Arc<Names>,
    pub(super) tx: SourceSender,
    /// The delivery of the subscription in place, paused when the
    /// connection is lost.
    pub(super) delivery: std::sync::Mutex<Option<delivery::Shared>>,
    /// The PLC's own alarms (`opcua.events`), across subscriptions.
    pub(super) conditions: Arc<std::sync::Mutex<Conditions>>,
    /// Where the requests made of the server are counted.
    pub(super) requests: Requests,
}

impl Context {
    /// The connection is lost: the subscription's publishes wait until the
    /// source knows whether it resumes without a loss.
    /// The server read from.
    pub(super) fn endpoint(&self) -> String {
        self.endpoint
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Reads from `endpoint` from now on (a move within a redundant set).
    pub(super) fn reading_from(&self, endpoint: &str) {
        *self.endpoint.lock().unwrap_or_else(|e| e.into_inner()) = endpoint.to_string();
    }

    pub(super) fn pause(&self) {
        if let Some(d) = self
            .delivery
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
        {
            d.lock().pause();
        }
    }

    pub(super) fn new(
        config: &OpcUaConfig,
        tags: TagTable,
        tx: SourceSender,
        requests: Requests,
    ) -> Context {
        Context {
            endpoint: std::sync::Mutex::new(config.endpoint.clone()),
            config: config.clone(),
            nodes: tags.nodes,
            uses: tags.uses,
            names: tags.names,
            tx,
            delivery: std::sync::Mutex::new(None),
            conditions: Arc::new(std::sync::Mutex::new(Conditions::new(&config.events))),
            requests,
        }
    }
}

/// A subscription in place on the server.
pub(super) struct Live {
    pub(super) subscription: subscription::Subscribed,
    /// Its publishes' way to the cell loop, in order.
    pub(super) shared: delivery::Shared,
    /// The monitored nodes and their tags.
    pub(super) nodes: Arc<subscription::Monitored>,
    /// The namespace array its node ids were resolved against.
    pub(super) namespaces: Vec<String>,
    pub(super) heard: Arc<subscription::Heard>,
}

/// What the source reads of each tag: its node (`None` when its node id
/// cannot be read), how it is read, its name for messages.
pub(super) struct TagTable {
    pub(super) nodes: Arc<Vec<Option<TagNode>>>,
    pub(super) uses: Arc<subscription::Uses>,
    pub(super) names: Arc<Names>,
}

impl TagTable {
    pub(super) fn new(config: &OpcUaConfig, tags: &[TagConfig]) -> TagTable {
        let nodes = tags
            .iter()
            .map(
                |t| match TagNode::parse(&t.node_id, config.namespace_uri.as_deref()) {
                    Ok(n) => Some(n),
                    Err(e) => {
                        tracing::error!(tag = %t.name, error = %e, "tag not read");
                        None
                    }
                },
            )
            .collect();
        TagTable {
            nodes: Arc::new(nodes),
            uses: Arc::new(subscription::Uses::of_tags(tags)),
            names: Arc::new(Names::of(tags)),
        }
    }
}
