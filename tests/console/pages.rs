//! The console's pages in a real browser: a fault shown live with its culprits,
//! acknowledged and shelved by an operator; what an operator may not do not
//! offered, and texts from the bus rendered inert.

use std::time::Duration;

use cellwatch::operator::OperatorKey;
use fantoccini::Locator;

use crate::browser;
use crate::spawned::Cell;
use crate::util::{bus_args, cellwatch};

use super::{answer, load_key, open, plant, ANA, HOSTILE};

/// The cell's command rows in its journal, as `cellwatch history` prints
/// them (JSON), asked as operator kim.
fn journaled_commands(cell: &Cell) -> Vec<serde_json::Value> {
    journal_rows(cell, "command")
}

/// The cell's rows of `kind` in its journal over the last 24 hours, as
/// `cellwatch history` prints them (JSON), asked as operator kim.
fn journal_rows(cell: &Cell, kind: &str) -> Vec<serde_json::Value> {
    let mut args = vec![
        "history",
        "--cell",
        "m01ps0004",
        "--kind",
        kind,
        "--since",
        "24h",
        "--all",
        "--json",
        "--timeout",
        "30",
    ];
    let bus = bus_args(&cell.dir, "operator-kim", cell.zenoh_port);
    args.extend(bus.iter().map(String::as_str));
    let run = cellwatch(&args);
    assert_eq!(run.code, 0, "{}", run.stderr);
    run.stdout
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .flat_map(|page| page["rows"].as_array().cloned().unwrap_or_default())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fault_shows_live_with_its_culprits_and_an_operator_acknowledges_and_shelves_it() {
    let d = tempfile::tempdir().unwrap();
    let p = plant(d.path()).await;
    let b = browser::start().await;
    // Before anyone signs in the page shows nothing of the plant, and
    // asks for a key.
    b.client.goto(&p.url).await.unwrap();
    b.wait_until(
        "the page asks to sign in",
        "return typeof S !== 'undefined' && S.started === true && document.getElementById('link').textContent === 'signed out';",
    )
    .await;
    assert!(b.text("#operator-name").await.contains("sign in"));
    b.screenshot("sign-in").await;
    assert_eq!(
        b.client
            .execute("return S.cells.size;", vec![])
            .await
            .unwrap(),
        serde_json::json!(0)
    );
    open(&b, &p, "#/alarms").await;
    // When each alarm's row first appears, by the page's clock (the same
    // machine's as the agent's).
    b.client
        .execute(
            "window.__seen = {}; new MutationObserver(() => { for (const r of document.querySelectorAll('tr[data-alarm]')) { if (!(r.dataset.alarm in window.__seen)) window.__seen[r.dataset.alarm] = Date.now(); } }).observe(document.getElementById('view'), { childList: true, subtree: true }); return true;",
            vec![],
        )
        .await
        .unwrap();
    p.sim.set("X0.06", false).unwrap();
    b.wait_for("tr[data-alarm='ese']").await;
    let late = b
        .client
        .execute(
            "const a = S.alarms.get('m01ps0004\\u0000ese'); return window.__seen['ese'] - Date.parse(a.raised_at);",
            vec![],
        )
        .await
        .unwrap();
    let late = late.as_f64().unwrap();
    assert!(
        late <= 1000.0,
        "the raise showed in the table {late} ms after it happened"
    );
    let row = b.text("tr[data-alarm='ese']").await;
    assert!(row.contains("Y Over Travel Limit SW (B)"), "{row}");
    assert!(row.contains("Active, unacknowledged"), "{row}");
    b.screenshot("alarms").await;

    // The overview and the cell page show it too.
    open(&b, &p, "#/").await;
    b.wait_until(
        "the tile counts the alarm",
        "const t = document.querySelector(\"a.tile[data-cell='m01ps0004']\"); return !!t && t.textContent.includes('ESE');",
    )
    .await;
    b.screenshot("overview").await;
    open(&b, &p, "#/cell/m01ps0004").await;
    b.wait_for("section.timeline svg rect").await;
    b.wait_until(
        "the cell page lists the alarm",
        "return [...document.querySelectorAll('#view a')].some(a => a.textContent === 'ese');",
    )
    .await;
    b.screenshot("cell").await;

    // The Agents page: what the agent says it runs, judged.
    open(&b, &p, "#/agents").await;
    b.wait_for("table.agents tbody tr").await;
    let agents = b.text("table.agents").await;
    assert!(
        agents.contains("m01ps0004")
            && agents.contains(env!("CARGO_PKG_VERSION"))
            && agents.contains("ok — cellwatch"),
        "{agents}"
    );
    b.screenshot("agents").await;

    // Its detail: the step, the culprits with their comments and values.
    open(&b, &p, "#/alarm/m01ps0004/ese").await;
    b.wait_for("table.culprits").await;
    let diagnosis = b.text("section.diagnosis").await;
    assert!(diagnosis.contains("ESE at step 6"), "{diagnosis}");
    assert!(
        diagnosis.contains("X0.06 Y Over Travel Limit SW (B) 0 1 trigger"),
        "{diagnosis}"
    );

    // Kim, signed in with her key, acknowledges with a comment: the
    // agent journals it under her, her words after what was done.
    b.wait_for("input[name='ack-comment']")
        .await
        .send_keys("limit switch cable re-seated")
        .await
        .unwrap();
    b.screenshot("alarm-ack").await;
    b.wait_for("button[data-action='ack']")
        .await
        .click()
        .await
        .unwrap();
    let said = answer(&b).await;
    assert!(said.starts_with("ack accepted"), "{said}");
    b.wait_until(
        "the page shows it acknowledged with her comment (and no longer offers to)",
        "return document.querySelector('dl.facts').textContent.includes('Acknowledged bykim: limit switch cable re-seated') && !document.querySelector(\"button[data-action='ack']\");",
    )
    .await;
    let rows = journaled_commands(&p.cell);
    assert!(
        rows.iter().any(|r| r["fields"]["action"] == "ack"
            && r["fields"]["operator"] == "kim"
            && r["fields"]["alarm"] == "ese"
            && r["fields"]["accepted"] == true
            && r["fields"]["detail"] == "ack ese by kim: limit switch cable re-seated"),
        "{rows:#?}"
    );

    // A shelf for 30 minutes, with a reason.
    b.wait_for("select[name='shelve-for']")
        .await
        .select_by_value("30m")
        .await
        .unwrap();
    b.wait_for("input[name='shelve-reason']")
        .await
        .send_keys("limit switch being replaced")
        .await
        .unwrap();
    b.wait_for("button[data-action='shelve']")
        .await
        .click()
        .await
        .unwrap();
    b.wait_until(
        "the page shows it shelved with its reason",
        "const a = S.alarms.get('m01ps0004\\u0000ese'); return !!a && !!a.shelved && a.shelved.reason === 'limit switch being replaced' && a.shelved.by === 'kim' && document.querySelector('dl.facts').textContent.includes('limit switch being replaced');",
    )
    .await;
    b.wait_until(
        "the detail lists the operator actions",
        "return document.querySelectorAll('table.actions-log tbody tr').length >= 2;",
    )
    .await;
    let facts = b.text("dl.facts").await;
    assert!(
        facts.contains("by kim until") && facts.contains("limit switch being replaced"),
        "{facts}"
    );
    // Its flight recording, journaled once complete (`recorder.after` after
    // the raise), drawn on the alarm's page: ESE's signals, X0.06 among
    // them, and the raise.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !journal_rows(&p.cell, "recording")
        .iter()
        .any(|r| r["fields"]["alarm"] == "ese")
    {
        assert!(
            std::time::Instant::now() < deadline,
            "ESE's recording never reached the journal"
        );
        tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    }
    open(&b, &p, "#/alarms").await;
    open(&b, &p, "#/alarm/m01ps0004/ese").await;
    b.wait_for("svg.recording-chart line.raise").await;
    let recording = b.text("section.recording").await;
    assert!(
        recording.contains("X0.06 x0_06") && recording.contains("signals ese's check reads"),
        "{recording}"
    );
    // The alarm's events say who acknowledged it, and what she said.
    let events = b.text("section.events").await;
    assert!(
        events.contains("kim: limit switch cable re-seated"),
        "{events}"
    );
    b.screenshot("alarm").await;
    b.client
        .execute(
            "document.querySelector('section.recording').scrollIntoView(); return true;",
            vec![],
        )
        .await
        .unwrap();
    b.screenshot("alarm-recording").await;
    assert!(journaled_commands(&p.cell)
        .iter()
        .any(|r| r["fields"]["action"] == "shelve" && r["fields"]["accepted"] == true));

    // The ISA-18.2 figures of the last 24 hours, asked of the agent: as
    // many raises as its journal has raised rows.
    open(&b, &p, "#/kpi").await;
    b.wait_for("table.kpi-cells tbody tr").await;
    let raised: usize = b.text("[data-kpi='raised']").await.parse().unwrap();
    let rows = journal_rows(&p.cell, "alarm");
    let in_journal = rows
        .iter()
        .filter(|r| r["fields"]["transition"] == "raised")
        .count();
    assert!(in_journal >= 1);
    assert_eq!(raised, in_journal, "{rows:#?}");
    // The same figures over the bus from the CLI.
    let mut args = vec![
        "history",
        "--cell",
        "m01ps0004",
        "--kind",
        "kpi",
        "--since",
        "24h",
        "--timeout",
        "30",
    ];
    let bus = bus_args(&p.cell.dir, "operator-kim", p.cell.zenoh_port);
    args.extend(bus.iter().map(String::as_str));
    let cli = cellwatch(&args);
    assert_eq!(cli.code, 0, "{}", cli.stderr);
    let figures: serde_json::Value = serde_json::from_str(&cli.stdout).unwrap();
    assert_eq!(figures["raised"], raised, "{figures:#}");
    let cells = b.text("table.kpi-cells").await;
    assert!(cells.contains("m01ps0004 machining"), "{cells}");
    b.screenshot("kpi").await;

    // A write from the cell page goes to the agent, which answers for it:
    // here a tag the cell does not have.
    open(&b, &p, "#/cell/m01ps0004").await;
    b.wait_for("input[name='write-tag']")
        .await
        .send_keys("X9.99")
        .await
        .unwrap();
    b.wait_for("input[name='write-value']")
        .await
        .send_keys("1")
        .await
        .unwrap();
    b.wait_for("button[data-action='write']")
        .await
        .click()
        .await
        .unwrap();
    assert_eq!(answer(&b).await, "write refused: no tag X9.99");

    // Today's production on the cell page, asked of the agent: as
    // `cellwatch report daily` reads it from the journal.
    let parts: u64 = b
        .wait_for("[data-production='parts']")
        .await
        .text()
        .await
        .unwrap()
        .parse()
        .unwrap();
    let today = chrono::Utc::now().format("%Y-%m-%d").to_string();
    let journal = p.cell.dir.join("journal.sqlite");
    let report = cellwatch(&[
        "report",
        "daily",
        "--date",
        &today,
        "--db",
        journal.to_str().unwrap(),
        "--causes",
        crate::util::root()
            .join("config/stop-causes.toml")
            .to_str()
            .unwrap(),
        "--json",
    ]);
    assert_eq!(report.code, 0, "{}", report.stderr);
    let report: serde_json::Value = serde_json::from_str(&report.stdout).unwrap();
    assert_eq!(report["production"], parts);

    // The current shift's OEE (the demo's [oee]: early 06-14, late 14-22,
    // night 22-06 UTC), as the agent's snapshot carries it.
    let oee = b
        .wait_for("[data-oee='availability']")
        .await
        .text()
        .await
        .unwrap();
    let shown = |t: &str| {
        t == "—"
            || t.strip_suffix(" %")
                .is_some_and(|p| p.parse::<f64>().is_ok())
    };
    assert!(shown(&oee), "{oee}");
    let shift = || {
        let hour = chrono::Utc::now().format("%H").to_string();
        match hour.parse::<u32>().unwrap() {
            6..=13 => "early",
            14..=21 => "late",
            _ => "night",
        }
    };
    let before = shift();
    let heading = b.text("section.oee h3").await;
    // (The shift may change while it is read.)
    assert!(
        [before, shift()]
            .iter()
            .any(|s| heading.starts_with(&format!("OEE of the {s} shift"))),
        "{heading}"
    );
    b.client
        .execute(
            "document.querySelector('section.oee').scrollIntoView(); return true;",
            vec![],
        )
        .await
        .unwrap();
    b.screenshot("oee").await;

    // A timed transition taken far too early (F17.01 falls at once instead
    // of 60 s after F17.00): its measurement shows against its window.
    b.wait_for("tr[data-timer='tmr-001']").await;
    p.sim.set("F17.00", false).unwrap();
    // The transition arms on the state the PLC reports: wait for it.
    b.wait_until(
        "the page's snapshot has F17.00 off",
        "return !!S.view.snap && S.view.snap.tags.some(t => t.address === 'F17.00' && t.value === false);",
    )
    .await;
    p.sim.set("F17.01", false).unwrap();
    b.wait_for("tr[data-timer='tmr-001'] .m.early").await;
    let row = b.text("tr[data-timer='tmr-001']").await;
    assert!(row.contains("60.0 – 70.0"), "{row}");
    b.client
        .execute(
            "document.querySelector('section.timers').scrollIntoView(); return true;",
            vec![],
        )
        .await
        .unwrap();
    b.screenshot("timers").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn what_an_operator_may_not_do_is_not_offered_and_bus_texts_render_inert() {
    let d = tempfile::tempdir().unwrap();
    let p = plant(d.path()).await;
    let b = browser::start().await;
    // CSD, whose culprit's comment is hostile markup.
    // The cell page, watched for when CSD's row first appears.
    open(&b, &p, "#/cell/m01ps0004").await;
    b.wait_for("section.timeline svg").await;
    b.client
        .execute(
            "window.__seen = null; new MutationObserver(() => { if (window.__seen === null && [...document.querySelectorAll('#view a')].some(a => a.textContent === 'csd')) window.__seen = Date.now(); }).observe(document.getElementById('view'), { childList: true, subtree: true }); return true;",
            vec![],
        )
        .await
        .unwrap();
    // Auto mode left for JOG, cycle start pressed: CSD, with the contacts
    // the changes as they arrive make its culprits.
    p.sim.set("X201.02", false).unwrap();
    p.sim.set("X201.06", true).unwrap();
    p.sim.set("X200.01", true).unwrap();
    b.wait_until(
        "CSD shows on the cell page",
        "return window.__seen !== null;",
    )
    .await;
    let late = b
        .client
        .execute(
            "const a = S.alarms.get('m01ps0004\\u0000csd'); return window.__seen - Date.parse(a.raised_at);",
            vec![],
        )
        .await
        .unwrap()
        .as_f64()
        .unwrap();
    assert!(
        late <= 1000.0,
        "the raise showed on the cell page {late} ms after it happened"
    );
    open(&b, &p, "#/alarms").await;
    b.wait_until(
        "CSD is shown with its culprits",
        "const a = S.alarms.get('m01ps0004\\u0000csd'); return !!a && a.culprits.length > 0 && !!document.querySelector(\"tr[data-alarm='csd']\");",
    )
    .await;
    open(&b, &p, "#/alarm/m01ps0004/csd").await;
    b.wait_for("table.culprits").await;
    let culprits = b.text("table.culprits").await;
    assert!(culprits.contains(HOSTILE), "{culprits}");
    let pwned = b
        .client
        .execute(
            "return [typeof window.__pwned, document.querySelectorAll('#view img, #view script').length];",
            vec![],
        )
        .await
        .unwrap();
    assert_eq!(pwned, serde_json::json!(["undefined", 0]));

    // Ana may acknowledge only: nothing else is offered her.
    load_key(&b, &d.path().join("ana.key"), "ana").await;
    b.wait_for("button[data-action='ack']").await;
    for action in [
        "shelve",
        "out-of-service",
        "reset",
        "unshelve",
        "in-service",
    ] {
        assert_eq!(
            b.count(&format!("[data-action='{action}']")).await,
            0,
            "{action} offered to ana"
        );
    }
    assert!(b
        .text("#operator-name")
        .await
        .contains("operator ana (ack)"));
    // A shelve she makes by hand, signed with her key, is refused by the
    // agent, which journals the refusal.
    let answer = b
        .client
        .execute_async(
            "const done = arguments[arguments.length - 1]; sign('m01ps0004', { action: 'shelve', alarm: 'csd', value: '30m', reason: 'by hand' }).then(cmd => fetch('/api/cells/m01ps0004/command', { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(cmd) })).then(r => r.json()).then(done, e => done(String(e)));",
            vec![],
        )
        .await
        .unwrap();
    assert_eq!(answer["accepted"], false, "{answer}");
    assert!(
        answer["detail"]
            .as_str()
            .unwrap_or_default()
            .contains("operator 'ana' may not shelve"),
        "{answer}"
    );
    assert!(journaled_commands(&p.cell)
        .iter()
        .any(|r| r["fields"]["operator"] == "ana"
            && r["fields"]["action"] == "shelve"
            && r["fields"]["accepted"] == false));
    // A key that is not the operators file's for that name is refused in
    // the page.
    let forged = d.path().join("forged.key");
    std::fs::write(
        &forged,
        OperatorKey::from_hex("kim", ANA).unwrap().to_file(),
    )
    .unwrap();
    b.client
        .find(Locator::Css("#key-file"))
        .await
        .unwrap()
        .send_keys(forged.to_str().unwrap())
        .await
        .unwrap();
    b.wait_until(
        "the forged key is refused",
        "return S.key === null && document.getElementById('operator-name').textContent.includes('not the key the operators file holds');",
    )
    .await;
    // Every response forbids inline script and HTML sinks, framing and
    // sniffing.
    let headers = head(&p.url);
    for expected in [
        "content-security-policy: default-src 'none'; script-src 'self';",
        "require-trusted-types-for 'script'",
        "x-frame-options: DENY",
        "x-content-type-options: nosniff",
    ] {
        assert!(headers.contains(expected), "{expected} not in:\n{headers}");
    }
}

/// The response head of `GET /` at `url` (`http://IP:PORT/`).
fn head(url: &str) -> String {
    use std::io::{Read, Write};
    let addr = url.trim_start_matches("http://").trim_end_matches('/');
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    s.write_all(b"GET / HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n")
        .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    text.split("\r\n\r\n")
        .next()
        .unwrap_or_default()
        .to_string()
}
