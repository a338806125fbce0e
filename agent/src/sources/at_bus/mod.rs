//! The `@` bus source (paper 002): the control computer's side of an
//! RS-485 multidrop line of injection-moulding units, over a serial port or
//! a serial device server's raw TCP socket.
//!
//! Every poll cycle, each unit is asked what its tags need (`R?` for the
//! status bits and production, `RT`, `RJ`, ...), one request at a time: a
//! unit answers within the response timeout or not at all. An answer with
//! a bad FCS or format, or `NC14`/`NC15`, or none at all, is asked again,
//! at most `retries` times; then the unit is out of reach: its tags become
//! unknown (not bad quality) and the source raises one problem for it
//! (`legacy-unit-<nn>`), cleared when it answers again. Nothing else is
//! raised meanwhile: checks hold their verdicts on unknown contacts.
//! A value is sent to the cell loop when it changes (and all of them
//! after a reconnection).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use cellwatch_models::at_bus::{Decoded, Decoder, Field, Frame, Header, Status};
use cellwatch_models::engine::{Reading, TagReading};
use cellwatch_models::value::{Num, ValueType};
use futures_util::future::BoxFuture;
use futures_util::FutureExt;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::sync::{mpsc, oneshot};

use super::{
    Source, SourceError, SourceEvent, SourceSender, Write, WriteError, WriteRequest, WriteSender,
    WRITE_CAPACITY,
};
use crate::backoff::Backoff;

pub mod config;
mod error;
use crate::clock::Clock;
pub use crate::sources::at_bus::config::{
    AtBusConfig, BusNode, Item, Parity, SerialLine, Transport,
};
use crate::tags::TagConfig;
pub use error::{AtBusError, LineError};

/// How long a serial device server has to take the connection.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// A value read from a unit.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Value {
    Word(u64),
    Text(Arc<str>),
}

/// A tag's reading from its item's value, as the tag is configured.
fn reading(value: &Value, item: Item, tag: &TagConfig) -> Reading {
    let wrong = || Reading::WrongType {
        expected: tag.value_type,
        received: Some(item.value_type()),
    };
    match value {
        Value::Word(w) => match tag.bit {
            Some(bit) => Reading::Good((w >> bit) & 1 == 1),
            None if tag.value_type.is_numeric() => Reading::Number(Num::UInt(*w)),
            None => wrong(),
        },
        Value::Text(t) if tag.value_type == ValueType::String && tag.bit.is_none() => {
            Reading::Text(t.clone())
        }
        Value::Text(_) => wrong(),
    }
}

/// The poller of one bus.
pub struct AtBusSource {
    config: AtBusConfig,
    tags: Vec<TagConfig>,
    writes: Option<mpsc::Receiver<WriteRequest>>,
}

impl AtBusSource {
    /// A source reading `tags` (node ids `@<unit>/<item>`) from the bus.
    pub fn new(config: AtBusConfig, tags: Vec<TagConfig>) -> AtBusSource {
        AtBusSource {
            config,
            tags,
            writes: None,
        }
    }
}

impl Source for AtBusSource {
    fn describe(&self) -> String {
        self.config.describe()
    }

    fn writer(&mut self) -> Option<WriteSender> {
        Some(write_queue(&mut self.writes))
    }

    fn run(
        self: Box<Self>,
        tx: SourceSender,
        shutdown: BoxFuture<'static, ()>,
    ) -> BoxFuture<'static, Result<(), SourceError>> {
        async move {
            let AtBusSource {
                config,
                tags,
                writes,
            } = *self;
            run(&config, &tags, tx, writes, shutdown).await
        }
        .boxed()
    }
}

/// The frame that writes `value` to the unit item `node` names: the item
/// code (`WJ`), the target (`WT`) or a production correction (`WP`).
///
/// # Errors
/// The item is not written this way, or the value does not fit its field.
pub fn write_frame(node: BusNode, value: &str) -> Result<Frame, AtBusError> {
    let quantity = |v: &str| {
        v.trim()
            .parse::<u64>()
            .ok()
            .and_then(|n| Field::Quantity.number(n))
            .ok_or_else(|| AtBusError::NotQuantity { value: v.into() })
    };
    let (header, text) = match node.item {
        Item::Target => (Header::WriteTarget, quantity(value)?),
        Item::Production => (Header::WriteProduction, quantity(value)?),
        Item::ItemCode => (
            Header::WriteItem,
            Field::Item
                .item(value)
                .ok_or_else(|| AtBusError::NotItemCode {
                    value: value.into(),
                })?,
        ),
        item => return Err(AtBusError::NotWritable { item }),
    };
    Ok(Frame::new(node.unit, header, text))
}

/// The bytes to and from the bus.
trait Line: AsyncRead + AsyncWrite + Unpin + Send {}
impl<T: AsyncRead + AsyncWrite + Unpin + Send> Line for T {}

async fn open(config: &AtBusConfig) -> Result<Box<dyn Line>, AtBusError> {
    match &config.transport {
        Transport::Tcp(addr) => {
            let s = tokio::time::timeout(CONNECT_TIMEOUT, tokio::net::TcpStream::connect(addr))
                .await
                .map_err(|_| AtBusError::ConnectTimeout {
                    addr: addr.to_string(),
                    within: CONNECT_TIMEOUT,
                })?
                .map_err(|source| AtBusError::Connect {
                    addr: addr.to_string(),
                    source,
                })?;
            let _ = s.set_nodelay(true);
            Ok(Box::new(s))
        }
        Transport::Serial(line) => {
            use tokio_serial::SerialPortBuilderExt;
            let port = tokio_serial::new(&line.path, line.baud)
                .data_bits(match line.data_bits {
                    5 => tokio_serial::DataBits::Five,
                    6 => tokio_serial::DataBits::Six,
                    7 => tokio_serial::DataBits::Seven,
                    _ => tokio_serial::DataBits::Eight,
                })
                .parity(match line.parity {
                    Parity::None => tokio_serial::Parity::None,
                    Parity::Even => tokio_serial::Parity::Even,
                    Parity::Odd => tokio_serial::Parity::Odd,
                })
                .stop_bits(if line.stop_bits == 2 {
                    tokio_serial::StopBits::Two
                } else {
                    tokio_serial::StopBits::One
                })
                .open_native_async()
                .map_err(|source| AtBusError::Serial {
                    path: line.path.to_string(),
                    source,
                })?;
            Ok(Box::new(port))
        }
    }
}

/// Why one request got no usable answer.
enum Failed {
    /// The unit did not answer well within the retries: why, last time.
    Unit(String),
    /// The line itself failed (the connection closed).
    Line(LineError),
}

/// Sends `request` and waits for its answer, asking again on a bad,
/// refused or missing answer.
async fn exchange(
    line: &mut Box<dyn Line>,
    decoder: &mut Decoder,
    request: &Frame,
    config: &AtBusConfig,
) -> Result<Frame, Failed> {
    let mut why = String::new();
    let mut buf = [0u8; 256];
    let mut decoded = Vec::new();
    for _attempt in 0..=config.retries {
        decoder.request_sent();
        line.write_all(&request.encode())
            .await
            .map_err(|e| Failed::Line(LineError::Write(Arc::new(e))))?;
        let deadline = tokio::time::Instant::now() + config.response_timeout;
        why = "no answer".into();
        'wait: loop {
            let n = match tokio::time::timeout_at(deadline, line.read(&mut buf)).await {
                Err(_) => break 'wait,
                Ok(Ok(0)) => return Err(Failed::Line(LineError::Closed)),
                Ok(Ok(n)) => n,
                Ok(Err(e)) => return Err(Failed::Line(LineError::Read(Arc::new(e)))),
            };
            decoded.clear();
            decoder.push(&buf[..n], &mut decoded);
            for d in decoded.drain(..) {
                match d {
                    Decoded::Frame(f) if f.unit == request.unit => {
                        let fits = if request.header.is_write() {
                            f.header == Header::Ack
                        } else {
                            f.header == request.header
                        };
                        if fits {
                            return Ok(f);
                        }
                        why = format!("answered {}{}", f.header, f.text);
                        break 'wait;
                    }
                    // Another unit's late answer, or a copy: not ours.
                    Decoded::Frame(_) | Decoded::Duplicate(_) => {}
                    Decoded::Error { end, why: w, .. } => {
                        why = format!("a bad answer (end code {end}): {w}");
                        break 'wait;
                    }
                }
            }
        }
    }
    Err(Failed::Unit(format!(
        "{why} (after {} attempts)",
        config.retries + 1
    )))
}

/// The problem id of a unit out of reach.
pub fn unit_problem(unit: u8) -> String {
    format!("legacy-unit-{unit:02X}")
}

/// Runs the poller for one cell until `shutdown` completes.
///
/// # Errors
/// None yet: trouble on the line is reported as events and retried.
pub async fn run(
    config: &AtBusConfig,
    tags: &[TagConfig],
    tx: SourceSender,
    writes: Option<mpsc::Receiver<WriteRequest>>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), SourceError> {
    let member = Member {
        tags: tags.to_vec(),
        tx,
        writes,
    };
    poll(config, vec![member], &Clock::system(), shutdown).await
}

/// A new queue for operators' writes: its receiving end kept in `slot`.
fn write_queue(slot: &mut Option<mpsc::Receiver<WriteRequest>>) -> WriteSender {
    let (tx, rx) = mpsc::channel(WRITE_CAPACITY);
    *slot = Some(rx);
    tx
}

/// One cell's share of a bus: its tags (node ids `@<unit>/<item>`), where
/// its events go, and its operators' writes.
pub struct Member {
    /// The cell's tags.
    pub tags: Vec<TagConfig>,
    /// The cell loop's channel.
    pub tx: SourceSender,
    /// Writes to the cell's tags.
    pub writes: Option<mpsc::Receiver<WriteRequest>>,
}

/// Where a member's tag sits among all the members' tags.
#[derive(Clone, Copy)]
struct Owner {
    member: usize,
    tag: usize,
}

/// The next write any member asks for, with the member's index; members
/// whose writers are gone are dropped.
async fn next_write(members: &mut [Member]) -> (usize, WriteRequest) {
    std::future::poll_fn(|cx| {
        for (m, member) in members.iter_mut().enumerate() {
            let Some(rx) = member.writes.as_mut() else {
                continue;
            };
            match rx.poll_recv(cx) {
                std::task::Poll::Ready(Some(w)) => return std::task::Poll::Ready((m, w)),
                std::task::Poll::Ready(None) => member.writes = None,
                std::task::Poll::Pending => {}
            }
        }
        std::task::Poll::Pending
    })
    .await
}

/// Polls the bus for `members` (one cell, or each unit a cell of its own)
/// until `shutdown` completes or no member listens any more; readings are
/// stamped with `clock`.
///
/// # Errors
/// None yet: trouble on the line is reported as events and retried.
pub async fn poll(
    config: &AtBusConfig,
    mut members: Vec<Member>,
    clock: &Clock,
    shutdown: impl Future<Output = ()>,
) -> Result<(), SourceError> {
    // Per unit, the requests its tags need and, per item, the tags; per
    // unit, the members reading it.
    let mut plan: BTreeMap<u8, BTreeSet<Header>> = BTreeMap::new();
    let mut readers: HashMap<(u8, Item), Vec<Owner>> = HashMap::new();
    let mut unit_members: BTreeMap<u8, BTreeSet<usize>> = BTreeMap::new();
    for (m, member) in members.iter().enumerate() {
        for (i, t) in member.tags.iter().enumerate() {
            match BusNode::parse(&t.node_id) {
                Ok(n) => {
                    plan.entry(n.unit).or_default().insert(n.item.request());
                    readers
                        .entry((n.unit, n.item))
                        .or_default()
                        .push(Owner { member: m, tag: i });
                    unit_members.entry(n.unit).or_default().insert(m);
                }
                Err(e) => tracing::error!(tag = %t.name, error = %e, "tag not read"),
            }
        }
    }
    // Whether a member's cell loop still listens.
    let mut listening = vec![true; members.len()];
    // Sends `ev` to member `m`; false once no member listens.
    async fn tell(members: &[Member], listening: &mut [bool], m: usize, ev: SourceEvent) -> bool {
        if listening[m] && members[m].tx.send(ev).await.is_err() {
            listening[m] = false;
        }
        listening.iter().any(|l| *l)
    }
    async fn tell_all(members: &[Member], listening: &mut [bool], ev: &SourceEvent) -> bool {
        for m in 0..members.len() {
            tell(members, listening, m, ev.clone()).await;
        }
        listening.iter().any(|l| *l)
    }
    tokio::pin!(shutdown);
    let mut backoff = Backoff::new(Duration::from_millis(250), Duration::from_secs(10));
    let mut said_down = false;
    loop {
        let opened = tokio::select! {
            _ = &mut shutdown => return Ok(()),
            l = open(config) => l,
        };
        let mut line = match opened {
            Ok(l) => l,
            Err(e) => {
                if !said_down {
                    let down = SourceEvent::Disconnected(format!("cannot open the bus: {e}"));
                    if !tell_all(&members, &mut listening, &down).await {
                        return Ok(());
                    }
                    said_down = true;
                }
                tokio::select! {
                    _ = &mut shutdown => return Ok(()),
                    _ = tokio::time::sleep(backoff.next_wait()) => {}
                }
                continue;
            }
        };
        backoff.reset();
        if !tell_all(
            &members,
            &mut listening,
            &SourceEvent::Connected(config.describe()),
        )
        .await
        {
            return Ok(());
        }
        let mut decoder = Decoder::answers();
        // What was last sent per member and tag; units out of reach.
        let mut sent: Vec<Vec<Option<Reading>>> =
            members.iter().map(|m| vec![None; m.tags.len()]).collect();
        let mut away: BTreeSet<u8> = BTreeSet::new();
        let mut next = tokio::time::Instant::now();
        let lost = 'polls: loop {
            // Between polls: operators' writes, one at a time.
            loop {
                tokio::select! {
                    _ = &mut shutdown => return Ok(()),
                    _ = tokio::time::sleep_until(next) => break,
                    (m, w) = next_write(&mut members) => {
                        let tags = &members[m].tags;
                        if let Err(why) = write_one(&mut line, &mut decoder, config, tags, w).await {
                            break 'polls why;
                        }
                    }
                }
            }
            // A cycle longer than the interval (units timing out) starts
            // the next one at once, not a burst to catch up.
            next = (next + config.poll_interval).max(tokio::time::Instant::now());
            let mut readings: Vec<Vec<TagReading>> = vec![Vec::new(); members.len()];
            let mut problems: Vec<(usize, SourceEvent)> = Vec::new();
            let mut line_lost = None;
            'units: for (&unit, requests) in &plan {
                let mut values: Vec<(Item, Value)> = Vec::new();
                let mut failed = None;
                for &h in requests {
                    match exchange(&mut line, &mut decoder, &Frame::read(unit, h), config).await {
                        Ok(answer) => values.extend(decode(&answer)),
                        Err(Failed::Unit(why)) => {
                            failed = Some(format!("{} {why}", h));
                            break;
                        }
                        Err(Failed::Line(why)) => {
                            line_lost = Some(why);
                            break 'units;
                        }
                    }
                }
                let now = clock.now_ms();
                let owners = unit_members.get(&unit).into_iter().flatten();
                match failed {
                    Some(why) => {
                        if away.insert(unit) {
                            tracing::warn!(unit, %why, "unit does not answer");
                            for &m in owners {
                                problems.push((
                                    m,
                                    SourceEvent::Problem {
                                        id: unit_problem(unit),
                                        problem: Some(format!(
                                            "unit {unit:02X} does not answer: {why}"
                                        )),
                                    },
                                ));
                            }
                            for o in readers
                                .iter()
                                .filter(|((u, _), _)| *u == unit)
                                .flat_map(|(_, o)| o)
                            {
                                sent[o.member][o.tag] = Some(Reading::Unreachable);
                                readings[o.member].push(TagReading {
                                    tag: o.tag,
                                    reading: Reading::Unreachable,
                                    source_time: now,
                                });
                            }
                        }
                    }
                    None => {
                        if away.remove(&unit) {
                            for &m in owners {
                                problems.push((
                                    m,
                                    SourceEvent::Problem {
                                        id: unit_problem(unit),
                                        problem: None,
                                    },
                                ));
                            }
                        }
                        for (item, value) in values {
                            for o in readers.get(&(unit, item)).into_iter().flatten() {
                                let r = reading(&value, item, &members[o.member].tags[o.tag]);
                                if sent[o.member][o.tag].as_ref() != Some(&r) {
                                    sent[o.member][o.tag] = Some(r.clone());
                                    readings[o.member].push(TagReading {
                                        tag: o.tag,
                                        reading: r,
                                        source_time: now,
                                    });
                                }
                            }
                        }
                    }
                }
            }
            // The unit's problem first: its alarm explains the unknown
            // values that follow.
            for (m, p) in problems {
                tell(&members, &mut listening, m, p).await;
            }
            for (m, r) in readings.into_iter().enumerate() {
                if !r.is_empty()
                    && !tell(&members, &mut listening, m, SourceEvent::Readings(r.into())).await
                {
                    return Ok(());
                }
            }
            if !listening.iter().any(|l| *l) {
                return Ok(());
            }
            if let Some(why) = line_lost {
                break why;
            }
        };
        tracing::warn!(bus = %config.describe(), why = %lost, "bus connection lost");
        let down = SourceEvent::Disconnected(format!("the bus: {lost}"));
        if !tell_all(&members, &mut listening, &down).await {
            return Ok(());
        }
        said_down = true;
    }
}

/// One bus shared by several cells (each unit a cell of its own, the
/// default for a bus): the poller runs once, and each cell's agent gets a
/// [`BusShare`] as its source.
pub struct SharedBus {
    config: AtBusConfig,
    joins: Vec<oneshot::Receiver<Member>>,
    clock: Clock,
}

impl SharedBus {
    /// A bus polled for cells reading `cells` (each cell's tags); one
    /// share per cell, in the same order.
    pub fn new(config: AtBusConfig, cells: Vec<Vec<TagConfig>>) -> (SharedBus, Vec<BusShare>) {
        let mut joins = Vec::new();
        let mut shares = Vec::new();
        for tags in cells {
            let (join, joined) = oneshot::channel();
            joins.push(joined);
            shares.push(BusShare {
                describe: config.describe(),
                tags,
                join,
                writes: None,
            });
        }
        let bus = SharedBus {
            config,
            joins,
            clock: Clock::system(),
        };
        (bus, shares)
    }

    /// Stamps readings with `clock` (a test's virtual time).
    #[must_use]
    pub fn timed_by(mut self, clock: Clock) -> SharedBus {
        self.clock = clock;
        self
    }

    /// Waits for the cells' agents to start their shares (one that never
    /// starts is left out), then polls until `shutdown` completes or no
    /// cell listens.
    ///
    /// # Errors
    /// See [`poll`].
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> Result<(), SourceError> {
        tokio::pin!(shutdown);
        let mut members = Vec::new();
        for joined in self.joins {
            tokio::select! {
                _ = &mut shutdown => return Ok(()),
                m = joined => if let Ok(m) = m { members.push(m) },
            }
        }
        if members.is_empty() {
            return Ok(());
        }
        poll(&self.config, members, &self.clock, shutdown).await
    }
}

/// The buses several cells share: for each cell whose `[legacy]` bus
/// (port or address) another cell also reads, a [`BusShare`] (in the
/// cells' order; `None` for a cell that has the source its configuration
/// names alone), and the buses to run.
///
/// # Errors
/// Two cells on one bus poll it differently (interval, timeout, retries,
/// line settings): which two, and what differs.
pub fn share_buses(
    cells: &[(String, Option<AtBusConfig>, Vec<TagConfig>)],
) -> Result<(Vec<Option<BusShare>>, Vec<SharedBus>), AtBusError> {
    let mut sources: Vec<Option<BusShare>> = cells.iter().map(|_| None).collect();
    let mut buses = Vec::new();
    let mut done = vec![false; cells.len()];
    for (i, (name, bus, _)) in cells.iter().enumerate() {
        let Some(bus) = bus else { continue };
        if done[i] {
            continue;
        }
        let same: Vec<usize> = (i..cells.len())
            .filter(|&j| {
                cells[j]
                    .1
                    .as_ref()
                    .is_some_and(|b| b.transport.place() == bus.transport.place())
            })
            .collect();
        if same.len() < 2 {
            continue;
        }
        for &j in &same {
            done[j] = true;
            if cells[j].1.as_ref() != Some(bus) {
                return Err(AtBusError::SharedDifferently {
                    cell: name.clone(),
                    other_cell: cells[j].0.clone(),
                    place: bus.transport.place().to_string(),
                    settings: bus.settings().to_string(),
                    other_settings: cells[j]
                        .1
                        .as_ref()
                        .map(AtBusConfig::settings)
                        .unwrap_or_default()
                        .to_string(),
                });
            }
        }
        let (shared, shares) = SharedBus::new(
            bus.clone(),
            same.iter().map(|&j| cells[j].2.clone()).collect(),
        );
        for (&j, share) in same.iter().zip(shares) {
            sources[j] = Some(share);
        }
        buses.push(shared);
    }
    Ok((sources, buses))
}

/// One cell's source on a [`SharedBus`]: it hands the cell's channel and
/// writes to the bus's poller.
pub struct BusShare {
    describe: String,
    tags: Vec<TagConfig>,
    join: oneshot::Sender<Member>,
    writes: Option<mpsc::Receiver<WriteRequest>>,
}

impl Source for BusShare {
    fn describe(&self) -> String {
        format!("{} (shared)", self.describe)
    }

    fn writer(&mut self) -> Option<WriteSender> {
        Some(write_queue(&mut self.writes))
    }

    fn run(
        self: Box<Self>,
        tx: SourceSender,
        shutdown: BoxFuture<'static, ()>,
    ) -> BoxFuture<'static, Result<(), SourceError>> {
        async move {
            let BusShare {
                tags, join, writes, ..
            } = *self;
            let _ = join.send(Member { tags, tx, writes });
            shutdown.await;
            Ok(())
        }
        .boxed()
    }
}

/// Carries out one write and replies; `Err` if the line itself failed.
async fn write_one(
    line: &mut Box<dyn Line>,
    decoder: &mut Decoder,
    config: &AtBusConfig,
    tags: &[TagConfig],
    w: WriteRequest,
) -> Result<(), LineError> {
    let frame = match &w.what {
        Write::Value(value) => w
            .tag
            .and_then(|t| tags.get(t))
            .ok_or(AtBusError::NoSuchTag)
            .and_then(|t| BusNode::parse(&t.node_id).map_err(AtBusError::NodeId))
            .and_then(|node| write_frame(node, value)),
        Write::Pulse(_) => Err(AtBusError::NoPulses),
        Write::Acknowledge { .. } => Err(AtBusError::NoAlarms),
    };
    let frame = match frame {
        Ok(f) => f,
        Err(why) => {
            let _ = w.reply.send(Err(WriteError::Refused(why.into())));
            return Ok(());
        }
    };
    let what = format!(
        "{}{} to unit {:02X}",
        frame.header,
        frame.text.trim_end(),
        frame.unit
    );
    match exchange(line, decoder, &frame, config).await {
        Ok(answer) => {
            tracing::info!(write = %what, answer = %answer.text, "written");
            let _ = w.reply.send(Ok(format!("{what}: AC{}", answer.text)));
            Ok(())
        }
        Err(Failed::Unit(why)) => {
            let refused = AtBusError::NotTaken { what, why };
            let _ = w.reply.send(Err(WriteError::Failed(refused.into())));
            Ok(())
        }
        Err(Failed::Line(why)) => {
            let told = AtBusError::BusFailed {
                what,
                source: why.clone(),
            };
            let _ = w.reply.send(Err(WriteError::Failed(told.into())));
            Err(why)
        }
    }
}

/// The values an answer carries.
fn decode(answer: &Frame) -> Vec<(Item, Value)> {
    let t = answer.text.as_str();
    let word = |radix| u64::from_str_radix(t.trim(), radix).ok().map(Value::Word);
    match answer.header {
        Header::ReadStatus => Status::parse(t.as_bytes())
            .map(|s| {
                vec![
                    (Item::Status, Value::Word(u64::from(s.bits))),
                    (Item::Production, Value::Word(u64::from(s.production))),
                ]
            })
            .unwrap_or_default(),
        Header::ReadTarget => word(10)
            .map(|v| vec![(Item::Target, v)])
            .unwrap_or_default(),
        Header::ReadStockIn => word(10)
            .map(|v| vec![(Item::StockIn, v)])
            .unwrap_or_default(),
        Header::ReadCycleIncrement => word(10)
            .map(|v| vec![(Item::CycleIncrement, v)])
            .unwrap_or_default(),
        Header::ReadOutputs => word(16)
            .map(|v| vec![(Item::Outputs, v)])
            .unwrap_or_default(),
        Header::ReadItem => vec![(Item::ItemCode, Value::Text(Arc::from(t.trim_end())))],
        _ => Vec::new(),
    }
}
