//! `cellwatch mad import`: a rationalised file taken back as the cell's
//! master alarm database. The file is checked as the agent will read it
//! (every problem at its line and column, every id an alarm of the cell),
//! the changes against the database the cell has are shown, and, unless
//! `--dry-run`, the file is written where `alarms.database` says.

use std::io::Write;
use std::path::{Path, PathBuf};

use cellwatch_models::madb::{Database, Rationale};

use super::rows::MadRow;
use crate::cell::compile::CompileError;
use crate::commands::Failure;
use crate::config::{Disk, Files};

/// `cellwatch mad import`.
#[derive(Debug, clap::Args)]
pub(crate) struct ImportArgs {
    /// The cell's configuration (its `alarms.database` says where the
    /// database is kept).
    pub(crate) config: PathBuf,
    /// The rationalised file (CSV, as `cellwatch mad export` writes it).
    pub(crate) file: PathBuf,
    /// Show the changes and check the file, write nothing.
    #[arg(long)]
    pub(crate) dry_run: bool,
}

/// The disk, with one file's bytes replaced: the configuration read as it
/// will be once the import is written.
struct WithFile<'a> {
    path: &'a Path,
    bytes: &'a [u8],
}

impl Files for WithFile<'_> {
    fn read(&self, path: &Path) -> std::io::Result<Vec<u8>> {
        if path == self.path {
            Ok(self.bytes.to_vec())
        } else {
            Disk.read(path)
        }
    }

    fn list(&self, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
        Disk.list(dir)
    }
}

pub(crate) fn run(args: &ImportArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let config_name = args.config.display().to_string();
    let text = std::fs::read_to_string(&args.config)
        .map_err(|e| Failure::Input(format!("{config_name}: cannot read: {e}")))?;
    let base = args
        .config
        .parent()
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let target = database_path(&config_name, &text, &base)?;
    let file_name = args.file.display().to_string();
    let bytes = std::fs::read(&args.file)
        .map_err(|e| Failure::Input(format!("{file_name}: cannot read: {e}")))?;
    let new_text = cellwatch_models::source::text(&file_name, &bytes, None)
        .map_err(Failure::input)?
        .to_string();
    let new = Database::parse(&file_name, &new_text).map_err(Failure::input)?;
    // The cell as it will be: its configuration with this database.
    let files = WithFile {
        path: &target,
        bytes: new_text.as_bytes(),
    };
    let c = crate::config::parse(&config_name, &text, &base, &files).map_err(Failure::input)?;
    let engine = crate::cell::compile::engine(&c).map_err(|e| match e {
        // Said in the file given, where the row is.
        CompileError::Database { line, id, .. } => Failure::Input(format!(
            "{file_name}:{line}:1: column 'id': '{id}' is no alarm of this cell (`cellwatch mad export` lists them)"
        )),
        e => Failure::Input(format!("{config_name}: {e}")),
    })?;
    let old = match std::fs::read_to_string(&target) {
        Ok(t) => Database::parse(&target.display().to_string(), &t).ok(),
        Err(_) => None,
    };
    // Where the database has no row yet, the draft is what was: the
    // priority and class the cell gives, nothing rationalised.
    let draft = {
        let mut bare = c.clone();
        bare.database = None;
        let engine = crate::cell::compile::engine(&bare).map_err(Failure::input)?;
        super::rows::rows(&bare, &engine.catalogue())
    };
    drop(engine);
    let lines = changes(old.as_ref(), &new, &draft);
    let io = Failure::output;
    for l in &lines {
        writeln!(out, "{l}").map_err(io)?;
    }
    let changed = lines.len();
    if args.dry_run {
        writeln!(
            out,
            "{changed} change{}; dry run: {} not written",
            if changed == 1 { "" } else { "s" },
            target.display()
        )
        .map_err(io)?;
        return Ok(());
    }
    std::fs::write(&target, new_text.as_bytes())
        .map_err(|e| Failure::Runtime(format!("{}: {e}", target.display())))?;
    writeln!(
        out,
        "{changed} change{}; wrote {} ({} alarms): the agent takes it at its next start or `cellwatch reload`",
        if changed == 1 { "" } else { "s" },
        target.display(),
        new.rows.len()
    )
    .map_err(io)
}

/// Where the cell keeps its database: `alarms.database`, relative to the
/// configuration's folder.
fn database_path(origin: &str, text: &str, base: &Path) -> Result<PathBuf, Failure> {
    let doc: toml::Table = text
        .parse()
        .map_err(|e| Failure::Input(format!("{origin}: {e}")))?;
    let Some(path) = doc
        .get("alarms")
        .and_then(|a| a.get("database"))
        .and_then(toml::Value::as_str)
    else {
        return Err(Failure::Input(format!(
            "{origin} names no master alarm database: add `database = \"<cell>-madb.csv\"` under [alarms], then import again"
        )));
    };
    let p = Path::new(path);
    Ok(if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    })
}

/// The changes from `old` (or, where it has no row, the `draft` the cell
/// gives) to `new`, one line each.
fn changes(old: Option<&Database>, new: &Database, draft: &[MadRow]) -> Vec<String> {
    let time = |ms: Option<u64>| {
        ms.map(|ms| humantime::format_duration(std::time::Duration::from_millis(ms)).to_string())
            .unwrap_or_default()
    };
    let columns = |r: &Rationale, priority: String| {
        [
            ("priority", priority),
            ("class", r.guidance.class.clone()),
            (
                "consequence_of_inaction",
                r.guidance.consequence_of_inaction.clone(),
            ),
            ("corrective_action", r.guidance.corrective_action.clone()),
            ("response_time", time(r.guidance.response_time_ms)),
        ]
    };
    let shown = |t: &str| {
        if t.is_empty() {
            "-".to_string()
        } else {
            format!("'{t}'")
        }
    };
    let mut out = Vec::new();
    for (id, n) in &new.rows {
        let drafted = draft.iter().find(|r| r.id == *id);
        let before: Vec<(&str, String)> = match old.and_then(|o| o.rows.get(id)) {
            Some(o) => {
                let p = o.priority.map(|p| p.as_str().to_string());
                columns(o, p.unwrap_or_default()).to_vec()
            }
            None => match drafted {
                Some(d) => vec![
                    ("priority", d.priority.clone()),
                    ("class", d.class.clone()),
                    ("consequence_of_inaction", String::new()),
                    ("corrective_action", String::new()),
                    ("response_time", String::new()),
                ],
                None => Vec::new(),
            },
        };
        let was = |column: &str| {
            before
                .iter()
                .find(|(c, _)| *c == column)
                .map(|(_, v)| v.clone())
                .unwrap_or_default()
        };
        // An empty priority keeps what was.
        let priority = n
            .priority
            .map_or_else(|| was("priority"), |p| p.as_str().to_string());
        for (column, now) in columns(n, priority) {
            let before = was(column);
            if before != now {
                out.push(format!(
                    "{id}: {column} {} -> {}",
                    shown(&before),
                    shown(&now)
                ));
            }
        }
    }
    if let Some(old) = old {
        for id in old.rows.keys().filter(|id| !new.rows.contains_key(*id)) {
            out.push(format!("{id}: row removed (its rationalisation forgotten)"));
        }
    }
    out
}
