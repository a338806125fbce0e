//! `cellwatch sfc check|patch`: chart files on their own, no cell needed.

use std::io::Write;
use std::path::{Path, PathBuf};

use cellwatch_models::sfc::{patch, Sfc};
use cellwatch_models::signal::Signal;

use super::Failure;

/// Reads and checks the chart file at `path`, TOML or PLCopen XML (any contact accepted: no
/// cell is named here; `cellwatch validate` checks them against a cell's
/// tags).
fn charts(path: &Path) -> Result<Sfc, Failure> {
    let text = super::inputs::read_text(path, "charts")?;
    cellwatch_models::sfc::read(&path.display().to_string(), &text, &|_| true)
        .map_err(|errors| Failure::Input(errors.join("\n")))
}

/// Runs `command`.
pub(crate) fn run(command: &SfcCommand, out: &mut dyn Write) -> Result<(), Failure> {
    let io = Failure::output;
    match command {
        SfcCommand::Check { charts: path } => {
            let sfc = charts(path)?;
            for chart in &sfc.charts {
                let initial = chart
                    .initial
                    .map_or("none (entered by jumps)".to_string(), |i| {
                        chart.steps[i].name.clone()
                    });
                writeln!(out, "chart {} (initial step {initial})", chart.name).map_err(io)?;
                for s in &chart.steps {
                    writeln!(
                        out,
                        "  step {:<6} flag {:<12} supervision {:<8} {}",
                        s.name,
                        s.flag.name(),
                        s.supervision_ms
                            .map_or("-".to_string(), |ms| format!("{:.1} s", ms as f64 / 1000.0)),
                        s.comment.as_deref().unwrap_or("")
                    )
                    .map_err(io)?;
                }
                for t in &chart.transitions {
                    let names = |refs: &[cellwatch_models::sfc::StepRef]| {
                        refs.iter()
                            .map(|&r| sfc.step_name(r))
                            .collect::<Vec<_>>()
                            .join(" + ")
                    };
                    let condition = cellwatch_models::switching::SwitchingFunction::from_expr(
                        Signal::new(&t.id),
                        &t.condition,
                    )
                    .notation();
                    writeln!(
                        out,
                        "  transition {:<5} {} -> {}  when {condition}  {}",
                        t.id,
                        names(&t.from),
                        names(&t.to),
                        t.comment.as_deref().unwrap_or("")
                    )
                    .map_err(io)?;
                }
            }
            Ok(())
        }
        SfcCommand::Patch {
            charts: path,
            force_switch,
            transitions,
        } => {
            let sfc = charts(path)?;
            let force = match cellwatch_models::expr::Expr::parse(force_switch) {
                Ok(cellwatch_models::expr::Expr::Lit(s, false)) => s,
                _ => {
                    return Err(Failure::Input(format!(
                        "--force-switch '{force_switch}': give one address (%IX0.3.1)"
                    )))
                }
            };
            let mut found = Vec::new();
            for name in transitions {
                let Some((chart, id)) = name.split_once('.') else {
                    return Err(Failure::Input(format!(
                        "--transition '{name}': write CHART.ID (F1.t3)"
                    )));
                };
                let Some((c, t)) = sfc.transition(chart, id) else {
                    return Err(Failure::Input(format!(
                        "--transition '{name}': {} has no such transition",
                        path.display()
                    )));
                };
                found.push((c, t));
            }
            for (i, (c, t)) in found.into_iter().enumerate() {
                if i > 0 {
                    writeln!(out).map_err(io)?;
                }
                write!(out, "{}", patch::patch(&sfc, c, t, &force)).map_err(io)?;
            }
            Ok(())
        }
    }
}

#[derive(Debug, clap::Subcommand)]
pub(crate) enum SfcCommand {
    /// Check a chart file (every problem with file, line and column) and
    /// list its charts: steps with flag, supervision and comment, and
    /// transitions with source, target and condition.
    Check {
        /// The chart file (TOML).
        charts: PathBuf,
    },
    /// For each transition named, the term paper 004's eq. (3)/(4) adds so
    /// that the force switch can fire it while its condition holds —
    /// `(S14 · t15) + (ForceSW · t15)` — as IEC 61131-3 ST and IL, for the
    /// engineer to add to the PLC program.
    Patch {
        /// The chart file (TOML).
        charts: PathBuf,
        /// The force switch's address in the PLC (`%IX0.3.1`).
        #[arg(long, value_name = "ADDRESS")]
        force_switch: String,
        /// A transition to make forcible, `CHART.ID` (`F1.t3`); repeat for
        /// several.
        #[arg(long = "transition", value_name = "CHART.ID", required = true)]
        transitions: Vec<String>,
    },
}
