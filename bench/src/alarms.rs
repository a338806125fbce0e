//! The faults injected and the alarms reported: subscribers that note
//! each fault alarm's arrival, the matching of faults to alarms, and the
//! load generator that injects them.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use anyhow::anyhow;

use crate::cell::zenoh_config;
use crate::load::{self, Fault, LoadServer};

/// Alarms seen on the bus, per cell: (when received, the switch named as
/// the changed contact) for every `raised` transition of `fault`.
pub type Seen = Arc<Mutex<HashMap<String, Vec<(SystemTime, Option<usize>)>>>>;

/// Per cell, for every `raised` transition of `fault`: seconds from the
/// agent's put (the sample's timestamp, stamped by the publishing session)
/// to the subscriber's callback — the bus's own share of the latency (one
/// machine, one clock).
pub type Transits = Arc<Mutex<HashMap<String, Vec<f64>>>>;

/// Subscribes to the alarms of `cells` (a key expression chunk: `bench`,
/// `*`) through a peer session connected to `endpoints`.
pub async fn subscribe_alarms(
    endpoints: &[String],
    cells: &str,
) -> anyhow::Result<(Seen, Transits)> {
    let config = zenoh_config("peer", &[], endpoints)?;
    let session = zenoh::open(config).await.map_err(|e| anyhow!("{e}"))?;
    let transits: Transits = Arc::default();
    let seen = alarms_with_transits(&session, cells, Some(transits.clone())).await?;
    // The session lives as long as the process.
    std::mem::forget(session);
    Ok((seen, transits))
}

/// The alarms of `cells` as `session` receives them (its subscriber lives
/// as long as the process).
pub async fn alarms_into(session: &zenoh::Session, cells: &str) -> anyhow::Result<Seen> {
    alarms_with_transits(session, cells, None).await
}

async fn alarms_with_transits(
    session: &zenoh::Session,
    cells: &str,
    transits: Option<Transits>,
) -> anyhow::Result<Seen> {
    let seen: Seen = Arc::default();
    let out = seen.clone();
    let subscriber = session
        .declare_subscriber(format!("cellwatch/{cells}/alarms/**"))
        .callback(move |sample| {
            let now = SystemTime::now();
            // The alarm is the body of the agent's signed envelope.
            let Some(v) = serde_json::from_slice::<serde_json::Value>(&sample.payload().to_bytes())
                .ok()
                .and_then(|env| {
                    serde_json::from_str::<serde_json::Value>(env["body"].as_str()?).ok()
                })
            else {
                return;
            };
            let Some((cell, switch)) = fault_raised(&v) else {
                return;
            };
            let put = sample.timestamp().map(|t| t.get_time().to_system_time());
            if let (Some(transits), Some(transit)) =
                (&transits, put.and_then(|put| now.duration_since(put).ok()))
            {
                if let Ok(mut t) = transits.lock() {
                    t.entry(cell.clone())
                        .or_default()
                        .push(transit.as_secs_f64());
                }
            }
            if let Ok(mut s) = out.lock() {
                s.entry(cell).or_default().push((now, switch));
            }
        })
        .await
        .map_err(|e| anyhow!("{e}"))?;
    std::mem::forget(subscriber);
    Ok(seen)
}

/// An alarm event that is check `fault` raised: its cell, and the limit
/// switch named as the changed contact.
pub fn fault_raised(v: &serde_json::Value) -> Option<(String, Option<usize>)> {
    if v["id"] != "fault" || v["transition"] != "raised" {
        return None;
    }
    let switch = v["culprits"].as_array().and_then(|cs| {
        cs.iter()
            .find(|c| c["trigger"] == true)
            .and_then(|c| c["address"].as_str())
            .and_then(|a| a.strip_prefix("LS_"))
            .and_then(|k| k.parse().ok())
    });
    Some((v["cell"].as_str().unwrap_or_default().to_string(), switch))
}

/// For each fault, in order, the first alarm after it naming its switch
/// not already taken by an earlier fault: the latency of each fault so
/// reported, seconds.
pub fn match_faults(faults: &[Fault], seen: &[(SystemTime, Option<usize>)]) -> Vec<f64> {
    match_each(faults, seen).into_iter().flatten().collect()
}

/// [`match_faults`], fault by fault: `None` for one no alarm reported.
pub fn match_each(faults: &[Fault], seen: &[(SystemTime, Option<usize>)]) -> Vec<Option<f64>> {
    let mut used = vec![false; seen.len()];
    let mut out = Vec::new();
    for f in faults {
        let found = seen
            .iter()
            .enumerate()
            .find(|(i, (at, switch))| !used[*i] && *switch == Some(f.switch) && *at >= f.at);
        out.push(found.map(|(i, (at, _))| {
            used[i] = true;
            at.duration_since(f.at).unwrap_or_default().as_secs_f64()
        }));
    }
    out
}

/// The load generator of one run.
pub struct Generator {
    stop: Arc<AtomicBool>,
    produced: Arc<load::Produced>,
    thread: std::thread::JoinHandle<()>,
    started: Instant,
}

impl Generator {
    /// Starts `rate` noise changes per second and a fault every
    /// `fault_every`, held `fault_hold`.
    pub fn start(
        server: &LoadServer,
        rate: u64,
        fault_every: Duration,
        fault_hold: Duration,
        seed: u64,
    ) -> Generator {
        let stop = Arc::new(AtomicBool::new(false));
        let (produced, thread) = server.generate(rate, fault_every, fault_hold, seed, stop.clone());
        Generator {
            stop,
            produced,
            thread,
            started: Instant::now(),
        }
    }

    /// The faults injected so far.
    pub fn faults(&self) -> usize {
        self.produced.faults.lock().map_or(0, |f| f.len())
    }

    /// Stops it: changes made, faults injected, its worst lag (s), and how
    /// long it ran (s).
    pub fn stop(self) -> (u64, Vec<Fault>, f64, f64) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.thread.join();
        let seconds = self.started.elapsed().as_secs_f64();
        let faults = self
            .produced
            .faults
            .lock()
            .map(|f| f.clone())
            .unwrap_or_default();
        (
            self.produced.changes.load(Ordering::Relaxed),
            faults,
            self.produced.max_lag_us.load(Ordering::Relaxed) as f64 / 1e6,
            seconds,
        )
    }
}
