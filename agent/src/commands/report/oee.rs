//! The OEE section of `cellwatch report daily|monthly`: each day's shifts
//! (those starting in it) and the day, availability, performance, quality
//! and OEE with the six big losses and the breakdowns by stop cause,
//! computed by the models' [`oee`] from the journal's history, as the
//! cell's `[oee]` (from `--config`) says.

use std::io::Write;

use cellwatch_models::oee::{self, DayFigures, Facts, Figures, OeeRules};
use cellwatch_models::report::StopCauses;

use crate::journal::ReportInput;
use crate::operator::escaped;

/// The OEE of the days starting at `day_starts`.
pub(super) fn days(
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
