//! The alarms the agent raises of itself for a cell (kind `system`), and
//! the prefixes of the PLC's own alarms it follows: what the master alarm
//! database lists beside the engine's alarms, and which of its rows name
//! an alarm of the cell.

use crate::config::CellConfig;

/// An alarm the agent raises of itself, or a pattern of the PLC's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct OwnAlarm {
    /// Its id, or `<prefix>-*` for the PLC's own alarms.
    pub id: String,
    /// Whether it is the PLC's (kind `plc`) rather than the agent's
    /// (kind `system`).
    pub plc: bool,
    /// Its condition in words.
    pub condition: String,
}

/// The agent's own alarms for cell `c`: the journal's; with OPC UA, a
/// namespace missing, changes lost and (with `[[opcua.events]]`) the PLC's
/// alarms not followed, and one pattern per prefix of those; a forced
/// transition late; an `@` bus unit not answering.
pub(crate) fn own_alarms(c: &CellConfig) -> Vec<OwnAlarm> {
    let system = |id: String, condition: String| OwnAlarm {
        id,
        plc: false,
        condition,
    };
    let mut out = vec![system(
        super::JOURNAL_ALARM.into(),
        "the journal cannot write (rows kept in memory and retried)".into(),
    )];
    if let Some(ua) = &c.opcua {
        out.push(system(
            crate::sources::opcua::NAMESPACE_ALARM.into(),
            "a tag's namespace is not on the OPC UA server".into(),
        ));
        out.push(system(
            crate::sources::opcua::OVERFLOW_ALARM.into(),
            "changes were lost in the OPC UA server's queues".into(),
        ));
        if !ua.events.is_empty() {
            out.push(system(
                crate::sources::opcua::EVENTS_ALARM.into(),
                "the PLC's own alarms cannot be followed".into(),
            ));
        }
        for e in &ua.events {
            out.push(OwnAlarm {
                id: format!("{}-*", e.prefix),
                plc: true,
                condition: "the PLC's own alarm (OPC UA Alarms & Conditions), its text as message"
                    .into(),
            });
        }
    }
    for s in &c.sfc {
        for (chart, transition) in &s.forcible {
            out.push(system(
                format!("force-{chart}-{transition}"),
                format!("a forced transition {chart}.{transition} did not arrive in time"),
            ));
        }
    }
    if c.legacy.is_some() {
        let mut units: Vec<u8> = c
            .tags
            .iter()
            .filter_map(|t| crate::config::at_bus::BusNode::parse(&t.node_id).ok())
            .map(|n| n.unit)
            .collect();
        units.sort_unstable();
        units.dedup();
        for unit in units {
            out.push(system(
                crate::sources::at_bus::unit_problem(unit),
                format!("unit @{unit:02X} on the bus does not answer"),
            ));
        }
    }
    out
}
