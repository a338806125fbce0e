//! `plant.toml`, the plant inventory: its areas, cells (each on a host,
//! with its PLC and its configuration), routers, operators with their
//! permissions per area or cell, and the console. Read with every value's
//! place, validated whole: every problem is said at its line and column.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::PlantError;
use crate::operator::Action;

/// The bus port a router listens on unless its entry says otherwise.
pub(crate) const ROUTER_PORT: u16 = 7447;
/// The `/metrics` port of a cell's agent unless its entry says otherwise.
pub(crate) const METRICS_PORT: u16 = 9464;
/// The console's HTTPS port unless `[console]` says otherwise.
pub(crate) const CONSOLE_PORT: u16 = 8443;

/// Configuration on every host: where the packaged unit
/// `cellwatch@.service` reads `<cell>.toml`.
pub(crate) const ETC: &str = "/etc/cellwatch";
/// The agents' state on every host: the unit's `StateDirectory`.
pub(crate) const STATE: &str = "/var/lib/cellwatch";
/// How long the routers' archive keeps what the agents put unless
/// `[plant] archive_retention` says otherwise.
pub(crate) const ARCHIVE_RETENTION: &str = "90d";

/// The plant, as its inventory says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inventory {
    /// The inventory file.
    pub path: PathBuf,
    /// The folder it is in: every generated file is under it.
    pub dir: PathBuf,
    /// `[plant] name`.
    pub name: String,
    /// The root of the agents' prefixes (`cellwatch`).
    pub root: String,
    /// `[plant] archive_retention`: how long the routers' archive keeps
    /// what the agents put ([`ARCHIVE_RETENTION`] unless set).
    pub archive_retention: String,
    /// Where the hosts keep configuration: [`ETC`].
    pub etc: String,
    /// Where the hosts keep the agents' state: [`STATE`].
    pub state: String,
    /// The routers, by name.
    pub routers: BTreeMap<String, Router>,
    /// The cells, by id.
    pub cells: BTreeMap<String, InventoryCell>,
    /// The operators, by name.
    pub operators: BTreeMap<String, Operator>,
    /// The console, when the plant has one.
    pub console: Option<ConsoleSite>,
}

/// A `zenohd` router.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Router {
    /// The name clients reach it by (and its certificate's first name).
    pub host: String,
    /// More names or addresses its certificate holds.
    pub addresses: Vec<String>,
    /// Its QUIC port.
    pub port: u16,
}

/// A cell and its agent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InventoryCell {
    /// Its area.
    pub area: String,
    /// The host its agent runs on.
    pub host: String,
    /// The PLC's OPC UA endpoint, when the plant sets it.
    pub plc: Option<String>,
    /// The cell's own configuration (its checks), resolved against the
    /// inventory's folder.
    pub config: PathBuf,
    /// Its agent's `/metrics` port.
    pub metrics: u16,
}

/// An operator and what they may do where.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Operator {
    /// Their Ed25519 public key, 64 hex digits.
    pub public_key: String,
    /// Allowed on every cell.
    pub allow: BTreeSet<Action>,
    /// Allowed on the cells of an area.
    pub areas: BTreeMap<String, BTreeSet<Action>>,
    /// Allowed on one cell.
    pub cells: BTreeMap<String, BTreeSet<Action>>,
}

impl Operator {
    /// What the operator may do on `cell` of `area`.
    pub fn allowed_on(&self, cell: &str, area: &str) -> BTreeSet<Action> {
        let mut all = self.allow.clone();
        all.extend(self.areas.get(area).into_iter().flatten());
        all.extend(self.cells.get(cell).into_iter().flatten());
        all
    }
}

/// The operators' console.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConsoleSite {
    /// The host it runs on, the name browsers reach it by.
    pub host: String,
    /// Its HTTPS port.
    pub port: u16,
}

impl Inventory {
    /// The areas, each with its cells.
    pub fn areas(&self) -> BTreeMap<&str, Vec<&str>> {
        let mut areas: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
        for (id, cell) in &self.cells {
            areas.entry(&cell.area).or_default().push(id);
        }
        areas
    }

    /// The hosts, each with its cells.
    pub fn hosts(&self) -> BTreeMap<&str, Vec<&str>> {
        let mut hosts: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
        for (id, cell) in &self.cells {
            hosts.entry(&cell.host).or_default().push(id);
        }
        hosts
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInventory {
    #[serde(default)]
    plant: RawPlant,
    #[serde(default)]
    routers: BTreeMap<String, Spanned<RawRouter>>,
    #[serde(default)]
    cells: BTreeMap<String, Spanned<RawCell>>,
    #[serde(default)]
    operators: BTreeMap<String, Spanned<RawOperator>>,
    console: Option<Spanned<RawConsole>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPlant {
    name: Option<Spanned<String>>,
    root: Option<Spanned<String>>,
    archive_retention: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRouter {
    host: Spanned<String>,
    #[serde(default)]
    addresses: Vec<Spanned<String>>,
    port: Option<Spanned<u16>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCell {
    area: Spanned<String>,
    host: Spanned<String>,
    plc: Option<Spanned<String>>,
    config: Spanned<String>,
    metrics: Option<Spanned<u16>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOperator {
    public_key: Spanned<String>,
    #[serde(default)]
    allow: Vec<Spanned<String>>,
    #[serde(default)]
    areas: BTreeMap<String, Spanned<Vec<Spanned<String>>>>,
    #[serde(default)]
    cells: BTreeMap<String, Spanned<Vec<Spanned<String>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConsole {
    host: Spanned<String>,
    port: Option<Spanned<u16>>,
}

/// Collects the problems of one inventory, each at its place.
struct Problems<'a> {
    file: String,
    text: &'a str,
    said: Vec<String>,
}

impl Problems<'_> {
    fn at(&mut self, span: std::ops::Range<usize>, key: &str, message: impl std::fmt::Display) {
        let (line, col) = crate::table::line_col(self.text, span.start);
        self.said
            .push(format!("{}:{line}:{col}: {key}: {message}", self.file));
    }
}

/// Whether `id` is a name the plant can use in keys, file names and
/// certificates: letters, digits, `-` and `_`.
pub(crate) fn is_name(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= 64
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
}

/// Whether `host` is a host name or an address (no scheme, port or path).
fn is_host(host: &str) -> bool {
    !host.is_empty()
        && host.len() <= 253
        && host
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '.' | ':'))
}

/// Reads and validates the inventory at `path`.
///
/// # Errors
/// [`PlantError::Read`], or [`PlantError::Inventory`] with every problem.
pub(crate) fn load(path: &Path) -> Result<Inventory, PlantError> {
    let text = std::fs::read_to_string(path).map_err(|source| PlantError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse(path, &text)
}

/// Validates inventory `text`, read from `path`.
///
/// # Errors
/// [`PlantError::Inventory`] with every problem at its line and column.
pub(crate) fn parse(path: &Path, text: &str) -> Result<Inventory, PlantError> {
    let mut p = Problems {
        file: path.display().to_string(),
        text,
        said: Vec::new(),
    };
    let raw: RawInventory = match toml::from_str(text) {
        Ok(raw) => raw,
        Err(e) => {
            p.at(
                e.span().unwrap_or(0..0),
                "plant.toml",
                e.message().trim_end(),
            );
            return Err(PlantError::Inventory(p.said));
        }
    };
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let root = match &raw.plant.root {
        Some(r) if r.get_ref().split('/').all(is_name) => r.get_ref().clone(),
        Some(r) => {
            p.at(
                r.span(),
                "plant.root",
                "a key root of names (letters, digits, '-', '_') separated by '/'",
            );
            String::new()
        }
        None => "cellwatch".into(),
    };
    let archive_retention = match &raw.plant.archive_retention {
        Some(r) => match humantime::parse_duration(r.get_ref()) {
            Ok(d) if !d.is_zero() => r.get_ref().clone(),
            _ => {
                p.at(
                    r.span(),
                    "plant.archive_retention",
                    format!("'{}': a duration such as \"90d\" or \"2160h\"", r.get_ref()),
                );
                String::new()
            }
        },
        None => ARCHIVE_RETENTION.into(),
    };
    let routers = routers(&mut p, raw.routers);
    let cells = cells(&mut p, &dir, raw.cells);
    if !cells.is_empty() && routers.is_empty() {
        p.said.push(format!(
            "{}: routers: the plant's agents and clients meet at routers: add one ([routers.router-1] host = \"…\")",
            p.file
        ));
    }
    let areas: BTreeSet<&str> = cells.values().map(|c| c.area.as_str()).collect();
    let mut operators = BTreeMap::new();
    for (name, entry) in raw.operators {
        let key = format!("operators.{name}");
        if !is_name(&name) {
            p.at(
                entry.span(),
                &key,
                "an operator name is letters, digits, '-' and '_'",
            );
        }
        let entry = entry.into_inner();
        let public_key = entry.public_key.get_ref().to_ascii_lowercase();
        if public_key.len() != 64 || hex::decode(&public_key).is_err() {
            p.at(
                entry.public_key.span(),
                &format!("{key}.public_key"),
                "64 hex digits (printed by `cellwatch keygen` on the operator's machine)",
            );
        }
        let allow = actions(&mut p, &format!("{key}.allow"), &entry.allow);
        let scoped = |p: &mut Problems,
                      what: &str,
                      known: &dyn Fn(&str) -> bool,
                      table: BTreeMap<String, Spanned<Vec<Spanned<String>>>>| {
            let mut out = BTreeMap::new();
            for (scope, list) in table {
                let at = format!("{key}.{what}.{scope}");
                if !known(&scope) {
                    p.at(
                        list.span(),
                        &at,
                        format!(
                            "no {} of that name in the inventory",
                            &what[..what.len() - 1]
                        ),
                    );
                }
                out.insert(scope, actions(p, &at, list.get_ref()));
            }
            out
        };
        let in_areas = scoped(&mut p, "areas", &|a| areas.contains(a), entry.areas);
        let in_cells = scoped(&mut p, "cells", &|c| cells.contains_key(c), entry.cells);
        operators.insert(
            name,
            Operator {
                public_key,
                allow,
                areas: in_areas,
                cells: in_cells,
            },
        );
    }
    let console = raw.console.map(|c| {
        let c = c.into_inner();
        if !is_host(c.host.get_ref()) {
            p.at(c.host.span(), "console.host", "a host name or address");
        }
        ConsoleSite {
            host: c.host.into_inner(),
            port: c.port.map_or(CONSOLE_PORT, Spanned::into_inner),
        }
    });
    if !p.said.is_empty() {
        return Err(PlantError::Inventory(p.said));
    }
    Ok(Inventory {
        path: path.to_path_buf(),
        dir,
        name: raw
            .plant
            .name
            .map_or_else(|| "plant".to_string(), Spanned::into_inner),
        root,
        archive_retention,
        etc: ETC.into(),
        state: STATE.into(),
        routers,
        cells,
        operators,
        console,
    })
}

fn routers(
    p: &mut Problems,
    raw: BTreeMap<String, Spanned<RawRouter>>,
) -> BTreeMap<String, Router> {
    let mut routers = BTreeMap::new();
    for (name, entry) in raw {
        let key = format!("routers.{name}");
        if !is_name(&name) {
            p.at(
                entry.span(),
                &key,
                "a router name is letters, digits, '-' and '_'",
            );
        }
        let entry = entry.into_inner();
        for h in std::iter::once(&entry.host).chain(&entry.addresses) {
            if !is_host(h.get_ref()) {
                p.at(
                    h.span(),
                    &key,
                    format!("'{}': a host name or address", h.get_ref()),
                );
            }
        }
        routers.insert(
            name,
            Router {
                host: entry.host.into_inner(),
                addresses: entry
                    .addresses
                    .into_iter()
                    .map(Spanned::into_inner)
                    .collect(),
                port: entry.port.map_or(ROUTER_PORT, Spanned::into_inner),
            },
        );
    }
    routers
}

fn cells(
    p: &mut Problems,
    dir: &Path,
    raw: BTreeMap<String, Spanned<RawCell>>,
) -> BTreeMap<String, InventoryCell> {
    let mut cells = BTreeMap::new();
    let mut ports: BTreeMap<(String, u16), String> = BTreeMap::new();
    for (id, entry) in raw {
        let key = format!("cells.{id}");
        if !is_name(&id) || id.starts_with('_') {
            p.at(
                entry.span(),
                &key,
                "a cell id is letters, digits, '-' and '_', not '_' first (`<root>/_plant` is the plant's own key)",
            );
        }
        let entry = entry.into_inner();
        if !is_name(entry.area.get_ref()) {
            p.at(
                entry.area.span(),
                &format!("{key}.area"),
                "an area name is letters, digits, '-' and '_'",
            );
        }
        if !is_host(entry.host.get_ref()) {
            p.at(
                entry.host.span(),
                &format!("{key}.host"),
                "a host name or address",
            );
        }
        if let Some(plc) = &entry.plc {
            if !plc.get_ref().starts_with("opc.tcp://") {
                p.at(
                    plc.span(),
                    &format!("{key}.plc"),
                    "an OPC UA endpoint (opc.tcp://host:port/…)",
                );
            }
        }
        let config = dir.join(entry.config.get_ref());
        if !config.is_file() {
            p.at(
                entry.config.span(),
                &format!("{key}.config"),
                format!(
                    "{}: no such file (the cell's configuration, relative to this file)",
                    config.display()
                ),
            );
        }
        let metrics = entry
            .metrics
            .as_ref()
            .map_or(METRICS_PORT, |m| *m.get_ref());
        if let Some(other) = ports.insert((entry.host.get_ref().clone(), metrics), id.clone()) {
            let span = entry
                .metrics
                .as_ref()
                .map_or(entry.host.span(), Spanned::span);
            p.at(
                span,
                &format!("{key}.metrics"),
                format!("cell {other} on host {} has /metrics on port {metrics} too: give each cell of a host its own (metrics = {})", entry.host.get_ref(), metrics + 1),
            );
        }
        cells.insert(
            id,
            InventoryCell {
                area: entry.area.into_inner(),
                host: entry.host.into_inner(),
                plc: entry.plc.map(Spanned::into_inner),
                config,
                metrics,
            },
        );
    }
    cells
}

fn actions(p: &mut Problems, key: &str, names: &[Spanned<String>]) -> BTreeSet<Action> {
    let mut set = BTreeSet::new();
    for name in names {
        match Action::parse(name.get_ref()) {
            Some(a) => {
                set.insert(a);
            }
            None => {
                let all: Vec<&str> = Action::ALL.iter().map(|a| a.as_str()).collect();
                p.at(
                    name.span(),
                    key,
                    format!(
                        "'{}' is no action (one of {})",
                        name.get_ref(),
                        all.join(", ")
                    ),
                );
            }
        }
    }
    set
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir_with_config() -> tempfile::TempDir {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("m01.toml"), "[cell]\nid = \"m01\"\n").unwrap();
        d
    }

    #[test]
    fn every_problem_is_said_at_its_place() {
        let d = dir_with_config();
        let path = d.path().join("plant.toml");
        let text = "[routers.r1]\nhost = \"r1 plant\"\n\n[cells.m01]\narea = \"press\"\nhost = \"h1\"\nconfig = \"nope.toml\"\n\n[operators.kim]\npublic_key = \"12\"\nallow = [\"ack\", \"launch\"]\nareas = { paint = [\"force\"] }\n";
        let Err(PlantError::Inventory(said)) = parse(&path, text) else {
            panic!("accepted");
        };
        let said = said.join("\n");
        for expected in [
            "plant.toml:2:8: routers.r1: 'r1 plant': a host name or address",
            "plant.toml:7:10: cells.m01.config:",
            "plant.toml:10:14: operators.kim.public_key: 64 hex digits",
            "plant.toml:11:17: operators.kim.allow: 'launch' is no action",
            "plant.toml:12:19: operators.kim.areas.paint: no area of that name",
        ] {
            assert!(said.contains(expected), "{expected}\nnot in\n{said}");
        }
    }

    #[test]
    fn an_operator_may_do_what_any_of_their_scopes_allows() {
        let d = dir_with_config();
        let path = d.path().join("plant.toml");
        let key = "ab".repeat(32);
        let text = format!("[routers.r1]\nhost = \"r1.plant\"\n\n[cells.m01]\narea = \"press\"\nhost = \"h1\"\nconfig = \"m01.toml\"\n\n[operators.kim]\npublic_key = \"{key}\"\nallow = [\"ack\"]\nareas = {{ press = [\"reset\"] }}\ncells = {{ m01 = [\"force\"] }}\n");
        let inv = parse(&path, &text).unwrap();
        let kim = &inv.operators["kim"];
        let on_m01: Vec<_> = kim.allowed_on("m01", "press").into_iter().collect();
        assert_eq!(on_m01, vec![Action::Ack, Action::Reset, Action::Force]);
        let elsewhere: Vec<_> = kim.allowed_on("m02", "paint").into_iter().collect();
        assert_eq!(elsewhere, vec![Action::Ack]);
        assert_eq!(inv.routers["r1"].port, ROUTER_PORT);
        assert_eq!(inv.cells["m01"].metrics, METRICS_PORT);
    }

    #[test]
    fn two_cells_of_a_host_need_their_own_metrics_ports() {
        let d = dir_with_config();
        let path = d.path().join("plant.toml");
        let text = "[routers.r1]\nhost = \"r1\"\n[cells.m01]\narea = \"a\"\nhost = \"h\"\nconfig = \"m01.toml\"\n[cells.m02]\narea = \"a\"\nhost = \"h\"\nconfig = \"m01.toml\"\n";
        let Err(PlantError::Inventory(said)) = parse(&path, text) else {
            panic!("accepted");
        };
        assert!(
            said[0].contains("cells.m02.metrics: cell m01 on host h has /metrics on port 9464 too"),
            "{said:?}"
        );
    }
}
