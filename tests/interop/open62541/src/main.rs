//! An independent OPC UA server (open62541, the C stack, through its Rust
//! bindings) for cellwatch's interoperability tests: Basic256Sha256 +
//! SignAndEncrypt (beside open62541's other policies, None among them: the
//! endpoints are asked for over None), client certificates all accepted, Double tags under an object Plc in
//! namespace URI, node ids s=NAME.
//!
//!   cellwatch-open62541-server PORT PKI_DIR URI NAME=VALUE...
//!   cellwatch-open62541-server certificate PKI_DIR
//!
//! Listens on 127.0.0.1:PORT with the certificate and key it keeps in
//! PKI_DIR (made on the first start, the same after a restart); prints
//! "ready <own certificate, DER>" once a connection is accepted, "expired
//! subscription" when one outlives its lifetime without publish requests
//! (a client cut off: the server drops it). `certificate` only makes the
//! certificate and key (a moment's work in a release build, seconds in a
//! debug one: a test copies one pair into every server's PKI_DIR).
//! Standard input:
//!   set NAME VALUE        write a tag (a Double)
//!   recreate NAME VALUE   delete the tag's node and add it again, same node
//!                         id, holding VALUE, telling nobody (open62541's
//!                         items sample the node id: bad while it is gone,
//!                         then the new node's value)
//!   delete NAME           delete the tag's node (its items' samples say
//!                         BadNodeIdUnknown); add NAME VALUE adds it (back)
//!   quit
//! Each command done is told as "done <the command>".

use std::io::BufRead;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use open62541::{ua, Attributes, DataType, ObjectNode, Server, ServerBuilder, VariableNode};

/// Standard output, and the server's own log on standard error.
struct Said;

impl log::Log for Said {
    fn enabled(&self, metadata: &log::Metadata<'_>) -> bool {
        metadata.level() <= log::Level::Info
    }

    fn log(&self, record: &log::Record<'_>) {
        let text = record.args().to_string();
        if text.contains("End of subscription lifetime") {
            println!("expired subscription");
        }
        eprintln!("{} {text}", record.level());
    }

    fn flush(&self) {}
}

/// The server's certificate and key (DER), made once and kept in `pki`.
fn own_certificate(pki: &std::path::Path) -> (PathBuf, Vec<u8>, Vec<u8>) {
    let (der, key) = (pki.join("server.der"), pki.join("server-key.der"));
    if let (Ok(c), Ok(k)) = (std::fs::read(&der), std::fs::read(&key)) {
        return (der, c, k);
    }
    let strings = |s: &[&str]| {
        let all: Vec<ua::String> = s.iter().map(|s| ua::String::new(s).unwrap()).collect();
        ua::Array::from_slice(&all)
    };
    let (cert, private) = open62541::create_certificate(
        &strings(&["C=DE", "O=cellwatch", "CN=cellwatch interop open62541"]),
        // The application URI open62541 describes itself with first
        // (clients skip the first alternative name), then the host names a
        // client may reach it by: given last first, as Mbed TLS writes
        // them in the reverse order.
        &strings(&[
            "IP:127.0.0.1",
            "DNS:localhost",
            "URI:urn:open62541.unconfigured.application",
        ]),
        &ua::CertificateFormat::DER,
        // 2048 bits, not open62541's 4096: made in a moment.
        Some(&ua::KeyValueMap::from_slice(&[(
            &ua::QualifiedName::new(0, "key-size-bits"),
            &ua::Variant::scalar(ua::UInt16::new(2048)),
        )])),
    )
    .expect("certificate made");
    std::fs::create_dir_all(pki).unwrap();
    std::fs::write(&der, cert.as_bytes()).unwrap();
    std::fs::write(&key, private.as_bytes()).unwrap();
    (der, cert.as_bytes().to_vec(), private.as_bytes().to_vec())
}

/// A Double variable `name` under `plc`, holding `value`, readable and
/// writable.
fn add(server: &Server, plc: &ua::NodeId, ns: u16, name: &str, value: f64) {
    let mut attributes = ua::VariableAttributes::default()
        .with_data_type(&ua::NodeId::ns0(11))
        .with_value_rank(-1)
        .with_access_level(
            &ua::AccessLevelType::NONE
                .with_current_read(true)
                .with_current_write(true),
        )
        .with_display_name(&ua::LocalizedText::new("", name).unwrap());
    // SAFETY: the attributes' own value, replaced (the old one freed).
    ua::Variant::scalar(ua::Double::new(value))
        .move_into_raw(unsafe { &mut attributes.as_mut().value });
    server
        .add_variable_node(VariableNode {
            requested_new_node_id: Some(ua::NodeId::string(ns, name)),
            parent_node_id: plc.clone(),
            reference_type_id: ua::NodeId::ns0(47),
            browse_name: ua::QualifiedName::new(ns, name),
            type_definition: ua::NodeId::ns0(63),
            attributes,
        })
        .expect("variable added");
}

fn main() {
    log::set_logger(&Said).unwrap();
    log::set_max_level(log::LevelFilter::Info);
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let [command, pki] = &args[..] {
        if command == "certificate" {
            own_certificate(std::path::Path::new(pki));
            return;
        }
    }
    let [port, pki, uri, tags @ ..] = &args[..] else {
        eprintln!("usage: cellwatch-open62541-server PORT PKI_DIR URI NAME=VALUE...");
        std::process::exit(2);
    };
    let port: u16 = port.parse().expect("a port");
    let (der, cert, key) = own_certificate(std::path::Path::new(pki));
    // The secure policies and None: a client asks for the endpoints over
    // None (the bindings have no switch for None only for that), then
    // opens its session over Basic256Sha256 + SignAndEncrypt.
    let (cert, key) = (
        open62541::Certificate::from_bytes(&cert),
        open62541::PrivateKey::from_bytes(&key),
    );
    let (server, runner) = ServerBuilder::default_with_security_policies(port, &cert, &key)
        .expect("server configured")
        .server_urls(&[&format!("opc.tcp://127.0.0.1:{port}")])
        .accept_all()
        .build();
    let ns = server.add_namespace(uri);
    let plc = server
        .add_object_node(ObjectNode {
            requested_new_node_id: Some(ua::NodeId::string(ns, "Plc")),
            parent_node_id: ua::NodeId::ns0(85),
            reference_type_id: ua::NodeId::ns0(35),
            browse_name: ua::QualifiedName::new(ns, "Plc"),
            type_definition: ua::NodeId::ns0(58),
            attributes: ua::ObjectAttributes::default(),
        })
        .expect("Plc added");
    let mut names = Vec::new();
    for tag in tags {
        let (name, value) = tag.split_once('=').expect("NAME=VALUE");
        add(&server, &plc, ns, name, value.parse().expect("a number"));
        names.push(name.to_string());
    }
    let stop = Arc::new(AtomicBool::new(false));
    let running = std::thread::spawn({
        let stop = stop.clone();
        move || runner.run_until_cancelled(|| stop.load(Ordering::SeqCst))
    });
    // Listening once a connection is accepted.
    let deadline = Instant::now() + Duration::from_secs(60);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "not listening on {port}");
        std::thread::sleep(Duration::from_millis(20));
    }
    println!("ready {}", der.display());
    for line in std::io::stdin().lock().lines() {
        let Ok(line) = line else { break };
        let words: Vec<&str> = line.split_whitespace().collect();
        match words[..] {
            ["set", name, value] if names.iter().any(|n| n == name) => {
                let value = ua::Variant::scalar(ua::Double::new(value.parse().unwrap()));
                server
                    .write_value(&ua::NodeId::string(ns, name), &value)
                    .expect("written");
            }
            ["recreate", name, value] if names.iter().any(|n| n == name) => {
                server
                    .delete_node(&ua::NodeId::string(ns, name))
                    .expect("deleted");
                add(&server, &plc, ns, name, value.parse().unwrap());
            }
            ["delete", name] if names.iter().any(|n| n == name) => {
                server
                    .delete_node(&ua::NodeId::string(ns, name))
                    .expect("deleted");
                names.retain(|n| n != name);
            }
            ["add", name, value] if !names.iter().any(|n| n == name) => {
                add(&server, &plc, ns, name, value.parse().unwrap());
                names.push(name.to_string());
            }
            ["quit"] => break,
            _ => {}
        }
        println!("done {}", line.trim());
    }
    stop.store(true, Ordering::SeqCst);
    let _ = running.join();
}
