use super::*;

#[test]
fn an_unknown_action_does_not_parse() {
    let text = r#"{"action":"launch","alarm":"ese","operator":"kim","nonce":"n","issued_at":1,"signature":"00"}"#;
    let err = serde_json::from_str::<Command>(text)
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("unknown variant `launch`, expected one of `ack`, `reset`, `write`"),
        "{err}"
    );
    let ok = text.replace("launch", "reset");
    assert_eq!(
        serde_json::from_str::<Command>(&ok).unwrap().action,
        Action::Reset
    );
}
