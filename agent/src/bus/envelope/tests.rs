use super::*;

fn trust_of(key: &AgentKey) -> Trust {
    Trust::parse("trust.toml", &key.trust_entry()).unwrap()
}

#[test]
fn a_sealed_put_opens_with_the_cells_key_only() {
    let m01 = AgentKey::generate("m01");
    let m02 = AgentKey::generate("m02");
    let sealed = m01.seal(Kind::Put, "cellwatch/m01/state", "", 7, "{\"a\":1}".into());
    let opened = trust_of(&m01)
        .open(sealed.as_bytes(), Kind::Put, "cellwatch/m01/state", "")
        .unwrap();
    assert_eq!((opened.cell.as_str(), opened.at), ("m01", 7));
    assert_eq!(opened.body, "{\"a\":1}");
    // Another cell's trust file does not know m01.
    assert_eq!(
        trust_of(&m02).open(sealed.as_bytes(), Kind::Put, "cellwatch/m01/state", ""),
        Err(Distrust::UnknownCell("m01".into()))
    );
    // m02's agent claiming to be m01: its signature is not m01's.
    let mut forged: Envelope =
        serde_json::from_str(&m02.seal(Kind::Put, "cellwatch/m01/state", "", 7, "{}".into()))
            .unwrap();
    forged.cell = "m01".into();
    assert_eq!(
        trust_of(&m01).open(
            serde_json::to_string(&forged).unwrap().as_bytes(),
            Kind::Put,
            "cellwatch/m01/state",
            ""
        ),
        Err(Distrust::BadSignature("m01".into()))
    );
}

#[test]
fn an_envelope_moved_to_another_key_kind_or_query_is_refused() {
    let m01 = AgentKey::generate("m01");
    let trust = trust_of(&m01);
    let put = m01.seal(Kind::Put, "cellwatch/m01/alarms/ese", "", 7, "{}".into());
    assert!(matches!(
        trust.open(put.as_bytes(), Kind::Put, "cellwatch/m01/alarms/csd", ""),
        Err(Distrust::Misplaced { .. })
    ));
    assert!(matches!(
        trust.open(put.as_bytes(), Kind::Reply, "cellwatch/m01/alarms/ese", ""),
        Err(Distrust::Misplaced { .. })
    ));
    let reply = m01.seal(
        Kind::Reply,
        "cellwatch/m01/snapshot",
        "nonce=aa",
        7,
        "{}".into(),
    );
    assert!(trust
        .open(
            reply.as_bytes(),
            Kind::Reply,
            "cellwatch/m01/snapshot",
            "nonce=aa"
        )
        .is_ok());
    // An old answer replayed to a new query.
    assert!(matches!(
        trust.open(
            reply.as_bytes(),
            Kind::Reply,
            "cellwatch/m01/snapshot",
            "nonce=bb"
        ),
        Err(Distrust::Misplaced { .. })
    ));
    // A body edited after sealing.
    let mut edited: Envelope = serde_json::from_str(&reply).unwrap();
    edited.body = "{\"x\":1}".into();
    assert_eq!(
        trust.open(
            serde_json::to_string(&edited).unwrap().as_bytes(),
            Kind::Reply,
            "cellwatch/m01/snapshot",
            "nonce=aa"
        ),
        Err(Distrust::BadSignature("m01".into()))
    );
}

#[test]
fn the_signed_bytes_are_length_prefixed() {
    // A field boundary moved by text inside a field changes the bytes.
    let a = signed_bytes(Kind::Put, "m01", "k", "a\u{0}", 1, "b");
    let b = signed_bytes(Kind::Put, "m01", "k", "a", 1, "\u{0}b");
    assert_ne!(a, b);
    let mut expected = b"cellwatch.signed.v1".to_vec();
    for f in ["put", "m01", "k", "", "12", "{}"] {
        expected.extend_from_slice(&(f.len() as u32).to_be_bytes());
        expected.extend_from_slice(f.as_bytes());
    }
    assert_eq!(signed_bytes(Kind::Put, "m01", "k", "", 12, "{}"), expected);
}

#[test]
fn key_files_round_trip_and_trust_files_name_their_errors() {
    let key = AgentKey::generate("m01");
    let back = AgentKey::parse("m01.key", &key.to_file()).unwrap();
    assert_eq!((back.cell(), back.public_hex()), ("m01", key.public_hex()));
    assert_eq!(
        Trust::parse("trust.toml", "[cells.m01]\npublic_key = \"abc\"\n")
            .unwrap_err()
            .to_string(),
        "trust.toml: cells.m01.public_key: not an Ed25519 public key (64 hex digits)"
    );
    assert!(Trust::parse("trust.toml", "[cells.m01]\nkey = \"abc\"\n").is_err());
}

#[cfg(unix)]
#[test]
fn a_private_key_others_may_read_is_refused() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m01.key");
    let (_, made) = AgentKey::load_or_create(&path, "m01").unwrap();
    assert!(made);
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600);
    assert!(!AgentKey::load_or_create(&path, "m01").unwrap().1);
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
    let err = AgentKey::load(&path).err().unwrap().to_string();
    assert_eq!(
        err,
        format!(
            "{0}: a private key readable by others (mode 644); make it the owner's only: chmod 600 {0}",
            path.display()
        )
    );
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
    let err = AgentKey::load_or_create(&path, "m02")
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.ends_with("the signing key of cell 'm01', not of 'm02': each cell's agent has its own"),
        "{err}"
    );
}

/// The puts of one step: an alarm event, the state, a recording.
const STEP: [(&str, &str); 3] = [
    ("cellwatch/m01/alarms/ese", "{\"id\":\"ese\"}"),
    ("cellwatch/m01/state", "{\"state\":\"fault\"}"),
    ("cellwatch/m01/recordings/csd", "{\"alarm\":\"csd\"}"),
];

/// `puts` sealed together at 7 ms, each envelope as written.
fn sealed_together(key: &AgentKey, puts: &[(&str, &str)]) -> Vec<String> {
    let sealed = key.seal_puts(7, puts);
    puts.iter()
        .enumerate()
        .map(|(i, (k, b))| sealed.envelope(i, k, b))
        .collect()
}

fn reparsed(sealed: &str, edit: impl FnOnce(&mut Envelope)) -> String {
    let mut env: Envelope = serde_json::from_str(sealed).unwrap();
    edit(&mut env);
    serde_json::to_string(&env).unwrap()
}

#[test]
fn a_steps_puts_are_sealed_with_one_signature_and_each_opens_alone() {
    let m01 = AgentKey::generate("m01");
    let sealed = sealed_together(&m01, &STEP);
    assert_eq!(m01.signing().0, 1, "one signature for the step");
    for (i, ((key, body), sealed)) in STEP.iter().zip(&sealed).enumerate() {
        // A fresh trust each time: nothing remembered from a sibling.
        let opened = trust_of(&m01)
            .open(sealed.as_bytes(), Kind::Put, key, "")
            .unwrap();
        assert_eq!(
            (opened.cell.as_str(), opened.at, opened.body.as_str()),
            ("m01", 7, *body)
        );
        let env: Envelope = serde_json::from_str(sealed).unwrap();
        let tree = env.tree.unwrap();
        assert_eq!(env.schema, GROUP_SCHEMA);
        assert_eq!((tree.size, tree.index), (3, i as u64));
        // Three leaves: the first two one level deeper than the third.
        assert_eq!(tree.path.len(), if i < 2 { 2 } else { 1 });
    }
    // Opened in turn by one trust: the second and third from memory.
    let trust = trust_of(&m01);
    for ((key, _), sealed) in STEP.iter().zip(&sealed) {
        assert!(trust.open(sealed.as_bytes(), Kind::Put, key, "").is_ok());
    }
    // A put alone is sealed as ever.
    let one = sealed_together(&m01, &STEP[..1]);
    let env: Envelope = serde_json::from_str(&one[0]).unwrap();
    assert_eq!((env.schema.as_str(), env.tree), (SIGNED_SCHEMA, None));
    assert!(trust
        .open(one[0].as_bytes(), Kind::Put, "cellwatch/m01/alarms/ese", "")
        .is_ok());
    assert_eq!(m01.signing().0, 2);
    // A large step: one signature, each path short.
    let keys: Vec<String> = (0..1000)
        .map(|i| format!("cellwatch/m01/alarms/a{i}"))
        .collect();
    let puts: Vec<(&str, &str)> = keys.iter().map(|k| (k.as_str(), "{}")).collect();
    let sealed = sealed_together(&m01, &puts);
    assert_eq!(m01.signing().0, 3);
    for (i, sealed) in sealed.iter().enumerate().step_by(97) {
        let env: Envelope = serde_json::from_str(sealed).unwrap();
        assert!(env.tree.unwrap().path.len() <= 10);
        assert!(trust
            .open(sealed.as_bytes(), Kind::Put, &keys[i], "")
            .is_ok());
    }
}

#[test]
fn a_sealed_together_envelope_edited_moved_or_forged_is_refused() {
    let m01 = AgentKey::generate("m01");
    let m02 = AgentKey::generate("m02");
    let trust = trust_of(&m01);
    let sealed = sealed_together(&m01, &STEP);
    let (alarm, state) = (STEP[0].0, STEP[1].0);
    // Opened once, so its root's signature is remembered: what follows
    // must be refused all the same.
    assert!(trust
        .open(sealed[0].as_bytes(), Kind::Put, alarm, "")
        .is_ok());
    let bad = Err(Distrust::BadSignature("m01".into()));
    // Its body edited: its leaf no longer leads to the signed root.
    let edited = reparsed(&sealed[0], |e| e.body = "{\"id\":\"csd\"}".into());
    assert_eq!(trust.open(edited.as_bytes(), Kind::Put, alarm, ""), bad);
    // Its time changed (a replay as news).
    let later = reparsed(&sealed[1], |e| e.at = 9);
    assert_eq!(trust.open(later.as_bytes(), Kind::Put, state, ""), bad);
    // Its place changed: another index, another size, a sibling's path.
    let moved = |edit: fn(&mut InTree)| reparsed(&sealed[0], |e| edit(e.tree.as_mut().unwrap()));
    for forged in [
        moved(|t| t.index = 1),
        moved(|t| t.size = 4),
        moved(|t| t.path.truncate(1)),
        moved(|t| t.path.swap(0, 1)),
        moved(|t| t.path[0] = "zz".into()),
    ] {
        assert_eq!(trust.open(forged.as_bytes(), Kind::Put, alarm, ""), bad);
    }
    // A sibling put on another key than sealed for.
    assert!(matches!(
        trust.open(sealed[1].as_bytes(), Kind::Put, alarm, ""),
        Err(Distrust::Misplaced { .. })
    ));
    // m02's agent sealing a step in m01's name.
    let forged = sealed_together(&m02, &STEP);
    let forged = reparsed(&forged[0], |e| e.cell = "m01".into());
    assert_eq!(trust.open(forged.as_bytes(), Kind::Put, alarm, ""), bad);
    // m01's key replaced in the trust file: the remembered root is not
    // believed under the new key.
    let mut rekeyed = trust.clone();
    rekeyed.insert("m01", trust_of(&m02).cells.get("m02").unwrap()[0]);
    assert_eq!(
        rekeyed.open(sealed[0].as_bytes(), Kind::Put, alarm, ""),
        bad
    );
    // A tree of one, a tree in a v1 envelope, a v2 envelope without one.
    let not_an_envelope = |sealed: String| {
        assert!(matches!(
            trust.open(sealed.as_bytes(), Kind::Put, alarm, ""),
            Err(Distrust::NotAnEnvelope(_))
        ));
    };
    not_an_envelope(moved(|t| t.size = 1));
    not_an_envelope(reparsed(&sealed[0], |e| e.schema = SIGNED_SCHEMA.into()));
    not_an_envelope(reparsed(&sealed[0], |e| e.tree = None));
}

#[cfg(unix)]
#[test]
fn every_private_key_file_others_may_read_is_named() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let (https, bus, missing) = (
        dir.path().join("console.key"),
        dir.path().join("operator-kim.key"),
        dir.path().join("gone.key"),
    );
    for (path, mode) in [(&https, 0o640), (&bus, 0o600)] {
        std::fs::write(path, "-----BEGIN PRIVATE KEY-----\n").unwrap();
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }
    assert!(check_private_keys([bus.as_path()]).is_ok());
    let refused: Vec<String> =
        check_private_keys([https.as_path(), bus.as_path(), missing.as_path()])
            .unwrap_err()
            .iter()
            .map(ToString::to_string)
            .collect();
    assert_eq!(refused.len(), 2, "{refused:?}");
    assert_eq!(
        refused[0],
        format!(
            "{0}: a private key readable by others (mode 640); make it the owner's only: chmod 600 {0}",
            https.display()
        )
    );
    assert!(
        refused[1].starts_with(&format!("{}: ", missing.display())),
        "{}",
        refused[1]
    );
}

#[test]
fn a_key_being_rotated_from_is_believed_beside_the_new_one_until_removed() {
    let old = AgentKey::generate("m01");
    let new = AgentKey::generate("m01");
    let sealed = |k: &AgentKey| k.seal(Kind::Put, "cellwatch/m01/state", "", 1, "{}".into());
    let both = Trust::parse(
        "trust.toml",
        &format!(
            "[cells.m01]\npublic_key = \"{}\"\nprevious_keys = [\"{}\"]\n",
            new.public_hex(),
            old.public_hex()
        ),
    )
    .unwrap();
    for k in [&old, &new] {
        both.open(sealed(k).as_bytes(), Kind::Put, "cellwatch/m01/state", "")
            .unwrap();
    }
    assert_eq!(both.public_hex("m01"), Some(new.public_hex()));
    assert_eq!(both.previous_hex("m01"), vec![old.public_hex()]);
    let done = Trust::parse(
        "trust.toml",
        &format!("[cells.m01]\npublic_key = \"{}\"\n", new.public_hex()),
    )
    .unwrap();
    assert!(matches!(
        done.open(
            sealed(&old).as_bytes(),
            Kind::Put,
            "cellwatch/m01/state",
            ""
        ),
        Err(Distrust::BadSignature(_))
    ));
}
