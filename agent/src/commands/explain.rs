//! `cellwatch explain`: the fault step and culprits of one coil at a
//! snapshot of signal values; with `--consequences`, which alarms of a
//! cell follow from which.

use std::io::Write;
use std::path::{Path, PathBuf};

use cellwatch_models::explain::{explain, Culprit, Explanation, Polarity};
use cellwatch_models::signal::Signal;
use cellwatch_models::switching::SwitchingFunction;
use serde::Serialize;

use super::inputs::{self, ProgramArgs};
use super::Failure;

/// `--json` output.
#[derive(Serialize)]
struct ExplanationJson<'a> {
    coil: &'a Signal,
    value: bool,
    fault: bool,
    fault_when: Polarity,
    fault_step: Option<usize>,
    steps: Vec<StepJson>,
    culprits: &'a [Culprit],
}

#[derive(Serialize)]
struct StepJson {
    index: usize,
    value: bool,
    expr: String,
}

pub(crate) fn run(
    args: &ExplainArgs,
    out: &mut dyn Write,
    err: &mut dyn Write,
) -> Result<(), Failure> {
    if let Some(config) = &args.consequences {
        return consequences(config, out);
    }
    let (Some(file), Some(coil), Some(snapshot)) = (&args.file, &args.coil, &args.snapshot) else {
        return Err(Failure::Input(
            "give the PROGRAM, --coil and --snapshot (or --consequences CONFIG)".into(),
        ));
    };
    let program_args = &args.program;
    let (program, comments, observable) = inputs::load(file, program_args, err)?;
    let coil = program
        .resolve(coil)
        .map_err(|m| Failure::Input(format!("--coil: {m}")))?;
    let sf = SwitchingFunction::expand(&program, &coil, &observable).map_err(Failure::input)?;
    let now = inputs::values("--snapshot", snapshot, &program)?;
    let before = args
        .before
        .as_deref()
        .map(|b| inputs::values("--before", b, &program))
        .transpose()?;
    let before_fn = before.as_ref().map(|b| move |s: &Signal| b.get(s));
    let before_ref: Option<cellwatch_models::explain::Lookup<'_>> =
        before_fn.as_ref().map(|f| f as _);
    let e = explain(&sf, |s| now.get(s), before_ref, args.fault_when, &comments)
        .map_err(|e| Failure::Input(format!("--snapshot: {e}")))?;
    let io = Failure::output;
    if program_args.json {
        let json = ExplanationJson {
            coil: &e.coil,
            value: e.value,
            fault: e.is_fault(),
            fault_when: e.polarity,
            fault_step: e.fault_step,
            steps: e
                .steps
                .iter()
                .enumerate()
                .map(|(i, v)| StepJson {
                    index: i + 1,
                    value: *v,
                    expr: sf.step_notation(i + 1),
                })
                .collect(),
            culprits: &e.culprits,
        };
        serde_json::to_writer_pretty(&mut *out, &json)
            .map_err(|e| Failure::Runtime(e.to_string()))?;
        writeln!(out).map_err(io)?;
    } else {
        print(out, &sf, &e).map_err(io)?;
    }
    Ok(())
}

/// `--consequences CONFIG`: the relation the cell's checks give, with the
/// configuration's edges added and removed, as the agent runs it.
fn consequences(config: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let c = crate::config::load(config).map_err(Failure::input)?;
    let engine = crate::cell::compile::engine(&c)
        .map_err(|e| Failure::Input(format!("{}: {e}", config.display())))?;
    let io = Failure::output;
    writeln!(
        out,
        "cell {}: consequences {} (alarms.consequences.suppress = {})",
        c.cell,
        if c.consequences.suppress {
            "suppressed: journaled and shown, not annunciated"
        } else {
            "annunciated, each marked with its cause"
        },
        c.consequences.suppress
    )
    .map_err(io)?;
    out.write_all(engine.relation().render().as_bytes())
        .map_err(io)
}

fn print(out: &mut dyn Write, sf: &SwitchingFunction, e: &Explanation) -> std::io::Result<()> {
    let verdict = if e.is_fault() { "FAULT" } else { "no fault" };
    write!(
        out,
        "{} = {}: {verdict} (fault when {})",
        e.coil,
        u8::from(e.value),
        e.polarity
    )?;
    match e.fault_step {
        Some(step) => writeln!(out, ", at step {step}")?,
        None => writeln!(out)?,
    }
    for (i, v) in e.steps.iter().enumerate() {
        let mark = if e.fault_step == Some(i + 1) {
            "  <- fault step"
        } else {
            ""
        };
        writeln!(
            out,
            "  SSF{:<3} = {}   {}{mark}",
            i + 1,
            u8::from(*v),
            sf.step_notation(i + 1)
        )?;
    }
    if e.is_fault() {
        writeln!(out, "culprits:")?;
        for c in &e.culprits {
            let trigger = if c.trigger { "   [trigger]" } else { "" };
            writeln!(out, "  {c}{trigger}")?;
        }
    }
    Ok(())
}

#[derive(Debug, clap::Args)]
pub(crate) struct ExplainArgs {
    /// The PLC program: an instruction list (FANUC PMC, IEC IL, Siemens
    /// STL), PLCopen XML, a Studio 5000 export (.L5X) or a TIA Portal
    /// block export (SimaticML); the format is told by its content.
    #[arg(value_name = "PROGRAM", required_unless_present = "consequences")]
    pub(crate) file: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// The fault coil to explain.
    #[arg(long, value_name = "NAME", required_unless_present = "consequences")]
    pub(crate) coil: Option<String>,
    /// Signal values at the fault: inline `X0.06=0,X0.07=1`, or a file with
    /// one `ADDRESS=VALUE` (or CSV `ADDRESS,VALUE`) a line. Values: 0/1,
    /// true/false, on/off.
    #[arg(long, value_name = "VALUES", required_unless_present = "consequences")]
    pub(crate) snapshot: Option<String>,
    /// Instead of one fault: print which alarms of the cell configured in
    /// CONFIG follow from which, as derived from its programs and checks
    /// (an alarm whose check reads a signal another's fault holds: its
    /// fault coil, an output the program derives from it, a contact, the
    /// operand a stuck step waits for), with `[alarms.consequences]`'s
    /// edges added and removed, for review.
    #[arg(long, value_name = "CONFIG", conflicts_with_all = ["file", "coil", "snapshot", "before"])]
    pub(crate) consequences: Option<PathBuf>,
    /// Signal values just before the fault, same forms; contacts that changed
    /// are marked as the trigger.
    #[arg(long, value_name = "VALUES")]
    pub(crate) before: Option<String>,
    /// Which coil value is the fault: `on` (an alarm coil) or `off` (an enable coil).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_polarity)]
    pub(crate) fault_when: Polarity,
}

fn parse_polarity(s: &str) -> Result<Polarity, String> {
    s.parse()
}
