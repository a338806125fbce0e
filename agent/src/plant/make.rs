//! Making the plant's folder from its inventory: what is missing is made,
//! what exists is kept. The CA, every certificate and key once (keys
//! owner-only, each on its host's folder); the trust file, the operators
//! files, each cell's configuration for its host with the files it reads,
//! the routers' configurations, Prometheus's targets, the console's
//! configuration, the Alertmanager routes and the systemd instances from
//! the inventory every time, unchanged when it has not changed.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::files::{make_dir, Made, Writer};
use super::inventory::{Inventory, InventoryCell};
use super::layout::Layout;
use super::{render, PlantError};
use crate::bus::certs::{ca_files, issue_to, make_ca};
use crate::bus::envelope::AgentKey;
use crate::operator::plant::{ListedOperator, PlantList, SignedList, LIST_SCHEMA};
use crate::operator::OperatorKey;

/// Where the packaged unit of `cellwatch@.service` is, which an instance
/// links to.
const UNIT: &str = "/usr/lib/systemd/system/cellwatch@.service";

/// Makes what the inventory asks for and is missing, and writes again the
/// derived files it changed.
///
/// # Errors
/// A file cannot be read or written, a certificate made, or a cell's
/// configuration does not read; files changed by hand are no error here
/// (they are in [`Made::edited`]).
pub(crate) fn make(inventory: &Inventory) -> Result<Made, PlantError> {
    let layout = Layout::of(inventory);
    let mut w = Writer::open(&layout)?;
    let ca_dir = layout.ca_dir();
    let (ca_pem, ca_key) = ca_files(&ca_dir);
    make_dir(&ca_dir, 0o700)?;
    w.once(&ca_key, || {
        make_ca(&ca_dir, &format!("{} plant CA", inventory.name))
            .map(|_| ())
            .map_err(|message| PlantError::Certificate {
                name: "the plant CA".into(),
                message: message.to_string(),
            })
    })?;
    let ca = std::fs::read_to_string(&ca_pem).map_err(|source| PlantError::Read {
        path: ca_pem.clone(),
        source,
    })?;
    let issue = |w: &mut Writer, name: &str, hosts: Vec<String>, cert: PathBuf, key: PathBuf| {
        w.once(&key, || {
            if let Some(parent) = key.parent() {
                make_dir(parent, 0o700)?;
            }
            if let Some(parent) = cert.parent() {
                std::fs::create_dir_all(parent).map_err(|source| PlantError::Write {
                    path: parent.to_path_buf(),
                    source,
                })?;
            }
            issue_to(&ca_dir, name, &hosts, (&cert, &key)).map_err(|message| {
                PlantError::Certificate {
                    name: name.into(),
                    message: message.to_string(),
                }
            })
        })
    };
    let etc = layout.etc().to_string();
    let (cert, key) = layout.admin_cert();
    if let Some(dir) = key.parent() {
        make_dir(dir, 0o700)?;
    }
    issue(&mut w, "plant-admin", vec!["localhost".into()], cert, key)?;
    let admin = admin_signing(&mut w, &layout)?;
    operators_list(&mut w, inventory, &layout, &admin)?;
    // Routers.
    for (name, r) in &inventory.routers {
        let root = layout.router(name);
        let on = |path: &str| root.join(path.trim_start_matches('/'));
        let dir = layout.router_etc();
        let mut hosts = vec![r.host.clone()];
        hosts.extend(r.addresses.iter().cloned());
        issue(
            &mut w,
            name,
            hosts,
            on(&format!("{dir}/{name}.pem")),
            on(&format!("{dir}/{name}.key")),
        )?;
        w.derived(&on(&format!("{dir}/ca.pem")), &ca)?;
        w.derived(
            &on(&format!("{dir}/router.json5")),
            render::router(inventory, name, r, &layout),
        )?;
    }
    // Cells: keys and certificates first, the trust file needs them.
    let mut public = BTreeMap::new();
    for (id, cell) in &inventory.cells {
        let host = &cell.host;
        make_dir(&layout.on_host(host, &layout.cell_state(id)), 0o700)?;
        let signing = layout.on_host(host, &layout.signing_key(id));
        let (key, made) =
            AgentKey::load_or_create(&signing, id).map_err(|e| PlantError::Certificate {
                name: format!("agent {id}'s signing key"),
                message: e.to_string(),
            })?;
        if made {
            w.made.made.push(layout.shown(&signing));
        }
        public.insert(id.clone(), key.public_hex());
        issue(
            &mut w,
            &format!("agent-{id}"),
            vec![host.clone()],
            layout.on_host(host, &format!("{etc}/agent-{id}.pem")),
            layout.on_host(host, &layout.bus_key(id)),
        )?;
    }
    let mut previous = BTreeMap::new();
    for id in inventory.cells.keys() {
        if let Ok(text) = std::fs::read_to_string(layout.rotating(id)) {
            previous.insert(
                id.clone(),
                text.lines()
                    .map(|l| l.trim().to_string())
                    .filter(|l| !l.is_empty())
                    .collect(),
            );
        }
    }
    let trust = render::trust(inventory, &public, &previous);
    w.derived(&layout.trust(), &trust)?;
    for (id, cell) in &inventory.cells {
        let host = &cell.host;
        let at = |path: &str| layout.on_host(host, path);
        w.derived(&at(&format!("{etc}/ca.pem")), &ca)?;
        w.derived(&at(&format!("{etc}/trust.toml")), &trust)?;
        w.derived(
            &at(&format!("{etc}/{id}.operators.toml")),
            render::operators(inventory, Some((id, cell))),
        )?;
        // The list the agent starts with, until a newer one reaches it.
        let list = layout.operators_list();
        let signed =
            std::fs::read(&list).map_err(|source| PlantError::Read { path: list, source })?;
        w.derived(
            &at(&format!("{}/{id}/plant-operators.json", inventory.state)),
            signed,
        )?;
        cell_files(&mut w, inventory, &layout, id, cell)?;
        w.link(&layout.systemd_instance(host, id), UNIT)?;
    }
    w.derived(&layout.scrape_targets(), render::scrape_targets(inventory))?;
    w.derived(
        &layout.alertmanager_routes(),
        render::alertmanager_routes(inventory),
    )?;
    if let (Some(c), Some(text)) = (&inventory.console, render::console(inventory, &layout)) {
        let root = layout.console();
        let on = |path: &str| root.join(path.trim_start_matches('/'));
        issue(
            &mut w,
            "console",
            vec![c.host.clone()],
            on(&format!("{etc}/console.pem")),
            on(&layout.console_key()),
        )?;
        w.derived(&on(&format!("{etc}/console.toml")), &text)?;
        w.derived(&on(&format!("{etc}/ca.pem")), &ca)?;
        w.derived(&on(&format!("{etc}/trust.toml")), &trust)?;
        w.derived(
            &on(&format!("{etc}/operators.toml")),
            render::operators(inventory, None),
        )?;
        // What each agent runs is judged against this on the Agents page:
        // the files deployed to the hosts, as they are now.
        let deployed =
            serde_json::to_string_pretty(&super::check::deployed(inventory)).map_err(|e| {
                PlantError::Encode {
                    what: "plant-deployed.json".into(),
                    message: e.to_string(),
                }
            })?;
        w.derived(&on(&format!("{etc}/plant-deployed.json")), deployed + "\n")?;
    }
    w.finish()
}

/// Reads what a configuration names and keeps the list.
struct Recording {
    read: RefCell<Vec<PathBuf>>,
}

impl crate::config::Files for Recording {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        let bytes = std::fs::read(path)?;
        self.read.borrow_mut().push(path.to_path_buf());
        Ok(bytes)
    }

    fn list(&self, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
        crate::config::Disk.list(dir)
    }
}

/// Cell `id`'s configuration for its host, validated as the agent will,
/// and every file it reads (programs, comments, tags files), copied beside
/// it as they are relative to it.
fn cell_files(
    w: &mut Writer,
    inventory: &Inventory,
    layout: &Layout,
    id: &str,
    cell: &InventoryCell,
) -> Result<(), PlantError> {
    let text = std::fs::read_to_string(&cell.config).map_err(|source| PlantError::Read {
        path: cell.config.clone(),
        source,
    })?;
    let admin =
        std::fs::read_to_string(layout.admin_signing().1).map_err(|source| PlantError::Read {
            path: layout.admin_signing().1,
            source,
        })?;
    let generated = render::cell_config(inventory, id, cell, &text, layout, admin.trim())?;
    let etc = layout.etc();
    let target = layout.on_host(&cell.host, &format!("{etc}/{id}.toml"));
    let base = cell
        .config
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let files = Recording {
        read: RefCell::new(Vec::new()),
    };
    crate::config::parse(&layout.shown(&target), &generated, &base, &files).map_err(|e| {
        PlantError::CellConfig {
            path: cell.config.clone(),
            message: format!("does not validate as the plant makes it:\n{e}"),
        }
    })?;
    w.derived(&target, &generated)?;
    for read in files.read.into_inner() {
        let rel = read.strip_prefix(&base).map_err(|_| PlantError::CellConfig {
            path: cell.config.clone(),
            message: format!(
                "it reads {}, outside its own folder {}: the plant copies a cell's files to its host beside its configuration; move the file into that folder",
                read.display(),
                base.display()
            ),
        })?;
        let bytes = std::fs::read(&read).map_err(|source| PlantError::Read {
            path: read.clone(),
            source,
        })?;
        let to = layout.on_host(&cell.host, etc).join(rel);
        w.derived(&to, &bytes)?;
    }
    Ok(())
}

/// The plant administrator's signing key, made once (owner-only) with its
/// public half beside it.
fn admin_signing(w: &mut Writer, layout: &Layout) -> Result<OperatorKey, PlantError> {
    let (private, public) = layout.admin_signing();
    w.once(&private, || {
        let key = OperatorKey::generate("plant-admin");
        crate::bus::certs::write_private(&private, &key.to_file()).map_err(|message| {
            PlantError::Certificate {
                name: "the plant administrator's signing key".into(),
                message: message.to_string(),
            }
        })
    })?;
    let text = std::fs::read_to_string(&private).map_err(|source| PlantError::Read {
        path: private.clone(),
        source,
    })?;
    let key = OperatorKey::parse(&private.display().to_string(), &text).map_err(|e| {
        PlantError::Certificate {
            name: "the plant administrator's signing key".into(),
            message: e.to_string(),
        }
    })?;
    w.derived(&public, format!("{}\n", key.public_hex()))?;
    Ok(key)
}

/// The plant operators list: each operator's key and, per cell, what they
/// may do there; signed anew, one version up, only when that changes.
fn operators_list(
    w: &mut Writer,
    inventory: &Inventory,
    layout: &Layout,
    admin: &OperatorKey,
) -> Result<(), PlantError> {
    let mut operators = BTreeMap::new();
    for (name, op) in &inventory.operators {
        let cells = inventory
            .cells
            .iter()
            .map(|(id, c)| (id.clone(), op.allowed_on(id, &c.area)))
            .filter(|(_, allowed)| !allowed.is_empty())
            .collect();
        operators.insert(
            name.clone(),
            ListedOperator {
                public_key: op.public_key.clone(),
                cells,
            },
        );
    }
    let path = layout.operators_list();
    let before = match std::fs::read(&path) {
        Ok(bytes) => {
            let list = SignedList::parse(&bytes)
                .and_then(|s| s.open(&admin.public()))
                .map_err(|e| PlantError::Edit {
                    path: path.clone(),
                    message: format!("{e}: it was not made by this plant's administrator key; move it away to have it made again (agents take only a version above the one they hold)"),
                })?;
            Some(list)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(source) => return Err(PlantError::Read { path, source }),
    };
    if let Some(b) = &before {
        if b.operators == operators && b.plant == inventory.name {
            return Ok(());
        }
    }
    let list = PlantList {
        schema: LIST_SCHEMA.into(),
        plant: inventory.name.clone(),
        version: before.map_or(1, |b| b.version + 1),
        issued_at: crate::clock::rfc3339(crate::clock::now_ms()),
        operators,
    };
    let signed = list.signed_by(admin);
    w.derived(
        &path,
        serde_json::to_string_pretty(&signed).unwrap_or_default(),
    )
}

/// Starts rotating cell `id`'s signing key: its public key kept as the one
/// rotated from, a new key made in its place; the trust file then holds
/// both (every client believes either) until [`finish_rotation`].
///
/// # Errors
/// A rotation under way, no key to rotate, or a file that cannot be
/// written.
pub(crate) fn rotate(inventory: &Inventory, id: &str) -> Result<Made, PlantError> {
    let layout = Layout::of(inventory);
    let cell = inventory.cells.get(id).ok_or_else(|| PlantError::Edit {
        path: inventory.path.clone(),
        message: format!("no cell '{id}' in the inventory"),
    })?;
    let rotating = layout.rotating(id);
    if rotating.exists() {
        return Err(PlantError::Edit {
            path: rotating,
            message: format!("a rotation of {id}'s key is under way: end it first (cellwatch plant rotate-key --cell {id} --done)"),
        });
    }
    let signing = layout.on_host(&cell.host, &layout.signing_key(id));
    let old = AgentKey::load(&signing).map_err(|e| PlantError::Certificate {
        name: format!("agent {id}'s signing key"),
        message: format!("{e} (make the plant first: cellwatch plant init)"),
    })?;
    make_dir(&layout.dir().join("rotating"), 0o755)?;
    std::fs::write(&rotating, format!("{}\n", old.public_hex())).map_err(|source| {
        PlantError::Write {
            path: rotating.clone(),
            source,
        }
    })?;
    std::fs::remove_file(&signing).map_err(|source| PlantError::Write {
        path: signing.clone(),
        source,
    })?;
    make(inventory)
}

/// Ends the rotation of cell `id`'s signing key: the trust file holds the
/// new key only.
///
/// # Errors
/// No rotation under way, or a file that cannot be written.
pub(crate) fn finish_rotation(inventory: &Inventory, id: &str) -> Result<Made, PlantError> {
    let layout = Layout::of(inventory);
    let rotating = layout.rotating(id);
    std::fs::remove_file(&rotating).map_err(|source| PlantError::Write {
        path: rotating,
        source,
    })?;
    make(inventory)
}

/// Issues cell `id`'s bus certificate again (a new key, owner-only), in
/// place of the one it has: for a certificate ending soon or a key
/// feared known.
///
/// # Errors
/// No such cell, or the certificate cannot be made.
pub(crate) fn renew(inventory: &Inventory, id: &str) -> Result<Vec<PathBuf>, PlantError> {
    let layout = Layout::of(inventory);
    let cell = inventory.cells.get(id).ok_or_else(|| PlantError::Edit {
        path: inventory.path.clone(),
        message: format!("no cell '{id}' in the inventory"),
    })?;
    let cert = layout.on_host(&cell.host, &format!("{}/agent-{id}.pem", layout.etc()));
    let key = layout.on_host(&cell.host, &layout.bus_key(id));
    let (new_cert, new_key) = (
        cert.with_extension("renewing"),
        key.with_extension("renewing"),
    );
    for p in [&new_cert, &new_key] {
        let _ = std::fs::remove_file(p);
    }
    issue_to(
        &layout.ca_dir(),
        &format!("agent-{id}"),
        std::slice::from_ref(&cell.host),
        (&new_cert, &new_key),
    )
    .map_err(|message| PlantError::Certificate {
        name: format!("agent-{id}"),
        message: message.to_string(),
    })?;
    for (from, to) in [(&new_key, &key), (&new_cert, &cert)] {
        std::fs::rename(from, to).map_err(|source| PlantError::Write {
            path: to.clone(),
            source,
        })?;
    }
    Ok(vec![cert, key])
}
