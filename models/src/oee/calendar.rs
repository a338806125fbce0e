//! The shift calendar: which shifts a weekday has, their breaks, and the
//! windows they make in time. Times are minutes of the local day in the
//! configuration and ms since the epoch here; the plant's offset from UTC
//! is passed in. What the windows hold (run time, losses) is
//! [`super::figures`]'s.

use serde::Serialize;

/// A day in ms.
pub const DAY_MS: u64 = 86_400_000;
const MINUTE_MS: u64 = 60_000;

/// One shift of the calendar, in local time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Shift {
    /// Its name (`early`).
    pub name: String,
    /// The weekdays it is worked, Monday first.
    pub days: [bool; 7],
    /// When it starts, minutes after local midnight.
    pub start: u32,
    /// When it ends, minutes after local midnight; at or before `start`:
    /// the next day (`22:00`-`06:00`; `06:00`-`06:00` is 24 hours).
    pub end: u32,
    /// Its breaks, `(start, end)` in minutes after local midnight; a break
    /// before the shift's start is on the next day.
    pub breaks: Vec<(u32, u32)>,
}

/// One worked shift in time.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ShiftWindow {
    /// The shift's name.
    pub name: String,
    /// From, ms since the epoch.
    pub start: u64,
    /// Until, ms since the epoch.
    pub end: u64,
    /// Its breaks, `[from, to)` in ms since the epoch, within the shift.
    pub breaks: Vec<(u64, u64)>,
}

impl ShiftWindow {
    /// Whether `t` falls in one of the breaks.
    pub fn in_break(&self, t: u64) -> bool {
        self.breaks.iter().any(|&(a, b)| a <= t && t < b)
    }
}

/// The shift calendar.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Calendar {
    /// The shifts.
    pub shifts: Vec<Shift>,
    /// The plant's offset from UTC, ms (east positive).
    pub utc_offset_ms: i64,
}

impl Calendar {
    /// The windows of the shifts starting within `[from, to)`, in time
    /// order.
    pub fn windows(&self, from: u64, to: u64) -> Vec<ShiftWindow> {
        let local = |t: u64| t as i64 + self.utc_offset_ms;
        // Local days from the one before `from` (a night shift begun then).
        let first = local(from).div_euclid(DAY_MS as i64) - 1;
        let last = local(to).div_euclid(DAY_MS as i64);
        let mut out = Vec::new();
        for day in first..=last {
            // 1970-01-01 was a Thursday: Monday is index 0.
            let weekday = (day + 3).rem_euclid(7) as usize;
            let midnight = day * DAY_MS as i64 - self.utc_offset_ms;
            for s in self.shifts.iter().filter(|s| s.days[weekday]) {
                let at = |m: u32| (midnight + i64::from(m) * MINUTE_MS as i64).max(0) as u64;
                let start = at(s.start);
                let length = if s.end > s.start {
                    u64::from(s.end - s.start)
                } else {
                    u64::from(s.end + 24 * 60 - s.start)
                } * MINUTE_MS;
                let end = start + length;
                if start < from || start >= to {
                    continue;
                }
                let breaks = s
                    .breaks
                    .iter()
                    .map(|&(a, b)| {
                        let from = if a < s.start { a + 24 * 60 } else { a };
                        let until = from + (b + 24 * 60 - a) % (24 * 60);
                        (at(from).clamp(start, end), at(until).clamp(start, end))
                    })
                    .filter(|(a, b)| a < b)
                    .collect();
                out.push(ShiftWindow {
                    name: s.name.clone(),
                    start,
                    end,
                    breaks,
                });
            }
        }
        out.sort_by_key(|w| w.start);
        out
    }

    /// The shift worked at `now`, or else the last one ended before it
    /// (within a week).
    pub fn current(&self, now: u64) -> Option<ShiftWindow> {
        let windows = self.windows(now.saturating_sub(8 * DAY_MS), now + 1);
        windows
            .iter()
            .rev()
            .find(|w| w.start <= now && now < w.end)
            .or_else(|| {
                windows
                    .iter()
                    .filter(|w| w.end <= now)
                    .max_by_key(|w| w.end)
            })
            .cloned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: u64 = 3_600_000;
    /// 2026-03-02, a Monday, 00:00 UTC.
    const MONDAY: u64 = 1_772_409_600_000;

    fn calendar(offset_h: i64) -> Calendar {
        Calendar {
            shifts: vec![
                Shift {
                    name: "early".into(),
                    days: [true, true, true, true, true, false, false],
                    start: 6 * 60,
                    end: 14 * 60,
                    breaks: vec![(10 * 60, 10 * 60 + 30)],
                },
                Shift {
                    name: "night".into(),
                    days: [true; 7],
                    start: 22 * 60,
                    end: 6 * 60,
                    breaks: vec![(2 * 60, 2 * 60 + 15)],
                },
            ],
            utc_offset_ms: offset_h * H as i64,
        }
    }

    #[test]
    fn weekdays_night_shifts_and_breaks_after_midnight() {
        let c = calendar(0);
        let w = c.windows(MONDAY, MONDAY + DAY_MS);
        assert_eq!(
            w.iter()
                .map(|w| (w.name.as_str(), w.start, w.end))
                .collect::<Vec<_>>(),
            [
                ("early", MONDAY + 6 * H, MONDAY + 14 * H),
                ("night", MONDAY + 22 * H, MONDAY + 30 * H)
            ]
        );
        assert_eq!(w[0].breaks, [(MONDAY + 10 * H, MONDAY + 10 * H + H / 2)]);
        assert_eq!(w[1].breaks, [(MONDAY + 26 * H, MONDAY + 26 * H + H / 4)]);
        // Saturday: the night shift only.
        let sat = MONDAY + 5 * DAY_MS;
        let w = c.windows(sat, sat + DAY_MS);
        assert_eq!(w.len(), 1);
        assert_eq!(w[0].name, "night");
    }

    #[test]
    fn the_plants_offset_moves_the_windows_and_the_current_shift_is_found() {
        let c = calendar(9);
        let w = c.windows(MONDAY, MONDAY + DAY_MS);
        // Monday 06:00 at +09:00 is Sunday 21:00 UTC: before the span.
        assert_eq!(w[0].start, MONDAY + 13 * H);
        assert_eq!(w[0].name, "night");
        let c = calendar(0);
        let now = MONDAY + 7 * H;
        assert_eq!(c.current(now).unwrap().name, "early");
        // Between shifts: the early one, ended.
        let now = MONDAY + 15 * H;
        let cur = c.current(now).unwrap();
        assert_eq!((cur.name.as_str(), cur.end), ("early", MONDAY + 14 * H));
        // Tuesday 03:00: Monday's night shift.
        assert_eq!(c.current(MONDAY + 27 * H).unwrap().start, MONDAY + 22 * H);
    }
}
