//! `cellwatch run` under systemd (`Type=notify`, `deploy/cellwatch@.service`):
//! `READY=1` once every cell is running, `WATCHDOG=1` while no cell loop
//! is stuck in a step ([`Feeder`]), `RELOADING=1` and `READY=1` around a
//! reload, `STOPPING=1` on the way out. Without systemd (no
//! `NOTIFY_SOCKET`), nothing is sent.

use std::time::{Duration, Instant};

use sd_notify::NotifyState;

use crate::health::{Feed, Feeder, Health};

fn send(states: &[NotifyState]) {
    if let Err(e) = sd_notify::notify(false, states) {
        tracing::warn!(error = %e, "cannot notify systemd");
    }
}

/// Every cell is running.
pub(crate) fn ready(cells: &[String]) {
    let status = format!("watching {}", cells.join(", "));
    send(&[NotifyState::Ready, NotifyState::Status(&status)]);
}

/// The configurations are being read again (systemd's `notify-reload`
/// protocol wants the monotonic time with it); [`ready`] follows.
pub(crate) fn reloading() {
    match NotifyState::monotonic_usec_now() {
        Ok(now) => send(&[NotifyState::Reloading, now]),
        Err(_) => send(&[NotifyState::Reloading]),
    }
}

/// The process is stopping.
pub(crate) fn stopping() {
    send(&[NotifyState::Stopping]);
}

/// Feeds systemd's watchdog while no cell loop of `health` is stuck in a step,
/// if systemd asked for it (`WatchdogSec`); a stuck loop stops the
/// feeding, which systemd answers by restarting the process.
pub(crate) fn watchdog(health: Health) -> Option<tokio::task::JoinHandle<()>> {
    let mut usec = 0;
    if !sd_notify::watchdog_enabled(false, &mut usec) {
        return None;
    }
    let interval = Duration::from_micros(usec);
    tracing::info!(
        interval = %humantime::format_duration(interval),
        "feeding systemd's watchdog while every cell loop goes round"
    );
    let mut feeder = Feeder::new(interval);
    Some(tokio::spawn(async move {
        let mut every = tokio::time::interval(Feeder::period(interval));
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            every.tick().await;
            match feeder.round(&health, Instant::now()) {
                Feed::Feed => send(&[NotifyState::Watchdog]),
                Feed::Withhold(Some(why)) => {
                    let why = why.join("; ");
                    tracing::error!(%why, "not feeding systemd's watchdog");
                    send(&[NotifyState::Status(&format!("stuck: {why}"))]);
                }
                Feed::Withhold(None) => {}
            }
        }
    }))
}
