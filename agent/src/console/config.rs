//! The console's configuration file (`cellwatch console --config FILE`):
//! where it serves its pages, how it joins the bus, which cells form which
//! area, and whose operators' permissions it offers.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::config::{link_problem, ConfigErrors, ZenohConfig, ZenohMode, ZenohTls, DEFAULT_ROOT};
use crate::table::line_col;

/// The address the console serves on unless `http.listen` says otherwise.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:8470";

/// How long an operator's sign-in lasts unless `http.session` says
/// otherwise: a shift and its handover.
pub const DEFAULT_SESSION: std::time::Duration = std::time::Duration::from_secs(12 * 3600);

/// The most alarms the console keeps (active, unacknowledged, shelved or
/// out of service) unless `console.max_alarms` says otherwise.
pub const DEFAULT_MAX_ALARMS: usize = 20_000;

/// A validated console configuration.
#[derive(Debug, Clone)]
pub struct ConsoleConfig {
    /// Where the pages are served.
    pub listen: SocketAddr,
    /// The HTTPS certificate and key (PEM); `None`: plain HTTP, only on
    /// loopback or with `http.plain = true`.
    pub tls: Option<HttpTls>,
    /// The console's Zenoh session (a client: it listens on nothing).
    pub bus: ZenohConfig,
    /// The plant trust file: every alarm, state and answer is believed only
    /// if its cell's agent signed it.
    pub trust: PathBuf,
    /// The root of the agents' prefixes.
    pub root: String,
    /// The operators file (public keys and permissions): the page offers
    /// an operator only the actions it allows. Agents check them anyway.
    pub operators_file: Option<PathBuf>,
    /// Areas, by name: the cells of each.
    pub areas: BTreeMap<String, Vec<String>>,
    /// The most alarms kept at once.
    pub max_alarms: usize,
    /// How long an operator's sign-in lasts.
    pub session: std::time::Duration,
    /// The host names the console is reached by, besides loopback's, its
    /// listening address and its certificate's names: a request for any
    /// other `Host` or from any other `Origin` is refused.
    pub names: Vec<String>,
    /// Who may read which cells (`[readers]`: identity → areas, cells or
    /// `*`); `None`: every plant identity reads every cell.
    pub readers: Option<BTreeMap<String, Vec<String>>>,
    /// What the plant deployed to each agent (`plant.deployed`, the file
    /// `cellwatch plant` writes): the Agents page judges each agent's
    /// `about` against it; `None`: only against this console's version
    /// and the certificates' ends.
    pub deployed: Option<PathBuf>,
}

/// The console's HTTPS files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HttpTls {
    /// Its certificate chain (PEM), e.g. from `cellwatch pki issue`.
    pub cert: PathBuf,
    /// Its private key (PEM).
    pub key: PathBuf,
    /// The plant CA (PEM) whose client certificates sign a reader in
    /// (mutual TLS); `None`: operators sign in with their keys only.
    pub clients: Option<PathBuf>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    #[serde(default)]
    http: RawHttp,
    bus: Spanned<RawBus>,
    #[serde(default)]
    operators: RawOperators,
    #[serde(default)]
    areas: BTreeMap<String, Spanned<Vec<String>>>,
    #[serde(default)]
    console: RawConsole,
    readers: Option<BTreeMap<String, Spanned<Vec<String>>>>,
    #[serde(default)]
    plant: RawPlant,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlant {
    deployed: Option<String>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHttp {
    listen: Option<Spanned<String>>,
    tls: Option<Spanned<RawHttpTls>>,
    plain: Option<bool>,
    session: Option<Spanned<String>>,
    #[serde(default)]
    names: Vec<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHttpTls {
    cert: String,
    key: String,
    clients: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBus {
    mode: Option<Spanned<String>>,
    #[serde(default)]
    connect: Vec<Spanned<String>>,
    tls: Option<RawBusTls>,
    plain: Option<bool>,
    root: Option<String>,
    trust: Spanned<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBusTls {
    ca: String,
    cert: String,
    key: String,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOperators {
    file: Option<String>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConsole {
    max_alarms: Option<Spanned<i64>>,
}

/// Reads and validates the console's configuration file; relative paths
/// are taken from the file's directory.
///
/// # Errors
/// Every problem, each as `FILE:LINE:COL: key: message`.
pub fn load(path: &Path) -> Result<ConsoleConfig, ConfigErrors> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| ConfigErrors(vec![format!("{name}: cannot read: {e}")]))?;
    let base = path
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    parse(&name, &text, &base)
}

/// Validates the console configuration `text` named `origin`; relative
/// paths are resolved against `base`.
///
/// # Errors
/// Every problem, each as `ORIGIN:LINE:COL: key: message`.
pub fn parse(origin: &str, text: &str, base: &Path) -> Result<ConsoleConfig, ConfigErrors> {
    let at = |span: std::ops::Range<usize>, key: &str, message: String| {
        let (line, col) = line_col(text, span.start);
        format!("{origin}:{line}:{col}: {key}: {message}")
    };
    let raw: Raw = toml::from_str(text).map_err(|e| {
        let (line, col) = e.span().map_or((1, 1), |s| line_col(text, s.start));
        ConfigErrors(vec![format!("{origin}:{line}:{col}: {}", e.message())])
    })?;
    let path = |p: &str| {
        let p = PathBuf::from(p);
        if p.is_absolute() {
            p
        } else {
            base.join(p)
        }
    };
    let mut problems = Vec::new();

    let listen = match &raw.http.listen {
        None => DEFAULT_LISTEN.parse().ok(),
        Some(l) => match l.get_ref().parse::<SocketAddr>() {
            Ok(a) => Some(a),
            Err(_) => {
                problems.push(at(
                    l.span(),
                    "http.listen",
                    format!("'{}' is not an IP:port address", l.get_ref()),
                ));
                None
            }
        },
    };
    let tls = raw.http.tls.as_ref().map(|t| HttpTls {
        cert: path(&t.get_ref().cert),
        key: path(&t.get_ref().key),
        clients: t.get_ref().clients.as_deref().map(path),
    });
    if let (Some(listen), None) = (listen, &tls) {
        if !listen.ip().is_loopback() && raw.http.plain != Some(true) {
            let span = raw.http.listen.as_ref().map_or(0..0, Spanned::span);
            problems.push(at(
                span,
                "http.listen",
                format!("{listen} is reachable from the network: give http.tls (cert and key from `cellwatch pki issue`), or write http.plain = true to serve plain HTTP there knowingly"),
            ));
        }
    }

    let bus_span = raw.bus.span();
    let bus = raw.bus.into_inner();
    let mode = match bus.mode.as_ref().map(|m| m.get_ref().as_str()) {
        None | Some("peer") => ZenohMode::Peer,
        Some("client") => ZenohMode::Client,
        Some(other) => {
            problems.push(at(
                bus.mode.as_ref().map_or(bus_span.clone(), Spanned::span),
                "bus.mode",
                format!(
                    "unknown mode '{other}': use peer or client (the console listens on nothing)"
                ),
            ));
            ZenohMode::Peer
        }
    };
    let plain = bus.plain == Some(true);
    if bus.connect.is_empty() {
        problems.push(at(
            bus_span.clone(),
            "bus.connect",
            "no endpoint: give the agents' or a router's endpoints (quic/HOST:PORT)".into(),
        ));
    }
    for e in &bus.connect {
        if !plain {
            if let Some(problem) = link_problem(e.get_ref()) {
                problems.push(at(
                    e.span(),
                    "bus.connect",
                    format!("'{}': {problem}", e.get_ref()),
                ));
            }
        }
    }
    let bus_tls = bus.tls.as_ref().map(|t| ZenohTls {
        ca: path(&t.ca),
        cert: path(&t.cert),
        key: path(&t.key),
    });
    if bus_tls.is_none() && !plain {
        problems.push(at(
            bus_span,
            "bus.tls",
            "missing: the console joins the bus with its own certificate from the plant CA (ca, cert, key), or write bus.plain = true for a bus without TLS".into(),
        ));
    }
    let root = bus.root.clone().unwrap_or_else(|| DEFAULT_ROOT.into());

    let mut areas = BTreeMap::new();
    let mut area_of: BTreeMap<String, String> = BTreeMap::new();
    for (area, cells) in raw.areas {
        for cell in cells.get_ref() {
            if let Some(first) = area_of.insert(cell.clone(), area.clone()) {
                problems.push(at(
                    cells.span(),
                    &format!("areas.{area}"),
                    format!("cell '{cell}' is already in area '{first}': a cell is in one area"),
                ));
            }
        }
        areas.insert(area, cells.into_inner());
    }

    let max_alarms = match &raw.console.max_alarms {
        None => DEFAULT_MAX_ALARMS,
        Some(n) if (100..=1_000_000).contains(n.get_ref()) => {
            usize::try_from(*n.get_ref()).unwrap_or(DEFAULT_MAX_ALARMS)
        }
        Some(n) => {
            problems.push(at(
                n.span(),
                "console.max_alarms",
                format!("{} is not in 100 to 1000000", n.get_ref()),
            ));
            DEFAULT_MAX_ALARMS
        }
    };

    let session = match &raw.http.session {
        None => DEFAULT_SESSION,
        Some(text) => match humantime::parse_duration(text.get_ref()) {
            Ok(d) if (300..=7 * 86_400).contains(&d.as_secs()) => d,
            _ => {
                problems.push(at(
                    text.span(),
                    "http.session",
                    format!(
                        "'{}' is not a duration from 5m to 7d (e.g. 12h)",
                        text.get_ref()
                    ),
                ));
                DEFAULT_SESSION
            }
        },
    };
    let mut names = Vec::new();
    for n in &raw.http.names {
        let name = n.get_ref();
        let plain = !name.is_empty()
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b".-:[]".contains(&b));
        if plain {
            names.push(name.to_ascii_lowercase());
        } else {
            problems.push(at(
                n.span(),
                "http.names",
                format!(
                    "'{name}' is not a host name or address (console.plant.example, 10.20.0.9)"
                ),
            ));
        }
    }
    let clients = tls.as_ref().and_then(|t| t.clients.as_ref());
    if raw.operators.file.is_none() && clients.is_none() {
        problems.push(format!(
            "{origin}: nobody could sign in: give operators.file (operators sign in with their keys) or http.tls.clients (the plant CA, for client certificates)"
        ));
    }
    let readers = raw.readers.map(|r| {
        r.into_iter()
            .map(|(who, cells)| (who, cells.into_inner()))
            .collect()
    });

    if !problems.is_empty() {
        return Err(ConfigErrors(problems));
    }
    Ok(ConsoleConfig {
        listen: listen.unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 8470))),
        tls,
        bus: ZenohConfig {
            mode,
            connect: bus.connect.iter().map(|e| e.get_ref().clone()).collect(),
            listen: Vec::new(),
            prefix: String::new(),
            multicast_scouting: false,
            tls: bus_tls,
            config_file: None,
            plain,
            signing_key: None,
        },
        trust: path(bus.trust.get_ref()),
        root,
        operators_file: raw.operators.file.as_deref().map(path),
        deployed: raw.plant.deployed.as_deref().map(path),
        areas,
        max_alarms,
        session,
        names,
        readers,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[http]
listen = "0.0.0.0:8443"
tls = { cert = "console.pem", key = "console.key" }

[bus]
connect = ["quic/10.0.0.5:7447"]
tls = { ca = "ca.pem", cert = "c.pem", key = "c.key" }
trust = "trust.toml"

[operators]
file = "operators.toml"

[areas]
press-shop = ["press7", "press8"]
"#;

    #[test]
    fn the_shipped_example_is_valid() {
        let text = include_str!("../../../config/console.toml");
        let c = parse("config/console.toml", text, Path::new("/etc/cellwatch"))
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.bus.mode, ZenohMode::Client);
        assert_eq!(c.areas.len(), 2);
        assert!(c.tls.is_some() && c.operators_file.is_some());
        assert_eq!(
            c.tls.as_ref().and_then(|t| t.clients.clone()),
            Some(PathBuf::from("/etc/cellwatch/pki/ca.pem"))
        );
        assert_eq!(c.names, vec!["console.plant.example"]);
        assert_eq!(c.session, DEFAULT_SESSION);
        assert_eq!(
            c.readers.as_ref().map(|r| r["ana"].clone()),
            Some(vec!["press-shop".to_string()])
        );
    }

    #[test]
    fn a_console_nobody_could_sign_in_to_is_refused() {
        let text = GOOD.replace("[operators]\nfile = \"operators.toml\"\n", "");
        let e = parse("c.toml", &text, Path::new("."))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "c.toml: nobody could sign in: give operators.file (operators sign in with their keys) or http.tls.clients (the plant CA, for client certificates)"
        );
        let with_clients = text.replace(
            "key = \"console.key\" }",
            "key = \"console.key\", clients = \"ca.pem\" }",
        );
        assert!(parse("c.toml", &with_clients, Path::new(".")).is_ok());
    }

    #[test]
    fn a_session_and_names_out_of_form_are_said_with_their_place() {
        let text = GOOD.replace(
            "[http]\n",
            "[http]\nsession = \"1s\"\nnames = [\"console.plant.example\", \"a b\"]\n",
        );
        let e = parse("c.toml", &text, Path::new("."))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "c.toml:3:11: http.session: '1s' is not a duration from 5m to 7d (e.g. 12h)"
            ),
            "{e}"
        );
        assert!(
            e.contains("c.toml:4:35: http.names: 'a b' is not a host name or address"),
            "{e}"
        );
    }

    #[test]
    fn a_good_file_gives_every_key() {
        let c = parse("console.toml", GOOD, Path::new("/etc/cellwatch")).expect("valid");
        assert_eq!(c.listen.to_string(), "0.0.0.0:8443");
        assert_eq!(
            c.tls.as_ref().map(|t| t.cert.clone()),
            Some(PathBuf::from("/etc/cellwatch/console.pem"))
        );
        assert_eq!(c.trust, PathBuf::from("/etc/cellwatch/trust.toml"));
        assert_eq!(c.areas["press-shop"], vec!["press7", "press8"]);
        assert_eq!(c.root, DEFAULT_ROOT);
        assert_eq!(c.max_alarms, DEFAULT_MAX_ALARMS);
    }

    #[test]
    fn plain_http_off_loopback_is_refused_with_its_place() {
        let text = GOOD.replace(
            "tls = { cert = \"console.pem\", key = \"console.key\" }\n",
            "",
        );
        let e = parse("console.toml", &text, Path::new(".")).unwrap_err();
        assert_eq!(e.0.len(), 1, "{e}");
        assert!(
            e.0[0].starts_with("console.toml:3:10: http.listen: 0.0.0.0:8443 is reachable"),
            "{e}"
        );
        let knowingly = text.replace("[http]\n", "[http]\nplain = true\n");
        assert!(parse("console.toml", &knowingly, Path::new(".")).is_ok());
    }

    #[test]
    fn every_problem_is_said_at_once() {
        let text = r#"
[http]
listen = "here"
[bus]
connect = ["tcp/10.0.0.5:7447"]
trust = "t.toml"
[areas]
a = ["m1"]
b = ["m1"]
[console]
max_alarms = 5
"#;
        let e = parse("c.toml", text, Path::new("."))
            .unwrap_err()
            .to_string();
        for expected in [
            "c.toml:3:10: http.listen: 'here' is not an IP:port address",
            "c.toml:5:12: bus.connect: 'tcp/10.0.0.5:7447': not an encrypted endpoint",
            "bus.tls: missing",
            "areas.b: cell 'm1' is already in area 'a'",
            "c.toml:11:14: console.max_alarms: 5 is not in 100 to 1000000",
        ] {
            assert!(e.contains(expected), "{expected:?} not in:\n{e}");
        }
    }

    #[test]
    fn an_unknown_key_is_named() {
        let text = GOOD.replace("[areas]", "[areas]\n").replace(
            "trust = \"trust.toml\"",
            "trust = \"trust.toml\"\nlisten = [\"quic/0.0.0.0:7447\"]",
        );
        let e = parse("c.toml", &text, Path::new("."))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown field `listen`"), "{e}");
    }
}
