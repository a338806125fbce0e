//! The console rings (ISA-101): a new unacknowledged high or critical
//! alarm sounds until an operator silences it on the page, which
//! acknowledges nothing; the header counts the unacknowledged and the
//! overdue (past the response time of the cell's master alarm database),
//! and the alarm's page says what to do and within what time.

use super::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_new_critical_alarm_rings_until_silenced_and_its_guidance_and_lateness_show() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("madb.csv"),
        "id,priority,class,consequence_of_inaction,corrective_action,response_time\n\
         ese,,safety,the machine stays stopped,Drive the Y axis off its limit switch in JOG,1s\n",
    )
    .unwrap();
    let p = plant_with_cell(d.path(), "", "", "\n[alarms]\ndatabase = \"madb.csv\"\n").await;
    let b = crate::browser::start().await;
    open(&b, &p, "#/alarms").await;
    b.wait_until(
        "nothing rings",
        "return document.body.dataset.ringing === 'no';",
    )
    .await;
    p.sim.set("X0.06", false).unwrap();
    b.wait_until(
        "ESE rings",
        "return document.body.dataset.ringing === 'yes' && !document.getElementById('silence').hidden;",
    )
    .await;
    // Its response time (1 s) passes unacknowledged: overdue.
    b.wait_until(
        "the header counts it overdue",
        "return document.getElementById('banner').textContent.includes('1 unacknowledged, 1 overdue');",
    )
    .await;
    // The table's row says it too, without an event to redraw it.
    b.wait_until(
        "the row says overdue",
        "const r = document.querySelector(\"tr[data-alarm='ese']\"); return !!r && r.textContent.includes('OVERDUE');",
    )
    .await;
    b.screenshot("ringing").await;
    open(&b, &p, "#/alarm/m01ps0004/ese").await;
    b.wait_for("dl.facts .guidance").await;
    let facts = b.text("dl.facts").await;
    assert!(
        facts.contains("Drive the Y axis off its limit switch in JOG (within 1s)")
            && facts.contains("the machine stays stopped")
            && facts.contains("safety")
            && facts.contains("OVERDUE (response time 1s)"),
        "{facts}"
    );
    b.screenshot("guidance").await;
    // Silenced: the horn stops, the alarm stays unacknowledged.
    b.client
        .find(Locator::Css("#silence"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    b.wait_until(
        "silenced",
        "return document.body.dataset.ringing === 'no' && document.getElementById('silence').hidden;",
    )
    .await;
    let state = b
        .client
        .execute("return S.alarms.get('m01ps0004\\u0000ese').state;", vec![])
        .await
        .unwrap();
    assert_eq!(state, serde_json::json!("active_unacknowledged"));
    assert!(b.text("#banner").await.contains("1 unacknowledged"));
}
