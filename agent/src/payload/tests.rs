//! The payloads' tests: what an alarm's payload says and what a journaled
//! one gives back (culprits, comments, shelves, designed suppression,
//! guidance), and the state and snapshot payloads.

use super::*;

#[test]
fn a_comparison_culprit_is_restored_with_its_numbers() {
    let alarm = Alarm {
        id: "spindle-temp".into(),
        kind: AlarmKind::Switching,
        severity: Severity::High,
        fault_type: "HOT".into(),
        active: true,
        acknowledged: false,
        latched: false,
        raised_at: 1_764_000_000_000,
        cleared_at: None,
        acked_by: None,
        ack_comment: None,
        fault_step: Some(1),
        message: "HOT".into(),
        shelved: None,
        out_of_service: None,
        consequence: None,
        designed: None,
        guidance: None,
        culprits: vec![Culprit {
            address: cellwatch_models::signal::Signal::new("TEMP <= 80.5"),
            value: false,
            expected: true,
            comment: Some("Spindle temperature".into()),
            trigger: true,
            compared: Some(cellwatch_models::explain::Compared {
                variable: cellwatch_models::signal::Signal::new("TEMP"),
                value: "85.25".into(),
                needs: "<= 80.5".into(),
            }),
        }],
    };
    let payload = AlarmPayload::new("m01", &alarm, Transition::Raised, alarm.raised_at);
    let back = payload.to_alarm().unwrap();
    assert_eq!(back.culprits, alarm.culprits);
    assert!(back.culprits[0]
        .to_string()
        .starts_with("TEMP = 85.25 (needs <= 80.5)"));
}

#[test]
fn an_acknowledgements_comment_is_restored_and_absent_in_older_payloads() {
    let alarm = Alarm {
        id: "ese".into(),
        kind: AlarmKind::Switching,
        severity: Severity::Critical,
        fault_type: "ESE".into(),
        active: true,
        acknowledged: true,
        latched: false,
        raised_at: 1_764_000_000_000,
        cleared_at: None,
        acked_by: Some("kim".into()),
        ack_comment: Some("tool changed".into()),
        fault_step: Some(6),
        message: "ESE at step 6".into(),
        shelved: None,
        out_of_service: None,
        consequence: None,
        designed: Some(Box::new(DesignedSuppression {
            mode: "setup".into(),
            since: 1_764_000_000_500,
        })),
        guidance: Some(std::sync::Arc::new(cellwatch_models::madb::Guidance {
            class: "safety".into(),
            consequence_of_inaction: "stays stopped".into(),
            corrective_action: "Release the E-stop".into(),
            response_time_ms: Some(300_000),
        })),
        culprits: Vec::new(),
    };
    let payload = AlarmPayload::new("m01", &alarm, Transition::Acknowledged, 1_764_000_001_000);
    let text = serde_json::to_string(&payload).unwrap();
    assert!(text.contains(r#""ack_comment":"tool changed""#), "{text}");
    assert!(
        text.contains(
            r#""suppressed_by_design":{"mode":"setup","since":"2025-11-24T16:00:00.500Z"}"#
        ),
        "{text}"
    );
    let back: AlarmPayload = serde_json::from_str(&text).unwrap();
    assert_eq!(
        back.to_alarm().unwrap().ack_comment.as_deref(),
        Some("tool changed")
    );
    assert_eq!(back.to_alarm().unwrap().designed, alarm.designed);
    assert_eq!(back.to_alarm().unwrap().guidance, alarm.guidance);
    assert!(text.contains(r#""response_time":"5m""#), "{text}");
    // A journal row from before comments were carried.
    let older = text.replace(r#""ack_comment":"tool changed","#, "");
    assert!(!older.contains("ack_comment"), "{older}");
    let back: AlarmPayload = serde_json::from_str(&older).unwrap();
    let back = back.to_alarm().unwrap();
    assert_eq!(
        (back.acked_by.as_deref(), back.ack_comment),
        (Some("kim"), None)
    );
}
