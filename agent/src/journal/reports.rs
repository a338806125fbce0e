//! Reading the journal for the reports: production and the alarm system's figures.

use rusqlite::Connection;

/// What reports read.
#[derive(Debug, Default)]
pub struct ReportInput {
    /// Machine-state rows, the last one before the period first.
    pub changes: Vec<cellwatch_models::report::StateChange>,
    /// Parts made `(time, count)`.
    pub parts: Vec<(u64, u64)>,
    /// Work-order changes, the last one before the period first.
    pub orders: Vec<cellwatch_models::report::OrderChange>,
    /// Parts rejected `(time, count)`.
    pub rejects: Vec<(u64, u64)>,
    /// Machine modes entered and left, each mode's last change before
    /// the period first.
    pub modes: Vec<cellwatch_models::oee::ModeChange>,
}

/// Machine-state rows, parts made and work orders between `since` and
/// `until` (ms), plus the last state and order before `since`, for
/// reports.
///
/// # Errors
/// SQLite failing.
pub fn report_input(conn: &Connection, since: u64, until: u64) -> rusqlite::Result<ReportInput> {
    let mut input = ReportInput::default();
    let row = |r: &rusqlite::Row<'_>| {
        Ok(cellwatch_models::report::StateChange {
            at: r.get::<_, i64>(0)? as u64,
            state: r.get(1)?,
            fault_type: r.get(2)?,
        })
    };
    let before = conn
        .query_row(
            "SELECT at_ms, state, fault_type FROM state_history WHERE at_ms < ?1 ORDER BY at_ms DESC, seq DESC LIMIT 1",
            [since as i64],
            row,
        )
        .ok();
    input.changes.extend(before);
    let mut stmt = conn.prepare("SELECT at_ms, state, fault_type FROM state_history WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms, seq")?;
    for c in stmt.query_map([since as i64, until as i64], row)? {
        input.changes.push(c?);
    }
    let counted = |column: &str| -> rusqlite::Result<Vec<(u64, u64)>> {
        let mut stmt = conn.prepare(&format!(
            "SELECT at_ms, {column} FROM production WHERE at_ms >= ?1 AND at_ms < ?2 AND {column} > 0 ORDER BY at_ms, seq"
        ))?;
        let rows = stmt.query_map([since as i64, until as i64], |r| {
            Ok((
                r.get::<_, i64>(0)? as u64,
                r.get::<_, i64>(1)?.max(0) as u64,
            ))
        })?;
        rows.collect()
    };
    input.parts = counted("parts")?;
    input.rejects = counted("rejects")?;
    let mode = |r: &rusqlite::Row<'_>| {
        Ok(cellwatch_models::oee::ModeChange {
            at: r.get::<_, i64>(0)?.max(0) as u64,
            mode: r.get(1)?,
            entered: r.get::<_, i64>(2)? != 0,
        })
    };
    let mut stmt = conn.prepare(
        "SELECT at_ms, mode, entered FROM modes WHERE seq IN \
         (SELECT MAX(seq) FROM modes WHERE at_ms < ?1 GROUP BY mode) ORDER BY at_ms, seq",
    )?;
    for m in stmt.query_map([since as i64], mode)? {
        input.modes.push(m?);
    }
    let mut stmt = conn.prepare(
        "SELECT at_ms, mode, entered FROM modes WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms, seq",
    )?;
    for m in stmt.query_map([since as i64, until as i64], mode)? {
        input.modes.push(m?);
    }
    let order = |r: &rusqlite::Row<'_>| {
        Ok(cellwatch_models::report::OrderChange {
            at: r.get::<_, i64>(0)? as u64,
            item: r.get(1)?,
            target: r.get::<_, Option<i64>>(2)?.map(|t| t.max(0) as u64),
        })
    };
    let before = conn
        .query_row(
            "SELECT at_ms, item, target FROM orders WHERE at_ms < ?1 ORDER BY at_ms DESC, seq DESC LIMIT 1",
            [since as i64],
            order,
        )
        .ok();
    input.orders.extend(before);
    let mut stmt = conn.prepare(
        "SELECT at_ms, item, target FROM orders WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms, seq",
    )?;
    for o in stmt.query_map([since as i64, until as i64], order)? {
        input.orders.push(o?);
    }
    Ok(input)
}

/// What the alarm report reads: the alarm events of `[since, until)` in
/// time order, and each alarm's last event before `since`. A row whose
/// payload does not parse (written by a newer agent, damaged) is skipped
/// and counted.
#[derive(Debug, Default)]
pub struct AlarmEvents {
    /// In the period.
    pub events: Vec<cellwatch_models::kpi::AlarmEvent>,
    /// Before it, the last per alarm.
    pub before: Vec<cellwatch_models::kpi::AlarmEvent>,
    /// Rows skipped.
    pub unreadable: u64,
}

/// Reads [`AlarmEvents`].
///
/// # Errors
/// The journal cannot be read.
pub fn alarm_events(conn: &Connection, since: u64, until: u64) -> rusqlite::Result<AlarmEvents> {
    let mut out = AlarmEvents::default();
    let event = |at: i64, transition: String, payload: String| {
        let p: crate::payload::AlarmPayload = serde_json::from_str(&payload).ok()?;
        let transition = serde_json::from_value(serde_json::Value::String(transition)).ok()?;
        let alarm = p.to_alarm()?;
        Some(cellwatch_models::kpi::AlarmEvent {
            at: at.max(0) as u64,
            id: alarm.id,
            transition,
            severity: alarm.severity,
            raised_at: alarm.raised_at,
            active: alarm.active,
            consequence: alarm.consequence.is_some(),
            by_design: alarm.designed.is_some(),
        })
    };
    let row = |r: &rusqlite::Row<'_>| {
        Ok((
            r.get::<_, i64>(0)?,
            r.get::<_, String>(1)?,
            r.get::<_, String>(2)?,
        ))
    };
    let mut stmt = conn.prepare(
        "SELECT at_ms, transition, payload FROM alarm_events WHERE seq IN \
         (SELECT MAX(seq) FROM alarm_events WHERE at_ms < ?1 GROUP BY alarm) ORDER BY seq",
    )?;
    for r in stmt.query_map([since as i64], row)? {
        let (at, t, p) = r?;
        match event(at, t, p) {
            Some(e) => out.before.push(e),
            None => out.unreadable += 1,
        }
    }
    let mut stmt = conn.prepare(
        "SELECT at_ms, transition, payload FROM alarm_events \
         WHERE at_ms >= ?1 AND at_ms < ?2 ORDER BY at_ms, seq",
    )?;
    for r in stmt.query_map([since as i64, until as i64], row)? {
        let (at, t, p) = r?;
        match event(at, t, p) {
            Some(e) => out.events.push(e),
            None => out.unreadable += 1,
        }
    }
    Ok(out)
}
