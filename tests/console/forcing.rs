//! A stuck step drawn on the cell page and forced from it, once its condition
//! holds, by an operator who may force.

use std::time::Duration;

use crate::browser;
use crate::spawned::kim;
use crate::util::{bus_pki, trust_file};

use super::{answer, load_key, open_at};

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
