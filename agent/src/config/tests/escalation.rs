//! Configuration tests of `alertmanager.escalation`: the steps of the
//! `unacknowledged_for` label.

use super::*;

fn with(escalation: Option<&str>) -> String {
    let line = escalation.map_or_else(String::new, |e| format!("escalation = {e}\n"));
    format!("{GOOD}\n[alertmanager]\nurls = [\"http://127.0.0.1:9093\"]\n{line}")
}

fn steps(text: &str) -> Vec<(String, Duration)> {
    parse("cell.toml", text, Path::new("base"), &mem())
        .unwrap()
        .alertmanager
        .unwrap()
        .escalation
}

#[test]
fn escalation_steps_default_to_5m_15m_1h_and_are_checked_where_written() {
    let minutes = |m: u64| Duration::from_secs(60 * m);
    assert_eq!(
        steps(&with(None)),
        [
            ("5m".to_string(), minutes(5)),
            ("15m".to_string(), minutes(15)),
            ("1h".to_string(), minutes(60)),
        ]
    );
    assert_eq!(
        steps(&with(Some("[\"2m\", \"10m\"]"))),
        [
            ("2m".to_string(), minutes(2)),
            ("10m".to_string(), minutes(10))
        ]
    );
    assert!(steps(&with(Some("[]"))).is_empty());
    assert_eq!(
        errors(&with(Some("[\"10m\", \"5m\", \"0s\", \"soon\"]"))),
        [
            "cell.toml:30:22: alertmanager.escalation: '5m': each step must be longer than the one before it",
            "cell.toml:30:28: alertmanager.escalation: '0s': a step is a time after the raise, more than 0",
            "cell.toml:30:34: alertmanager.escalation: 'soon' is not a duration like 5m or 1h (expected number at 0)",
        ]
        .join("\n")
    );
}
