//! The load server: an async-opcua server (this build's own, release
//! profile) with `noise` Boolean variables toggled at a fixed rate and ten
//! limit switches opened one at a time, each opening a fault both
//! subscribers must report.
//!
//! Variables are numeric nodes of namespace [`NAMESPACE`]: noise `i=1..=N`
//! (`N_<i>`), limit switches `i=2000000+k` (`LS_<k>`). Every change carries
//! the time it was made as its source timestamp, so a subscriber's latency
//! is its receive time minus that stamp (one machine, one clock).

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use anyhow::{anyhow, Context};
use opcua::crypto::SecurityPolicy;
use opcua::server::address_space::Variable;
use opcua::server::diagnostics::NamespaceMetadata;
use opcua::server::node_manager::memory::{simple_node_manager, SimpleNodeManager};
use opcua::server::{ServerBuilder, ServerHandle, SubscriptionCache, ANONYMOUS_USER_TOKEN_ID};
use opcua::types::{DataValue, DateTime, MessageSecurityMode, NodeId};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};

/// The load server's namespace.
pub const NAMESPACE: &str = "urn:cellwatch:bench:load";

/// How many limit switches the fault check reads.
pub const SWITCHES: usize = 10;

/// The numeric id of limit switch `k`.
pub fn switch_id(k: usize) -> u32 {
    2_000_000 + k as u32
}

/// How long the generator sleeps between two batches of changes.
const TICK: Duration = Duration::from_millis(5);

/// An injected fault: which switch opened, and when (its source timestamp).
#[derive(Debug, Clone, Copy)]
pub struct Fault {
    /// The limit switch.
    pub switch: usize,
    /// When it opened.
    pub at: SystemTime,
}

/// What the generator did.
#[derive(Debug, Default)]
pub struct Produced {
    /// Value changes made (noise and switches), each one notification.
    pub changes: AtomicU64,
    /// The faults injected, in order.
    pub faults: Mutex<Vec<Fault>>,
    /// The most the generator fell behind its schedule, µs.
    pub max_lag_us: AtomicU64,
}

/// A running load server.
pub struct LoadServer {
    handle: ServerHandle,
    manager: Arc<SimpleNodeManager>,
    subscriptions: Arc<SubscriptionCache>,
    noise: Vec<NodeId>,
    switches: Vec<NodeId>,
    /// The noise variables' current values.
    values: Vec<bool>,
    addr: SocketAddr,
    /// How much lower than the benchmark's the server's and the
    /// generator's threads run (niceness added).
    nice: i32,
    /// The server's own runtime, its threads at `nice`; shut down on drop.
    runtime: Option<tokio::runtime::Runtime>,
}

impl Drop for LoadServer {
    fn drop(&mut self) {
        self.handle.cancel();
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_background();
        }
    }
}

/// Lowers the calling thread's priority by `nice` (on Linux niceness is
/// per thread, and threads it starts inherit it).
fn lower_priority(nice: i32) {
    if nice != 0 {
        if let Err(e) = rustix::process::nice(nice) {
            eprintln!("load server: cannot lower a thread's priority by {nice}: {e}");
        }
    }
}

impl LoadServer {
    /// Serves `noise` variables (random initial values from `seed`) and the
    /// limit switches (closed) on `listen`, with endpoints None and
    /// Basic256Sha256 + SignAndEncrypt; client certificates are trusted
    /// from `pki/trusted/` only. The server runs on its own runtime, and
    /// it and the generator at `nice` below the benchmark (0: the same
    /// priority): with the server standing in for a PLC on its own
    /// hardware, a positive `nice` keeps it from taking the agent's turn
    /// on a machine they share.
    pub async fn start(
        listen: SocketAddr,
        pki: &Path,
        noise: usize,
        seed: u64,
        nice: i32,
    ) -> anyhow::Result<LoadServer> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("load-server")
            .on_thread_start(move || lower_priority(nice))
            .enable_all()
            .build()
            .context("cannot start the load server's runtime")?;
        let listener = runtime
            .spawn(tokio::net::TcpListener::bind(listen))
            .await?
            .with_context(|| format!("cannot listen on {listen}"))?;
        let addr = listener.local_addr()?;
        let tokens: &[&str] = &[ANONYMOUS_USER_TOKEN_ID];
        let builder = ServerBuilder::new()
            .application_name("cellwatch load server")
            .application_uri("urn:cellwatch:bench:server")
            .product_uri("urn:cellwatch");
        let mut builder = cellwatch::sources::pki::served_from(builder, pki, addr)
            .add_endpoint(
                "basic256sha256_sign_encrypt",
                (
                    "/",
                    SecurityPolicy::Basic256Sha256,
                    MessageSecurityMode::SignAndEncrypt,
                    tokens,
                ),
            )
            .add_endpoint(
                "none",
                ("/", SecurityPolicy::None, MessageSecurityMode::None, tokens),
            )
            .with_node_manager(simple_node_manager(
                NamespaceMetadata {
                    namespace_uri: NAMESPACE.to_owned(),
                    ..Default::default()
                },
                "load",
            ));
        let limits = builder.limits_mut();
        // Requests of 10,000 monitored items, publishes of 10,000 changes.
        limits.max_array_length = 100_000;
        limits.max_message_size = 64 << 20;
        limits.max_chunk_count = 1024;
        limits.subscriptions.min_sampling_interval_ms = 0.0;
        limits.subscriptions.max_monitored_item_queue_size = 1000;
        limits.subscriptions.max_monitored_items_per_sub = noise + SWITCHES + 1000;
        limits.subscriptions.max_notifications_per_publish = 10_000;
        limits.subscriptions.max_queued_notifications = 1_000_000;
        limits.operational.max_monitored_items_per_call = 10_000;
        limits.operational.max_nodes_per_read = 10_000;
        let (server, handle) = builder.build().map_err(|e| anyhow!(e))?;
        let manager = handle
            .node_managers()
            .get_by_name::<SimpleNodeManager>("load")
            .ok_or_else(|| anyhow!("the load node manager is missing"))?;
        let ns = handle
            .get_namespace_index(NAMESPACE)
            .ok_or_else(|| anyhow!("the load namespace is missing"))?;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let values: Vec<bool> = (0..noise).map(|_| rng.gen()).collect();
        let noise_ids: Vec<NodeId> = (1..=noise as u32).map(|i| NodeId::new(ns, i)).collect();
        let switches: Vec<NodeId> = (0..SWITCHES)
            .map(|k| NodeId::new(ns, switch_id(k)))
            .collect();
        {
            let space = manager.address_space();
            let mut space = space.write();
            let folder = NodeId::new(ns, "Load");
            space.add_folder(&folder, "Load", "Load", &NodeId::objects_folder_id());
            let mut vars: Vec<Variable> = noise_ids
                .iter()
                .zip(&values)
                .enumerate()
                .map(|(i, (id, v))| {
                    let name = format!("N_{}", i + 1);
                    Variable::new(id, name.as_str(), name.as_str(), *v)
                })
                .collect();
            vars.extend(switches.iter().enumerate().map(|(k, id)| {
                let name = format!("LS_{k}");
                Variable::new(id, name.as_str(), name.as_str(), true)
            }));
            space.add_variables(vars, &folder);
        }
        runtime.spawn(async move {
            if let Err(e) = server.run_with(listener).await {
                eprintln!("load server stopped: {e}");
            }
        });
        let subscriptions = handle.subscriptions().clone();
        Ok(LoadServer {
            handle,
            manager,
            subscriptions,
            noise: noise_ids,
            switches,
            values,
            addr,
            nice,
            runtime: Some(runtime),
        })
    }

    /// The endpoint URL.
    pub fn endpoint(&self) -> String {
        format!("opc.tcp://{}/", self.addr)
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.addr.port()
    }

    /// Stops the server.
    pub fn stop(&self) {
        self.handle.cancel();
    }

    /// Runs the generator on its own thread until `stop`: `rate` noise
    /// changes per second (each variable in turn, in an order shuffled
    /// every round, so a variable changes once per `noise / rate` seconds),
    /// and every `fault_every` one switch opened for `fault_hold`.
    pub fn generate(
        &self,
        rate: u64,
        fault_every: Duration,
        fault_hold: Duration,
        seed: u64,
        stop: Arc<AtomicBool>,
    ) -> (Arc<Produced>, std::thread::JoinHandle<()>) {
        let produced = Arc::new(Produced::default());
        let out = produced.clone();
        let manager = self.manager.clone();
        let subscriptions = self.subscriptions.clone();
        let noise = self.noise.clone();
        let switches = self.switches.clone();
        let mut values = self.values.clone();
        let nice = self.nice;
        let thread = std::thread::spawn(move || {
            lower_priority(nice);
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let mut order: Vec<usize> = (0..noise.len()).collect();
            order.shuffle(&mut rng);
            let mut next = 0;
            // The batch each variable was last toggled in.
            let mut in_tick = vec![0u64; noise.len()];
            let mut tick = 0u64;
            let start = Instant::now();
            let mut made: u64 = 0;
            let mut next_fault = start + fault_every;
            let mut open: Option<(usize, Instant)> = None;
            let mut fault_no = 0;
            let mut batch: Vec<(&NodeId, Option<&opcua::types::NumericRange>, DataValue)> =
                Vec::new();
            while !stop.load(Ordering::Relaxed) {
                let now = Instant::now();
                let due = (now - start).as_secs_f64() * rate as f64;
                let lag = (due as u64).saturating_sub(made) * 1_000_000 / rate.max(1);
                produced.max_lag_us.fetch_max(lag, Ordering::Relaxed);
                let wall = SystemTime::now();
                let stamp = DateTime::from(chrono::DateTime::<chrono::Utc>::from(wall));
                batch.clear();
                tick += 1;
                // At most every variable once per batch: a rate above
                // noise / TICK falls behind (and says so in the lag).
                let mut in_batch = 0;
                while (made as f64) < due && in_batch < noise.len() {
                    if next == order.len() {
                        order.shuffle(&mut rng);
                        next = 0;
                    }
                    let i = order[next];
                    next += 1;
                    // Never twice in one batch: the server keeps only a
                    // node's last value of a batch, and a variable toggled
                    // back within it would not change at all.
                    if in_tick[i] == tick {
                        continue;
                    }
                    in_tick[i] = tick;
                    in_batch += 1;
                    values[i] = !values[i];
                    batch.push((&noise[i], None, DataValue::new_at(values[i], stamp)));
                    made += 1;
                }
                let mut closed = false;
                if let Some((k, since)) = open {
                    if now >= since + fault_hold {
                        batch.push((&switches[k], None, DataValue::new_at(true, stamp)));
                        open = None;
                        closed = true;
                        // A generator behind its schedule keeps the gap
                        // between a recovery and the next fault all the
                        // same: a PLC does not run two faults together
                        // because a benchmark was late.
                        next_fault = next_fault.max(now + fault_every.saturating_sub(fault_hold));
                    }
                }
                // Never the next fault in the batch that ends the last (a
                // generator behind its schedule would): with one timestamp
                // for both, the fault could be seen before the recovery.
                if open.is_none() && !closed && now >= next_fault {
                    let k = fault_no % switches.len();
                    fault_no += 1;
                    batch.push((&switches[k], None, DataValue::new_at(false, stamp)));
                    if let Ok(mut f) = produced.faults.lock() {
                        f.push(Fault {
                            switch: k,
                            at: wall,
                        });
                    }
                    open = Some((k, now));
                    next_fault += fault_every;
                }
                let n = batch.len() as u64;
                if n > 0 {
                    if let Err(e) = manager.set_values(&subscriptions, batch.drain(..)) {
                        eprintln!("load server: cannot set values: {e}");
                        return;
                    }
                    produced.changes.fetch_add(n, Ordering::Relaxed);
                }
                let spent = now.elapsed();
                if spent < TICK {
                    std::thread::sleep(TICK - spent);
                }
            }
            if let Some((k, _)) = open {
                let _ = manager.set_values(
                    &subscriptions,
                    std::iter::once((&switches[k], None, DataValue::new_now(true))),
                );
                produced.changes.fetch_add(1, Ordering::Relaxed);
            }
        });
        (out, thread)
    }
}
