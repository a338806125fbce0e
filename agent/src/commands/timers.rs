//! `cellwatch learn` and `cellwatch replay`: transition timers from run logs.

use std::io::Write;
use std::path::{Path, PathBuf};

use cellwatch_models::timer::learn::{self, LearnOptions, Tau, TimerModel};
use cellwatch_models::timer::log::{self, RunLog};
use cellwatch_models::timer::monitor::{self, Outcome};

use super::inputs::read_text;
use super::Failure;

fn runs(paths: &[std::path::PathBuf], map: Option<&Path>) -> Result<Vec<RunLog>, Failure> {
    let map_text = map.map(|m| read_text(m, "signal map")).transpose()?;
    let mut out = Vec::new();
    for p in paths {
        let text = read_text(p, "run log")?;
        let name = p.display().to_string();
        let run = match (&map_text, map) {
            (Some(m), Some(mp)) => log::parse_numeric(&mp.display().to_string(), m, &name, &text),
            _ => log::parse_csv(&name, &text),
        };
        out.push(run.map_err(|e| Failure::Input(e.to_string()))?);
    }
    if out.is_empty() {
        return Err(Failure::Input("give at least one run log".into()));
    }
    Ok(out)
}

/// The duration `text` given to `option`, in ms.
pub(crate) fn millis(option: &str, text: &str) -> Result<u64, Failure> {
    humantime::parse_duration(text)
        .map(|d| d.as_millis() as u64)
        .map_err(|e| {
            Failure::Input(format!(
                "{option} '{text}': not a duration ({e}); write e.g. 2s or 100ms"
            ))
        })
}

/// `cellwatch learn`.
pub(crate) fn learn(args: &LearnArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let runs = runs(&args.runs, args.map.as_deref())?;
    if let Some(charts) = &args.sfc {
        return learn_steps(args, charts, &runs, out);
    }
    let tau = match (&args.tau, args.tau_auto) {
        (_, true) => Tau::Auto,
        (Some(t), false) => Tau::Fixed(millis("--tau", t)?),
        (None, false) => Tau::Fixed(100),
    };
    let options = LearnOptions {
        delta_min: millis("--delta-min", &args.delta_min)?,
        tau,
        min_support: args.min_support,
    };
    let learned = match args.method.as_str() {
        "common" => learn::common(&runs, &options),
        "full-state" => learn::full_state(&runs, &options),
        other => {
            return Err(Failure::Input(format!(
                "--method '{other}': use common or full-state"
            )))
        }
    };
    let io = Failure::output;
    writeln!(
        out,
        "{} runs, {} signals; kept {} transitions:",
        runs.len(),
        learned.model.signals.len(),
        learned.model.transitions.len()
    )
    .map_err(io)?;
    for t in &learned.model.transitions {
        let edge = if t.event.edge == learn::SignalEdge::Rise {
            "+"
        } else {
            "-"
        };
        writeln!(
            out,
            "  #{:03} δ({}{}, {edge}{} | {}) window [{}, {}] ms, support {}",
            t.id,
            t.trigger.as_ref().map_or(String::new(), |e| format!(
                "after {}{} ",
                if e.edge == learn::SignalEdge::Rise {
                    "+"
                } else {
                    "-"
                },
                e.tag
            )),
            t.from.join(":"),
            t.event.tag,
            t.delta_ms,
            t.window_ms[0],
            t.window_ms[1],
            t.support
        )
        .map_err(io)?;
    }
    if !learned.dropped.is_empty() {
        writeln!(out, "dropped {}:", learned.dropped.len()).map_err(io)?;
        for d in &learned.dropped {
            writeln!(out, "  {}: {}", d.transition, d.reason).map_err(io)?;
        }
    }
    if args.table {
        table(out, &learned.model).map_err(io)?;
    }
    save(
        &learned.model,
        args.out.as_deref().unwrap_or(Path::new("timers.json")),
        out,
    )
}

/// Writes `model` as JSON to `path` and says so.
fn save(model: &impl serde::Serialize, path: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let json = serde_json::to_string_pretty(model).map_err(|e| Failure::Runtime(e.to_string()))?;
    std::fs::write(path, json + "\n")
        .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", path.display())))?;
    writeln!(out, "model written to {}", path.display()).map_err(Failure::output)
}

/// `cellwatch learn --sfc`: step supervision times.
fn learn_steps(
    args: &LearnArgs,
    charts: &Path,
    runs: &[RunLog],
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let text = read_text(charts, "charts")?;
    // Contacts are checked against the cell's tags in its configuration;
    // here only the charts' shape matters.
    let sfc = cellwatch_models::sfc::read(&charts.display().to_string(), &text, &|_| true)
        .map_err(|e| Failure::Input(e.join("\n")))?;
    let learned = cellwatch_models::sfc::learn::learn(&sfc, runs, args.min_support);
    let io = Failure::output;
    writeln!(
        out,
        "{} runs; learned {} of {} steps:",
        runs.len(),
        learned.model.steps.len(),
        sfc.steps().count()
    )
    .map_err(io)?;
    for s in &learned.model.steps {
        writeln!(
            out,
            "  {} supervision {} ms (durations {}..{} ms, mean {} ms, {} activations in {} runs)",
            s.step, s.supervision_ms, s.min_ms, s.max_ms, s.mean_ms, s.count, s.support
        )
        .map_err(io)?;
    }
    if !learned.not_learned.is_empty() {
        writeln!(out, "not learned {}:", learned.not_learned.len()).map_err(io)?;
        for n in &learned.not_learned {
            writeln!(out, "  {}: {}", n.step, n.reason).map_err(io)?;
        }
    }
    save(
        &learned.model,
        args.out.as_deref().unwrap_or(Path::new("steps.json")),
        out,
    )
}

fn model(path: &Path) -> Result<TimerModel, Failure> {
    let text = read_text(path, "timer model")?;
    serde_json::from_str(&text).map_err(|e| Failure::Input(format!("{}: {e}", path.display())))
}

/// `cellwatch export-st`.
pub(crate) fn export_st(args: &ExportStArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let model = model(&args.timers)?;
    let valid = args
        .name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_')
        && args.name.starts_with(|c: char| c.is_ascii_alphabetic());
    if !valid {
        return Err(Failure::Input(format!(
            "--name '{}' is not an IEC 61131-3 identifier",
            args.name
        )));
    }
    let st =
        cellwatch_models::timer::st::export(&model, &args.name, &args.timers.display().to_string());
    match &args.out {
        Some(path) => std::fs::write(path, st)
            .map_err(|e| Failure::Runtime(format!("cannot write {}: {e}", path.display()))),
        None => out
            .write_all(st.as_bytes())
            .map_err(|e| Failure::Runtime(e.to_string())),
    }
}

/// `cellwatch replay`.
pub(crate) fn replay(args: &ReplayArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let model = model(&args.timers)?;
    let io = Failure::output;
    for (path, run) in args.runs.iter().zip(runs(&args.runs, args.map.as_deref())?) {
        let outcomes = monitor::replay(&model, &run)
            .map_err(|e| Failure::Input(format!("{}: {e}", args.timers.display())))?;
        for o in outcomes {
            if args.json {
                writeln!(out, "{}", serde_json::to_string(&o).unwrap_or_default()).map_err(io)?;
            } else {
                let line = match o {
                    Outcome::Early {
                        transition,
                        at_ms,
                        observed_ms,
                    } => format!("#{transition:03} early at {at_ms} ms (after {observed_ms} ms)"),
                    Outcome::Late { transition, at_ms } => {
                        format!("#{transition:03} LATE at {at_ms} ms")
                    }
                    Outcome::Normal {
                        transition,
                        at_ms,
                        observed_ms,
                    } => format!("#{transition:03} normal at {at_ms} ms (after {observed_ms} ms)"),
                };
                writeln!(out, "{}: {line}", path.display()).map_err(io)?;
            }
        }
    }
    Ok(())
}

/// The paper's Fig. 12: one row per transition, one column per signal in
/// some start condition or event.
fn table(out: &mut dyn Write, model: &TimerModel) -> std::io::Result<()> {
    let used: Vec<&String> = model
        .signals
        .iter()
        .filter(|s| {
            model.transitions.iter().any(|t| {
                t.event.tag == **s
                    || t.from
                        .iter()
                        .any(|l| l.trim_start_matches('-') == s.as_str())
            })
        })
        .collect();
    writeln!(
        out,
        "transitions × signals (1/0: start condition, E: event, .: not read):"
    )?;
    let width = used.iter().map(|s| s.len()).max().unwrap_or(1);
    for row in 0..width {
        let header: String = used
            .iter()
            .map(|s| s.chars().nth(row).unwrap_or(' '))
            .collect();
        writeln!(out, "       {header}")?;
    }
    for t in &model.transitions {
        let cells: String = used
            .iter()
            .map(|s| {
                if t.event.tag == **s {
                    'E'
                } else if t.from.iter().any(|l| l == *s) {
                    '1'
                } else if t
                    .from
                    .iter()
                    .any(|l| l.strip_prefix('-') == Some(s.as_str()))
                {
                    '0'
                } else {
                    '.'
                }
            })
            .collect();
        writeln!(out, "  #{:03} {cells}", t.id)?;
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
pub(crate) struct LearnArgs {
    /// Run logs: CSV `time_ms,tag,value`, or the paper's `t,e` form with --map.
    #[arg(required = true)]
    pub(crate) runs: Vec<PathBuf>,
    /// Signal map `number,tag` for logs in the paper's numeric form.
    #[arg(long, value_name = "CSV")]
    pub(crate) map: Option<PathBuf>,
    /// Shortest Δt kept (shorter transitions are the program flipping its own signals).
    #[arg(long, default_value = "2s")]
    pub(crate) delta_min: String,
    /// Fixed tolerance τ (default 100ms).
    #[arg(long, conflicts_with = "tau_auto")]
    pub(crate) tau: Option<String>,
    /// τ per transition: max(2 × largest training deviation, 5 % of Δt, 100 ms).
    #[arg(long)]
    pub(crate) tau_auto: bool,
    /// Runs a transition must be seen in (default: every run).
    #[arg(long)]
    pub(crate) min_support: Option<usize>,
    /// Learning method: `common` (each event timed from its most consistent
    /// trigger; copes with stations running in parallel) or `full-state`
    /// (the paper's: timed from entering the full state).
    #[arg(long, default_value = "common")]
    pub(crate) method: String,
    /// Learn step supervision times for these charts (`.sfc.toml`) instead
    /// of transition timers: each step's longest duration in the runs plus
    /// max(half of it, twice the spread, 1 s). The file goes to a
    /// `[[checks.sfc]]` `steps` key; a supervision declared in the charts wins.
    #[arg(
        long,
        value_name = "CHARTS",
        conflicts_with_all = ["tau", "tau_auto", "table", "method", "delta_min"]
    )]
    pub(crate) sfc: Option<PathBuf>,
    /// Where to write the model (JSON; default timers.json, with --sfc
    /// steps.json).
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    /// Also print the paper's Fig. 12 view: transitions × signals (1, 0, or
    /// . when the signal is not in the start condition; E marks the event).
    #[arg(long)]
    pub(crate) table: bool,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ExportStArgs {
    /// The timer model (JSON, from `cellwatch learn`).
    #[arg(long)]
    pub(crate) timers: PathBuf,
    /// Name of the function block.
    #[arg(long, default_value = "FB_CELLWATCH_TIMERS")]
    pub(crate) name: String,
    /// Write to this file instead of standard output.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub(crate) struct ReplayArgs {
    /// The timer model (JSON, from `cellwatch learn`).
    #[arg(long)]
    pub(crate) timers: PathBuf,
    /// Run logs to replay.
    #[arg(required = true)]
    pub(crate) runs: Vec<PathBuf>,
    /// Signal map for logs in the paper's numeric form.
    #[arg(long, value_name = "CSV")]
    pub(crate) map: Option<PathBuf>,
    /// One JSON outcome per line: {outcome, transition, at_ms, observed_ms}.
    #[arg(long)]
    pub(crate) json: bool,
}
