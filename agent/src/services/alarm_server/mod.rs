//! The alarm server (`[alarm_server]`): the cell's alarms served to SCADA
//! clients as OPC UA Alarms & Conditions, beside the cell loop. One
//! `CellAlarmType` (an `AlarmConditionType` with the alarm's culprits as
//! `Culprits`, for a consequence why as `Consequence`, and the master
//! alarm database's guidance: `CorrectiveAction`, `ConsequenceOfInaction`,
//! `AlarmClass`, `ResponseTime`, `Overdue` once unacknowledged past it, an
//! event of its own) per alarm id under the cell's object, a notifier the
//! `Server` object reaches, so a client subscribing to events on i=2253
//! sees every transition; `ConditionRefresh` is answered, and
//! `Acknowledge`, shelving and `Disable`/`Enable` are carried out by the
//! cell loop as the operator the session's user acts as ([`users`]).
//!
//! Security: Basic256Sha256 with SignAndEncrypt only; the server's key pair
//! is made in its PKI directory on first start, client certificates are
//! trusted only from `trusted/` (others land in `rejected/`), checked before
//! a secure channel's request is decrypted, and each address may open a
//! few secure channels a second (the patched async-opcua-server,
//! `vendor/README.md`). Anonymous sessions may browse and subscribe, never
//! acknowledge.
//!
//! - `events.rs`: the event and its fields; `guidance.rs`: the guidance
//!   properties and lateness; `machinery.rs`: the cell's
//!   `MachineryItemState` (OPC UA for Machinery) following its machine state; `filters.rs`: the fields a
//!   client's event filter may name, and the filters over a real event;
//!   `conditions.rs`: the conditions kept from the alarm payloads; `methods.rs`: the methods
//!   (Acknowledge, ConditionRefresh, Disable/Enable, shelving); `users.rs`: the users file, passwords.
//!
//! Not here: the sink that feeds it (`sinks::alarm_server`), the loop's
//! side of an acknowledgement (`cell/session.rs`).

mod conditions;
pub(crate) mod config;
mod events;
mod filters;
mod guidance;
mod machinery;
mod methods;
pub mod users;

use std::future::Future;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use opcua::crypto::SecurityPolicy;
use opcua::server::address_space::{
    EventNotifier, ObjectBuilder, ObjectTypeBuilder, VariableBuilder,
};
use opcua::server::diagnostics::{DiagnosticsNodeManagerBuilder, NamespaceMetadata};
use opcua::server::node_manager::memory::{
    simple_node_manager, InMemoryNodeManager, InMemoryNodeManagerBuilder, SimpleNodeManager,
};
use opcua::server::{ServerBuilder, ServerUserToken, ANONYMOUS_USER_TOKEN_ID};
use opcua::types::{
    DataTypeId, MessageSecurityMode, NodeId, ObjectId, ObjectTypeId, QualifiedName,
    ReferenceTypeId, VariableTypeId,
};
use tokio::net::TcpListener;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use self::config::AlarmServerConfig;
use crate::step::{CellStep, SessionCommand};
use conditions::{Conditions, Served};
use machinery::ItemState;
use methods::{AlarmCore, AlarmCoreBuilder};
use users::{Users, UsersError};

/// The node manager of the cell's namespace.
const NODES: &str = "cellwatch-alarms";

/// The endpoint's user token id for user names (the authenticator
/// decides; the library wants an id).
const USER_TOKEN_ID: &str = "cellwatch-users";

/// How many acknowledgements may wait for the cell loop.
pub const ACK_QUEUE: usize = 16;

/// How many events a client's event item keeps between two publishes: the
/// queue of an item asking 0 or 1 (Python asyncua's default; the patched
/// async-opcua-server, `vendor/README.md`) and the most any may ask. A
/// refresh sends every retained condition at once, between its start and
/// end.
const EVENT_QUEUE: usize = 1_000;

/// Why the alarm server cannot start.
#[derive(Debug, thiserror::Error)]
pub enum AlarmServerError {
    /// The users file is unusable.
    #[error(transparent)]
    Users(#[from] UsersError),
    /// The address cannot be listened on.
    #[error("alarm server: cannot listen on {addr}: {source}")]
    Listen {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The server cannot be built (its PKI directory, its key).
    #[error("alarm server: {0}")]
    Build(String),
}

/// A running alarm server.
pub struct AlarmServer {
    conditions: Arc<Conditions>,
    /// The cell's `MachineryItemState`.
    item_state: Arc<ItemState>,
    /// The running server's own (its sessions).
    info: Arc<opcua::server::ServerInfo>,
    /// Its users, as read at start.
    users: Users,
    addr: SocketAddr,
    /// Runs the server until the agent stops.
    task: JoinHandle<()>,
}

impl AlarmServer {
    /// Serves the alarms of `cell` as `config` says; acknowledgements go
    /// to `acks` (the cell loop's); stops when `shutdown` completes.
    ///
    /// # Errors
    /// The users file, the address or the PKI directory is unusable.
    pub async fn start(
        cell: &str,
        config: &AlarmServerConfig,
        acks: mpsc::Sender<SessionCommand>,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> Result<AlarmServer, AlarmServerError> {
        let users = Users::load(&config.users_file)?;
        let listener =
            TcpListener::bind(config.listen)
                .await
                .map_err(|source| AlarmServerError::Listen {
                    addr: config.listen,
                    source,
                })?;
        let addr = listener
            .local_addr()
            .map_err(|e| AlarmServerError::Build(e.to_string()))?;
        let conditions = Arc::new(Conditions::new(cell));
        let namespace = format!("urn:cellwatch:alarms:{cell}");
        let key_existed = crate::sources::pki::own_key(&config.pki_dir).exists();
        let tokens: &[&str] = &[ANONYMOUS_USER_TOKEN_ID, USER_TOKEN_ID];
        let mut builder = ServerBuilder::new()
            // Namespace 0's manager wrapped (the condition methods), then
            // the diagnostics and the cell's namespace as usual.
            .without_node_managers()
            .with_node_manager(InMemoryNodeManagerBuilder::new(AlarmCoreBuilder {
                conditions: conditions.clone(),
                users: users.clone(),
                acks,
            }))
            .with_node_manager(DiagnosticsNodeManagerBuilder)
            .with_node_manager(simple_node_manager(
                NamespaceMetadata {
                    namespace_uri: namespace.clone(),
                    ..Default::default()
                },
                NODES,
            ))
            .with_node_manager(simple_node_manager(
                NamespaceMetadata {
                    namespace_uri: cellwatch_models::machinery::NAMESPACE.into(),
                    ..Default::default()
                },
                machinery::MACHINERY,
            ))
            .with_authenticator(Arc::new(users.clone()))
            .application_name(format!("cellwatch alarms of {cell}"))
            .application_uri(format!("urn:cellwatch:alarm-server:{cell}"))
            .product_uri("urn:cellwatch")
            // For the count of its sessions (`sessions`).
            .diagnostics_enabled(true);
        builder
            .limits_mut()
            .subscriptions
            .max_monitored_item_queue_size = EVENT_QUEUE;
        let (server, handle) = crate::sources::pki::served_from(builder, &config.pki_dir, addr)
            .add_user_token(USER_TOKEN_ID, ServerUserToken::user_pass(USER_TOKEN_ID, ""))
            .add_endpoint(
                "basic256sha256_sign_encrypt",
                (
                    "/",
                    SecurityPolicy::Basic256Sha256,
                    MessageSecurityMode::SignAndEncrypt,
                    tokens,
                ),
            )
            .build()
            .map_err(AlarmServerError::Build)?;
        crate::sources::pki::protect_own_key(&config.pki_dir, key_existed)
            .map_err(|e| AlarmServerError::Build(e.to_string()))?;
        let missing = |what: &str| AlarmServerError::Build(format!("{what} is missing"));
        let ns = handle
            .get_namespace_index(&namespace)
            .ok_or_else(|| missing("the cell's namespace"))?;
        let nodes = handle
            .node_managers()
            .get_by_name::<SimpleNodeManager>(NODES)
            .ok_or_else(|| missing("the cell's node manager"))?;
        let core = handle
            .node_managers()
            .get_of_type::<InMemoryNodeManager<AlarmCore>>()
            .ok_or_else(|| missing("the core node manager"))?;
        let notifier = NodeId::new(ns, cell);
        let event_type = NodeId::new(ns, "CellAlarmType");
        declare(&nodes, ns, cell, &notifier, &event_type);
        let machinery_ns = handle
            .get_namespace_index(cellwatch_models::machinery::NAMESPACE)
            .ok_or_else(|| missing("the Machinery namespace"))?;
        let machinery_nodes = handle
            .node_managers()
            .get_by_name::<SimpleNodeManager>(machinery::MACHINERY)
            .ok_or_else(|| missing("the Machinery node manager"))?;
        let item_state = Arc::new(ItemState::declare(
            &machinery_nodes,
            machinery_ns,
            nodes.clone(),
            ns,
            cell,
            &notifier,
            handle.subscriptions().clone(),
        ));
        filters::accept_condition_fields(&mut handle.type_tree().write(), ns, &event_type);
        let served = Served {
            ns,
            notifier,
            event_type,
            subscriptions: handle.subscriptions().clone(),
            nodes,
            core: core.address_space().clone(),
        };
        if conditions.served.set(served).is_err() {
            return Err(AlarmServerError::Build("served twice".into()));
        }
        let stop = handle.clone();
        let late = conditions.clone();
        let task = tokio::spawn(async move {
            tokio::select! {
                r = server.run_with(listener) => {
                    if let Err(e) = r {
                        tracing::error!(error = %e, "alarm server stopped");
                    }
                }
                () = shutdown => stop.cancel(),
                () = mark_overdue(&late) => {}
            }
        });
        tracing::info!(cell, %addr, "serving the cell's alarms over OPC UA");
        Ok(AlarmServer {
            conditions,
            item_state,
            info: handle.info().clone(),
            users,
            addr,
            task,
        })
    }

    /// Where it listens (with port 0, the port the system gave).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// How many sessions its clients hold open now.
    pub fn sessions(&self) -> Arc<dyn Fn() -> i64 + Send + Sync> {
        let info = self.info.clone();
        Arc::new(move || {
            let count = info.diagnostics.summary.get(
                opcua::types::VariableId::Server_ServerDiagnostics_ServerDiagnosticsSummary_CurrentSessionCount,
            );
            match count.and_then(|v| v.value) {
                Some(opcua::types::Variant::UInt32(n)) => i64::from(n),
                _ => 0,
            }
        })
    }

    /// What became of the secure channels its clients asked for: each
    /// decrypted only from an address within its share, under the
    /// endpoint's policy, with a trusted certificate (the patched
    /// async-opcua-server, `vendor/README.md`).
    pub fn secure_channels(&self) -> opcua::server::SecureChannelCounts {
        self.info.secure_channels()
    }

    /// Its users, as read at start.
    pub fn users(&self) -> &Users {
        &self.users
    }

    /// What the sink calls with each step: its alarm transitions and, when
    /// it changed, the machine state.
    pub fn feed(&self) -> Arc<dyn Fn(&CellStep) + Send + Sync> {
        let conditions = self.conditions.clone();
        let item_state = self.item_state.clone();
        Arc::new(move |step| {
            for a in &step.alarms {
                conditions.apply(&a.payload);
            }
            if let Some(s) = &step.state {
                item_state.set(s.state);
            }
        })
    }

    /// The server's task, which ends after the agent's stop.
    pub fn task(self) -> JoinHandle<()> {
        self.task
    }
}

/// Marks the conditions overdue as their response times pass, for ever:
/// asleep until the next falls due or a condition changes.
async fn mark_overdue(conditions: &Conditions) {
    loop {
        let changed = conditions.overdue.changed.notified();
        let next = conditions.mark_overdue(crate::clock::now_ms());
        match next {
            Some(at) => {
                let wait = Duration::from_millis(at.saturating_sub(crate::clock::now_ms()));
                tokio::select! {
                    () = tokio::time::sleep(wait) => {}
                    () = changed => {}
                }
            }
            None => changed.await,
        }
    }
}

/// `CellAlarmType` (with `Culprits`, `Consequence` and the guidance of
/// [`guidance::PROPERTIES`]) and the cell's object, a notifier the
/// `Server` object reaches.
fn declare(nodes: &SimpleNodeManager, ns: u16, cell: &str, cell_node: &NodeId, ty: &NodeId) {
    let space = nodes.address_space();
    let mut space = space.write();
    ObjectTypeBuilder::new(ty, "CellAlarmType", "CellAlarmType")
        .subtype_of(ObjectTypeId::AlarmConditionType)
        .insert(&mut *space);
    let own = [
        ("Culprits", DataTypeId::String),
        ("Consequence", DataTypeId::String),
    ];
    let none = guidance::Guidance::default();
    for (name, data_type) in own.into_iter().chain(guidance::PROPERTIES) {
        let initial = match data_type {
            DataTypeId::String => "".into(),
            _ => none.value(name),
        };
        VariableBuilder::new(
            &NodeId::new(ns, format!("CellAlarmType.{name}")),
            QualifiedName::new(ns, name),
            name,
        )
        .data_type(data_type)
        .value(initial)
        .property_of(ty.clone())
        .has_type_definition(VariableTypeId::PropertyType)
        .has_modelling_rule(ObjectId::ModellingRule_Mandatory)
        .insert(&mut *space);
    }
    ObjectBuilder::new(cell_node, cell, cell)
        .event_notifier(EventNotifier::SUBSCRIBE_TO_EVENTS)
        .organized_by(ObjectId::ObjectsFolder)
        .has_type_definition(ObjectTypeId::BaseObjectType)
        .insert(&mut *space);
    space.insert_reference(
        &ObjectId::Server.into(),
        cell_node,
        ReferenceTypeId::HasNotifier,
    );
}
