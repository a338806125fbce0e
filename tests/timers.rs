//! `cellwatch learn` and `replay` on the paper's Table 1 log.

use crate::util::{cellwatch, Dir};

#[test]
fn learn_and_replay_table1() {
    let d = Dir::new();
    let map = d.file("map.csv", "1,S1\n2,S2\n3,S3\n");
    let run = d.file("table1.csv", "t,e\n10,+2\n140,+3\n150,-3\n");
    let early = d.file("early.csv", "t,e\n10,+2\n125,+3\n");
    let model = d.file("timers.json", "");
    let r = cellwatch(&[
        "learn",
        &run,
        "--map",
        &map,
        "--method",
        "full-state",
        "--delta-min",
        "100ms",
        "--tau",
        "10ms",
        "--out",
        &model,
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains(
            "kept 1 transitions:\n  #001 δ(S2:-S3, +S3 | 130) window [120, 140] ms, support 1\n"
        ),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("  δ(-2:-3, +2 | 10) = 2:-3: Δt 10 ms < Δmin\n"),
        "{}",
        r.stdout
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(v["version"], 1);
    assert_eq!(
        v["transitions"][0]["event"],
        serde_json::json!({"tag": "S3", "edge": "rise"})
    );
    assert_eq!(
        v["transitions"][0]["window_ms"],
        serde_json::json!([120, 140])
    );
    let r = cellwatch(&["replay", "--timers", &model, &run, "--map", &map, "--json"]);
    assert_eq!(
        r.stdout, "{\"outcome\":\"normal\",\"transition\":1,\"at_ms\":140,\"observed_ms\":130}\n",
        "{}",
        r.stderr
    );
    let r = cellwatch(&[
        "replay", "--timers", &model, &early, "--map", &map, "--json",
    ]);
    assert_eq!(
        r.stdout,
        "{\"outcome\":\"early\",\"transition\":1,\"at_ms\":125,\"observed_ms\":115}\n"
    );
}

#[test]
fn bad_logs_exit_2_with_file_and_line() {
    let d = Dir::new();
    let run = d.file("r.csv", "time_ms,tag,value\n0,a,0\n20,a,1\n10,a,0\n");
    let r = cellwatch(&["learn", &run, "--out", &d.file("t.json", "")]);
    assert_eq!(r.code, 2);
    assert_eq!(
        r.stderr.replace(&run, "r.csv"),
        "error: r.csv:4: time 10 ms goes backwards (previous row at 20 ms)\n"
    );
    let map = d.file("map.csv", "1,S1\n");
    let run = d.file("n.csv", "t,e\n10,+7\n");
    let r = cellwatch(&["learn", &run, "--map", &map]);
    assert_eq!(r.code, 2);
    assert_eq!(
        r.stderr.replace(&run, "n.csv").replace(&map, "map.csv"),
        "error: n.csv:2: unknown signal number 7 in '+7' (not in map.csv)\n"
    );
}

/// The simulated line end to end through the CLI: simulate, learn, replay.
#[test]
fn simulate_learn_replay_the_line() {
    let d = tempfile::tempdir().unwrap();
    let dir = |n: &str| d.path().join(n).to_str().unwrap().to_string();
    let r = cellwatch(&[
        "simulate",
        "line",
        "--runs",
        "4",
        "--seed",
        "1",
        "--out",
        &dir("train"),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = cellwatch(&[
        "simulate",
        "line",
        "--runs",
        "2",
        "--seed",
        "200",
        "--out",
        &dir("normal"),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = cellwatch(&[
        "simulate",
        "line",
        "--runs",
        "1",
        "--seed",
        "300",
        "--inject",
        "slow@12",
        "--out",
        &dir("faulty"),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let labels = std::fs::read_to_string(d.path().join("faulty/faults.csv")).unwrap();
    let sensor = labels
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(2)
        .unwrap()
        .to_string();
    let runs: Vec<String> = (1..=4)
        .map(|i| format!("{}/run-{i:03}.csv", dir("train")))
        .collect();
    let model = dir("timers.json");
    let mut args = vec!["learn", "--delta-min", "2s", "--tau-auto", "--out", &model];
    args.extend(runs.iter().map(String::as_str));
    let r = cellwatch(&args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r.stdout.contains("kept 26 transitions"), "{}", r.stdout);
    let normal = [
        format!("{}/run-001.csv", dir("normal")),
        format!("{}/run-002.csv", dir("normal")),
    ];
    let r = cellwatch(&[
        "replay", "--timers", &model, &normal[0], &normal[1], "--json",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .lines()
            .all(|l| l.contains("\"outcome\":\"normal\"")),
        "false alarm: {}",
        r.stdout
    );
    let r = cellwatch(&[
        "replay",
        "--timers",
        &model,
        &format!("{}/run-001.csv", dir("faulty")),
        "--json",
    ]);
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path().join("timers.json")).unwrap())
            .unwrap();
    let late: Vec<u64> = r
        .stdout
        .lines()
        .filter(|l| l.contains("\"outcome\":\"late\""))
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["transition"]
                .as_u64()
                .unwrap()
        })
        .collect();
    let named: Vec<&str> = late
        .iter()
        .map(|id| {
            model["transitions"]
                .as_array()
                .unwrap()
                .iter()
                .find(|t| t["id"] == *id)
                .unwrap()["event"]["tag"]
                .as_str()
                .unwrap()
        })
        .collect();
    assert!(
        named.contains(&sensor.as_str()),
        "slow {sensor} not flagged: {named:?}\n{}",
        r.stdout
    );
}

/// The `blark` Structured Text parser (PyPI), installed on first use in a
/// virtual environment under cargo's target directory.
fn blark() -> std::path::PathBuf {
    let venv = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("blark-venv");
    let bin = venv.join("bin").join("blark");
    if !bin.exists() {
        let ok = std::process::Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .unwrap()
            .success()
            && std::process::Command::new(venv.join("bin").join("pip"))
                .args(["install", "--quiet", "blark==0.8.3"])
                .status()
                .unwrap()
                .success();
        assert!(
            ok,
            "cannot install blark (python3 -m venv, pip install blark==0.8.3)"
        );
    }
    bin
}

fn blark_accepts(file: &str) -> bool {
    let out = std::process::Command::new(blark())
        .args(["parse", file])
        .output()
        .unwrap();
    out.status.success()
}

#[test]
fn exported_structured_text_is_accepted_by_an_independent_parser() {
    let d = tempfile::tempdir().unwrap();
    let path = |n: &str| d.path().join(n).to_str().unwrap().to_string();
    // The paper's example (full-state) and the simulated line (common).
    std::fs::write(path("map.csv"), "1,S1\n2,S2\n3,S3\n").unwrap();
    std::fs::write(path("table1.csv"), "t,e\n10,+2\n140,+3\n150,-3\n").unwrap();
    let r = cellwatch(&[
        "learn",
        &path("table1.csv"),
        "--map",
        &path("map.csv"),
        "--method",
        "full-state",
        "--delta-min",
        "0ms",
        "--tau",
        "10ms",
        "--out",
        &path("t1.json"),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = cellwatch(&["simulate", "line", "--runs", "4", "--out", &path("train")]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let runs: Vec<String> = (1..=4)
        .map(|i| format!("{}/run-{i:03}.csv", path("train")))
        .collect();
    let out = path("line.json");
    let mut args = vec!["learn", "--out", out.as_str()];
    args.extend(runs.iter().map(String::as_str));
    assert_eq!(cellwatch(&args).code, 0);
    for (model, st) in [("t1.json", "t1.st"), ("line.json", "line.st")] {
        let r = cellwatch(&["export-st", "--timers", &path(model), "--out", &path(st)]);
        assert_eq!(r.code, 0, "{}", r.stderr);
        let text = std::fs::read_to_string(path(st)).unwrap();
        assert!(
            text.contains("ERROR_ALARM_001")
                && text.contains("ERROR_RESET_001")
                && text.contains("MIN_WAIT_001")
                && text.contains("MAX_WAIT_001")
                && text.contains("COM :=")
        );
        assert!(blark_accepts(&path(st)), "blark refused {st}:\n{text}");
    }
    // The parser is a real check: it refuses broken text.
    std::fs::write(path("broken.st"), "FUNCTION_BLOCK X\nVAR_INPUT a : BOOL; END_VAR\nIF a THEN b := ; END_IF;\nEND_FUNCTION_BLOCK\n").unwrap();
    assert!(!blark_accepts(&path("broken.st")));
    // Bad names are refused before any output.
    let r = cellwatch(&[
        "export-st",
        "--timers",
        &path("t1.json"),
        "--name",
        "9lives",
    ]);
    assert_eq!(
        (r.code, r.stderr.as_str()),
        (
            2,
            "error: --name '9lives' is not an IEC 61131-3 identifier\n"
        )
    );
}
