//! `cellwatch run --realtime-priority`: the agent's threads under
//! SCHED_FIFO, or a clear refusal where the system does not allow it.

use std::process::Command;
use std::time::{Duration, Instant};

use crate::spawned::scrape;

/// Whether this process may put a thread under SCHED_FIFO at `priority`
/// (root, CAP_SYS_NICE or RLIMIT_RTPRIO): tried on a thread of its own.
fn fifo_allowed(priority: u8) -> bool {
    std::thread::spawn(move || {
        use thread_priority::{
            set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy,
            ThreadPriority, ThreadSchedulePolicy,
        };
        set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Crossplatform(priority.try_into().unwrap()),
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
        )
        .is_ok()
    })
    .join()
    .unwrap()
}

/// Each thread of `pid`: its name, scheduling policy and real-time
/// priority (`/proc/PID/task/TID/stat` fields 2, 41 and 40).
fn threads(pid: u32) -> Vec<(String, u32, u32)> {
    let mut out = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).unwrap() {
        let Ok(stat) = std::fs::read_to_string(task.unwrap().path().join("stat")) else {
            continue; // the thread ended
        };
        let (head, rest) = stat.rsplit_once(')').unwrap();
        let name = head.split_once('(').unwrap().1.to_string();
        // Fields from 3 (the state) on.
        let fields: Vec<&str> = rest.split_whitespace().collect();
        out.push((
            name,
            fields[38].parse().unwrap(),
            fields[37].parse().unwrap(),
        ));
    }
    out
}

const SCHED_FIFO: u32 = 1;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_realtime_agent_runs_every_thread_under_sched_fifo_and_still_raises_alarms() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, mut cell) = crate::spawned::start(dir.path()).await;
    if !fifo_allowed(7) {
        // Not allowed here: the agent must refuse before any cell starts,
        // and say what it needs.
        let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
            .args([
                "run",
                cell.config.to_str().unwrap(),
                "--realtime-priority",
                "7",
            ])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains("--realtime-priority 7: the system refused SCHED_FIFO")
                && stderr.contains("LimitRTPRIO=7"),
            "{stderr}"
        );
        assert!(!stderr.contains("agent running"), "{stderr}");
        sim.stop();
        return;
    }
    let mut child = cell
        .spawn_with("agent.log", &["--realtime-priority", "7"])
        .await;
    let running = threads(child.id());
    // The runtime's workers, the cell loop, Zenoh's and the journal's
    // threads: every one started after the flag took effect.
    assert!(running.len() >= 5, "{running:?}");
    for name in ["cell-loop", "journal-writer", "tokio-rt-worker"] {
        assert!(
            running.iter().any(|t| t.0 == name),
            "no {name}: {running:?}"
        );
    }
    for (name, policy, priority) in &running {
        assert_eq!(
            (*policy, *priority),
            (SCHED_FIFO, 7),
            "thread {name} is not under SCHED_FIFO at 7: {running:?}"
        );
    }
    // And the agent works as without it: a fault is raised (X0.06, a
    // limit switch, opens).
    let start = Instant::now();
    let raised = loop {
        let body = scrape(cell.metrics_port);
        let connected = body
            .lines()
            .any(|l| l.starts_with("cellwatch_opcua_connected{") && l.ends_with(" 1"));
        if connected {
            sim.set("X0.06", false).unwrap();
        }
        let raised: f64 = body
            .lines()
            .filter(|l| l.starts_with("cellwatch_alarms_raised_total{"))
            .filter_map(|l| l.rsplit_once(' ')?.1.parse::<f64>().ok())
            .sum();
        if raised >= 1.0 || start.elapsed() > Duration::from_secs(60) {
            break raised;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    child.kill().unwrap();
    child.wait().unwrap();
    sim.stop();
    assert!(
        raised >= 1.0,
        "no alarm raised; agent log:\n{}",
        cell.log("agent.log")
    );
}

#[test]
fn realtime_priorities_outside_one_to_ninety_nine_are_refused_by_name() {
    for bad in ["0", "100", "ten"] {
        let out = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
            .args(["run", "cell.toml", "--realtime-priority", bad])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{bad}: {stderr}");
        assert!(
            stderr.contains(&format!(
                "invalid value '{bad}' for '--realtime-priority <PRIORITY>'"
            )),
            "{stderr}"
        );
    }
}
