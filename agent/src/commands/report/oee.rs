//! The OEE section of `cellwatch report daily|monthly`: each day's shifts
//! (those starting in it) and the day, availability, performance, quality
//! and OEE with the six big losses and the breakdowns by stop cause,
//! computed by the models' [`oee`] from the journal's history, as the
//! cell's `[oee]` (from `--config`) says.

use std::io::Write;

use cellwatch_models::oee::{self, DayFigures, Facts, Figures, OeeRules, DAY_MS};
use cellwatch_models::report::StopCauses;

use crate::commands::Failure;
use crate::journal::{self, ReportInput};
use crate::operator::escaped;

/// The OEE of the days starting at `day_starts` under `rules` (none
/// without `[oee]`), from the journal: its facts read to two days past the
/// last day's start, so a night shift starting in it is taken whole.
pub(super) fn period(
    rules: Option<&OeeRules>,
    conn: &rusqlite::Connection,
    causes: &StopCauses,
    day_starts: &[u64],
    now: u64,
) -> Result<Option<Vec<DayFigures>>, Failure> {
    let (Some(rules), Some(&first), Some(&last)) = (rules, day_starts.first(), day_starts.last())
    else {
        return Ok(None);
    };
    let input = journal::report_input(conn, first, last + 2 * DAY_MS).map_err(Failure::runtime)?;
    Ok(Some(days(rules, causes, &input, day_starts, now)))
}

/// The OEE of the days starting at `day_starts`.
fn days(
    rules: &OeeRules,
    causes: &StopCauses,
    input: &ReportInput,
    day_starts: &[u64],
    now: u64,
) -> Vec<DayFigures> {
    let facts = Facts {
        changes: &input.changes,
        modes: &input.modes,
        parts: &input.parts,
        rejects: &input.rejects,
        orders: &input.orders,
        earlier_start: None,
    };
    day_starts
        .iter()
        .map(|&d| oee::day(rules, causes, &facts, d, now))
        .collect()
}

/// The sum of `days`.
pub(super) fn total(days: &[DayFigures]) -> Figures {
    let mut total = Figures::default();
    for d in days {
        total.add(&d.total);
    }
    total
}

fn pct(a: Option<f64>) -> String {
    a.map_or_else(|| "-".into(), |a| format!("{:.1}", 100.0 * a))
}

fn minutes(ms: u64) -> String {
    format!("{:.1}", ms as f64 / 60_000.0)
}

/// One line of figures: `label` then A, P, Q, OEE, planned and run
/// minutes, parts and rejects.
fn line(out: &mut dyn Write, label: &str, f: &Figures) -> std::io::Result<()> {
    writeln!(
        out,
        "  {label:<24} {:>6} {:>6} {:>6} {:>6} {:>9} {:>9} {:>7} {:>7}",
        pct(f.availability),
        pct(f.performance),
        pct(f.quality),
        pct(f.oee),
        minutes(f.planned_ms),
        minutes(f.run_ms),
        f.parts,
        f.rejects
    )
}

/// The section as a table: a line per shift, one per day when there are
/// several, then the period's losses.
pub(super) fn table(
    out: &mut dyn Write,
    days: &[(String, &DayFigures)],
    total: &Figures,
    period: &str,
) -> std::io::Result<()> {
    writeln!(out, "OEE (percent; planned and run time in minutes):")?;
    writeln!(
        out,
        "  {:<24} {:>6} {:>6} {:>6} {:>6} {:>9} {:>9} {:>7} {:>7}",
        "shift", "avail", "perf", "qual", "OEE", "planned", "run", "parts", "rejects"
    )?;
    for (day, d) in days {
        for s in &d.shifts {
            line(
                out,
                &format!("{day} {}", escaped(&s.shift.name)),
                &s.figures,
            )?;
        }
        if days.len() > 1 {
            line(out, day, &d.total)?;
        }
    }
    line(out, period, total)?;
    let l = &total.losses;
    writeln!(out, "six big losses ({period}):")?;
    for (name, ms, extra) in [
        ("breakdowns", l.breakdowns_ms, String::new()),
        ("setup and adjustment", l.setup_ms, String::new()),
        ("small stops", l.small_stops_ms, String::new()),
        ("reduced speed", l.reduced_speed_ms, String::new()),
        (
            "start-up rejects",
            l.startup_rejects_ms,
            format!("  ({} parts)", l.startup_rejects),
        ),
        (
            "production rejects",
            l.production_rejects_ms,
            format!("  ({} parts)", l.production_rejects),
        ),
    ] {
        writeln!(out, "  {name:<24} {:>9} min{extra}", minutes(ms))?;
    }
    writeln!(out, "breakdowns by stop cause:")?;
    if total.breakdowns.is_empty() {
        writeln!(out, "  none")?;
    }
    for b in &total.breakdowns {
        writeln!(
            out,
            "  {:<3} {:<32} {:>4} stop{} {:>8} min",
            escaped(&b.code),
            escaped(&b.name),
            b.stops,
            if b.stops == 1 { " " } else { "s" },
            minutes(b.ms)
        )?;
    }
    Ok(())
}

/// The columns OEE adds to the report's CSV.
const CSV_COLUMNS: &str =
    "performance_pct,quality_pct,oee_pct,planned_min,run_min,unobserved_min,rejects";

/// The report's CSV `production` with OEE: its header and rows widened by
/// [`CSV_COLUMNS`] (empty in its own rows), then a row per shift
/// (`oee-shift`, the day, the shift's name), per day when there are
/// several (`oee-day`) and for the period (`oee-total`), their
/// availability and parts in the columns of that name.
pub(super) fn csv(
    out: &mut dyn Write,
    production: &[u8],
    days: &[(String, &DayFigures)],
    total: Option<&Figures>,
) -> std::io::Result<()> {
    let text = String::from_utf8_lossy(production);
    let mut lines = text.lines();
    if let Some(header) = lines.next() {
        writeln!(out, "{header},{CSV_COLUMNS}")?;
    }
    let empty = ",".repeat(CSV_COLUMNS.matches(',').count() + 1);
    for l in lines {
        writeln!(out, "{l}{empty}")?;
    }
    let quote = |s: &str| format!("\"{}\"", escaped(s).replace('"', "\"\""));
    let row = |out: &mut dyn Write, section: &str, key: &str, name: &str, f: &Figures| {
        writeln!(
            out,
            "{section},{key},{},,,,,,,{},{},,{},{},{},{},{},{},{}",
            quote(name),
            pct(f.availability).replace('-', ""),
            f.parts,
            pct(f.performance).replace('-', ""),
            pct(f.quality).replace('-', ""),
            pct(f.oee).replace('-', ""),
            minutes(f.planned_ms),
            minutes(f.run_ms),
            minutes(f.unobserved_ms),
            f.rejects
        )
    };
    for (day, d) in days {
        for s in &d.shifts {
            row(out, "oee-shift", day, &s.shift.name, &s.figures)?;
        }
        if total.is_some() {
            row(out, "oee-day", day, "", &d.total)?;
        }
    }
    match (total, days) {
        (Some(total), _) => row(out, "oee-total", "month", "", total),
        (None, [(day, d)]) => row(out, "oee-total", day, "", &d.total),
        (None, _) => Ok(()),
    }
}
