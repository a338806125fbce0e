//! The Sparkplug B topics of one edge node and its device
//! (`spBv1.0/<group>/<kind>/<node>[/<device>]`) and of its primary host's
//! `STATE`: the only place they are spelled.

use super::config::SparkplugConfig;

/// The Sparkplug B namespace of every topic.
pub(crate) const NAMESPACE: &str = "spBv1.0";

/// The topics of one edge node.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Topics {
    /// The node's birth.
    pub nbirth: String,
    /// The node's death (its will, and its last word on a clean stop).
    pub ndeath: String,
    /// The device's birth.
    pub dbirth: String,
    /// The device's data.
    pub ddata: String,
    /// The device's death (its PLC link down).
    pub ddeath: String,
    /// Commands to the node (only a rebirth is taken).
    pub ncmd: String,
    /// Commands to the device (none is taken).
    pub dcmd: String,
    /// The primary host's state, when there is one.
    pub state: Option<String>,
}

impl Topics {
    /// The topics of `config`'s node and device.
    pub(crate) fn of(config: &SparkplugConfig) -> Topics {
        let node = |kind: &str| {
            format!(
                "{NAMESPACE}/{}/{kind}/{}",
                config.group_id, config.edge_node_id
            )
        };
        let device = |kind: &str| format!("{}/{}", node(kind), config.device_id);
        Topics {
            nbirth: node("NBIRTH"),
            ndeath: node("NDEATH"),
            dbirth: device("DBIRTH"),
            ddata: device("DDATA"),
            ddeath: device("DDEATH"),
            ncmd: node("NCMD"),
            dcmd: device("DCMD"),
            state: config
                .primary_host
                .as_ref()
                .map(|h| format!("{NAMESPACE}/STATE/{h}")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sinks::sparkplug::config::Broker;

    #[test]
    fn the_topics_are_the_specifications() {
        let t = Topics::of(&SparkplugConfig {
            broker: Broker {
                host: "b".into(),
                port: 8883,
                secure: true,
            },
            group_id: "press-shop".into(),
            edge_node_id: "m01-agent".into(),
            device_id: "m01".into(),
            primary_host: Some("scada".into()),
            credentials: None,
            tls: None,
            max_held: 1,
        });
        assert_eq!(t.nbirth, "spBv1.0/press-shop/NBIRTH/m01-agent");
        assert_eq!(t.ndeath, "spBv1.0/press-shop/NDEATH/m01-agent");
        assert_eq!(t.dbirth, "spBv1.0/press-shop/DBIRTH/m01-agent/m01");
        assert_eq!(t.ddata, "spBv1.0/press-shop/DDATA/m01-agent/m01");
        assert_eq!(t.ddeath, "spBv1.0/press-shop/DDEATH/m01-agent/m01");
        assert_eq!(t.ncmd, "spBv1.0/press-shop/NCMD/m01-agent");
        assert_eq!(t.dcmd, "spBv1.0/press-shop/DCMD/m01-agent/m01");
        assert_eq!(t.state.as_deref(), Some("spBv1.0/STATE/scada"));
    }
}
