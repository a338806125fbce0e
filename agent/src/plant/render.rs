//! The plant's derived files, rendered from the inventory: pure text, no
//! I/O. Each starts with a header saying what made it; `files.rs` writes
//! them and keeps an edited one from being overwritten.

use std::collections::BTreeMap;
use std::fmt::Write;

use super::inventory::{Inventory, InventoryCell, Router};
use super::layout::Layout;
use super::PlantError;

/// The first line of every file the plant renders.
pub fn header(comment: &str, inventory: &Inventory) -> String {
    format!(
        "{comment} Made by `cellwatch plant` from {}: change the inventory, not this file.\n",
        inventory
            .path
            .file_name()
            .map_or_else(|| "plant.toml".into(), |n| n.to_string_lossy())
    )
}

fn quoted(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_default()
}

/// The plant trust file: every cell's agent's public key (`public` by
/// cell; cells without one yet are left out), and the keys of a rotation
/// under way (`previous`).
pub fn trust(
    inventory: &Inventory,
    public: &BTreeMap<String, String>,
    previous: &BTreeMap<String, Vec<String>>,
) -> String {
    let mut out = header("#", inventory);
    out.push_str(
        "# Each cell's agent's signing key: clients believe a payload only if it verifies.\n",
    );
    for (cell, key) in public {
        let _ = write!(out, "\n[cells.{cell}]\npublic_key = \"{key}\"\n");
        if let Some(old) = previous.get(cell).filter(|o| !o.is_empty()) {
            let old: Vec<String> = old.iter().map(|k| quoted(k)).collect();
            let _ = writeln!(
                out,
                "# Being rotated from (cellwatch plant rotate-key --cell {cell} --done ends it):\nprevious_keys = [{}]",
                old.join(", ")
            );
        }
    }
    out
}

/// Cell `id`'s operators file: each operator allowed anything on it, with
/// what (from every scope of theirs that covers the cell).
pub fn operators(inventory: &Inventory, cell: Option<(&str, &InventoryCell)>) -> String {
    let mut out = header("#", inventory);
    match cell {
        Some((id, _)) => {
            let _ = writeln!(
                out,
                "# The operators of cell {id} and what each may do on it."
            );
        }
        None => out.push_str("# Every operator of the plant and what each may do on every cell.\n"),
    }
    out.push_str("\n[operators]\n");
    for (name, op) in &inventory.operators {
        let allowed = match cell {
            Some((id, c)) => op.allowed_on(id, &c.area),
            None => op.allow.clone(),
        };
        if allowed.is_empty() && cell.is_some() {
            continue;
        }
        let list: Vec<String> = allowed.iter().map(|a| quoted(a.as_str())).collect();
        let _ = write!(
            out,
            "\n[operators.{name}]\npublic_key = \"{}\"\nallow = [{}]\n",
            op.public_key,
            list.join(", ")
        );
    }
    out
}

/// What a cell's agent may say on the bus, and hear: one `-speaks`
/// (ingress) and one `-hears` (egress) rule under its own prefix.
const AGENT_MESSAGES: &str = "[\"put\", \"delete\", \"declare_queryable\", \"reply\", \"liveliness_token\",\n                   \"declare_subscriber\", \"query\", \"declare_liveliness_subscriber\", \"liveliness_query\"]";

/// A router's lease, ms: its clients (agents, the console) take it for gone
/// after this long without a word from it and move to the next router of
/// their list; it says a word every quarter of it.
pub const ROUTER_LEASE_MS: u64 = 3_000;

/// Router `name`'s `zenohd` configuration: mutual TLS over QUIC with the
/// plant CA, the other routers to link with, and access control from the
/// inventory (default deny; an agent's certificate speaks under its own
/// cell's prefix only; routers relay for each other; every plant
/// certificate may subscribe and query).
pub fn router(inventory: &Inventory, name: &str, r: &Router, layout: &Layout) -> String {
    let root = &inventory.root;
    let mut out = header("//", inventory);
    let dir = layout.router_etc();
    let _ = write!(
        out,
        "// cellwatch router --config {dir}/router.json5\n// (Zenoh's router, as zenohd runs it, with the storage manager linked in:\n// the plugins section below keeps the plant archive.)\n{{\n  mode: \"router\",\n  listen: {{ endpoints: [\"quic/0.0.0.0:{}\"] }},\n",
        r.port
    );
    let others: Vec<String> = inventory
        .routers
        .iter()
        .filter(|(n, _)| n.as_str() < name)
        .map(|(_, o)| quoted(&format!("quic/{}:{}", o.host, o.port)))
        .collect();
    let _ = write!(
        out,
        "  // Each router links to those named before it: one mesh.\n  connect: {{ endpoints: [{}] }},\n",
        others.join(", ")
    );
    let _ = write!(
        out,
        "  scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }},\n  transport: {{\n    link: {{\n      // Clients take this router for gone after {} ms without a word from it\n      // (Zenoh's default: 10 s), then move to the next of their list.\n      tx: {{ lease: {} }},\n      tls: {{\n        root_ca_certificate: {},\n        listen_certificate: {},\n        listen_private_key: {},\n        connect_certificate: {},\n        connect_private_key: {},\n        enable_mtls: true,\n        verify_name_on_connect: true,\n      }},\n    }},\n  }},\n",
        ROUTER_LEASE_MS,
        ROUTER_LEASE_MS,
        quoted(&format!("{dir}/ca.pem")),
        quoted(&format!("{dir}/{name}.pem")),
        quoted(&format!("{dir}/{name}.key")),
        quoted(&format!("{dir}/{name}.pem")),
        quoted(&format!("{dir}/{name}.key")),
    );
    out.push_str(&archive(inventory, layout));
    out.push_str("  access_control: {\n    enabled: true,\n    default_permission: \"deny\",\n    rules: [\n");
    for cell in inventory.cells.keys() {
        let prefix = format!("{root}/{cell}");
        let keys = format!(
            "[{}, {}, {}]",
            quoted(&prefix),
            quoted(&format!("{prefix}/**")),
            quoted(&format!("{prefix}/**/@adv/**"))
        );
        for (rule, flow) in [("speaks", "ingress"), ("hears", "egress")] {
            let _ = write!(
                out,
                "      {{\n        id: \"agent-{cell}-{rule}\",\n        messages: {AGENT_MESSAGES},\n        flows: [\"{flow}\"],\n        permission: \"allow\",\n        key_exprs: {keys},\n      }},\n"
            );
        }
    }
    let every = format!(
        "[{}, {}]",
        quoted(&format!("{root}/**")),
        quoted(&format!("{root}/**/@adv/**"))
    );
    let _ = write!(
        out,
        "      {{\n        id: \"routers-relay\",\n        messages: {AGENT_MESSAGES},\n        flows: [\"ingress\", \"egress\"],\n        permission: \"allow\",\n        key_exprs: {every},\n      }},\n"
    );
    let _ = write!(
        out,
        "      {{\n        id: \"plant-admin-publishes\",\n        messages: [\"put\"],\n        flows: [\"ingress\"],\n        permission: \"allow\",\n        key_exprs: [{}],\n      }},\n      {{\n        id: \"plant-asks\",\n        messages: [\"declare_subscriber\", \"query\", \"declare_liveliness_subscriber\", \"liveliness_query\"],\n        flows: [\"ingress\"],\n        permission: \"allow\",\n        key_exprs: {every},\n      }},\n      {{\n        id: \"plant-hears\",\n        messages: {AGENT_MESSAGES},\n        flows: [\"egress\"],\n        permission: \"allow\",\n        key_exprs: {every},\n      }},\n    ],\n    subjects: [\n",
        quoted(&crate::bus::keys::plant_operators(root))
    );
    for cell in inventory.cells.keys() {
        let _ = writeln!(
            out,
            "      {{ id: \"agent-{cell}\", cert_common_names: [\"agent-{cell}\"] }},"
        );
    }
    let routers: Vec<String> = inventory.routers.keys().map(|r| quoted(r)).collect();
    let _ = write!(
        out,
        "      {{ id: \"routers\", cert_common_names: [{}] }},\n      {{ id: \"plant-admin\", cert_common_names: [\"plant-admin\"] }},\n      {{ id: \"plant\", link_protocols: [\"tls\", \"quic\"] }},\n    ],\n    policies: [\n",
        routers.join(", ")
    );
    for cell in inventory.cells.keys() {
        let _ = writeln!(
            out,
            "      {{ rules: [\"agent-{cell}-speaks\", \"agent-{cell}-hears\"], subjects: [\"agent-{cell}\"] }},"
        );
    }
    out.push_str("      { rules: [\"routers-relay\"], subjects: [\"routers\"] },\n      { rules: [\"plant-admin-publishes\"], subjects: [\"plant-admin\"] },\n      { rules: [\"plant-asks\", \"plant-hears\"], subjects: [\"plant\"] },\n    ],\n  },\n}\n");
    out
}

/// A router's part of the plant archive: Zenoh's storage manager with the
/// SQLite volume, one storage per kind of what the agents put, each
/// keeping every sample for the plant's retention. Timestamps on: the
/// storage manager orders what it keeps by them, and a router adds them to
/// what it routes.
fn archive(inventory: &Inventory, layout: &Layout) -> String {
    let root = &inventory.root;
    let volume = format!(
        "{{ id: \"{}\", retention: {} }}",
        crate::archive::volume::VOLUME,
        quoted(&inventory.archive_retention)
    );
    let mut out = format!(
        "  timestamping: {{ enabled: {{ router: true }} }},\n  // The plant archive (docs/reference/archive.md): every cell's signed\n  // alarm events, machine states and flight recordings, kept for\n  // [plant] archive_retention, read by `cellwatch history --plant`.\n  plugins: {{\n    storage_manager: {{\n      volumes: {{ {}: {{ dir: {} }} }},\n      storages: {{\n",
        crate::archive::volume::VOLUME,
        quoted(&layout.archive_dir())
    );
    for (name, keys) in [
        ("alarms", "alarms/**"),
        ("states", "state"),
        ("recordings", "recordings/**"),
    ] {
        let _ = writeln!(
            out,
            "        {name}: {{ key_expr: {}, volume: {volume} }},",
            quoted(&format!("{root}/*/{keys}"))
        );
    }
    out.push_str("      },\n    },\n  },\n");
    out
}

/// Prometheus `file_sd` targets: each agent's `/metrics`, labelled with
/// its cell and area.
pub fn scrape_targets(inventory: &Inventory) -> String {
    let mut out = header("#", inventory);
    out.push_str("# Prometheus file_sd_configs: every agent's /metrics.\n");
    for (id, cell) in &inventory.cells {
        let _ = write!(
            out,
            "- targets: [{}]\n  labels: {{ cell: {}, area: {} }}\n",
            quoted(&format!("{}:{}", cell.host, cell.metrics)),
            quoted(id),
            quoted(&cell.area)
        );
    }
    if inventory.cells.is_empty() {
        out.push_str("[]\n");
    }
    out
}

/// The console's configuration: the plant's routers, its trust file and
/// operators, its areas.
pub fn console(inventory: &Inventory, layout: &Layout) -> Option<String> {
    let c = inventory.console.as_ref()?;
    let etc = &inventory.etc;
    let mut out = header("#", inventory);
    let connect: Vec<String> = inventory
        .routers
        .values()
        .map(|r| quoted(&format!("quic/{}:{}", r.host, r.port)))
        .collect();
    let _ = write!(
        out,
        "# cellwatch console --config {etc}/console.toml\n\n[http]\nlisten = \"0.0.0.0:{}\"\ntls = {{ cert = {}, key = {}, clients = {} }}\nnames = [{}]\n\n[bus]\nmode = \"client\"\nconnect = [{}]\ntls = {{ ca = {}, cert = {}, key = {} }}\ntrust = {}\nroot = {}\n\n[operators]\nfile = {}\n\n[plant]\ndeployed = {}\n\n[areas]\n",
        c.port,
        quoted(&format!("{etc}/console.pem")),
        quoted(&layout.console_key()),
        quoted(&format!("{etc}/ca.pem")),
        quoted(&c.host),
        connect.join(", "),
        quoted(&format!("{etc}/ca.pem")),
        quoted(&format!("{etc}/console.pem")),
        quoted(&layout.console_key()),
        quoted(&format!("{etc}/trust.toml")),
        quoted(&inventory.root),
        quoted(&format!("{etc}/operators.toml")),
        quoted(&format!("{etc}/plant-deployed.json")),
    );
    for (area, cells) in inventory.areas() {
        let cells: Vec<String> = cells.iter().map(|c| quoted(c)).collect();
        let _ = writeln!(out, "{area} = [{}]", cells.join(", "));
    }
    Some(out)
}

/// The Alertmanager routes skeleton: one route per area, by the `area`
/// label every alert carries, each to a receiver of its own to fill in.
pub fn alertmanager_routes(inventory: &Inventory) -> String {
    let mut out = header("#", inventory);
    out.push_str("# Alertmanager routes by area: put each receiver's e-mail, pager or chat.\n# Merge into alertmanager.yml (amtool check-config checks it).\nroute:\n  receiver: plant\n  group_by: [cell, alarm]\n  routes:\n");
    let areas = inventory.areas();
    for area in areas.keys() {
        let _ = write!(
            out,
            "    - matchers: ['area=\"{area}\"']\n      receiver: area-{area}\n"
        );
    }
    out.push_str("receivers:\n  - name: plant\n");
    for area in areas.keys() {
        let _ = writeln!(out, "  - name: area-{area}");
    }
    out
}

/// Cell `id`'s configuration on its host: the cell's own configuration
/// (`text`, its checks and tags kept as written, comments too) with what
/// the plant owns set from the inventory: the PLC endpoint, the bus (the
/// routers, its certificate, its signing key, its prefix), the operators
/// file, the journal's place and `/metrics`.
///
/// # Errors
/// [`PlantError::CellConfig`]: the text is no TOML, or names another cell.
pub fn cell_config(
    inventory: &Inventory,
    id: &str,
    cell: &InventoryCell,
    text: &str,
    layout: &Layout,
    admin_public: &str,
) -> Result<String, PlantError> {
    use toml_edit::{value, Array, DocumentMut, InlineTable, Item, Table};
    let bad = |message: String| PlantError::CellConfig {
        path: cell.config.clone(),
        message,
    };
    let mut doc: DocumentMut = text.parse().map_err(|e| bad(format!("{e}")))?;
    let said = doc
        .get("cell")
        .and_then(|c| c.get("id"))
        .and_then(Item::as_str)
        .map(str::to_string);
    if said.as_deref() != Some(id) {
        return Err(bad(format!(
            "its [cell] id is {}; the inventory names it '{id}'",
            said.map_or_else(|| "missing".into(), |s| format!("'{s}'"))
        )));
    }
    let etc = &inventory.etc;
    if let Some(opcua) = doc.get_mut("opcua").and_then(Item::as_table_mut) {
        if let Some(plc) = &cell.plc {
            opcua["endpoint"] = value(plc.as_str());
        }
        // The agent's own OPC UA key pair and the servers it trusts: its
        // state, never the read-only configuration folder.
        opcua["pki_dir"] = value(format!("{}/{id}/pki", inventory.state));
    }
    let mut zenoh = Table::new();
    zenoh["mode"] = value("client");
    let mut connect = Array::new();
    for r in inventory.routers.values() {
        connect.push(format!("quic/{}:{}", r.host, r.port));
    }
    zenoh["connect"] = value(connect);
    zenoh["key_prefix"] = value(crate::config::cell_prefix(&inventory.root, id));
    zenoh["signing_key"] = value(layout.signing_key(id));
    let mut tls = InlineTable::new();
    tls.insert("ca", format!("{etc}/ca.pem").into());
    tls.insert("cert", format!("{etc}/agent-{id}.pem").into());
    tls.insert("key", layout.bus_key(id).into());
    zenoh["tls"] = value(tls);
    doc["zenoh"] = Item::Table(zenoh);
    let table = |doc: &mut DocumentMut, name: &str| -> Result<(), PlantError> {
        if doc.get(name).is_none() {
            doc[name] = Item::Table(Table::new());
        }
        doc[name]
            .as_table_mut()
            .map(|_| ())
            .ok_or_else(|| bad(format!("[{name}] is not a table")))
    };
    table(&mut doc, "commands")?;
    doc["commands"]["operators_file"] = value(format!("{etc}/{id}.operators.toml"));
    doc["commands"]["plant_key"] = value(admin_public);
    doc["commands"]["plant_list"] = value(format!("{}/{id}/plant-operators.json", inventory.state));
    table(&mut doc, "journal")?;
    doc["journal"]["path"] = value(format!("{}/{id}/journal.sqlite", inventory.state));
    table(&mut doc, "metrics")?;
    doc["metrics"]["listen"] = value(format!("0.0.0.0:{}", cell.metrics));
    if let Some(am) = doc.get_mut("alertmanager").and_then(Item::as_table_mut) {
        am["area"] = value(cell.area.as_str());
    }
    let mut out = header("#", inventory);
    let _ = writeln!(
        out,
        "# From {} with [zenoh], opcua.endpoint and pki_dir, commands.operators_file, plant_key and\n# plant_list, journal.path and metrics.listen set by the plant.",
        layout.shown(&cell.config)
    );
    out.push_str(&doc.to_string());
    Ok(out)
}
