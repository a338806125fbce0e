//! The same faults against every OPC UA server stack the project did not
//! write: node-opcua (`tests/interop/server.js`, `npm ci` on first use),
//! open62541 (`tests/interop/open62541/`, the C stack through its Rust
//! bindings, built on first use into `target/open62541-server`) and Python
//! asyncua (`tests/interop/asyncua_server.py`, pinned, in a virtual
//! environment under `target/`), each a process driven on its standard
//! input ([`StackServer`]), reached through a relay that can cut and stall
//! (`liveness::relay_with_cut`), Basic256Sha256 + SignAndEncrypt, each
//! side trusting the other's certificate (open62541 and asyncua accept
//! any client's).
//!
//! One table, stack × fault ([`matrix!`]): a network cut, a stall (held
//! both ways, or only the server's answers, then delivered), a server
//! restart, a node deleted and added again in silence, a node deleted as
//! the stack deletes one (what it tells its items) and added back, and a
//! subscription the server drops (its lifetime over while cut off). In
//! each, a tag's value changes and the source must deliver it, saying a
//! gap first wherever changes may have been lost (never losing one
//! silently), the node comes back, and the requests the source made
//! (`cellwatch_opcua_requests_total`, counted as the agent counts them,
//! the client library's own `Publish` requests among them) stay few: a
//! storm fails the test.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::AtomicBool;
use std::sync::mpsc as std_mpsc;
use std::sync::Arc;
use std::time::Duration;

use cellwatch::config::TagConfig;
use cellwatch::sources::{pki, SourceEvent};
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::ValueType;

use crate::liveness::{relay_with_cut, Cut, Running};
use crate::network_cut::until;
use crate::opcua::{all, opcua_config};
use crate::util::root;

/// The namespace the asyncua and open62541 servers serve their tags in.
pub(crate) const URI: &str = "urn:cellwatch:test:asyncua:plc";

/// How long a server is given to be gone after `quit`.
const STOPPED_WITHIN: Duration = Duration::from_secs(20);

/// The asyncua release the interoperability is checked against.
const ASYNCUA: &str = "asyncua==2.1.0";

/// What the open62541 server is built with: CMake (3.x: Mbed TLS's
/// CMakeLists asks for 3.5, below what CMake 4 still accepts) and
/// libclang, which the bindings' bindgen loads.
const OPEN62541_BUILD: [&str; 2] = ["cmake==3.31.10", "libclang==18.1.1"];

/// An OPC UA server of another stack, a process driven on its standard
/// input: `set`, `recreate`, `delete`, `add`, each answered `done …`.
pub(crate) struct StackServer {
    name: &'static str,
    child: Child,
    stdin: ChildStdin,
    lines: std_mpsc::Receiver<String>,
    /// How it was started: program, then arguments (to start it again).
    command: Vec<OsString>,
    /// Its own certificate (DER).
    pub(crate) cert: PathBuf,
    /// Where it listens.
    pub(crate) port: u16,
}

impl StackServer {
    /// Starts `command` and waits for its `ready <certificate> [port]`.
    fn spawn(name: &'static str, command: Vec<OsString>, port: u16) -> StackServer {
        let mut child = Command::new(&command[0])
            .args(&command[1..])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("{name} server: {e}"));
        let stdin = child.stdin.take().unwrap();
        let lines = crate::util::lines_of(&mut child);
        let mut server = StackServer {
            name,
            child,
            stdin,
            lines,
            command,
            cert: PathBuf::new(),
            port,
        };
        let ready = server.wait_for("ready ");
        let mut words = ready.split_whitespace().skip(1);
        server.cert = PathBuf::from(words.next().unwrap());
        if let Some(p) = words.next() {
            server.port = p.parse().unwrap();
        }
        server
    }

    /// node-opcua on `port`, with Boolean tags T0…T(`tags`-1), all true,
    /// trusting the client certificates in `pki_dir/trusted/certs`.
    pub(crate) fn node_opcua(port: u16, pki_dir: &Path, tags: usize) -> StackServer {
        let dir = crate::interop::installed();
        let command = [
            "node".into(),
            dir.join("server.js").into_os_string(),
            port.to_string().into(),
            pki_dir.into(),
            tags.to_string().into(),
            crate::interop::URI.into(),
        ];
        StackServer::spawn("node-opcua", command.to_vec(), port)
    }

    /// Python asyncua on `port` (0: one the system picks), serving the
    /// Double tags `tags` (name, value) in namespace [`URI`].
    pub(crate) fn asyncua(port: u16, pki_dir: &Path, tags: &[(&str, f64)]) -> StackServer {
        let python = crate::util::python_with("asyncua", "asyncua", &[ASYNCUA]);
        let mut command: Vec<OsString> = vec![
            python.into(),
            root().join("tests/interop/asyncua_server.py").into(),
            pki_dir.into(),
            URI.into(),
            port.to_string().into(),
        ];
        command.extend(tags.iter().map(|(n, v)| format!("{n}={v}").into()));
        StackServer::spawn("asyncua", command, port)
    }

    /// open62541 on `port`, serving the Double tags `tags` (name, value) in
    /// namespace [`URI`].
    pub(crate) fn open62541(port: u16, pki_dir: &Path, tags: &[(&str, f64)]) -> StackServer {
        let (program, made) = open62541_server();
        // One certificate for them all, made once (seconds unoptimised).
        std::fs::create_dir_all(pki_dir).unwrap();
        for file in ["server.der", "server-key.der"] {
            if !pki_dir.join(file).exists() {
                std::fs::copy(made.join(file), pki_dir.join(file)).unwrap();
            }
        }
        let mut command: Vec<OsString> = vec![
            program.into(),
            port.to_string().into(),
            pki_dir.into(),
            URI.into(),
        ];
        command.extend(tags.iter().map(|(n, v)| format!("{n}={v}").into()));
        StackServer::spawn("open62541", command, port)
    }

    /// The next line that starts with `prefix`.
    pub(crate) fn wait_for(&mut self, prefix: &str) -> String {
        loop {
            match self.lines.recv_timeout(Duration::from_secs(120)) {
                Ok(line) if line.starts_with(prefix) => return line,
                Ok(_) => {}
                Err(_) => panic!("{} server: no '{prefix}' line", self.name),
            }
        }
    }

    /// Sends a command and waits until the server has carried it out.
    pub(crate) fn send(&mut self, command: &str) {
        self.tell(command);
        self.wait_for(&format!("done {command}"));
    }

    /// Sends a command and returns its answer, the line after `prefix`.
    pub(crate) fn ask(&mut self, command: &str, prefix: &str) -> String {
        self.tell(command);
        let line = self.wait_for(prefix);
        line[prefix.len()..].to_string()
    }

    fn tell(&mut self, command: &str) {
        use std::io::Write;
        writeln!(self.stdin, "{command}").unwrap();
    }

    /// Stops it: `quit`, and the process waited for; killed if it is not
    /// gone within [`STOPPED_WITHIN`] (a stack's own shutdown that waits on
    /// a connection is not what a test is about).
    pub(crate) fn stop(mut self) {
        use std::io::Write;
        let _ = writeln!(self.stdin, "quit");
        let deadline = std::time::Instant::now() + STOPPED_WITHIN;
        while matches!(self.child.try_wait(), Ok(None)) {
            if std::time::Instant::now() > deadline {
                eprintln!(
                    "{} server: not gone {STOPPED_WITHIN:?} after quit, killed",
                    self.name
                );
                let _ = self.child.kill();
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.wait();
    }

    /// Stopped and started again, on the same port with the same
    /// certificate: the same server after a restart (its values as at its
    /// first start, its sessions and subscriptions gone).
    pub(crate) fn restarted(self) -> StackServer {
        let (name, command, port) = (self.name, self.command.clone(), self.port);
        self.stop();
        StackServer::spawn(name, command, port)
    }

    /// It, once it has carried `command` out (off the runtime's workers).
    pub(crate) async fn said(self, command: &str) -> StackServer {
        let command = command.to_string();
        tokio::task::spawn_blocking(move || {
            let mut server = self;
            server.send(&command);
            server
        })
        .await
        .unwrap()
    }
}

impl Drop for StackServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The open62541 server program (`tests/interop/open62541`), built on first
/// use into `target/open62541-server` with CMake and libclang from a
/// virtual environment under `target/` (Cargo's build is a no-op once
/// built), and a folder holding a certificate and key it made. One build
/// at a time in this process.
pub(crate) fn open62541_server() -> (PathBuf, PathBuf) {
    static BUILT: std::sync::Mutex<Option<(PathBuf, PathBuf)>> = std::sync::Mutex::new(None);
    let mut built = BUILT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(built) = &*built {
        return built.clone();
    }
    let python = crate::util::python_with("open62541", "clang.native", &OPEN62541_BUILD);
    let out = |cmd: &mut Command| {
        let out = cmd.output().unwrap();
        assert!(
            out.status.success(),
            "{cmd:?} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap().trim().to_string()
    };
    let libclang = out(Command::new(&python).args([
        "-c",
        "import clang.native, os; print(os.path.dirname(clang.native.__file__))",
    ]));
    // The C compiler's own headers, for bindgen.
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let include = out(Command::new(cc).arg("-print-file-name=include"));
    let path = std::env::join_paths(
        std::iter::once(python.parent().unwrap().to_path_buf())
            .chain(std::env::split_paths(&std::env::var_os("PATH").unwrap())),
    )
    .unwrap();
    let target = root().join("target/open62541-server");
    let started = std::time::Instant::now();
    out(
        Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
            .args(["build", "--locked", "--manifest-path"])
            .arg(root().join("tests/interop/open62541/Cargo.toml"))
            .env("CARGO_TARGET_DIR", &target)
            .env("PATH", path)
            .env("LIBCLANG_PATH", libclang)
            .env("BINDGEN_EXTRA_CLANG_ARGS", format!("-I{include}")),
    );
    eprintln!("open62541 server built in {:?}", started.elapsed());
    let bin = target.join("debug/cellwatch-open62541-server");
    let pki = target.join("pki");
    out(Command::new(&bin).arg("certificate").arg(&pki));
    *built = Some((bin.clone(), pki.clone()));
    (bin, pki)
}

/// A server stack nobody here wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stack {
    NodeOpcua,
    Open62541,
    Asyncua,
}

impl Stack {
    /// The tag the faults are played on. node-opcua's server serves
    /// Booleans (T0, value `k` odd), the others Doubles (Temp, value `k`).
    fn tag(self) -> TagConfig {
        match self {
            Stack::NodeOpcua => TagConfig::boolean(
                "t0",
                &format!("nsu={};s=T0", crate::interop::URI),
                Signal::new("T0"),
            ),
            Stack::Open62541 | Stack::Asyncua => TagConfig {
                value_type: ValueType::Double,
                ..TagConfig::boolean("temp", &format!("nsu={URI};s=Temp"), Signal::new("D100"))
            },
        }
    }

    /// Its server on `port`, the tag holding value 1.
    fn start(self, port: u16, pki_dir: &Path) -> StackServer {
        match self {
            Stack::NodeOpcua => StackServer::node_opcua(port, pki_dir, 1),
            Stack::Open62541 => StackServer::open62541(port, pki_dir, &[("Temp", 1.0)]),
            Stack::Asyncua => StackServer::asyncua(port, pki_dir, &[("Temp", 1.0)]),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Stack::NodeOpcua => "T0",
            Stack::Open62541 | Stack::Asyncua => "Temp",
        }
    }

    fn value(self, k: u32) -> String {
        match self {
            Stack::NodeOpcua => (k % 2).to_string(),
            Stack::Open62541 | Stack::Asyncua => k.to_string(),
        }
    }

    /// The command that writes value `k`; `verb` another that leaves the
    /// node holding it (`recreate`, `add`).
    fn command(self, verb: &str, k: u32) -> String {
        format!("{verb} {} {}", self.name(), self.value(k))
    }

    /// Whether `reading` is value `k`.
    fn is(self, reading: &Reading, k: u32) -> bool {
        match (self, reading) {
            (Stack::NodeOpcua, Reading::Good(b)) => *b == (k % 2 == 1),
            (Stack::Open62541 | Stack::Asyncua, Reading::Number(n)) => n.as_f64() == f64::from(k),
            _ => false,
        }
    }
}

/// A fault played between the source and a server.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fault {
    /// The network cut (shorter than the subscription's lifetime) while
    /// the value pulses.
    Cut,
    /// Nothing passes either way for longer than the subscription's
    /// silence allows, then it is all delivered.
    Stall,
    /// The server's answers and publishes held (the source's requests
    /// reach it) as long, then delivered.
    StallAnswers,
    /// The server stops and starts again on the same port.
    Restart,
    /// The node deleted and added again, its old items told nothing where
    /// the stack allows it.
    Recreated,
    /// The node deleted as the stack deletes one (what it tells its items:
    /// node-opcua `BadNodeIdInvalid`, asyncua a status change naming no
    /// item, open62541 bad samples), then added back.
    Deleted,
    /// Cut off until the server drops the subscription (its lifetime
    /// over).
    Dropped,
}

/// How long a value is held on the server so that every stack samples it
/// (open62541 samples its items on a timer, not on a write).
const HELD: Duration = Duration::from_millis(300);

/// Longer than the subscription's silence allows (three keep-alive
/// periods of 1 s at a 100 ms publishing interval): the stall's length.
const STALLED: Duration = Duration::from_secs(5);

/// The requests a fault may cost at most, all services but `Publish`: a
/// reconnection reads the namespaces and takes the subscription over or
/// creates it and its item, a recovery asks for a few publishes, and the
/// verification reads the node every 2 s while the fault lasts (0 to 6 in
/// all in the runs so far); a storm is hundreds.
const REQUESTS_AT_MOST: u64 = 40;

/// `Publish` requests (the client library's, kept queued) a second may
/// cost at most: one per publishing interval of 100 ms while data flows,
/// twice that for what a fault's recovery asks again; a storm is hundreds
/// a second.
const PUBLISHES_PER_SECOND_AT_MOST: u64 = 20;

/// `Republish` requests a fault may cost at most: three missing publishes
/// asked for three times each (one or two asked for in the runs so far).
const REPUBLISHES_AT_MOST: u64 = 9;

/// The readings of tag 0 among `events`, and where the gaps for it were
/// said, in order: `Ok` for a reading, `Err(why)` for a gap.
fn told(events: &[SourceEvent]) -> Vec<Result<Reading, String>> {
    let mut out = Vec::new();
    for e in events {
        match e {
            SourceEvent::Readings(rs) => out.extend(
                rs.iter()
                    .filter(|r| r.tag == 0)
                    .map(|r| Ok(r.reading.clone())),
            ),
            SourceEvent::Gap { tags, why, .. } if tags.as_ref().is_none_or(|t| t.contains(&0)) => {
                out.push(Err(why.clone()))
            }
            _ => {}
        }
    }
    out
}

/// The values `ks` were each delivered, in order, and no gap was said:
/// nothing lost (a cut or stall shorter than the subscription's lifetime
/// loses nothing, on every stack).
fn nothing_lost(stack: Stack, events: &[SourceEvent], ks: &[u32]) {
    let told = told(events);
    assert!(!told.iter().any(Result::is_err), "a gap said: {told:?}");
    let mut want = ks.iter().peekable();
    for t in &told {
        if let (Some(&&w), Ok(r)) = (want.peek(), t) {
            if stack.is(r, w) {
                want.next();
            }
        }
    }
    assert!(
        want.peek().is_none(),
        "{:?} not delivered in order: {told:?}",
        want.collect::<Vec<_>>()
    );
}

/// Whether any of `events` says the connection or subscription was lost.
fn reconnected(events: &[SourceEvent]) -> bool {
    events
        .iter()
        .any(|e| matches!(e, SourceEvent::Disconnected(_) | SourceEvent::Connected(_)))
}

/// The requests counted in `requests`: all, and those of `service`.
fn requests(requests: &prometheus::IntCounterVec, service: Option<&str>) -> u64 {
    use prometheus::core::Collector;
    requests
        .collect()
        .iter()
        .flat_map(|family| family.get_metric())
        .filter(|m| {
            service.is_none_or(|s| {
                m.get_label()
                    .iter()
                    .any(|l| l.name() == "service" && l.value() == s)
            })
        })
        .map(|m| m.get_counter().get_value() as u64)
        .sum()
}

/// One case of the table: `fault` played against `stack`.
async fn play(stack: Stack, fault: Fault) {
    crate::network_cut::logs();
    let d = tempfile::tempdir().unwrap();
    let (agent_pki, server_pki) = (d.path().join("agent-pki"), d.path().join("server-pki"));
    let port = crate::util::restartable_port();
    if stack == Stack::NodeOpcua {
        crate::interop::trusted_by_server(&agent_pki, &server_pki);
    }
    let mut server = tokio::task::spawn_blocking({
        let pki = server_pki.clone();
        move || stack.start(port, &pki)
    })
    .await
    .unwrap();
    let cut = Cut::default();
    let via = relay_with_cut(
        format!("127.0.0.1:{port}").parse().unwrap(),
        Arc::new(AtomicBool::new(false)),
        cut.clone(),
    )
    .await;
    let mut config = opcua_config(&format!("opc.tcp://{via}/"), &agent_pki);
    config.publishing_interval = Duration::from_millis(100);
    config.verify_interval = Duration::from_secs(2);
    if fault == Fault::Dropped {
        // The shortest lifetime allowed: 30 publishing intervals.
        config.subscription_lifetime = config.publishing_interval * 30;
    }
    pki::trust(&server.cert, &config.pki_dir).unwrap();
    let (mut source, counted) = Running::counted(config, vec![stack.tag()]);
    all(
        &mut source.rx,
        "connected, and the tag's first value",
        &[&|e| matches!(e, SourceEvent::Connected(_)), &|e| {
            matches!(e, SourceEvent::Readings(rs) if rs.iter().any(|r| stack.is(&r.reading, 1)))
        }],
    )
    .await;
    let delivered = |k: u32| move |e: &SourceEvent| matches!(e, SourceEvent::Readings(rs) if rs.iter().any(|r| r.tag == 0 && stack.is(&r.reading, k)));
    let (before, publishes_before, started) = (
        requests(&counted, None),
        requests(&counted, Some("Publish")),
        std::time::Instant::now(),
    );
    // The value the tag holds after the fault.
    let mut last = 2;
    match fault {
        Fault::Cut | Fault::Stall | Fault::StallAnswers => {
            match fault {
                Fault::Cut => {
                    cut.set(true);
                    until(&mut source, "the cut seen", |e| {
                        matches!(e, SourceEvent::Disconnected(_))
                    })
                    .await;
                }
                Fault::Stall => cut.stall(true),
                _ => cut.stall_answers(true),
            }
            // A pulse while nothing passes.
            server = server.said(&stack.command("set", 2)).await;
            tokio::time::sleep(HELD).await;
            server = server.said(&stack.command("set", 3)).await;
            if fault != Fault::Cut {
                tokio::time::sleep(STALLED).await;
            }
            cut.set(false);
            cut.stall(false);
            let events = until(&mut source, "the pulse's end", delivered(3)).await;
            nothing_lost(stack, &events, &[2, 3]);
            last = 3;
        }
        Fault::Restart => {
            server = tokio::task::spawn_blocking(move || server.restarted())
                .await
                .unwrap();
            // Its value as at its first start (1), then changed.
            server = server.said(&stack.command("set", 2)).await;
            let events = until(&mut source, "the value after the restart", delivered(2)).await;
            // The subscription went with the server: said.
            assert!(
                told(&events).iter().any(Result::is_err),
                "no gap said: {events:?}"
            );
        }
        Fault::Recreated => {
            server = server.said(&stack.command("recreate", 2)).await;
            let events = until(&mut source, "the recreated node's value", delivered(2)).await;
            assert!(!reconnected(&events), "{events:?}");
        }
        Fault::Deleted => {
            server = server.said(&format!("delete {}", stack.name())).await;
            let mut events = until(&mut source, "the tag bad", |e| {
                matches!(e, SourceEvent::Readings(rs) if rs.iter().any(|r| r.tag == 0 && r.reading == Reading::Bad))
            })
            .await;
            server = server.said(&stack.command("add", 2)).await;
            events.extend(until(&mut source, "the node back", delivered(2)).await);
            // Not mistaken for a closed subscription.
            assert!(!reconnected(&events), "{events:?}");
        }
        Fault::Dropped => {
            cut.set(true);
            until(&mut source, "the cut seen", |e| {
                matches!(e, SourceEvent::Disconnected(_))
            })
            .await;
            server = tokio::task::spawn_blocking(move || {
                let mut server = server;
                server.wait_for("expired subscription");
                server
            })
            .await
            .unwrap();
            // Queued nowhere: the server dropped the subscription.
            server = server.said(&stack.command("set", 2)).await;
            cut.set(false);
            let events = until(&mut source, "the value after the drop", delivered(2)).await;
            let told = told(&events);
            assert!(
                told.iter().any(Result::is_err),
                "no gap said: {told:?} {events:?}"
            );
        }
    }
    // And followed from then on.
    server = server.said(&stack.command("set", last + 1)).await;
    until(&mut source, "a value after the fault", delivered(last + 1)).await;
    let publishes = requests(&counted, Some("Publish")) - publishes_before;
    let (all_requests, republishes) = (
        requests(&counted, None) - before - publishes,
        requests(&counted, Some("Republish")),
    );
    let seconds = started.elapsed().as_secs() + 1;
    eprintln!("{stack:?} {fault:?}: {all_requests} requests, {republishes} Republish, {publishes} Publish in {seconds} s");
    // The library's publishes are counted (one at least answered the
    // value after the fault), and never a storm.
    assert!(publishes > 0, "{stack:?} {fault:?}: no Publish counted");
    assert!(
        publishes <= PUBLISHES_PER_SECOND_AT_MOST * seconds,
        "{stack:?} {fault:?}: {publishes} Publish requests in {seconds} s"
    );
    assert!(
        all_requests <= REQUESTS_AT_MOST,
        "{stack:?} {fault:?}: {all_requests} requests: {:?}",
        counted_by_service(&counted)
    );
    assert!(
        republishes <= REPUBLISHES_AT_MOST,
        "{stack:?} {fault:?}: {republishes} Republish requests"
    );
    source.stop().await;
    tokio::task::spawn_blocking(move || server.stop())
        .await
        .unwrap();
}

/// Each service's and result's count, for a failure's message.
fn counted_by_service(requests: &prometheus::IntCounterVec) -> Vec<String> {
    use prometheus::core::Collector;
    requests
        .collect()
        .iter()
        .flat_map(|family| family.get_metric())
        .map(|m| {
            let labels: Vec<&str> = m.get_label().iter().map(|l| l.value()).collect();
            format!("{} {}", labels.join(" "), m.get_counter().get_value())
        })
        .collect()
}

/// One test per row: its name, the stack, the fault.
macro_rules! matrix {
    ($($name:ident: $stack:ident $fault:ident,)*) => {
        $(
            #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
            async fn $name() {
                play(Stack::$stack, Fault::$fault).await;
            }
        )*
    };
}

matrix! {
    node_opcua_network_cut: NodeOpcua Cut,
    node_opcua_stall: NodeOpcua Stall,
    node_opcua_stall_of_answers: NodeOpcua StallAnswers,
    node_opcua_restart: NodeOpcua Restart,
    node_opcua_node_recreated_in_silence: NodeOpcua Recreated,
    node_opcua_node_deleted_and_added_back: NodeOpcua Deleted,
    node_opcua_subscription_dropped: NodeOpcua Dropped,
    open62541_network_cut: Open62541 Cut,
    open62541_stall: Open62541 Stall,
    open62541_stall_of_answers: Open62541 StallAnswers,
    open62541_restart: Open62541 Restart,
    open62541_node_recreated_in_silence: Open62541 Recreated,
    open62541_node_deleted_and_added_back: Open62541 Deleted,
    open62541_subscription_dropped: Open62541 Dropped,
    asyncua_network_cut: Asyncua Cut,
    asyncua_stall: Asyncua Stall,
    asyncua_stall_of_answers: Asyncua StallAnswers,
    asyncua_restart: Asyncua Restart,
    asyncua_node_recreated_in_silence: Asyncua Recreated,
    asyncua_node_deleted_and_added_back: Asyncua Deleted,
    asyncua_subscription_dropped: Asyncua Dropped,
}
