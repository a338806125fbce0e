//! A simulated body-shop line (paper 001's case), deterministic per seed.
//!
//! Four stations work in parallel, each with a transport robot, two
//! welding robots and a clamp, fed by one conveyor. A station's cycle:
//! an operator loads a part (a random wait: no timing invariant), the
//! transport robot carries it in, the clamp closes, both welding robots
//! weld at once, the clamp opens, the robot carries the body out and
//! returns home. Every motion is a command followed, after its motion time
//! (2.4–10 s, with ±2 % jitter), by its end-of-motion sensor; the PLC's own
//! reactions follow within a scan (20–60 ms). Stations start at random
//! phases, so their events interleave differently in every run. Forty
//! signals never change (modes, safety circuits): 94 signals in all.
//!
//! Faults can be injected at a given motion ([`Fault`]): a sensor that
//! never comes, a motion too fast, a motion too slow, an actuator stuck
//! (the command given but the motion never starts). One motion can wear
//! instead ([`Slowdown`], [`run_slowing`]): it takes a little longer every
//! hour of the run.

use super::log::{Change, RunLog};

/// A deterministic generator (xorshift64*), so that runs repeat per seed.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// Seeded; seed 0 is replaced by a fixed odd constant.
    pub fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `[lo, hi]`.
    pub fn between(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next_u64() % (hi - lo + 1)
    }
}

/// What goes wrong in a faulty run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// The end-of-motion sensor never comes.
    SensorMissing,
    /// The motion takes half its time.
    TooFast,
    /// The motion takes 60 % longer.
    TooSlow,
    /// The command is given but the motion never starts: the sensor never comes.
    Stuck,
}

/// A fault's name that is none of `missing`, `fast`, `slow`, `stuck`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown fault '{text}': use missing, fast, slow or stuck")]
pub struct UnknownFault {
    /// The name as given.
    pub text: String,
}

impl std::str::FromStr for FaultKind {
    type Err = UnknownFault;

    fn from_str(s: &str) -> Result<Self, UnknownFault> {
        match s {
            "missing" => Ok(FaultKind::SensorMissing),
            "fast" => Ok(FaultKind::TooFast),
            "slow" => Ok(FaultKind::TooSlow),
            "stuck" => Ok(FaultKind::Stuck),
            other => Err(UnknownFault { text: other.into() }),
        }
    }
}

/// A fault at the `step`-th motion of the run (counting every motion of
/// every station in time order of their commands).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fault {
    /// What.
    pub kind: FaultKind,
    /// Which motion.
    pub step: usize,
}

/// The fault as it happened, for scoring.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InjectedFault {
    /// What.
    pub kind: FaultKind,
    /// The end-of-motion sensor of the faulty motion.
    pub sensor: String,
    /// When its command was given, ms.
    pub command_at: u64,
}

/// A motion that slows down steadily through a run (a cylinder wearing,
/// a valve clogging): its time grows by `percent_per_hour` of itself per
/// hour since the run began, jitter on top.
#[derive(Debug, Clone, PartialEq)]
pub struct Slowdown {
    /// Its end-of-motion sensor (`WR2B_DONE`).
    pub sensor: String,
    /// Whether the sensor's rising edge ends it (the clamp's sensor ends
    /// two motions: closing rises, opening falls).
    pub rising: bool,
    /// How much longer per hour, percent.
    pub percent_per_hour: f64,
}

impl Slowdown {
    /// `mo`'s time when commanded at `t`, ms.
    fn motion_ms(slowdown: Option<&Slowdown>, mo: &Motion, t: u64) -> u64 {
        match slowdown {
            Some(s) if s.sensor == mo.sensor && s.rising == mo.sensor_value => {
                let hours = t as f64 / 3_600_000.0;
                (mo.ms as f64 * (1.0 + s.percent_per_hour / 100.0 * hours)).round() as u64
            }
            _ => mo.ms,
        }
    }
}

/// One motion: its command and end-of-motion sensor, motion time, jitter.
struct Motion {
    command: String,
    command_value: bool,
    sensor: String,
    sensor_value: bool,
    ms: u64,
}

fn station_motions(k: usize) -> Vec<Motion> {
    let m = |command: String, command_value, sensor: String, sensor_value, ms| Motion {
        command,
        command_value,
        sensor,
        sensor_value,
        ms,
    };
    let base = [6000u64, 7500, 5200, 8400][k];
    vec![
        m(
            format!("TR{k}_IN"),
            true,
            format!("TR{k}_AT_STATION"),
            true,
            base,
        ),
        m(
            format!("ST{k}_CLAMP"),
            true,
            format!("ST{k}_CLAMPED"),
            true,
            2400 + 300 * k as u64,
        ),
        m(
            format!("WR{k}A_START"),
            true,
            format!("WR{k}A_DONE"),
            true,
            4000 + 500 * k as u64,
        ),
        m(
            format!("WR{k}B_START"),
            true,
            format!("WR{k}B_DONE"),
            true,
            3500 + 700 * k as u64,
        ),
        m(
            format!("ST{k}_CLAMP"),
            false,
            format!("ST{k}_CLAMPED"),
            false,
            2600 + 200 * k as u64,
        ),
        m(
            format!("TR{k}_OUT"),
            true,
            format!("TR{k}_HOME"),
            true,
            base + 1500,
        ),
    ]
}

/// Every signal of the line, in a fixed order.
pub fn signals() -> Vec<String> {
    let mut s = vec!["CV_RUN".to_string(), "CV_IN_POS".to_string()];
    for k in 0..4 {
        for name in ["LOADED", "PART_PRESENT", "CLAMP", "CLAMPED", "CYCLE_DONE"] {
            s.push(format!("ST{k}_{name}"));
        }
        for name in ["IN", "AT_STATION", "OUT", "HOME"] {
            s.push(format!("TR{k}_{name}"));
        }
        for w in ["A", "B"] {
            s.push(format!("WR{k}{w}_START"));
            s.push(format!("WR{k}{w}_DONE"));
        }
    }
    for i in 0..38 {
        s.push(format!("SAFETY_{i:02}"));
    }
    s.push("MODE_AUTO".into());
    s.push("LINE_READY".into());
    s
}

/// Simulates one run of `cycles` cycles per station.
pub fn run(seed: u64, cycles: usize, fault: Option<Fault>) -> (RunLog, Option<InjectedFault>) {
    run_slowing(seed, cycles, fault, None)
}

/// Simulates one run like [`run`], with one motion slowing down through
/// it; with `None`, exactly [`run`].
pub fn run_slowing(
    seed: u64,
    cycles: usize,
    fault: Option<Fault>,
    slowdown: Option<&Slowdown>,
) -> (RunLog, Option<InjectedFault>) {
    let names = signals();
    let idx = |n: &str| names.iter().position(|x| x == n).expect("known signal");
    let mut rng = Rng::new(seed);
    let mut initial = vec![false; names.len()];
    for (i, n) in names.iter().enumerate() {
        if n.starts_with("SAFETY_") || n == "MODE_AUTO" || n == "LINE_READY" || n.ends_with("_HOME")
        {
            initial[i] = true;
        }
    }
    // (time, order, signal, value): events are generated per station, then
    // merged in time order; `order` keeps a station's own order at ties.
    let mut events: Vec<(u64, u64, usize, bool)> = Vec::new();
    let mut order = 0u64;
    let mut push = |events: &mut Vec<(u64, u64, usize, bool)>, t: u64, s: usize, v: bool| {
        order += 1;
        events.push((t, order, s, v));
    };
    let scan = |rng: &mut Rng| rng.between(20, 60);
    let jitter = |rng: &mut Rng, ms: u64| {
        let j = ms / 50; // ±2 %
        ms - j + rng.between(0, 2 * j)
    };
    // Motions of all stations, to number them for fault injection.
    struct Planned {
        t_command: u64,
        station: usize,
        motion: usize,
        cycle: usize,
    }
    let mut planned: Vec<Planned> = Vec::new();
    let mut station_events: Vec<Vec<(u64, usize, bool)>> = vec![Vec::new(); 4];
    // First pass: each station's timeline without faults, remembering each
    // motion's command time.
    let mut conveyor_t = rng.between(0, 3000);
    for (k, station) in station_events.iter_mut().enumerate() {
        let motions = station_motions(k);
        let mut t = rng.between(0, 20_000);
        for cycle in 0..cycles {
            // The operator loads a part: a random wait.
            t += rng.between(500, 12_000);
            station.push((t, idx(&format!("ST{k}_LOADED")), true));
            t += scan(&mut rng);
            for (mi, mo) in motions.iter().enumerate() {
                if mi == 3 {
                    // Welding robot B starts with A (same scan).
                    continue;
                }
                let parallel = mi == 2;
                planned.push(Planned {
                    t_command: t,
                    station: k,
                    motion: mi,
                    cycle,
                });
                station.push((t, idx(&mo.command), mo.command_value));
                let mut end = t + jitter(&mut rng, Slowdown::motion_ms(slowdown, mo, t));
                if parallel {
                    let b = &motions[3];
                    planned.push(Planned {
                        t_command: t,
                        station: k,
                        motion: 3,
                        cycle,
                    });
                    station.push((t, idx(&b.command), b.command_value));
                    let end_b = t + jitter(&mut rng, Slowdown::motion_ms(slowdown, b, t));
                    station.push((end_b, idx(&b.sensor), b.sensor_value));
                    let drop_b = end_b + scan(&mut rng);
                    station.push((drop_b, idx(&b.command), !b.command_value));
                    station.push((drop_b + scan(&mut rng), idx(&b.sensor), !b.sensor_value));
                    end = end.max(end_b);
                    let end_a = t + jitter(&mut rng, Slowdown::motion_ms(slowdown, mo, t));
                    station.push((end_a, idx(&mo.sensor), mo.sensor_value));
                    let drop_a = end_a + scan(&mut rng);
                    station.push((drop_a, idx(&mo.command), !mo.command_value));
                    station.push((drop_a + scan(&mut rng), idx(&mo.sensor), !mo.sensor_value));
                    end = end.max(end_a);
                    t = end + scan(&mut rng);
                    continue;
                }
                station.push((end, idx(&mo.sensor), mo.sensor_value));
                if mo.command.ends_with("_IN") || mo.command.ends_with("_OUT") {
                    station.push((end + scan(&mut rng), idx(&mo.command), false));
                }
                if mi == 0 {
                    station.push((
                        end + scan(&mut rng),
                        idx(&format!("ST{k}_PART_PRESENT")),
                        true,
                    ));
                    station.push((
                        end + 2 * scan(&mut rng),
                        idx(&format!("TR{k}_AT_STATION")),
                        false,
                    ));
                }
                if mi == 5 {
                    station.push((
                        t + scan(&mut rng),
                        idx(&format!("ST{k}_PART_PRESENT")),
                        false,
                    ));
                    station.push((t + scan(&mut rng), idx(&format!("TR{k}_HOME")), false));
                    station.push((end + scan(&mut rng), idx(&format!("ST{k}_LOADED")), false));
                    station.push((
                        end + scan(&mut rng),
                        idx(&format!("ST{k}_CYCLE_DONE")),
                        true,
                    ));
                    station.push((
                        end + 3 * scan(&mut rng),
                        idx(&format!("ST{k}_CYCLE_DONE")),
                        false,
                    ));
                }
                t = end + scan(&mut rng);
            }
            let _ = cycle;
        }
        if k == 0 {
            // The conveyor indexes now and then, independently.
            while conveyor_t < t {
                push(&mut events, conveyor_t, idx("CV_RUN"), true);
                let arrive = conveyor_t + jitter(&mut rng, 4000);
                push(&mut events, arrive, idx("CV_IN_POS"), true);
                push(&mut events, arrive + scan(&mut rng), idx("CV_RUN"), false);
                push(
                    &mut events,
                    arrive + rng.between(1000, 9000),
                    idx("CV_IN_POS"),
                    false,
                );
                conveyor_t = arrive + rng.between(10_000, 30_000);
            }
        }
    }
    // The fault, on the step-th motion in command-time order.
    planned.sort_by_key(|p| p.t_command);
    let mut injected = None;
    if let Some(f) = fault {
        if let Some(p) = planned.get(f.step % planned.len().max(1)) {
            let mo = &station_motions(p.station)[p.motion];
            let sensor = idx(&mo.sensor);
            let k = p.station;
            // The sensor edge of this motion is the first one after its command.
            if let Some(pos) = station_events[k]
                .iter()
                .position(|&(t, s, v)| s == sensor && v == mo.sensor_value && t > p.t_command)
            {
                let (t_end, _, _) = station_events[k][pos];
                match f.kind {
                    FaultKind::SensorMissing | FaultKind::Stuck => {
                        // Nothing after the fault happens at this station.
                        station_events[k].retain(|&(t, _, _)| t < t_end);
                        if f.kind == FaultKind::Stuck {
                            station_events[k]
                                .retain(|&(t, s, _)| !(t >= p.t_command && s == sensor));
                        }
                    }
                    FaultKind::TooFast => {
                        let dt = (t_end - p.t_command) / 2;
                        let shift = t_end - (p.t_command + dt);
                        for e in station_events[k].iter_mut().filter(|e| e.0 >= t_end) {
                            e.0 -= shift;
                        }
                    }
                    FaultKind::TooSlow => {
                        let shift = (t_end - p.t_command) * 6 / 10;
                        for e in station_events[k].iter_mut().filter(|e| e.0 >= t_end) {
                            e.0 += shift;
                        }
                    }
                }
                injected = Some(InjectedFault {
                    kind: f.kind,
                    sensor: mo.sensor.clone(),
                    command_at: p.t_command,
                });
            }
            let _ = p.cycle;
        }
    }
    for station in &mut station_events {
        for (t, s, v) in std::mem::take(station) {
            push(&mut events, t, s, v);
        }
    }
    events.sort_by_key(|e| (e.0, e.1));
    let mut value = initial.clone();
    let mut changes = Vec::with_capacity(events.len());
    for (t, _, s, v) in events {
        if value[s] != v {
            value[s] = v;
            changes.push(Change {
                at: t,
                signal: s,
                value: v,
            });
        }
    }
    (
        RunLog {
            signals: names,
            initial,
            changes,
        },
        injected,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_repeat_per_seed_and_differ_between_seeds() {
        let (a, _) = run(7, 3, None);
        let (b, _) = run(7, 3, None);
        let (c, _) = run(8, 3, None);
        assert_eq!(a, b);
        assert_ne!(a.changes, c.changes);
        assert_eq!(a.signals.len(), 94);
        assert!(a.changes.windows(2).all(|w| w[0].at <= w[1].at));
    }

    #[test]
    fn a_slowdown_stretches_only_its_motion_and_more_as_time_goes() {
        let slow = Slowdown {
            sensor: "WR2B_DONE".into(),
            rising: true,
            percent_per_hour: 10.0,
        };
        assert_eq!(run_slowing(5, 3, None, None), run(5, 3, None));
        let (normal, _) = run(5, 200, None);
        let (worn, _) = run_slowing(5, 200, None, Some(&slow));
        // A weld's START → DONE, per cycle.
        let durations = |log: &RunLog, weld: &str| {
            let at = |n: String| log.signals.iter().position(|s| *s == n).unwrap();
            let (start, done) = (at(format!("{weld}_START")), at(format!("{weld}_DONE")));
            let mut since = 0;
            let mut out = Vec::new();
            for c in &log.changes {
                if c.signal == start && c.value {
                    since = c.at;
                } else if c.signal == done && c.value {
                    out.push(c.at - since);
                }
            }
            out
        };
        let (n, w) = (durations(&normal, "WR2B"), durations(&worn, "WR2B"));
        assert_eq!(n.len(), w.len());
        // 4.9 s ± 2 % at first; 200 cycles (over an hour) later, more
        // than 10 % slower.
        assert!(w[0] <= 5000, "{}", w[0]);
        assert!(w[199] > n[199] * 110 / 100, "{} {}", w[199], n[199]);
        // The other motions keep their times.
        for weld in ["WR2A", "WR1B"] {
            assert_eq!(durations(&normal, weld), durations(&worn, weld));
        }
    }

    #[test]
    fn injected_faults_change_the_run() {
        let (normal, none) = run(3, 3, None);
        assert!(none.is_none());
        let (slow, f) = run(
            3,
            3,
            Some(Fault {
                kind: FaultKind::TooSlow,
                step: 5,
            }),
        );
        let f = f.unwrap();
        assert_eq!(f.kind, FaultKind::TooSlow);
        assert_ne!(normal.changes, slow.changes);
        let (missing, f) = run(
            3,
            3,
            Some(Fault {
                kind: FaultKind::SensorMissing,
                step: 5,
            }),
        );
        assert!(missing.changes.len() < normal.changes.len(), "{f:?}");
    }
}
