//! The console with a certificate (`http.tls`): HTTPS only, said to browsers
//! (HSTS).

use crate::util::{bus_pki, bus_tls};

use super::plant_with;

/// With `http.tls`, the console serves HTTPS only, with the certificate
/// given (here from the plant CA), and says so to browsers (HSTS).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_certificate_the_console_serves_https_only() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    use tokio_rustls::rustls;
    use tokio_rustls::rustls::pki_types::pem::PemObject;
    let d = tempfile::tempdir().unwrap();
    bus_pki(d.path(), &["console"]);
    let tls = bus_tls(d.path(), "console");
    let p = plant_with(
        d.path(),
        &format!("tls = {{ cert = {:?}, key = {:?} }}", tls.cert, tls.key),
        "",
    )
    .await;
    assert!(p.url.starts_with("https://127.0.0.1:"), "{}", p.url);
    let addr = p.url.trim_start_matches("https://").trim_end_matches('/');
    let mut roots = rustls::RootCertStore::empty();
    roots
        .add(rustls::pki_types::CertificateDer::from_pem_file(&tls.ca).unwrap())
        .unwrap();
    let config = rustls::ClientConfig::builder_with_provider(std::sync::Arc::new(
        rustls::crypto::ring::default_provider(),
    ))
    .with_safe_default_protocol_versions()
    .unwrap()
    .with_root_certificates(roots)
    .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut stream = connector
        .connect("127.0.0.1".try_into().unwrap(), tcp)
        .await
        .expect("the console's certificate, checked against the plant CA");
    stream
        .write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut text = Vec::new();
    let _ = stream.read_to_end(&mut text).await;
    let text = String::from_utf8_lossy(&text);
    assert!(text.starts_with("HTTP/1.1 200 OK"), "{text}");
    assert!(
        text.contains("strict-transport-security: max-age=31536000"),
        "{text}"
    );
    assert!(text.contains("<title>cellwatch console</title>"), "{text}");
    // Plain HTTP on the same port gets no page.
    let mut plain = tokio::net::TcpStream::connect(addr).await.unwrap();
    plain
        .write_all(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .await
        .unwrap();
    let mut got = Vec::new();
    let _ = plain.read_to_end(&mut got).await;
    assert!(!String::from_utf8_lossy(&got).contains("cellwatch console"));
}
