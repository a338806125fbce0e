//! Configuration tests of `[[opcua.events]]`: the PLC's own alarms.

use super::*;

fn with(tables: &str) -> String {
    GOOD.replace(
        "endpoint = \"opc.tcp://127.0.0.1:4840/\"\n",
        &format!("endpoint = \"opc.tcp://127.0.0.1:4840/\"\n\n{tables}\n"),
    )
}

#[test]
fn the_plcs_alarms_are_read_from_the_server_object_unless_told_otherwise() {
    let c = parse(
        "cell.toml",
        &with("[[opcua.events]]"),
        Path::new("base"),
        &mem(),
    )
    .unwrap();
    let events = c.opcua.unwrap().events;
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].prefix, "plc");
    assert_eq!(events[0].min_severity, 1);
    assert_eq!(
        events[0].source,
        crate::config::node::TagNode::parse("i=2253", None).unwrap()
    );
    let two = "[[opcua.events]]\nsource = \"nsu=urn:plc;s=Press\"\nprefix = \"press\"\nmin_severity = 300\n\n[[opcua.events]]\nsource = \"nsu=urn:plc;s=Oven\"\nprefix = \"oven\"";
    let c = parse("cell.toml", &with(two), Path::new("base"), &mem()).unwrap();
    let events = c.opcua.unwrap().events;
    assert_eq!(
        events
            .iter()
            .map(|e| (e.prefix.as_str(), e.min_severity))
            .collect::<Vec<_>>(),
        [("press", 300), ("oven", 1)]
    );
}

#[test]
fn a_bad_notifier_prefix_or_severity_is_named_at_its_place() {
    assert_eq!(
        errors(&with("[[opcua.events]]\nsource = \"Press\"")),
        "cell.toml:9:10: opcua.events[0].source: 'Press' is not a node id like nsu=<namespace uri>;s=X0.06 or ns=2;s=X0.06"
    );
    assert_eq!(
        errors(&with("[[opcua.events]]\nprefix = \"plc alarms\"")),
        "cell.toml:9:10: opcua.events[0].prefix: 'plc alarms' must be letters, digits, - and _ only (it begins the alarms' ids)"
    );
    assert_eq!(
        errors(&with("[[opcua.events]]\nmin_severity = 1001")),
        "cell.toml:9:16: opcua.events[0].min_severity: an OPC UA severity: 1 to 1000"
    );
    assert_eq!(
        errors(&with(
            "[[opcua.events]]\n\n[[opcua.events]]\nprefix = \"other\""
        )),
        "cell.toml:10:1: opcua.events[1].source: 'i=2253' is read twice"
    );
    assert_eq!(
        errors(&with("[[opcua.events]]\nsource = \"nsu=urn:plc;s=A\"\n\n[[opcua.events]]\nsource = \"nsu=urn:plc;s=B\"")),
        "cell.toml:11:1: opcua.events[1].prefix: 'plc' is used twice"
    );
    assert!(
        errors(&with("[[opcua.events]]\nfilter = \"x\"")).contains("unknown field `filter`"),
        "{}",
        errors(&with("[[opcua.events]]\nfilter = \"x\""))
    );
}
