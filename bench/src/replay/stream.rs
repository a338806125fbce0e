//! The changes the replay source sends, as bytes built once: every
//! monitored noise tag's notification encoded into one template (in a fixed
//! shuffled order), the limit switches' into another, and the recipe of a
//! publish ([`Segment`]s) that says which of them it carries and with what
//! values and timestamps. Sending patches the template in place (value
//! byte, timestamps) and copies it out; nothing is encoded per change.
//!
//! It owns the layout of a notification and the values of the tags; it
//! does not frame, sign or schedule (`frame.rs`, `subscription.rs`).

use opcua::types::{
    BinaryEncodable, ContextOwned, DataValue, DateTime, MonitoredItemNotification,
    TimestampsToReturn, Variant,
};
use rand::seq::SliceRandom;
use rand::SeedableRng;

/// The offset of the value's Boolean byte in an encoded notification:
/// client handle (4), DataValue mask (1), Variant type (1).
const VALUE_AT: usize = 6;

/// The offset of the first timestamp: the value byte, then the timestamps.
const STAMPS_AT: usize = VALUE_AT + 1;

/// One run of changes in a publish.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Segment {
    /// Changes `start..start + len` of the endless noise stream: change `g`
    /// is the tag at position `g % tags` of the template in round `g /
    /// tags`, whose value is `true` in odd rounds; stamped evenly from
    /// `from` to `to` (OPC UA ticks).
    Noise {
        /// The first change.
        start: u64,
        /// How many.
        len: u32,
        /// The first change's stamp.
        from: i64,
        /// Past the last change's stamp.
        to: i64,
    },
    /// Limit switch `k` open (`false`) or closed (`true`), stamped `at`.
    Switch {
        /// Which switch.
        k: u8,
        /// Its value.
        closed: bool,
        /// Its stamp (OPC UA ticks).
        at: i64,
    },
}

impl Segment {
    /// How many notifications it holds.
    pub fn len(&self) -> usize {
        match self {
            Segment::Noise { len, .. } => *len as usize,
            Segment::Switch { .. } => 1,
        }
    }
}

/// The templates of one subscription's monitored items.
pub struct Stream {
    /// Bytes per notification (all alike: a Boolean with the same stamps).
    item: usize,
    /// Which timestamps a value carries (0, 1 or 2 of them).
    stamps: usize,
    /// The noise tags' notifications in stream order, built once.
    noise: Vec<u8>,
    /// The noise tags' client handles in stream order.
    noise_handles: Vec<u32>,
    /// Where each noise tag (by its index) stands in the stream.
    position: Vec<u32>,
    /// The limit switches' notifications, switch `k` at `k`.
    switches: Vec<u8>,
    /// The limit switches' client handles.
    switch_handles: Vec<u32>,
    /// What the timestamps to return ask for.
    timestamps: TimestampsToReturn,
}

/// OPC UA ticks (100 ns since 1601) of a wall-clock time.
pub fn ticks(t: std::time::SystemTime) -> i64 {
    DateTime::from(chrono::DateTime::<chrono::Utc>::from(t)).checked_ticks()
}

impl Stream {
    /// The templates for noise tags with client handles `noise[i]` (tag
    /// `i`, in a fixed order shuffled with `seed`) and switches with
    /// `switches[k]`, their values carrying `timestamps`.
    pub fn new(
        noise: &[u32],
        switches: &[u32],
        timestamps: TimestampsToReturn,
        seed: u64,
    ) -> Stream {
        let mut order: Vec<u32> = (0..noise.len() as u32).collect();
        order.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed));
        let mut position = vec![0; noise.len()];
        for (p, &i) in order.iter().enumerate() {
            position[i as usize] = p as u32;
        }
        let noise_handles: Vec<u32> = order.iter().map(|&i| noise[i as usize]).collect();
        let ctx = ContextOwned::default();
        let encode = |handles: &[u32]| {
            let mut out = Vec::new();
            for &h in handles {
                // Encoding into a Vec cannot fail.
                let _ = notification(h, false, 0, timestamps).encode(&mut out, &ctx.context());
            }
            out
        };
        let one = notification(1, false, 0, timestamps).byte_len(&ctx.context());
        let stamps = match timestamps {
            TimestampsToReturn::Both => 2,
            TimestampsToReturn::Source | TimestampsToReturn::Server => 1,
            _ => 0,
        };
        Stream {
            item: one,
            stamps,
            noise: encode(&noise_handles),
            noise_handles,
            position,
            switches: encode(switches),
            switch_handles: switches.to_vec(),
            timestamps,
        }
    }

    /// Bytes per encoded notification.
    pub fn item_len(&self) -> usize {
        self.item
    }

    /// Noise tags in the stream.
    pub fn tags(&self) -> usize {
        self.noise_handles.len()
    }

    /// Appends `segment`'s notifications, encoded, to `out`: the template
    /// patched in place (values, timestamps), then copied.
    pub fn write(&mut self, segment: &Segment, out: &mut Vec<u8>) {
        let item = self.item;
        match *segment {
            Segment::Noise {
                start,
                len,
                from,
                to,
            } => {
                let tags = self.tags() as u64;
                if tags == 0 {
                    return;
                }
                let step = (to - from) / i64::from(len.max(1));
                let (mut g, end, mut stamp) = (start, start + u64::from(len), from);
                while g < end {
                    // One pass over the template at most: up to its end or
                    // the segment's.
                    let (round, at) = (g / tags, (g % tags) as usize);
                    let n = ((tags - at as u64).min(end - g)) as usize;
                    let value = u8::from(round % 2 == 1);
                    let part = &mut self.noise[at * item..(at + n) * item];
                    for one in part.chunks_exact_mut(item) {
                        patch(one, value, stamp, self.stamps);
                        stamp += step;
                    }
                    out.extend_from_slice(part);
                    g += n as u64;
                }
            }
            Segment::Switch { k, closed, at } => {
                let k = usize::from(k);
                let one = &mut self.switches[k * item..(k + 1) * item];
                patch(one, u8::from(closed), at, self.stamps);
                out.extend_from_slice(one);
            }
        }
    }

    /// `segment`'s notifications as values (for a Republish, which the
    /// library encodes).
    pub fn notifications(&self, segment: &Segment, out: &mut Vec<MonitoredItemNotification>) {
        match *segment {
            Segment::Noise {
                start,
                len,
                from,
                to,
            } => {
                let tags = self.tags() as u64;
                let step = (to - from) / i64::from(len.max(1));
                for (i, g) in (start..start + u64::from(len)).enumerate() {
                    out.push(notification(
                        self.noise_handles[(g % tags) as usize],
                        (g / tags) % 2 == 1,
                        from + step * i as i64,
                        self.timestamps,
                    ));
                }
            }
            Segment::Switch { k, closed, at } => out.push(notification(
                self.switch_handles[usize::from(k)],
                closed,
                at,
                self.timestamps,
            )),
        }
    }

    /// Noise tag `i`'s value once `sent` changes of the stream are out.
    pub fn value(&self, i: usize, sent: u64) -> bool {
        let (p, tags) = (u64::from(self.position[i]), self.tags() as u64);
        // Sent in rounds 0..=r, where the last is the one with g < sent.
        sent > p && ((sent - 1 - p) / tags) % 2 == 1
    }
}

/// Writes `value` and `stamp` into one encoded notification.
fn patch(one: &mut [u8], value: u8, stamp: i64, stamps: usize) {
    one[VALUE_AT] = value;
    let bytes = stamp.to_le_bytes();
    for s in 0..stamps {
        let at = STAMPS_AT + 8 * s;
        one[at..at + 8].copy_from_slice(&bytes);
    }
}

/// A Boolean notification for `handle` stamped `at` as `timestamps` asks.
fn notification(
    handle: u32,
    value: bool,
    at: i64,
    timestamps: TimestampsToReturn,
) -> MonitoredItemNotification {
    let stamp = Some(DateTime::from(at));
    let (source, server) = match timestamps {
        TimestampsToReturn::Both => (stamp, stamp),
        TimestampsToReturn::Source => (stamp, None),
        TimestampsToReturn::Server => (None, stamp),
        _ => (None, None),
    };
    MonitoredItemNotification {
        client_handle: handle,
        value: DataValue {
            value: Some(Variant::Boolean(value)),
            source_timestamp: source,
            server_timestamp: server,
            ..Default::default()
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use opcua::types::BinaryDecodable;

    fn decode_all(bytes: &[u8], item: usize) -> Vec<MonitoredItemNotification> {
        let ctx = ContextOwned::default();
        bytes
            .chunks_exact(item)
            .map(|mut b| MonitoredItemNotification::decode(&mut b, &ctx.context()).unwrap())
            .collect()
    }

    /// What the patched template sends is what the library encodes for the
    /// same values, for every choice of timestamps, across rounds.
    #[test]
    fn patched_bytes_decode_to_the_changes_they_stand_for() {
        for ts in [
            TimestampsToReturn::Both,
            TimestampsToReturn::Source,
            TimestampsToReturn::Server,
            TimestampsToReturn::Neither,
        ] {
            let noise: Vec<u32> = (11..=17).collect();
            let mut s = Stream::new(&noise, &[1, 2, 3], ts, 7);
            let from = ticks(std::time::SystemTime::now());
            let segs = [
                Segment::Noise {
                    start: 5,
                    len: 16,
                    from,
                    to: from + 16_000,
                },
                Segment::Switch {
                    k: 2,
                    closed: false,
                    at: from + 5,
                },
            ];
            let mut bytes = Vec::new();
            let mut typed = Vec::new();
            for seg in &segs {
                s.write(seg, &mut bytes);
                s.notifications(seg, &mut typed);
            }
            assert_eq!(bytes.len(), 17 * s.item);
            let decoded = decode_all(&bytes, s.item);
            assert_eq!(decoded, typed);
            // Change 5 is position 5 in round 0; change 7 is position 0 of
            // round 1, true.
            assert_eq!(decoded[0].value.value, Some(Variant::Boolean(false)));
            assert_eq!(decoded[2].value.value, Some(Variant::Boolean(true)));
            assert_eq!(decoded[2].client_handle, s.noise_handles[0]);
            assert_eq!(decoded[16].client_handle, 3);
            assert_eq!(decoded[16].value.value, Some(Variant::Boolean(false)));
            if ts == TimestampsToReturn::Both {
                assert_eq!(
                    decoded[1].value.source_timestamp,
                    Some(DateTime::from(from + 1000))
                );
                assert_eq!(
                    decoded[1].value.server_timestamp,
                    Some(DateTime::from(from + 1000))
                );
            }
        }
    }

    #[test]
    fn a_tags_value_is_its_last_rounds() {
        let noise: Vec<u32> = (1..=4).collect();
        let s = Stream::new(&noise, &[], TimestampsToReturn::Both, 1);
        for i in 0..4 {
            let p = u64::from(s.position[i]);
            assert!(!s.value(i, 0));
            assert!(!s.value(i, p + 1));
            // Round 1 has sent it.
            assert!(s.value(i, 4 + p + 1));
            assert!(!s.value(i, 4 + p));
            assert!(!s.value(i, 8 + p + 1));
        }
    }
}
