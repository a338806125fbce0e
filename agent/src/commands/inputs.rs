//! Reading the user's files: programs, comment databases and snapshots.
//!
//! Thin wrappers over the models' parsers: read the bytes, decode them
//! (UTF-8, UTF-16, Latin-1), and hand the text over with the file's name, so every error comes
//! back as `FILE:LINE:COL: message`.

use std::path::{Path, PathBuf};

use cellwatch_models::comments::CommentDb;
use cellwatch_models::program::Program;
use cellwatch_models::programs::{Dialect, UnknownDialect};
use cellwatch_models::signal::Observability;
use cellwatch_models::source;
use cellwatch_models::values::Values;

use super::Failure;

/// Reads a text file, its encoding told by a byte-order mark or by its
/// bytes (see [`source::text`]); `what` names it in errors ("program").
pub(crate) fn read_text(path: &Path, what: &str) -> Result<String, Failure> {
    read_encoded(path, what, None)
}

/// Reads a text file in `encoding` (a byte-order mark still wins), or as
/// [`read_text`] does when `None`.
pub(crate) fn read_encoded(
    path: &Path,
    what: &str,
    encoding: Option<&'static source::Encoding>,
) -> Result<String, Failure> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path)
        .map_err(|e| Failure::Input(format!("cannot read {what} '{name}': {e}")))?;
    Ok(source::text(&name, &bytes, encoding)
        .map_err(Failure::input)?
        .into_owned())
}

/// The compiled program, its comment database and observability, with
/// compiler warnings written to `err`.
pub(crate) fn load(
    file: &std::path::Path,
    args: &ProgramArgs,
    err: &mut dyn std::io::Write,
) -> Result<(Program, CommentDb, Observability), Failure> {
    let name = file.display().to_string();
    let text = read_encoded(file, "program", args.encoding)?;
    let language = args.language.as_deref();
    let program =
        Program::compile_in(&name, &text, args.dialect, language).map_err(Failure::input)?;
    for w in program.warnings() {
        let _ = writeln!(err, "{name}:{}: warning: {}", w.at, w.message);
    }
    // The program's declarations comment its signals, then the TIA Portal
    // tag tables exported beside it; a CSV (or a tag table) given with
    // --comments adds to them and wins where both say something.
    let mut declared = program.documentation().clone();
    let given = args.comments.as_ref().and_then(|c| c.canonicalize().ok());
    for (table, text) in crate::config::tag_tables_beside(&crate::config::Disk, file, &text) {
        if table.canonicalize().ok() == given {
            continue;
        }
        let _ = writeln!(
            err,
            "{}:1:1: note: the program's comments are read from this tag table, exported beside it",
            table.display()
        );
        let db = CommentDb::parse_in(
            &table.display().to_string(),
            &text,
            |a| program.resolve(a),
            language,
        )
        .map_err(Failure::input)?;
        declared = declared.overridden_by(db);
    }
    let comments = match &args.comments {
        Some(path) => {
            let text = read_text(path, "comment database")?;
            let csv = CommentDb::parse_in(
                &path.display().to_string(),
                &text,
                |a| program.resolve(a),
                language,
            )
            .map_err(Failure::input)?;
            declared.overridden_by(csv)
        }
        None => declared,
    };
    let observable = match &args.observable {
        Some(list) => Observability::parse(program.dialect(), list)
            .map_err(|m| Failure::Input(format!("--observable: {m}")))?,
        None => Observability::default_for(program.dialect()),
    };
    Ok((program, comments, observable))
}

/// Signal values from `--snapshot`/`--before`: a file if one exists at that
/// path, otherwise inline `A=1,B=0` pairs.
pub(crate) fn values(option: &str, arg: &str, program: &Program) -> Result<Values, Failure> {
    let path = Path::new(arg);
    if path.is_file() {
        let text = read_text(path, "snapshot")?;
        return Values::parse_file(arg, &text, |a| program.resolve(a)).map_err(Failure::input);
    }
    if !arg.contains('=') {
        return Err(Failure::Input(format!(
            "{option} '{arg}': no such file, and not inline ADDRESS=VALUE pairs"
        )));
    }
    Values::parse_inline(option, arg, |a| program.resolve(a)).map_err(Failure::input)
}

/// How to read the program (the file itself is each command's positional
/// PROGRAM: an instruction list (FANUC PMC, IEC IL, Siemens STL), PLCopen
/// XML, a Studio 5000 export (.L5X) or a TIA Portal block export
/// (SimaticML), the format told by its content).
#[derive(Debug, clap::Args)]
pub(crate) struct ProgramArgs {
    /// The instruction-list dialect: `pmc` (RD, AND.NOT, WRT; X0.07),
    /// `iec` (LD, ANDN, ST; %IX0.0.3) or `stl` (Siemens STL/AWL: U, UN, =;
    /// E 0.0, or A, AN; I 0.0). Detected from the mnemonics if not given.
    #[arg(long, value_name = "pmc|iec|stl", value_parser = parse_dialect)]
    pub(crate) dialect: Option<Dialect>,
    /// Signals the SF may stop at, comma-separated: classes (`X,Y,F,G`;
    /// `%I,%Q`; `E,A`) or single signals (`R1024.00`). Default: X, Y, F, G
    /// for pmc; %I, %Q for iec; E, A, I, Q for stl.
    #[arg(long, value_name = "LIST")]
    pub(crate) observable: Option<String>,
    /// The I/O database: CSV `address,comment`, one row per address, or
    /// a TIA Portal tag table (SimaticML). A tag table exported beside a
    /// TIA Portal block is read without it.
    #[arg(long, value_name = "CSV")]
    pub(crate) comments: Option<PathBuf>,
    /// The language of a TIA Portal export's comments (`de-DE`, `en-US`):
    /// a comment in several languages is read in this one where it has
    /// it, else in the first that has a text. Default: en-US.
    #[arg(long, value_name = "CULTURE")]
    pub(crate) language: Option<String>,
    /// The program file's encoding: `utf-8`, `utf-16le`, `utf-16be`,
    /// `latin1` (Windows-1252)... Default: a byte-order mark decides, then
    /// UTF-8 if the bytes are UTF-8, else Latin-1 (Windows-1252).
    #[arg(long, value_name = "NAME", value_parser = parse_encoding)]
    pub(crate) encoding: Option<&'static cellwatch_models::source::Encoding>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub(crate) json: bool,
}

fn parse_encoding(
    s: &str,
) -> Result<&'static cellwatch_models::source::Encoding, source::UnknownEncoding> {
    cellwatch_models::source::encoding(s)
}

fn parse_dialect(s: &str) -> Result<Dialect, UnknownDialect> {
    s.parse()
}
