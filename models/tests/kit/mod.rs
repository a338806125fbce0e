//! The models' integration tests' kit: the fixtures they share (paper
//! 000's programs and snapshots, its Fig. 6 exports) and the builders of
//! what they run (switching functions and checks, step supervision,
//! transition timers, a `CellEngine` over its tags), with the readings
//! they feed it and what they read of its steps.
//!
//! Each test file takes it with `mod kit;` (`#[path = "../kit/mod.rs"]`
//! from a test in a folder of its own); being in a folder, it is no test
//! of its own. The unit tests' cell is `src/engine/fixture.rs`.

// Each test binary uses a part of the kit.
#![allow(dead_code)]
#![allow(clippy::unwrap_used)] // test helpers fail loudly by design

use cellwatch_models::alarm::{Alarm, Severity, Transition};
use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{
    CellEngine, CheckSet, EngineStep, Reading, StateRules, SwitchingCheck, Tag,
};
use cellwatch_models::explain::Polarity;
use cellwatch_models::expr::Expr;
use cellwatch_models::logic::Term;
use cellwatch_models::program::Program;
use cellwatch_models::programs::Op;
use cellwatch_models::sfc::{self, Sfc, SfcChecks};
use cellwatch_models::signal::{Observability, Signal};
use cellwatch_models::switching::SwitchingFunction;
use cellwatch_models::timer::checks::TimerChecks;
use cellwatch_models::timer::learn::{
    Event, LearnedTransition, SignalEdge, TimerModel, MODEL_VERSION,
};

/// Paper 000's emergency stop error (ESE, coil G8.02), as shipped.
pub(crate) const ESE: &str = include_str!("../../../config/cnc/ese.il");
/// Paper 000's cycle start disability (CSD, coil G9.00), as shipped.
pub(crate) const CSD: &str = include_str!("../../../config/cnc/csd.il");
/// CSD with the emergency-stop coil G8.02 a contact of its logic, as on
/// real machines.
pub(crate) const CSD_ESE: &str = include_str!("../../../tests/data/paper000/csd-ese.il");
/// ESE's contacts as the machine runs normally (a `.values` snapshot).
pub(crate) const ESE_NORMAL: &str = include_str!("../../../config/cnc/ese-normal.values");
/// CSD's contacts as the machine runs normally (a `.values` snapshot).
pub(crate) const CSD_NORMAL: &str = include_str!("../../../config/cnc/csd-normal.values");

/// Fig. 6 exported from TIA Portal as a ladder (LAD).
pub(crate) const FIG6_TIA_LAD: &str =
    include_str!("../../../tests/data/paper000/fig6.lad.SimaticML.xml");
/// Fig. 6 exported from TIA Portal as a function block diagram (FBD).
pub(crate) const FIG6_TIA_FBD: &str =
    include_str!("../../../tests/data/paper000/fig6.fbd.SimaticML.xml");
/// Fig. 6 as a PLCopen XML ladder.
pub(crate) const FIG6_PLCOPEN: &str = include_str!("../../../tests/data/paper000/fig6.xml");
/// Fig. 6 as a Studio 5000 function block diagram.
pub(crate) const FIG6_FBD_L5X: &str = include_str!("../../../tests/data/paper000/fig6.fbd.L5X");

/// `text` compiled as the file `origin`; panics with the error.
pub(crate) fn compile(origin: &str, text: &str) -> Program {
    Program::compile(origin, text, None).unwrap_or_else(|e| panic!("{e}"))
}

/// The switching function of `p`'s `coil`, every signal the dialect
/// observes by default a leaf; panics with the error.
pub(crate) fn expand(p: &Program, coil: &str) -> SwitchingFunction {
    SwitchingFunction::expand(
        p,
        &Signal::new(coil),
        &Observability::default_for(p.dialect()),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// The switching function of `coil` in `text`, compiled as `origin`.
pub(crate) fn switching_function(origin: &str, text: &str, coil: &str) -> SwitchingFunction {
    expand(&compile(origin, text), coil)
}

/// Step `i` of `sf` as an expression whose earlier steps are the leaves
/// `SSF1`, `SSF2`, ... as the paper writes them.
pub(crate) fn step_expr(sf: &SwitchingFunction, i: usize) -> Expr {
    let block = &sf.steps[i - 1];
    let terms = block
        .terms
        .iter()
        .map(|t| match t {
            Term::Block { id, negated } => {
                Expr::Lit(Signal::new(&format!("SSF{}", id + 1)), *negated)
            }
            Term::Signal { signal, negated } => Expr::Lit(signal.clone(), *negated),
            Term::Const(v) => Expr::Const(*v),
        })
        .collect();
    match block.op {
        Op::And => Expr::And(terms),
        Op::Or => Expr::Or(terms),
    }
}

/// `e` with every signal renamed by `f`.
pub(crate) fn rename(e: &Expr, f: &dyn Fn(&Signal) -> Signal) -> Expr {
    match e {
        Expr::Const(v) => Expr::Const(*v),
        Expr::Lit(s, n) => Expr::Lit(f(s), *n),
        Expr::Not(inner) => Expr::Not(Box::new(rename(inner, f))),
        Expr::And(t) => Expr::And(t.iter().map(|x| rename(x, f)).collect()),
        Expr::Or(t) => Expr::Or(t.iter().map(|x| rename(x, f)).collect()),
    }
}

/// `e` with the exports' tag names (`F17_00`, `G0_00`) named as the paper
/// (`F17.00`, `G0.00`).
pub(crate) fn tags_to_paper(e: &Expr) -> Expr {
    rename(e, &|s: &Signal| Signal::new(&s.name().replace('_', ".")))
}

/// The switching check `id` over `sf`: a fault while `sf` is on, of type
/// `id` in upper case, always armed, forcing nothing, without comments.
pub(crate) fn switching_check(
    id: &str,
    sf: SwitchingFunction,
    severity: Severity,
) -> SwitchingCheck {
    SwitchingCheck {
        forces: Vec::new(),
        text: None,
        id: id.into(),
        sf,
        polarity: Polarity::On,
        severity,
        fault_type: id.to_uppercase(),
        comments: CommentDb::default(),
        armed_when: None,
    }
}

/// Paper 000's ESE check (critical) and its contacts' tags (named in lower
/// case), as the unit tests' cell has them.
pub(crate) fn ese() -> (Vec<Tag>, SwitchingCheck) {
    let sf = switching_function("ese.il", ESE, "G8.02");
    let tags = tags(sf.leaves());
    (tags, switching_check("ese", sf, Severity::Critical))
}

/// The charts of `text`, read as the file `origin`, every signal known.
pub(crate) fn charts(origin: &str, text: &str) -> Sfc {
    sfc::read(origin, text, &|_| true).unwrap()
}

/// The step supervision `sfc` of `charts` (high), with `comments`.
pub(crate) fn supervision(charts: Sfc, comments: CommentDb) -> SfcChecks {
    SfcChecks::new("sfc", charts, Severity::High, comments)
}

/// `tag`'s `edge`.
pub(crate) fn event(tag: &str, edge: SignalEdge) -> Event {
    Event {
        tag: tag.into(),
        edge,
    }
}

/// `+event` after `+trigger`, learned from 4 runs: `delta_ms` typical,
/// `[min_ms, max_ms]` seen, `window` allowed.
pub(crate) fn triggered(
    id: u32,
    trigger: &str,
    event: &str,
    delta_ms: u64,
    [min_ms, max_ms]: [u64; 2],
    window: [u64; 2],
) -> LearnedTransition {
    LearnedTransition {
        id,
        from: vec![],
        event: self::event(event, SignalEdge::Rise),
        to: vec![],
        delta_ms,
        min_ms,
        max_ms,
        support: 4,
        window_ms: window,
        from_numbered: None,
        trigger: Some(self::event(trigger, SignalEdge::Rise)),
    }
}

/// A timer model over `signals`, learned by `method`.
pub(crate) fn timer_model(
    method: &str,
    signals: &[&str],
    transitions: Vec<LearnedTransition>,
) -> TimerModel {
    TimerModel {
        version: MODEL_VERSION,
        method: method.into(),
        signals: signals.iter().map(|s| s.to_string()).collect(),
        transitions,
    }
}

/// The transition timers `id` of `model` (high), each signal its own
/// address.
pub(crate) fn timer_checks(id: &str, model: &TimerModel) -> TimerChecks {
    TimerChecks::new(id, model, Severity::High, |n| Some(Signal::new(n))).unwrap()
}

/// A tag for each signal, named as its address in lower case (`x0.06`).
pub(crate) fn tags(signals: impl IntoIterator<Item = Signal>) -> Vec<Tag> {
    named(signals, str::to_lowercase)
}

/// A tag for each address, named as the address in lower case.
pub(crate) fn tags_at(addresses: &[&str]) -> Vec<Tag> {
    tags(addresses.iter().map(|a| Signal::new(a)))
}

/// A tag for each signal, named as its address (`bStart`).
pub(crate) fn tags_as_named(signals: impl IntoIterator<Item = Signal>) -> Vec<Tag> {
    named(signals, str::to_string)
}

/// A tag for each signal, named `name` of its address.
fn named(signals: impl IntoIterator<Item = Signal>, name: fn(&str) -> String) -> Vec<Tag> {
    signals
        .into_iter()
        .map(|s| Tag {
            name: name(s.name()),
            address: s,
        })
        .collect()
}

/// The cell `id` reading `tags`, judged by `sets`, with the default state
/// rules.
pub(crate) fn cell(id: &str, tags: Vec<Tag>, sets: Vec<Box<dyn CheckSet>>) -> CellEngine {
    CellEngine::new(id, tags, sets, StateRules::default()).unwrap()
}

/// `e` relating its alarms by the relation it derived from its checks,
/// consequences suppressed if `suppress`.
pub(crate) fn related(e: CellEngine, suppress: bool) -> CellEngine {
    let relation = e.relation().clone();
    e.relating(relation, suppress)
}

/// The index of the tag at `address`; panics if there is none.
pub(crate) fn tag(e: &CellEngine, address: &str) -> usize {
    e.tag_index(&Signal::new(address)).unwrap()
}

/// The tag at `address` reads `reading`, stamped `at` and taken at `at`.
pub(crate) fn read(e: &mut CellEngine, address: &str, reading: Reading, at: u64) -> EngineStep {
    let t = tag(e, address);
    e.on_reading(t, reading, at, at)
}

/// The contact at `address` reads `v` at `at`.
pub(crate) fn set(e: &mut CellEngine, address: &str, v: bool, at: u64) -> EngineStep {
    read(e, address, Reading::Good(v), at)
}

/// Each contact of `values` reads its value at `at`, in order.
pub(crate) fn set_all(e: &mut CellEngine, values: &[(&str, bool)], at: u64) -> Vec<EngineStep> {
    values.iter().map(|&(a, v)| set(e, a, v, at)).collect()
}

/// The rows of a `.values` snapshot (`address,value` under a header and
/// `#` comments), in the file's order.
pub(crate) fn snapshot(text: &str) -> Vec<(&str, bool)> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
        .map(|line| {
            let (a, v) = line.split_once(',').unwrap();
            (a, v == "1")
        })
        .collect()
}

/// Each row of the snapshot `text` whose address is one of `e`'s tags,
/// read at `at`, in the file's order.
pub(crate) fn load(e: &mut CellEngine, text: &str, at: u64) {
    for (a, v) in snapshot(text) {
        if e.tag_index(&Signal::new(a)).is_some() {
            set(e, a, v, at);
        }
    }
}

/// The alarms `step` raised.
pub(crate) fn raised(step: &EngineStep) -> Vec<Alarm> {
    step.alarms()
        .filter(|(_, t, _)| *t == Transition::Raised)
        .map(|(a, _, _)| a.clone())
        .collect()
}
