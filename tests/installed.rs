//! The binary away from the checkout, as the package installs it: `cellwatch
//! demo` run from an empty directory finds its own configuration (carried in
//! the binary, written under its state directory), starts every cell and
//! raises its first alarm.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::util::root;

#[test]
fn the_demo_runs_from_an_empty_directory() {
    let cwd = tempfile::tempdir().unwrap();
    let log = tempfile::NamedTempFile::new().unwrap();
    let start = Instant::now();
    let mut demo = Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["demo", "--duration", "120s", "--any-ports"])
        .current_dir(cwd.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::from(log.reopen().unwrap()))
        .spawn()
        .unwrap();
    let lines = crate::util::lines_of(&mut demo);
    let wanted = [
        "cellwatch demo: cell m01ps0004",
        "  configuration   cellwatch-demo/config (the demo's own",
        "body-shop line on opc.tcp://",
        "injection-moulding units 1-3 on an @ bus",
        "LCD-glass robot on opc.tcp://",
        "  ALARM  ",
    ];
    let mut seen: Vec<String> = Vec::new();
    while !wanted.iter().all(|w| seen.iter().any(|l| l.contains(w))) {
        // The first alarm comes on the scenarios' schedule; the bound only
        // ends a demo that never shows it.
        match lines.recv_timeout(Duration::from_secs(90).saturating_sub(start.elapsed())) {
            Ok(line) => seen.push(line),
            Err(_) => {
                let _ = demo.kill();
                let _ = demo.wait();
                panic!(
                    "the demo from an empty directory:\n{}\nstderr:\n{}",
                    seen.join("\n"),
                    std::fs::read_to_string(log.path()).unwrap_or_default()
                );
            }
        }
    }
    let _ = demo.kill();
    let _ = demo.wait();
    // Its configuration, as the checkout has it, in its state directory.
    let written = cwd.path().join("cellwatch-demo/config");
    for file in [
        "demo.toml",
        "cnc/ese.il",
        "line/timers.json",
        "robot/robot.sfc.toml",
    ] {
        assert_eq!(
            std::fs::read(written.join(file)).unwrap(),
            std::fs::read(root().join("config").join(file)).unwrap(),
            "{file}"
        );
    }
    assert!(!cwd.path().join("config").exists());
}
