//! The alarm server's secure channels admitted before any RSA decryption
//! (RUSTSEC-2023-0071; the patched async-opcua-server, vendor/README.md):
//! an OpenSecureChannel request with an untrusted sender certificate or a
//! policy the server does not offer is refused without being decrypted,
//! and an address that opens more than its share is refused while another
//! is served. The requests are written by hand on a socket bound to the
//! address they come from; their encrypted part is garbage, which a
//! decryption would have refused otherwise.

use std::net::{IpAddr, SocketAddr};
use std::path::Path;
use std::time::Instant;

use cellwatch::config::AlarmServerConfig;
use cellwatch::services::alarm_server::AlarmServer;
use cellwatch::sources::pki;
use opcua::client::IdentityToken;
use opcua::server::{SecureChannelCounts, SECURE_CHANNELS_PER_SECOND, SECURE_CHANNEL_BURST};
use opcua::types::StatusCode;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const BASIC256SHA256: &str = "http://opcfoundation.org/UA/SecurityPolicy#Basic256Sha256";
const BASIC128RSA15: &str = "http://opcfoundation.org/UA/SecurityPolicy#Basic128Rsa15";

/// An OPC UA string or byte string: its length, then its bytes.
fn counted(out: &mut Vec<u8>, bytes: &[u8]) {
    out.extend_from_slice(&(bytes.len() as i32).to_le_bytes());
    out.extend_from_slice(bytes);
}

/// A message of type `kind` (final chunk) with `body` after its header.
fn message(kind: &[u8; 3], body: &[u8]) -> Vec<u8> {
    let mut out = kind.to_vec();
    out.push(b'F');
    out.extend_from_slice(&((body.len() + 8) as u32).to_le_bytes());
    out.extend_from_slice(body);
    out
}

/// Reads one message: its type and body.
async fn read_message(stream: &mut tokio::net::TcpStream) -> ([u8; 3], Vec<u8>) {
    let mut header = [0u8; 8];
    stream.read_exact(&mut header).await.unwrap();
    let size = u32::from_le_bytes(header[4..8].try_into().unwrap()) as usize;
    let mut body = vec![0u8; size - 8];
    stream.read_exact(&mut body).await.unwrap();
    ([header[0], header[1], header[2]], body)
}

/// Opens a connection to `server` from `from`, says hello and asks for a
/// secure channel under `policy` with `certificate` as the sender's (its
/// encrypted part garbage): what the server answered (`Good` for a
/// secure channel, else the status of its error message).
async fn open_channel(
    from: IpAddr,
    server: SocketAddr,
    policy: &str,
    certificate: &[u8],
) -> StatusCode {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(from, 0)).unwrap();
    let mut stream = socket.connect(server).await.unwrap();
    let mut hello = Vec::new();
    for n in [0u32, 65_536, 65_536, 0, 0] {
        hello.extend_from_slice(&n.to_le_bytes());
    }
    counted(&mut hello, format!("opc.tcp://{server}/").as_bytes());
    stream.write_all(&message(b"HEL", &hello)).await.unwrap();
    let (kind, _) = read_message(&mut stream).await;
    assert_eq!(&kind, b"ACK");
    let mut open = 0u32.to_le_bytes().to_vec();
    counted(&mut open, policy.as_bytes());
    counted(&mut open, certificate);
    counted(&mut open, &[0x5a; 20]);
    open.extend_from_slice(&1u32.to_le_bytes());
    open.extend_from_slice(&1u32.to_le_bytes());
    open.extend_from_slice(&[0xa5; 256]);
    stream.write_all(&message(b"OPN", &open)).await.unwrap();
    match read_message(&mut stream).await {
        (kind, _) if &kind == b"OPN" => StatusCode::Good,
        (kind, body) if &kind == b"ERR" => {
            StatusCode::from(u32::from_le_bytes(body[0..4].try_into().unwrap()))
        }
        (kind, _) => panic!("unexpected {}", String::from_utf8_lossy(&kind)),
    }
}

/// The alarm server of cell m01ps0004 in `dir`, its users kim's and
/// others' ([`super::users_file`]).
async fn alarm_server(
    dir: &Path,
) -> (
    AlarmServer,
    tokio::sync::oneshot::Sender<()>,
    tokio::sync::mpsc::Receiver<cellwatch::step::SessionCommand>,
) {
    super::users_file(&dir.join("opcua-users.toml"));
    let config = AlarmServerConfig {
        listen: "127.0.0.1:0".parse().unwrap(),
        pki_dir: dir.join("alarm-server-pki"),
        users_file: dir.join("opcua-users.toml"),
    };
    let (acks, acks_rx) = tokio::sync::mpsc::channel(16);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = AlarmServer::start("m01ps0004", &config, acks, async move {
        let _ = stopped.await;
    })
    .await
    .unwrap();
    (server, stop, acks_rx)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn untrusted_and_unoffered_channels_are_refused_before_decryption_and_a_burst_is_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let (server, stop, _acks) = alarm_server(dir.path()).await;
    let addr = server.addr();
    let server_pki = dir.path().join("alarm-server-pki");
    // A SCADA the server trusts, and a stranger it does not.
    let (scada_pki, stranger_pki) = (
        dir.path().join("scada-pki"),
        dir.path().join("stranger-pki"),
    );
    drop(super::scada(&scada_pki));
    drop(super::scada(&stranger_pki));
    pki::trust(&pki::own_cert(&scada_pki), &server_pki).unwrap();
    pki::trust(&pki::own_cert(&server_pki), &scada_pki).unwrap();
    let stranger = std::fs::read(pki::own_cert(&stranger_pki)).unwrap();
    let trusted = std::fs::read(pki::own_cert(&scada_pki)).unwrap();

    // A policy no endpoint offers (Basic128Rsa15's PKCS#1 v1.5), even with
    // a trusted certificate: refused, nothing decrypted.
    let policy = open_channel("127.0.0.3".parse().unwrap(), addr, BASIC128RSA15, &trusted).await;
    assert_eq!(policy, StatusCode::BadSecurityPolicyRejected);

    // From 127.0.0.2, the stranger asks again and again: its certificate
    // refused at once (left in rejected/ for review, and refused as such
    // after), then the address refused as too busy.
    const ASKED: usize = 40;
    let began = Instant::now();
    let mut answers = Vec::new();
    for _ in 0..ASKED {
        answers.push(
            open_channel(
                "127.0.0.2".parse().unwrap(),
                addr,
                BASIC256SHA256,
                &stranger,
            )
            .await,
        );
    }
    let took = began.elapsed().as_secs_f64();
    let untrusted = answers
        .iter()
        .filter(|s| {
            matches!(
                **s,
                StatusCode::BadCertificateUntrusted | StatusCode::BadSecurityChecksFailed
            )
        })
        .count();
    let busy = answers
        .iter()
        .filter(|s| **s == StatusCode::BadTcpServerTooBusy)
        .count();
    assert_eq!(untrusted + busy, ASKED, "{answers:?}");
    assert_eq!(
        answers[0],
        StatusCode::BadCertificateUntrusted,
        "{answers:?}"
    );
    // At most the burst and what the address earned while it asked.
    let share = (SECURE_CHANNEL_BURST + SECURE_CHANNELS_PER_SECOND * took).floor() as usize + 1;
    assert!(
        untrusted <= share,
        "{untrusted} admitted of {ASKED} in {took:.1} s: {answers:?}"
    );
    assert!(
        busy >= ASKED.saturating_sub(share),
        "{busy} refused as busy: {answers:?}"
    );
    assert!(std::fs::read_dir(server_pki.join("rejected"))
        .unwrap()
        .any(|f| std::fs::read(f.unwrap().path()).unwrap() == stranger));
    assert_eq!(
        server.secure_channels(),
        SecureChannelCounts {
            decrypted: 0,
            refused_busy: busy as u64,
            refused_policy: 1,
            refused_untrusted: untrusted as u64,
        }
    );

    // Meanwhile the trusted SCADA, from 127.0.0.1, is served.
    let session = super::connect(
        &format!("opc.tcp://{addr}/"),
        &scada_pki,
        IdentityToken::Anonymous,
    )
    .await;
    assert!(server.secure_channels().decrypted >= 1);
    let _ = session.disconnect().await;
    let _ = stop.send(());
    server.task().await.unwrap();
}
