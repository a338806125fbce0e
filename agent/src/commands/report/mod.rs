//! `cellwatch report daily|monthly`: production reports from a journal
//! (paper 002, Tables 3-5); `cellwatch report alarms`: the alarm system's
//! ISA-18.2 benchmark table. As a terminal table, CSV or JSON; text read
//! from the journal (alarm ids, item codes) is printed escaped
//! ([`crate::operator::escaped`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use cellwatch_models::kpi::{self, AlarmReport};
use cellwatch_models::report::{
    self, CauseTotal, DailyReport, Minutes, MonthlyReport, OrderSpan, StopCauses,
};
use chrono::{Datelike, FixedOffset, NaiveDate, TimeZone};

mod oee;

use super::Failure;
use crate::journal;
use crate::operator::escaped;

/// The table `--causes` names, or the shipped one.
fn causes(path: Option<&Path>) -> Result<StopCauses, Failure> {
    let Some(path) = path else {
        return crate::config::oee::shipped_stop_causes()
            .map_err(|e| Failure::Runtime(format!("the shipped stop causes: {e}")));
    };
    let text = std::fs::read_to_string(path).map_err(|e| {
        Failure::Input(format!("cannot read stop causes '{}': {e}", path.display()))
    })?;
    toml::from_str(&text).map_err(|e| {
        let at = e.span().map_or((1, 1), |s| {
            let before = &text[..s.start];
            (
                before.matches('\n').count() + 1,
                before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1,
            )
        });
        Failure::Input(format!(
            "{}:{}:{}: {}",
            path.display(),
            at.0,
            at.1,
            e.message().trim_end()
        ))
    })
}

fn offset(text: &str) -> Result<FixedOffset, Failure> {
    let bad = || {
        Failure::Input(format!(
            "--utc-offset '{text}': write it as +09:00 or -05:30"
        ))
    };
    let (sign, rest) = match text.as_bytes().first() {
        Some(b'+') => (1, &text[1..]),
        Some(b'-') => (-1, &text[1..]),
        _ => return Err(bad()),
    };
    let (h, m) = rest.split_once(':').ok_or_else(bad)?;
    let secs =
        h.parse::<i32>().map_err(|_| bad())? * 3600 + m.parse::<i32>().map_err(|_| bad())? * 60;
    FixedOffset::east_opt(sign * secs).ok_or_else(bad)
}

/// Milliseconds since the epoch at the start of `date` in `tz`.
fn day_start(date: NaiveDate, tz: &FixedOffset) -> u64 {
    let local = date.and_hms_opt(0, 0, 0).unwrap_or_default();
    tz.from_local_datetime(&local)
        .single()
        .map_or(0, |t| t.timestamp_millis().max(0) as u64)
}

/// Runs a report command.
pub(crate) fn run(args: &ReportArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let config = match &args.config {
        Some(path) => Some(crate::config::load(path).map_err(|e| Failure::Input(e.to_string()))?),
        None => None,
    };
    let rules = config
        .as_ref()
        .and_then(|c| c.oee.as_ref())
        .map(|o| &o.rules);
    let (tz, zone) = plant_offset(args, rules)?;
    if !args.db.is_file() {
        return Err(Failure::Input(format!(
            "--db '{}': no such journal",
            args.db.display()
        )));
    }
    let conn = journal::open_read(&args.db).map_err(|e| Failure::Runtime(e.to_string()))?;
    let now = crate::clock::now_ms();
    let io = Failure::output;
    match &args.command {
        ReportCommand::Daily { date } => {
            let d = NaiveDate::parse_from_str(date, "%Y-%m-%d")
                .map_err(|_| Failure::Input(format!("--date '{date}': write it as 2026-11-21")))?;
            let causes = causes(args.causes.as_deref())?;
            let start = day_start(d, &tz);
            let i = journal::report_input(&conn, start, start + 86_400_000)
                .map_err(|e| Failure::Runtime(e.to_string()))?;
            let r = report::daily(&i.changes, &i.parts, &i.orders, start, &causes, now);
            let oee = oee::period(rules, &conn, &causes, &[start], now)?;
            match args.format() {
                Format::Json => {
                    let mut v = serde_json::to_value(&r).unwrap_or_default();
                    if let Some(days) = &oee {
                        v["oee"] = serde_json::to_value(&days[0]).unwrap_or_default();
                    }
                    writeln!(
                        out,
                        "{}",
                        serde_json::to_string_pretty(&v).unwrap_or_default()
                    )
                    .map_err(io)
                }
                Format::Csv => match &oee {
                    Some(days) => {
                        let mut production = Vec::new();
                        daily_csv(&mut production, &r).map_err(io)?;
                        let named = [(d.to_string(), &days[0])];
                        oee::csv(out, &production, &named, None).map_err(io)
                    }
                    None => daily_csv(out, &r).map_err(io),
                },
                Format::Table => {
                    daily_table(out, &args.db, &d.to_string(), &zone, &r).map_err(io)?;
                    match &oee {
                        Some(days) => {
                            oee::table(out, &[(d.to_string(), &days[0])], &days[0].total, "day")
                                .map_err(io)
                        }
                        None => Ok(()),
                    }
                }
            }
        }
        ReportCommand::Monthly { month } => {
            let days = month_days(month)?;
            let causes = causes(args.causes.as_deref())?;
            let starts: Vec<u64> = days.iter().map(|d| day_start(*d, &tz)).collect();
            let end = starts.last().copied().unwrap_or(0) + 86_400_000;
            let i = journal::report_input(&conn, starts[0], end)
                .map_err(|e| Failure::Runtime(e.to_string()))?;
            let r = report::monthly(&i.changes, &i.parts, &i.orders, &starts, &causes, now);
            let oee = oee::period(rules, &conn, &causes, &starts, now)?;
            match args.format() {
                Format::Json => {
                    let mut v = serde_json::to_value(&r).unwrap_or_default();
                    if let Some(figures) = &oee {
                        v["oee"] = serde_json::json!({
                            "days": figures,
                            "total": oee::total(figures),
                        });
                    }
                    writeln!(
                        out,
                        "{}",
                        serde_json::to_string_pretty(&v).unwrap_or_default()
                    )
                    .map_err(io)
                }
                Format::Csv => match &oee {
                    Some(figures) => {
                        let mut production = Vec::new();
                        monthly_csv(&mut production, &days, &r).map_err(io)?;
                        let named: Vec<(String, &cellwatch_models::oee::DayFigures)> =
                            days.iter().map(|d| d.to_string()).zip(figures).collect();
                        let total = oee::total(figures);
                        oee::csv(out, &production, &named, Some(&total)).map_err(io)
                    }
                    None => monthly_csv(out, &days, &r).map_err(io),
                },
                Format::Table => {
                    monthly_table(out, &args.db, month, &zone, &days, &r).map_err(io)?;
                    match &oee {
                        Some(figures) => {
                            let named: Vec<(String, &cellwatch_models::oee::DayFigures)> =
                                days.iter().map(|d| d.to_string()).zip(figures).collect();
                            oee::table(out, &named, &oee::total(figures), "month").map_err(io)
                        }
                        None => Ok(()),
                    }
                }
            }
        }
        ReportCommand::Alarms { date, month } => {
            let kpi = config.map(|c| c.kpi).unwrap_or_default();
            let period = (date.as_deref(), month.as_deref());
            alarms(args, &conn, (&tz, &zone), &kpi, period, out)
        }
    }
}

/// The plant's offset from UTC, for the days' boundaries, and as
/// written: `--utc-offset`, else the `[oee]` section's of `--config`, else
/// UTC. Both given and different is refused: the days and the shifts
/// would be cut at different hours.
fn plant_offset(
    args: &ReportArgs,
    oee: Option<&cellwatch_models::oee::OeeRules>,
) -> Result<(FixedOffset, String), Failure> {
    let configured = oee.map(|r| {
        let ms = r.calendar.utc_offset_ms;
        let sign = if ms < 0 { '-' } else { '+' };
        let minutes = ms.unsigned_abs() / 60_000;
        format!("{sign}{:02}:{:02}", minutes / 60, minutes % 60)
    });
    let text = match (&args.utc_offset, configured) {
        (Some(given), Some(configured)) => {
            let tz = offset(given)?;
            if Some(tz) != offset(&configured).ok() {
                return Err(Failure::Input(format!(
                    "--utc-offset '{given}' is not the plant's offset in {} (oee.utc_offset = \"{configured}\"): the days and the shifts would be cut at different hours; give the same or leave --utc-offset out",
                    args.config.as_deref().unwrap_or(Path::new("--config")).display()
                )));
            }
            given.clone()
        }
        (Some(given), None) => given.clone(),
        (None, Some(configured)) => configured,
        (None, None) => "+00:00".into(),
    };
    Ok((offset(&text)?, text))
}

/// The days of `month` (`2026-11`).
fn month_days(month: &str) -> Result<Vec<NaiveDate>, Failure> {
    let first = NaiveDate::parse_from_str(&format!("{month}-01"), "%Y-%m-%d")
        .map_err(|_| Failure::Input(format!("--month '{month}': write it as 2026-11")))?;
    let mut days = Vec::new();
    let mut d = first;
    while d.month() == first.month() && days.len() < 31 {
        days.push(d);
        match d.succ_opt() {
            Some(next) => d = next,
            None => break,
        }
    }
    Ok(days)
}

/// `cellwatch report alarms`: the ISA-18.2 benchmark table of a day or a
/// month.
fn alarms(
    args: &ReportArgs,
    conn: &rusqlite::Connection,
    (tz, zone): (&FixedOffset, &str),
    rules: &kpi::KpiRules,
    period: (Option<&str>, Option<&str>),
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let (title, from, to) = match period {
        (Some(date), None) => {
            let d = NaiveDate::parse_from_str(date, "%Y-%m-%d")
                .map_err(|_| Failure::Input(format!("--date '{date}': write it as 2026-11-21")))?;
            let start = day_start(d, tz);
            (date.to_string(), start, start + 86_400_000)
        }
        (None, Some(month)) => {
            let days = month_days(month)?;
            let start = day_start(days[0], tz);
            (
                month.to_string(),
                start,
                start + 86_400_000 * days.len() as u64,
            )
        }
        _ => return Err(Failure::Input("give --date or --month".into())),
    };
    let read =
        journal::alarm_events(conn, from, to).map_err(|e| Failure::Runtime(e.to_string()))?;
    if read.unreadable > 0 {
        eprintln!(
            "warning: {} alarm rows of {} could not be read and are not counted",
            read.unreadable,
            args.db.display()
        );
    }
    let r = kpi::alarm_report(
        &read.events,
        &read.before,
        from,
        to,
        crate::clock::now_ms(),
        rules,
    );
    let io = Failure::output;
    match args.format() {
        Format::Json => {
            let mut v = serde_json::to_value(&r).unwrap_or_default();
            v["benchmarks"] = serde_json::to_value(r.benchmarks()).unwrap_or_default();
            writeln!(
                out,
                "{}",
                serde_json::to_string_pretty(&v).unwrap_or_default()
            )
            .map_err(io)
        }
        Format::Csv => alarms_csv(out, &r).map_err(io),
        Format::Table => alarms_table(out, &args.db, &title, zone, &r).map_err(io),
    }
}

fn alarms_csv(out: &mut dyn Write, r: &AlarmReport) -> std::io::Result<()> {
    let quote = |s: &str| format!("\"{}\"", s.replace('"', "\"\""));
    writeln!(out, "metric,value,target,met")?;
    for b in r.benchmarks() {
        writeln!(
            out,
            "{},{},{},{}",
            quote(&b.metric),
            quote(&b.value),
            quote(&b.target),
            b.met.map_or("", |m| if m { "yes" } else { "no" })
        )?;
    }
    Ok(())
}

fn alarms_table(
    out: &mut dyn Write,
    db: &Path,
    period: &str,
    tz: &str,
    r: &AlarmReport,
) -> std::io::Result<()> {
    writeln!(
        out,
        "alarm performance {period} (UTC{tz}) from {}: {} alarms in {} intervals of 10 min",
        db.display(),
        r.raised,
        r.intervals
    )?;
    writeln!(
        out,
        "{:<44} {:>26}  {:<22} met",
        "ISA-18.2", "value", "target"
    )?;
    for b in r.benchmarks() {
        writeln!(
            out,
            "{:<44} {:>26}  {:<22} {}",
            b.metric,
            b.value,
            b.target,
            b.met.map_or("", |m| if m { "yes" } else { "NO" })
        )?;
    }
    writeln!(out, "most frequent alarms:")?;
    if r.top.is_empty() {
        writeln!(out, "  none")?;
    }
    for f in &r.top {
        writeln!(
            out,
            "  {:<32} {:>6} {:>6.1} %",
            escaped(&f.id),
            f.raised,
            f.share
        )?;
    }
    let rules = &r.rules;
    writeln!(
        out,
        "chattering alarms (most raises within {} s, {} or more):",
        rules.chatter_window_ms as f64 / 1000.0,
        rules.chatter_raises
    )?;
    if r.chattering.is_empty() {
        writeln!(out, "  none")?;
    }
    for c in &r.chattering {
        writeln!(out, "  {:<32} {:>6}", escaped(&c.id), c.raises_in_window)?;
    }
    writeln!(
        out,
        "stale alarms (active > {} h):",
        rules.stale_ms as f64 / 3_600_000.0
    )?;
    if r.stale.is_empty() {
        writeln!(out, "  none")?;
    }
    for s in &r.stale {
        writeln!(
            out,
            "  {:<32} raised {}  {:.1} h",
            escaped(&s.id),
            crate::clock::rfc3339(s.raised_at),
            s.hours
        )?;
    }
    Ok(())
}

/// Output format.
pub(crate) enum Format {
    Table,
    Csv,
    Json,
}

fn pct(a: Option<f64>) -> String {
    a.map_or_else(|| "-".into(), |a| format!("{a:.1}"))
}

fn row(m: &Minutes) -> String {
    format!(
        "{:>8.1} {:>8.1} {:>8.1} {:>8.1}",
        m.running, m.idle, m.fault, m.offline
    )
}

fn causes_table(out: &mut dyn Write, causes: &[CauseTotal]) -> std::io::Result<()> {
    writeln!(out, "stop causes:")?;
    if causes.is_empty() {
        writeln!(out, "  none")?;
    }
    for c in causes {
        writeln!(
            out,
            "  {:<3} {:<32} {:>4} stop{} {:>8.1} min",
            escaped(&c.code),
            escaped(&c.name),
            c.count,
            if c.count == 1 { " " } else { "s" },
            c.minutes
        )?;
    }
    Ok(())
}

fn daily_table(
    out: &mut dyn Write,
    db: &Path,
    date: &str,
    tz: &str,
    r: &DailyReport,
) -> std::io::Result<()> {
    writeln!(out, "daily report {date} (UTC{tz}) from {}", db.display())?;
    writeln!(out, "hour      run     idle    fault  offline   (minutes)")?;
    for (h, m) in r.hours.iter().enumerate() {
        writeln!(out, "{h:02}   {}", row(m))?;
    }
    writeln!(out, "day  {}", row(&r.total))?;
    writeln!(out, "availability: {} %", pct(r.availability))?;
    causes_table(out, &r.stop_causes)?;
    writeln!(out, "production: {} parts", r.production)?;
    writeln!(out, "orders (item / mould, target, made):")?;
    if r.orders.is_empty() {
        writeln!(out, "  none known")?;
    }
    for o in &r.orders {
        writeln!(
            out,
            "  {}  {:<12} target {:>7}  made {:>7}",
            span(r.day_start, o),
            escaped(o.item.as_deref().unwrap_or("-")),
            o.target.map_or_else(|| "-".into(), |t| t.to_string()),
            o.parts
        )?;
    }
    Ok(())
}

/// An order's time within its day, `HH:MM-HH:MM`.
fn span(day_start: u64, o: &OrderSpan) -> String {
    let hm = |ms: u64| {
        let min = ms.saturating_sub(day_start) / 60_000;
        format!("{:02}:{:02}", min / 60, min % 60)
    };
    format!("{}-{}", hm(o.from), hm(o.to))
}

const CSV_HEADER: &str = "section,key,name,running_min,idle_min,fault_min,offline_min,stops,stop_min,availability_pct,parts,target";

fn csv_minutes(m: &Minutes) -> String {
    format!(
        "{:.1},{:.1},{:.1},{:.1}",
        m.running, m.idle, m.fault, m.offline
    )
}

fn csv_causes(out: &mut dyn Write, causes: &[CauseTotal]) -> std::io::Result<()> {
    for c in causes {
        writeln!(
            out,
            "cause,{},\"{}\",,,,,{},{:.1},,,",
            escaped(&c.code),
            escaped(&c.name).replace('"', "\"\""),
            c.count,
            c.minutes
        )?;
    }
    Ok(())
}

/// A CSV row of minutes, availability and parts for a day or a total.
fn summary_row(
    out: &mut dyn Write,
    section: &str,
    key: &str,
    m: &Minutes,
    availability: Option<f64>,
    parts: u64,
) -> std::io::Result<()> {
    let availability = availability.map_or_else(String::new, |a| format!("{a:.1}"));
    writeln!(
        out,
        "{section},{key},,{},,,{availability},{parts},",
        csv_minutes(m)
    )
}

fn daily_csv(out: &mut dyn Write, r: &DailyReport) -> std::io::Result<()> {
    writeln!(out, "{CSV_HEADER}")?;
    for (h, m) in r.hours.iter().enumerate() {
        writeln!(out, "hour,{h:02},,{},,,,,", csv_minutes(m))?;
    }
    csv_causes(out, &r.stop_causes)?;
    for o in &r.orders {
        writeln!(
            out,
            "order,{},\"{}\",,,,,,,,{},{}",
            span(r.day_start, o),
            escaped(o.item.as_deref().unwrap_or("")).replace('"', "\"\""),
            o.parts,
            o.target.map_or_else(String::new, |t| t.to_string())
        )?;
    }
    summary_row(out, "total", "day", &r.total, r.availability, r.production)
}

fn monthly_table(
    out: &mut dyn Write,
    db: &Path,
    month: &str,
    tz: &str,
    days: &[NaiveDate],
    r: &MonthlyReport,
) -> std::io::Result<()> {
    writeln!(
        out,
        "monthly report {month} (UTC{tz}) from {}",
        db.display()
    )?;
    writeln!(
        out,
        "day             run     idle    fault  offline   avail%   parts  items"
    )?;
    for (d, day) in days.iter().zip(&r.days) {
        let mut items: Vec<std::borrow::Cow<'_, str>> = Vec::new();
        for o in &day.orders {
            let item = escaped(o.item.as_deref().unwrap_or("-"));
            if !items.contains(&item) {
                items.push(item);
            }
        }
        writeln!(
            out,
            "{d}  {} {:>8} {:>7}  {}",
            row(&day.total),
            pct(day.availability),
            day.production,
            items.join(" ")
        )?;
    }
    writeln!(
        out,
        "month       {} {:>8} {:>7}",
        row(&r.total),
        pct(r.availability),
        r.production
    )?;
    causes_table(out, &r.stop_causes)
}

fn monthly_csv(out: &mut dyn Write, days: &[NaiveDate], r: &MonthlyReport) -> std::io::Result<()> {
    writeln!(out, "{CSV_HEADER}")?;
    for (d, day) in days.iter().zip(&r.days) {
        summary_row(
            out,
            "day",
            &d.to_string(),
            &day.total,
            day.availability,
            day.production,
        )?;
    }
    csv_causes(out, &r.stop_causes)?;
    summary_row(
        out,
        "total",
        "month",
        &r.total,
        r.availability,
        r.production,
    )
}

#[derive(Debug, clap::Args)]
pub(crate) struct ReportArgs {
    #[command(subcommand)]
    pub(crate) command: ReportCommand,
    /// The agent's SQLite journal.
    #[arg(long, global = true, default_value = "cellwatch.sqlite")]
    pub(crate) db: PathBuf,
    /// Stop-cause table (TOML, `[[cause]] code, name, fault_type | state`);
    /// without it, the shipped table (paper 002's Table 4 and the demo's
    /// faults, `config/stop-causes.toml`), wherever the command runs.
    #[arg(long, global = true)]
    pub(crate) causes: Option<PathBuf>,
    /// The cell's configuration: `report alarms` judges by its `[kpi]`
    /// rules (flood, chattering, stale), without it by ISA-18.2's;
    /// `report daily|monthly` add the OEE of its `[oee]` shifts, whose
    /// `utc_offset` cuts the days too.
    #[arg(long, global = true)]
    pub(crate) config: Option<PathBuf>,
    /// The plant's offset from UTC, for day boundaries (+09:00); without
    /// it, the `[oee]` section's `utc_offset` of `--config`, else UTC.
    #[arg(long, global = true, allow_hyphen_values = true)]
    pub(crate) utc_offset: Option<String>,
    /// CSV instead of a table.
    #[arg(long, global = true, conflicts_with = "json")]
    pub(crate) csv: bool,
    /// JSON instead of a table.
    #[arg(long, global = true)]
    pub(crate) json: bool,
}

impl ReportArgs {
    pub(crate) fn format(&self) -> crate::commands::report::Format {
        use crate::commands::report::Format;
        match (self.csv, self.json) {
            (true, _) => Format::Csv,
            (_, true) => Format::Json,
            _ => Format::Table,
        }
    }
}

#[derive(Debug, clap::Subcommand)]
pub(crate) enum ReportCommand {
    /// One day: 24 hourly slots (paper 002, Table 3).
    Daily {
        /// The day, 2026-11-21.
        #[arg(long)]
        date: String,
    },
    /// One month, day by day (paper 002, Table 5).
    Monthly {
        /// The month, 2026-11.
        #[arg(long)]
        month: String,
    },
    /// The alarm system's performance (ISA-18.2 / IEC 62682) over a day or
    /// a month, each figure against its target: average and peak alarm
    /// rate per 10 minutes, 10-minute intervals in flood, the 10 most
    /// frequent alarms and their share, chattering and stale alarms,
    /// priority distribution, shelving and out-of-service use,
    /// acknowledgement times.
    #[command(group(clap::ArgGroup::new("period").required(true).args(["date", "month"])))]
    Alarms {
        /// One day, 2026-11-21.
        #[arg(long)]
        date: Option<String>,
        /// One month, 2026-11.
        #[arg(long)]
        month: Option<String>,
    },
}
