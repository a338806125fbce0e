//! What the bench and the replay source's thread share: the run ordered
//! (rate, faults), and what the source did (changes made and dropped,
//! faults injected, its own CPU time, the services it was asked for).
//! Neither side's code: the source writes it, the bench reads it.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use crate::load::Fault;

/// A run the bench orders: noise changes per second, and a limit switch
/// opened every `fault_every` for `fault_hold`, both counted from `at`
/// (when it was ordered: the publishing intervals' phase is the
/// subscription's own, as a server's is).
#[derive(Debug, Clone, Copy)]
pub struct Order {
    /// When the run starts.
    pub at: std::time::Instant,
    /// The wall-clock time then.
    pub wall: std::time::SystemTime,
    /// Noise changes per second.
    pub rate: u64,
    /// A switch opens this often.
    pub fault_every: Duration,
    /// And stays open this long.
    pub fault_hold: Duration,
}

/// What the bench and the source's thread share: the order, and what the
/// source did.
#[derive(Default)]
pub struct Control {
    /// The run under way, if any.
    pub(super) order: Mutex<Option<Order>>,
    /// When the last run was ended.
    pub(super) ended: Mutex<Option<std::time::Instant>>,
    /// Changes made (noise and switches), each one notification.
    pub(super) produced: AtomicU64,
    /// Changes dropped unsent: no Publish request came for them in time.
    dropped: AtomicU64,
    /// The faults injected, in order.
    pub(super) faults: Mutex<Vec<Fault>>,
    /// The source thread's CPU time, ns, as it last read it.
    cpu_ns: AtomicU64,
    /// The services asked for, by name, and how often.
    pub(super) asked: Mutex<BTreeMap<&'static str, u64>>,
}

impl Control {
    pub(super) fn order(&self) -> Option<Order> {
        self.order.lock().ok().and_then(|o| *o)
    }

    pub(super) fn ended(&self) -> Option<std::time::Instant> {
        self.ended.lock().ok().and_then(|e| *e)
    }

    pub(super) fn made(&self, n: u64) {
        self.produced.fetch_add(n, Ordering::Relaxed);
    }

    pub(super) fn dropped(&self, n: u64) {
        self.dropped.fetch_add(n, Ordering::Relaxed);
    }

    pub(super) fn fault(&self, f: Fault) {
        if let Ok(mut faults) = self.faults.lock() {
            faults.push(f);
        }
    }

    /// Reads the calling thread's CPU time (the source's thread).
    pub(super) fn note_cpu(&self) {
        let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
        let ns = t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64;
        self.cpu_ns.store(ns, Ordering::Relaxed);
    }

    /// The source's CPU seconds so far.
    pub fn cpu(&self) -> f64 {
        self.cpu_ns.load(Ordering::Relaxed) as f64 / 1e9
    }

    /// Changes dropped unsent so far.
    pub fn dropped_so_far(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// The services asked for so far, by name, and how often.
    pub fn asked(&self) -> BTreeMap<&'static str, u64> {
        self.asked.lock().map(|a| a.clone()).unwrap_or_default()
    }
}
