//! `cellwatch console` end to end: the real agent and console binaries on
//! the simulated CNC, a real headless Chromium on the console's pages
//! (`browser`), operators' keys loaded into the page and commands signed
//! there with WebCrypto Ed25519.

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use cellwatch::operator::{Action, OperatorKey};
use cellwatch::sim::cnc::SimulatedCnc;
use fantoccini::Locator;

use crate::browser::{self, Browser};
use crate::spawned::{self, kim, Cell};
use crate::util::{bus_args, bus_pki, bus_tls, cellwatch, trust_file};

/// Operator ana may acknowledge, nothing else.
const ANA: &str = "ffeeddccbbaa99887766554433221100ffeeddccbbaa99887766554433221100";

/// What a hostile comment in an I/O list would do if the page made HTML
/// of it.
const HOSTILE: &str = "<script>window.__pwned=1</script><img src=x onerror=window.__pwned=2>";

/// The agent, the console and their files.
struct Plant {
    sim: SimulatedCnc,
    cell: Cell,
    agent: Child,
    console: Child,
    url: String,
}

impl Drop for Plant {
    fn drop(&mut self) {
        for child in [&mut self.console, &mut self.agent] {
            let _ = child.kill();
            let _ = child.wait();
        }
        self.sim.stop();
    }
}

/// The simulated CNC, its agent (kim may do everything, ana only
/// acknowledge; every comment of the CSD check's I/O list ends with [`HOSTILE`]) and
/// a console on it, on ports the system picks.
async fn plant(dir: &Path) -> Plant {
    plant_with(dir, "", "").await
}

/// [`plant`] with `http` added to the console's `[http]` section and
/// `sections` at the end of its configuration.
async fn plant_with(dir: &Path, http: &str, sections: &str) -> Plant {
    let (sim, mut cell) = spawned::start(dir).await;
    let ana = OperatorKey::from_hex("ana", ANA).unwrap();
    let operators = dir.join("operators.toml");
    let all =
        std::fs::read_to_string(&operators).unwrap() + "\n" + &ana.operators_entry(&[Action::Ack]);
    std::fs::write(&operators, all).unwrap();
    std::fs::write(dir.join("kim.key"), kim().to_file()).unwrap();
    std::fs::write(dir.join("ana.key"), ana.to_file()).unwrap();
    // Every comment of the CSD machine's I/O list ends with it: whichever
    // contacts CSD names, their comments carry it.
    let csd: String =
        std::fs::read_to_string(crate::util::root().join("config/cnc/csd-comments.csv"))
            .unwrap()
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i == 0 {
                    format!("{l}\n")
                } else {
                    format!("{l} {HOSTILE}\n")
                }
            })
            .collect();
    std::fs::write(dir.join("csd-comments.csv"), csd).unwrap();
    let config = std::fs::read_to_string(&cell.config).unwrap().replace(
        &format!(
            "{}/config/cnc/csd-comments.csv",
            crate::util::root().display()
        ),
        &dir.join("csd-comments.csv").display().to_string(),
    );
    std::fs::write(&cell.config, config).unwrap();
    let agent = cell.spawn("agent.log").await;

    let trust = trust_file(dir);
    bus_pki(dir, &["console"]);
    let tls = bus_tls(dir, "console");
    std::fs::write(
        dir.join("console.toml"),
        format!(
            "[http]\nlisten = \"127.0.0.1:0\"\n{http}\n\n[bus]\nconnect = [\"quic/127.0.0.1:{}\"]\ntrust = {:?}\ntls = {{ ca = {:?}, cert = {:?}, key = {:?} }}\n\n[operators]\nfile = {:?}\n\n[areas]\nmachining = [\"m01ps0004\"]\n{sections}\n",
            cell.zenoh_port, trust, tls.ca, tls.cert, tls.key, operators
        ),
    )
    .unwrap();
    let mut console = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["console", "--config"])
        .arg(dir.join("console.toml"))
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.join("console.log")).unwrap())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufReader::new(console.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let url = first
        .trim()
        .strip_prefix("cellwatch console: ")
        .unwrap_or_else(|| {
            panic!(
                "the console said {first:?}:\n{}",
                std::fs::read_to_string(dir.join("console.log")).unwrap_or_default()
            )
        })
        .to_string();
    assert!(url.contains("://127.0.0.1:"), "{url}");
    Plant {
        sim,
        cell,
        agent,
        console,
        url,
    }
}

/// Opens `route` of the console, signed in as kim, and waits until its
/// live stream runs and the cell's agent is known to be there.
async fn open(b: &Browser, p: &Plant, route: &str) {
    let key = p.cell.dir.join("kim.key");
    open_at(b, &p.url, "m01ps0004", route, &key, "kim").await;
}

/// Opens `route` of the console at `url`, as [`open`], for `cell`,
/// signed in with `key` (of `operator`) unless a key is loaded already.
async fn open_at(b: &Browser, url: &str, cell: &str, route: &str, key: &Path, operator: &str) {
    b.client.goto(&format!("{url}{route}")).await.unwrap();
    b.wait_until(
        "the page knows whether it is signed in",
        "return typeof S !== 'undefined' && S.started === true;",
    )
    .await;
    let loaded = b
        .client
        .execute("return S.key !== null;", vec![])
        .await
        .unwrap();
    if loaded != serde_json::json!(true) {
        load_key(b, key, operator).await;
    }
    b.wait_for("#link.up").await;
    b.wait_until(
        "the console knows the agent is up",
        &format!("return typeof S !== 'undefined' && S.cells.has('{cell}') && S.cells.get('{cell}').agent === true;"),
    )
    .await;
}

/// Loads the operator key file `key` into the page.
async fn load_key(b: &Browser, key: &Path, operator: &str) {
    b.client
        .find(Locator::Css("#key-file"))
        .await
        .unwrap()
        .send_keys(key.to_str().unwrap())
        .await
        .unwrap();
    b.wait_until(
        "the key is loaded",
        &format!("return S.key !== null && S.key.operator === '{operator}';"),
    )
    .await;
}

/// The answer line after an action, once the agent answered.
async fn answer(b: &Browser) -> String {
    b.wait_until(
        "the agent answered",
        "const a = document.getElementById('answer'); return !!a && (a.classList.contains('accepted') || a.classList.contains('refused'));",
    )
    .await;
    b.text("#answer").await
}

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

/// With `http.tls`, the console serves HTTPS only, with the certificate
/// given (here from the plant CA), and says so to browsers (HSTS).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_certificate_the_console_serves_https_only() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    let d = tempfile::tempdir().unwrap();
    bus_pki(d.path(), &["console"]);
    let tls = bus_tls(d.path(), "console");
    let p = plant_with(
        d.path(),
        &format!("tls = {{ cert = {:?}, key = {:?} }}", tls.cert, tls.key),
        "",
    )
    .await;
    assert!(p.url.starts_with("https://127.0.0.1:"), "{}", p.url);
    let addr = p.url.trim_start_matches("https://").trim_end_matches('/');
    let mut roots = rustls::RootCertStore::empty();
    roots
        .add(rustls::pki_types::CertificateDer::from_pem_file(&tls.ca).unwrap())
        .unwrap();
    let config = rustls::ClientConfig::builder_with_provider(std::sync::Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .unwrap()
    .with_root_certificates(roots)
    .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut stream = connector
        .connect("127.0.0.1".try_into().unwrap(), tcp)
        .await
        .expect("the console's certificate, checked against the plant CA");
    stream
        .write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut text = Vec::new();
    let _ = stream.read_to_end(&mut text).await;
    let text = String::from_utf8_lossy(&text);
    assert!(text.starts_with("HTTP/1.1 200 OK"), "{text}");
    assert!(
        text.contains("strict-transport-security: max-age=31536000"),
        "{text}"
    );
    assert!(text.contains("<title>cellwatch console</title>"), "{text}");
    // Plain HTTP on the same port gets no page.
    let mut plain = tokio::net::TcpStream::connect(addr).await.unwrap();
    plain
        .write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut got = Vec::new();
    let _ = plain.read_to_end(&mut got).await;
    assert!(!String::from_utf8_lossy(&got).contains("cellwatch console"));
}

/// The robot's cell page draws its charts live; a stuck step's forcible
/// transition is offered to an operator who may force (not to one who may
/// not, whose hand-made request the agent refuses), refused while its
/// condition is false and carried out once it holds.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stuck_step_is_drawn_and_forced_from_the_cell_page_once_its_condition_holds() {
    use crate::force::{supervise, RobotCell, CELL};
    let d = tempfile::tempdir().unwrap();
    // S2 is in error from the start and the shuttle not yet at its
    // waiting position (t3 false); its supervision shortened to 2 s.
    let cell = RobotCell::start(
        d.path(),
        Duration::from_millis(200),
        |robot| {
            robot.stick("F1.S2", true).unwrap();
            robot.pin("%IX0.0.3", Some(false));
        },
        |c| supervise(c, 0, "S2", 2000),
    )
    .await;
    let port = crate::util::agent_port(&cell.agent).await;
    bus_pki(d.path(), &["console"]);
    let console = cellwatch::console::Console::start(&cellwatch::console::ConsoleConfig {
        listen: "127.0.0.1:0".parse().unwrap(),
        tls: None,
        bus: crate::util::client_config(d.path(), "console", port),
        trust: trust_file(d.path()),
        root: "cellwatch".into(),
        operators_file: Some(d.path().join("operators.toml")),
        areas: Default::default(),
        max_alarms: 1000,
        session: cellwatch::console::config::DEFAULT_SESSION,
        names: Vec::new(),
        readers: None,
        deployed: None,
    })
    .await
    .unwrap();
    std::fs::write(d.path().join("kim.key"), kim().to_file()).unwrap();
    std::fs::write(d.path().join("lee.key"), cell.lee.to_file()).unwrap();
    let b = browser::start().await;
    let lee = d.path().join("lee.key");
    open_at(
        &b,
        &console.url(),
        CELL,
        &format!("#/cell/{CELL}"),
        &lee,
        "lee",
    )
    .await;
    b.wait_for(".sfc-step.stuck[data-step='F1.S2']").await;
    b.wait_for("[data-transition='F1.t3'].waits").await;
    let t3 = b.text("[data-transition='F1.t3']").await;
    assert!(
        t3.contains("%IX0.0.3 = 0 (Shuttle at waiting position)"),
        "{t3}"
    );

    // Lee may only acknowledge: no force is offered her, and one she
    // signs by hand is refused by the agent.
    load_key(&b, &d.path().join("lee.key"), "lee").await;
    assert_eq!(b.count("button[data-action='force']").await, 0);
    let by_hand = b
        .client
        .execute_async(
            &format!("const done = arguments[arguments.length - 1]; sign('{CELL}', {{ action: 'force', value: 'F1.t3' }}).then(cmd => fetch('/api/cells/{CELL}/command', {{ method: 'POST', headers: {{ 'Content-Type': 'application/json' }}, body: JSON.stringify(cmd) }})).then(r => r.json()).then(done, e => done(String(e)));"),
            vec![],
        )
        .await
        .unwrap();
    assert_eq!(by_hand["accepted"], false, "{by_hand}");
    assert_eq!(
        by_hand["detail"], "operator 'lee' may not force",
        "{by_hand}"
    );

    // Kim may: refused while t3 is false, for that reason.
    load_key(&b, &d.path().join("kim.key"), "kim").await;
    b.wait_for("[data-transition='F1.t3'] button[data-action='force']")
        .await
        .click()
        .await
        .unwrap();
    let said = answer(&b).await;
    assert!(
        said.starts_with(
            "force refused: condition: t3 (Shuttle at waiting position) does not hold"
        ),
        "{said}"
    );
    b.client
        .execute(
            "document.querySelector(\"[data-chart='F1']\").scrollIntoView(); return true;",
            vec![],
        )
        .await
        .unwrap();
    b.screenshot("sfc").await;

    // The shuttle arrives (arm 1 held at its sub-job, so that the arrival
    // can be seen): t3 holds on the page, and the force is carried out.
    cell.robot.pin("%IX0.1.0", Some(false));
    cell.robot.pin("%IX0.0.3", None);
    b.wait_for("[data-transition='F1.t3'].holds").await;
    b.client
        .execute(
            "document.getElementById('answer').className = 'answer';",
            vec![],
        )
        .await
        .unwrap();
    b.wait_for("[data-transition='F1.t3'] button[data-action='force']")
        .await
        .click()
        .await
        .unwrap();
    let said = answer(&b).await;
    assert!(said.starts_with("force accepted: F1.t3 forced"), "{said}");
    b.wait_for(".sfc-step.active[data-step='F2.S5']").await;
    console.stop().await;
    cell.stop().await;
}

/// The console's own session sends no put and declares no queryable (its
/// access control, egress): it reads the bus and asks, nothing more. A
/// query it sends after its put reaches the other side, the put does not.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_session_puts_nothing_and_answers_nothing() {
    let plain = |connect: Vec<String>, listen: Vec<String>| cellwatch::config::ZenohConfig {
        mode: cellwatch::config::ZenohMode::Peer,
        connect,
        listen,
        prefix: String::new(),
        multicast_scouting: false,
        tls: None,
        config_file: None,
        plain: true,
        signing_key: None,
    };
    let bus = cellwatch::bus::open(&plain(vec![], vec!["tcp/127.0.0.1:0".into()]))
        .await
        .unwrap();
    let endpoint = bus.info().locators().await[0].to_string();
    let puts = bus.declare_subscriber("cellwatch/**").await.unwrap();
    let asked = bus
        .declare_queryable("cellwatch/m01/snapshot")
        .await
        .unwrap();
    let console = cellwatch::bus::open_console(&plain(vec![endpoint], vec![]))
        .await
        .unwrap();
    // What a cell's agent would say, said by the console.
    console
        .put("cellwatch/m01/alarms/ese", "forged")
        .await
        .unwrap();
    let queryable = console.declare_queryable("cellwatch/m01/history").await;
    // Then a query, which is allowed: once it has arrived, so would have
    // the put before it on the same link.
    let replies = console
        .get("cellwatch/m01/snapshot")
        .timeout(Duration::from_secs(30))
        .await
        .unwrap();
    let query = asked.recv_async().await.unwrap();
    query
        .reply("cellwatch/m01/snapshot", "answered")
        .await
        .unwrap();
    // The query ends (its final message) when it is dropped.
    drop(query);
    let reply = replies.recv_async().await.unwrap();
    assert!(
        reply.result().is_ok(),
        "{:?}",
        reply
            .result()
            .err()
            .map(|e| e.payload().try_to_string().map(|s| s.to_string()))
    );
    assert!(
        puts.try_recv().unwrap().is_none(),
        "the console's put arrived"
    );
    // Its queryable, if Zenoh declared it locally, is never known outside.
    let mut answers = bus
        .get("cellwatch/m01/history")
        .timeout(Duration::from_secs(2))
        .await
        .unwrap();
    assert!(answers.recv_async().await.is_err(), "the console answered");
    drop((queryable, &mut answers));
}

/// One HTTP/1.1 request to `addr` (`IP:PORT`) as written in `head` (the
/// `Connection: close` and length added), and its status, head and body.
pub(crate) fn request(addr: &str, head: &str, body: &str) -> (u16, String, String) {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    let text = format!(
        "{head}\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    s.write_all(text.as_bytes()).unwrap();
    let mut got = String::new();
    let _ = s.read_to_string(&mut got);
    let (head, body) = got.split_once("\r\n\r\n").unwrap_or((&got, ""));
    let status = head
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, head.to_string(), body.to_string())
}

/// Signs `operator` (key file `key`) in over HTTP as the page does, and
/// returns the session's `Cookie` header line.
pub(crate) fn sign_in(addr: &str, key: &Path) -> Result<String, (u16, String)> {
    use ed25519_dalek::Signer;
    let file =
        cellwatch::operator::OperatorKey::parse("key", &std::fs::read_to_string(key).unwrap())
            .unwrap();
    let seed = std::fs::read_to_string(key)
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("private_key = \""))
        .map(|l| l.trim_end_matches('"').to_string())
        .unwrap();
    let signing =
        ed25519_dalek::SigningKey::from_bytes(&hex::decode(seed).unwrap().try_into().unwrap());
    let host = format!("Host: {addr}");
    let (_, _, body) = request(
        addr,
        &format!("POST /api/sign-in/challenge HTTP/1.1\r\n{host}"),
        "",
    );
    let challenge = serde_json::from_str::<serde_json::Value>(&body).unwrap()["challenge"]
        .as_str()
        .unwrap()
        .to_string();
    let text = format!("cellwatch-console-sign-in-v1\n{challenge}\n{addr}\n");
    let signature = hex::encode(signing.sign(text.as_bytes()).to_bytes());
    let answer = serde_json::json!({ "operator": file.operator, "challenge": challenge, "signature": signature });
    let (status, head, body) = request(
        addr,
        &format!("POST /api/sign-in HTTP/1.1\r\n{host}\r\nContent-Type: application/json"),
        &answer.to_string(),
    );
    if status != 200 {
        return Err((status, body));
    }
    let cookie = head
        .lines()
        .find_map(|l| l.strip_prefix("set-cookie: "))
        .and_then(|c| c.split(';').next())
        .unwrap()
        .to_string();
    Ok(format!("Cookie: {cookie}"))
}

/// Nothing of the plant without a plant identity: every route under
/// `/api/` refuses a client that has not signed in (the page itself holds
/// nothing), a request for another host name (DNS rebinding) or from
/// another site's page is refused, a reader sees only the cells
/// `[readers]` gives it, an operator signs in only with the key the
/// operators file holds, and one client's share of the console is bounded.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_console_serves_nothing_without_a_plant_identity_and_each_reader_its_cells() {
    let d = tempfile::tempdir().unwrap();
    // A second cell in the trust file (its agent not running), which ana
    // alone reads.
    std::fs::create_dir(d.path().join("press7")).unwrap();
    cellwatch::bus::envelope::AgentKey::load_or_create(
        &d.path().join("press7/press7.agent.key"),
        "press7",
    )
    .unwrap();
    let p = plant_with(
        d.path(),
        "",
        &format!(
            "press-shop = [\"press7\"]\n\n[readers]\nkim = [\"*\"]\nana = [\"press-shop\"]\n\n[plant]\ndeployed = {:?}\n",
            d.path().join("plant-deployed.json")
        ),
    )
    .await;
    let addr = p
        .url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let host = format!("Host: {addr}");
    let get = |path: &str, extra: &str| {
        let extra = if extra.is_empty() {
            String::new()
        } else {
            format!("\r\n{extra}")
        };
        request(&addr, &format!("GET {path} HTTP/1.1\r\n{host}{extra}"), "")
    };

    // Anonymous: the page, yes; the plant, no.
    assert_eq!(get("/", "").0, 200);
    for path in [
        "/api/plant",
        "/api/operators",
        "/api/kpi?since=24h",
        "/api/cells/m01ps0004/snapshot",
        "/api/cells/m01ps0004/history?kind=command&since=24h",
        "/api/events",
        "/api/agents",
    ] {
        let (status, _, body) = get(path, "");
        assert_eq!(status, 401, "{path}: {body}");
        assert!(body.contains("sign in first"), "{path}: {body}");
    }
    let (status, _, _) = request(
        &addr,
        &format!("POST /api/cells/m01ps0004/command HTTP/1.1\r\n{host}\r\nContent-Type: application/json"),
        "{}",
    );
    assert_eq!(status, 401);

    // Kim signs in with her key: she reads everything.
    let kim = sign_in(&addr, &d.path().join("kim.key")).expect("kim signs in");
    let (status, _, body) = get("/api/plant", &kim);
    assert_eq!(status, 200, "{body}");
    let view: serde_json::Value = serde_json::from_str(&body).unwrap();
    let cells: Vec<&str> = view["cells"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["cell"].as_str().unwrap())
        .collect();
    assert_eq!(cells, ["m01ps0004", "press7"], "{body}");
    assert_eq!(get("/api/cells/m01ps0004/snapshot", &kim).0, 200);
    let (_, _, mine) = get("/api/operators", &kim);
    assert!(
        mine.contains("\"operator\":\"kim\"") && !mine.contains("ana"),
        "{mine}"
    );
    // A window further back than a month is not asked of the agents.
    let (status, _, body) = get("/api/kpi?since=1970-01-01T00:00:00Z", &kim);
    assert_eq!(status, 400, "{body}");

    // The Agents page: each agent's about judged against what the plant
    // deployed. No such file yet: said, and the agent judged without it.
    let agents = |who: &str| {
        let (status, _, body) = get("/api/agents", who);
        assert_eq!(status, 200, "{body}");
        serde_json::from_str::<serde_json::Value>(&body).unwrap()
    };
    let of = |v: &serde_json::Value, cell: &str| {
        v["cells"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["cell"] == cell)
            .cloned()
            .unwrap_or_else(|| panic!("no {cell} in {v}"))
    };
    let v = agents(&kim);
    assert!(
        v["deployed"]["error"]
            .as_str()
            .unwrap()
            .contains("plant-deployed.json"),
        "{v}"
    );
    assert_eq!(
        of(&v, "m01ps0004")["problems"],
        serde_json::json!([]),
        "{v}"
    );
    assert_eq!(
        of(&v, "press7")["problems"],
        serde_json::json!(["its agent is not on the bus"]),
        "{v}"
    );
    // Deployed: another configuration than the one it runs.
    let deployed = |sha: &str| {
        let cell = serde_json::json!({
            "config": "hosts/h1/etc/cellwatch/m01ps0004.toml",
            "config_sha256": { "Ok": sha },
            "bus_certificate": "hosts/h1/etc/cellwatch/agent-m01ps0004.pem",
            "bus_certificate_sha256": null,
            "signing_key": "hosts/h1/var/lib/cellwatch/m01ps0004/signing.key",
            "rotated_from": [],
        });
        std::fs::write(
            d.path().join("plant-deployed.json"),
            serde_json::json!({
                "schema": "cellwatch.plant-deployed.v1",
                "operators_version": null,
                "cells": { "m01ps0004": cell },
            })
            .to_string(),
        )
        .unwrap();
    };
    deployed(&"0".repeat(64));
    let m01 = of(&agents(&kim), "m01ps0004");
    assert!(
        m01["problems"][0]
            .as_str()
            .unwrap()
            .contains("runs another configuration than hosts/h1/etc/cellwatch/m01ps0004.toml"),
        "{m01}"
    );
    // The one it runs, by its own hash, computed here.
    use sha2::Digest;
    let runs = hex::encode(sha2::Sha256::digest(std::fs::read(&p.cell.config).unwrap()));
    deployed(&runs);
    let m01 = of(&agents(&kim), "m01ps0004");
    assert_eq!(m01["problems"], serde_json::json!([]), "{m01}");
    assert!(
        m01["facts"]
            .as_array()
            .unwrap()
            .contains(&serde_json::json!("runs the configuration deployed")),
        "{m01}"
    );
    assert_eq!(m01["about"]["config_sha256"], runs.as_str());

    // The same cookie under another host name, or from another site's
    // page, gets nothing.
    let (status, _, _) = request(
        &addr,
        &format!(
            "GET /api/plant HTTP/1.1\r\nHost: attacker.example:{}\r\n{kim}",
            addr.rsplit(':').next().unwrap()
        ),
        "",
    );
    assert_eq!(status, 421);
    let (status, _, _) = get(
        "/api/plant",
        &format!("{kim}\r\nOrigin: http://attacker.example"),
    );
    assert_eq!(status, 403);

    // Ana reads the press shop only.
    let ana = sign_in(&addr, &d.path().join("ana.key")).expect("ana signs in");
    let (_, _, body) = get("/api/plant", &ana);
    assert!(!body.contains("m01ps0004"), "{body}");
    let (_, _, body) = get("/api/agents", &ana);
    assert!(
        !body.contains("m01ps0004") && body.contains("press7"),
        "{body}"
    );
    let (status, _, body) = get("/api/cells/m01ps0004/snapshot", &ana);
    assert_eq!(status, 403, "{body}");
    // Nor does she forward kim's commands.
    let (status, _, body) = request(
        &addr,
        &format!("POST /api/cells/press7/command HTTP/1.1\r\n{host}\r\n{ana}\r\nContent-Type: application/json"),
        &serde_json::json!({"action": "ack", "alarm": "x", "operator": "kim", "nonce": "00", "issued_at": 0, "signature": "00"}).to_string(),
    );
    assert_eq!(status, 403, "{body}");

    // A key that is not the operators file's signs nobody in.
    let forged = cellwatch::operator::OperatorKey::generate("kim");
    std::fs::write(d.path().join("forged.key"), forged.to_file()).unwrap();
    let (status, body) = sign_in(&addr, &d.path().join("forged.key")).unwrap_err();
    assert_eq!(status, 403);
    assert!(
        body.contains("not the key the operators file holds for 'kim'"),
        "{body}"
    );

    // One identity holds at most 8 live streams.
    let streams: Vec<std::net::TcpStream> = (0..8)
        .map(|_| {
            use std::io::{BufRead, Write};
            let mut s = std::net::TcpStream::connect(&addr).unwrap();
            s.write_all(format!("GET /api/events HTTP/1.1\r\n{host}\r\n{kim}\r\n\r\n").as_bytes())
                .unwrap();
            let mut first = String::new();
            std::io::BufReader::new(s.try_clone().unwrap())
                .read_line(&mut first)
                .unwrap();
            assert!(first.starts_with("HTTP/1.1 200"), "{first}");
            s
        })
        .collect();
    let (status, _, body) = get("/api/events", &kim);
    assert_eq!(status, 429, "{body}");
    drop(streams);

    // One address gets 100 requests at once, then 20 a second.
    let refused = (0..150)
        .map(|_| get("/api/session", &kim).0)
        .filter(|s| *s == 429)
        .count();
    assert!(refused > 0, "no request of 150 was refused");
}
