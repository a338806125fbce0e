//! `cellwatch discover`: browse an OPC UA server and print its variables as
//! a cell configuration, or check a configuration's tags against it.

use std::path::PathBuf;

use std::collections::{BTreeMap, HashSet, VecDeque};
use std::io::Write;

use ::opcua::client::Session;
use ::opcua::types::{
    AttributeId, BrowseDescription, BrowseDirection, BrowseResultMask, DataValue, NodeClass,
    NodeId, ReadValueId, ReferenceTypeId, StatusCode, TimestampsToReturn, Variant,
};
use cellwatch_models::value::ValueType;

use super::Failure;
use crate::config::{self, OpcUaConfig, TagConfig};
use crate::sources::opcua::{self, TagNode};

/// The most variables one discovery collects (memory stays bounded on a
/// server with millions of nodes; narrow with --root and --filter).
const MAX_VARIABLES: usize = 100_000;
/// Nodes per Browse and Read call.
const CHUNK: usize = 500;

/// A variable found on the server.
struct Found {
    node: NodeId,
    browse_name: String,
    data_type: Result<ValueType, String>,
    description: Option<String>,
}

pub(crate) async fn run(args: &DiscoverArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let (opcua, check) = match &args.check {
        Some(path) => {
            let c = config::load(path).map_err(Failure::input)?;
            let mut o = c.opcua.clone().ok_or_else(|| {
                Failure::input(format!(
                    "{}: --check needs an OPC UA cell (this one reads a [legacy] bus)",
                    path.display()
                ))
            })?;
            if let Some(e) = &args.endpoint {
                o.endpoint = e.clone();
            }
            (o, Some(c))
        }
        None => (args.opcua()?, None),
    };
    let (session, task) = opcua::connect_once("discover", &opcua)
        .await
        .map_err(Failure::runtime)?;
    let result = async {
        let namespaces = opcua::namespaces(&session)
            .await
            .map_err(|e| Failure::runtime(format!("cannot read the namespace array: {e}")))?;
        match &check {
            Some(c) => check_tags(&session, &namespaces, &c.tags, out).await,
            None => {
                let root = match &args.root {
                    None => NodeId::objects_folder_id(),
                    Some(text) => TagNode::parse(text, None)
                        .map_err(Failure::input)?
                        .resolve(&namespaces)
                        .ok_or_else(|| {
                            Failure::input(format!(
                                "--root {text}: the server has no such namespace"
                            ))
                        })?,
                };
                let filter = match &args.filter {
                    None => None,
                    Some(g) => Some(
                        glob::Pattern::new(g)
                            .map_err(|e| Failure::input(format!("--filter '{g}': {e}")))?,
                    ),
                };
                let id = match &args.cell {
                    Some(id) if config::key_chunk(id) => id.clone(),
                    Some(id) => {
                        return Err(Failure::input(format!(
                            "--cell '{id}': letters, digits, '-' and '_' only"
                        )))
                    }
                    None => cell_id(
                        &opcua::server_identity(&opcua)
                            .await
                            .map_err(Failure::runtime)?
                            .application_name,
                    ),
                };
                let cell = Cell { id, args };
                let found = browse(&session, root, args.depth, filter.as_ref()).await?;
                let (tags, skipped) = discovered_tags(&namespaces, &found);
                if let Some(path) = &args.tags_file {
                    write_tags_file(path, &tags).map_err(|e| {
                        Failure::runtime(format!("--tags-file {}: {e}", path.display()))
                    })?;
                }
                print_config(&opcua, &cell, &tags, &skipped, out).map_err(Failure::output)?;
                let missing = cell.missing();
                if !missing.is_empty() {
                    eprintln!(
                        "note: the configuration names files that are not there yet; `cellwatch validate` wants them:"
                    );
                    for m in missing {
                        eprintln!("  {m}");
                    }
                }
                Ok(())
            }
        }
    }
    .await;
    let _ = session.disconnect().await;
    task.abort();
    result
}

/// Every variable under `root`, `depth` levels of hierarchical references
/// deep, whose browse name matches `filter`, with type and description.
/// Nodes of namespace 0 (the OPC UA standard's own: the Server object) are
/// left out.
async fn browse(
    session: &Session,
    root: NodeId,
    depth: u32,
    filter: Option<&glob::Pattern>,
) -> Result<Vec<Found>, Failure> {
    let mut seen: HashSet<NodeId> = HashSet::from([root.clone()]);
    let mut queue: VecDeque<(NodeId, u32)> = VecDeque::from([(root, 0)]);
    let mut variables: Vec<(NodeId, String)> = Vec::new();
    while !queue.is_empty() {
        let batch: Vec<(NodeId, u32)> = queue.drain(..queue.len().min(CHUNK)).collect();
        let request: Vec<BrowseDescription> = batch
            .iter()
            .map(|(n, _)| BrowseDescription {
                node_id: n.clone(),
                browse_direction: BrowseDirection::Forward,
                reference_type_id: ReferenceTypeId::HierarchicalReferences.into(),
                include_subtypes: true,
                node_class_mask: NodeClass::Object as u32 | NodeClass::Variable as u32,
                result_mask: BrowseResultMask::All as u32,
            })
            .collect();
        let mut results = session
            .browse(&request, 1000, None)
            .await
            .map_err(|e| Failure::runtime(format!("browse failed: {e}")))?;
        let mut levels: Vec<u32> = batch.iter().map(|(_, d)| *d).collect();
        loop {
            let mut more = Vec::new();
            let mut more_levels = Vec::new();
            for (r, level) in results.iter().zip(&levels) {
                for rd in r.references.iter().flatten() {
                    if rd.node_id.server_index != 0 || rd.node_id.node_id.is_null() {
                        continue;
                    }
                    let node = rd.node_id.node_id.clone();
                    // The OPC UA namespace itself (the Server object, its
                    // capabilities and diagnostics) is no PLC data.
                    if node.namespace == 0 || !seen.insert(node.clone()) {
                        continue;
                    }
                    let name = rd.browse_name.name.as_ref().to_string();
                    if rd.node_class == NodeClass::Variable
                        && filter.is_none_or(|f| f.matches(&name))
                    {
                        if variables.len() >= MAX_VARIABLES {
                            return Err(Failure::runtime(format!(
                                "more than {MAX_VARIABLES} variables: narrow the search with --root, --depth or --filter"
                            )));
                        }
                        variables.push((node.clone(), name));
                    }
                    if rd.node_class == NodeClass::Object && level + 1 < depth {
                        queue.push_back((node, level + 1));
                    }
                }
                if !r.continuation_point.is_null() {
                    more.push(r.continuation_point.clone());
                    more_levels.push(*level);
                }
            }
            if more.is_empty() {
                break;
            }
            results = session
                .browse_next(false, &more)
                .await
                .map_err(|e| Failure::runtime(format!("browse failed: {e}")))?;
            levels = more_levels;
        }
    }
    let nodes: Vec<NodeId> = variables.iter().map(|(n, _)| n.clone()).collect();
    let types = read_attribute(session, &nodes, AttributeId::DataType).await?;
    let descriptions = read_attribute(session, &nodes, AttributeId::Description).await?;
    Ok(variables
        .into_iter()
        .zip(types.iter().zip(&descriptions))
        .map(|((node, browse_name), (t, d))| Found {
            node,
            browse_name,
            data_type: value_type(t),
            description: match &d.value {
                Some(Variant::LocalizedText(t)) if !t.text.is_empty() => {
                    Some(t.text.as_ref().to_string())
                }
                _ => None,
            },
        })
        .collect())
}

async fn read_attribute(
    session: &Session,
    nodes: &[NodeId],
    attribute: AttributeId,
) -> Result<Vec<DataValue>, Failure> {
    let mut out = Vec::with_capacity(nodes.len());
    for part in nodes.chunks(CHUNK) {
        let ids: Vec<ReadValueId> = part
            .iter()
            .map(|n| ReadValueId {
                node_id: n.clone(),
                attribute_id: attribute as u32,
                ..Default::default()
            })
            .collect();
        out.extend(
            session
                .read(&ids, TimestampsToReturn::Neither, 0.0)
                .await
                .map_err(|e| Failure::runtime(format!("read failed: {e}")))?,
        );
    }
    Ok(out)
}

/// The scalar type a `DataType` attribute names, or why it is not one.
fn value_type(v: &DataValue) -> Result<ValueType, String> {
    if let Some(s) = v.status.filter(|s| !s.is_good()) {
        return Err(if s == StatusCode::BadNodeIdUnknown {
            "no such node".into()
        } else {
            s.to_string()
        });
    }
    let Some(Variant::NodeId(id)) = &v.value else {
        return Err("no data type".into());
    };
    if id.namespace == 0 {
        if let ::opcua::types::Identifier::Numeric(n) = id.identifier {
            if (1..=13).contains(&n) {
                return Ok(ValueType::ALL[n as usize - 1]);
            }
        }
    }
    Err(format!(
        "data type {id} is not a scalar type cellwatch reads"
    ))
}

/// A node id written with its namespace URI where the server has one.
fn node_text(node: &NodeId, namespaces: &[String]) -> String {
    match namespaces.get(node.namespace as usize) {
        Some(uri) if node.namespace > 0 => format!("nsu={uri};{}", node.identifier),
        _ => format!("ns={};{}", node.namespace, node.identifier),
    }
}

fn quoted(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// A tag as discovery found it.
struct Discovered {
    name: String,
    node_id: String,
    address: String,
    value_type: ValueType,
    comment: Option<String>,
}

/// The tags of the variables `found` (unique names and addresses), and the
/// nodes left out with the reason.
fn discovered_tags(
    namespaces: &[String],
    found: &[Found],
) -> (Vec<Discovered>, BTreeMap<String, String>) {
    let mut names = HashSet::new();
    let mut addresses = HashSet::new();
    let mut skipped = BTreeMap::new();
    let mut tags = Vec::new();
    for f in found {
        let t = match &f.data_type {
            Ok(t) => *t,
            Err(why) => {
                skipped.insert(node_text(&f.node, namespaces), why.clone());
                continue;
            }
        };
        let Some(address) = address_of(&f.browse_name).filter(|a| addresses.insert(a.clone()))
        else {
            skipped.insert(
                node_text(&f.node, namespaces),
                format!(
                    "'{}' is no usable address (or is used twice)",
                    f.browse_name
                ),
            );
            continue;
        };
        let mut name = tag_name(&f.browse_name);
        let base = name.clone();
        let mut k = 2;
        while !names.insert(name.clone()) {
            name = format!("{base}_{k}");
            k += 1;
        }
        tags.push(Discovered {
            name,
            node_id: node_text(&f.node, namespaces),
            address,
            value_type: t,
            comment: f.description.clone(),
        });
    }
    (tags, skipped)
}

/// Writes `tags` as a `tags_file`: a header, one row a tag (`type` empty
/// for Boolean, the default).
fn write_tags_file(path: &std::path::Path, tags: &[Discovered]) -> Result<(), String> {
    let mut w = csv::Writer::from_path(path).map_err(|e| e.to_string())?;
    w.write_record(["name", "node_id", "address", "type", "comment"])
        .map_err(|e| e.to_string())?;
    for t in tags {
        let ty = if t.value_type == ValueType::Boolean {
            ""
        } else {
            t.value_type.as_str()
        };
        w.write_record([
            t.name.as_str(),
            &t.node_id,
            &t.address,
            ty,
            t.comment.as_deref().unwrap_or(""),
        ])
        .map_err(|e| e.to_string())?;
    }
    w.flush().map_err(|e| e.to_string())
}

fn print_config(
    opcua: &OpcUaConfig,
    cell: &Cell<'_>,
    tags: &[Discovered],
    skipped: &BTreeMap<String, String>,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    let args = cell.args;
    let tags_file = args.tags_file.as_deref();
    writeln!(
        out,
        "# Cell {} as `cellwatch discover` found it on {}.",
        cell.id, opcua.endpoint
    )?;
    writeln!(
        out,
        "# Keep the tags your checks read and add the checks ([[checks.limit]],\n# [[checks.discrete]], ...); `cellwatch validate` this file before `run`."
    )?;
    if let Some(path) = tags_file {
        writeln!(
            out,
            "\n# {} tags in the tags file (relative paths: from this file's directory).",
            tags.len()
        )?;
        writeln!(out, "tags_file = {}", quoted(&path.display().to_string()))?;
    }
    writeln!(out, "\n[cell]\nid = {}\n", quoted(&cell.id))?;
    writeln!(out, "[opcua]\nendpoint = {}", quoted(&opcua.endpoint))?;
    writeln!(out, "security_policy = {}", quoted(opcua.policy.as_str()))?;
    writeln!(out, "security_mode = {}", quoted(opcua.mode.as_str()))?;
    writeln!(
        out,
        "pki_dir = {}",
        quoted(&opcua.pki_dir.display().to_string())
    )?;
    if let crate::config::Identity::User { user, password } = &opcua.identity {
        writeln!(
            out,
            "\n[opcua.identity]\nkind = \"user\"\nuser = {}",
            quoted(user)
        )?;
        if let crate::config::PasswordSource::Env(var) = password {
            writeln!(out, "password_env = {}", quoted(var))?;
        }
    }
    if tags_file.is_none() {
        for t in tags {
            writeln!(out, "\n[[tags]]")?;
            writeln!(out, "name = {}", quoted(&t.name))?;
            writeln!(out, "node_id = {}", quoted(&t.node_id))?;
            writeln!(out, "address = {}", quoted(&t.address))?;
            if t.value_type != ValueType::Boolean {
                writeln!(out, "type = {}", quoted(t.value_type.as_str()))?;
            }
            if let Some(d) = &t.comment {
                writeln!(out, "comment = {}", quoted(d))?;
            }
        }
    }
    for (node, why) in skipped {
        let (node, why) = (
            crate::operator::escaped(node),
            crate::operator::escaped(why),
        );
        writeln!(out, "# skipped {node}: {why}")?;
    }
    let list = |items: &[String]| {
        items
            .iter()
            .map(|i| quoted(i))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let listen = if args.listen.is_empty() && args.connect.is_empty() {
        vec!["quic/127.0.0.1:7447".to_string()]
    } else {
        args.listen.clone()
    };
    writeln!(out, "\n[zenoh]")?;
    if !listen.is_empty() {
        writeln!(out, "listen = [{}]", list(&listen))?;
    }
    if !args.connect.is_empty() {
        writeln!(out, "connect = [{}]", list(&args.connect))?;
    }
    writeln!(
        out,
        "signing_key = {}",
        quoted(&cell.signing_key().display().to_string())
    )?;
    let [ca, cert, key] = cell.bus_files();
    writeln!(out, "\n[zenoh.tls]")?;
    for (k, path) in [("ca", ca), ("cert", cert), ("key", key)] {
        writeln!(out, "{k} = {}", quoted(&path.display().to_string()))?;
    }
    writeln!(
        out,
        "\n[commands]\noperators_file = {}",
        quoted(&args.operators.display().to_string())
    )
}

/// The PLC address a browse name stands for: the name itself when it is
/// one (`X0.06`, `D100`, `%IX0.0.3`, `Start`), else its letters, digits,
/// `_` and `.`.
fn address_of(browse_name: &str) -> Option<String> {
    config::tag_address(browse_name)
        .or_else(|_| {
            let clean: String = browse_name
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '.' {
                        c
                    } else {
                        '_'
                    }
                })
                .collect();
            config::tag_address(&clean)
        })
        .ok()
        .map(|s| s.to_string())
}

fn tag_name(browse_name: &str) -> String {
    let name: String = browse_name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if name.is_empty() {
        "tag".into()
    } else {
        name
    }
}

/// Reports the configured tags the server lacks or types differently.
async fn check_tags(
    session: &Session,
    namespaces: &[String],
    tags: &[TagConfig],
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let mut nodes = Vec::new();
    let mut problems = Vec::new();
    for t in tags {
        let node = TagNode::parse(&t.node_id, None)
            .ok()
            .and_then(|n| n.resolve(namespaces));
        match node {
            Some(n) => nodes.push((t, n)),
            None => problems.push(format!(
                "{} ({}): missing: the server has no namespace for {}",
                t.name, t.address, t.node_id
            )),
        }
    }
    let ids: Vec<NodeId> = nodes.iter().map(|(_, n)| n.clone()).collect();
    let types = read_attribute(session, &ids, AttributeId::DataType).await?;
    for ((t, _), v) in nodes.iter().zip(&types) {
        match value_type(v) {
            Err(why) => problems.push(format!(
                "{} ({}): missing: {} ({why})",
                t.name, t.address, t.node_id
            )),
            Ok(server) if server != t.value_type => problems.push(format!(
                "{} ({}): typed differently: the configuration says {}, the server has {server}",
                t.name, t.address, t.value_type
            )),
            Ok(_) => {}
        }
    }
    for p in &problems {
        // Node ids and the server's reasons are the server's text.
        writeln!(out, "{}", crate::operator::escaped(p)).map_err(Failure::output)?;
    }
    if problems.is_empty() {
        writeln!(
            out,
            "all {} tags are on the server with their types",
            tags.len()
        )
        .map_err(Failure::output)?;
        Ok(())
    } else {
        Err(Failure::runtime(format!(
            "{} of {} tags do not match the server",
            problems.len(),
            tags.len()
        )))
    }
}

#[derive(Debug, clap::Args)]
pub(crate) struct DiscoverArgs {
    /// The server's endpoint (opc.tcp://host:port/path); with --check, the
    /// configuration's endpoint unless given.
    #[arg(required_unless_present = "check")]
    pub(crate) endpoint: Option<String>,
    /// Where to start browsing (a node id: nsu=<uri>;s=Machine or
    /// ns=2;i=1000); the Objects folder by default.
    #[arg(long)]
    pub(crate) root: Option<String>,
    /// How many levels of folders and objects to descend.
    #[arg(long, default_value_t = 10)]
    pub(crate) depth: u32,
    /// Only variables whose browse name matches this glob (`X0.*`, `D1??`).
    #[arg(long)]
    pub(crate) filter: Option<String>,
    /// Write the tags found to this CSV file (the `tags_file` format: one
    /// row a tag, columns name, node_id, address, type, comment) instead
    /// of `[[tags]]` tables, and print a configuration that reads it: for
    /// servers of thousands of tags. Replaces the file if it exists.
    #[arg(long, value_name = "PATH", conflicts_with = "check")]
    pub(crate) tags_file: Option<PathBuf>,
    /// Check this cell configuration instead: report the tags the server
    /// lacks or types differently (exit status 1 if any); connects with
    /// the configuration's [opcua] settings.
    #[arg(long)]
    pub(crate) check: Option<PathBuf>,
    /// PKI directory (own key pair, trusted/ and rejected/ certificates).
    #[arg(long, default_value = "pki")]
    pub(crate) pki_dir: PathBuf,
    /// Basic256Sha256 | Aes128_Sha256_RsaOaep | Aes256_Sha256_RsaPss | None.
    #[arg(long, default_value = "Basic256Sha256")]
    pub(crate) security_policy: crate::config::SecurityPolicy,
    /// SignAndEncrypt | Sign | None.
    #[arg(long, default_value = "SignAndEncrypt")]
    pub(crate) security_mode: crate::config::SecurityMode,
    /// Log in as this user (the password from --password-env).
    #[arg(long, requires = "password_env")]
    pub(crate) user: Option<String>,
    /// The environment variable holding the user's password.
    #[arg(long)]
    pub(crate) password_env: Option<String>,
    /// The cell's id; by default made from the server's application name
    /// (`Press 7 PLC` → `press-7-plc`).
    #[arg(long, conflicts_with = "check")]
    pub(crate) cell: Option<String>,
    /// The bus's certificates (`cellwatch pki`): its ca.pem and the cell's
    /// agent-<cell>.pem and .key.
    #[arg(
        long,
        value_name = "DIR",
        default_value = "pki-bus",
        conflicts_with = "check"
    )]
    pub(crate) bus_pki: PathBuf,
    /// Where the agent listens on the bus (repeatable); without --listen or
    /// --connect, quic/127.0.0.1:7447.
    #[arg(long, value_name = "ENDPOINT", conflicts_with = "check")]
    pub(crate) listen: Vec<String>,
    /// A Zenoh router or peer the agent connects to (repeatable),
    /// quic/host:port.
    #[arg(long, value_name = "ENDPOINT", conflicts_with = "check")]
    pub(crate) connect: Vec<String>,
    /// The agent's signing key (`cellwatch pki agent-key`); by default
    /// <cell>.agent.key.
    #[arg(long, value_name = "FILE", conflicts_with = "check")]
    pub(crate) signing_key: Option<PathBuf>,
    /// The operators file (`cellwatch keygen`).
    #[arg(
        long,
        value_name = "FILE",
        default_value = "operators.toml",
        conflicts_with = "check"
    )]
    pub(crate) operators: PathBuf,
}

/// What `discover` writes beyond the server's variables: the cell and its
/// place on the bus.
struct Cell<'a> {
    id: String,
    args: &'a DiscoverArgs,
}

impl Cell<'_> {
    fn signing_key(&self) -> PathBuf {
        self.args
            .signing_key
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("{}.agent.key", self.id)))
    }

    fn bus_files(&self) -> [PathBuf; 3] {
        let dir = &self.args.bus_pki;
        [
            dir.join("ca.pem"),
            dir.join(format!("agent-{}.pem", self.id)),
            dir.join(format!("agent-{}.key", self.id)),
        ]
    }

    /// The files the configuration names that are not there yet, with the
    /// command that makes each.
    fn missing(&self) -> Vec<String> {
        let [ca, cert, key] = self.bus_files();
        let dir = self.args.bus_pki.display();
        let mut out = Vec::new();
        if !ca.exists() {
            out.push(format!("{}: cellwatch pki ca --dir {dir}", ca.display()));
        }
        if !cert.exists() || !key.exists() {
            out.push(format!(
                "{}: cellwatch pki issue --dir {dir} --name agent-{}",
                cert.display(),
                self.id
            ));
        }
        let signing = self.signing_key();
        if !signing.exists() {
            out.push(format!(
                "{}: cellwatch pki agent-key --cell {} --out {} >> trust.toml",
                signing.display(),
                self.id,
                signing.display()
            ));
        }
        if !self.args.operators.exists() {
            out.push(format!(
                "{}: cellwatch keygen --operator NAME --out NAME.key --allow ack >> {}",
                self.args.operators.display(),
                self.args.operators.display()
            ));
        }
        out
    }
}

/// A cell id from a server's application name: lower case, every run of
/// other characters than letters, digits, `-` and `_` one `-`.
fn cell_id(application_name: &str) -> String {
    let mut id = String::new();
    for c in application_name.trim().chars() {
        if c.is_alphanumeric() || c == '_' {
            id.extend(c.to_lowercase());
        } else if !id.ends_with('-') {
            id.push('-');
        }
    }
    let id = id.trim_matches('-').to_string();
    if id.is_empty() {
        "cell".into()
    } else {
        id
    }
}

impl DiscoverArgs {
    /// The connection the flags describe.
    pub(crate) fn opcua(&self) -> Result<crate::config::OpcUaConfig, Failure> {
        connection(
            self.endpoint.as_deref().unwrap_or_default(),
            &self.pki_dir,
            self.security_policy,
            self.security_mode,
            self.user.as_deref().zip(self.password_env.as_deref()),
        )
    }
}

/// A one-off connection to `endpoint`: security, the PKI directory, a
/// user and the environment variable of its password.
pub(crate) fn connection(
    endpoint: &str,
    pki_dir: &std::path::Path,
    policy: crate::config::SecurityPolicy,
    mode: crate::config::SecurityMode,
    user: Option<(&str, &str)>,
) -> Result<crate::config::OpcUaConfig, Failure> {
    use crate::config::{Identity, OpcUaConfig, PasswordSource, SecurityMode, SecurityPolicy};
    if !endpoint.starts_with("opc.tcp://") {
        return Err(Failure::input(format!(
            "'{endpoint}' must start with opc.tcp://"
        )));
    }
    if (policy == SecurityPolicy::None) != (mode == SecurityMode::None) {
        return Err(Failure::input(
            "--security-policy None goes with --security-mode None, and only with it",
        ));
    }
    let publishing = std::time::Duration::from_millis(100);
    let sampling = std::time::Duration::from_millis(50);
    Ok(OpcUaConfig {
        endpoint: endpoint.to_string(),
        policy,
        mode,
        pki_dir: pki_dir.to_path_buf(),
        identity: match user {
            Some((user, var)) => Identity::User {
                user: user.to_string(),
                password: PasswordSource::Env(var.to_string()),
            },
            None => Identity::Anonymous,
        },
        publishing_interval: publishing,
        sampling_interval: sampling,
        namespace_uri: None,
        queue_size: OpcUaConfig::default_queue_size(publishing, sampling),
        max_notifications_per_publish: OpcUaConfig::DEFAULT_MAX_NOTIFICATIONS,
        overflow_clear_after: OpcUaConfig::DEFAULT_OVERFLOW_CLEAR_AFTER,
        subscription_lifetime: OpcUaConfig::DEFAULT_SUBSCRIPTION_LIFETIME,
        verify_interval: OpcUaConfig::DEFAULT_VERIFY_INTERVAL,
        reverse_listen: None,
        redundant: Vec::new(),
        events: Vec::new(),
    })
}
