//! The LCD-glass carrying robot of paper 004, served over OPC UA.
//!
//! The PLC side runs the charts of `config/robot/robot.sfc.toml` with
//! [`Plant`] (its runner and plant), one scan every [`SCAN`]: eq. (1)/(2) for every transition,
//! and for the forcible ones (t3, t18) the force switch term of eq.
//! (3)/(4). The plant around it is simple: a step that has been active
//! for the dwell time makes the inputs of its first outgoing transition
//! true (the shuttle arrives, the arm finishes); every other input is off.
//! A test or the demo puts a step in error ([`SimulatedRobot::stick`]) —
//! active, never done — and holds inputs ([`SimulatedRobot::pin`]).
//!
//! The remote module's force switch `%IX0.3.1` and stop switch `%IX0.3.0`
//! are the only variables a client may write; every write is in the
//! server's [`WriteLog`]. The stop switch stops the charts (no transition
//! fires) and lights `%QX0.3.0` until [`SimulatedRobot::restart`].

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use cellwatch_models::sfc::plant::{self, Plant};
use cellwatch_models::sfc::{text, Sfc, StepRef};
use cellwatch_models::signal::Signal;

use super::server::{SimOptions, SimServer, WriteLog};
use super::SimError;

/// The charts the simulated PLC runs.
pub const CHARTS: &str = include_str!("../../../config/robot/robot.sfc.toml");

/// The force switch of the remote module (paper 004: `%IX0.3.1`).
pub const FORCE_SWITCH: &str = "%IX0.3.1";
/// The stop switch of the remote module.
pub const STOP_SWITCH: &str = "%IX0.3.0";
/// The lamp that says the system is stopped.
pub const STOPPED: &str = "%QX0.3.0";

/// The transitions the PLC program lets the force switch fire (its
/// eq. (3)/(4) terms, as `cellwatch sfc patch` prints them).
pub const FORCIBLE: [(&str, &str); 2] = [("F1", "t3"), ("F2", "t18")];

/// How often the simulated PLC scans.
pub const SCAN: Duration = Duration::from_millis(20);

struct State {
    plant: Plant,
    started: tokio::time::Instant,
    stopped: bool,
    /// What the server shows, to write only changes.
    shown: HashMap<String, bool>,
    /// When each variable last became true, ms since the epoch (its
    /// source timestamp).
    rose: HashMap<String, u64>,
}

/// A running simulated robot cell.
#[derive(Clone)]
pub struct SimulatedRobot {
    server: SimServer,
    sfc: Arc<Sfc>,
    plant: Arc<Mutex<State>>,
    log: WriteLog,
}

impl SimulatedRobot {
    /// Serves the robot's step flags, inputs and switches; each step done
    /// after `dwell`. Call [`SimulatedRobot::run`] to scan.
    ///
    /// # Errors
    /// The port cannot be bound or the server cannot be built.
    pub async fn start(options: &SimOptions, dwell: Duration) -> Result<SimulatedRobot, SimError> {
        let sfc = text::parse("robot.sfc.toml", CHARTS, &|_| true)
            .map_err(|problems| SimError::Charts { problems })?;
        let dwell = dwell.as_millis() as u64;
        let mut names: Vec<String> = plant::signals(&sfc)
            .iter()
            .map(|s| s.name().to_string())
            .collect();
        names.extend([FORCE_SWITCH, STOP_SWITCH, STOPPED].map(String::from));
        let variables: Vec<(String, bool)> = names.iter().map(|n| (n.clone(), false)).collect();
        let server = SimServer::start(
            options,
            "robot",
            "cellwatch simulated LCD-glass robot",
            &variables,
        )
        .await?;
        let log = server.writable(&[FORCE_SWITCH, STOP_SWITCH])?;
        let robot = SimulatedRobot {
            server,
            plant: Arc::new(Mutex::new(State {
                plant: Plant::new(&sfc, [dwell, dwell], 1),
                started: tokio::time::Instant::now(),
                stopped: false,
                shown: variables.into_iter().collect(),
                rose: HashMap::new(),
            })),
            sfc: Arc::new(sfc),
            log,
        };
        robot.scan();
        Ok(robot)
    }

    /// Scans forever, every [`SCAN`].
    pub async fn run(&self) {
        let mut every = tokio::time::interval(SCAN);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            every.tick().await;
            self.scan();
        }
    }

    /// One PLC scan: inputs from the plant, the charts, outputs to the
    /// server.
    fn scan(&self) {
        let Ok(mut p) = self.plant.lock() else {
            return;
        };
        let now = p.started.elapsed().as_millis() as u64;
        let force = self.log.value(FORCE_SWITCH).unwrap_or(false);
        if self.log.value(STOP_SWITCH).unwrap_or(false) {
            p.stopped = true;
        }
        let sfc = &self.sfc;
        let forcible = |c: usize, id: &str| {
            FORCIBLE
                .iter()
                .any(|&(fc, ft)| sfc.charts[c].name == fc && ft == id)
        };
        let stopped = p.stopped;
        let scanned = p.plant.scan(sfc, now, force, stopped, &forcible);
        let mut out: Vec<(String, bool)> = plant::shown(sfc, &p.plant, &scanned)
            .into_iter()
            .map(|(s, v)| (s.name().to_string(), v))
            .collect();
        out.push((STOPPED.to_string(), p.stopped));
        let changed: Vec<(String, bool)> = out
            .into_iter()
            .filter(|(n, v)| p.shown.get(n) != Some(v))
            .collect();
        if changed.is_empty() {
            return;
        }
        let at = crate::clock::now_ms();
        for (n, v) in &changed {
            p.shown.insert(n.clone(), *v);
            if *v {
                p.rose.insert(n.clone(), at);
            }
        }
        let stamp = chrono::DateTime::from_timestamp_millis(at as i64)
            .map_or_else(opcua::types::DateTime::now, opcua::types::DateTime::from);
        if let Err(e) = self.server.set_at(&changed, stamp) {
            tracing::error!(error = %e, "simulated robot");
        }
    }

    /// Puts step `name` (`F1.S2`) in error (`true`: active but never done)
    /// or out of it.
    ///
    /// # Errors
    /// No such step.
    pub fn stick(&self, name: &str, stuck: bool) -> Result<(), SimError> {
        let r = self.step(name)?;
        let mut p = self.plant.lock().map_err(|_| SimError::Poisoned)?;
        p.plant.runner_mut().set_faulty(r, stuck);
        Ok(())
    }

    /// Holds input `name` at `value` (`None`: the plant drives it again).
    pub fn pin(&self, name: &str, value: Option<bool>) {
        if let Ok(mut p) = self.plant.lock() {
            p.plant.pin(Signal::new(name), value);
        }
    }

    /// The active steps (`F1.S2`), sorted.
    pub fn active(&self) -> Vec<String> {
        let Ok(p) = self.plant.lock() else {
            return Vec::new();
        };
        let mut names: Vec<String> = p
            .plant
            .runner()
            .active()
            .map(|r| self.sfc.step_name(r))
            .collect();
        names.sort();
        names
    }

    /// When variable `name` (a step flag `S2.X`, an input) last became
    /// true, as stamped on the server, ms since the epoch.
    pub fn rose_at(&self, name: &str) -> Option<u64> {
        self.plant.lock().ok()?.rose.get(name).copied()
    }

    /// Whether the stop switch has stopped the charts.
    pub fn stopped(&self) -> bool {
        self.plant.lock().is_ok_and(|p| p.stopped)
    }

    /// Clears a stop (the local restart at the machine).
    pub fn restart(&self) {
        if let Ok(mut p) = self.plant.lock() {
            p.stopped = false;
        }
    }

    /// The demo's scenario, forever: normal cycles; then F1.S2 in error
    /// with the shuttle not at its waiting position, so that its stuck
    /// alarm comes with the criteria analysis; a force on F1.t3 asked
    /// through `force` while t3 is false (the agent refuses it), then again
    /// once the shuttle has arrived (carried out: F2's sub-jobs start);
    /// then the same for F2.S15 (data save) and F2.t18 back to F1's S0.
    /// `stuck` waits until the agent has the stuck alarm of a step
    /// (`CHART.STEP`) up; `note` says what happens.
    pub async fn play_demo<F, Fut, E, S, SFut>(&self, stuck: S, force: F, note: impl Fn(String))
    where
        F: Fn(&'static str) -> Fut,
        Fut: std::future::Future<Output = Result<(bool, String), E>>,
        E: std::fmt::Display,
        S: Fn(&'static str) -> SFut,
        SFut: std::future::Future<Output = ()>,
    {
        // (stuck step, the input its transition waits for, the transition)
        const SCENES: [(&str, &str, &str, &str); 2] = [
            (
                "F1.S2",
                "%IX0.0.3",
                "F1.t3",
                "the shuttle does not reach its waiting position",
            ),
            (
                "F2.S15",
                "%IX0.2.2",
                "F2.t18",
                "the data save does not finish",
            ),
        ];
        let ask = |t: &'static str| {
            let f = force(t);
            async move {
                match f.await {
                    Ok((true, detail)) => format!("force {t}: carried out: {detail}"),
                    Ok((false, detail)) => format!("force {t}: refused: {detail}"),
                    Err(e) => format!("force {t}: not sent: {e}"),
                }
            }
        };
        loop {
            for (step, input, transition, why) in SCENES {
                note("normal cycles".into());
                tokio::time::sleep(Duration::from_secs(10)).await;
                note(format!("{step} in error: {why} ({input} held off)"));
                let _ = self.stick(step, true);
                self.pin(input, Some(false));
                stuck(step).await;
                note(format!(
                    "operator demo asks to force {transition} while its condition is false"
                ));
                note(ask(transition).await);
                note(format!("{input} on: the condition of {transition} holds"));
                self.pin(input, Some(true));
                tokio::time::sleep(Duration::from_millis(1_500)).await;
                note(format!("operator demo asks to force {transition} again"));
                note(ask(transition).await);
                let _ = self.stick(step, false);
                self.pin(input, None);
            }
        }
    }

    /// Every write clients made to the switches, in order.
    pub fn writes(&self) -> Vec<(String, bool)> {
        self.log.writes()
    }

    fn step(&self, name: &str) -> Result<StepRef, SimError> {
        let (chart, step) = name
            .split_once('.')
            .ok_or_else(|| SimError::NotStepName { name: name.into() })?;
        let c = self.sfc.chart(chart).ok_or_else(|| SimError::NoChart {
            chart: chart.into(),
        })?;
        let s = self.sfc.charts[c]
            .steps
            .iter()
            .position(|s| s.name == step)
            .ok_or_else(|| SimError::NoStep { name: name.into() })?;
        Ok(StepRef { chart: c, step: s })
    }

    /// The endpoint URL clients connect to.
    pub fn endpoint(&self) -> String {
        self.server.endpoint()
    }

    /// The address the server listens on.
    pub fn addr(&self) -> SocketAddr {
        self.server.addr()
    }

    /// Stops the server.
    pub fn stop(&self) {
        self.server.stop();
    }
}
