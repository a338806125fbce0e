//! Programs from public projects (`tests/data/real/`, sources and licences
//! in its README): each file's outcome is pinned — which coils, which
//! switching functions, how many warnings, which errors — and on four of
//! them a fault is explained and checked against values worked out by hand.
//! The helpers are here; the programs, by the tools that made them, in
//! `iec61131.rs` (matiec, Beremiz, OpenPLC), `siemens.rs` (awlsim, TIA
//! Portal) and `rockwell.rs` (Studio 5000).

#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

mod iec61131;
mod rockwell;
mod siemens;

#[path = "../kit/mod.rs"]
mod kit;

use std::path::PathBuf;

use cellwatch_models::explain::{explain, Explanation, Polarity};
use cellwatch_models::program::Program;
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::source;
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::values::Values;
use kit::expand as sf;

fn path(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/data/real")
        .join(file)
}

fn compile(file: &str) -> Result<Program, String> {
    let bytes = std::fs::read(path(file)).unwrap();
    let text = source::text(file, &bytes, None).map_err(|e| e.to_string())?;
    Program::compile(file, &text, None).map_err(|e| e.to_string())
}

fn program(file: &str) -> Program {
    compile(file).unwrap_or_else(|e| panic!("{e}"))
}

/// Every coil with its SF (internal relays replaced by their logic, as
/// `cellwatch sf` prints it), or `!` and the line the reason points at.
fn outcome(p: &Program) -> Vec<(String, String)> {
    p.coils()
        .iter()
        .map(|c| {
            let sf =
                SwitchingFunction::expand(p, &c.signal, &Observability::default_for(p.dialect()));
            let shown = match sf {
                Ok(sf) => sf.notation(),
                Err(e) => {
                    let e = e.to_string();
                    let line = e.split(':').nth(1).unwrap_or("?").to_string();
                    format!("! line {line}")
                }
            };
            (c.signal.name().to_string(), shown)
        })
        .collect()
}

fn pinned(p: &Program, expected: &[(&str, &str)]) {
    let got = outcome(p);
    let want: Vec<(String, String)> = expected
        .iter()
        .map(|(c, s)| ((*c).to_string(), (*s).to_string()))
        .collect();
    assert_eq!(got, want, "{}", p.origin());
}

fn values(pairs: &[(&str, bool)]) -> Values {
    let mut v = Values::new();
    for (s, b) in pairs {
        v.set(Signal::new(s), *b);
    }
    v
}

fn explained(
    p: &Program,
    coil: &str,
    before: &Values,
    now: &Values,
    polarity: Polarity,
) -> Explanation {
    let b = |s: &Signal| before.get(s);
    explain(
        &sf(p, coil),
        |s| now.get(s),
        Some(&b),
        polarity,
        p.documentation(),
    )
    .unwrap()
}

fn culprits(e: &Explanation) -> Vec<String> {
    e.culprits.iter().map(ToString::to_string).collect()
}

/// Every warning as `LINE:COL: message`.
fn warnings(p: &Program) -> Vec<String> {
    p.warnings()
        .iter()
        .map(|w| format!("{}: {}", w.at, w.message))
        .collect()
}
