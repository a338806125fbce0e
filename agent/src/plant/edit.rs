//! Adding to the inventory: a new one written with its comments, a cell or
//! an operator added to an existing one, every comment and table of it
//! kept. The inventory is written only if it validates afterwards; an
//! entry that exists is never changed (the same entry again changes
//! nothing: running a command twice is running it once).

use std::path::Path;

use toml_edit::{value, Array, DocumentMut, InlineTable, Item, Table};

use super::inventory::{self, Inventory};
use super::PlantError;
use crate::operator::Action;

/// A new inventory's text: the plant's name, its routers, and every
/// other table explained in comments.
pub(crate) fn new_inventory(name: &str, routers: &[(String, String)]) -> String {
    let mut text = String::from(
        "# The plant inventory: `cellwatch plant init` makes everything the plant\n\
         # needs from it; `cellwatch plant check` compares the running plant with it.\n\
         # Every key: docs/reference/plant.md. The tables, by example:\n\
         #\n\
         # [routers.router-1]            # a zenohd router: agents and clients meet there\n\
         # host = \"router-1.plant\"      # the name it is reached by (its certificate's)\n\
         # addresses = [\"10.0.0.5\"]     # more names or addresses for its certificate\n\
         # port = 7447\n\
         #\n\
         # [cells.m01ps0004]             # `cellwatch plant add-cell`\n\
         # area = \"machining\"\n\
         # host = \"cnc-4.plant\"         # where its agent runs\n\
         # plc = \"opc.tcp://10.0.1.4:4840\"\n\
         # config = \"cells/m01ps0004.toml\"  # its checks, relative to this file\n\
         # metrics = 9464                # its /metrics port (each cell of a host its own)\n\
         #\n\
         # [operators.kim]               # `cellwatch plant add-operator`\n\
         # public_key = \"<64 hex digits>\"  # from `cellwatch keygen` on kim's machine\n\
         # allow = [\"ack\", \"reset\"]     # on every cell\n\
         # areas = { machining = [\"shelve\"] }\n\
         # cells = { m01ps0004 = [\"force\"] }\n\
         #\n\
         # [console]                     # the operators' console, if the plant has one\n\
         # host = \"console.plant\"\n\
         # port = 8443\n\n",
    );
    text.push_str(&format!(
        "[plant]\nname = {}\n# root = \"cellwatch\"   # the root of the agents' bus prefixes\n",
        toml_edit::Value::from(name)
    ));
    for (router, host) in routers {
        text.push_str(&format!(
            "\n[routers.{router}]\nhost = {}\n",
            toml_edit::Value::from(host.as_str())
        ));
    }
    text
}

/// A cell to add.
pub(crate) struct NewCell<'a> {
    /// Its id.
    pub id: &'a str,
    /// Its area.
    pub area: &'a str,
    /// Its agent's host.
    pub host: &'a str,
    /// Its PLC's endpoint.
    pub plc: Option<&'a str>,
    /// Its configuration, as written in the inventory.
    pub config: &'a str,
    /// Its agent's `/metrics` port, if not the default.
    pub metrics: Option<u16>,
}

/// An operator to add.
pub(crate) struct NewOperator<'a> {
    /// Their name.
    pub name: &'a str,
    /// Their public key.
    pub public_key: &'a str,
    /// Allowed everywhere.
    pub allow: &'a [Action],
    /// Allowed per area.
    pub areas: &'a [(String, Vec<Action>)],
    /// Allowed per cell.
    pub cells: &'a [(String, Vec<Action>)],
}

fn read(path: &Path) -> Result<DocumentMut, PlantError> {
    let text = std::fs::read_to_string(path).map_err(|source| PlantError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    text.parse()
        .map_err(|e| PlantError::Inventory(vec![format!("{}: {e}", path.display())]))
}

/// Writes `doc` to `path` if it validates; the inventory it makes.
fn write(path: &Path, doc: &DocumentMut) -> Result<Inventory, PlantError> {
    let text = doc.to_string();
    let inventory = inventory::parse(path, &text)?;
    std::fs::write(path, text).map_err(|source| PlantError::Write {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(inventory)
}

fn table<'d>(doc: &'d mut DocumentMut, name: &str) -> &'d mut Table {
    if !doc.contains_key(name) {
        let mut t = Table::new();
        t.set_implicit(true);
        doc[name] = Item::Table(t);
    }
    doc[name].as_table_mut().expect("a table")
}

fn actions(list: &[Action]) -> Array {
    list.iter().map(|a| a.as_str()).collect()
}

/// Adds `cell` to the inventory at `path`.
///
/// # Errors
/// A cell of that id with other values, or an inventory that would not
/// validate.
pub(crate) fn add_cell(path: &Path, cell: &NewCell) -> Result<Inventory, PlantError> {
    let mut doc = read(path)?;
    let mut entry = Table::new();
    entry["area"] = value(cell.area);
    entry["host"] = value(cell.host);
    if let Some(plc) = cell.plc {
        entry["plc"] = value(plc);
    }
    entry["config"] = value(cell.config);
    if let Some(port) = cell.metrics {
        entry["metrics"] = value(i64::from(port));
    }
    let cells = table(&mut doc, "cells");
    if let Some(existing) = cells.get(cell.id).cloned() {
        return same_or_refused(path, &format!("cells.{}", cell.id), &existing, &entry, &doc);
    }
    cells.insert(cell.id, Item::Table(entry));
    write(path, &doc)
}

/// Adds `op` to the inventory at `path`.
///
/// # Errors
/// An operator of that name with other values, or an inventory that would
/// not validate.
pub(crate) fn add_operator(path: &Path, op: &NewOperator) -> Result<Inventory, PlantError> {
    let mut doc = read(path)?;
    let mut entry = Table::new();
    entry["public_key"] = value(op.public_key.to_ascii_lowercase());
    entry["allow"] = value(actions(op.allow));
    for (key, scoped) in [("areas", op.areas), ("cells", op.cells)] {
        if !scoped.is_empty() {
            let mut t = InlineTable::new();
            for (scope, list) in scoped {
                t.insert(scope, actions(list).into());
            }
            entry[key] = value(t);
        }
    }
    let operators = table(&mut doc, "operators");
    if let Some(existing) = operators.get(op.name).cloned() {
        return same_or_refused(
            path,
            &format!("operators.{}", op.name),
            &existing,
            &entry,
            &doc,
        );
    }
    operators.insert(op.name, Item::Table(entry));
    write(path, &doc)
}

/// An entry that exists: the same one again changes nothing; another is
/// refused, naming it.
fn same_or_refused(
    path: &Path,
    key: &str,
    existing: &Item,
    new: &Table,
    doc: &DocumentMut,
) -> Result<Inventory, PlantError> {
    let as_values = |t: &Table| -> Vec<(String, String)> {
        t.iter()
            .map(|(k, v)| (k.to_string(), v.to_string().trim().to_string()))
            .collect()
    };
    let same = existing
        .as_table()
        .is_some_and(|t| as_values(t) == as_values(new));
    if same {
        return inventory::parse(path, &doc.to_string());
    }
    Err(PlantError::Edit {
        path: path.to_path_buf(),
        message: format!(
            "{key} exists with other values; change it in the inventory itself (an entry is never replaced by an addition)"
        ),
    })
}
