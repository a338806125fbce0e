//! The cell the engine's tests run: paper 000's ESE check over its
//! contacts' tags, their normal values, and what the tests read of a step.

use super::{CellEngine, EngineEvent, Reading, StateRules, SwitchingCheck, SwitchingChecks, Tag};
use crate::alarm::{Severity, Transition};
use crate::comments::CommentDb;
use crate::explain::Polarity;
use crate::expr::Expr;
use crate::program::Program;
use crate::signal::{Observability, Signal};
use crate::switching::SwitchingFunction;

const ESE: &str = include_str!("../../../config/cnc/ese.il");

const NORMAL: &str = include_str!("../../../config/cnc/ese-normal.values");

pub(super) fn engine() -> CellEngine {
    engine_with(&[], "G0.00 * F0.00")
}

/// The ESE check over its contacts' tags, then `extra` tags, with
/// `running` as the running rule.
pub(super) fn engine_with(extra: &[Tag], running: &str) -> CellEngine {
    let rules = StateRules {
        running: Some(Expr::parse(running).unwrap()),
        ..StateRules::default()
    };
    engine_ruled(extra, rules)
}

/// Paper 000's ESE check and its contacts' tags (named in lower case).
pub(super) fn ese() -> (Vec<Tag>, SwitchingCheck) {
    let p = Program::compile("ese.il", ESE, None).unwrap();
    let sf = SwitchingFunction::expand(
        &p,
        &Signal::new("G8.02"),
        &Observability::default_for(p.dialect()),
    )
    .unwrap();
    let tags: Vec<Tag> = sf
        .leaves()
        .into_iter()
        .map(|s| Tag {
            name: s.name().to_lowercase(),
            address: s,
        })
        .collect();
    let check = SwitchingCheck {
        forces: Vec::new(),
        text: None,
        id: "ese".into(),
        sf,
        polarity: Polarity::On,
        severity: Severity::Critical,
        fault_type: "ESE".into(),
        comments: CommentDb::default(),
        armed_when: None,
    };
    (tags, check)
}

/// The ESE check over its contacts' tags, then `extra` tags, with the
/// state `rules`.
pub(super) fn engine_ruled(extra: &[Tag], rules: StateRules) -> CellEngine {
    let (mut tags, check) = ese();
    tags.extend_from_slice(extra);
    CellEngine::new(
        "m01",
        tags,
        vec![Box::new(SwitchingChecks::new(vec![check]))],
        rules,
    )
    .unwrap()
}

pub(super) fn load_normal(e: &mut CellEngine, at: u64) -> Vec<EngineEvent> {
    let mut out = Vec::new();
    for line in NORMAL
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("address"))
    {
        let (a, v) = line.split_once(',').unwrap();
        let t = e.tag_index(&Signal::new(a)).unwrap();
        out.extend(e.on_reading(t, Reading::Good(v == "1"), at, at).events);
    }
    out
}

pub(super) fn alarm_transitions(events: &[EngineEvent]) -> Vec<(String, Transition)> {
    events
        .iter()
        .filter_map(|e| match e {
            EngineEvent::Alarm {
                alarm, transition, ..
            } => Some((alarm.id.clone(), *transition)),
            _ => None,
        })
        .collect()
}

/// The alarm `id`'s transitions and texts in `events`.
pub(super) fn said(events: &[EngineEvent], id: &str) -> Vec<(Transition, String)> {
    events
        .iter()
        .filter_map(|e| match e {
            EngineEvent::Alarm {
                alarm, transition, ..
            } if alarm.id == id => Some((*transition, alarm.message.clone())),
            _ => None,
        })
        .collect()
}
