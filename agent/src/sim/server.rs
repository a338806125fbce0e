//! A simulated PLC as an OPC UA server: boolean variables in one namespace,
//! named by PLC address (`ns=2;s=X0.06`), set by the simulation.
//!
//! Real OPC UA security: the server's own key pair in its PKI directory,
//! a Basic256Sha256 + SignAndEncrypt endpoint, client certificates trusted
//! only from `trusted/` (and an endpoint without security only on request).

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use opcua::crypto::SecurityPolicy;
use opcua::server::address_space::{NodeBase, NodeType, Variable};
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{simple_node_manager, SimpleNodeManager};
use opcua::server::{
    ServerBuilder, ServerHandle, SubscriptionCache, SubscriptionState, ANONYMOUS_USER_TOKEN_ID,
};
use opcua::types::{
    AttributeId, DataValue, DateTime, MessageSecurityMode, NodeId, StatusCode, Variant,
};
use tokio::net::TcpListener;

use super::SimError;

/// Session numbers [`SimServer::subscriptions`] looks up.
pub const SESSIONS_SCANNED: u32 = 100_000;

/// The name of the decoy namespace's node manager.
const DECOY: &str = "decoy";

/// Adds a folder `app` with `variables` (their opposite values when
/// `invert`) to `manager`'s namespace `ns`.
fn add_variables(
    manager: &SimpleNodeManager,
    ns: u16,
    app: &str,
    title: &str,
    variables: &[(String, bool)],
    invert: bool,
) {
    let space = manager.address_space();
    let mut space = space.write();
    let folder = NodeId::new(ns, app);
    space.add_folder(&folder, title, title, &NodeId::objects_folder_id());
    let vars = variables
        .iter()
        .map(|(name, v)| {
            Variable::new(
                &NodeId::new(ns, name.as_str()),
                name.as_str(),
                name.as_str(),
                *v != invert,
            )
        })
        .collect();
    space.add_variables(vars, &folder);
}

/// Monitored items, each as (subscription id, item id).
type Items = HashSet<(u32, u32)>;

/// The writes clients made to a simulated PLC's writable variables.
#[derive(Clone, Default)]
pub struct WriteLog {
    inner: Arc<Mutex<Written>>,
}

/// Every write in order, and each variable's last value.
type Written = (Vec<(String, bool)>, std::collections::HashMap<String, bool>);

impl WriteLog {
    fn push(&self, name: &str, on: bool) {
        if let Ok(mut g) = self.inner.lock() {
            g.0.push((name.to_string(), on));
            g.1.insert(name.to_string(), on);
        }
    }

    /// Every write so far, in order: variable and value.
    pub fn writes(&self) -> Vec<(String, bool)> {
        self.inner.lock().map(|g| g.0.clone()).unwrap_or_default()
    }

    /// The last value written to `name`, if any.
    pub fn value(&self, name: &str) -> Option<bool> {
        self.inner.lock().ok()?.1.get(name).copied()
    }
}

/// How to serve a simulated PLC.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Address to listen on; port 0 picks one.
    pub listen: SocketAddr,
    /// The server's PKI directory.
    pub pki_dir: PathBuf,
    /// Also offer an endpoint without security.
    pub insecure: bool,
    /// A decoy namespace with this URI, registered before the PLC's: the
    /// same variable names with the opposite values, as a server that
    /// renumbered its namespaces could hold at the index the PLC had.
    pub decoy: Option<String>,
}

/// A running simulated PLC.
#[derive(Clone)]
pub struct SimServer {
    handle: ServerHandle,
    manager: Arc<SimpleNodeManager>,
    decoy: Option<(Arc<SimpleNodeManager>, u16)>,
    /// Variables deleted ([`SimServer::delete`]): no longer written.
    deleted: Arc<Mutex<HashSet<String>>>,
    /// The monitored items (subscription, item) that a node deleted in
    /// silence left behind ([`SimServer::delete_quietly`]): they never hear
    /// of it again.
    deaf: Arc<Mutex<HashMap<NodeId, Items>>>,
    subscriptions: Arc<SubscriptionCache>,
    ns: u16,
    addr: SocketAddr,
    /// The folder the variables are in.
    app: String,
    /// The clients it dials (reverse connect), by target id.
    dialled: Arc<Mutex<Vec<String>>>,
}

impl SimServer {
    /// Serves `variables` (name, initial value) as application `app`
    /// (`urn:cellwatch:sim:<app>`), tags in namespace
    /// `urn:cellwatch:sim:<app>:plc`.
    ///
    /// # Errors
    /// The port cannot be bound or the server cannot be built.
    pub async fn start(
        options: &SimOptions,
        app: &str,
        title: &str,
        variables: &[(String, bool)],
    ) -> Result<SimServer, SimError> {
        Self::start_sending_at_most(options, app, title, variables, 0).await
    }

    /// [`SimServer::start`], a server that sends at most
    /// `max_notifications` notifications a publish whatever a client asks
    /// (0: the library's limit), as some PLCs' servers do.
    ///
    /// # Errors
    /// The port cannot be bound or the server cannot be built.
    pub async fn start_sending_at_most(
        options: &SimOptions,
        app: &str,
        title: &str,
        variables: &[(String, bool)],
        max_notifications: u64,
    ) -> Result<SimServer, SimError> {
        let listener =
            TcpListener::bind(options.listen)
                .await
                .map_err(|source| SimError::Listen {
                    addr: options.listen,
                    source,
                })?;
        let addr = listener.local_addr().map_err(SimError::LocalAddr)?;
        let namespace = format!("urn:cellwatch:sim:{app}:plc");
        let key_existed = crate::sources::pki::own_key(&options.pki_dir).exists();
        let tokens: &[&str] = &[ANONYMOUS_USER_TOKEN_ID];
        let mut builder = ServerBuilder::new()
            .application_name(title)
            .application_uri(format!("urn:cellwatch:sim:{app}"))
            .product_uri("urn:cellwatch");
        // Its key pair made here, so that a failure stops the start.
        crate::sources::pki::own_key_pair(
            &options.pki_dir,
            title,
            &format!("urn:cellwatch:sim:{app}"),
        )?;
        builder = crate::sources::pki::served_from(builder, &options.pki_dir, addr);
        if let Some(uri) = &options.decoy {
            builder = builder.with_node_manager(simple_node_manager(
                NamespaceMetadata {
                    namespace_uri: uri.clone(),
                    ..Default::default()
                },
                DECOY,
            ));
        }
        builder = builder
            .add_endpoint(
                "basic256sha256_sign_encrypt",
                (
                    "/",
                    SecurityPolicy::Basic256Sha256,
                    MessageSecurityMode::SignAndEncrypt,
                    tokens,
                ),
            )
            .with_node_manager(simple_node_manager(
                NamespaceMetadata {
                    namespace_uri: namespace.clone(),
                    ..Default::default()
                },
                app,
            ));
        if options.insecure {
            builder = builder.add_endpoint(
                "none",
                ("/", SecurityPolicy::None, MessageSecurityMode::None, tokens),
            );
        }
        // Sampling interval 0 means every change, as the PLC makes it
        // (exception-based), as OPC UA servers of discrete signals do.
        builder.limits_mut().subscriptions.min_sampling_interval_ms = 0.0;
        builder
            .limits_mut()
            .subscriptions
            .max_monitored_item_queue_size = 1000;
        if max_notifications > 0 {
            builder
                .limits_mut()
                .subscriptions
                .max_notifications_per_publish = max_notifications;
        }
        // A client it connects to (reverse connect) that was not listening
        // is tried again a second later.
        builder.config_mut().reverse_connect_failure_delay_ms = 1_000;
        let (server, handle) = builder.build().map_err(SimError::Build)?;
        crate::sources::pki::protect_own_key(&options.pki_dir, key_existed)?;
        let manager = handle
            .node_managers()
            .get_by_name::<SimpleNodeManager>(app)
            .ok_or(SimError::Missing("the simulator's node manager"))?;
        let ns = handle
            .get_namespace_index(&namespace)
            .ok_or(SimError::Missing("the simulator's namespace"))?;
        add_variables(&manager, ns, app, title, variables, false);
        let decoy = match &options.decoy {
            None => None,
            Some(uri) => {
                let decoy = handle
                    .node_managers()
                    .get_by_name::<SimpleNodeManager>(DECOY)
                    .ok_or(SimError::Missing("the decoy node manager"))?;
                let index = handle
                    .get_namespace_index(uri)
                    .ok_or(SimError::Missing("the decoy namespace"))?;
                add_variables(&decoy, index, DECOY, "Decoy", variables, true);
                Some((decoy, index))
            }
        };
        tokio::spawn(async move {
            if let Err(e) = server.run_with(listener).await {
                tracing::error!(error = %e, "simulated PLC server stopped");
            }
        });
        let subscriptions = handle.subscriptions().clone();
        Ok(SimServer {
            handle,
            manager,
            decoy,
            deleted: Arc::default(),
            deaf: Arc::default(),
            subscriptions,
            ns,
            addr,
            app: app.to_string(),
            dialled: Arc::default(),
        })
    }

    /// Writes values, all with the same source timestamp (now).
    ///
    /// # Errors
    /// A name that is not a variable of this server.
    pub fn set(&self, values: &[(String, bool)]) -> Result<(), SimError> {
        self.set_at(values, DateTime::now())
    }

    /// Writes values that changed at `at` (their source timestamp), as a PLC
    /// stamps a change when it happens, not when it is read.
    ///
    /// # Errors
    /// A name that is not a variable of this server.
    pub fn set_at(&self, values: &[(String, bool)], at: DateTime) -> Result<(), SimError> {
        self.write_named(values.iter().map(|(s, v)| (s.as_str(), *v, at)))
    }

    /// Writes values, each with its own source timestamp, in one write: the
    /// server takes them in one publishing cycle, as a PLC's changes of one
    /// scan.
    ///
    /// # Errors
    /// A name that is not a variable of this server.
    pub fn set_each_at(&self, values: &[(String, bool, DateTime)]) -> Result<(), SimError> {
        self.write_named(values.iter().map(|(s, v, at)| (s.as_str(), *v, *at)))
    }

    /// Writes named values with their source timestamps, but to the
    /// variables deleted.
    fn write_named<'a>(
        &self,
        values: impl Iterator<Item = (&'a str, bool, DateTime)>,
    ) -> Result<(), SimError> {
        let deleted = self.deleted.lock().map_err(|_| SimError::Poisoned)?;
        let values: Vec<(NodeId, DataValue)> = values
            .filter(|(s, _, _)| !deleted.contains(*s))
            .map(|(s, v, at)| (NodeId::new(self.ns, s), DataValue::new_at(v, at)))
            .collect();
        self.write(&values)
    }

    /// Writes values to their nodes, notifying subscribers (but the deaf
    /// ones a silent deletion left behind).
    fn write(&self, values: &[(NodeId, DataValue)]) -> Result<(), SimError> {
        let deaf = self.deaf.lock().map_err(|_| SimError::Poisoned)?;
        let (quiet, loud): (Vec<_>, Vec<_>) =
            values.iter().partition(|(n, _)| deaf.contains_key(n));
        self.manager
            .set_values(
                &self.subscriptions,
                loud.into_iter().map(|(n, v)| (n, None, v.clone())),
            )
            .map_err(|status| SimError::Update {
                what: "the simulated PLC".into(),
                status,
            })?;
        if quiet.is_empty() {
            return Ok(());
        }
        {
            let space = self.manager.address_space();
            let mut space = space.write();
            for (node, value) in &quiet {
                if let Some(NodeType::Variable(v)) = space.find_mut(node) {
                    v.set_data_value(value.clone());
                }
            }
        }
        let mut notifier = self.subscriptions.data_notifier();
        for (node, value) in quiet {
            let Some(mut batch) = notifier.notify_for(node, AttributeId::Value) else {
                continue;
            };
            let heard: Vec<_> = batch
                .entries()
                .map(|(h, _)| *h)
                .filter(|h| !deaf[node].contains(&(h.subscription_id, h.monitored_item_id)))
                .collect();
            for h in heard {
                batch.data_value_to_item(value.clone(), &h);
            }
        }
        Ok(())
    }

    /// The decoy namespace's index, if it has one.
    pub fn decoy_namespace(&self) -> Option<u16> {
        self.decoy.as_ref().map(|(_, ns)| *ns)
    }

    /// Writes values in the decoy namespace.
    ///
    /// # Errors
    /// There is no decoy, or a name is not a variable of it.
    pub fn set_decoy(&self, values: &[(String, bool)]) -> Result<(), SimError> {
        let (decoy, ns) = self.decoy.as_ref().ok_or(SimError::NoDecoy)?;
        let values: Vec<(NodeId, DataValue)> = values
            .iter()
            .map(|(s, v)| (NodeId::new(*ns, s.as_str()), DataValue::new_now(*v)))
            .collect();
        decoy
            .set_values(
                &self.subscriptions,
                values.iter().map(|(n, v)| (n, None, v.clone())),
            )
            .map_err(|status| SimError::Update {
                what: "the decoy".into(),
                status,
            })
    }

    /// Deletes a variable, as a server whose configuration changed does;
    /// its monitored items get `BadNodeIdUnknown`, as from a server that
    /// samples its nodes, and never hear of it again, even once it is
    /// added back ([`SimServer::restore`]).
    ///
    /// # Errors
    /// No such variable.
    pub fn delete(&self, name: &str) -> Result<(), SimError> {
        let (node, items) = self.remove(name)?;
        let mut gone = DataValue::null();
        gone.status = Some(StatusCode::BadNodeIdUnknown);
        gone.server_timestamp = Some(DateTime::now());
        self.subscriptions
            .notify_data_change([(gone, &node, AttributeId::Value)].into_iter());
        self.deafen(node, items)
    }

    /// The monitored items on `node` now: (subscription, item).
    fn items_on(&self, node: &NodeId) -> HashSet<(u32, u32)> {
        let mut notifier = self.subscriptions.data_notifier();
        notifier
            .notify_for(node, AttributeId::Value)
            .map(|b| {
                b.entries()
                    .map(|(h, _)| (h.subscription_id, h.monitored_item_id))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// `items` never hear of `node` again.
    fn deafen(&self, node: NodeId, items: HashSet<(u32, u32)>) -> Result<(), SimError> {
        self.deaf
            .lock()
            .map_err(|_| SimError::Poisoned)?
            .entry(node)
            .or_default()
            .extend(items);
        Ok(())
    }

    /// Tells a variable's monitored items it has no data (`GoodNoData`, no
    /// value) and then nothing more, as a server whose device had nothing
    /// to give at the time: those items never hear of the node again;
    /// items created after do, and read what it holds.
    pub fn no_data(&self, name: &str) {
        let node = NodeId::new(self.ns, name);
        let items = self.items_on(&node);
        let mut none = DataValue::null();
        none.status = Some(StatusCode::GoodNoData);
        none.source_timestamp = Some(DateTime::now());
        self.subscriptions
            .notify_data_change([(none, &node, AttributeId::Value)].into_iter());
        let _ = self.deafen(node, items);
    }

    /// Deletes a variable and says nothing to its monitored items, which
    /// stay on the server and never hear of the node again, even once it
    /// is added back ([`SimServer::restore`]) — as servers do that lose
    /// track of their items when a PLC download recreates a data block.
    ///
    /// # Errors
    /// No such variable.
    pub fn delete_quietly(&self, name: &str) -> Result<(), SimError> {
        let (node, items) = self.remove(name)?;
        self.deafen(node, items)
    }

    /// Takes a variable out of the address space; no longer written. Its
    /// node, and the monitored items on it.
    fn remove(&self, name: &str) -> Result<(NodeId, Items), SimError> {
        let node = NodeId::new(self.ns, name);
        let items = self.items_on(&node);
        self.manager
            .address_space()
            .write()
            .delete(&node, true)
            .ok_or_else(|| SimError::NoVariable { name: name.into() })?;
        self.deleted
            .lock()
            .map_err(|_| SimError::Poisoned)?
            .insert(name.to_string());
        Ok((node, items))
    }

    /// Deletes a variable and adds it back holding `value` in one step (no
    /// client sees it missing), telling its monitored items nothing: they
    /// never hear of it again — a PLC download that recreates a data
    /// block, on a server that loses track of its items.
    ///
    /// # Errors
    /// No such variable.
    pub fn recreate_quietly(&self, name: &str, value: Variant) -> Result<(), SimError> {
        let node = NodeId::new(self.ns, name);
        let items = self.items_on(&node);
        {
            let space = self.manager.address_space();
            let mut space = space.write();
            space
                .delete(&node, true)
                .ok_or_else(|| SimError::NoVariable { name: name.into() })?;
            let var = Variable::new(&node, name, name, value.clone());
            space.add_variables(vec![var], &NodeId::new(self.ns, self.app.as_str()));
        }
        self.deafen(node.clone(), items)?;
        self.write(&[(node, DataValue::new_now(value))])
    }

    /// Adds a deleted variable back, holding `value`, as a PLC download
    /// does: new monitored items see it; those a silent deletion left
    /// behind do not.
    ///
    /// # Errors
    /// The variable exists.
    pub fn restore(&self, name: &str, value: Variant) -> Result<(), SimError> {
        let node = NodeId::new(self.ns, name);
        {
            let space = self.manager.address_space();
            let mut space = space.write();
            if space.find(&node).is_some() {
                return Err(SimError::Exists { name: name.into() });
            }
            let var = Variable::new(&node, name, name, value.clone());
            space.add_variables(vec![var], &NodeId::new(self.ns, self.app.as_str()));
        }
        self.deleted
            .lock()
            .map_err(|_| SimError::Poisoned)?
            .remove(name);
        self.write(&[(node, DataValue::new_now(value))])
    }

    /// How many live subscriptions the server holds for all its sessions; a
    /// subscription that went without publish requests for its lifetime is
    /// closed and not counted (the server keeps it until a publish request
    /// takes its `BadTimeout` status change).
    ///
    /// The server numbers sessions process-wide from 1 and keeps no list of
    /// them that can be read; the first [`SESSIONS_SCANNED`] numbers are
    /// looked up.
    pub fn subscriptions(&self) -> usize {
        (1..=SESSIONS_SCANNED)
            .filter_map(|id| self.subscriptions.get_session_subscriptions(id))
            .map(|s| {
                let s = s.lock();
                s.subscription_ids()
                    .into_iter()
                    .filter(|&id| {
                        s.get(id)
                            .is_some_and(|s| s.state() != SubscriptionState::Closed)
                    })
                    .count()
            })
            .sum()
    }

    /// Says `level` as the server's `ServiceLevel` (OPC UA redundancy:
    /// 200–255 healthy, 2–199 degraded), to clients reading it and those
    /// subscribed to it.
    pub fn set_service_level(&self, level: u8) {
        self.handle.set_service_level(level);
    }

    /// Adds a variable of any scalar type (a data register) beside the
    /// contacts, with an optional description (what `cellwatch discover`
    /// prints as the comment).
    ///
    /// # Errors
    /// A variable of that name exists.
    pub fn add_register(
        &self,
        name: &str,
        value: Variant,
        description: &str,
    ) -> Result<(), SimError> {
        let node = NodeId::new(self.ns, name);
        let space = self.manager.address_space();
        let mut space = space.write();
        if space.find(&node).is_some() {
            return Err(SimError::Exists { name: name.into() });
        }
        let mut var = Variable::new(&node, name, name, value);
        if !description.is_empty() {
            var.set_description(description.into());
        }
        space.add_variables(vec![var], &NodeId::new(self.ns, self.app.as_str()));
        Ok(())
    }

    /// Writes registers' values (source timestamp now).
    ///
    /// # Errors
    /// A name that is not a variable of this server.
    pub fn set_registers(&self, values: &[(String, Variant)]) -> Result<(), SimError> {
        let now = DateTime::now();
        let deleted = self.deleted.lock().map_err(|_| SimError::Poisoned)?.clone();
        let values: Vec<(NodeId, DataValue)> = values
            .iter()
            .filter(|(s, _)| !deleted.contains(s))
            .map(|(s, v)| {
                (
                    NodeId::new(self.ns, s.as_str()),
                    DataValue::new_at(v.clone(), now),
                )
            })
            .collect();
        self.write(&values)
    }

    /// Marks a variable's value as bad (a broken sensor wire).
    ///
    /// # Errors
    /// The server refuses the update.
    pub fn set_bad(&self, name: &str, value: bool) -> Result<(), SimError> {
        let mut dv = DataValue::new_now(value);
        dv.status = Some(StatusCode::BadSensorFailure);
        let node = NodeId::new(self.ns, name);
        self.manager
            .set_value(&self.subscriptions, &node, None, dv)
            .map_err(|status| SimError::Update {
                what: name.into(),
                status,
            })
    }

    /// The endpoint URL clients connect to.
    pub fn endpoint(&self) -> String {
        format!("opc.tcp://{}/", self.addr)
    }

    /// The address the server listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Dials out to a client listening at `client` (OPC UA reverse
    /// connect), saying its endpoint URL, and again whenever that
    /// connection ends, as a PLC in a DMZ reaches its clients.
    pub fn reverse_connect(&self, client: SocketAddr) {
        let id = format!("client-{client}");
        self.dialled
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(id.clone());
        self.handle
            .add_reverse_connect_target(opcua::server::ReverseConnectTargetConfig {
                address: client,
                endpoint_url: self.endpoint(),
                id,
            });
    }

    /// The namespace index of the tags.
    pub fn namespace(&self) -> u16 {
        self.ns
    }

    /// Lets clients write these Boolean variables (a remote module's push
    /// buttons). Every write a client makes is logged, in order, whatever
    /// the simulation does with it; the value is readable at once and
    /// published to subscribers.
    ///
    /// # Errors
    /// A name that is not a variable of this server.
    pub fn writable(&self, names: &[&str]) -> Result<WriteLog, SimError> {
        let log = WriteLog::default();
        for &name in names {
            let node = NodeId::new(self.ns, name);
            {
                let space = self.manager.address_space();
                let mut space = space.write();
                let var = space
                    .find_mut(&node)
                    .and_then(|n| match n {
                        opcua::server::address_space::NodeType::Variable(v) => Some(v),
                        _ => None,
                    })
                    .ok_or_else(|| SimError::NoVariable { name: name.into() })?;
                var.set_writable(true);
                var.set_user_access_level(
                    opcua::server::address_space::AccessLevel::CURRENT_READ
                        | opcua::server::address_space::AccessLevel::CURRENT_WRITE,
                );
            }
            let (log_w, log_r) = (log.clone(), log.clone());
            let name_w = name.to_string();
            let name_r = name.to_string();
            let manager = self.manager.clone();
            let subscriptions = self.subscriptions.clone();
            let target = node.clone();
            // The server holds its address space while it calls this: the
            // node's own value (what subscribers get) is set just after.
            self.manager
                .inner()
                .add_write_callback(node.clone(), move |value, _| {
                    let Some(Variant::Boolean(on)) = value.value else {
                        return StatusCode::BadTypeMismatch;
                    };
                    log_w.push(&name_w, on);
                    let (manager, subscriptions, target) =
                        (manager.clone(), subscriptions.clone(), target.clone());
                    tokio::spawn(async move {
                        let _ = manager.set_value(
                            &subscriptions,
                            &target,
                            None,
                            DataValue::new_now(on),
                        );
                    });
                    StatusCode::Good
                });
            self.manager
                .inner()
                .add_read_callback(node, move |_, _, _| {
                    Ok(DataValue::new_now(log_r.value(&name_r).unwrap_or(false)))
                });
        }
        Ok(log)
    }

    /// Stops the server; connected clients see the connection drop, and
    /// it dials none any more.
    pub fn stop(&self) {
        for id in self
            .dialled
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .drain(..)
        {
            self.handle.remove_reverse_connect_target(&id);
        }
        self.handle.cancel();
    }
}
