//! A SCADA client program driven line by line (`tests/interop/scada.js`,
//! node-opcua's client; `tests/interop/scada.py`, Python asyncua's): it
//! prints its certificate, connects when told, prints each event as a JSON
//! line and answers commands (`ack`, `call`, `refresh`).

use std::io::Write as _;
use std::path::Path;
use std::time::Duration;

/// A SCADA client program: its lines on standard output, its errors in a
/// file shown when a wait fails.
pub(crate) struct ScadaProgram {
    /// Whose client it is, for messages.
    client: &'static str,
    child: std::process::Child,
    stdin: std::process::ChildStdin,
    lines: std::sync::mpsc::Receiver<String>,
    /// Events that came while an answer was awaited, in order: the next
    /// [`ScadaProgram::event`] looks at them first.
    events: std::collections::VecDeque<String>,
    log: std::path::PathBuf,
}

impl ScadaProgram {
    /// node-opcua's, started with its key pair in `pki` (which trusts what
    /// is in `pki/trusted/certs`); returns it and its certificate (DER).
    fn node_opcua(
        url: &str,
        pki: &Path,
        user: &str,
        password: &str,
    ) -> (ScadaProgram, std::path::PathBuf) {
        let mut command = std::process::Command::new("node");
        command
            .arg(crate::interop::installed().join("scada.js"))
            .args([
                url,
                pki.to_str().unwrap(),
                user,
                password,
                "urn:cellwatch:alarms:m01ps0004",
            ]);
        ScadaProgram::start("node-opcua", command, pki)
    }

    /// Python asyncua's (pinned, in a virtual environment under target/),
    /// its key pair in `pki`, trusting `pki/trusted/certs/cellwatch.der`.
    fn asyncua(
        url: &str,
        pki: &Path,
        user: &str,
        password: &str,
    ) -> (ScadaProgram, std::path::PathBuf) {
        let python = crate::util::python_with("asyncua", "asyncua", &["asyncua==2.1.0"]);
        let mut command = std::process::Command::new(python);
        command
            .arg(crate::util::root().join("tests/interop/scada.py"))
            .args([url, pki.to_str().unwrap(), user, password]);
        ScadaProgram::start("asyncua", command, pki)
    }

    /// `command` started, its errors in a file beside `pki`; it and its
    /// certificate, once it says it.
    fn start(
        client: &'static str,
        mut command: std::process::Command,
        pki: &Path,
    ) -> (ScadaProgram, std::path::PathBuf) {
        use std::process::Stdio;
        let log = pki.with_extension("log");
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let lines = crate::util::lines_of(&mut child);
        let mut scada = ScadaProgram {
            client,
            child,
            stdin,
            lines,
            events: std::collections::VecDeque::new(),
            log,
        };
        let cert = scada.line("its certificate", false, |l| {
            l.strip_prefix("certificate ").map(Into::into)
        });
        (scada, cert)
    }

    /// node-opcua's, connected to the alarm server at `url` (its PKI
    /// directory `server_pki`) as `user` (password `kims-password`), each
    /// trusting the other's certificate, and subscribed to its events.
    pub(crate) fn connected(url: &str, pki: &Path, server_pki: &Path, user: &str) -> ScadaProgram {
        ScadaProgram::connect(ScadaProgram::node_opcua, url, pki, server_pki, user)
    }

    /// Python asyncua's, connected as [`ScadaProgram::connected`] and
    /// subscribed as that library does by default:
    /// `subscribe_events(Server, AlarmConditionType)`.
    pub(crate) fn asyncua_connected(
        url: &str,
        pki: &Path,
        server_pki: &Path,
        user: &str,
    ) -> ScadaProgram {
        ScadaProgram::connect(ScadaProgram::asyncua, url, pki, server_pki, user)
    }

    fn connect(
        start: fn(&str, &Path, &str, &str) -> (ScadaProgram, std::path::PathBuf),
        url: &str,
        pki: &Path,
        server_pki: &Path,
        user: &str,
    ) -> ScadaProgram {
        use cellwatch::sources::pki;
        // The SCADA trusts the agent's certificate from the start; the
        // agent trusts the SCADA's once it is made.
        let trusted = pki.join("trusted/certs");
        std::fs::create_dir_all(&trusted).unwrap();
        std::fs::copy(pki::own_cert(server_pki), trusted.join("cellwatch.der")).unwrap();
        let (mut scada, cert) = start(url, pki, user, "kims-password");
        pki::trust(&cert, server_pki).unwrap();
        scada.ask("connect", "connected");
        scada
    }

    /// The first line `f` takes, skipping the others.
    /// (An event line skipped is kept for [`ScadaProgram::event`] when `keep`.)
    fn line<T>(&mut self, what: &str, keep: bool, f: impl Fn(&str) -> Option<T>) -> T {
        tokio::task::block_in_place(|| {
            let deadline = std::time::Instant::now() + Duration::from_secs(120);
            let mut seen = Vec::new();
            loop {
                let left = deadline.saturating_duration_since(std::time::Instant::now());
                let kept = if keep { None } else { self.events.pop_front() };
                let next = match kept {
                    Some(line) => Ok(line),
                    None => self.lines.recv_timeout(left),
                };
                match next {
                    Ok(line) => match f(&line) {
                        Some(t) => return t,
                        None if keep && line.starts_with("event ") => self.events.push_back(line),
                        None => seen.push(line),
                    },
                    Err(_) => panic!(
                        "{} SCADA: no {what}; saw {seen:#?}; its errors:\n{}",
                        self.client,
                        std::fs::read_to_string(&self.log).unwrap_or_default()
                    ),
                }
            }
        })
    }

    /// The next event `f` accepts.
    pub(crate) fn event(
        &mut self,
        what: &str,
        f: impl Fn(&serde_json::Value) -> bool,
    ) -> serde_json::Value {
        self.line(what, false, |l| {
            let e: serde_json::Value = serde_json::from_str(l.strip_prefix("event ")?).unwrap();
            f(&e).then_some(e)
        })
    }

    /// Sends `command`; its answer (the line after `answer`).
    pub(crate) fn ask(&mut self, command: &str, answer: &str) -> String {
        writeln!(self.stdin, "{command}").unwrap();
        self.line(answer, true, |l| l.strip_prefix(answer).map(str::to_string))
    }
}

impl Drop for ScadaProgram {
    fn drop(&mut self) {
        let _ = writeln!(self.stdin, "quit");
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
