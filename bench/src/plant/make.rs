//! The plant made and started: its inventory and each cell's configuration,
//! `cellwatch plant init`'s files made this host's, the routers, the console,
//! Prometheus and the agents as processes of their own.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use anyhow::{anyhow, bail, Context};

use crate::cell::{self};
use crate::load::NAMESPACE;

use super::parts::{Cell, Process, Setup, CELLS_PER_AREA};

/// Writes the plant's inventory and each cell's configuration.
pub(super) fn inventory(
    setup: &Setup,
    dir: &Path,
    cells: &[Cell],
    ports: &[u16],
    operator: &cellwatch::operator::OperatorKey,
) -> anyhow::Result<()> {
    let mut toml = String::from("# Written by cellwatch-bench plant.\n[plant]\nname = \"bench\"\n");
    for (i, port) in ports.iter().enumerate() {
        toml.push_str(&format!(
            "\n[routers.router-{}]\nhost = \"127.0.0.1\"\nport = {port}\n",
            i + 1
        ));
    }
    toml.push_str(&format!(
        "\n[operators.bench]\npublic_key = \"{}\"\nallow = [\"ack\"]\n",
        operator.public_hex()
    ));
    for (i, c) in cells.iter().enumerate() {
        let folder = dir.join("cells").join(&c.id);
        std::fs::create_dir_all(&folder)?;
        std::fs::write(folder.join("fault.il"), cell::program())?;
        std::fs::write(folder.join("tags.csv"), cell::tags_csv(setup.load))?;
        std::fs::write(
            folder.join("cell.toml"),
            format!(
                "# Written by cellwatch-bench plant.\ntags_file = \"tags.csv\"\n\n\
                 [cell]\nid = \"{}\"\n\n\
                 [opcua]\nendpoint = \"{}\"\nsecurity_policy = \"Basic256Sha256\"\n\
                 security_mode = \"SignAndEncrypt\"\npublishing_interval = \"100ms\"\n\
                 namespace_uri = \"{NAMESPACE}\"\n\n\
                 [[checks.switching]]\nid = \"fault\"\nprogram = \"fault.il\"\ndialect = \"iec\"\n\
                 coil = \"FAULT\"\nfault_when = \"on\"\nseverity = \"high\"\n",
                c.id,
                c.server.endpoint()
            ),
        )?;
        toml.push_str(&format!(
            "\n[cells.{}]\narea = \"area{}\"\nhost = \"127.0.0.1\"\nconfig = \"cells/{}/cell.toml\"\nplc = \"{}\"\nmetrics = {}\n",
            c.id,
            i / CELLS_PER_AREA + 1,
            c.id,
            c.server.endpoint(),
            c.metrics.port()
        ));
    }
    std::fs::write(dir.join("plant.toml"), toml)?;
    Ok(())
}

/// Cell `id`'s configuration as the plant deployed it, its paths made the
/// ones of the host's folder in the plant's tree; the file written.
pub(super) fn as_on_host(dir: &Path, id: &str) -> anyhow::Result<PathBuf> {
    let tree = dir.join("hosts/127.0.0.1");
    let etc = tree.join("etc/cellwatch");
    let text = std::fs::read_to_string(etc.join(format!("{id}.toml")))
        .with_context(|| format!("the plant made no configuration for {id}"))?
        .replace("/etc/cellwatch", &etc.display().to_string())
        .replace(
            "/var/lib/cellwatch",
            &tree.join("var/lib/cellwatch").display().to_string(),
        );
    let file = etc.join(format!("{id}.bench.toml"));
    std::fs::write(&file, text)?;
    Ok(file)
}

/// Router `r` as `cellwatch router` runs it from the configuration the
/// plant made, its paths the router's folder; returns once it listens.
pub(super) fn router(agent: &Path, dir: &Path, r: usize) -> anyhow::Result<Process> {
    let root = dir.join(format!("routers/router-{r}"));
    let text = std::fs::read_to_string(root.join("etc/cellwatch/router/router.json5"))?
        .replace(
            "/etc/cellwatch",
            &root.join("etc/cellwatch").display().to_string(),
        )
        .replace(
            "/var/lib/cellwatch",
            &root.join("var/lib/cellwatch").display().to_string(),
        );
    let file = root.join("router.bench.json5");
    std::fs::write(&file, text)?;
    let mut child = Command::new(agent)
        .args(["router", "--config"])
        .arg(&file)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(root.join("router.log"))?)
        .spawn()?;
    first_line(&mut child, "listening on", &root.join("router.log"))?;
    Ok(Process {
        name: format!("router-{r}"),
        child,
    })
}

/// Waits for the first line of `child`'s output, which must hold `says`.
pub(super) fn first_line(child: &mut Child, says: &str, log: &Path) -> anyhow::Result<String> {
    use std::io::BufRead;
    let out = child.stdout.take().ok_or_else(|| anyhow!("no stdout"))?;
    let mut reader = std::io::BufReader::new(out);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    if !line.contains(says) {
        bail!("{line:?} (see {})", log.display());
    }
    // Read on, so the child never blocks on a full pipe.
    std::thread::spawn(move || {
        let mut sink = String::new();
        while reader.read_line(&mut sink).is_ok_and(|n| n > 0) {
            sink.clear();
        }
    });
    Ok(line)
}

/// The console: the plant's operators, every area, a client of every
/// router with the plant administrator's certificate, plain HTTP on
/// loopback; returns it and its address once it serves.
pub(super) fn console(
    setup: &Setup,
    dir: &Path,
    ports: &[u16],
    operator: &cellwatch::operator::OperatorKey,
) -> anyhow::Result<(Process, SocketAddr)> {
    let root = dir.join("console");
    std::fs::create_dir_all(&root)?;
    std::fs::write(
        root.join("operators.toml"),
        operator.operators_entry(&[cellwatch::operator::Action::Ack]),
    )?;
    let connect: Vec<String> = ports
        .iter()
        .map(|p| format!("\"quic/127.0.0.1:{p}\""))
        .collect();
    let mut areas = BTreeMap::<usize, Vec<String>>::new();
    for i in 0..setup.cells {
        areas
            .entry(i / CELLS_PER_AREA + 1)
            .or_default()
            .push(format!("\"c{i:02}\""));
    }
    let areas: String = areas
        .iter()
        .map(|(a, cs)| format!("area{a} = [{}]\n", cs.join(", ")))
        .collect();
    std::fs::write(
        root.join("console.toml"),
        format!(
            "[http]\nlisten = \"127.0.0.1:0\"\n\n[bus]\nmode = \"client\"\nconnect = [{}]\ntrust = {:?}\n\
             tls = {{ ca = {:?}, cert = {:?}, key = {:?} }}\n\n[operators]\nfile = {:?}\n\n[areas]\n{areas}",
            connect.join(", "),
            dir.join("trust.toml"),
            dir.join("ca/ca.pem"),
            dir.join("admin/plant-admin.pem"),
            dir.join("admin/plant-admin.key"),
            root.join("operators.toml"),
        ),
    )?;
    let log = root.join("console.log");
    let mut child = Command::new(&setup.agent)
        .args(["console", "--config"])
        .arg(root.join("console.toml"))
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(&log)?)
        .spawn()?;
    let line = first_line(&mut child, "cellwatch console: http://", &log)?;
    let addr = line
        .trim()
        .trim_start_matches("cellwatch console: http://")
        .trim_end_matches('/')
        .parse()
        .with_context(|| format!("the console's address in {line:?}"))?;
    Ok((
        Process {
            name: "console".into(),
            child,
        },
        addr,
    ))
}

/// Prometheus with the plant's targets file, its data under the plant's
/// folder: it and its port.
pub(super) fn prometheus(program: &Path, dir: &Path) -> anyhow::Result<(Process, u16)> {
    let root = dir.join("prometheus");
    let port = cell::free_port()?;
    std::fs::write(
        root.join("bench.yml"),
        format!(
            "global:\n  scrape_interval: 15s\nscrape_configs:\n  - job_name: cellwatch\n    file_sd_configs:\n      - files: [{:?}]\n",
            root.join("cellwatch.yml")
        ),
    )?;
    let child = Command::new(program)
        .arg(format!(
            "--config.file={}",
            root.join("bench.yml").display()
        ))
        .arg(format!(
            "--storage.tsdb.path={}",
            root.join("data").display()
        ))
        .arg(format!("--web.listen-address=127.0.0.1:{port}"))
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(root.join("prometheus.log"))?)
        .spawn()
        .with_context(|| format!("cannot start {}", program.display()))?;
    Ok((
        Process {
            name: "prometheus".into(),
            child,
        },
        port,
    ))
}

/// Starts cell `c`'s agent from its deployed configuration.
pub(super) fn spawn_agent(agent: &Path, c: &Cell) -> anyhow::Result<Process> {
    let log = c.config.with_extension("log");
    let child = Command::new(agent)
        .arg("run")
        .arg(&c.config)
        .env("RUST_LOG", "warn")
        .stdout(std::fs::File::create(&log)?)
        .stderr(std::fs::File::create(log.with_extension("err.log"))?)
        .spawn()
        .with_context(|| format!("cannot start {}", agent.display()))?;
    Ok(Process {
        name: c.id.clone(),
        child,
    })
}

/// Waits until `c`'s agent is connected and has every tag's first value.
pub(super) async fn ready(c: &mut Cell, dir: &Path) -> anyhow::Result<()> {
    let agent = c
        .agent
        .as_mut()
        .ok_or_else(|| anyhow!("{} has no agent", c.id))?;
    cell::wait_ready(&mut agent.child, c.metrics, dir)
        .await
        .with_context(|| {
            format!(
                "cell {} (see {})",
                c.id,
                c.config.with_extension("log").display()
            )
        })
}
