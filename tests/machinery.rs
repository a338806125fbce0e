//! A machine that says its operation mode as OPC UA for Machinery does
//! (`MachineryOperationMode`'s `CurrentState/Id`: the node id of its state,
//! in the Machinery namespace): the agent reads it as the state's number,
//! and a mode on it suppresses alarms by design while the machine is set
//! up, announcing them when it is back to processing.

use cellwatch::config::TagConfig;
use cellwatch::payload::AlarmPayload;
use cellwatch::sim::cnc::NAMESPACE;
use cellwatch_models::alarm::AlarmPattern;
use cellwatch_models::engine::Mode;
use cellwatch_models::expr::Expr;
use cellwatch_models::machinery::{StateMachine, NAMESPACE as MACHINERY};
use cellwatch_models::signal::Signal;
use cellwatch_models::value::ValueType;
use opcua::types::{NodeId, Variant};

use crate::agent::{alarm_until, Fixture};

/// The state object `id` of Machinery's namespace `ns` as a
/// `CurrentState/Id` says it.
fn state(ns: u16, id: u32) -> Variant {
    Variant::from(NodeId::new(ns, id))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_operation_mode_of_opc_ua_for_machinery_suppresses_alarms_by_design_during_setup() {
    let fx = Fixture::start_with_namespace(
        Some(MACHINERY),
        |sim| {
            let ns = sim.decoy_namespace().unwrap();
            // Processing.
            sim.add_register("D300", state(ns, 5026)).unwrap();
        },
        |c| {
            c.tags.push(TagConfig {
                states: Some(StateMachine::OperationMode),
                value_type: ValueType::UInt32,
                comment: Some("Operation mode (OPC UA for Machinery)".into()),
                ..TagConfig::boolean(
                    "operation_mode",
                    &format!("nsu={NAMESPACE};s=D300"),
                    Signal::new("D300"),
                )
            });
            // Setup (state number 2): the setter works in the machine,
            // its emergency-stop chain opened by design.
            c.state.modes.push(Mode {
                id: "setup".into(),
                when: Expr::parse("D300 == 2").unwrap(),
                suppress: vec![AlarmPattern::new("es*")],
            });
        },
    )
    .await;
    let ns = fx.sim.decoy_namespace().unwrap();
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    fx.tag_value_is("D300", serde_json::json!(3)).await;
    // Into setup.
    fx.sim
        .set_registers(&[("D300".into(), state(ns, 5027))])
        .unwrap();
    fx.tag_value_is("D300", serde_json::json!(2)).await;
    let m = fx.scrape().await;
    assert!(
        m.contains("cellwatch_mode_active{cell=\"m01ps0004\",mode=\"setup\"} 1"),
        "{m}"
    );
    let mut seen: Vec<AlarmPayload> = Vec::new();
    fx.sim.set("X0.06", false).unwrap();
    let raised = alarm_until(&sub, "ESE raised", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    let by_design = raised.suppressed_by_design.as_ref();
    assert_eq!(
        by_design.map(|d| d.mode.as_str()),
        Some("setup"),
        "{raised:#?}"
    );
    // A node that is no state of the machine (another namespace's) is not
    // believed as one: the tag's quality is bad, the mode kept as it was.
    fx.sim
        .set_registers(&[("D300".into(), state(ns + 1, 5026))])
        .unwrap();
    let bad = alarm_until(&sub, "D300's quality bad", &mut seen, |a| {
        a.id == "tag-quality" && a.transition.as_str() == "raised"
    })
    .await;
    assert!(bad.message.contains("D300"), "{}", bad.message);
    let m = fx.scrape().await;
    assert!(
        m.contains("cellwatch_mode_active{cell=\"m01ps0004\",mode=\"setup\"} 1"),
        "{m}"
    );
    // Processing again: ESE, still active, is announced now.
    fx.sim
        .set_registers(&[("D300".into(), state(ns, 5026))])
        .unwrap();
    alarm_until(&sub, "ESE announced", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "unsuppressed"
    })
    .await;
    fx.tag_value_is("D300", serde_json::json!(3)).await;
}
