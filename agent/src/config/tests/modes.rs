//! Configuration tests of `[[state.modes]]`: machine modes and the alarms
//! each suppresses by design, every mistake at its place, and a pattern
//! that matches no alarm of the cell refused when the engine is built.

use super::*;

fn with(modes: &str) -> String {
    GOOD.replace("[zenoh.tls]", &format!("{modes}\n[zenoh.tls]"))
}

#[test]
fn a_mode_reads_the_cells_tags_and_names_alarms_to_suppress() {
    let text = with(
        "[[state.modes]]\nid = \"setup\"\nwhen = \"x1 * -X2\"\nsuppress = [\"fig*\", \"communication\"]\n",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let m = &c.state.modes[0];
    assert_eq!(m.id, "setup");
    assert_eq!(m.when.to_string(), "X1 * -X2");
    let patterns: Vec<&str> = m.suppress.iter().map(|p| p.as_str()).collect();
    assert_eq!(patterns, ["fig*", "communication"]);
    crate::cell::compile::engine(&c).unwrap();
}

#[test]
fn a_bad_mode_is_an_error_at_its_place() {
    let text = with(concat!(
        "[[state.modes]]\nid = \"setup\"\nwhen = \"MODE == 2\"\nsuppress = []\n",
        "[[state.modes]]\nid = \"setup\"\nwhen = \"X1\"\nsuppress = [\" \"]\n",
    ));
    assert_eq!(
        errors(&text),
        [
            "cell.toml:26:12: state.modes[0].suppress: names no alarm: list the alarm ids (or patterns with *) the mode suppresses",
            "cell.toml:25:8: state.modes[0].when: no tag has the name or address MODE (in 'MODE == 2')",
            "cell.toml:28:6: state.modes[1].id: mode 'setup' is declared twice",
            "cell.toml:30:13: state.modes[1].suppress[0]: is empty: an alarm id, or a pattern with * (`door-*`)",
        ]
        .join("\n")
    );
}

#[test]
fn a_pattern_that_matches_no_alarm_of_the_cell_is_refused() {
    let text =
        with("[[state.modes]]\nid = \"setup\"\nwhen = \"X1\"\nsuppress = [\"fig6\", \"door-*\"]\n");
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let Err(e) = crate::cell::compile::engine(&c) else {
        panic!("door-* accepted");
    };
    assert_eq!(
        e.to_string(),
        "state.modes[0].suppress[1]: 'door-*' matches no alarm of this cell's checks, `communication`, `tag-quality` or the PLC's (`[[opcua.events]]` prefixes)"
    );
}

/// `GOOD` with a tag reading a Machinery state machine, `extra` said of it.
fn with_state_machine(extra: &str) -> String {
    GOOD.replace(
        "[[checks.switching]]",
        &format!("[[tags]]\nname = \"mode\"\nnode_id = \"nsu=urn:plc;s=Machine.OperationMode.CurrentState.Id\"\naddress = \"D300\"\n{extra}\n[[checks.switching]]"),
    )
}

#[test]
fn a_tag_may_be_a_state_machine_of_opc_ua_for_machinery_read_as_its_state_number() {
    let text = with_state_machine("states = \"MachineryOperationMode\"\n");
    let text = text.replace(
        "[zenoh.tls]",
        "[[state.modes]]\nid = \"setup\"\nwhen = \"D300 == 2\"\nsuppress = [\"fig6\"]\n\n[zenoh.tls]",
    );
    let c = parse("cell.toml", &text, Path::new("base"), &mem()).unwrap();
    let tag = c.tags.iter().find(|t| t.name == "mode").unwrap();
    assert_eq!(
        tag.states,
        Some(cellwatch_models::machinery::StateMachine::OperationMode)
    );
    assert_eq!(tag.value_type, ValueType::UInt32);
    crate::cell::compile::engine(&c).unwrap();
}

#[test]
fn a_state_machine_tag_said_wrong_is_an_error_at_its_place() {
    for (extra, error) in [
        (
            "states = \"MachineryState\"",
            "cell.toml:22:10: tags[2].states: 'MachineryState' is not a state machine of OPC UA for Machinery: MachineryItemState or MachineryOperationMode",
        ),
        (
            "states = \"MachineryItemState\"\ntype = \"Double\"",
            "cell.toml:22:10: tags[2].states: a MachineryItemState is read as its state's number, a UInt32: leave `type` out",
        ),
        (
            "states = \"MachineryItemState\"\nbit = 1",
            "cell.toml:22:10: tags[2].states: a MachineryItemState is read as its state's number: leave `bit` out",
        ),
    ] {
        assert_eq!(errors(&with_state_machine(extra)), error, "{extra}");
    }
}
