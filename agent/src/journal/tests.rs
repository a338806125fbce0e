//! Journal tests: durability, batches, history pages, restarts.

use super::*;

struct Quiet;
impl CommitObserver for Quiet {
    fn committed(&self, _: usize, _: Duration) {}
    fn failed(&self, _: &str) {}
}

#[tokio::test]
async fn writes_commit_and_query_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("j.sqlite");
    let now = crate::clock::now_ms();
    let j = Journal::start(
        &path,
        &crate::journal::config::Keep::all(Duration::from_secs(3600)),
        Quiet,
    )
    .unwrap();
    j.write(Entry::State {
        at: now,
        kind: "fault".into(),
        state: "fault".into(),
        fault_type: Some("ESE".into()),
        element: Some("X0.06".into()),
    })
    .await
    .unwrap();
    j.write(Entry::Command {
        at: now + 1,
        operator: "kim".into(),
        action: "ack".into(),
        alarm: "ese".into(),
        nonce: "n1".into(),
        accepted: false,
        verified: false,
        detail: "bad signature".into(),
        stage: "command".into(),
        source: String::new(),
        count: 1,
        digest: None,
    })
    .await
    .unwrap();
    let mut c = j.committed();
    c.wait_for(|n| *n >= 2).await.unwrap();
    let conn = open_read(&path).unwrap();
    let rows = history(&conn, &HistoryQuery::default()).unwrap().rows;
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[0].fields["element"], "X0.06");
    assert_eq!(rows[1].fields["accepted"], false);
    let only = history(
        &conn,
        &HistoryQuery {
            kind: Some("command".into()),
            ..Default::default()
        },
    )
    .unwrap()
    .rows;
    assert_eq!(only.len(), 1);
    assert_eq!(
        history(
            &conn,
            &HistoryQuery {
                kind: Some("x".into()),
                ..Default::default()
            }
        )
        .unwrap_err()
        .to_string(),
        "unknown kind 'x': use alarm, state, command, recording, kpi or production"
    );
    // Old rows go at the next start.
    drop(j);
    let conn = open(&path).unwrap();
    conn.execute("UPDATE state_history SET at_ms = 5", [])
        .unwrap();
    drop(conn);
    let j = Journal::start(
        &path,
        &crate::journal::config::Keep::all(Duration::from_secs(3600)),
        Quiet,
    )
    .unwrap();
    let conn = open_read(&path).unwrap();
    // The purge runs on the writer thread: wait for it through a write.
    j.write(Entry::Alarm {
        at: now,
        alarm: "ese".into(),
        kind: "switching".into(),
        severity: "critical".into(),
        transition: "raised".into(),
        payload: "{}".into(),
        open: true,
    })
    .await
    .unwrap();
    let mut c = j.committed();
    c.wait_for(|n| *n >= 3).await.unwrap();
    let rows = history(
        &conn,
        &HistoryQuery {
            kind: Some("state".into()),
            ..Default::default()
        },
    )
    .unwrap()
    .rows;
    assert!(rows.is_empty());
}

fn state(at: u64, n: usize) -> Entry {
    Entry::State {
        at,
        kind: "normal".into(),
        state: "running".into(),
        fault_type: None,
        element: Some(format!("row {n} {}", "x".repeat(200))),
    }
}

#[tokio::test]
async fn a_barrier_waits_for_rows_staged_before_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("j.sqlite");
    let j = Journal::start(
        &path,
        &crate::journal::config::Keep::all(Duration::from_secs(3600)),
        Quiet,
    )
    .unwrap();
    // The cell loop stages a step's rows before the bus has the alarm;
    // a client that saw it asks for history (a barrier) before the
    // rows are queued.
    let step = j.stage(1);
    let barrier = j.barrier();
    let mut settled = std::pin::pin!(barrier.settled());
    // Everything queued after the barrier is committed, and the
    // barrier still waits: it is not ahead of the staged rows.
    tokio::select! {
        biased;
        () = &mut settled => panic!("the barrier passed rows staged before it"),
        r = j.commit(Vec::new()) => r.unwrap(),
    }
    j.queue_staged(vec![state(1, 1)], step).await.unwrap();
    settled.await;
    let conn = open_read(&path).unwrap();
    let rows: i64 = conn
        .query_row("SELECT count(*) FROM state_history", [], |r| r.get(0))
        .unwrap();
    assert_eq!(
        rows, 1,
        "the staged row is committed once the barrier passes"
    );
    // A barrier with nothing staged passes once the queue is committed.
    j.barrier().settled().await;
    j.close().await;
    // And at once when the journal is closed.
    barrier.settled().await;
}

#[tokio::test]
async fn history_comes_in_bounded_pages_in_journal_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("j.sqlite");
    let now = crate::clock::now_ms();
    let j = Journal::start(
        &path,
        &crate::journal::config::Keep::all(Duration::from_secs(3600)),
        Quiet,
    )
    .unwrap();
    // Rows of two tables, interleaved: one sequence for all.
    let mut rows = Vec::new();
    for n in 0..12_000 {
        rows.push(state(now, n));
        if n % 1000 == 0 {
            rows.push(Entry::Part { at: now, count: 1 });
        }
    }
    j.commit(rows).await.unwrap();
    let conn = open_read(&path).unwrap();
    // The newest, bounded in bytes before rows.
    let q = HistoryQuery {
        limit: Some(MAX_ROWS),
        ..Default::default()
    };
    let page = history(&conn, &q).unwrap();
    let bytes = serde_json::to_string(&page).unwrap().len();
    assert!(bytes <= MAX_REPLY_BYTES + 1024, "{bytes}");
    assert!(page.more && page.next.is_none());
    assert_eq!(
        page.rows.last().unwrap().fields["element"]
            .as_str()
            .unwrap()[..9]
            .to_string(),
        "row 11999"
    );
    // Forward pages: every row once, in order.
    let mut after = 0;
    let mut seen = Vec::new();
    loop {
        let page = history(
            &conn,
            &HistoryQuery {
                limit: Some(MAX_ROWS),
                after: Some(after),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(serde_json::to_string(&page).unwrap().len() <= MAX_REPLY_BYTES + 1024);
        seen.extend(page.rows.iter().map(|r| r.seq));
        match page.next {
            Some(n) => after = n,
            None => break,
        }
    }
    // Parts are not history rows; the 12,000 states are, in order.
    assert_eq!(seen.len(), 12_000);
    assert!(seen.windows(2).all(|w| w[0] < w[1]));
}

/// Records what the writer reports, and whether the journal's health
/// had already been announced (failing) when it did.
#[derive(Clone, Default)]
struct Watch {
    log: std::sync::Arc<std::sync::Mutex<Vec<(String, bool)>>>,
    health: std::sync::Arc<std::sync::OnceLock<watch::Receiver<Option<String>>>>,
}
impl Watch {
    fn note(&self, what: String) {
        let failing = self.health.get().is_some_and(|h| h.borrow().is_some());
        self.log.lock().unwrap().push((what, failing));
    }
    fn log(&self) -> Vec<(String, bool)> {
        self.log.lock().unwrap().clone()
    }
}
impl CommitObserver for Watch {
    fn committed(&self, _: usize, _: Duration) {}
    fn failed(&self, _: &str) {
        self.note("failed".into());
    }
    fn pending(&self, rows: usize) {
        self.note(format!("pending {rows}"));
    }
}

/// The last count of rows not yet committed the observer was told.
fn last_pending(watch: &Watch) -> Option<String> {
    watch
        .log()
        .into_iter()
        .rev()
        .find(|(w, _)| w.starts_with("pending "))
        .map(|(w, _)| w)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_row_not_yet_committed_counts_as_pending() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("j.sqlite");
    let now = crate::clock::now_ms();
    let watch = Watch::default();
    let j = Journal::start(
        &path,
        &crate::journal::config::Keep::all(Duration::from_secs(3600)),
        watch.clone(),
    )
    .unwrap();
    // Busy for a moment: another connection holds the write lock.
    let admin = Connection::open(&path).unwrap();
    admin.execute_batch("BEGIN IMMEDIATE").unwrap();
    // A step's rows staged (the bus has not seen it yet), five rows
    // queued one by one behind the writer's first batch, which waits
    // for the lock.
    let step = j.stage(3);
    assert_eq!(last_pending(&watch).as_deref(), Some("pending 3"));
    for n in 0..5 {
        j.write(state(now, n)).await.unwrap();
    }
    assert_eq!(last_pending(&watch).as_deref(), Some("pending 8"));
    // Queued at last: still not committed, counted once.
    j.queue_staged((5..8).map(|n| state(now, n)).collect(), step)
        .await
        .unwrap();
    assert_eq!(last_pending(&watch).as_deref(), Some("pending 8"));
    // Free again: all eight committed, none pending.
    admin.execute_batch("COMMIT").unwrap();
    let mut committed = j.committed();
    committed.wait_for(|&n| n == 8).await.unwrap();
    assert_eq!(last_pending(&watch).as_deref(), Some("pending 0"));
    j.close().await;
}

#[tokio::test]
async fn an_unwritable_journal_keeps_its_rows_and_writes_them_later() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("j.sqlite");
    let now = crate::clock::now_ms();
    let watch = Watch::default();
    let j = Journal::start(
        &path,
        &crate::journal::config::Keep::all(Duration::from_secs(3600)),
        watch.clone(),
    )
    .unwrap();
    let _ = watch.health.set(j.health());
    j.commit(vec![state(now, 0)]).await.unwrap();
    // Another process holds the journal's write lock: nothing can be
    // written.
    let admin = Connection::open(&path).unwrap();
    admin.execute_batch("BEGIN IMMEDIATE").unwrap();
    let mut health = j.health();
    let big: Vec<Entry> = (1..400).map(|n| state(now, n)).collect();
    assert!(j.commit(big).await.is_err());
    health.wait_for(Option::is_some).await.unwrap();
    // The rows kept were counted when they came, and the failure
    // before the journal said it was failing: whoever sees its alarm
    // sees both.
    let log = watch.log();
    let failed = log.iter().position(|(w, _)| w == "failed").unwrap();
    assert_eq!(log[failed], ("failed".to_string(), false));
    assert_eq!(
        log[..failed].last(),
        Some(&("pending 399".to_string(), false))
    );
    // Released: the queued rows are written at the next retry, none
    // lost.
    admin.execute_batch("COMMIT").unwrap();
    health.wait_for(Option::is_none).await.unwrap();
    // No rows pending was said while it still counted as failing.
    let log = watch.log();
    let cleared = log.iter().rev().find(|(w, _)| w == "pending 0");
    assert_eq!(cleared, Some(&("pending 0".to_string(), true)), "{log:?}");
    let conn = open_read(&path).unwrap();
    let n: i64 = conn
        .query_row("SELECT count(*) FROM state_history", [], |r| r.get(0))
        .unwrap();
    assert_eq!(n, 400);
}

#[test]
fn each_table_keeps_its_own_age_and_row_limit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("j.sqlite");
    let conn = schema::open(&path).unwrap();
    let now = crate::clock::now_ms() as i64;
    let day = 86_400_000i64;
    // 25,000 state rows over the last 25 days, 30 alarm events of the
    // last 30 days, 30 production rows likewise.
    conn.execute_batch("BEGIN").unwrap();
    for i in 0..25_000i64 {
        conn.execute(
            "INSERT INTO state_history (at_ms, kind, state) VALUES (?1, 'beat', 'running')",
            [now - 25 * day + i * day / 1000],
        )
        .unwrap();
    }
    for d in 0..30i64 {
        conn.execute(
            "INSERT INTO alarm_events (at_ms, alarm, kind, severity, transition, payload) VALUES (?1, 'ese', 'switching', 'high', 'raised', '{}')",
            [now - d * day - 1000],
        )
        .unwrap();
        conn.execute(
            "INSERT INTO production (at_ms) VALUES (?1)",
            [now - d * day - 1000],
        )
        .unwrap();
    }
    conn.execute_batch("COMMIT").unwrap();
    let mut keep = crate::journal::config::Keep::all(Duration::from_secs(20 * 86_400));
    for k in &mut keep {
        match k.table {
            // The newest 12,345 state rows, whatever their age.
            "state_history" => {
                k.age = Duration::from_secs(365 * 86_400);
                k.max_rows = Some(12_345);
            }
            "alarm_events" => k.age = Duration::from_secs(10 * 86_400),
            _ => {}
        }
    }
    schema::purge(&conn, &keep, &path);
    let count = |t: &str, since: i64| -> i64 {
        conn.query_row(
            &format!("SELECT count(*) FROM {t} WHERE at_ms >= ?1"),
            [since],
            |r| r.get(0),
        )
        .unwrap()
    };
    assert_eq!(count("state_history", 0), 12_345);
    let newest_kept: i64 = conn
        .query_row("SELECT min(seq) FROM state_history", [], |r| r.get(0))
        .unwrap();
    assert_eq!(newest_kept, 25_000 - 12_345 + 1);
    // Alarm events: the last 10 days (days 0..=9); production: 20 days.
    assert_eq!(count("alarm_events", 0), 10);
    assert_eq!(count("production", 0), 20);
}

/// A journal written before command digests were kept: opened, its
/// `commands` table gains the column, and its verified commands read back
/// with no digest (known by operator and action, `cell::answers`).
#[test]
fn commands_journaled_before_digests_read_back_without_one() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.sqlite");
    let old = Connection::open(&path).unwrap();
    old.execute_batch(
        "CREATE TABLE commands (seq INTEGER PRIMARY KEY AUTOINCREMENT, at_ms INTEGER NOT NULL, \
         operator TEXT NOT NULL, action TEXT NOT NULL, alarm TEXT NOT NULL, nonce TEXT NOT NULL, \
         accepted INTEGER NOT NULL, detail TEXT NOT NULL, verified INTEGER NOT NULL DEFAULT 0, \
         stage TEXT NOT NULL DEFAULT 'command');
         INSERT INTO commands (at_ms, operator, action, alarm, nonce, accepted, detail, verified) \
         VALUES (5000, 'kim', 'ack', 'ese', 'n1', 1, 'ack ese by kim', 1);",
    )
    .unwrap();
    drop(old);
    drop(open(&path).unwrap());
    let saved = saved(&open_read(&path).unwrap(), 0).unwrap();
    assert_eq!(
        saved.outcomes,
        [SavedOutcome {
            nonce: "n1".into(),
            operator: "kim".into(),
            action: "ack".into(),
            digest: None,
            at: 5000,
            outcome: Some((true, "ack ese by kim".into())),
        }]
    );
}
