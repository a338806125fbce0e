use super::*;

fn cmd(now: u64, action: Action) -> Command {
    Command {
        action,
        alarm: "ese".into(),
        tag: None,
        value: None,
        reason: None,
        operator: "kim".into(),
        nonce: nonce(),
        issued_at: now,
        signature: String::new(),
    }
}

fn gate(kim: &OperatorKey, allow: &[Action]) -> Gate {
    Gate::new(
        "m01",
        OperatorKeys::parse("k", &kim.operators_entry(allow)).unwrap(),
    )
}

#[test]
fn signed_once_accepted_then_replay_refused() {
    let kim = OperatorKey::generate("kim");
    let mut gate = gate(&kim, &[Action::Ack]);
    let mut c = cmd(1_000_000, Action::Ack);
    assert_eq!(gate.check(&c, 1_000_000), Err(Refusal::Unsigned));
    c.sign("m01", &kim);
    assert_eq!(gate.check(&c, 1_000_500), Ok(()));
    assert_eq!(gate.check(&c, 1_000_600), Err(Refusal::Replay));
    // Another key under kim's name.
    let mut forged = cmd(1_000_000, Action::Ack);
    forged.sign("m01", &OperatorKey::generate("kim"));
    assert_eq!(gate.check(&forged, 1_000_000), Err(Refusal::BadSignature));
    // Signed for another cell.
    let mut other_cell = cmd(1_000_000, Action::Ack);
    other_cell.sign("m02", &kim);
    assert_eq!(
        gate.check(&other_cell, 1_000_000),
        Err(Refusal::BadSignature)
    );
    // Altered after signing.
    let mut altered = cmd(1_000_000, Action::Ack);
    altered.sign("m01", &kim);
    altered.alarm = "csd".into();
    assert_eq!(gate.check(&altered, 1_000_000), Err(Refusal::BadSignature));
    let mut old = cmd(1_000_000, Action::Ack);
    old.sign("m01", &kim);
    assert!(gate
        .check(&old, 1_100_000)
        .unwrap_err()
        .to_string()
        .starts_with("issued 100000 ms away"));
}

#[test]
fn actions_need_permission() {
    let kim = OperatorKey::generate("kim");
    let mut gate = gate(&kim, &[Action::Ack]);
    let mut reset = cmd(1_000_000, Action::Reset);
    reset.sign("m01", &kim);
    let refusal = gate.check(&reset, 1_000_000).unwrap_err();
    assert_eq!(refusal.to_string(), "operator 'kim' may not reset");
    let mut unknown = cmd(1_000_000, Action::Ack);
    unknown.operator = "lee".into();
    unknown.sign("m01", &OperatorKey::generate("lee"));
    assert_eq!(
        gate.check(&unknown, 1_000_000),
        Err(Refusal::UnknownOperator("lee".into()))
    );
}

#[test]
fn key_files_round_trip_and_hold_the_private_key_only_there() {
    let kim = OperatorKey::generate("kim");
    let file = kim.to_file();
    let back = OperatorKey::parse("kim.key", &file).unwrap();
    assert_eq!(back.public_hex(), kim.public_hex());
    let entry = kim.operators_entry(&[Action::Ack, Action::Reset]);
    assert!(!entry.contains(&hex::encode(kim.key.to_bytes())));
    assert!(entry.contains("allow = [\"ack\", \"reset\"]"), "{entry}");
}

#[test]
fn bad_operators_files() {
    let err = |text: &str| {
        OperatorKeys::parse("ops.toml", text)
            .err()
            .unwrap()
            .to_string()
    };
    assert_eq!(
        err("[operators]\nkim = \"00112233445566778899aabbccddeeff\""),
        "ops.toml: operators.kim: a shared secret is no longer accepted: operators sign with their own key; run `cellwatch keygen --operator kim` and put the public_key and allow it prints here"
    );
    assert_eq!(
        err("[operators.kim]\npublic_key = \"zz\"\nallow = []"),
        "ops.toml: operators.kim: public_key: not an Ed25519 public key (64 hex digits)"
    );
    let kim = OperatorKey::generate("kim");
    assert_eq!(
        err(&format!(
            "[operators.kim]\npublic_key = \"{}\"\nallow = [\"fly\"]",
            kim.public_hex()
        )),
        "ops.toml: operators.kim: allow: unknown action 'fly': use ack, reset, write, shelve, unshelve, out-of-service, in-service, force, stop, configure"
    );
    assert!(err(&format!(
        "[operators.kim]\npublic_key = \"{}\"",
        kim.public_hex()
    ))
    .contains("missing field `allow`"));
    // A name that is no bare key would break the file's tables.
    assert_eq!(
        err(&format!(
            "[operators.\"a.b\"]\npublic_key = \"{}\"\nallow = []",
            kim.public_hex()
        )),
        "ops.toml: operators.\"a.b\": an operator's name is letters, digits, '-' or '_' (a bare key in the operators file)"
    );
}
