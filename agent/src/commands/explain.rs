//! `cellwatch explain`: the fault step and culprits of one coil at a
//! snapshot of signal values; with `--consequences`, which alarms of a
//! cell follow from which; with `--alarm`, an alarm's flight recording.

use std::io::Write;
use std::path::{Path, PathBuf};

use cellwatch_models::engine::Sample;
use cellwatch_models::explain::{explain, Culprit, Explanation, Polarity, UnknownPolarity};
use cellwatch_models::signal::Signal;
use cellwatch_models::switching::SwitchingFunction;
use serde::Serialize;

use super::inputs::{self, ProgramArgs};
use super::Failure;
use crate::payload::RecordingPayload;

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
    if let Some(alarm) = &args.alarm {
        return recording(args, alarm, out);
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

/// `--alarm ID`: the alarm's flight recording from the journal, as a
/// timing chart (`--timeline`), a list of changes, or its payload.
fn recording(args: &ExplainArgs, alarm: &str, out: &mut dyn Write) -> Result<(), Failure> {
    let Some(path) = &args.journal else {
        return Err(Failure::Input(
            "--alarm needs --journal FILE: the cell's journal (journal.path)".into(),
        ));
    };
    if !path.exists() {
        return Err(Failure::Input(format!(
            "--journal {}: no such file",
            path.display()
        )));
    }
    let now = crate::clock::now_ms();
    let at = args
        .at
        .as_deref()
        .map(|t| crate::clock::parse_time(t, now))
        .transpose()
        .map_err(|e| Failure::Input(format!("--at: {e}")))?;
    let conn = crate::journal::open_read(path).map_err(Failure::runtime)?;
    let found = crate::journal::recording(&conn, alarm, at).map_err(Failure::runtime)?;
    let Some(json) = found else {
        return Err(Failure::Input(format!(
            "{}: no recording of alarm '{alarm}'{} (recordings are kept for alarms raised while [recorder] is on)",
            path.display(),
            at.map(|t| format!(" raised at or before {}", crate::clock::rfc3339(t)))
                .unwrap_or_default()
        )));
    };
    let io = Failure::output;
    if args.program.json {
        return writeln!(out, "{json}").map_err(io);
    }
    let p: RecordingPayload = serde_json::from_str(&json).map_err(|e| {
        Failure::Runtime(format!(
            "{}: a recording that does not read: {e}",
            path.display()
        ))
    })?;
    let r = &p.recording;
    writeln!(
        out,
        "{}/{} raised {}, recorded {} to {}",
        p.cell,
        r.alarm,
        crate::clock::rfc3339(r.raised_at),
        offset(r.from as i64 - r.raised_at as i64),
        offset(r.to as i64 - r.raised_at as i64),
    )
    .map_err(io)?;
    if args.timeline {
        return out.write_all(r.timeline(args.width).as_bytes()).map_err(io);
    }
    let mut changes: Vec<(u64, &str, Option<&Sample>)> = Vec::new();
    for s in &r.signals {
        let name = s.name.as_deref().unwrap_or("");
        let start = s
            .start
            .as_ref()
            .map_or("?".to_string(), ToString::to_string);
        writeln!(out, "  {} {name}: {start} at the start", s.address).map_err(io)?;
        changes.extend(
            s.changes
                .iter()
                .map(|(t, v)| (*t, s.address.as_str(), v.as_ref())),
        );
    }
    changes.sort_by_key(|c| c.0);
    for (t, address, v) in changes {
        let v = v.map_or("unknown".to_string(), ToString::to_string);
        writeln!(
            out,
            "  {:>9}  {address} = {v}",
            offset(t as i64 - r.raised_at as i64)
        )
        .map_err(io)?;
    }
    Ok(())
}

/// `ms` from the raise, for people: `-2.350 s`, `+0.100 s`.
fn offset(ms: i64) -> String {
    format!(
        "{}{:.3} s",
        if ms < 0 { "-" } else { "+" },
        ms.unsigned_abs() as f64 / 1000.0
    )
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
    #[arg(value_name = "PROGRAM", required_unless_present_any = ["consequences", "alarm"])]
    pub(crate) file: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// The fault coil to explain.
    #[arg(long, value_name = "NAME", required_unless_present_any = ["consequences", "alarm"])]
    pub(crate) coil: Option<String>,
    /// Signal values at the fault: inline `X0.06=0,X0.07=1`, or a file with
    /// one `ADDRESS=VALUE` (or CSV `ADDRESS,VALUE`) a line. Values: 0/1,
    /// true/false, on/off.
    #[arg(long, value_name = "VALUES", required_unless_present_any = ["consequences", "alarm"])]
    pub(crate) snapshot: Option<String>,
    /// Instead of one fault: print which alarms of the cell configured in
    /// CONFIG follow from which, as derived from its programs and checks
    /// (an alarm whose check reads a signal another's fault holds: its
    /// fault coil, an output the program derives from it, a contact, the
    /// operand a stuck step waits for), with `[alarms.consequences]`'s
    /// edges added and removed, for review.
    #[arg(long, value_name = "CONFIG", conflicts_with_all = ["file", "coil", "snapshot", "before", "alarm"])]
    pub(crate) consequences: Option<PathBuf>,
    /// Instead of one fault: alarm ID's flight recording from the journal
    /// (--journal): every signal its check reads from `recorder.before`
    /// before its raise to `recorder.after` after it, as a list of
    /// changes, or with --timeline as a timing chart. The newest
    /// occurrence's, or the last raised at or before --at.
    #[arg(long, value_name = "ID", conflicts_with_all = ["file", "coil", "snapshot", "before"])]
    pub(crate) alarm: Option<String>,
    /// The cell's journal (`journal.path`), for --alarm.
    #[arg(long, value_name = "FILE", requires = "alarm")]
    pub(crate) journal: Option<PathBuf>,
    /// With --alarm: the occurrence raised last at or before this time
    /// (RFC 3339, or a duration back from now: `2h`).
    #[arg(long, value_name = "TIME", requires = "alarm")]
    pub(crate) at: Option<String>,
    /// With --alarm: draw the recording as a timing chart, one row per
    /// signal (▔ 1, ▁ 0, ╱ rise, ╲ fall, numbers at their changes, ░
    /// unknown), the raise marked ▼.
    #[arg(long, requires = "alarm")]
    pub(crate) timeline: bool,
    /// The timing chart's width in columns.
    #[arg(long, value_name = "N", default_value_t = 80, requires = "timeline")]
    pub(crate) width: usize,
    /// Signal values just before the fault, same forms; contacts that changed
    /// are marked as the trigger.
    #[arg(long, value_name = "VALUES")]
    pub(crate) before: Option<String>,
    /// Which coil value is the fault: `on` (an alarm coil) or `off` (an enable coil).
    #[arg(long, value_name = "on|off", default_value = "on", value_parser = parse_polarity)]
    pub(crate) fault_when: Polarity,
}

fn parse_polarity(s: &str) -> Result<Polarity, UnknownPolarity> {
    s.parse()
}
