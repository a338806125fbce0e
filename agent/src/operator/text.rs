use super::*;

fn shelf(value: &str, reason: &str) -> Command {
    Command {
        action: Action::Shelve,
        alarm: "ese".into(),
        tag: None,
        value: Some(value.into()),
        reason: Some(reason.into()),
        operator: "kim".into(),
        nonce: nonce(),
        issued_at: 1_000_000,
        signature: String::new(),
    }
}

#[test]
fn the_signed_text_is_injective() {
    // Under v4 both were "…\n30m\n2h\nwaiting": one signature for a
    // 30-minute and a 2-hour shelf.
    let short = shelf("30m", "2h\nwaiting");
    let long = Command {
        nonce: short.nonce.clone(),
        ..shelf("30m\n2h", "waiting")
    };
    assert_ne!(short.canonical("m01"), long.canonical("m01"));
    let text = String::from_utf8(short.canonical("m01")).unwrap();
    assert_eq!(
        text,
        format!(
            "cellwatch-command-v5\n3:m01\n6:shelve\n3:ese\n3:kim\n32:{}\n7:1000000\n-\n3:30m\n10:2h\nwaiting\n",
            short.nonce
        )
    );
    // An absent field is not an empty one.
    let mut empty = short.clone();
    empty.tag = Some(String::new());
    assert_ne!(empty.canonical("m01"), short.canonical("m01"));
    // The signature of one does not verify the other.
    let kim = OperatorKey::generate("kim");
    let mut signed = shelf("30m", "2h waiting");
    signed.sign("m01", &kim);
    let mut bent = Command {
        value: Some("30m 2h".into()),
        reason: Some("waiting".into()),
        ..signed.clone()
    };
    bent.signature = signed.signature.clone();
    let mut gate = Gate::new(
        "m01",
        OperatorKeys::parse("k", &kim.operators_entry(&[Action::Shelve])).unwrap(),
    );
    assert_eq!(gate.check(&bent, 1_000_000), Err(Refusal::BadSignature));
    assert_eq!(gate.check(&signed, 1_000_000), Ok(()));
}

#[test]
fn control_characters_and_bad_nonces_are_refused_before_the_signature() {
    let kim = OperatorKey::generate("kim");
    let mut gate = Gate::new(
        "m01",
        OperatorKeys::parse("k", &kim.operators_entry(&Action::ALL)).unwrap(),
    );
    let mut c = shelf("30m", "2h\nwaiting");
    c.sign("m01", &kim);
    let refusal = gate.check(&c, 1_000_000).unwrap_err();
    assert_eq!(
        refusal.to_string(),
        "reason holds a control character (a newline, tab or escape): write it on one line"
    );
    assert_eq!(refusal.unauthenticated(), Some("malformed"));
    for text in ["a\rb", "\u{1b}[2K", "x\u{202e}y", "tab\there"] {
        let mut c = shelf("30m", "ok");
        c.alarm = text.into();
        assert_eq!(
            c.check_text(),
            Err(Refusal::ControlCharacter("alarm")),
            "{text:?}"
        );
    }
    // Letters of any script are text.
    assert_eq!(
        shelf("30m", "Förderband läuft / ベルト").check_text(),
        Ok(())
    );
    // A nonce longer than the journal keeps, or not hex, is refused.
    for bad in [
        "n1",
        &"a".repeat(200),
        "ABCDEF0123456789",
        "0123456789abcdeg",
    ] {
        let c = Command {
            nonce: bad.to_string(),
            ..shelf("30m", "ok")
        };
        assert_eq!(c.check_text(), Err(Refusal::BadNonce), "{bad}");
    }
    assert!(valid_nonce(&nonce()));
}

#[test]
fn printers_escape_control_characters_only() {
    assert_eq!(escaped("Förderband läuft"), "Förderband läuft");
    assert_eq!(
        escaped("no\n2026-01-01 fake\u{1b}[2K\\"),
        "no\\n2026-01-01 fake\\u{1b}[2K\\\\"
    );
}
