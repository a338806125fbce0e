//! The cell loop with no network and no disk: a scripted source feeds it,
//! a recording sink shows every step it hands to its sinks.

use std::time::Duration;

use cellwatch::cell::{compile, CellLoop, CellStep, Input, Request};
use cellwatch::config;
use cellwatch::metrics::Metrics;
use cellwatch::operator::{Action, Command, Gate, OperatorKeys};
use cellwatch::sinks::zenoh::ZenohPublisher;
use cellwatch::sinks::{RecordingSink, Sink};
use cellwatch::sources::scripted::ScriptedSource;
use cellwatch::sources::{Source, SourceEvent, QUEUE_CAPACITY};
use cellwatch_models::alarm::Transition;
use cellwatch_models::engine::{CellEngine, MachineState, Reading, TagReading};
use cellwatch_models::signal::pmc_address;
use cellwatch_models::values::Values;
use futures_util::FutureExt;
use tokio::sync::{mpsc, oneshot};

use crate::util::root;

/// Receives steps until `f` accepts one.
async fn step_until(
    steps: &mut mpsc::UnboundedReceiver<CellStep>,
    what: &str,
    f: impl Fn(&CellStep) -> bool,
) -> CellStep {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        let step = tokio::time::timeout_at(deadline, steps.recv())
            .await
            .unwrap_or_else(|_| panic!("timed out waiting for {what}"))
            .expect("the loop stopped");
        if f(&step) {
            return step;
        }
    }
}

fn raised(step: &CellStep, id: &str) -> bool {
    step.engine
        .alarms()
        .any(|(a, t, _)| a.id == id && t == Transition::Raised)
}

/// Every tag of `config` as the CNC's normal image has it, at 1 s.
fn normal_image(config: &config::CellConfig) -> Vec<TagReading> {
    let mut normal = Vec::new();
    for (name, text) in [
        (
            "ese-normal.values",
            include_str!("../config/cnc/ese-normal.values"),
        ),
        (
            "csd-normal.values",
            include_str!("../config/cnc/csd-normal.values"),
        ),
    ] {
        normal.push(Values::parse_file(name, text, pmc_address).unwrap());
    }
    config
        .tags
        .iter()
        .enumerate()
        .map(|(tag, t)| TagReading {
            tag,
            reading: Reading::Good(
                normal
                    .iter()
                    .find_map(|v| v.get(&t.address))
                    .unwrap_or(false),
            ),
            source_time: 1_000,
        })
        .collect()
}

/// The index of the tag at `address`.
fn tag_of(config: &config::CellConfig, address: &str) -> usize {
    config
        .tags
        .iter()
        .position(|t| t.address.name() == address)
        .unwrap()
}

/// A loop of the demo cell over `engine`, handing its steps to `sinks`;
/// its state beat once an hour (never, in these tests).
fn demo_loop(
    config: &config::CellConfig,
    engine: CellEngine,
    sinks: Vec<Box<dyn Sink>>,
) -> CellLoop {
    CellLoop::new(
        &config.cell,
        engine,
        Gate::new(&config.cell, OperatorKeys::default()),
        sinks,
        Duration::from_secs(3600),
    )
}

/// Runs `cell_loop` as a task until the returned sender is used.
fn run_until_stopped(
    cell_loop: CellLoop,
    source: mpsc::Receiver<SourceEvent>,
    requests: mpsc::Receiver<Request>,
) -> (oneshot::Sender<()>, tokio::task::JoinHandle<()>) {
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(cell_loop.run(source, requests, async {
        let _ = stopped.await;
    }));
    (stop, task)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scripted_source_drives_the_loop_into_the_recording_sink() {
    let config = config::load(&root().join("config/demo.toml")).unwrap();
    let engine = compile::engine(&config).unwrap();
    let (recording, mut steps) = RecordingSink::new();
    let (source, script) = ScriptedSource::new();
    let (source_tx, source_rx) = mpsc::channel(QUEUE_CAPACITY);
    let source = tokio::spawn(Box::new(source).run(source_tx, std::future::pending().boxed()));
    let (requests, requests_rx) = mpsc::channel(4);
    let (stop, cell_loop) = run_until_stopped(
        demo_loop(&config, engine, vec![Box::new(recording)]),
        source_rx,
        requests_rx,
    );

    // The machine's normal image, then the Y over-travel switch opens.
    let image = normal_image(&config);
    let x006 = tag_of(&config, "X0.06");
    let at = |tag, v, t| {
        SourceEvent::Readings(
            vec![TagReading {
                tag,
                reading: Reading::Good(v),
                source_time: t,
            }]
            .into(),
        )
    };
    script
        .send(SourceEvent::Connected("scripted".into()))
        .await
        .unwrap();
    let up = step_until(&mut steps, "connection", |s| {
        matches!(s.input, Input::Connection { up: true, .. })
    })
    .await;
    assert!(up.alarms.is_empty());
    script
        .send(SourceEvent::Readings(image.into()))
        .await
        .unwrap();
    let loaded = step_until(&mut steps, "the image", |s| s.input == Input::Readings).await;
    assert_eq!(loaded.engine.readings, config.tags.len() as u64);
    assert_eq!(loaded.engine.unknown_delta, -(config.tags.len() as i64));
    assert!(loaded.alarms.is_empty(), "{:?}", loaded.alarms);
    script.send(at(x006, false, 2_000)).await.unwrap();
    let fault = step_until(&mut steps, "ESE raised", |s| raised(s, "ese")).await;
    // The payload is built once, for every sink, in the engine's order.
    assert_eq!(fault.alarms.len(), 1);
    let ese = &fault.alarms[0].payload;
    assert_eq!(ese.transition, Transition::Raised);
    assert_eq!(ese.culprits[0].address, "X0.06");
    assert!(ese.culprits[0].trigger);
    assert!(fault.alarms[0].json.contains("\"transition\":\"raised\""));
    let (state, _, _) = fault.engine.states().last().unwrap();
    assert!(matches!(state, MachineState::Fault { .. }), "{state:?}");
    assert_eq!(
        fault.state.as_ref().unwrap().element.as_deref(),
        Some("X0.06")
    );
    // A delivery repeated after a subscription is recreated is one duplicate.
    script.send(at(x006, false, 2_000)).await.unwrap();
    let dup = step_until(&mut steps, "duplicate", |s| s.input == Input::Readings).await;
    assert_eq!((dup.engine.duplicates, dup.alarms.len()), (1, 0));

    // An unsigned command is refused, and the refusal is a step of its own.
    let (reply, outcome) = oneshot::channel();
    requests
        .send(Request::Command {
            source: "unknown".into(),
            command: Ok(Command {
                action: Action::Ack,
                alarm: "ese".into(),
                tag: None,
                value: None,
                reason: None,
                operator: "kim".into(),
                nonce: cellwatch::operator::nonce(),
                issued_at: cellwatch::clock::now_ms(),
                signature: String::new(),
            }),
            reply,
        })
        .await
        .unwrap();
    let outcome = outcome.await.unwrap();
    assert_eq!(
        (outcome.accepted, outcome.detail.as_str()),
        (false, "unsigned command")
    );
    let refused = step_until(&mut steps, "the command", |s| {
        matches!(s.input, Input::Command(_))
    })
    .await;
    let Input::Command(record) = &refused.input else {
        unreachable!()
    };
    assert_eq!(record.action, Some(Action::Ack));
    assert!(!record.accepted);

    // A snapshot is answered by the loop from the engine.
    let (reply, snap) = oneshot::channel();
    requests.send(Request::Snapshot(reply)).await.unwrap();
    let snap = snap.await.unwrap();
    assert!(snap.alarms.iter().any(|a| a.id == "ese"));
    assert_eq!(snap.last_fault.unwrap().alarm, "ese");

    script.send(at(x006, true, 3_000)).await.unwrap();
    let cleared = step_until(&mut steps, "ESE cleared", |s| {
        s.engine
            .alarms()
            .any(|(a, t, _)| a.id == "ese" && t == Transition::Cleared)
    })
    .await;
    assert_eq!(
        cleared.alarms[0].payload.state.as_str(),
        "cleared_unacknowledged"
    );
    // Time passes in ticks, each a step the metrics count state time on.
    step_until(&mut steps, "a tick", |s| s.input == Input::Tick).await;

    drop(script);
    source.await.unwrap().unwrap();
    let _ = stop.send(());
    cell_loop.await.unwrap();
}

/// On its own thread ([`CellLoop::spawn`]), the loop publishes an alarm on
/// the bus and, when stopped, closes the Zenoh sink: dropping an alarm
/// publisher blocks in place, which a current-thread runtime would refuse
/// with a panic that `Agent::stop` passes on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_loop_on_its_own_thread_closes_the_bus_sink() {
    let config = config::load(&root().join("config/demo.toml")).unwrap();
    let engine = compile::engine(&config).unwrap();
    let bus = zenoh::open(
        zenoh::Config::from_json5(
            r#"{mode: "peer", listen: {endpoints: []}, timestamping: {enabled: {peer: true}},
                scouting: {multicast: {enabled: false}, gossip: {enabled: false}}}"#,
        )
        .unwrap(),
    )
    .await
    .unwrap();
    let prefix = format!("cellwatch/{}", config.cell);
    let alarms = bus
        .declare_subscriber(format!("{prefix}/alarms/**"))
        .await
        .unwrap();
    let metrics = std::sync::Arc::new(Metrics::new(&config.cell));
    let key = std::sync::Arc::new(cellwatch::bus::envelope::AgentKey::generate(&config.cell));
    let publisher = ZenohPublisher::start(bus.clone(), &prefix, key, metrics)
        .await
        .unwrap();
    let (recording, mut steps) = RecordingSink::new();
    let (source_tx, source_rx) = mpsc::channel(QUEUE_CAPACITY);
    let (_requests, requests_rx) = mpsc::channel(4);
    let (stop, stopped) = oneshot::channel::<()>();
    let cell_loop = demo_loop(
        &config,
        engine,
        vec![Box::new(publisher), Box::new(recording)],
    )
    .spawn(source_rx, requests_rx, async {
        let _ = stopped.await;
    })
    .unwrap();
    let image = normal_image(&config);
    let x006 = tag_of(&config, "X0.06");
    source_tx
        .send(SourceEvent::Readings(image.into()))
        .await
        .unwrap();
    let fault = TagReading {
        tag: x006,
        reading: Reading::Good(false),
        source_time: 2_000,
    };
    source_tx
        .send(SourceEvent::Readings(vec![fault].into()))
        .await
        .unwrap();
    step_until(&mut steps, "ESE raised", |s| raised(s, "ese")).await;
    let sample = tokio::time::timeout(Duration::from_secs(20), alarms.recv_async())
        .await
        .expect("no alarm on the bus")
        .unwrap();
    assert_eq!(sample.key_expr().as_str(), format!("{prefix}/alarms/ese"));
    let _ = stop.send(());
    if let Err(e) = cell_loop.await {
        let panic = e.into_panic();
        let text = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied());
        panic!("the loop did not end cleanly: {text:?}");
    }
    bus.close().await.unwrap();
}

/// A `journal` alarm still active when the agent stopped follows the
/// journal's health at the restart: a journal that writes again clears it
/// at once, though its health never changes after the start.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_restored_journal_alarm_follows_the_journal_at_the_start() {
    let config = config::load(&root().join("config/demo.toml")).unwrap();
    let mut engine = compile::engine(&config).unwrap();
    let alarm = cellwatch_models::alarm::Alarm {
        id: "journal".into(),
        kind: cellwatch_models::alarm::AlarmKind::System,
        severity: cellwatch_models::alarm::Severity::High,
        fault_type: "JOURNAL".into(),
        active: true,
        acknowledged: false,
        latched: false,
        raised_at: 1_000,
        cleared_at: None,
        acked_by: None,
        ack_comment: None,
        fault_step: None,
        culprits: Vec::new(),
        message: "journal: database is locked".into(),
        shelved: None,
        out_of_service: None,
        consequence: None,
        designed: None,
        guidance: None,
    };
    let restored = engine.restore(vec![alarm], None, 2_000);
    let (recording, mut steps) = RecordingSink::new();
    let (_health_tx, health) = tokio::sync::watch::channel(None::<String>);
    let (_source_tx, source_rx) = mpsc::channel(QUEUE_CAPACITY);
    let (_requests, requests_rx) = mpsc::channel(4);
    let (stop, cell_loop) = run_until_stopped(
        demo_loop(&config, engine, vec![Box::new(recording)])
            .restored(restored, None)
            .watching_journal(health),
        source_rx,
        requests_rx,
    );
    let first = step_until(&mut steps, "the restore", |_| true).await;
    assert_eq!(first.input, Input::Restored);
    let cleared = step_until(&mut steps, "the journal alarm cleared", |s| {
        s.engine
            .alarms()
            .any(|(a, t, _)| a.id == "journal" && t == Transition::Cleared)
    })
    .await;
    assert_eq!(cleared.input, Input::System);
    assert_eq!(
        cleared.alarms[0].payload.state.as_str(),
        "cleared_unacknowledged"
    );
    let _ = stop.send(());
    cell_loop.await.unwrap();
}

/// An idle loop sleeps to its next deadline, at most `MAX_SLEEP`, and a
/// test's clock set wakes it at once: its tick comes with no time passed
/// on the runtime's clock (paused: it only moves when every task waits).
#[tokio::test(start_paused = true)]
async fn an_idle_loop_sleeps_and_a_set_clock_wakes_it_at_once() {
    use cellwatch::cell::MAX_SLEEP;
    use tokio::time::Instant;
    let config = config::load(&root().join("config/demo.toml")).unwrap();
    let engine = compile::engine(&config).unwrap();
    let (recording, mut steps) = RecordingSink::new();
    let clock = cellwatch::clock::Clock::manual(1_700_000_000_000);
    let cell_loop = demo_loop(&config, engine, vec![Box::new(recording)]).timed_by(clock.clone());
    let (_source, source_rx) = mpsc::channel(QUEUE_CAPACITY);
    let (_requests, requests_rx) = mpsc::channel(4);
    let (stop, cell_loop) = run_until_stopped(cell_loop, source_rx, requests_rx);
    let tick = async |steps: &mut mpsc::UnboundedReceiver<CellStep>| {
        step_until(steps, "a tick", |s| s.input == Input::Tick).await
    };
    tick(&mut steps).await;
    // Nothing due: the next look at the time is MAX_SLEEP later.
    let slept = Instant::now();
    tick(&mut steps).await;
    assert_eq!(slept.elapsed(), MAX_SLEEP);
    let set = Instant::now();
    clock.set(1_700_000_060_000);
    let woken = tick(&mut steps).await;
    assert_eq!(
        (woken.at, set.elapsed()),
        (1_700_000_060_000, Duration::ZERO)
    );
    let _ = stop.send(());
    cell_loop.await.unwrap();
}
