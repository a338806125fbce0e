//! The end of the journal's command chain is signed on the bus (the
//! agent's state and snapshot), so `cellwatch audit verify --against-bus`
//! finds rows cut off the journal's end, which the chain alone cannot.

use std::time::Duration;

use cellwatch::operator::Action;

use crate::agent::Fixture;
use crate::spawned::{send, signed_with};

/// `cellwatch audit verify JOURNAL --against-bus --cell m01ps0004` through
/// `port`, run as a user would.
async fn verify_against_bus(fx: &Fixture) -> crate::util::Run {
    let mut args = vec![
        "audit".to_string(),
        "verify".into(),
        fx.journal_path().display().to_string(),
        "--against-bus".into(),
        "--cell".into(),
        "m01ps0004".into(),
    ];
    args.extend(crate::util::bus_args(
        fx.dir(),
        "operator-kim",
        fx.zenoh_port(),
    ));
    tokio::task::spawn_blocking(move || {
        crate::util::cellwatch(&args.iter().map(String::as_str).collect::<Vec<_>>())
    })
    .await
    .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn rows_cut_off_the_journals_end_are_found_against_the_bus() {
    let fx = Fixture::start_with(|c| c.state_interval = Duration::from_millis(200)).await;
    let state = fx
        .client()
        .declare_subscriber("cellwatch/m01ps0004/state")
        .await
        .unwrap();
    fx.settled().await;
    for (action, reason) in [
        (Action::OutOfService, Some("sensor swap")),
        (Action::InService, None),
        (Action::OutOfService, Some("sensor swap again")),
    ] {
        let (accepted, detail) = send(fx.client(), &signed_with(action, "csd", None, reason)).await;
        assert!(accepted, "{detail}");
    }
    let chained: Vec<(i64, i64, String)> = {
        let c = rusqlite::Connection::open(fx.journal_path()).unwrap();
        let mut st = c
            .prepare(
                "SELECT chain_index, seq, hash FROM commands WHERE hash IS NOT NULL ORDER BY seq",
            )
            .unwrap();
        st.query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
            .unwrap()
            .map(Result::unwrap)
            .collect()
    };
    assert_eq!(chained.len(), 3, "{chained:?}");
    let (last_position, last_seq, last_hash) = chained[2].clone();
    // The state the agent puts carries the chain's end, signed.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(30);
    loop {
        let sample = tokio::time::timeout_at(deadline, state.recv_async())
            .await
            .expect("no state put carrying the chain's end")
            .unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&crate::util::opened(sample.payload())).unwrap();
        if v["command_chain"]["position"] == last_position {
            assert_eq!(v["command_chain"]["seq"], last_seq);
            assert_eq!(v["command_chain"]["hash"], last_hash.as_str());
            break;
        }
    }
    let journal = fx.journal_path().display().to_string();
    let intact = verify_against_bus(&fx).await;
    assert_eq!(
        (intact.code, intact.stdout.as_str()),
        (
            0,
            format!(
                "{journal}: 3 command rows intact; cell m01ps0004's agent signs the chain's end \
                 at position 3 (seq {last_seq}): it is there\n"
            )
            .as_str()
        ),
        "{}",
        intact.stderr
    );
    // The two newest rows cut off: the chain alone still verifies.
    let first_seq = chained[0].1;
    rusqlite::Connection::open(fx.journal_path())
        .unwrap()
        .execute("DELETE FROM commands WHERE seq > ?1", [first_seq])
        .unwrap();
    let alone = crate::util::cellwatch(&["audit", "verify", &journal]);
    assert_eq!(alone.code, 0, "{}", alone.stderr);
    let cut = verify_against_bus(&fx).await;
    assert_eq!(cut.code, 1, "{}{}", cut.stdout, cut.stderr);
    // After Zenoh's own warnings, if any.
    assert!(
        cut.stderr.ends_with(&format!(
            "error: {journal}: 2 command rows cut off the end: cell m01ps0004's agent signs \
             the chain's end at position 3 (seq {last_seq}); the journal's chain ends at \
             position 1 (seq {first_seq}): positions 2 to 3 are missing\n"
        )),
        "{}",
        cut.stderr
    );
}
