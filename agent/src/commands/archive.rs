//! The plant archive's readers on the command line: `cellwatch history
//! --plant` (a cell's history from the routers' storages) and the chain ends
//! `audit verify --against-archive` holds a journal to.

use std::io::Write;
use std::time::Duration;

use super::bus::{io, print_alarm, session, HistoryArgs, ZenohArgs};
use crate::archive::read::{self, Kept, Range};
use crate::commands::Failure;

/// Prints what the archive keeps of `args.cell` in the range asked: alarm
/// events as `cellwatch alarms` prints them, machine states when they
/// change (an agent puts its state again every `publish_interval`), and
/// recordings when asked; then what was not believed, on stderr.
pub(crate) async fn history(args: &HistoryArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let kinds: &[Kept] = match args.kind.as_deref() {
        None => &[Kept::Alarm, Kept::State],
        Some("alarm") => &[Kept::Alarm],
        Some("state") => &[Kept::State],
        Some("recording") => &[Kept::Recording],
        Some(other) => {
            return Err(Failure::Input(format!(
                "--kind {other}: the plant archive keeps `alarm`, `state` and `recording`"
            )))
        }
    };
    let range = Range::new(&args.since, args.until.as_deref()).map_err(Failure::input)?;
    let bus = session(&args.zenoh).await?;
    let timeout = Duration::from_secs(args.zenoh.timeout_secs);
    let reading = read::read(&bus, &args.cell, kinds, &range, timeout)
        .await
        .map_err(|e| Failure::Runtime(format!("the plant archive could not be asked: {e}")))?;
    let mut last_state = std::collections::HashMap::new();
    for entry in &reading.entries {
        match entry.kept {
            Kept::Alarm => match entry.alarm() {
                Some(a) => print_alarm(out, &a, args.json, None).map_err(io)?,
                None => eprintln!("{}: signed, but not an alarm event", entry.key),
            },
            Kept::State => match entry.state() {
                Some(s) => {
                    let line = format!(
                        "{}  {}  state={} kind={} type={} element={} since {}",
                        s.at,
                        s.cell,
                        s.state,
                        s.kind.as_str(),
                        s.fault_type.as_deref().unwrap_or("None"),
                        s.element.as_deref().unwrap_or("None"),
                        s.since
                    );
                    if args.json {
                        // Every state as put (each carries the command
                        // chain's end signed then).
                        writeln!(out, "{}", entry.opened.body).map_err(io)?;
                        continue;
                    }
                    // Put again unchanged every publish_interval: said once.
                    let what = (s.state, s.kind, s.fault_type, s.element, s.since);
                    if last_state.get(&s.cell) == Some(&what) {
                        continue;
                    }
                    last_state.insert(s.cell.clone(), what);
                    writeln!(out, "{}", crate::operator::escaped(&line)).map_err(io)?;
                }
                None => eprintln!("{}: signed, but not a machine state", entry.key),
            },
            Kept::Recording => {
                if args.json {
                    writeln!(out, "{}", entry.opened.body).map_err(io)?;
                    continue;
                }
                let chart =
                    serde_json::from_str::<crate::payload::RecordingPayload>(&entry.opened.body)
                        .map(|p| p.recording.timeline(80))
                        .unwrap_or_else(|e| format!("(a recording that does not read: {e})\n"));
                writeln!(
                    out,
                    "{}  recording {}",
                    crate::clock::rfc3339(entry.opened.at),
                    crate::operator::escaped(&entry.key)
                )
                .map_err(io)?;
                for l in chart.lines() {
                    writeln!(out, "    {}", crate::operator::escaped(l)).map_err(io)?;
                }
            }
        }
    }
    if reading.entries.is_empty() {
        eprintln!(
            "(nothing in the plant archive for {} in that range: none kept, or no router with the storage manager reached)",
            args.cell
        );
    }
    for (key, why) in &reading.refused {
        eprintln!("not believed: {key}: {why}");
    }
    if !reading.refused.is_empty() {
        return Err(Failure::Runtime(format!(
            "{} archived entries not believed (above)",
            reading.refused.len()
        )));
    }
    Ok(())
}

/// Every end of the command chain `cell`'s agent signed in a state the
/// plant archive keeps (each once, oldest first): what `audit verify
/// --against-archive` holds the journal to.
pub(crate) async fn archived_chain_heads(
    z: &ZenohArgs,
    cell: &str,
) -> Result<Vec<crate::payload::CommandChain>, Failure> {
    // As far back as any retention goes.
    let range = Range::new("36500d", None).map_err(Failure::input)?;
    let bus = session(z).await?;
    let timeout = Duration::from_secs(z.timeout_secs);
    let reading = read::read(&bus, cell, &[Kept::State], &range, timeout)
        .await
        .map_err(|e| Failure::Runtime(format!("the plant archive could not be asked: {e}")))?;
    if let Some((key, why)) = reading.refused.first() {
        return Err(Failure::Runtime(format!(
            "the plant archive holds {} entries not believed, the first {key}: {why}",
            reading.refused.len()
        )));
    }
    let mut heads: Vec<crate::payload::CommandChain> = Vec::new();
    for entry in &reading.entries {
        let Some(head) = entry.state().and_then(|s| s.command_chain) else {
            continue;
        };
        if !heads.contains(&head) {
            heads.push(*head);
        }
    }
    Ok(heads)
}
