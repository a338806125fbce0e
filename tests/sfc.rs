//! `cellwatch sfc check|patch` on chart files.

use crate::util::{cellwatch, root, Dir};

#[test]
fn check_lists_the_robot_charts_and_refuses_a_bad_one_with_its_place() {
    let robot = root().join("config/robot/robot.sfc.toml");
    let r = cellwatch(&["sfc", "check", robot.to_str().unwrap()]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout
            .contains("chart F2 (initial step none (entered by jumps))"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("transition t3    F1.S2 -> F2.S5 + F2.S8 + F2.S11  when %IX0.0.3"),
        "{}",
        r.stdout
    );
    // The same charts as PLCopen XML: the same listing, but for the
    // supervision times XML has no place for.
    let xml = root().join("config/robot/robot.sfc.xml");
    let x = cellwatch(&["sfc", "check", xml.to_str().unwrap()]);
    assert_eq!(x.code, 0, "{}", x.stderr);
    let unsupervised = |s: &str| {
        s.lines()
            .map(|l| match l.find("supervision ") {
                Some(i) => format!(
                    "{} {}",
                    &l[..i],
                    l[i..].splitn(3, "  ").last().unwrap_or("").trim()
                ),
                None => l.to_string(),
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(unsupervised(&x.stdout), unsupervised(&r.stdout));
    assert!(x.stdout.contains("supervision -"), "{}", x.stdout);
    let d = Dir::new();
    let bad = d.file(
        "bad.sfc.toml",
        "[[chart]]\nname = \"F1\"\ninitial = \"S0\"\n[[chart.step]]\nname = \"S0\"\nflag = \"S0.X\"\n[[chart.transition]]\nid = \"t1\"\nfrom = \"S0\"\nto = \"F2.S5\"\ncondition = \"X1\"\n",
    );
    let r = cellwatch(&["sfc", "check", &bad]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .contains("bad.sfc.toml:10:6: transition t1 jumps to 'F2.S5': no chart 'F2'"),
        "{}",
        r.stderr
    );
}

#[test]
fn patch_prints_the_force_term_in_st_and_il() {
    let robot = root().join("config/robot/robot.sfc.toml");
    let r = cellwatch(&[
        "sfc",
        "patch",
        robot.to_str().unwrap(),
        "--force-switch",
        "%IX0.3.1",
        "--transition",
        "F1.t3",
        "--transition",
        "F2.t18",
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(r
        .stdout
        .contains("F1_t3_FIRE := (S2.X AND %IX0.0.3) OR (%IX0.3.1 AND %IX0.0.3);"));
    assert!(r
        .stdout
        .contains("F2_t18_FIRE := (S15.X AND %IX0.2.2) OR (%IX0.3.1 AND %IX0.2.2);"));
    assert!(r
        .stdout
        .contains("OR(  %IX0.3.1\nAND  %IX0.2.2\n)\nST   F2_t18_FIRE"));
    let r = cellwatch(&[
        "sfc",
        "patch",
        robot.to_str().unwrap(),
        "--force-switch",
        "%IX0.3.1",
        "--transition",
        "F1.t9",
    ]);
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("--transition 'F1.t9'"), "{}", r.stderr);
}

/// Step supervision learned through the CLI: the robot's normal runs,
/// `learn --sfc`, and the file taken by a cell's `steps` key.
#[test]
fn learn_sfc_writes_step_supervision_a_cell_takes() {
    let d = Dir::new();
    let train = d.path().join("train");
    let r = cellwatch(&[
        "simulate",
        "robot-runs",
        "--runs",
        "4",
        "--length",
        "40s",
        "--out",
        train.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let robot = root().join("config/robot/robot.sfc.toml");
    let steps = d.path().join("robot-steps.json");
    let mut args = vec![
        "learn".to_string(),
        "--sfc".into(),
        robot.to_str().unwrap().into(),
        "--out".into(),
        steps.to_str().unwrap().into(),
    ];
    args.extend((1..=4).map(|i| format!("{}/run-{i:03}.csv", train.display())));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = cellwatch(&args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.starts_with("4 runs; learned 12 of 13 steps:"),
        "{}",
        r.stdout
    );
    assert!(
        r.stdout
            .contains("F1.S3: never active and left in the runs"),
        "{}",
        r.stdout
    );
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&steps).unwrap()).unwrap();
    let s2 = &model["steps"][2];
    assert_eq!(s2["step"], "F1.S2");
    // Each step takes 1.0-1.4 s: the longest plus at least 1 s.
    let sup = s2["supervision_ms"].as_u64().unwrap();
    assert!((2_000..=2_500).contains(&sup), "{sup}");

    // Options of the timer learner do not apply.
    let r = cellwatch(&[
        "learn",
        "--sfc",
        robot.to_str().unwrap(),
        "--tau",
        "1s",
        "x.csv",
    ]);
    assert_eq!(r.code, 2);
    assert!(r.stderr.contains("cannot be used with"), "{}", r.stderr);
    // A step that is not in the robot's charts.
    let r = cellwatch(&[
        "simulate",
        "robot-runs",
        "--stuck",
        "F1.S9@1s",
        "--out",
        train.to_str().unwrap(),
    ]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .contains("--stuck 'F1.S9@1s': no such step in the robot's charts"),
        "{}",
        r.stderr
    );
}
