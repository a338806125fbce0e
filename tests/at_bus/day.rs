//! Each unit a cell of its own reports its day as the simulator logged it.

use std::time::Duration;

use cellwatch::sim::moulding::MouldingBus;
use cellwatch::sources::at_bus::{self, Transport};
use cellwatch_models::at_bus::Status;

/// What the simulator's log says of one unit's day, computed here from
/// the log alone: minutes running / idle / fault per hour, stops per
/// cause code, parts, and parts per order.
struct Logged {
    hours: Vec<[f64; 3]>,
    causes: std::collections::BTreeMap<String, (u64, f64)>,
    parts: u64,
    orders: Vec<(String, u64, u64)>,
}

fn logged(log: &[cellwatch::sim::moulding::LogEntry], unit: u8, start: u64) -> Logged {
    let end = start + 86_400_000;
    let mut out = Logged {
        hours: vec![[0.0; 3]; 24],
        causes: Default::default(),
        parts: 0,
        orders: vec![("ITEM-01".into(), 1000, 0)],
    };
    // (since, 0 running / 1 idle / 2 fault, cause)
    let mut state = (start, 0usize, String::new());
    let close = |from: u64, to: u64, s: usize, cause: &str, out: &mut Logged| {
        let mut t = from;
        while t < to {
            let h = ((t - start) / 3_600_000) as usize;
            let slot_end = (start + (h as u64 + 1) * 3_600_000).min(to);
            out.hours[h][s] += (slot_end - t) as f64 / 60_000.0;
            t = slot_end;
        }
        if s > 0 {
            let c = out.causes.entry(cause.to_string()).or_default();
            c.0 += 1;
            c.1 += (to - from) as f64 / 60_000.0;
        }
    };
    for e in log.iter().filter(|e| e.unit == unit) {
        let words: Vec<&str> = e.what.split(' ').collect();
        match words[..] {
            ["stop", code] => {
                close(state.0, e.at, state.1, &state.2, &mut out);
                state = (e.at, if code == "05" { 1 } else { 2 }, code.to_string());
            }
            ["run"] => {
                close(state.0, e.at, state.1, &state.2, &mut out);
                state = (e.at, 0, String::new());
            }
            ["cycle", k] => {
                let k: u64 = k.trim_start_matches('+').parse().unwrap();
                out.parts += k;
                out.orders.last_mut().unwrap().2 += k;
            }
            ["order", item, "target", target] => {
                out.orders
                    .push((item.to_string(), target.parse().unwrap(), 0));
            }
            _ => panic!("unexpected log entry {e:?}"),
        }
    }
    close(state.0, end, state.1, &state.2, &mut out);
    out
}

/// Each unit of a bus a cell of its own (the shipped `imm-0N.toml`), three
/// agents sharing one poller on one simulated bus; a scripted day in
/// virtual time (stops with causes, a mould change, cycles); then each
/// unit's `report daily` gives the hourly slots, availability, stop
/// causes, production and orders that the simulator's own log says.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_unit_a_cell_of_its_own_reports_its_day_as_the_simulator_logged_it() {
    use cellwatch::clock::Clock;
    let dir = tempfile::tempdir().unwrap();
    let start: u64 = chrono::NaiveDate::from_ymd_opt(2021, 3, 2)
        .unwrap()
        .and_hms_opt(0, 0, 0)
        .unwrap()
        .and_utc()
        .timestamp_millis() as u64;
    let min = |m: u64| start + m * 60_000;
    let clock = Clock::manual(start);
    let bus = MouldingBus::new(3).timed_by(clock.clone());
    let (addr, server) = bus
        .listen_tcp("127.0.0.1:0".parse().unwrap())
        .await
        .unwrap();
    let names = ["imm-01", "imm-02", "imm-03"];
    crate::util::bus_pki(
        dir.path(),
        &names
            .map(|n| format!("agent-{n}"))
            .each_ref()
            .map(|s| s.as_str()),
    );
    let mut configs = Vec::new();
    for (i, name) in names.iter().enumerate() {
        let path = crate::util::root().join(format!("config/moulding/{name}.toml"));
        let mut c = cellwatch::config::load(&path).unwrap();
        assert_eq!(c.cell, *name);
        let l = c.legacy.as_mut().unwrap();
        l.transport = Transport::Tcp(addr.to_string());
        l.poll_interval = Duration::from_millis(20);
        c.zenoh.listen = vec!["quic/127.0.0.1:0".into()];
        c.zenoh.tls = Some(crate::util::bus_tls(dir.path(), &format!("agent-{name}")));
        c.journal.path = dir.path().join(format!("{name}.sqlite"));
        c.zenoh.signing_key = Some(c.journal.path.with_extension("agent.key"));
        c.metrics = None;
        assert!(c
            .tags
            .iter()
            .all(|t| t.node_id.starts_with(&format!("@{:02X}/", i + 1))));
        configs.push(c);
    }
    let cells: Vec<_> = configs
        .iter()
        .map(|c| (c.cell.clone(), c.legacy.clone(), c.tags.clone()))
        .collect();
    let (shares, buses) = at_bus::share_buses(&cells).unwrap();
    assert_eq!(buses.len(), 1, "one poller for the three cells");
    let mut agents = Vec::new();
    for (c, share) in configs.into_iter().zip(shares) {
        let options = cellwatch::agent::Options {
            source: Some(Box::new(share.expect("a share of the bus"))),
            clock: clock.clone(),
            ..Default::default()
        };
        agents.push(cellwatch::agent::start_with(c, options).await.unwrap());
    }
    let (stop_bus, mut stopped) = tokio::sync::watch::channel(false);
    let bus_poller = buses.into_iter().next().unwrap().timed_by(clock.clone());
    let poller = tokio::spawn(bus_poller.run(async move {
        let _ = stopped.wait_for(|s| *s).await;
    }));
    let db = |u: usize| dir.path().join(format!("{}.sqlite", names[u]));
    let mut committed: Vec<_> = agents.iter().map(|a| a.committed()).collect();
    for (u, c) in committed.iter_mut().enumerate() {
        crate::util::row_at(c, &db(u), "orders", start).await;
        crate::util::row_at(c, &db(u), "state_history", start).await;
    }
    // The day's script, minutes after midnight: (unit, what).
    enum Do {
        Stop(u16),
        Run,
        Order(&'static str, u32),
    }
    let mut script: Vec<(u64, u8, Do)> = vec![
        (150, 2, Do::Stop(Status::FRONT_DOOR_OPEN)),
        (190, 2, Do::Run),
        (375, 1, Do::Stop(Status::MOULD_CLAMP_ABNORMAL)),
        (380, 1, Do::Run),
        (585, 2, Do::Stop(Status::MOULD_CHANGE)),
        (620, 2, Do::Order("B-200", 400)),
        (640, 2, Do::Run),
        (720, 3, Do::Order("C-300", 250)),
        (845, 2, Do::Stop(Status::STOPPED)),
        (900, 2, Do::Run),
        (1370, 2, Do::Stop(Status::ROBOT_ABNORMAL)),
    ];
    script.sort_by_key(|(m, _, _)| *m);
    let mut cycle_at = 5;
    let mut next = script.into_iter().peekable();
    loop {
        let event = next.peek().map(|(m, _, _)| *m);
        if cycle_at >= 24 * 60 && event.is_none() {
            break;
        }
        if event.is_some_and(|m| m <= cycle_at) {
            let (m, unit, what) = next.next().unwrap();
            clock.set(min(m));
            let u = usize::from(unit - 1);
            match what {
                Do::Stop(bit) => bus.stop(unit, Some(bit)),
                Do::Run => bus.stop(unit, None),
                Do::Order(item, target) => bus.set_order(unit, item, target),
            }
            let table = if matches!(what, Do::Order(..)) {
                "orders"
            } else {
                "state_history"
            };
            crate::util::row_at(&mut committed[u], &db(u), table, min(m)).await;
        } else {
            clock.set(min(cycle_at));
            let running: Vec<usize> = (1..=3u8)
                .filter(|&n| bus.unit(n).unwrap().bits & Status::RUNNING != 0)
                .map(|n| usize::from(n - 1))
                .collect();
            bus.cycle();
            for u in running {
                crate::util::row_at(&mut committed[u], &db(u), "production", min(cycle_at)).await;
            }
            cycle_at += 37;
        }
    }
    clock.set(min(24 * 60));
    let _ = stop_bus.send(true);
    for a in agents {
        a.stop().await;
    }
    poller.await.unwrap().unwrap();
    server.abort();
    let log = bus.log();
    for u in 0..3u8 {
        let expected = logged(&log, u + 1, start);
        let r = crate::util::daily_report(&db(usize::from(u)), "2021-03-02");
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        for (h, [run, idle, fault]) in expected.hours.iter().enumerate() {
            let got = &r["hours"][h];
            assert!(
                close(got["running"].as_f64().unwrap(), *run)
                    && close(got["idle"].as_f64().unwrap(), *idle)
                    && close(got["fault"].as_f64().unwrap(), *fault)
                    && close(got["offline"].as_f64().unwrap(), 0.0),
                "unit {} hour {h}: report {got}, log {run} / {idle} / {fault}",
                u + 1
            );
        }
        let run: f64 = expected.hours.iter().map(|h| h[0]).sum();
        let availability = 100.0 * run / (24.0 * 60.0);
        assert!(
            close(r["availability"].as_f64().unwrap(), availability),
            "{r}"
        );
        let causes: std::collections::BTreeMap<String, (u64, f64)> = r["stop_causes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| {
                (
                    c["code"].as_str().unwrap().to_string(),
                    (c["count"].as_u64().unwrap(), c["minutes"].as_f64().unwrap()),
                )
            })
            .collect();
        assert_eq!(
            causes.keys().collect::<Vec<_>>(),
            expected.causes.keys().collect::<Vec<_>>()
        );
        for (code, (count, minutes)) in &expected.causes {
            assert_eq!(causes[code].0, *count, "unit {} cause {code}", u + 1);
            assert!(
                close(causes[code].1, *minutes),
                "unit {} cause {code}: {r}",
                u + 1
            );
        }
        assert_eq!(r["production"], expected.parts, "unit {}", u + 1);
        let orders: Vec<(String, u64, u64)> = r["orders"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| {
                (
                    o["item"].as_str().unwrap().to_string(),
                    o["target"].as_u64().unwrap(),
                    o["parts"].as_u64().unwrap(),
                )
            })
            .collect();
        assert_eq!(orders, expected.orders, "unit {}", u + 1);
    }
    // The script did what it says: unit 2 stopped for four causes, unit 1
    // for one, unit 3 never; unit 2 still stopped at midnight.
    let stops = |u: u8| logged(&log, u, start).causes.len();
    assert_eq!((stops(1), stops(2), stops(3)), (1, 4, 0));
}
