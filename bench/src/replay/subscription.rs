//! One subscription of the replay source: its monitored items, the
//! changes it makes while a run is ordered (noise at the ordered rate, a
//! limit switch opened every so often, as the load server's generator
//! does), the notification messages they make (each at most the
//! subscription's notifications per publish, numbered), the Publish
//! requests waiting for them, the messages sent and not acknowledged
//! (for Republish), and keep-alives.
//!
//! It says what each message holds ([`Segment`]s); `frame.rs` and
//! `wire.rs` turn that into bytes on the socket.

use std::collections::VecDeque;
use std::time::{Duration, Instant, SystemTime};

use opcua::core::ResponseMessage;
use opcua::types::{
    CreateMonitoredItemsRequest, CreateMonitoredItemsResponse, CreateSubscriptionRequest,
    CreateSubscriptionResponse, DataChangeNotification, ExtensionObject, MonitoredItemCreateResult,
    NotificationMessage, PublishRequest, PublishResponse, RepublishRequest, RepublishResponse,
    ResponseHeader, StatusCode, TimestampsToReturn,
};

use super::control::Control;
use super::frame::Publish;
use super::session::{fault, Served, Server};
use super::stream::{ticks, Segment, Stream};
use super::wire::Wire;
use crate::load::{Fault, SWITCHES};

/// Changes queued at most (made, no Publish request to carry them); past
/// it the oldest messages are dropped, as a server's queue overflows.
const MAX_QUEUED: usize = 1_000_000;

/// Messages kept for Republish until acknowledged.
const MAX_SENT: usize = 256;

/// The seed of the noise tags' order.
const ORDER_SEED: u64 = 1;

/// A notification message, made and numbered, not yet encoded.
#[derive(Debug, Clone)]
struct Plan {
    seq: u32,
    publish_time: i64,
    segments: Vec<Segment>,
}

/// A Publish request waiting for a message.
struct Waiting {
    request_id: u32,
    handle: u32,
    results: Vec<StatusCode>,
}

/// The changes of a run under way.
struct Run {
    start: Instant,
    wall: SystemTime,
    rate: u64,
    every: Duration,
    hold: Duration,
    /// Noise changes made so far.
    made: u64,
    /// The last noise change's stamp (ticks).
    stamped: i64,
    next_fault: Instant,
    open: Option<(u8, Instant)>,
    faults: usize,
}

impl Run {
    fn wall(&self, at: Instant) -> SystemTime {
        self.wall + at.saturating_duration_since(self.start)
    }
}

/// One subscription.
pub struct Subscription {
    /// Its id.
    pub id: u32,
    /// Its publishing interval.
    pub interval: Duration,
    keep_alive: u32,
    max_per_publish: usize,
    timestamps: TimestampsToReturn,
    /// Client handle of each noise tag's item (0: none).
    noise: Vec<u32>,
    /// Client handle of each switch's item (0: none).
    switches: Vec<u32>,
    items: u32,
    /// When items were last created, if after the stream was built.
    changed: Option<Instant>,
    stream: Option<Stream>,
    /// Noise changes queued so far: where the stream goes on.
    cursor: u64,
    next_seq: u32,
    queued: VecDeque<Plan>,
    queued_changes: usize,
    sent: VecDeque<Plan>,
    waiting: VecDeque<Waiting>,
    /// Publishing intervals since a message went out.
    quiet: u32,
    run: Option<Run>,
    closed: [bool; SWITCHES],
}

impl Subscription {
    /// Subscription `id` as `request` asks (a publishing interval of at
    /// least 10 ms), and the answer.
    pub fn create(
        id: u32,
        tags: usize,
        request: &CreateSubscriptionRequest,
    ) -> (Subscription, ResponseMessage) {
        let interval =
            Duration::from_secs_f64(request.requested_publishing_interval.max(10.0) / 1e3);
        let keep_alive = request.requested_max_keep_alive_count.max(1);
        let s = Subscription {
            id,
            interval,
            keep_alive,
            max_per_publish: match request.max_notifications_per_publish {
                0 => usize::MAX,
                n => n as usize,
            },
            timestamps: TimestampsToReturn::Both,
            noise: vec![0; tags],
            switches: vec![0; SWITCHES],
            items: 0,
            changed: None,
            stream: None,
            cursor: 0,
            next_seq: 1,
            queued: VecDeque::new(),
            queued_changes: 0,
            sent: VecDeque::new(),
            waiting: VecDeque::new(),
            quiet: 0,
            run: None,
            closed: [true; SWITCHES],
        };
        let response = CreateSubscriptionResponse {
            response_header: ResponseHeader::new_good(&request.request_header),
            subscription_id: id,
            revised_publishing_interval: interval.as_secs_f64() * 1e3,
            revised_lifetime_count: request.requested_lifetime_count.max(3 * keep_alive),
            revised_max_keep_alive_count: keep_alive,
        };
        (s, response.into())
    }

    /// CreateMonitoredItems: served tags get an item; their first values
    /// go out at the next publishing interval.
    pub fn create_items(
        &mut self,
        server: &Server,
        request: &CreateMonitoredItemsRequest,
    ) -> ResponseMessage {
        self.timestamps = request.timestamps_to_return;
        let results = request
            .items_to_create
            .iter()
            .flatten()
            .map(|item| {
                let handle = item.requested_parameters.client_handle;
                let status = match server.served(&item.item_to_monitor.node_id) {
                    Some(Served::Noise(i)) => {
                        self.noise[i] = handle;
                        StatusCode::Good
                    }
                    Some(Served::Switch(k)) => {
                        self.switches[k] = handle;
                        StatusCode::Good
                    }
                    None => StatusCode::BadNodeIdUnknown,
                };
                self.items += 1;
                self.changed = Some(Instant::now());
                MonitoredItemCreateResult {
                    status_code: status,
                    monitored_item_id: self.items,
                    revised_sampling_interval: 0.0,
                    revised_queue_size: item.requested_parameters.queue_size,
                    filter_result: ExtensionObject::null(),
                }
            })
            .collect();
        CreateMonitoredItemsResponse {
            response_header: ResponseHeader::new_good(&request.request_header),
            results: Some(results),
            diagnostic_infos: None,
        }
        .into()
    }

    /// A Publish request: its acknowledgements taken, then it waits for a
    /// message.
    pub fn publish(&mut self, request_id: u32, request: &PublishRequest) {
        let results = request
            .subscription_acknowledgements
            .iter()
            .flatten()
            .map(|a| {
                if a.subscription_id != self.id {
                    return StatusCode::BadSubscriptionIdInvalid;
                }
                match self.sent.iter().position(|p| p.seq == a.sequence_number) {
                    Some(i) => {
                        self.sent.remove(i);
                        StatusCode::Good
                    }
                    None => StatusCode::BadSequenceNumberUnknown,
                }
            })
            .collect();
        self.waiting.push_back(Waiting {
            request_id,
            handle: request.request_header.request_handle,
            results,
        });
    }

    /// Republish: a message sent and not acknowledged, encoded by the
    /// library.
    pub fn republish(&self, request: &RepublishRequest) -> ResponseMessage {
        let handle = request.request_header.request_handle;
        if request.subscription_id != self.id {
            return fault(handle, StatusCode::BadSubscriptionIdInvalid);
        }
        let (Some(plan), Some(stream)) = (
            self.sent
                .iter()
                .find(|p| p.seq == request.retransmit_sequence_number),
            &self.stream,
        ) else {
            return fault(handle, StatusCode::BadMessageNotAvailable);
        };
        let mut items = Vec::new();
        for s in &plan.segments {
            stream.notifications(s, &mut items);
        }
        RepublishResponse {
            response_header: ResponseHeader::new_good(handle),
            notification_message: NotificationMessage {
                sequence_number: plan.seq,
                publish_time: plan.publish_time.into(),
                notification_data: Some(vec![ExtensionObject::from_message(
                    DataChangeNotification {
                        monitored_items: Some(items),
                        diagnostic_infos: None,
                    },
                )]),
            },
        }
        .into()
    }

    /// A served tag's value now.
    pub fn value(&self, served: Served) -> bool {
        match served {
            Served::Noise(i) => self
                .stream
                .as_ref()
                .is_some_and(|s| s.value(i, self.cursor)),
            Served::Switch(k) => self.closed[k],
        }
    }

    /// One publishing interval: the first values of every item once the
    /// items are all there, the run's changes, numbered into messages.
    pub fn tick(&mut self, now: Instant, control: &Control) {
        let mut segments = Vec::new();
        let stamp = ticks(SystemTime::now());
        // Built once the agent has stopped creating items for an interval
        // (it creates them in calls of at most ITEMS_PER_CALL).
        if self
            .changed
            .is_some_and(|t| now.saturating_duration_since(t) >= self.interval)
        {
            self.changed = None;
            let stream = Stream::new(&self.noise, &self.switches, self.timestamps, ORDER_SEED);
            self.sent.clear();
            for k in 0..SWITCHES {
                if self.switches[k] != 0 {
                    segments.push(Segment::Switch {
                        k: k as u8,
                        closed: self.closed[k],
                        at: stamp,
                    });
                }
            }
            self.cursor = 0;
            let tags = stream.tags() as u32;
            segments.push(self.noise_segment(tags, stamp, stamp));
            self.stream = Some(stream);
        }
        let made = self.changes(now, control, &mut segments);
        control.made(made);
        self.number(segments, stamp, control);
        self.quiet = self.quiet.saturating_add(1);
    }

    /// The run's changes up to `now`, appended to `segments`; how many.
    fn changes(&mut self, now: Instant, control: &Control, segments: &mut Vec<Segment>) -> u64 {
        let order = control.order();
        let before = segments.len();
        if let (Some(order), None, Some(_)) = (order, &self.run, &self.stream) {
            self.run = Some(Run {
                start: order.at,
                wall: order.wall,
                rate: order.rate,
                every: order.fault_every,
                hold: order.fault_hold,
                made: 0,
                stamped: ticks(order.wall),
                next_fault: order.at + order.fault_every,
                open: None,
                faults: 0,
            });
        }
        // The run goes on up to now, or up to when it was ended.
        let now = match order {
            Some(_) => now,
            None => control.ended().map_or(now, |e| e.min(now)),
        };
        if let Some(run) = &mut self.run {
            if let Some((k, since)) = run.open {
                let end = since + run.hold;
                if now >= end {
                    segments.push(Segment::Switch {
                        k,
                        closed: true,
                        at: ticks(run.wall(end)),
                    });
                    self.closed[usize::from(k)] = true;
                    run.open = None;
                    run.next_fault = run.next_fault.max(end + run.every.saturating_sub(run.hold));
                }
            } else if now >= run.next_fault {
                let k = (run.faults % SWITCHES) as u8;
                run.faults += 1;
                let at = run.wall(run.next_fault);
                segments.push(Segment::Switch {
                    k,
                    closed: false,
                    at: ticks(at),
                });
                control.fault(Fault {
                    switch: usize::from(k),
                    at,
                });
                self.closed[usize::from(k)] = false;
                run.open = Some((k, run.next_fault));
                run.next_fault += run.every;
            }
            let due =
                (run.rate as f64 * now.saturating_duration_since(run.start).as_secs_f64()) as u64;
            let noise = due - run.made;
            run.made = due;
            let (from, to) = (run.stamped, ticks(run.wall(now)));
            run.stamped = to;
            if noise > 0 {
                let seg = self.noise_segment(noise as u32, from, to);
                segments.push(seg);
            }
        }
        if order.is_none() {
            if let Some(run) = self.run.take() {
                if let Some((k, _)) = run.open {
                    self.closed[usize::from(k)] = true;
                    segments.push(Segment::Switch {
                        k,
                        closed: true,
                        at: ticks(run.wall(now)),
                    });
                }
            }
        }
        segments[before..].iter().map(|s| s.len() as u64).sum()
    }

    /// The next `len` noise changes, stamped from `from` to `to`.
    fn noise_segment(&mut self, len: u32, from: i64, to: i64) -> Segment {
        let start = self.cursor;
        self.cursor += u64::from(len);
        Segment::Noise {
            start,
            len,
            from,
            to,
        }
    }

    /// `segments` cut into numbered messages of at most the notifications
    /// per publish, queued; the oldest dropped past [`MAX_QUEUED`].
    fn number(&mut self, segments: Vec<Segment>, stamp: i64, control: &Control) {
        let mut plan: Vec<Segment> = Vec::new();
        let mut room = self.max_per_publish;
        let mut plans = Vec::new();
        for mut seg in segments {
            while seg.len() > 0 {
                if room == 0 {
                    plans.push(std::mem::take(&mut plan));
                    room = self.max_per_publish;
                }
                let (head, rest) = split(seg, room);
                room -= head.len();
                plan.push(head);
                match rest {
                    Some(r) => seg = r,
                    None => break,
                }
            }
        }
        if !plan.is_empty() {
            plans.push(plan);
        }
        for segments in plans {
            self.queued_changes += segments.iter().map(Segment::len).sum::<usize>();
            self.queued.push_back(Plan {
                seq: self.next_seq,
                publish_time: stamp,
                segments,
            });
            self.next_seq = self.next_seq.wrapping_add(1).max(1);
        }
        while self.queued_changes > MAX_QUEUED {
            let Some(old) = self.queued.pop_front() else {
                break;
            };
            let n: usize = old.segments.iter().map(Segment::len).sum();
            self.queued_changes -= n;
            control.dropped(n as u64);
        }
    }

    /// Answers waiting Publish requests with queued messages (the hot
    /// path), or with a keep-alive when none went out for the keep-alive
    /// count.
    ///
    /// # Errors
    /// The connection failed.
    pub async fn flush(&mut self, wire: &mut Wire) -> anyhow::Result<()> {
        while !self.waiting.is_empty() && !self.queued.is_empty() {
            let (Some(w), Some(plan)) = (self.waiting.pop_front(), self.queued.pop_front()) else {
                break;
            };
            self.queued_changes -= plan.segments.iter().map(Segment::len).sum::<usize>();
            if self.sent.len() == MAX_SENT {
                self.sent.pop_front();
            }
            self.sent.push_back(plan.clone());
            let available: Vec<u32> = self.sent.iter().map(|p| p.seq).collect();
            let publish = Publish {
                request_handle: w.handle,
                subscription_id: self.id,
                available: &available,
                more: !self.queued.is_empty(),
                sequence_number: plan.seq,
                publish_time: plan.publish_time,
                results: &w.results,
            };
            let Some(stream) = self.stream.as_mut() else {
                break;
            };
            wire.send_publish(w.request_id, &publish, &plan.segments, stream)
                .await?;
            self.quiet = 0;
        }
        if self.quiet >= self.keep_alive && self.queued.is_empty() {
            if let Some(w) = self.waiting.pop_front() {
                let available: Vec<u32> = self.sent.iter().map(|p| p.seq).collect();
                let response = PublishResponse {
                    response_header: ResponseHeader::new_good(w.handle),
                    subscription_id: self.id,
                    available_sequence_numbers: Some(available),
                    more_notifications: false,
                    notification_message: NotificationMessage {
                        sequence_number: self.next_seq,
                        publish_time: ticks(SystemTime::now()).into(),
                        notification_data: None,
                    },
                    results: Some(w.results),
                    diagnostic_infos: None,
                };
                wire.send(w.request_id, response.into()).await?;
                self.quiet = 0;
            }
        }
        Ok(())
    }
}

/// `seg` cut after `n` notifications: the head, and the rest if any.
fn split(seg: Segment, n: usize) -> (Segment, Option<Segment>) {
    match seg {
        Segment::Noise {
            start,
            len,
            from,
            to,
        } if (len as usize) > n => {
            let step = (to - from) / i64::from(len);
            let cut = from + step * n as i64;
            (
                Segment::Noise {
                    start,
                    len: n as u32,
                    from,
                    to: cut,
                },
                Some(Segment::Noise {
                    start: start + n as u64,
                    len: len - n as u32,
                    from: cut,
                    to,
                }),
            )
        }
        seg => (seg, None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_segment_splits_where_its_stamps_go_on() {
        let seg = Segment::Noise {
            start: 10,
            len: 10,
            from: 0,
            to: 1000,
        };
        let (a, b) = split(seg, 4);
        assert_eq!(
            a,
            Segment::Noise {
                start: 10,
                len: 4,
                from: 0,
                to: 400
            }
        );
        assert_eq!(
            b,
            Some(Segment::Noise {
                start: 14,
                len: 6,
                from: 400,
                to: 1000
            })
        );
        assert_eq!(split(seg, 10), (seg, None));
    }
}
