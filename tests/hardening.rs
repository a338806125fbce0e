//! What a hostile server, Alertmanager or neighbour on the same host
//! cannot do through the text and files the agent and its commands handle:
//! draw lines into `trust-server`'s output, read a journal's backup or a
//! private key in the moment it is made, have a key or a copy written
//! through a planted link, or make the agent hold an endless error answer.

use std::io::{Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::time::Duration;

use cellwatch::config::AlertmanagerConfig;
use cellwatch::sim::cnc::SimOptions;
use cellwatch::sim::server::SimServer;

use crate::agent::Fixture;
use crate::util::cellwatch;

fn mode(path: &Path) -> u32 {
    std::fs::metadata(path).unwrap().permissions().mode() & 0o777
}

fn sim_options(pki: &Path) -> SimOptions {
    SimOptions {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: pki.to_path_buf(),
        insecure: false,
        decoy: None,
    }
}

/// A server whose application name holds a line break and a fingerprint
/// line of its own: `trust-server` prints it escaped, on its own line, and
/// the only fingerprint line is the certificate's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn trust_server_prints_a_servers_own_text_escaped() {
    let d = tempfile::tempdir().unwrap();
    let rogue = "rogue\n  SHA-256      00:11:22:33\n";
    let server = SimServer::start(
        &sim_options(&d.path().join("sim-pki")),
        "cnc",
        rogue,
        &[("X0.00".to_string(), true)],
    )
    .await
    .unwrap();
    let (endpoint, pki) = (server.endpoint(), d.path().join("pki"));
    let run = tokio::task::spawn_blocking(move || {
        cellwatch(&[
            "trust-server",
            &endpoint,
            "--pki-dir",
            pki.to_str().unwrap(),
        ])
    })
    .await
    .unwrap();
    // Not confirmed (no standard input): nothing trusted.
    assert_eq!(run.code, 2, "{}{}", run.stdout, run.stderr);
    let application = run
        .stdout
        .lines()
        .find(|l| l.starts_with("  application  "))
        .unwrap_or_else(|| panic!("{}", run.stdout));
    assert!(
        application.starts_with("  application  rogue\\n  SHA-256      00:11:22:33\\n ("),
        "{application}"
    );
    let fingerprints: Vec<&str> = run
        .stdout
        .lines()
        .filter(|l| l.starts_with("  SHA-256"))
        .collect();
    assert_eq!(fingerprints.len(), 1, "{}", run.stdout);
    assert!(!fingerprints[0].contains("00:11:22:33"), "{}", run.stdout);
    // The certificate's subject, the server's text too: on its own line
    // (the library writes a line break in a name as `\0a`, escaped again).
    let subject = run
        .stdout
        .lines()
        .find(|l| l.starts_with("  subject"))
        .unwrap();
    assert!(
        subject.starts_with("  subject      CN=rogue\\\\0a  SHA-256"),
        "{subject}"
    );
    server.stop();
}

/// A server's key pair is made with the private key its owner's only from
/// the start, in a `private/` only its owner may enter; a link planted at
/// the key's name is never written through.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_opcua_private_key_is_the_owners_only_from_the_start() {
    let d = tempfile::tempdir().unwrap();
    let pki = d.path().join("sim-pki");
    let server = SimServer::start(&sim_options(&pki), "cnc", "cellwatch simulated CNC", &[])
        .await
        .unwrap();
    assert_eq!(mode(&pki.join("private/private.pem")), 0o600);
    assert_eq!(mode(&pki.join("private")), 0o700);
    server.stop();
    // Someone who may write the PKI directory plants a link where the key
    // goes, to a file they can read.
    let planted = d.path().join("planted-pki");
    std::fs::create_dir_all(planted.join("private")).unwrap();
    let stolen = d.path().join("stolen.pem");
    std::os::unix::fs::symlink(&stolen, planted.join("private/private.pem")).unwrap();
    let refused = SimServer::start(
        &sim_options(&planted),
        "cnc",
        "cellwatch simulated CNC",
        &[],
    )
    .await
    .err()
    .unwrap()
    .to_string();
    assert!(
        refused.contains("private.pem is there without"),
        "{refused}"
    );
    assert!(!stolen.exists(), "the key was written through the link");
}

/// The agent's own OPC UA client key pair is made owner-only before the
/// client library runs, whatever the process's umask: `trust-server`
/// (and so `discover` and the source, which build their client the same
/// way) run with umask 000 leaves a `private/` only its owner may enter
/// (the library would make it open to all, and the key in it, before
/// tightening the key alone), and a key pair made before is kept as it is.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_agents_opcua_client_key_is_the_owners_only_from_the_start() {
    let d = tempfile::tempdir().unwrap();
    let server = SimServer::start(
        &sim_options(&d.path().join("sim-pki")),
        "cnc",
        "cellwatch simulated CNC",
        &[],
    )
    .await
    .unwrap();
    let endpoint = server.endpoint();
    let trust_server = |pki: std::path::PathBuf| {
        let endpoint = endpoint.clone();
        tokio::task::spawn_blocking(move || {
            // umask 000: whatever the library made itself would be open to all.
            std::process::Command::new("sh")
                .args(["-c", "umask 000; exec \"$0\" \"$@\""])
                .arg(env!("CARGO_BIN_EXE_cellwatch"))
                .args(["trust-server", &endpoint, "--pki-dir"])
                .arg(&pki)
                .stdin(std::process::Stdio::null())
                .output()
                .unwrap()
        })
    };
    let fresh = d.path().join("pki");
    let run = trust_server(fresh.clone()).await.unwrap();
    // Not confirmed (no standard input): nothing trusted, but the client
    // had its key pair.
    assert_eq!(run.status.code(), Some(2), "{run:?}");
    assert_eq!(mode(&fresh.join("private")), 0o700);
    assert_eq!(mode(&fresh.join("private/private.pem")), 0o600);
    assert!(fresh.join("own/cert.der").exists());
    // A key pair made before (as `own_key_pair` makes it) is the client's.
    let made = d.path().join("made-pki");
    let cell = "trust";
    assert!(cellwatch::sources::pki::own_key_pair(
        &made,
        &format!("cellwatch {cell}"),
        &format!("urn:cellwatch:agent:{cell}"),
    )
    .unwrap());
    let key = std::fs::read(made.join("private/private.pem")).unwrap();
    let cert = std::fs::read(made.join("own/cert.der")).unwrap();
    let run = trust_server(made.clone()).await.unwrap();
    assert_eq!(run.status.code(), Some(2), "{run:?}");
    assert_eq!(
        std::fs::read(made.join("private/private.pem")).unwrap(),
        key
    );
    assert_eq!(std::fs::read(made.join("own/cert.der")).unwrap(), cert);
    // One that others may read is refused, naming it.
    let loose = made.join("private/private.pem");
    std::fs::set_permissions(&loose, std::fs::Permissions::from_mode(0o644)).unwrap();
    let run = trust_server(made.clone()).await.unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_ne!(run.status.code(), Some(0), "{run:?}");
    assert!(stderr.contains(loose.to_str().unwrap()), "{stderr}");
    server.stop();
}

/// `journal backup` makes a copy its owner only may read, under a private
/// name while it is made, and never writes through or over what is at the
/// destination.
#[tokio::test]
async fn a_journal_backup_is_the_owners_only_and_never_through_a_link() {
    let d = tempfile::tempdir().unwrap();
    let db = d.path().join("journal.sqlite");
    cellwatch::journal::Journal::start(
        &db,
        &cellwatch::config::Keep::all(Duration::from_secs(3600)),
        crate::util::NoCommits,
    )
    .unwrap()
    .close()
    .await;
    let out = d.path().join("backups");
    std::fs::create_dir(&out).unwrap();
    let dest = out.join("copy.sqlite");
    let run = cellwatch(&[
        "journal",
        "backup",
        db.to_str().unwrap(),
        dest.to_str().unwrap(),
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(mode(&dest), 0o600);
    let left: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(left, ["copy.sqlite"]);
    // A link at the destination, leading nowhere yet: refused, nothing
    // written where it leads.
    let elsewhere = d.path().join("elsewhere.sqlite");
    let link = out.join("linked.sqlite");
    std::os::unix::fs::symlink(&elsewhere, &link).unwrap();
    let run = cellwatch(&[
        "journal",
        "backup",
        db.to_str().unwrap(),
        link.to_str().unwrap(),
    ]);
    assert_eq!(
        (run.code, run.stderr.as_str()),
        (
            2,
            format!(
                "error: {}: exists already (a backup never overwrites a file: name a new one)\n",
                link.display()
            )
            .as_str()
        )
    );
    assert!(!elsewhere.exists());
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 2);
}

/// An "Alertmanager" that answers every post with an error and an endless
/// body: the agent reads a bounded part of it and hangs up, whatever it
/// would send.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_alertmanagers_endless_error_answer_is_read_bounded() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    let (sent_tx, sent) = std::sync::mpsc::channel::<usize>();
    std::thread::spawn(move || {
        let (mut conn, _) = listener.accept().unwrap();
        // The request's head; its body is not waited for.
        let mut head = Vec::new();
        let mut byte = [0u8; 1];
        while !head.ends_with(b"\r\n\r\n") && conn.read(&mut byte).unwrap_or(0) == 1 {
            head.push(byte[0]);
        }
        let chunk = format!("4000\r\n{}\r\n", "x".repeat(0x4000));
        let mut sent = 0;
        let start = b"HTTP/1.1 500 Internal Server Error\r\ncontent-type: text/plain\r\ntransfer-encoding: chunked\r\n\r\n";
        if conn.write_all(start).is_ok() {
            // Until the agent hangs up.
            while conn.write_all(chunk.as_bytes()).is_ok() {
                sent += 0x4000;
            }
        }
        let _ = sent_tx.send(sent);
    });
    let fx = Fixture::start_with(|c| {
        c.alertmanager = Some(AlertmanagerConfig {
            urls: vec![url],
            area: None,
            console: None,
            resend: Duration::from_secs(60),
            tls: None,
            escalation: cellwatch::config::default_escalation(),
        });
    })
    .await;
    fx.settled().await;
    fx.sim.set("X0.06", false).unwrap();
    let sent = tokio::task::spawn_blocking(move || sent.recv_timeout(Duration::from_secs(60)))
        .await
        .unwrap()
        .expect("the agent never hung up");
    // What loopback's socket buffers hold at most, far from the endless.
    assert!(sent < 32 << 20, "{sent} bytes read of an error answer");
}

/// The agent's own OPC UA key pair is made owner-only from its first byte,
/// whatever the process's umask: its folders 0700 and its key 0600 as they
/// are created (not made so afterwards), before any connection.
#[test]
fn the_opcua_key_pair_is_owner_only_from_the_start_whatever_the_umask() {
    let d = tempfile::tempdir().unwrap();
    let pki = d.path().join("pki");
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "umask 000; exec {} discover opc.tcp://127.0.0.1:1/ --pki-dir {}",
            env!("CARGO_BIN_EXE_cellwatch"),
            pki.display()
        ))
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(mode(&pki), 0o700, "the PKI folder");
    assert_eq!(mode(&pki.join("private")), 0o700);
    assert_eq!(mode(&pki.join("private/private.pem")), 0o600);
}
