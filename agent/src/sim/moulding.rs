//! A simulated bus of injection-moulding units (paper 002): each unit's
//! gateway answers the control computer's `@` frames by unit number, as
//! on an RS-485 multidrop line, over TCP (a serial device server's raw
//! socket) or a pseudo-terminal (a serial port).
//!
//! Units run cycles (production up by the cycle increment), stop with the
//! paper's Table 4 causes, go silent, and line noise corrupts a frame now
//! and then — all on command ([`MouldingBus`]), so tests and the demo
//! decide what happens. Every change is logged with its time
//! ([`MouldingBus::log`]), the simulator's own record to compare reports
//! with.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

use cellwatch_models::at_bus::{
    Decoded, Decoder, Field, Frame, Header, Status, END_DATA, END_NORMAL,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// One unit's gateway and machine.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unit {
    /// Status bits ([`Status`]).
    pub bits: u16,
    /// Production count (wraps after 999,999).
    pub production: u32,
    /// Target quantity.
    pub target: u32,
    /// Item (product) code.
    pub item: String,
    /// Stock-in quantity.
    pub stock_in: u32,
    /// Password.
    pub password: u16,
    /// Parts per cycle.
    pub cycle_increment: u8,
    /// Output bits.
    pub outputs: u16,
    /// Does not answer (a gateway switched off, a cut cable).
    pub silent: bool,
}

impl Default for Unit {
    fn default() -> Unit {
        Unit {
            bits: Status::RUNNING,
            production: 0,
            target: 1000,
            item: "ITEM-01".into(),
            stock_in: 0,
            password: 0,
            cycle_increment: 1,
            outputs: 0,
            silent: false,
        }
    }
}

impl Unit {
    /// The answer to `request`, or `None` for a frame a unit does not
    /// answer (an acknowledgement).
    fn answer(&mut self, request: &Frame) -> Option<Frame> {
        let unit = request.unit;
        let number =
            |f: Field, n: u64| Frame::new(unit, request.header, f.number(n).unwrap_or_default());
        Some(match request.header {
            Header::ReadStatus => Frame::new(
                unit,
                Header::ReadStatus,
                Status {
                    bits: self.bits,
                    production: self.production,
                }
                .text(),
            ),
            Header::ReadItem => Frame::new(unit, Header::ReadItem, format!("{:<8}", self.item)),
            Header::ReadTarget => number(Field::Quantity, u64::from(self.target)),
            Header::ReadProduction => number(Field::Quantity, u64::from(self.production)),
            Header::ReadStockIn => number(Field::Quantity, u64::from(self.stock_in)),
            Header::ReadPassword => number(Field::Password, u64::from(self.password)),
            Header::ReadCycleIncrement => {
                number(Field::CycleIncrement, u64::from(self.cycle_increment))
            }
            Header::ReadOutputs => number(Field::Outputs, u64::from(self.outputs)),
            Header::Ack | Header::Nak => return None,
            write => {
                let text = request.text.trim_end();
                let n: u64 = if write == Header::WriteOutputs {
                    u64::from_str_radix(text, 16).unwrap_or(0)
                } else {
                    text.parse().unwrap_or(0)
                };
                match write {
                    Header::WriteItem => self.item = text.to_string(),
                    Header::WriteTarget => self.target = n as u32,
                    Header::WriteProduction => self.production = n as u32,
                    Header::WriteStockIn => self.stock_in = n as u32,
                    Header::WritePassword => self.password = n as u16,
                    Header::WriteCycleIncrement => self.cycle_increment = n as u8,
                    Header::WriteOutputs => self.outputs = n as u16,
                    _ => {}
                }
                Frame::ack(unit, END_NORMAL)
            }
        })
    }
}

/// What happened on the simulated bus, for comparing with reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogEntry {
    /// When, ms since the epoch.
    pub at: u64,
    /// Which unit.
    pub unit: u8,
    /// What (`stop 01`, `run`, `cycle +1`, `write WT001500`).
    pub what: String,
}

/// A bus of simulated units.
#[derive(Clone, Default)]
pub struct MouldingBus {
    units: Arc<Mutex<BTreeMap<u8, Unit>>>,
    /// Answers still to corrupt (line noise).
    noise: Arc<AtomicU32>,
    log: Arc<Mutex<Vec<LogEntry>>>,
    /// Requests answered, for tests.
    answered: Arc<AtomicU32>,
    /// The time the log is written in.
    clock: crate::clock::Clock,
}

impl MouldingBus {
    /// Units `1..=units`, each running item `ITEM-01`, target 1000.
    pub fn new(units: u8) -> MouldingBus {
        let bus = MouldingBus::default();
        if let Ok(mut u) = bus.units.lock() {
            for n in 1..=units {
                u.insert(n, Unit::default());
            }
        }
        bus
    }

    /// Logs in `clock`'s time (a test's virtual day) instead of the
    /// system's.
    #[must_use]
    pub fn timed_by(mut self, clock: crate::clock::Clock) -> MouldingBus {
        self.clock = clock;
        self
    }

    fn note(&self, unit: u8, what: String) {
        if let Ok(mut log) = self.log.lock() {
            log.push(LogEntry {
                at: self.clock.now_ms(),
                unit,
                what,
            });
        }
    }

    /// Changes unit `n` (no such unit: nothing).
    pub fn with_unit<T>(&self, n: u8, f: impl FnOnce(&mut Unit) -> T) -> Option<T> {
        self.units.lock().ok()?.get_mut(&n).map(f)
    }

    /// Unit `n` stops with a Table 4 cause bit ([`Status::FRONT_DOOR_OPEN`]
    /// ...), or runs again with `None`.
    pub fn stop(&self, n: u8, cause: Option<u16>) {
        let done = self.with_unit(n, |u| {
            u.bits = match cause {
                Some(bit) => bit,
                None => Status::RUNNING,
            };
        });
        if done.is_some() {
            let what = match cause {
                Some(bit) => {
                    let code = Status::NAMED
                        .iter()
                        .find(|(_, b, _)| *b == bit)
                        .and_then(|(_, _, c)| *c)
                        .unwrap_or("??");
                    format!("stop {code}")
                }
                None => "run".into(),
            };
            self.note(n, what);
        }
    }

    /// One machine cycle on every running unit: production up by its
    /// cycle increment.
    pub fn cycle(&self) {
        let mut made = Vec::new();
        if let Ok(mut units) = self.units.lock() {
            for (&n, u) in units.iter_mut() {
                if u.bits & Status::RUNNING != 0 {
                    u.production = (u.production + u32::from(u.cycle_increment)) % 1_000_000;
                    made.push((n, u.cycle_increment));
                }
            }
        }
        for (n, k) in made {
            self.note(n, format!("cycle +{k}"));
        }
    }

    /// Unit `n` is set to make `item` up to `target` (a mould change at
    /// its panel).
    pub fn set_order(&self, n: u8, item: &str, target: u32) {
        if self
            .with_unit(n, |u| {
                u.item = item.to_string();
                u.target = target;
            })
            .is_some()
        {
            self.note(n, format!("order {item} target {target}"));
        }
    }

    /// Unit `n` stops answering (or answers again).
    pub fn set_silent(&self, n: u8, silent: bool) {
        if self.with_unit(n, |u| u.silent = silent).is_some() {
            self.note(n, if silent { "silent" } else { "answers" }.into());
        }
    }

    /// The next `k` answers get a corrupted byte (the receiver sees a bad
    /// FCS).
    pub fn corrupt_next(&self, k: u32) {
        self.noise.fetch_add(k, Ordering::SeqCst);
    }

    /// Answers corrupted so far are gone from this count; how many are
    /// still to corrupt.
    pub fn noise_left(&self) -> u32 {
        self.noise.load(Ordering::SeqCst)
    }

    /// Requests answered so far.
    pub fn answered(&self) -> u32 {
        self.answered.load(Ordering::SeqCst)
    }

    /// The simulator's record.
    pub fn log(&self) -> Vec<LogEntry> {
        self.log.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// Unit `n` as it is now.
    pub fn unit(&self, n: u8) -> Option<Unit> {
        self.units.lock().ok()?.get(&n).cloned()
    }

    /// The bytes to send back for `bytes` received (the gateways' side of
    /// the line).
    fn respond(&self, decoder: &mut Decoder, bytes: &[u8]) -> Vec<u8> {
        let mut decoded = Vec::new();
        decoder.push(bytes, &mut decoded);
        let mut out = Vec::new();
        for d in decoded {
            let answer = match d {
                // A repeated request is a retransmission: answer again.
                Decoded::Frame(f) | Decoded::Duplicate(f) => {
                    decoder.request_sent();
                    let answer = self.units.lock().ok().and_then(|mut units| {
                        let u = units.get_mut(&f.unit).filter(|u| !u.silent)?;
                        u.answer(&f)
                    });
                    if let (Some(_), true) = (&answer, f.header.is_write()) {
                        self.note(f.unit, format!("write {}{}", f.header, f.text));
                    }
                    answer
                }
                Decoded::Error {
                    end,
                    unit: Some(unit),
                    ..
                } => {
                    let here = self
                        .units
                        .lock()
                        .ok()
                        .is_some_and(|u| u.get(&unit).is_some_and(|u| !u.silent));
                    here.then(|| Frame::ack(unit, if end == END_DATA { END_DATA } else { end }))
                }
                Decoded::Error { unit: None, .. } => None,
            };
            if let Some(a) = answer {
                let mut bytes = a.encode();
                let corrupt = self
                    .noise
                    .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| n.checked_sub(1))
                    .is_ok();
                if corrupt {
                    // Flip a bit of the FCS.
                    let i = bytes.len() - 3;
                    bytes[i] ^= 0x01;
                }
                self.answered.fetch_add(1, Ordering::SeqCst);
                out.extend(bytes);
            }
        }
        out
    }

    /// Serves the bus on a TCP listener (a serial device server's raw
    /// socket), one connection at a time, until the task is aborted.
    ///
    /// # Errors
    /// The address cannot be bound.
    pub async fn listen_tcp(
        &self,
        addr: SocketAddr,
    ) -> std::io::Result<(SocketAddr, tokio::task::JoinHandle<()>)> {
        let listener = tokio::net::TcpListener::bind(addr).await?;
        let local = listener.local_addr()?;
        let bus = self.clone();
        let task = tokio::spawn(async move {
            while let Ok((mut stream, _)) = listener.accept().await {
                let mut decoder = Decoder::requests();
                let mut buf = [0u8; 256];
                loop {
                    let n = match stream.read(&mut buf).await {
                        Ok(0) | Err(_) => break,
                        Ok(n) => n,
                    };
                    let out = bus.respond(&mut decoder, &buf[..n]);
                    if !out.is_empty() && stream.write_all(&out).await.is_err() {
                        break;
                    }
                }
            }
        });
        Ok((local, task))
    }

    /// Serves the bus on a new pseudo-terminal (raw mode): returns the path
    /// of its serial side, which the agent opens as a serial port. Runs on
    /// its own thread for as long as the process lives.
    ///
    /// # Errors
    /// No pseudo-terminal can be made.
    pub fn pty(&self) -> std::io::Result<PathBuf> {
        use nix::sys::termios;
        let pty = nix::pty::openpty(None, None).map_err(std::io::Error::from)?;
        let mut raw = termios::tcgetattr(&pty.slave).map_err(std::io::Error::from)?;
        termios::cfmakeraw(&mut raw);
        termios::tcsetattr(&pty.slave, termios::SetArg::TCSANOW, &raw)
            .map_err(std::io::Error::from)?;
        let path = nix::unistd::ttyname(&pty.slave).map_err(std::io::Error::from)?;
        let bus = self.clone();
        std::thread::Builder::new()
            .name("moulding-pty".into())
            .spawn(move || {
                // The serial side stays open here, so the line stays up
                // while the agent reconnects.
                let _slave = pty.slave;
                let mut master = std::fs::File::from(pty.master);
                let mut decoder = Decoder::requests();
                let mut buf = [0u8; 256];
                loop {
                    let n = match master.read(&mut buf) {
                        Ok(0) | Err(_) => break,
                        Ok(n) => n,
                    };
                    let out = bus.respond(&mut decoder, &buf[..n]);
                    if !out.is_empty() && master.write_all(&out).is_err() {
                        break;
                    }
                }
            })?;
        Ok(path)
    }
}

/// A scripted event of the demo's moulding bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A unit stops with a Table 4 cause bit.
    Stop(u8, u16),
    /// A unit runs again.
    Run(u8),
    /// A unit stops answering.
    Silent(u8),
    /// A unit answers again.
    Answer(u8),
    /// The next answers are corrupted.
    Noise(u32),
}

/// The demo's schedule, repeated every 40 s: (seconds into the period,
/// event, what it means).
pub const DEMO: [(u64, Event, &str); 8] = [
    (
        5,
        Event::Stop(2, Status::FRONT_DOOR_OPEN),
        "unit 2: operator opens the front door",
    ),
    (10, Event::Run(2), "unit 2: door closed, running again"),
    (14, Event::Noise(2), "line noise corrupts two answers"),
    (
        18,
        Event::Stop(3, Status::MOULD_CHANGE),
        "unit 3: mould change",
    ),
    (26, Event::Run(3), "unit 3: new mould in, running"),
    (30, Event::Silent(1), "unit 1: gateway switched off"),
    (35, Event::Answer(1), "unit 1: gateway back"),
    (
        38,
        Event::Stop(1, Status::STOPPED),
        "unit 1: stopped by the operator",
    ),
];

/// The length of the demo's schedule.
pub const DEMO_PERIOD: std::time::Duration = std::time::Duration::from_secs(40);

impl MouldingBus {
    /// Applies one scripted event.
    pub fn apply(&self, event: Event) {
        match event {
            Event::Stop(u, bit) => self.stop(u, Some(bit)),
            Event::Run(u) => self.stop(u, None),
            Event::Silent(u) => self.set_silent(u, true),
            Event::Answer(u) => self.set_silent(u, false),
            Event::Noise(k) => self.corrupt_next(k),
        }
    }

    /// Runs machine cycles every `cycle` and, with `schedule`, the demo's
    /// events, forever; `note` is told each event.
    pub async fn play(&self, cycle: std::time::Duration, schedule: bool, note: impl Fn(&str)) {
        let cycles = async {
            if cycle.is_zero() {
                return;
            }
            let mut tick = tokio::time::interval_at(tokio::time::Instant::now() + cycle, cycle);
            loop {
                tick.tick().await;
                self.cycle();
            }
        };
        let events = async {
            if !schedule {
                return;
            }
            let start = tokio::time::Instant::now();
            for period in 0u32.. {
                for (at, event, what) in DEMO {
                    let when = start + DEMO_PERIOD * period + std::time::Duration::from_secs(at);
                    tokio::time::sleep_until(when).await;
                    note(what);
                    self.apply(event);
                }
            }
        };
        tokio::join!(cycles, events);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_answer_reads_and_writes_and_stay_quiet_when_silent() {
        let bus = MouldingBus::new(3);
        let mut d = Decoder::requests();
        let mut answers = Decoder::answers();
        let mut got = Vec::new();
        let ask = |f: Frame, d: &mut Decoder, a: &mut Decoder, got: &mut Vec<Decoded>| {
            got.clear();
            a.request_sent();
            let bytes = bus.respond(d, &f.encode());
            a.push(&bytes, got);
        };
        ask(
            Frame::new(2, Header::WriteTarget, "001500"),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert_eq!(got, [Decoded::Frame(Frame::ack(2, END_NORMAL))]);
        ask(
            Frame::read(2, Header::ReadTarget),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert_eq!(
            got,
            [Decoded::Frame(Frame::new(2, Header::ReadTarget, "001500"))]
        );
        bus.stop(2, Some(Status::FRONT_DOOR_OPEN));
        bus.cycle();
        ask(
            Frame::read(2, Header::ReadStatus),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert_eq!(
            got,
            [Decoded::Frame(Frame::new(
                2,
                Header::ReadStatus,
                "0002000000"
            ))]
        );
        ask(
            Frame::read(1, Header::ReadStatus),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert_eq!(
            got,
            [Decoded::Frame(Frame::new(
                1,
                Header::ReadStatus,
                "0001000001"
            ))]
        );
        bus.set_silent(3, true);
        ask(
            Frame::read(3, Header::ReadStatus),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert!(got.is_empty());
        ask(
            Frame::read(9, Header::ReadStatus),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert!(got.is_empty(), "no unit 9 on the bus");
        bus.corrupt_next(1);
        ask(
            Frame::read(1, Header::ReadTarget),
            &mut d,
            &mut answers,
            &mut got,
        );
        assert!(matches!(got[..], [Decoded::Error { end: 14, .. }]));
        let log: Vec<String> = bus
            .log()
            .into_iter()
            .map(|e| format!("{} {}", e.unit, e.what))
            .collect();
        assert_eq!(
            log,
            [
                "2 write WT001500",
                "2 stop 01",
                "1 cycle +1",
                "3 cycle +1",
                "3 silent"
            ]
        );
    }
}
