//! Configuration tests: the shipped examples parse; bad configurations give
//! pinned messages naming file, line and key.

use std::collections::HashMap;
use std::io;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use cellwatch_models::alarm::Severity;
use cellwatch_models::engine::PartCounting;
use cellwatch_models::limit::Level;
use cellwatch_models::programs::Dialect;
use cellwatch_models::signal::Signal;
use cellwatch_models::value::ValueType;

use super::*;

/// Files from a map, for literal configurations.
struct Mem(HashMap<PathBuf, Vec<u8>>);

impl Files for Mem {
    fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
        self.0
            .get(path)
            .cloned()
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "No such file or directory"))
    }

    fn list(&self, dir: &Path) -> io::Result<Vec<PathBuf>> {
        let mut files: Vec<PathBuf> = self
            .0
            .keys()
            .filter(|p| p.parent() == Some(dir))
            .cloned()
            .collect();
        files.sort();
        Ok(files)
    }
}

fn mem() -> Mem {
    let mut m = HashMap::new();
    m.insert(
        PathBuf::from("base/fig6.il"),
        b"RD X1\nANDN X2\nWRT G0.00\n".to_vec(),
    );
    m.insert(
        PathBuf::from("base/timers.json"),
        br#"{"version": 1, "method": "common", "signals": ["x1", "X2", "belt"], "transitions": []}"#.to_vec(),
    );
    Mem(m)
}

const GOOD: &str = r#"
[cell]
id = "c1"

[opcua]
endpoint = "opc.tcp://127.0.0.1:4840/"

[[tags]]
name = "x1"
node_id = "nsu=urn:plc;s=X1"
address = "X1"

[[tags]]
name = "x2"
node_id = "nsu=urn:plc;s=X2"
address = "X2"

[[checks.switching]]
id = "fig6"
program = "fig6.il"
coil = "G0.00"

[zenoh.tls]
ca = "pki-bus/ca.pem"
cert = "pki-bus/agent-c1.pem"
key = "pki-bus/agent-c1.key"
"#;

fn errors(text: &str) -> String {
    parse("cell.toml", text, Path::new("base"), &mem())
        .unwrap_err()
        .to_string()
}

#[test]
fn defaults_are_secure_and_sane() {
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert_eq!(
        c.opcua.as_ref().unwrap().policy,
        SecurityPolicy::Basic256Sha256
    );
    assert_eq!(c.opcua.as_ref().unwrap().mode, SecurityMode::SignAndEncrypt);
    assert_eq!(c.opcua.as_ref().unwrap().identity, Identity::Anonymous);
    assert_eq!(c.opcua.as_ref().unwrap().pki_dir, PathBuf::from("base/pki"));
    assert_eq!(c.zenoh.prefix, "cellwatch/c1");
    assert_eq!(c.zenoh.mode, ZenohMode::Peer);
    assert_eq!(c.journal.path, PathBuf::from("base/cellwatch-c1.sqlite"));
    assert_eq!(c.metrics, Some(SocketAddr::from(([127, 0, 0, 1], 9464))));
    assert_eq!(c.switching[0].sf.notation(), "X1 * -X2");
    assert_eq!(c.switching[0].severity, Severity::High);
    assert_eq!(
        c.warnings,
        ["no commands.operators_file: every acknowledge and reset will be refused"]
    );
}

#[test]
fn unknown_key() {
    assert_eq!(
        errors(&GOOD.replace(
            "[cell]\nid = \"c1\"",
            "[cell]\nid = \"c1\"\ncolour = \"red\""
        )),
        "cell.toml:4:1: unknown field `colour`, expected one of `id`, `description`, `dialect`"
    );
}

#[test]
fn missing_tag_for_a_checks_address() {
    let text = GOOD.replace(
        "[[tags]]\nname = \"x2\"\nnode_id = \"nsu=urn:plc;s=X2\"\naddress = \"X2\"\n",
        "",
    );
    assert_eq!(
        errors(&text),
        "cell.toml:17:8: checks.switching[0].coil: G0.00 reads X2, but no tag has that address; add a [[tags]] entry for it"
    );
}

#[test]
fn unreadable_program() {
    assert_eq!(
        errors(&GOOD.replace("fig6.il", "nowhere.il")),
        "cell.toml:20:11: checks.switching[0].program: cannot read program 'base/nowhere.il': No such file or directory"
    );
}

#[test]
fn inline_password() {
    let text = GOOD.replace(
        "[[tags]]\nname = \"x1\"",
        "[opcua.identity]\nkind = \"user\"\nuser = \"kim\"\npassword = \"hunter2\"\n\n[[tags]]\nname = \"x1\"",
    );
    assert_eq!(
        errors(&text),
        "cell.toml:11:12: opcua.identity.password: passwords are never written in config files; use password_env (an environment variable) or password_file"
    );
}

#[test]
fn every_problem_is_reported_at_once() {
    let text = GOOD
        .replace("id = \"c1\"", "id = \"cell 1\"")
        .replace("opc.tcp://127.0.0.1:4840/", "http://plc")
        .replace("nsu=urn:plc;s=X1", "two;X1")
        .replace(
            "coil = \"G0.00\"",
            "coil = \"G0.00\"\nseverity = \"urgent\"",
        );
    let e = errors(&text);
    assert_eq!(
        e.lines().collect::<Vec<_>>(),
        [
            "cell.toml:3:6: cell.id: 'cell 1' must be letters, digits, '-' or '_' (it is part of Zenoh keys)",
            "cell.toml:6:12: opcua.endpoint: 'http://plc' must start with opc.tcp://",
            "cell.toml:10:11: tags[0].node_id: 'two;X1' is not a node id like nsu=<namespace uri>;s=X0.06 or ns=2;s=X0.06",
            "cell.toml:22:12: checks.switching[0].severity: unknown severity 'urgent': use low, medium, high or critical",
        ]
    );
}

#[test]
fn sampling_zero_is_exception_based_and_queues_fit_it() {
    let with = |extra: &str| {
        GOOD.replace(
            "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
            &format!("endpoint = \"opc.tcp://127.0.0.1:4840/\"\n{extra}"),
        )
    };
    let c = parse(
        "cell.toml",
        &with("sampling_interval = \"0\""),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(c.opcua.as_ref().unwrap().sampling_interval, Duration::ZERO);
    // 100 ms publishing, every change: room for four intervals of 1 ms samples.
    assert_eq!(c.opcua.as_ref().unwrap().queue_size, 400);
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert_eq!(
        (
            c.opcua.as_ref().unwrap().queue_size,
            c.opcua.as_ref().unwrap().max_notifications_per_publish
        ),
        (10, 10_000)
    );
    assert_eq!(
        errors(&with("queue_size = 0")),
        "cell.toml:7:14: opcua.queue_size: 0 is not between 1 and 10000"
    );
}

#[test]
fn the_subscription_outlives_a_network_cut_within_bounds() {
    let with = |extra: &str| {
        GOOD.replace(
            "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
            &format!("endpoint = \"opc.tcp://127.0.0.1:4840/\"\n{extra}"),
        )
    };
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert_eq!(
        c.opcua.unwrap().subscription_lifetime,
        Duration::from_secs(60)
    );
    let c = parse(
        "cell.toml",
        &with("subscription_lifetime = \"5m\""),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(
        c.opcua.unwrap().subscription_lifetime,
        Duration::from_secs(300)
    );
    // At least three keep-alive periods of the publishing interval (100 ms).
    assert_eq!(
        errors(&with("subscription_lifetime = \"2s\"")),
        "cell.toml:7:25: opcua.subscription_lifetime: at least three keep-alive periods (30 publishing intervals: 3s)"
    );
    assert_eq!(
        errors(&with("subscription_lifetime = \"2h\"")),
        "cell.toml:7:25: opcua.subscription_lifetime: at most 1h"
    );
    // A slow publishing interval stretches the default.
    let c = parse(
        "cell.toml",
        &with("publishing_interval = \"5s\""),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(
        c.opcua.unwrap().subscription_lifetime,
        Duration::from_secs(150)
    );
}

#[test]
fn monitored_items_are_verified_every_thirty_seconds_unless_configured() {
    let with = |extra: &str| {
        GOOD.replace(
            "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
            &format!("endpoint = \"opc.tcp://127.0.0.1:4840/\"\n{extra}"),
        )
    };
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.opcua.unwrap().verify_interval, Duration::from_secs(30));
    let c = parse(
        "cell.toml",
        &with("verify_interval = \"5s\""),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(c.opcua.unwrap().verify_interval, Duration::from_secs(5));
    assert_eq!(
        errors(&with("verify_interval = \"500ms\"")),
        "cell.toml:7:19: opcua.verify_interval: at least 1s"
    );
    assert_eq!(
        errors(&with("verify_interval = \"2h\"")),
        "cell.toml:7:19: opcua.verify_interval: at most 1h"
    );
}

#[test]
fn the_bus_is_tls_unless_plain_is_written() {
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    let tls = c.zenoh.tls.unwrap();
    assert_eq!(tls.ca, Path::new("base/pki-bus/ca.pem"));
    let no_tls = GOOD.split("[zenoh.tls]").next().unwrap().to_string();
    assert_eq!(
        errors(&format!("{no_tls}[zenoh]\nlisten = [\"tcp/0.0.0.0:7447\"]\n")),
        "cell.toml:24:11: zenoh: no [zenoh.tls]: the bus would be neither encrypted nor authenticated; give tls = { ca, cert, key } (made by `cellwatch pki`), or write plain = true to accept that"
    );
    let c = parse(
        "cell.toml",
        &format!("{no_tls}[zenoh]\nplain = true\nlisten = [\"tcp/0.0.0.0:7447\"]\n"),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert!(
        c.warnings
            .iter()
            .any(|w| w.starts_with("zenoh.plain = true")),
        "{:?}",
        c.warnings
    );
    let text = GOOD.replace(
        "[zenoh.tls]",
        "[zenoh]\nlisten = [\"tcp/0.0.0.0:7447\"]\n\n[zenoh.tls]",
    );
    assert_eq!(
        errors(&text),
        "cell.toml:24:11: zenoh.listen: 'tcp/0.0.0.0:7447': not an encrypted endpoint: the bus takes quic/host:port (mutual TLS over QUIC)"
    );
    // Zenoh's TLS-over-TCP link breaks its connections under load: refused,
    // with what to write instead.
    let text = GOOD.replace(
        "[zenoh.tls]",
        "[zenoh]\nconnect = [\"tls/router-1.plant:7447\"]\n\n[zenoh.tls]",
    );
    assert_eq!(
        errors(&text),
        "cell.toml:24:12: zenoh.connect: 'tls/router-1.plant:7447': Zenoh's tls/ link breaks its connections under load (it reads and writes one TLS stream from two threads at once, eclipse-zenoh/zenoh#2557): write quic/router-1.plant:7447 instead, with the same certificates (mutual TLS over QUIC, UDP)"
    );
}

#[test]
fn shared_operator_secrets_are_refused() {
    let text = format!("{GOOD}\n[commands]\nsecrets_file = \"ops.toml\"\n");
    assert_eq!(
        errors(&text),
        "cell.toml:29:16: commands.secrets_file: shared operator secrets are no longer accepted: operators sign with their own keys (cellwatch keygen --operator NAME); name the file of their public keys with commands.operators_file"
    );
}

#[test]
fn namespaces_are_named_by_uri() {
    // By URI in the node id itself: nothing to warn about.
    let c = parse("cell.toml", GOOD, Path::new("base"), &mem()).unwrap();
    assert!(
        !c.warnings.iter().any(|w| w.contains("namespace")),
        "{:?}",
        c.warnings
    );
    // `ns=2` with the URI it stands for: no warning about blind indices.
    let by_index = GOOD.replace("nsu=urn:plc;", "ns=2;");
    let text = by_index.replace(
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"\nnamespace_uri = \"urn:plc\"",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    assert_eq!(
        c.opcua.as_ref().unwrap().namespace_uri.as_deref(),
        Some("urn:plc")
    );
    assert!(
        !c.warnings.iter().any(|w| w.contains("namespace")),
        "{:?}",
        c.warnings
    );
    // A bare index without it is read, with a warning.
    let c = parse("cell.toml", &by_index, Path::new("base"), &mem()).unwrap();
    assert!(
        c.warnings
            .iter()
            .any(|w| w.contains("ns=2;... without opcua.namespace_uri")),
        "{:?}",
        c.warnings
    );
    // One URI cannot stand for two indices.
    let text = text.replace("ns=2;s=X2", "ns=3;s=X2");
    assert_eq!(
        errors(&text),
        "cell.toml:7:17: opcua.namespace_uri: names one namespace ('urn:plc') but the tags use ns=2 and ns=3: write their node ids as nsu=<namespace uri>;..."
    );
    let text = GOOD.replace("nsu=urn:plc;s=X1", "nsu=;s=X1");
    assert_eq!(
        errors(&text),
        "cell.toml:10:11: tags[0].node_id: 'nsu=;s=X1' names an empty namespace uri"
    );
}

#[test]
fn security_none_only_when_explicit_and_with_a_warning() {
    let text = GOOD.replace(
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"\nsecurity_policy = \"None\"",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    assert_eq!(c.opcua.as_ref().unwrap().mode, SecurityMode::None);
    assert!(c.warnings[0].starts_with("OPC UA security is off"));
    let text = GOOD.replace(
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"\nsecurity_policy = \"Basic128Rsa15\"",
    );
    assert_eq!(
        errors(&text),
        "cell.toml:7:19: opcua.security_policy: 'Basic128Rsa15' is deprecated and insecure; use Basic256Sha256"
    );
}

/// Every configuration shipped in `config/` is documentation: it must parse.
#[test]
fn shipped_configs_parse() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        if path.file_name().is_some_and(|n| n == "console.toml") {
            // The console's, not a cell's: `console::config`'s tests parse it.
            continue;
        }
        if path.file_name().is_some_and(|n| n == "stop-causes.toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            let causes: cellwatch_models::report::StopCauses =
                toml::from_str(&text).unwrap_or_else(|e| panic!("{}:\n{e}", path.display()));
            assert!(
                causes.causes.len() >= 6,
                "paper 002's Table 4 has six causes"
            );
        } else {
            let c = load(&path).unwrap_or_else(|e| panic!("{}:\n{e}", path.display()));
            assert!(!c.tags.is_empty());
        }
        seen += 1;
    }
    assert!(
        seen >= 2,
        "expected demo.toml and stop-causes.toml in {}",
        dir.display()
    );
}

mod checks;
mod consequences;
mod database;
mod escalation;
mod events;
mod modes;
mod oee;
mod rates;

#[test]
fn alertmanager_urls_tls_and_interval_are_checked() {
    let good = format!(
        "{GOOD}\n[alertmanager]\nurls = [\"http://127.0.0.1:9093/\", \"https://am.plant:9093/am\"]\narea = \"press shop\"\nconsole = \"https://console.plant:8470/\"\nresend_interval = \"30s\"\n[alertmanager.tls]\nca = \"pki/am-ca.pem\"\n"
    );
    let c = parse("cell.toml", &good, Path::new("base"), &mem()).unwrap();
    let am = c.alertmanager.unwrap();
    assert_eq!(
        am.urls,
        ["http://127.0.0.1:9093", "https://am.plant:9093/am"]
    );
    assert_eq!(am.area.as_deref(), Some("press shop"));
    assert_eq!(am.console.as_deref(), Some("https://console.plant:8470"));
    assert_eq!(am.resend, Duration::from_secs(30));
    assert_eq!(am.tls.unwrap().ca, PathBuf::from("base/pki/am-ca.pem"));
    // Without the section, nothing is pushed; plain HTTP off this machine
    // is said.
    assert!(parse("cell.toml", GOOD, Path::new("base"), &mem())
        .unwrap()
        .alertmanager
        .is_none());
    let plain = format!("{GOOD}\n[alertmanager]\nurls = [\"http://am.plant:9093\"]\n");
    let c = parse("cell.toml", &plain, Path::new("base"), &mem()).unwrap();
    assert!(
        c.warnings.iter().any(|w| w
            == "alertmanager.urls: http://am.plant:9093 is plain HTTP: alerts cross the network unencrypted and unauthenticated"),
        "{:?}",
        c.warnings
    );
    assert_eq!(c.alertmanager.unwrap().resend, DEFAULT_RESEND);

    let bad = format!(
        "{GOOD}\n[alertmanager]\nurls = [\"am.plant:9093\", \"https://am.plant:9093\", \"http://am?x=1\"]\nresend_interval = \"2h\"\n[alertmanager.tls]\nca = \"ca.pem\"\ncert = \"agent.pem\"\n"
    );
    assert_eq!(
        errors(&bad),
        [
            "cell.toml:29:9: alertmanager.urls: 'am.plant:9093': use http:// or https://",
            "cell.toml:29:51: alertmanager.urls: 'http://am?x=1': no query (?…) is allowed",
            "cell.toml:30:19: alertmanager.resend_interval: at most 1h: active alerts end four intervals after they were last sent",
            "cell.toml:31:1: alertmanager.tls: give both cert and key (a client certificate), or neither",
        ]
        .join("\n")
    );
    let many: Vec<String> = (0..17)
        .map(|i| format!("\"http://127.0.0.1:{}\"", 9000 + i))
        .collect();
    let too_many = format!("{GOOD}\n[alertmanager]\nurls = [{}]\n", many.join(", "));
    assert!(
        errors(&too_many)
            .ends_with("alertmanager.urls: at most 16 Alertmanagers (a cluster's instances)"),
        "{}",
        errors(&too_many)
    );
    let https = format!("{GOOD}\n[alertmanager]\nurls = [\"https://am.plant:9093\"]\n");
    assert_eq!(
        errors(&https),
        "cell.toml:29:9: alertmanager.tls: an https:// Alertmanager needs [alertmanager.tls] ca = the CA that signed its certificate"
    );
}

#[test]
fn journal_tables_keep_their_own_retention_and_rows() {
    let text = format!(
        "{GOOD}\n[journal]\nretention = \"30d\"\n[journal.tables.commands]\nretention = \"3650d\"\n[journal.tables.state_history]\nmax_rows = 2000000\n"
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let day = |d: u64| Duration::from_secs(d * 86_400);
    let keep: Vec<(&str, Duration, Option<u64>)> = c
        .journal
        .keep
        .iter()
        .map(|k| (k.table, k.age, k.max_rows))
        .collect();
    assert_eq!(
        keep,
        [
            ("alarm_events", day(30), None),
            ("state_history", day(30), Some(2_000_000)),
            ("commands", day(3650), None),
            ("production", day(30), None),
            ("orders", day(30), None),
            ("recordings", day(30), None),
            ("modes", day(30), None),
        ]
    );
    let bad = format!(
        "{GOOD}\n[journal]\nretention = \"10m\"\n[journal.tables.state_history]\nmax_rows = 10\n"
    );
    assert_eq!(
        errors(&bad),
        "cell.toml:29:13: journal.retention: at least 1h\ncell.toml:31:12: journal.tables.state_history.max_rows: at least 1000"
    );
    let unknown = format!("{GOOD}\n[journal.tables.alarm_current]\nmax_rows = 5000\n");
    assert!(
        errors(&unknown).contains("unknown field `alarm_current`, expected one of `alarm_events`, `state_history`, `commands`, `production`, `orders`"),
        "{}",
        errors(&unknown)
    );
}

#[test]
fn the_agents_own_alarms_clear_after_an_off_delay_unless_configured() {
    let c = parse(
        "cell.toml",
        &format!(
            "{GOOD}\n[alarms.communication]\non_delay = \"2s\"\noff_delay = \"0\"\n\n[alarms.tag-quality]\noff_delay = \"30s\"\n"
        ),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(
        c.delays,
        [
            ("communication".to_string(), 2_000, 0),
            ("tag-quality".to_string(), 0, 30_000)
        ]
    );
    assert_eq!(
        errors(&format!(
            "{GOOD}\n[alarms.communication]\noff_delay = \"2h\"\n"
        )),
        "cell.toml:29:13: alarms.communication.off_delay: at most 1h"
    );
    assert_eq!(
        errors(&format!("{GOOD}\n[alarms.tag-quality]\non_delay = \"soon\"\n")),
        "cell.toml:29:12: alarms.tag-quality.on_delay: 'soon' is not a duration (expected number at 0); write e.g. 100ms, 2s, 30d"
    );
    assert_eq!(
        errors(&format!("{GOOD}\n[alarms.ese]\noff_delay = \"1s\"\n")),
        "cell.toml:28:9: unknown field `ese`, expected one of `communication`, `tag-quality`, `consequences`, `database`"
    );
}

/// Paper 000's fig6 as TIA Portal exports it (`base/tia/`: the block and
/// its tag table, one object per file), and the `[[tags]]` of its contacts.
fn tia_folder() -> (Mem, String) {
    let mut files = mem();
    files.0.insert(
        PathBuf::from("base/tia/Fig6.xml"),
        include_bytes!("../../../tests/data/paper000/fig6.lad.SimaticML.xml").to_vec(),
    );
    files.0.insert(
        PathBuf::from("base/tia/PLC tags.xml"),
        include_bytes!("../../../tests/data/paper000/fig6.tags.SimaticML.xml").to_vec(),
    );
    let tags = ["X1", "X2", "X3", "X4", "Y1", "Y2"]
        .iter()
        .map(|a| format!("[[tags]]\nname = \"{a}\"\nnode_id = \"nsu=urn:plc;s={a}\"\naddress = '\"{a}\"'\n\n"))
        .collect();
    (files, tags)
}

#[test]
fn a_tia_portal_block_gets_the_comments_of_the_tag_table_exported_beside_it() {
    let (mut files, tags) = tia_folder();
    let text = format!(
        "[cell]\nid = \"c1\"\ndialect = \"stl\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n{tags}\
         [[checks.switching]]\nid = \"fig6\"\nprogram = \"tia/Fig6.xml\"\ncoil = '\"G0_00\"'\n\n\
         [zenoh.tls]\nca = \"ca.pem\"\ncert = \"c.pem\"\nkey = \"c.key\"\n"
    );
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    let comments = &c.switching[0].comments;
    assert_eq!(comments.get(&Signal::new("X3")), Some("Door closed switch"));
    // The project's comments in German.
    let german = text.replace(
        "coil = '\"G0_00\"'",
        "coil = '\"G0_00\"'\ncomment_language = \"de-DE\"",
    );
    let c = parse("cell.toml", &german, Path::new("base"), &files).unwrap();
    let comments = &c.switching[0].comments;
    assert_eq!(comments.get(&Signal::new("X3")), Some("Tür geschlossen"));
    let e = parse(
        "cell.toml",
        &german.replace("\"de-DE\"", "\"German\""),
        Path::new("base"),
        &files,
    )
    .unwrap_err()
    .to_string();
    assert_eq!(
        e,
        "cell.toml:42:20: checks.switching[0].comment_language: 'German' is not a language as TIA Portal names one: write e.g. de-DE or en-US"
    );
    // A broken tag table beside it is said, with its place.
    files.0.insert(
        PathBuf::from("base/tia/PLC tags.xml"),
        b"<?xml version=\"1.0\"?>\n<Document>\n<SW.Tags.PlcTagTable>\n</Document>\n".to_vec(),
    );
    let e = parse("cell.toml", &text, Path::new("base"), &files)
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "base/tia/PLC tags.xml:4:1: not well-formed XML: expected 'SW.Tags.PlcTagTable' tag, not 'Document' at 4:1"
    );
}

#[test]
fn a_folder_of_tia_portal_exports_is_read_once_however_many_checks_read_blocks_in_it() {
    /// `Mem`, counting the reads of each file.
    struct Counting(Mem, std::cell::RefCell<HashMap<PathBuf, usize>>);
    impl Files for Counting {
        fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
            *self.1.borrow_mut().entry(path.to_path_buf()).or_default() += 1;
            self.0.read(path)
        }
        fn list(&self, dir: &Path) -> io::Result<Vec<PathBuf>> {
            self.0.list(dir)
        }
    }
    let (files, tags) = tia_folder();
    let checks: String = (0..3)
        .map(|i| format!("[[checks.switching]]\nid = \"fig6-{i}\"\nprogram = \"tia/Fig6.xml\"\ncoil = '\"G0_00\"'\n\n"))
        .collect();
    let text = format!(
        "[cell]\nid = \"c1\"\ndialect = \"stl\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n{tags}{checks}\
         [zenoh.tls]\nca = \"ca.pem\"\ncert = \"c.pem\"\nkey = \"c.key\"\n"
    );
    let files = Counting(files, Default::default());
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    for check in &c.switching {
        assert_eq!(
            check.comments.get(&Signal::new("X3")),
            Some("Door closed switch")
        );
    }
    let reads = files.1.borrow();
    // The tag table once for the folder; each check reads its block.
    assert_eq!(reads[Path::new("base/tia/PLC tags.xml")], 1, "{reads:?}");
    assert_eq!(reads[Path::new("base/tia/Fig6.xml")], 3 + 1, "{reads:?}");
}

#[test]
fn a_server_that_dials_out_is_listened_for_at_an_ip_address() {
    let with = |v: &str| {
        GOOD.replace(
            "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
            &format!("endpoint = \"opc.tcp://127.0.0.1:4840/\"\nreverse_listen = \"{v}\""),
        )
    };
    let c = parse(
        "cell.toml",
        &with("opc.tcp://0.0.0.0:4843"),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    assert_eq!(
        c.opcua.unwrap().reverse_listen,
        Some(SocketAddr::from(([0, 0, 0, 0], 4843)))
    );
    assert!(parse("cell.toml", GOOD, Path::new("base"), &mem())
        .unwrap()
        .opcua
        .unwrap()
        .reverse_listen
        .is_none());
    assert_eq!(
        errors(&with("opc.tcp://agent-host:4843")),
        "cell.toml:7:18: opcua.reverse_listen: 'opc.tcp://agent-host:4843' is not opc.tcp://ADDRESS:PORT with an IP address: write e.g. opc.tcp://0.0.0.0:4843"
    );
}

#[test]
fn a_redundant_set_names_each_other_server_once() {
    let with = |v: &str| {
        GOOD.replace(
            "endpoint = \"opc.tcp://127.0.0.1:4840/\"",
            &format!("endpoint = \"opc.tcp://127.0.0.1:4840/\"\nredundant = {v}"),
        )
    };
    let c = parse(
        "cell.toml",
        &with("[\"opc.tcp://127.0.0.2:4840/\"]"),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    let ua = c.opcua.unwrap();
    assert_eq!(
        ua.servers(),
        ["opc.tcp://127.0.0.1:4840/", "opc.tcp://127.0.0.2:4840/"]
    );
    assert_eq!(ua.at("opc.tcp://127.0.0.2:4840/").endpoint, ua.redundant[0]);
    assert_eq!(
        errors(&with("[\"opc.tcp://127.0.0.1:4840/\"]")),
        "cell.toml:7:14: opcua.redundant[0]: 'opc.tcp://127.0.0.1:4840/' is named twice in the set"
    );
    assert_eq!(
        errors(&with("[\"http://b:4840/\"]")),
        "cell.toml:7:14: opcua.redundant[0]: 'http://b:4840/' must start with opc.tcp://"
    );
    let reverse = with("[\"opc.tcp://b:4840/\"]\nreverse_listen = \"opc.tcp://0.0.0.0:4843\"");
    assert_eq!(
        errors(&reverse),
        "cell.toml:7:14: opcua.redundant[0]: a redundant set is dialled by the agent: not with opcua.reverse_listen"
    );
}

#[test]
fn a_studio_5000_export_is_a_cells_program() {
    let mut files = mem();
    files.0.insert(
        PathBuf::from("base/fig6.L5X"),
        include_bytes!("../../../tests/data/paper000/fig6.L5X").to_vec(),
    );
    let tags: String = ["X1", "X2", "X3", "X4", "Y1", "Y2"]
        .iter()
        .map(|a| {
            format!(
                "[[tags]]\nname = \"{a}\"\nnode_id = \"nsu=urn:plc;s={a}\"\naddress = \"{a}\"\n\n"
            )
        })
        .collect();
    let text = format!(
        "[cell]\nid = \"c1\"\ndialect = \"iec\"\n\n[opcua]\nendpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n{tags}\
         [[checks.switching]]\nid = \"csd\"\nprogram = \"fig6.L5X\"\ncoil = \"G0_00\"\nfault_when = \"off\"\n\n\
         [zenoh.tls]\nca = \"ca.pem\"\ncert = \"c.pem\"\nkey = \"c.key\"\n"
    );
    let c = parse("cell.toml", &text, Path::new("base"), &files).unwrap();
    assert_eq!(
        c.switching[0].sf.notation(),
        "X4 * -Y2 * ((X1 * -X2) + -X3) * -Y1"
    );
    assert_eq!(
        c.switching[0].comments.get(&Signal::new("Y2")),
        Some("Y2: axis alarm lamp")
    );
}

#[test]
fn alarm_server_listens_on_opc_tcp_with_a_users_file() {
    let good = format!(
        "{GOOD}\n[alarm_server]\nlisten = \"opc.tcp://0.0.0.0:4855\"\nusers_file = \"opcua-users.toml\"\n"
    );
    let c = parse("cell.toml", &good, Path::new("base"), &mem()).unwrap();
    let s = c.alarm_server.unwrap();
    assert_eq!(s.listen, "0.0.0.0:4855".parse().unwrap());
    assert_eq!(s.users_file, PathBuf::from("base/opcua-users.toml"));
    assert_eq!(s.pki_dir, PathBuf::from("base/alarm-server-pki"));
    let bad = format!("{GOOD}\n[alarm_server]\nlisten = \"scada:4855\"\n");
    assert_eq!(
        errors(&bad),
        [
            "cell.toml:29:10: alarm_server.listen: 'scada:4855' is not like opc.tcp://0.0.0.0:4855",
            "cell.toml:28:1: alarm_server.users_file: required: the file of the OPC UA users and the operators they act as",
        ]
        .join("\n")
    );
}
