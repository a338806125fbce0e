//! A network cut between the agent and its OPC UA server (a TCP relay
//! that closes every connection and refuses new ones, with
//! Basic256Sha256 + SignAndEncrypt end to end): the subscription is taken
//! over by the new session and every change the server queued meanwhile
//! arrives, in order; a subscription the server dropped is said as a gap.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use cellwatch::config::TagConfig;
use cellwatch::sim::cnc::NAMESPACE;
use cellwatch::sources::SourceEvent;
use cellwatch_models::engine::Reading;
use cellwatch_models::signal::Signal;

use crate::liveness::{relay_with_cut, trusted_cnc, Cut, Running};
use crate::opcua::next;

fn tag(address: &str) -> TagConfig {
    TagConfig::boolean(
        &address.to_lowercase(),
        &format!("nsu={NAMESPACE};s={address}"),
        Signal::new(address),
    )
}

/// The source reading X0.06 and X0.04 of `sim` through a relay, once
/// connected and cut off.
async fn cut_off(
    sim: &cellwatch::sim::cnc::SimulatedCnc,
    mut config: cellwatch::config::OpcUaConfig,
) -> (Running, Cut) {
    let cut = Cut::default();
    let via = relay_with_cut(sim.addr(), Arc::new(AtomicBool::new(false)), cut.clone()).await;
    config.endpoint = format!("opc.tcp://{via}/");
    let mut source = Running::start(config, vec![tag("X0.06"), tag("X0.04")]);
    source.connected().await;
    cut.set(true);
    next(&mut source.rx, "the cut seen", |e| {
        matches!(e, SourceEvent::Disconnected(_))
    })
    .await;
    (source, cut)
}

pub(crate) fn logs() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
}

/// Every event until `until` matches one, then that one.
pub(crate) async fn until(
    source: &mut Running,
    what: &str,
    until: impl Fn(&SourceEvent) -> bool,
) -> Vec<SourceEvent> {
    let mut seen = Vec::new();
    loop {
        let ev = next(&mut source.rx, what, |_| true).await;
        let last = until(&ev);
        seen.push(ev);
        if last {
            return seen;
        }
    }
}

/// The readings of tag `tag` among `events`, in order.
fn of_tag(events: &[SourceEvent], tag: usize) -> Vec<(Reading, u64)> {
    events
        .iter()
        .filter_map(|e| match e {
            SourceEvent::Readings(rs) => Some(rs.iter()),
            _ => None,
        })
        .flatten()
        .filter(|r| r.tag == tag)
        .map(|r| (r.reading.clone(), r.source_time))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pulse_during_a_network_cut_arrives_in_order_through_the_taken_over_subscription() {
    logs();
    let dir = tempfile::tempdir().unwrap();
    let (sim, config, _) = trusted_cnc(dir.path()).await;
    let (mut source, cut) = cut_off(&sim, config).await;
    // A limit switch opens and closes again while the agent is cut off.
    let before = cellwatch::clock::now_ms();
    sim.set("X0.06", false).unwrap();
    tokio::time::sleep(Duration::from_millis(30)).await;
    sim.set("X0.06", true).unwrap();
    cut.set(false);
    let mut events = until(&mut source, "the pulse after the cut", |e| {
        of_tag(std::slice::from_ref(e), 0)
            .iter()
            .any(|(r, t)| *r == Reading::Good(true) && *t >= before)
    })
    .await;
    if !events
        .iter()
        .any(|e| matches!(e, SourceEvent::Connected(_)))
    {
        events.extend(
            until(&mut source, "connected again", |e| {
                matches!(e, SourceEvent::Connected(_))
            })
            .await,
        );
    }
    let mut pulse = of_tag(&events, 0);
    // The values read again after the take-over may repeat the last change
    // with its own source time: a duplicate the engine drops.
    pulse.dedup();
    assert_eq!(
        pulse.iter().map(|(r, _)| r.clone()).collect::<Vec<_>>(),
        [Reading::Good(false), Reading::Good(true)],
        "{events:?}"
    );
    assert!(pulse[0].1 >= before && pulse[0].1 < pulse[1].1, "{pulse:?}");
    assert!(
        events
            .iter()
            .any(|e| matches!(e, SourceEvent::Connected(_))),
        "{events:?}"
    );
    // Taken over, not recreated: nothing was lost.
    for e in &events {
        assert!(!matches!(e, SourceEvent::Gap { .. }), "{e:?}");
        if let SourceEvent::Disconnected(why) = e {
            assert!(!why.contains("dropped subscription"), "{why}");
        }
    }
    source.stop().await;
    sim.stop();
}

/// The traffic stalled (nothing passes either way, nothing is closed)
/// for longer than the subscription's silence allows, while a limit switch
/// opens and closes: what the server sent during the stall, arriving once
/// it flows again, is delivered in order and nothing is said lost.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pulse_during_a_stall_longer_than_the_silence_allowed_arrives_after_it() {
    logs();
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut config, _) = trusted_cnc(dir.path()).await;
    let stall = Cut::default();
    let via = relay_with_cut(sim.addr(), Arc::new(AtomicBool::new(false)), stall.clone()).await;
    config.endpoint = format!("opc.tcp://{via}/");
    let mut source = Running::start(config, vec![tag("X0.06"), tag("X0.04")]);
    source.connected().await;
    let before = cellwatch::clock::now_ms();
    stall.stall(true);
    sim.set("X0.06", false).unwrap();
    tokio::time::sleep(Duration::from_millis(30)).await;
    sim.set("X0.06", true).unwrap();
    // Three keep-alive periods (1 s each at a 100 ms publishing interval)
    // and more: the subscription is silent for longer than allowed.
    tokio::time::sleep(Duration::from_secs(5)).await;
    stall.stall(false);
    let events = until(&mut source, "the pulse after the stall", |e| {
        of_tag(std::slice::from_ref(e), 0)
            .iter()
            .any(|(r, t)| *r == Reading::Good(true) && *t >= before)
    })
    .await;
    let pulse: Vec<Reading> = of_tag(&events, 0)
        .into_iter()
        .filter(|(_, t)| *t >= before)
        .map(|(r, _)| r)
        .collect();
    assert_eq!(
        pulse,
        [Reading::Good(false), Reading::Good(true)],
        "{events:?}"
    );
    for e in &events {
        assert!(!matches!(e, SourceEvent::Gap { .. }), "{e:?}");
    }
    source.stop().await;
    sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_subscription_the_server_dropped_during_a_cut_is_said_as_a_gap_before_the_values_after_it(
) {
    logs();
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut config, _) = trusted_cnc(dir.path()).await;
    // The shortest lifetime allowed: 30 publishing intervals.
    config.subscription_lifetime = config.publishing_interval * 30;
    let (mut source, cut) = cut_off(&sim, config).await;
    // The server closes the subscription once its lifetime is over; a
    // change after that is queued nowhere.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while sim.subscriptions() > 0 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the subscription outlived its lifetime"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    sim.set("X0.06", false).unwrap();
    cut.set(false);
    let events = until(&mut source, "X0.06 = 0 after the cut", |e| {
        of_tag(std::slice::from_ref(e), 0)
            .iter()
            .any(|(r, _)| *r == Reading::Good(false))
    })
    .await;
    let gap = events
        .iter()
        .position(|e| matches!(e, SourceEvent::Gap { tags: None, .. }))
        .unwrap_or_else(|| panic!("no gap said: {events:?}"));
    let SourceEvent::Gap { why, .. } = &events[gap] else {
        unreachable!()
    };
    assert!(why.contains("may be lost"), "{why}");
    assert!(gap < events.len() - 1, "{events:?}");
    source.stop().await;
    sim.stop();
}

/// The demo cell behind a relay that can cut the network, with alarms
/// subscribed.
async fn cell_behind_a_cut(
    lifetime: Option<Duration>,
) -> (crate::agent::Fixture, Cut, crate::robust::AlarmSubscriber) {
    let cut = Cut::default();
    let via = Arc::new(std::sync::Mutex::new(None));
    let fx = crate::agent::Fixture::start_with_sim(
        |sim| {
            let (addr, cut) = (sim.addr(), cut.clone());
            let relay = tokio::task::block_in_place(|| {
                tokio::runtime::Handle::current().block_on(relay_with_cut(
                    addr,
                    Arc::new(AtomicBool::new(false)),
                    cut,
                ))
            });
            *via.lock().unwrap() = Some(relay);
        },
        |config| {
            let ua = config.opcua.as_mut().unwrap();
            ua.endpoint = format!("opc.tcp://{}/", via.lock().unwrap().unwrap());
            if let Some(l) = lifetime {
                ua.subscription_lifetime = l;
            }
        },
    )
    .await;
    let sub = crate::robust::alarms(fx.client(), "m01ps0004").await;
    fx.settled().await;
    (fx, cut, sub)
}

pub(crate) fn metric(metrics: &str, name: &str) -> f64 {
    metrics
        .lines()
        .find_map(|l| l.strip_prefix(&format!("{name}{{cell=\"m01ps0004\"}} ")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in {metrics}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_fault_during_a_network_cut_is_diagnosed_with_its_culprit_after_it() {
    logs();
    let (mut fx, cut, sub) = cell_behind_a_cut(None).await;
    let mut seen = Vec::new();
    cut.set(true);
    crate::agent::alarm_until(&sub, "communication lost", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "raised"
    })
    .await;
    // The Y over-travel switch opens for a moment while the agent is cut
    // off.
    let opened = cellwatch::clock::now_ms();
    fx.sim.set("X0.06", false).unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    fx.sim.set("X0.06", true).unwrap();
    let closed = cellwatch::clock::now_ms();
    cut.set(false);
    let raised = crate::agent::alarm_until(&sub, "ESE raised after the cut", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    let c = &raised.culprits[0];
    assert_eq!(
        (c.address.as_str(), c.value, c.trigger),
        ("X0.06", false, true),
        "{raised:?}"
    );
    assert!(!raised.message.contains("uncertain"), "{}", raised.message);
    let cleared = crate::agent::alarm_until(&sub, "ESE cleared", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "cleared"
    })
    .await;
    // Raised and cleared when the PLC saw it, not when it arrived.
    let ms = |t: &str| {
        chrono::DateTime::parse_from_rfc3339(t)
            .unwrap()
            .timestamp_millis() as u64
    };
    let (from, to) = (
        ms(&raised.raised_at),
        ms(cleared.cleared_at.as_deref().unwrap()),
    );
    assert!(
        opened <= from && from < to && to <= closed,
        "raised {from}, cleared {to}, the switch open from {opened} to {closed}"
    );
    crate::agent::alarm_until(&sub, "communication back", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "cleared"
    })
    .await;
    let metrics = fx.scrape().await;
    assert_eq!(metric(&metrics, "cellwatch_source_gaps_total"), 0.0);
    fx.stop().await;
    fx.sim.stop();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_fault_judged_across_a_gap_says_its_trigger_is_uncertain_and_the_gap_is_counted() {
    logs();
    let (mut fx, cut, sub) = cell_behind_a_cut(Some(Duration::from_secs(3))).await;
    let mut seen = Vec::new();
    cut.set(true);
    crate::agent::alarm_until(&sub, "communication lost", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "raised"
    })
    .await;
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    while fx.sim.subscriptions() > 0 {
        assert!(
            tokio::time::Instant::now() < deadline,
            "the subscription outlived its lifetime"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Queued nowhere: the server dropped the subscription.
    fx.sim.set("X0.06", false).unwrap();
    cut.set(false);
    let raised = crate::agent::alarm_until(&sub, "ESE raised after the gap", &mut seen, |a| {
        a.id == "ese" && a.transition.as_str() == "raised"
    })
    .await;
    assert!(raised.culprits.iter().all(|c| !c.trigger), "{raised:?}");
    assert_eq!(raised.culprits[0].address.as_str(), "X0.06");
    assert!(
        raised.message.contains("(trigger uncertain: subscription"),
        "{}",
        raised.message
    );
    let metrics = fx.scrape().await;
    assert!(
        metric(&metrics, "cellwatch_source_gaps_total") >= 1.0,
        "{metrics}"
    );
    fx.stop().await;
    fx.sim.stop();
}

/// Scrapes until the agent says its OPC UA session is up again.
async fn reconnected(fx: &crate::agent::Fixture) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let metrics = fx.scrape().await;
        if metric(&metrics, "cellwatch_opcua_connected") == 1.0 {
            return;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "not reconnected: {metrics}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_link_that_comes_and_goes_is_one_communication_alarm_its_losses_counted() {
    logs();
    // The default off-delay: the alarm clears once the link has stayed up
    // for 10 s.
    let (mut fx, cut, sub) = cell_behind_a_cut(None).await;
    let mut seen = Vec::new();
    cut.set(true);
    crate::agent::alarm_until(&sub, "communication lost", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() == "raised"
    })
    .await;
    cut.set(false);
    reconnected(&fx).await;
    // Lost again within 10 s of coming back: the same occurrence.
    cut.set(true);
    let again = crate::agent::alarm_until(&sub, "the second loss", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() != "raised"
    })
    .await;
    assert_eq!(
        (again.transition.as_str(), again.message.as_str()),
        (
            "updated",
            "communication lost: every tag is unknown (2 losses since it was raised)"
        ),
        "{seen:#?}"
    );
    cut.set(false);
    let cleared = crate::agent::alarm_until(&sub, "communication cleared", &mut seen, |a| {
        a.id == "communication" && a.transition.as_str() != "updated"
    })
    .await;
    assert_eq!(
        (cleared.transition.as_str(), cleared.message.as_str()),
        (
            "cleared",
            "communication restored (2 losses since it was raised)"
        ),
        "{seen:#?}"
    );
    // Nothing but the one occurrence: no raise per loss, no process alarm.
    let raised: Vec<&str> = seen
        .iter()
        .filter(|a| a.transition.as_str() == "raised")
        .map(|a| a.id.as_str())
        .collect();
    assert_eq!(raised, ["communication"], "{seen:#?}");
    let metrics = fx.scrape().await;
    assert_eq!(metric(&metrics, "cellwatch_connection_losses_total"), 2.0);
    let raises: f64 = metrics
        .lines()
        .filter(|l| {
            l.starts_with("cellwatch_alarms_raised_total{") && l.contains("check=\"communication\"")
        })
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum();
    assert_eq!(raises, 1.0, "{metrics}");
    fx.stop().await;
    fx.sim.stop();
}
