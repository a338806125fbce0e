//! `cellwatch explain`: the fault step and culprits of one coil at a
//! snapshot of signal values.

use std::io::Write;

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
    let (program, comments, observable) = inputs::load(&args.program, err)?;
    let coil = program
        .resolve(&args.coil)
        .map_err(|m| Failure::Input(format!("--coil: {m}")))?;
    let sf = SwitchingFunction::expand(&program, &coil, &observable).map_err(Failure::input)?;
    let now = inputs::values("--snapshot", &args.snapshot, &program)?;
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
    if args.program.json {
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
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// The fault coil to explain.
    #[arg(long, value_name = "NAME")]
    pub(crate) coil: String,
    /// Signal values at the fault: inline `X0.06=0,X0.07=1`, or a file with
    /// one `ADDRESS=VALUE` (or CSV `ADDRESS,VALUE`) a line. Values: 0/1,
    /// true/false, on/off.
    #[arg(long, value_name = "VALUES")]
    pub(crate) snapshot: String,
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
