//! Is the process alive, and is each cell ready? What `/healthz` and
//! `/readyz` answer, and what feeds systemd's watchdog.
//!
//! - **Alive**: no cell loop of the process has been in one step for
//!   [`STALLED_AFTER`]. Each loop says when it takes an input and when it
//!   has gone round and waits for the next: one that took an input and has
//!   not gone round since is stuck in a step (an engine call, a sink, or
//!   the journal's queue). A loop waiting is alive while it waits no longer
//!   than [`MAX_SLEEP`] past the stall time: an idle loop sleeps to its
//!   next deadline, [`MAX_SLEEP`] at most, so one that has not woken for
//!   longer is starved (its runtime's threads are blocked).
//! - **Ready**: each cell's source is connected, its bus session is up
//!   (open, and linked to a router or peer when `zenoh.connect` names
//!   one), and its journal can write.
//!
//! One [`Health`] is kept per process (`cellwatch run A.toml B.toml`: both
//! cells), so that whichever metrics port a supervisor probes, the answer
//! covers every cell a restart would restart. The cell loop reports to its
//! [`CellHealth`] (two clock reads and atomic stores per round); the
//! answers read it.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::watch;

/// A cell loop that has been in one step for this long is stuck.
pub(crate) const STALLED_AFTER: Duration = Duration::from_secs(5);

/// The longest a cell loop sleeps without looking at the time (its
/// deadlines wake it sooner).
pub(crate) const MAX_SLEEP: Duration = Duration::from_secs(1);

/// The health of every cell of this process.
#[derive(Clone)]
pub struct Health {
    cells: Arc<Mutex<Vec<Arc<CellHealth>>>>,
    /// What progress is measured from.
    base: Instant,
}

impl Default for Health {
    fn default() -> Self {
        Health {
            cells: Arc::default(),
            base: Instant::now(),
        }
    }
}

/// What one cell reports: its loop's progress, its source's connection,
/// and where to look for its journal's and bus's health.
pub struct CellHealth {
    cell: String,
    base: Instant,
    /// When the loop last took an input or went round, µs after `base`;
    /// with [`WAITING`] set, it went round then and waits for an input.
    progress: AtomicU64,
    /// The loop has ended.
    ended: AtomicBool,
    /// The source's connection: `None` until it has said.
    source: Mutex<Option<(bool, String)>>,
    /// `Some(why)` while the journal cannot write.
    journal: Mutex<Option<watch::Receiver<Option<String>>>>,
    bus: Mutex<Option<BusProbe>>,
}

/// The bit of `CellHealth::progress` set while the loop waits for an input.
const WAITING: u64 = 1 << 63;

/// How to tell whether a cell's bus session is up.
struct BusProbe {
    session: zenoh::Session,
    /// The endpoints the session connects to (none: it only listens, and
    /// being open is being up).
    connect: Vec<String>,
}

impl Health {
    /// A cell's health, kept with the others of this process until
    /// [`Health::remove`].
    pub fn add(&self, cell: &str) -> Arc<CellHealth> {
        let health = Arc::new(CellHealth {
            cell: cell.into(),
            base: self.base,
            progress: AtomicU64::new(micros(self.base, Instant::now())),
            ended: AtomicBool::new(false),
            source: Mutex::new(None),
            journal: Mutex::new(None),
            bus: Mutex::new(None),
        });
        self.lock().push(health.clone());
        health
    }

    /// Forgets `cell` (its agent was stopped on purpose).
    pub fn remove(&self, cell: &Arc<CellHealth>) {
        self.lock().retain(|c| !Arc::ptr_eq(c, cell));
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Arc<CellHealth>>> {
        self.cells
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn cells(&self) -> Vec<Arc<CellHealth>> {
        self.lock().clone()
    }

    /// `/healthz`: every cell loop's progress at `now`; `Err` names each
    /// loop that has been in one step for more than `stalled_after` or has
    /// ended.
    ///
    /// # Errors
    /// One line per cell that is not alive.
    pub fn alive(&self, now: Instant, stalled_after: Duration) -> Result<Vec<String>, Vec<String>> {
        let mut ok = Vec::new();
        let mut bad = Vec::new();
        for c in self.cells() {
            let (ago, waiting) = c.since_progress(now);
            if c.ended.load(Ordering::Acquire) {
                bad.push(format!("cell {}: the cell loop has ended", c.cell));
            } else if waiting && ago > stalled_after + MAX_SLEEP {
                bad.push(format!(
                    "cell {}: the cell loop has not woken for {:.1} s (it sleeps {} s at most)",
                    c.cell,
                    ago.as_secs_f64(),
                    MAX_SLEEP.as_secs()
                ));
            } else if waiting {
                ok.push(format!(
                    "cell {}: the cell loop went round {:.1} s ago and waits for input",
                    c.cell,
                    ago.as_secs_f64()
                ));
            } else if ago > stalled_after {
                bad.push(format!(
                    "cell {}: the cell loop has made no progress for {:.1} s",
                    c.cell,
                    ago.as_secs_f64()
                ));
            } else {
                ok.push(format!(
                    "cell {}: the cell loop went round {:.1} s ago",
                    c.cell,
                    ago.as_secs_f64()
                ));
            }
        }
        if bad.is_empty() {
            Ok(ok)
        } else {
            Err(bad)
        }
    }

    /// `/readyz`: per cell, its source, bus and journal.
    ///
    /// # Errors
    /// One line per cell that is not ready, saying each reason.
    pub async fn ready(&self) -> Result<Vec<String>, Vec<String>> {
        let mut ok = Vec::new();
        let mut bad = Vec::new();
        for c in self.cells() {
            let (fine, line) = c.ready().await;
            if fine {
                ok.push(line);
            } else {
                bad.push(line);
            }
        }
        if bad.is_empty() {
            Ok(ok)
        } else {
            Err(bad)
        }
    }
}

fn micros(base: Instant, at: Instant) -> u64 {
    u64::try_from(at.saturating_duration_since(base).as_micros())
        .map_or(WAITING - 1, |us| us.min(WAITING - 1))
}

impl CellHealth {
    /// The loop took an input now: it is stuck if it has not gone round
    /// within the stall time.
    pub fn working(&self) {
        self.working_at(Instant::now());
    }

    /// The loop took an input at `at`.
    pub fn working_at(&self, at: Instant) {
        self.progress
            .store(micros(self.base, at), Ordering::Release);
    }

    /// The loop went round now and waits for its next input: alive,
    /// however long that takes.
    pub fn waiting(&self) {
        self.waiting_at(Instant::now());
    }

    /// The loop went round at `at` and waits for its next input.
    pub fn waiting_at(&self, at: Instant) {
        self.progress
            .store(micros(self.base, at) | WAITING, Ordering::Release);
    }

    /// The loop has ended.
    pub fn ended(&self) {
        self.ended.store(true, Ordering::Release);
    }

    /// How long ago, at `now`, the loop last took an input or went round,
    /// and whether it is waiting for an input since.
    fn since_progress(&self, now: Instant) -> (Duration, bool) {
        let progress = self.progress.load(Ordering::Acquire);
        let at = self.base + Duration::from_micros(progress & !WAITING);
        (now.saturating_duration_since(at), progress & WAITING != 0)
    }

    /// The source connected (`up`, to `detail`) or lost its connection
    /// (`detail` says why).
    pub fn source(&self, up: bool, detail: &str) {
        *self
            .source
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some((up, detail.into()));
    }

    /// Reads the journal's health from `health` (`Some(why)` while it
    /// cannot write).
    pub fn journal(&self, health: watch::Receiver<Option<String>>) {
        *self
            .journal
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(health);
    }

    /// Tells the bus's health from `session`, which connects to `connect`.
    pub fn bus(&self, session: zenoh::Session, connect: Vec<String>) {
        *self
            .bus
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) =
            Some(BusProbe { session, connect });
    }

    /// Whether the cell is ready, and one line saying so or why not.
    async fn ready(&self) -> (bool, String) {
        let mut why = Vec::new();
        let mut fine = Vec::new();
        let source = self
            .source
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        match source {
            Some((true, to)) => fine.push(format!("source connected ({to})")),
            Some((false, detail)) => why.push(format!("source not connected: {detail}")),
            None => why.push("source not connected yet".into()),
        }
        let journal = self
            .journal
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .as_ref()
            .map(|h| h.borrow().clone());
        match journal {
            Some(Some(problem)) => why.push(format!("journal cannot write: {problem}")),
            Some(None) => fine.push("journal writable".into()),
            None => why.push("journal not open".into()),
        }
        let bus = self
            .bus
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .as_ref()
            .map(|b| (b.session.clone(), b.connect.clone()));
        match bus {
            None => why.push("bus session not open".into()),
            Some((session, _)) if session.is_closed() => why.push("bus session closed".into()),
            Some((session, connect)) => {
                let info = session.info();
                let linked = info.routers_zid().await.count() + info.peers_zid().await.count() > 0;
                if connect.is_empty() || linked {
                    fine.push("bus session up".into());
                } else {
                    why.push(format!(
                        "bus session linked to none of {}",
                        connect.join(", ")
                    ));
                }
            }
        }
        if why.is_empty() {
            (true, format!("cell {}: {}", self.cell, fine.join(", ")))
        } else {
            (false, format!("cell {}: {}", self.cell, why.join(", ")))
        }
    }
}

/// Feeds systemd's watchdog only while no cell loop is stuck in a step:
/// a stuck loop stops the feeding, and systemd restarts the process
/// (`WatchdogSec`).
pub(crate) struct Feeder {
    stalled_after: Duration,
    /// The last round withheld (the reasons are said once, when it
    /// starts).
    withheld: bool,
}

/// What one round of the feeder decided.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Feed {
    /// Every loop is alive: `WATCHDOG=1`.
    Feed,
    /// Not fed; the reasons, the first round not fed (`None` after, until
    /// fed again).
    Withhold(Option<Vec<String>>),
}

impl Feeder {
    /// A feeder for a watchdog of `interval` (systemd's `WATCHDOG_USEC`):
    /// a loop is stuck after [`STALLED_AFTER`], or half the interval if
    /// that is shorter, so that systemd hears of it in time.
    pub(crate) fn new(interval: Duration) -> Feeder {
        Feeder {
            stalled_after: STALLED_AFTER.min(interval / 2),
            withheld: false,
        }
    }

    /// How often to decide: four times per interval (systemd advises at
    /// least twice).
    pub(crate) fn period(interval: Duration) -> Duration {
        (interval / 4).max(Duration::from_millis(10))
    }

    /// Decides at `now`.
    pub(crate) fn round(&mut self, health: &Health, now: Instant) -> Feed {
        match health.alive(now, self.stalled_after) {
            Ok(_) => {
                self.withheld = false;
                Feed::Feed
            }
            Err(_) if self.withheld => Feed::Withhold(None),
            Err(why) => {
                self.withheld = true;
                Feed::Withhold(Some(why))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loop_that_stops_going_round_stops_feeding_the_watchdog() {
        let health = Health::default();
        let press = health.add("press");
        let lathe = health.add("lathe");
        let t0 = Instant::now();
        press.working_at(t0);
        lathe.working_at(t0);
        let mut feeder = Feeder::new(Duration::from_secs(20));
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_secs(1)),
            Feed::Feed
        );
        // The press goes on; the lathe's loop is stuck from t0.
        for s in 1..=5 {
            press.working_at(t0 + Duration::from_secs(s));
        }
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_millis(4_900)),
            Feed::Feed
        );
        let Feed::Withhold(Some(why)) = feeder.round(&health, t0 + Duration::from_millis(5_100))
        else {
            panic!("fed with a stuck loop");
        };
        assert_eq!(
            why,
            ["cell lathe: the cell loop has made no progress for 5.1 s"]
        );
        // Said once; still not fed.
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_millis(5_200)),
            Feed::Withhold(None)
        );
        // Going round again feeds again.
        lathe.working_at(t0 + Duration::from_secs(6));
        press.working_at(t0 + Duration::from_secs(6));
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_secs(6)),
            Feed::Feed
        );
        // An ended loop is not alive, however recent its last round.
        lathe.ended();
        assert!(matches!(
            feeder.round(&health, t0 + Duration::from_secs(6)),
            Feed::Withhold(Some(_))
        ));
        // A cell stopped on purpose is forgotten.
        health.remove(&lathe);
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_secs(6)),
            Feed::Feed
        );
    }

    #[test]
    fn a_short_watchdog_judges_sooner() {
        let health = Health::default();
        let cell = health.add("press");
        let t0 = Instant::now();
        cell.working_at(t0);
        let mut feeder = Feeder::new(Duration::from_secs(2));
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_millis(900)),
            Feed::Feed
        );
        assert!(matches!(
            feeder.round(&health, t0 + Duration::from_millis(1_100)),
            Feed::Withhold(Some(_))
        ));
        assert_eq!(
            Feeder::period(Duration::from_secs(2)),
            Duration::from_millis(500)
        );
    }

    #[test]
    fn a_loop_waiting_is_alive_while_it_may_sleep_and_starved_past_it() {
        let health = Health::default();
        let cell = health.add("press");
        let t0 = Instant::now();
        cell.waiting_at(t0);
        // A 2 s watchdog: stuck after 1 s in a step; a waiting loop may
        // sleep MAX_SLEEP more.
        let mut feeder = Feeder::new(Duration::from_secs(2));
        assert_eq!(
            feeder.round(&health, t0 + Duration::from_millis(1_900)),
            Feed::Feed
        );
        assert_eq!(
            health.alive(t0 + Duration::from_secs(3), STALLED_AFTER),
            Ok(vec![
                "cell press: the cell loop went round 3.0 s ago and waits for input".into()
            ])
        );
        // It has not woken for longer than it sleeps: its runtime starves it.
        assert!(matches!(
            feeder.round(&health, t0 + Duration::from_millis(2_100)),
            Feed::Withhold(Some(_))
        ));
        assert_eq!(
            health.alive(t0 + Duration::from_secs(3_600), STALLED_AFTER),
            Err(vec![
                "cell press: the cell loop has not woken for 3600.0 s (it sleeps 1 s at most)"
                    .into()
            ])
        );
        // It takes an input and stays in the step.
        let later = t0 + Duration::from_secs(3_600);
        cell.working_at(later);
        assert_eq!(
            feeder.round(&health, later + Duration::from_millis(900)),
            Feed::Feed
        );
        assert!(matches!(
            feeder.round(&health, later + Duration::from_millis(1_100)),
            Feed::Withhold(Some(_))
        ));
        // Round again, waiting: fed.
        cell.waiting_at(later + Duration::from_millis(1_200));
        assert_eq!(
            feeder.round(&health, later + Duration::from_millis(1_300)),
            Feed::Feed
        );
    }
}
