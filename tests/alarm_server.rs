//! The alarm server (`[alarm_server]`) with real parts: the agent over the
//! simulated CNC, a SCADA client of async-opcua over Basic256Sha256 with
//! SignAndEncrypt subscribing to events on the `Server` object, seeing ESE
//! raised with its diagnosis and culprits, and acknowledging it as users
//! mapped (or not) to operators; the bus and the journal say what the cell
//! loop did.

use std::path::Path;
use std::time::Duration;

use cellwatch::config::AlarmServerConfig;
use cellwatch::operator::Action;
use cellwatch::services::alarm_server::users::hash_password;
use opcua::client::{Client, ClientBuilder, IdentityToken, Session};
use opcua::crypto::SecurityPolicy;
use opcua::types::{
    AttributeId, MessageSecurityMode, NodeId, ReadValueId, TimestampsToReturn, Variant,
};

use crate::agent::Fixture;

mod acknowledging;
mod asyncua;
mod channels;
mod machinery;
mod node_opcua;
mod reload;
mod scada;
pub(crate) use scada::ScadaProgram;

/// The users: kim's SCADA account, one acting as an operator the agent
/// does not know, one as an operator who may not acknowledge, one acting
/// as nobody.
pub(crate) fn users_file(path: &Path) {
    let hash = hash_password("kims-password");
    std::fs::write(
        path,
        format!(
            "[users.scada-kim]\noperator = \"kim\"\npassword_hash = \"{hash}\"\n\n\
             [users.scada-lee]\noperator = \"lee\"\npassword_hash = \"{hash}\"\n\n\
             [users.scada-ana]\noperator = \"ana\"\npassword_hash = \"{hash}\"\n\n\
             [users.viewer]\npassword_hash = \"{hash}\"\n"
        ),
    )
    .unwrap();
}

/// Kim's signed `action` on ESE over the bus (a shelf: 30 minutes, for
/// a sensor cable): accepted, and what the agent said.
async fn kim_says(fx: &Fixture, action: Action) -> (bool, String) {
    let command = match action {
        Action::Shelve => {
            crate::spawned::signed_with(action, "ese", Some("30m"), Some("sensor cable"))
        }
        _ => crate::spawned::signed(action, "ese"),
    };
    crate::spawned::send(fx.client(), &command).await
}

/// The journal's command rows are `expected`: accepted, operator,
/// detail, source.
async fn commands_journaled(fx: &Fixture, expected: &[(bool, &str, &str, &str)]) {
    let rows = fx
        .history_rows("cellwatch/m01ps0004/history?since=1h;kind=command")
        .await;
    let commands: Vec<(bool, &str, &str, &str)> = rows
        .iter()
        .map(|r| {
            let f = &r["fields"];
            (
                f["accepted"].as_bool().unwrap(),
                f["operator"].as_str().unwrap(),
                f["detail"].as_str().unwrap(),
                f["source"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(commands, expected);
}

/// The SCADA's client, its key pair in `pki` (made if missing); it
/// trusts only the server certificates in `pki/trusted`.
pub(crate) fn scada(pki: &Path) -> Client {
    ClientBuilder::new()
        .application_name("scada")
        .application_uri("urn:cellwatch:test:scada")
        .product_uri("urn:cellwatch:test")
        .pki_dir(pki)
        .create_sample_keypair(true)
        .trust_server_certs(false)
        .session_retry_limit(0)
        .client()
        .unwrap()
}

/// A session to the alarm server at `url` as `identity`, the client's
/// certificate in `pki`.
pub(crate) async fn connect(
    url: &str,
    pki: &Path,
    identity: IdentityToken,
) -> std::sync::Arc<Session> {
    let mut client = scada(pki);
    let (session, event_loop) = client
        .connect_to_matching_endpoint(
            (
                url,
                SecurityPolicy::Basic256Sha256.to_str(),
                MessageSecurityMode::SignAndEncrypt,
            ),
            identity,
        )
        .await
        .unwrap();
    event_loop.spawn();
    tokio::time::timeout(Duration::from_secs(30), session.wait_for_connection())
        .await
        .unwrap();
    session
}

/// The value of ESE's state variable `name` (`ActiveState.Id`).
pub(crate) async fn state(session: &Session, ns: u16, name: &str) -> Variant {
    let read = session
        .read(
            &[ReadValueId {
                node_id: NodeId::new(ns, format!("m01ps0004.ese.{name}")),
                attribute_id: AttributeId::Value as u32,
                ..Default::default()
            }],
            TimestampsToReturn::Both,
            0.0,
        )
        .await
        .unwrap();
    read[0].value.clone().unwrap_or_default()
}

/// The agent over the simulated CNC with its alarm server: the users of
/// [`users_file`], ana an operator who may reset, not acknowledge.
async fn serving() -> Fixture {
    serving_with(|_| {}).await
}

/// [`serving`], with `more` said of the configuration too.
async fn serving_with(more: impl FnOnce(&mut cellwatch::config::CellConfig)) -> Fixture {
    Fixture::start_with(|c| {
        more(c);
        let dir = c.journal.path.parent().unwrap().to_path_buf();
        users_file(&dir.join("opcua-users.toml"));
        // Ana may reset, not acknowledge.
        let operators = c.operators_file.clone().unwrap();
        let mut text = std::fs::read_to_string(&operators).unwrap();
        text +=
            &cellwatch::operator::OperatorKey::generate("ana").operators_entry(&[Action::Reset]);
        std::fs::write(&operators, text).unwrap();
        c.alarm_server = Some(AlarmServerConfig {
            listen: "127.0.0.1:0".parse().unwrap(),
            pki_dir: dir.join("alarm-server-pki"),
            users_file: dir.join("opcua-users.toml"),
        });
    })
    .await
}
