//! `cellwatch plant`: one inventory for the whole plant, and everything
//! its cells, routers, console, Prometheus and Alertmanager need made from
//! it; the running plant checked against it.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use super::Failure;
use crate::operator::Action;
use crate::plant::edit::{self, NewCell, NewOperator};
use crate::plant::{check, make, Inventory, Made, PlantError};

#[derive(Debug, clap::Subcommand)]
pub(crate) enum PlantCommand {
    /// Make the plant: write the inventory if there is none, then make
    /// from it what is missing (the CA, certificates and keys, each on its
    /// host's folder) and write again what it derives (trust file,
    /// operators files, cells' configurations, routers' access control,
    /// Prometheus targets, console, Alertmanager routes, systemd
    /// instances). Never overwrites a key, a certificate or a file changed
    /// by hand; run twice, the second run changes nothing.
    Init(InitArgs),
    /// Add a cell to the inventory, then make what it needs.
    AddCell(AddCellArgs),
    /// Add an operator (their public key from `cellwatch keygen` on their
    /// own machine) and what they may do, then write every operators file.
    AddOperator(AddOperatorArgs),
    /// Rotate a cell agent's signing key with an overlap: a new key is
    /// made and the trust file holds the old and the new one (every
    /// client believes either) until `--done`, once every client has it
    /// and the agent signs with the new key.
    RotateKey(RotateKeyArgs),
    /// Issue a cell agent's bus certificate again, with a new key, in
    /// place of the one it has (one ending soon, or a key feared known);
    /// copy it to the host and restart the agent.
    Renew(RenewArgs),
    /// Put the plant operators list (operators.signed.json, signed by the
    /// plant administrator's key) on the bus, and wait until every cell's
    /// agent judges commands by it: a key revoked or a permission changed
    /// in the inventory reaches every agent at once, without a restart.
    /// Exit status 1 when an agent has not taken it within --timeout.
    Publish(PublishArgs),
    /// Check the plant's folder and the running plant against the
    /// inventory: per cell, whether its agent answers on the bus, is
    /// believed with the trust file's key, runs the configuration deployed
    /// and this version, its certificates' ends and its /readyz; per
    /// router, its access control. Exit status 1 when anything is wrong.
    Check(CheckArgs),
}

#[derive(Debug, clap::Args)]
pub(crate) struct InventoryArg {
    /// The plant inventory; every generated file is made in its folder.
    #[arg(long, value_name = "TOML", default_value = "plant.toml")]
    pub(crate) plant: PathBuf,
}

#[derive(Debug, clap::Args)]
pub(crate) struct InitArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// The plant's name (a new inventory only).
    #[arg(long, default_value = "plant")]
    pub(crate) name: String,
    /// A router, as NAME=HOST (a new inventory only); repeatable.
    #[arg(long, value_name = "NAME=HOST")]
    pub(crate) router: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct AddCellArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// The cell's id (its configuration's `[cell] id`).
    #[arg(long)]
    pub(crate) cell: String,
    /// Its area.
    #[arg(long)]
    pub(crate) area: String,
    /// The host its agent runs on (the name the plant reaches it by).
    #[arg(long)]
    pub(crate) host: String,
    /// Its PLC's OPC UA endpoint (set in its configuration for its host).
    #[arg(long, value_name = "URL")]
    pub(crate) plc: Option<String>,
    /// Its configuration, relative to the inventory.
    #[arg(long, value_name = "TOML")]
    pub(crate) config: String,
    /// Its agent's /metrics port (default 9464; each cell of a host its own).
    #[arg(long)]
    pub(crate) metrics: Option<u16>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct AddOperatorArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// The operator's name.
    #[arg(long)]
    pub(crate) name: String,
    /// Their public key, 64 hex digits (`cellwatch keygen` prints it).
    #[arg(long, value_name = "HEX")]
    pub(crate) public_key: String,
    /// What they may do on every cell, comma-separated (ack, reset, …).
    #[arg(long, value_delimiter = ',')]
    pub(crate) allow: Vec<String>,
    /// What they may do on an area's cells, as AREA=ACTION,ACTION;
    /// repeatable.
    #[arg(long, value_name = "AREA=ACTIONS")]
    pub(crate) area: Vec<String>,
    /// What they may do on one cell, as CELL=ACTION,ACTION; repeatable.
    #[arg(long = "on-cell", value_name = "CELL=ACTIONS")]
    pub(crate) on_cell: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct RotateKeyArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// The cell whose agent's signing key is rotated.
    #[arg(long)]
    pub(crate) cell: String,
    /// End the rotation: the trust file keeps the new key only.
    #[arg(long)]
    pub(crate) done: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct RenewArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// The cell whose agent's bus certificate is renewed; repeatable.
    #[arg(long, required = true)]
    pub(crate) cell: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct PublishArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// Where to join the bus (default: every router of the inventory).
    #[arg(long)]
    pub(crate) connect: Vec<String>,
    /// Seconds to wait for every agent to take it.
    #[arg(long = "timeout", default_value_t = 30)]
    pub(crate) timeout_secs: u64,
}

#[derive(Debug, clap::Args)]
pub(crate) struct CheckArgs {
    #[command(flatten)]
    pub(crate) inventory: InventoryArg,
    /// Where to join the bus (default: every router of the inventory).
    #[arg(long)]
    pub(crate) connect: Vec<String>,
    /// Only the plant's folder, not the running plant.
    #[arg(long)]
    pub(crate) offline: bool,
    /// Seconds to wait for each agent's answer.
    #[arg(long = "timeout", default_value_t = 5)]
    pub(crate) timeout_secs: u64,
}

fn plant_failure(e: PlantError) -> Failure {
    match e {
        e @ (PlantError::Inventory(_)
        | PlantError::CellConfig { .. }
        | PlantError::Edit { .. }
        | PlantError::Clash { .. }) => Failure::Input(e.to_string()),
        e => Failure::Runtime(e.to_string()),
    }
}

/// Makes the plant of `inventory` and says what was done.
fn made(inventory: &Inventory, out: &mut dyn Write) -> Result<(), Failure> {
    let done = make::make(inventory).map_err(plant_failure)?;
    say(&done, inventory, out)
}

fn say(done: &Made, inventory: &Inventory, out: &mut dyn Write) -> Result<(), Failure> {
    let io = Failure::output;
    for f in &done.made {
        writeln!(out, "made     {f}").map_err(io)?;
    }
    for f in &done.updated {
        writeln!(out, "updated  {f}").map_err(io)?;
    }
    if done.nothing() && done.edited.is_empty() {
        writeln!(
            out,
            "nothing to do: {} is as {} says",
            inventory.dir.display(),
            inventory.path.display()
        )
        .map_err(io)?;
    }
    if done.edited.is_empty() {
        return Ok(());
    }
    Err(Failure::Input(format!(
        "changed by hand since the plant wrote them, so not written:\n  {}\nput the change in {} (or move the file away) and run again",
        done.edited.join("\n  "),
        inventory.path.display()
    )))
}

/// `cellwatch plant init`.
pub(crate) fn init(args: &InitArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let path = &args.inventory.plant;
    if !path.exists() {
        let mut routers = Vec::new();
        for r in &args.router {
            let (name, host) = r.split_once('=').ok_or_else(|| {
                Failure::Input(format!(
                    "--router {r}: give NAME=HOST (router-1=router-1.plant)"
                ))
            })?;
            routers.push((name.to_string(), host.to_string()));
        }
        let text = edit::new_inventory(&args.name, &routers);
        crate::plant::inventory::parse(path, &text).map_err(plant_failure)?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| Failure::Runtime(format!("cannot create {}: {e}", dir.display())))?;
        }
        std::fs::write(path, text)
            .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", path.display())))?;
        writeln!(
            out,
            "made     {} (the inventory: add cells and operators to it)",
            path.display()
        )
        .map_err(Failure::output)?;
    } else if !args.router.is_empty() {
        return Err(Failure::Input(format!(
            "--router: {} exists; add routers to it as [routers.NAME] tables",
            path.display()
        )));
    }
    let inventory = crate::plant::inventory::load(path).map_err(plant_failure)?;
    made(&inventory, out)
}

fn actions(flag: &str, list: &[&str]) -> Result<Vec<Action>, Failure> {
    list.iter()
        .filter(|a| !a.is_empty())
        .map(|a| {
            Action::parse(a.trim()).ok_or_else(|| {
                let all: Vec<&str> = Action::ALL.iter().map(|a| a.as_str()).collect();
                Failure::Input(format!(
                    "{flag}: '{a}' is no action (one of {})",
                    all.join(", ")
                ))
            })
        })
        .collect()
}

fn scoped(flag: &str, given: &[String]) -> Result<Vec<(String, Vec<Action>)>, Failure> {
    given
        .iter()
        .map(|g| {
            let (scope, list) = g
                .split_once('=')
                .ok_or_else(|| Failure::Input(format!("{flag} {g}: give NAME=ACTION,ACTION")))?;
            let list: Vec<&str> = list.split(',').collect();
            Ok((scope.to_string(), actions(flag, &list)?))
        })
        .collect()
}

fn existing(path: &Path) -> Result<(), Failure> {
    if path.exists() {
        Ok(())
    } else {
        Err(Failure::Input(format!(
            "{}: no inventory (make one: cellwatch plant init --plant {})",
            path.display(),
            path.display()
        )))
    }
}

/// `cellwatch plant add-cell`.
pub(crate) fn add_cell(args: &AddCellArgs, out: &mut dyn Write) -> Result<(), Failure> {
    existing(&args.inventory.plant)?;
    let inventory = edit::add_cell(
        &args.inventory.plant,
        &NewCell {
            id: &args.cell,
            area: &args.area,
            host: &args.host,
            plc: args.plc.as_deref(),
            config: &args.config,
            metrics: args.metrics,
        },
    )
    .map_err(plant_failure)?;
    made(&inventory, out)
}

/// `cellwatch plant add-operator`.
pub(crate) fn add_operator(args: &AddOperatorArgs, out: &mut dyn Write) -> Result<(), Failure> {
    existing(&args.inventory.plant)?;
    let allow: Vec<&str> = args.allow.iter().map(String::as_str).collect();
    let allow = actions("--allow", &allow)?;
    let areas = scoped("--area", &args.area)?;
    let cells = scoped("--on-cell", &args.on_cell)?;
    let inventory = edit::add_operator(
        &args.inventory.plant,
        &NewOperator {
            name: &args.name,
            public_key: &args.public_key,
            allow: &allow,
            areas: &areas,
            cells: &cells,
        },
    )
    .map_err(plant_failure)?;
    made(&inventory, out)
}

/// `cellwatch plant rotate-key`.
pub(crate) fn rotate_key(args: &RotateKeyArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let inventory = crate::plant::inventory::load(&args.inventory.plant).map_err(plant_failure)?;
    let layout = crate::plant::layout::Layout::of(&inventory);
    let id = &args.cell;
    let done = if args.done {
        make::finish_rotation(&inventory, id)
    } else {
        make::rotate(&inventory, id)
    }
    .map_err(plant_failure)?;
    say(&done, &inventory, out)?;
    let host = inventory.cells.get(id).map_or("", |c| c.host.as_str());
    let key = layout.shown(&layout.on_host(host, &layout.signing_key(id)));
    let text = if args.done {
        format!("the trust file holds cell {id}'s new key only: give trust.toml to every client")
    } else {
        format!(
            "the trust file holds cell {id}'s old and new keys: 1. give trust.toml to every client; 2. copy {key} to {host} and restart cellwatch@{id}; 3. once `cellwatch plant check` says it signs with the new key, cellwatch plant rotate-key --cell {id} --done"
        )
    };
    writeln!(out, "{text}").map_err(Failure::output)
}

/// `cellwatch plant renew`.
pub(crate) fn renew(args: &RenewArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let inventory = crate::plant::inventory::load(&args.inventory.plant).map_err(plant_failure)?;
    let layout = crate::plant::layout::Layout::of(&inventory);
    for id in &args.cell {
        let files = make::renew(&inventory, id).map_err(plant_failure)?;
        let shown: Vec<String> = files.iter().map(|f| layout.shown(f)).collect();
        writeln!(
            out,
            "renewed  {} (copy them to its host and restart cellwatch@{id})",
            shown.join(", ")
        )
        .map_err(Failure::output)?;
    }
    // What the console judges agents against names the new certificates.
    let done = make::make(&inventory).map_err(plant_failure)?;
    say(&done, &inventory, out)
}

/// The plant's bus, joined as its administrator (`admin/plant-admin.pem`)
/// at the inventory's routers or `connect`.
async fn join(
    inventory: &Inventory,
    connect: &[String],
    trust: crate::bus::envelope::Trust,
) -> Result<crate::client::BusClient, Failure> {
    let layout = crate::plant::layout::Layout::of(inventory);
    let (cert, key) = layout.admin_cert();
    let connect = if connect.is_empty() {
        inventory
            .routers
            .values()
            .map(|r| format!("quic/{}:{}", r.host, r.port))
            .collect()
    } else {
        connect.to_vec()
    };
    let config = crate::config::ZenohConfig {
        mode: crate::config::ZenohMode::Client,
        connect,
        listen: Vec::new(),
        prefix: String::new(),
        multicast_scouting: false,
        tls: Some(crate::config::ZenohTls {
            ca: layout.ca_dir().join("ca.pem"),
            cert,
            key,
        }),
        config_file: None,
        plain: false,
        signing_key: None,
    };
    crate::client::BusClient::open(&config, trust, &inventory.root)
        .await
        .map_err(|e| Failure::Runtime(format!("cannot join the plant's bus: {e}")))
}

/// `cellwatch plant publish`.
pub(crate) async fn publish(args: &PublishArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let inventory = crate::plant::inventory::load(&args.inventory.plant).map_err(plant_failure)?;
    let layout = crate::plant::layout::Layout::of(&inventory);
    let (signed, version) = check::operators_list(&layout)
        .map_err(|e| Failure::Input(format!("{e} (make it: cellwatch plant init)")))?;
    let trust = crate::bus::envelope::Trust::load(&layout.trust()).map_err(Failure::input)?;
    let bus = join(&inventory, &args.connect, trust).await?;
    let key = crate::bus::keys::plant_operators(&inventory.root);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(args.timeout_secs);
    let mut waiting: Vec<&String> = inventory.cells.keys().collect();
    let mut held = std::collections::BTreeMap::new();
    loop {
        bus.session()
            .put(&key, signed.clone())
            .await
            .map_err(|e| Failure::Runtime(format!("cannot put {key}: {e}")))?;
        let asks = waiting.iter().map(|cell| {
            let bus = &bus;
            async move {
                let about = bus
                    .ask(
                        cell,
                        crate::bus::keys::Service::About,
                        "",
                        None,
                        Duration::from_secs(3),
                    )
                    .await;
                let v = about.ok().and_then(|t| {
                    serde_json::from_str::<crate::payload::AboutPayload>(&t)
                        .ok()?
                        .operators_version
                });
                (cell.to_string(), v)
            }
        });
        for (cell, v) in futures_util::future::join_all(asks).await {
            held.insert(cell, v);
        }
        waiting.retain(|c| held.get(*c).copied().flatten().unwrap_or(0) < version);
        if waiting.is_empty() || tokio::time::Instant::now() >= deadline {
            break;
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let io = Failure::output;
    for (cell, v) in &held {
        match v {
            Some(v) if *v >= version => writeln!(out, "cell {cell}: judges by operators list v{v}"),
            Some(v) => writeln!(out, "cell {cell}: still judges by operators list v{v}"),
            None => writeln!(out, "cell {cell}: has not taken the list (no answer, or it judges by its operators file)"),
        }
        .map_err(io)?;
    }
    if waiting.is_empty() {
        writeln!(out, "operators list v{version} taken by every cell").map_err(io)?;
        Ok(())
    } else {
        Err(Failure::Runtime(format!(
            "operators list v{version} not taken by {} of {} cells within {} s",
            waiting.len(),
            inventory.cells.len(),
            args.timeout_secs
        )))
    }
}

/// `cellwatch plant check`.
pub(crate) async fn run_check(args: &CheckArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let inventory = crate::plant::inventory::load(&args.inventory.plant).map_err(plant_failure)?;
    let now = crate::clock::now_ms();
    let (mut report, trust) = check::folder(&inventory, now);
    if let (false, Some(trust)) = (args.offline, trust) {
        let bus = join(&inventory, &args.connect, trust).await?;
        let timeout = Duration::from_secs(args.timeout_secs);
        check::running(&inventory, &bus, timeout, now, &mut report).await;
        // Each router alone: given --connect, the inventory's only router
        // is there.
        let routers: Vec<(&String, String)> = match (&args.connect[..], inventory.routers.len()) {
            ([one], 1) => inventory.routers.keys().map(|n| (n, one.clone())).collect(),
            ([], _) => inventory
                .routers
                .iter()
                .map(|(n, r)| (n, format!("quic/{}:{}", r.host, r.port)))
                .collect(),
            _ => Vec::new(),
        };
        for (name, endpoint) in routers {
            let through = |_| async {
                let t = crate::bus::envelope::Trust::default();
                join(&inventory, std::slice::from_ref(&endpoint), t).await
            };
            if let (Ok(speaker), Ok(hearer)) = (through(()).await, through(()).await) {
                check::probe(
                    &inventory,
                    name,
                    speaker.session(),
                    hearer.session(),
                    &mut report,
                )
                .await;
            }
        }
    }
    write!(out, "{}", report.text()).map_err(Failure::output)?;
    if report.wrong() {
        Err(Failure::Runtime(
            "the plant is not as its inventory says".into(),
        ))
    } else {
        Ok(())
    }
}
