//! A cell's sequential function charts as cellwatch holds them, whatever
//! they were read from: charts, steps, transitions, and where each is.

use crate::comments::CommentDb;
use crate::expr::Expr;
use crate::signal::Signal;

/// Charts of one cell.
#[derive(Debug, Clone, PartialEq)]
pub struct Sfc {
    /// The charts, in the order written.
    pub charts: Vec<Chart>,
    /// The comments of the variables the chart file declares, by name
    /// (PLCopen XML: each variable's `documentation`); the I/O list given
    /// to the supervision comes before them.
    pub variables: CommentDb,
}

/// One chart.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Its name (`F1`).
    pub name: String,
    /// Its initial step, if it has one (a chart may be entered by jumps
    /// only).
    pub initial: Option<usize>,
    /// Its steps.
    pub steps: Vec<Step>,
    /// Its transitions (those whose source steps are its own).
    pub transitions: Vec<SfcTransition>,
}

/// One step.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Its name (`S2`).
    pub name: String,
    /// The signal true while it is active.
    pub flag: Signal,
    /// Stuck when active longer than this, ms.
    pub supervision_ms: Option<u64>,
    /// What it does, for people.
    pub comment: Option<String>,
}

/// A step of some chart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct StepRef {
    /// The chart's index.
    pub chart: usize,
    /// The step's index in it.
    pub step: usize,
}

/// One transition.
#[derive(Debug, Clone, PartialEq)]
pub struct SfcTransition {
    /// Its id in its chart (`t3`).
    pub id: String,
    /// The steps it leaves (all must be active: more than one is a
    /// simultaneous convergence).
    pub from: Vec<StepRef>,
    /// The steps it activates (more than one: a simultaneous divergence;
    /// in another chart: a jump).
    pub to: Vec<StepRef>,
    /// Its condition, over tag addresses.
    pub condition: Expr,
    /// What it waits for, for people.
    pub comment: Option<String>,
}

impl Sfc {
    /// The chart named `name`.
    pub fn chart(&self, name: &str) -> Option<usize> {
        self.charts.iter().position(|c| c.name == name)
    }

    /// The step `r`.
    pub fn step(&self, r: StepRef) -> &Step {
        &self.charts[r.chart].steps[r.step]
    }

    /// `F1.S2`.
    pub fn step_name(&self, r: StepRef) -> String {
        format!("{}.{}", self.charts[r.chart].name, self.step(r).name)
    }

    /// The transition `id` of chart `chart`, if there is one.
    pub fn transition(&self, chart: &str, id: &str) -> Option<(usize, &SfcTransition)> {
        let c = self.chart(chart)?;
        self.charts[c]
            .transitions
            .iter()
            .find(|t| t.id == id)
            .map(|t| (c, t))
    }

    /// Every transition leaving step `r`.
    pub fn leaving(&self, r: StepRef) -> impl Iterator<Item = &SfcTransition> {
        self.charts[r.chart]
            .transitions
            .iter()
            .filter(move |t| t.from.contains(&r))
    }

    /// Every step, with its reference.
    pub fn steps(&self) -> impl Iterator<Item = (StepRef, &Step)> {
        self.charts.iter().enumerate().flat_map(|(c, chart)| {
            chart
                .steps
                .iter()
                .enumerate()
                .map(move |(s, step)| (StepRef { chart: c, step: s }, step))
        })
    }

    /// What transition `t` needs to fire (eq. (1)/(2) of paper 004): every
    /// source step's flag and its condition, one conjunction in the order
    /// the equations are written (`S2.X * t3`).
    pub fn needs(&self, t: &SfcTransition) -> Expr {
        and(t
            .from
            .iter()
            .map(|&r| Expr::Lit(self.step(r).flag.clone(), false))
            .chain(std::iter::once(t.condition.clone())))
    }
}

/// The conjunction of `terms`, a conjunction among them merged in, in
/// order.
pub(crate) fn and(terms: impl IntoIterator<Item = Expr>) -> Expr {
    let mut out = Vec::new();
    for t in terms {
        match t {
            Expr::And(inner) => out.extend(inner),
            other => out.push(other),
        }
    }
    Expr::And(out)
}

/// ` (comment)`, or nothing: how a step or transition is named with its
/// comment in messages.
pub(crate) fn about(comment: Option<&str>) -> String {
    comment.map(|c| format!(" ({c})")).unwrap_or_default()
}

/// Culprits as one line: `%IX0.0.3 = 0 (expected 1): comment, …`.
pub(crate) fn culprit_list(culprits: &[crate::explain::Culprit]) -> String {
    culprits
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}
