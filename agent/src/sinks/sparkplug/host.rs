//! The primary host application as the edge node follows it (Sparkplug
//! 3.0, "Primary Host Application STATE"): what its `STATE` messages say
//! and which of them count. An online message counts when its timestamp
//! is not older than the last `STATE` heard; an offline one when it is not
//! older than the last online one, so a stale retained death of an earlier
//! host session never takes the node down. Pure: the session decides what
//! to do (wait, be born, publish NDEATH and disconnect).

/// What one `STATE` message says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct HostState {
    /// The host is online.
    pub online: bool,
    /// Its timestamp (ms since the epoch); `None` for Sparkplug 2's
    /// `ONLINE`/`OFFLINE`, which carry none.
    pub timestamp: Option<u64>,
}

impl HostState {
    /// Reads a `STATE` payload: Sparkplug 3.0's JSON
    /// (`{"online": true, "timestamp": …}`) or the older `ONLINE` and
    /// `OFFLINE`; `None` for anything else.
    pub(crate) fn parse(payload: &[u8]) -> Option<HostState> {
        #[derive(serde::Deserialize)]
        struct Json {
            online: bool,
            timestamp: Option<u64>,
        }
        if let Ok(j) = serde_json::from_slice::<Json>(payload) {
            return Some(HostState {
                online: j.online,
                timestamp: j.timestamp,
            });
        }
        match payload {
            b"ONLINE" => Some(HostState {
                online: true,
                timestamp: None,
            }),
            b"OFFLINE" => Some(HostState {
                online: false,
                timestamp: None,
            }),
            _ => None,
        }
    }
}

/// What a `STATE` message means for the node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum HostSaid {
    /// The host is online.
    Online,
    /// The host is offline.
    Offline,
    /// Older than what was heard before: ignored.
    Stale,
}

impl HostSaid {
    /// The label of `cellwatch_sparkplug_primary_host_states_total`.
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            HostSaid::Online => "online",
            HostSaid::Offline => "offline",
            HostSaid::Stale => "stale",
        }
    }
}

/// The timestamps heard from the primary host, across MQTT sessions.
#[derive(Debug, Default, Clone)]
pub(crate) struct PrimaryHost {
    /// The newest timestamp of any `STATE` that counted.
    last: Option<u64>,
    /// The newest timestamp of an online `STATE` that counted.
    last_online: Option<u64>,
}

impl PrimaryHost {
    /// Judges `state` against what was heard before, and remembers it if
    /// it counts.
    pub(crate) fn heard(&mut self, state: HostState) -> HostSaid {
        let not_older = |than: Option<u64>| match (state.timestamp, than) {
            (Some(t), Some(before)) => t >= before,
            _ => true,
        };
        if state.online {
            if !not_older(self.last) {
                return HostSaid::Stale;
            }
            self.last_online = state.timestamp.or(self.last_online);
        } else if !not_older(self.last_online) {
            return HostSaid::Stale;
        }
        if let Some(t) = state.timestamp {
            self.last = Some(self.last.map_or(t, |l| l.max(t)));
        }
        if state.online {
            HostSaid::Online
        } else {
            HostSaid::Offline
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(online: bool, t: u64) -> HostState {
        HostState {
            online,
            timestamp: Some(t),
        }
    }

    #[test]
    fn a_state_is_read_as_sparkplug_3_or_2_says() {
        assert_eq!(
            HostState::parse(br#"{"online": true, "timestamp": 17}"#),
            Some(at(true, 17))
        );
        assert_eq!(
            HostState::parse(br#"{"online": false, "timestamp": 2}"#),
            Some(at(false, 2))
        );
        assert_eq!(
            HostState::parse(b"ONLINE").map(|s| (s.online, s.timestamp)),
            Some((true, None))
        );
        assert_eq!(HostState::parse(b"OFFLINE").map(|s| s.online), Some(false));
        assert_eq!(HostState::parse(b"garbage"), None);
    }

    #[test]
    fn an_older_state_never_flips_the_node() {
        let mut host = PrimaryHost::default();
        // No STATE heard yet: the first counts, whatever its time.
        assert_eq!(host.heard(at(false, 5)), HostSaid::Offline);
        // Online as new as the last STATE counts; older does not.
        assert_eq!(host.heard(at(true, 4)), HostSaid::Stale);
        assert_eq!(host.heard(at(true, 5)), HostSaid::Online);
        // A death of an earlier host session, delivered late: ignored.
        assert_eq!(host.heard(at(false, 3)), HostSaid::Stale);
        assert_eq!(host.heard(at(false, 5)), HostSaid::Offline);
        // Heard again on the next session (retained): still offline, and
        // an older online retained before it does not bring it back.
        assert_eq!(host.heard(at(false, 5)), HostSaid::Offline);
        assert_eq!(host.heard(at(true, 1)), HostSaid::Stale);
        assert_eq!(host.heard(at(true, 9)), HostSaid::Online);
        // Sparkplug 2's texts carry no time: they always count.
        assert_eq!(
            host.heard(HostState {
                online: false,
                timestamp: None
            }),
            HostSaid::Offline
        );
    }
}
