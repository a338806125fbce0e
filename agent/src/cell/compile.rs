//! From a validated configuration to a running engine: the check sets
//! (switching functions, transition timers, limit checks, chart supervision)
//! bound to the cell's tags.
//! `cellwatch validate` calls exactly this, so a configuration that
//! validates starts.

use cellwatch_models::comments::CommentDb;
use cellwatch_models::engine::{CellEngine, CheckSet, EngineError, SwitchingChecks};
use cellwatch_models::limit::LimitChecks;
use cellwatch_models::madb::Rationalised;
use cellwatch_models::sfc::SfcChecks;
use cellwatch_models::timer::checks::{TimerCheckError, TimerChecks};

use cellwatch_models::consequence::Relation;

use crate::config::{CellConfig, Consequences};

/// Why a configuration cannot be turned into an engine.
#[derive(Debug, thiserror::Error)]
pub enum CompileError {
    /// A timer model does not fit the cell.
    #[error("checks.timers {id}: {source}")]
    Timer {
        /// The check's id.
        id: String,
        /// Why.
        source: TimerCheckError,
    },
    /// The engine refuses the checks.
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// An edge of `[alarms.consequences]` names no alarm of the cell, or
    /// removes one the checks do not give.
    #[error("{key}: {why}")]
    Consequence {
        /// The key (`alarms.consequences.add[0]`).
        key: String,
        /// Why.
        why: String,
    },
    /// A row of the master alarm database (`alarms.database`) names no
    /// alarm of the cell.
    #[error("{file}:{line}:1: column 'id': '{id}' is no alarm of this cell (`cellwatch mad export` lists them)")]
    Database {
        /// The database file.
        file: String,
        /// The row's line.
        line: u64,
        /// The id.
        id: String,
    },
    /// A pattern of `[[state.modes]]` matches no alarm the cell can
    /// raise (a misspelt id would leave the alarm announced in its mode).
    #[error("state.modes[{mode}].suppress[{index}]: '{pattern}' matches no alarm of this cell's checks, `communication`, `tag-quality` or the PLC's (`[[opcua.events]]` prefixes)")]
    Mode {
        /// The mode's index.
        mode: usize,
        /// The pattern's index.
        index: usize,
        /// The pattern.
        pattern: String,
    },
}

/// How much later than the subscription's lifetime a change may still
/// arrive: the longest reconnect backoff.
const SOURCE_TIME_SLACK: std::time::Duration = std::time::Duration::from_secs(10);

/// Builds the engine for `config`.
///
/// # Errors
/// A timer model or a check reads something the cell does not have.
pub fn engine(config: &CellConfig) -> Result<CellEngine, CompileError> {
    let comments: CommentDb = config
        .tags
        .iter()
        .filter_map(|t| Some((t.address.clone(), t.comment.clone()?)))
        .collect();
    let mut sets: Vec<Box<dyn CheckSet>> =
        vec![Box::new(SwitchingChecks::new(config.switching.clone()))];
    for t in &config.timers {
        let checks = TimerChecks::new(&t.id, &t.model, t.severity, |n| {
            crate::config::timer_signal(config.addressing, &config.tags, n)
        })
        .map_err(|source| CompileError::Timer {
            id: t.id.clone(),
            source,
        })?
        .commented(comments.clone())
        .drifting(t.drift);
        sets.push(Box::new(checks));
    }
    if !config.limits.is_empty() {
        sets.push(Box::new(LimitChecks::new(config.limits.clone())));
    }
    if !config.sfc.is_empty() {
        for s in &config.sfc {
            let checks = SfcChecks::new(&s.id, s.sfc.clone(), s.severity, comments.clone());
            // The outputs the program drives from each step's flag, where
            // the cell reads them.
            let checks = match &s.program {
                Some((program, observable)) => checks.driving(program, observable, |a| {
                    config.tags.iter().any(|t| t.address == *a)
                }),
                None => checks,
            };
            sets.push(Box::new(checks));
        }
    }
    let engine = config.delays.iter().fold(
        CellEngine::new(
            &config.cell,
            config.engine_tags(),
            sets,
            config.state.clone(),
        )?,
        |e, (id, on, off)| e.delaying(id, *on, *off),
    );
    // An OPC UA server's source times are trusted as the times of the
    // alarms judged on them as far back as a change can arrive late: the
    // subscription's lifetime (a network cut it survives) and the longest
    // reconnect backoff. An `@` unit's values are stamped on arrival.
    let trust = config.opcua.as_ref().map_or(0, |ua| {
        (ua.subscription_lifetime + SOURCE_TIME_SLACK).as_millis() as u64
    });
    // The PLC's own alarms (`[[opcua.events]]`), by their ids' prefixes:
    // taken before the relation, whose edges may name them.
    let conditions = config.opcua.iter().flat_map(|ua| &ua.events);
    let engine = engine.taking_conditions(conditions.map(|e| e.prefix.clone()));
    if let Some(&(mode, index)) = engine.unmatched_patterns().first() {
        return Err(CompileError::Mode {
            mode,
            index,
            pattern: config.state.modes[mode].suppress[index].to_string(),
        });
    }
    let relation = relation(&engine, &config.consequences)?;
    let engine = match &config.database {
        Some((path, db)) => {
            let rows = rationalised(config, &engine, path, db)?;
            engine.rationalising(rows)
        }
        None => engine,
    };
    let engine = match &config.recorder {
        Some(r) => engine.recording(r.clone()),
        None => engine,
    };
    Ok(engine
        .relating(relation, config.consequences.suppress)
        .trusting_source_time(trust)
        .commenting(comments)
        .counting(config.part_counting())
        .counting_rejects(config.reject_counting())
        .ordering(config.order_item, config.order_target)
        .exporting(
            config
                .tags
                .iter()
                .enumerate()
                .filter(|(_, t)| t.export)
                .map(|(i, _)| i)
                .chain(config.step_flags().into_keys()),
        ))
}

/// The rows of the master alarm database as the engine applies them.
///
/// # Errors
/// A row names no alarm of the cell: not one the engine can raise, the
/// agent's own, nor a PLC pattern it follows.
fn rationalised(
    config: &CellConfig,
    engine: &CellEngine,
    path: &std::path::Path,
    db: &cellwatch_models::madb::Database,
) -> Result<Vec<(String, Rationalised)>, CompileError> {
    let own = crate::cell::own_alarms::own_alarms(config);
    let mut out = Vec::new();
    for (id, row) in &db.rows {
        if !engine.can_raise(id) && !own.iter().any(|a| a.id == *id) {
            return Err(CompileError::Database {
                file: path.display().to_string(),
                line: row.line,
                id: id.clone(),
            });
        }
        out.push((
            id.clone(),
            Rationalised {
                priority: row.priority,
                guidance: std::sync::Arc::new(row.guidance.clone()),
            },
        ));
    }
    Ok(out)
}

/// The relation the checks give, with the configuration's edges added and
/// removed.
///
/// # Errors
/// An edge names an alarm the cell cannot raise, or removes one that is
/// not there.
fn relation(engine: &CellEngine, edits: &Consequences) -> Result<Relation, CompileError> {
    let mut relation = engine.relation().clone();
    let unknown = |key: &str, id: &str| {
        CompileError::Consequence {
        key: key.to_string(),
        why: format!("'{id}' is no alarm of this cell's checks or of the PLC's (`[[opcua.events]]` prefixes)"),
    }
    };
    for (key, cause, effect) in &edits.add {
        for id in [cause, effect] {
            if !engine.can_raise(id) {
                return Err(unknown(key, id));
            }
        }
        relation.add(cause, effect);
    }
    for (key, cause, effect) in &edits.remove {
        if !relation.remove(cause, effect) {
            return Err(CompileError::Consequence {
                key: key.clone(),
                why: format!(
                    "{cause} -> {effect} is no edge of the relation the checks give (`cellwatch explain --consequences` prints it)"
                ),
            });
        }
    }
    Ok(relation)
}
