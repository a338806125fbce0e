//! `cellwatch sf`: the switching function and step blocks of coils.

use std::io::Write;

use cellwatch_models::comments::CommentDb;
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::{SfError, SwitchingFunction};
use serde::Serialize;

use super::inputs::{self, ProgramArgs};
use super::Failure;

/// One coil in `--json` output.
#[derive(Serialize)]
struct CoilJson {
    coil: Signal,
    /// The SF in observable signals, paper notation.
    #[serde(skip_serializing_if = "Option::is_none")]
    sf: Option<String>,
    /// The same in words.
    #[serde(skip_serializing_if = "Option::is_none")]
    readable: Option<String>,
    /// The coil's logic as written, relays not expanded.
    #[serde(skip_serializing_if = "Option::is_none")]
    expression: Option<String>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    steps: Vec<StepJson>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    contacts: Vec<ContactJson>,
    /// Why the coil has no SF.
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

#[derive(Serialize)]
struct StepJson {
    index: usize,
    expr: String,
}

#[derive(Serialize)]
struct ContactJson {
    address: Signal,
    comment: Option<String>,
}

pub(crate) fn run(args: &SfArgs, out: &mut dyn Write, err: &mut dyn Write) -> Result<(), Failure> {
    let (program, comments, observable) = inputs::load(&args.file, &args.program, err)?;
    let coils: Vec<Signal> = if args.coil.is_empty() {
        program.coils().iter().map(|c| c.signal.clone()).collect()
    } else {
        let mut coils = Vec::new();
        for name in &args.coil {
            let coil = program
                .resolve(name)
                .map_err(|m| Failure::Input(format!("--coil: {m}")))?;
            if program.coil(&coil).is_none() {
                // Reported with the program's list of coils.
                SwitchingFunction::expand(&program, &coil, &observable).map_err(Failure::input)?;
            }
            coils.push(coil);
        }
        coils
    };
    if coils.is_empty() && !args.program.json {
        writeln!(
            out,
            "{}: no coil is written by boolean logic (see the warnings for what was not read)",
            program.origin()
        )
        .map_err(Failure::output)?;
    }
    let everything = Observability::everything(program.dialect());
    let mut json = Vec::new();
    for coil in &coils {
        let sf = SwitchingFunction::expand(&program, coil, &observable);
        if !args.coil.is_empty() {
            // A coil asked for by name must have an SF.
            if let Err(e @ SfError::NotDerivable { .. }) = &sf {
                return Err(Failure::Input(e.to_string()));
            }
        }
        let written = SwitchingFunction::expand(&program, coil, &everything).ok();
        if args.program.json {
            json.push(coil_json(coil, sf, written, &comments));
        } else {
            print_coil(out, &program, coil, sf, written, &comments).map_err(Failure::output)?;
        }
    }
    if args.program.json {
        serde_json::to_writer_pretty(&mut *out, &json)
            .map_err(|e| Failure::Runtime(format!("cannot write output: {e}")))?;
        writeln!(out).map_err(Failure::output)?;
    }
    Ok(())
}

fn coil_json(
    coil: &Signal,
    sf: Result<SwitchingFunction, SfError>,
    written: Option<SwitchingFunction>,
    comments: &CommentDb,
) -> CoilJson {
    match sf {
        Ok(sf) => CoilJson {
            coil: coil.clone(),
            sf: Some(sf.notation()),
            readable: Some(sf.readable()),
            expression: written.map(|w| w.notation()),
            steps: (1..=sf.steps.len())
                .map(|i| StepJson {
                    index: i,
                    expr: sf.step_notation(i),
                })
                .collect(),
            contacts: sf
                .leaves()
                .into_iter()
                .map(|s| ContactJson {
                    comment: comments.get(&s).map(str::to_string),
                    address: s,
                })
                .collect(),
            error: None,
        },
        Err(e) => CoilJson {
            coil: coil.clone(),
            sf: None,
            readable: None,
            expression: None,
            steps: Vec::new(),
            contacts: Vec::new(),
            error: Some(e.to_string()),
        },
    }
}

fn print_coil(
    out: &mut dyn Write,
    program: &Program,
    coil: &Signal,
    sf: Result<SwitchingFunction, SfError>,
    written: Option<SwitchingFunction>,
    comments: &CommentDb,
) -> std::io::Result<()> {
    let sf = match sf {
        Ok(sf) => sf,
        Err(e) => return writeln!(out, "{coil}: not derivable\n  {e}\n"),
    };
    let leaves = sf.leaves();
    writeln!(
        out,
        "{coil}  ({}, {} step block{}, {} contact{})",
        program.origin(),
        sf.steps.len(),
        if sf.steps.len() == 1 { "" } else { "s" },
        leaves.len(),
        if leaves.len() == 1 { "" } else { "s" }
    )?;
    if let Some(w) = written.filter(|w| *w != sf) {
        writeln!(out, "  as written: {coil} = {}", w.notation())?;
    }
    writeln!(out, "  SF:         {coil} = {}", sf.notation())?;
    writeln!(out, "  in words:   {}", sf.readable())?;
    for i in 1..=sf.steps.len() {
        let last = if i == sf.steps.len()
            && matches!(
                sf.root,
                cellwatch_models::logic::Term::Block { negated: false, .. }
            ) {
            format!(" = {coil}")
        } else {
            String::new()
        };
        writeln!(out, "  SSF{i:<3} = {}{last}", sf.step_notation(i))?;
    }
    let width = leaves.iter().map(|s| s.name().len()).max().unwrap_or(0);
    writeln!(out, "  contacts:")?;
    for s in &leaves {
        match comments.get(s) {
            Some(c) => writeln!(out, "    {:<width$}  {c}", s.name())?,
            None => writeln!(out, "    {}", s.name())?,
        }
    }
    writeln!(out)
}

#[derive(Debug, clap::Args)]
pub(crate) struct SfArgs {
    /// The PLC program: an instruction list (FANUC PMC, IEC IL, Siemens
    /// STL), PLCopen XML, a Studio 5000 export (.L5X) or a TIA Portal
    /// block export (SimaticML); the format is told by its content.
    #[arg(value_name = "PROGRAM")]
    pub(crate) file: std::path::PathBuf,
    #[command(flatten)]
    pub(crate) program: ProgramArgs,
    /// A coil to print; repeat for several. Default: every coil the program writes.
    #[arg(long, value_name = "NAME")]
    pub(crate) coil: Vec<String>,
}
