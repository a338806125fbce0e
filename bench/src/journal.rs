//! What the journal costs on disk (`bench/run journal --rows 100000`):
//! rows written through the agent's own journal writer (its batches, its
//! hash chain over command rows), then measured with SQLite's `dbstat`
//! (each table with its index, pages as stored). The alarm payload is the
//! demo's ESE raise as the agent publishes it (one culprit with its
//! comment); a command is one row of a verified acknowledgement.

use std::path::Path;
use std::time::Duration;

use cellwatch::config::Keep;
use cellwatch::journal::{CommitObserver, Entry, Journal};

/// The demo's ESE raise, as journaled (one culprit).
const ALARM: &str = r#"{"schema":"cellwatch.alarm.v1","cell":"m01ps0004","id":"ese","kind":"switching","severity":"critical","state":"active_unacknowledged","transition":"raised","at":"2026-11-26T15:39:36.928Z","raised_at":"2026-11-26T15:39:36.928Z","cleared_at":null,"acked_by":null,"latched":false,"fault_type":"ESE","fault_step":6,"culprits":[{"address":"X0.06","value":false,"expected":true,"comment":"Y Over Travel Limit SW (B)","trigger":true}],"message":"ESE at step 6: X0.06 = 0 (expected 1): Y Over Travel Limit SW (B)","shelved":null,"out_of_service":null}"#;

/// One more culprit, as the payload carries it.
const CULPRIT: &str = r#",{"address":"X0.04","value":false,"expected":true,"comment":"X Over Travel Limit SW (B)","trigger":false}"#;

struct Quiet;
impl CommitObserver for Quiet {
    fn committed(&self, _: usize, _: Duration) {}
    fn failed(&self, _: &str) {}
}

/// One table's measure.
struct Measure {
    table: &'static str,
    rows: u64,
    bytes: u64,
    /// The rows' own bytes (SQLite's records, table and index): what the
    /// pages hold, the baseline of the table's cost.
    records: u64,
}

/// Writes `rows` rows of each kind into a fresh journal under `workdir`
/// and prints what each costs.
pub async fn run(workdir: &Path, rows: u64) -> anyhow::Result<String> {
    std::fs::create_dir_all(workdir)?;
    let path = workdir.join("sizing.sqlite");
    for suffix in ["", "-wal", "-shm"] {
        let _ = std::fs::remove_file(format!("{}{suffix}", path.display()));
    }
    let journal = Journal::start(&path, &Keep::all(Duration::from_secs(3650 * 86_400)), Quiet)?;
    let now = cellwatch::clock::now_ms();
    let two_culprits = ALARM.replace(
        "\"trigger\":true}]",
        &format!("\"trigger\":true}}{CULPRIT}]"),
    );
    let batch = 1000;
    for start in (0..rows).step_by(batch) {
        let mut entries = Vec::new();
        for i in start..(start + batch as u64).min(rows) {
            let at = now + i;
            entries.push(Entry::Alarm {
                at,
                alarm: "ese".into(),
                kind: "switching".into(),
                severity: "critical".into(),
                transition: "raised".into(),
                payload: if i % 2 == 0 {
                    ALARM.into()
                } else {
                    two_culprits.clone()
                },
                open: false,
            });
            entries.push(Entry::State {
                at,
                kind: "fault".into(),
                state: "fault".into(),
                fault_type: Some("ESE".into()),
                element: Some("X0.06".into()),
            });
            entries.push(Entry::Command {
                at,
                operator: "kim".into(),
                action: "ack".into(),
                alarm: "ese".into(),
                nonce: format!("{:032x}", u128::from(i) * 0x9e37_79b9_7f4a_7c15),
                accepted: true,
                verified: true,
                detail: "acknowledged".into(),
                stage: "command".into(),
                source: String::new(),
                count: 1,
                // A command's SHA-256, as the agent keeps it with its rows.
                digest: Some(format!("{:064x}", u128::from(i) * 0x2545_f491_4f6c_dd1d)),
            });
            entries.push(Entry::Part { at, count: 1 });
        }
        journal.commit(entries).await?;
    }
    journal.close().await;
    let conn = rusqlite::Connection::open(&path)?;
    conn.execute_batch("PRAGMA wal_checkpoint(TRUNCATE)")?;
    let mut measures = Vec::new();
    for table in ["alarm_events", "state_history", "commands", "production"] {
        let (bytes, records): (i64, i64) = conn.query_row(
            "SELECT sum(pgsize), sum(payload) FROM dbstat WHERE name = ?1 OR name = ?1 || '_at'",
            [table],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )?;
        let n: i64 = conn.query_row(&format!("SELECT count(*) FROM {table}"), [], |r| r.get(0))?;
        measures.push(Measure {
            table,
            rows: n as u64,
            bytes: bytes as u64,
            records: records as u64,
        });
    }
    let file = std::fs::metadata(&path)?.len();
    let mut out = String::from(
        "| table | rows | bytes on disk (table and index) | bytes per row | the row's own bytes | on disk ÷ own | rows per GiB |\n|---|---|---|---|---|---|---|\n",
    );
    for m in &measures {
        let per = m.bytes as f64 / m.rows as f64;
        let own = m.records as f64 / m.rows as f64;
        out.push_str(&format!(
            "| `{}` | {} | {} | {:.0} | {:.0} | {:.2}× | {:.1} M |\n",
            m.table,
            m.rows,
            m.bytes,
            per,
            own,
            per / own,
            (1u64 << 30) as f64 / per / 1e6
        ));
    }
    out.push_str(&format!(
        "\nThe file: {file} bytes for {} rows.\n",
        measures.iter().map(|m| m.rows).sum::<u64>()
    ));
    Ok(out)
}
