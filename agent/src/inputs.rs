//! Reading the user's files: programs, comment databases and snapshots.
//!
//! Thin wrappers over the models' parsers: read the bytes, decode them
//! (UTF-8, UTF-16, Latin-1), and hand the text over with the file's name, so every error comes
//! back as `FILE:LINE:COL: message`.

use std::path::Path;

use cellwatch_models::comments::CommentDb;
use cellwatch_models::program::Program;
use cellwatch_models::signal::Observability;
use cellwatch_models::source;
use cellwatch_models::values::Values;

use crate::cli::{Failure, ProgramArgs};

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
    args: &ProgramArgs,
    err: &mut dyn std::io::Write,
) -> Result<(Program, CommentDb, Observability), Failure> {
    let name = args.program.display().to_string();
    let text = read_encoded(&args.program, "program", args.encoding)?;
    let program = Program::compile(&name, &text, args.dialect).map_err(Failure::input)?;
    for w in program.warnings() {
        let _ = writeln!(err, "{name}:{}: warning: {}", w.at, w.message);
    }
    // The program's declarations comment its signals; a CSV adds to them
    // and wins where both say something.
    let comments = match &args.comments {
        Some(path) => {
            let text = read_text(path, "comment database")?;
            let csv = CommentDb::parse(&path.display().to_string(), &text, |a| program.resolve(a))
                .map_err(Failure::input)?;
            program.documentation().clone().overridden_by(csv)
        }
        None => program.documentation().clone(),
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
