//! `cellwatch-bare-client`: the peer benchmark's bare-client reference.
//!
//! An open62541 client (the C library, built by `open62541-sys` from its
//! own sources) that subscribes to the load server exactly as the agent
//! does — the same nodes, publishing and sampling intervals, queue size,
//! keep-alive and lifetime counts, notifications per publish, source
//! timestamps only, a data-change filter on status and value — and does
//! nothing with a notification but count it: every byte is decoded by
//! open62541, the callback adds one. What it costs per change is the floor
//! an OPC UA client pays before doing anything with a change.
//!
//! It speaks `bench/baseline.py`'s protocol with `cellwatch-bench`, one JSON
//! object per line on stdout:
//!   {"ready": true, "received": n}      once every item is created
//! and, on each line read from stdin ("count"; "quit" ends it):
//!   {"received": n, "alarms": [], "cpu": s}   (s: to the µs)
//! (`cpu`: its own user + system time from getrusage). On "quit" it prints
//! the count and its CPU time a last time, with `"final": true`, and exits.
//!
//! `cellwatch-bare-client make-cert CERT KEY URI` makes a self-signed
//! certificate and its private key (DER, RSA 2048) for application URI URI
//! with open62541's own `UA_CreateCertificate`, for the secure rows.
//!
//! Its library's log (warnings and worse) goes to stderr.

#![allow(non_upper_case_globals)]

use std::ffi::{c_void, CString};
use std::io::{BufRead, Write};
use std::os::fd::FromRawFd;
use std::ptr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use open62541_sys::*;

/// Notifications counted (one writer: the client's loop).
static RECEIVED: AtomicU64 = AtomicU64::new(0);
/// Set by "quit" on stdin.
static QUIT: AtomicBool = AtomicBool::new(false);

/// Numeric id of limit switch `k` in the load server's namespace
/// (`bench/src/load.rs`); noise tags are 1..=N.
const SWITCH_BASE: u32 = 2_000_000;
const SWITCHES: u32 = 10;
/// The agent's most monitored items per CreateMonitoredItems call
/// (`MAX_ITEMS_PER_CALL`; the load server allows as many).
const ITEMS_PER_CALL: usize = 10_000;
/// The agent's `KEEP_ALIVE_COUNT`.
const KEEP_ALIVE_COUNT: u32 = 10;
const NAMESPACE: &str = "urn:cellwatch:bench:load";
const POLICY_NONE: &str = "http://opcfoundation.org/UA/SecurityPolicy#None";
const POLICY_BASIC256SHA256: &str = "http://opcfoundation.org/UA/SecurityPolicy#Basic256Sha256";

/// The data-change callback: counts, nothing more.
unsafe extern "C" fn on_change(
    _client: *mut UA_Client,
    _sub_id: UA_UInt32,
    _sub_context: *mut c_void,
    _mon_id: UA_UInt32,
    _mon_context: *mut c_void,
    _value: *mut UA_DataValue,
) {
    // A single writer: no read-modify-write needed.
    RECEIVED.store(RECEIVED.load(Ordering::Relaxed) + 1, Ordering::Relaxed);
}

/// This process's user + system CPU seconds (getrusage).
fn cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 / 1e6;
    t(u.ru_utime) + t(u.ru_stime)
}

/// How the client is to connect.
struct Args {
    endpoint: String,
    noise: u32,
    publishing_ms: f64,
    sampling_ms: f64,
    queue_size: u32,
    max_notifications: u32,
    lifetime_count: u32,
    /// Certificate, key and the server's certificate (DER files): secure.
    secure: Option<(String, String, String)>,
    application_uri: String,
}

fn usage() -> ! {
    eprintln!(
        "usage: cellwatch-bare-client --endpoint URL --noise N [--publishing-ms 100] \
         [--sampling-ms 0] [--queue-size 400] [--max-notifications 1000] [--lifetime-count 600] \
         [--cert DER --key DER --server-cert DER [--application-uri URI]]\n\
         \x20      cellwatch-bare-client make-cert CERT KEY URI"
    );
    std::process::exit(2)
}

fn parse_args() -> Args {
    let mut a = Args {
        endpoint: String::new(),
        noise: 0,
        publishing_ms: 100.0,
        sampling_ms: 0.0,
        queue_size: 400,
        max_notifications: 1000,
        lifetime_count: 600,
        secure: None,
        application_uri: "urn:cellwatch:bench:bare-client".into(),
    };
    let (mut cert, mut key, mut server) = (None, None, None);
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().unwrap_or_else(|| usage());
        let num = |v: &str| v.parse::<f64>().unwrap_or_else(|_| usage());
        match flag.as_str() {
            "--endpoint" => a.endpoint = value,
            "--noise" => a.noise = num(&value) as u32,
            "--publishing-ms" => a.publishing_ms = num(&value),
            "--sampling-ms" => a.sampling_ms = num(&value),
            "--queue-size" => a.queue_size = num(&value) as u32,
            "--max-notifications" => a.max_notifications = num(&value) as u32,
            "--lifetime-count" => a.lifetime_count = num(&value) as u32,
            "--cert" => cert = Some(value),
            "--key" => key = Some(value),
            "--server-cert" => server = Some(value),
            "--application-uri" => a.application_uri = value,
            _ => usage(),
        }
    }
    if a.endpoint.is_empty() {
        usage();
    }
    a.secure = match (cert, key, server) {
        (Some(c), Some(k), Some(s)) => Some((c, k, s)),
        (None, None, None) => None,
        _ => usage(),
    };
    a
}

/// A UA_String owning a copy of `s` (UA_String_clear frees it).
fn ua_string(s: &str) -> UA_String {
    let c = CString::new(s).unwrap_or_default();
    // SAFETY: copies the NUL-terminated string.
    unsafe { UA_String_fromChars(c.as_ptr()) }
}

/// A UA_ByteString owning a copy of `bytes`.
fn ua_bytes(bytes: &[u8]) -> UA_ByteString {
    let mut b: UA_ByteString = unsafe { std::mem::zeroed() };
    // SAFETY: allocates `len` bytes, then fills them.
    unsafe {
        if UA_ByteString_allocBuffer(&mut b, bytes.len()) == UA_STATUSCODE_GOOD {
            ptr::copy_nonoverlapping(bytes.as_ptr(), b.data, bytes.len());
        }
    }
    b
}

fn read(path: &str) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| {
        eprintln!("cellwatch-bare-client: cannot read {path}: {e}");
        std::process::exit(1)
    })
}

fn fail(what: &str, status: UA_StatusCode) -> ! {
    // SAFETY: UA_StatusCode_name returns a static string.
    let name = unsafe { std::ffi::CStr::from_ptr(UA_StatusCode_name(status)) };
    eprintln!("cellwatch-bare-client: {what}: {}", name.to_string_lossy());
    std::process::exit(1)
}

/// `make-cert CERT KEY URI`.
fn make_cert(cert: &str, key: &str, uri: &str) {
    let subject = [
        ua_string("C=DE"),
        ua_string("O=cellwatch bench"),
        ua_string("CN=cellwatch bare client@localhost"),
    ];
    let alt = [ua_string("DNS:localhost"), ua_string(&format!("URI:{uri}"))];
    let mut out_key: UA_ByteString = unsafe { std::mem::zeroed() };
    let mut out_cert: UA_ByteString = unsafe { std::mem::zeroed() };
    // SAFETY: the arrays outlive the call; the outputs are allocated by it.
    let status = unsafe {
        let logger = UA_Log_Stdout_new(UA_LogLevel::UA_LOGLEVEL_WARNING);
        let mut params: UA_KeyValueMap = std::mem::zeroed();
        let mut bits: UA_UInt16 = 2048;
        let name = UA_QualifiedName {
            namespaceIndex: 0,
            name: ua_string("key-size-bits"),
        };
        UA_KeyValueMap_setScalar(
            &mut params,
            name,
            &mut bits as *mut _ as *mut c_void,
            &UA_TYPES[UA_TYPES_UINT16 as usize],
        );
        UA_CreateCertificate(
            logger,
            subject.as_ptr(),
            subject.len(),
            alt.as_ptr(),
            alt.len(),
            UA_CertificateFormat::UA_CERTIFICATEFORMAT_DER,
            &mut params,
            &mut out_key,
            &mut out_cert,
        )
    };
    if status != UA_STATUSCODE_GOOD {
        fail("cannot create a certificate", status);
    }
    // SAFETY: both were filled by UA_CreateCertificate.
    let bytes = |b: &UA_ByteString| unsafe { std::slice::from_raw_parts(b.data, b.length) };
    for (path, b) in [(cert, &out_cert), (key, &out_key)] {
        if let Err(e) = std::fs::write(path, bytes(b)) {
            eprintln!("cellwatch-bare-client: cannot write {path}: {e}");
            std::process::exit(1);
        }
    }
}

fn main() {
    let argv: Vec<String> = std::env::args().collect();
    if argv.get(1).map(String::as_str) == Some("make-cert") {
        match &argv[2..] {
            [cert, key, uri] => make_cert(cert, key, uri),
            _ => usage(),
        }
        return;
    }
    let args = parse_args();

    // The protocol keeps stdout; the library's log goes to stderr.
    // SAFETY: plain file descriptor duplication at start-up.
    let out = unsafe {
        let fd = libc::dup(1);
        libc::dup2(2, 1);
        std::fs::File::from_raw_fd(fd)
    };
    let out = Arc::new(Mutex::new(std::io::LineWriter::new(out)));
    let say = {
        let out = out.clone();
        move |line: String| {
            if let Ok(mut o) = out.lock() {
                let _ = writeln!(o, "{line}");
            }
        }
    };

    // SAFETY: below, the open62541 C API used as its documentation says:
    // one thread (this one) drives the client.
    unsafe {
        let mut config: UA_ClientConfig = std::mem::zeroed();
        config.logging = UA_Log_Stdout_new(UA_LogLevel::UA_LOGLEVEL_WARNING);
        let (mode, policy) = match &args.secure {
            None => {
                let s = UA_ClientConfig_setDefault(&mut config);
                if s != UA_STATUSCODE_GOOD {
                    fail("cannot configure the client", s);
                }
                (
                    UA_MessageSecurityMode::UA_MESSAGESECURITYMODE_NONE,
                    POLICY_NONE,
                )
            }
            Some((cert, key, server)) => {
                let trust = [ua_bytes(&read(server))];
                let s = UA_ClientConfig_setDefaultEncryption(
                    &mut config,
                    ua_bytes(&read(cert)),
                    ua_bytes(&read(key)),
                    trust.as_ptr(),
                    trust.len(),
                    ptr::null(),
                    0,
                );
                if s != UA_STATUSCODE_GOOD {
                    fail("cannot configure the client's encryption", s);
                }
                UA_String_clear(&mut config.clientDescription.applicationUri);
                config.clientDescription.applicationUri = ua_string(&args.application_uri);
                (
                    UA_MessageSecurityMode::UA_MESSAGESECURITYMODE_SIGNANDENCRYPT,
                    POLICY_BASIC256SHA256,
                )
            }
        };
        config.securityMode = mode;
        UA_String_clear(&mut config.securityPolicyUri);
        config.securityPolicyUri = ua_string(policy);
        // Creating 10,000 items in one call on a loaded machine.
        config.timeout = 60_000;
        let client = UA_Client_newWithConfig(&config);
        if client.is_null() {
            eprintln!("cellwatch-bare-client: cannot create the client");
            std::process::exit(1);
        }
        let endpoint = CString::new(args.endpoint.clone()).unwrap_or_default();
        let s = UA_Client_connect(client, endpoint.as_ptr());
        if s != UA_STATUSCODE_GOOD {
            fail(&format!("cannot connect to {}", args.endpoint), s);
        }
        let mut uri = ua_string(NAMESPACE);
        let mut ns: UA_UInt16 = 0;
        let s = UA_Client_NamespaceGetIndex(client, &mut uri, &mut ns);
        if s != UA_STATUSCODE_GOOD {
            fail("cannot find the load namespace", s);
        }

        // The subscription: as the agent's (subscription.rs).
        let mut request = UA_CreateSubscriptionRequest_default();
        request.requestedPublishingInterval = args.publishing_ms;
        request.requestedLifetimeCount = args.lifetime_count;
        request.requestedMaxKeepAliveCount = KEEP_ALIVE_COUNT;
        request.maxNotificationsPerPublish = args.max_notifications;
        request.publishingEnabled = true;
        request.priority = 0;
        let mut response =
            UA_Client_Subscriptions_create(client, request, ptr::null_mut(), None, None);
        if response.responseHeader.serviceResult != UA_STATUSCODE_GOOD {
            fail(
                "cannot create the subscription",
                response.responseHeader.serviceResult,
            );
        }
        let sub = response.subscriptionId;
        UA_CreateSubscriptionResponse_clear(&mut response);

        // Its items: the limit switches' and the noise tags' nodes, each
        // sampled as fast as the server may (0), queue as the agent's, the
        // oldest dropped, reported on status or value change.
        let mut filter: UA_DataChangeFilter = std::mem::zeroed();
        filter.trigger = UA_DataChangeTrigger::UA_DATACHANGETRIGGER_STATUSVALUE;
        filter.deadbandType = 0;
        filter.deadbandValue = 0.0;
        let ids: Vec<u32> = (SWITCH_BASE..SWITCH_BASE + SWITCHES)
            .chain(1..=args.noise)
            .collect();
        let mut created = 0usize;
        for chunk in ids.chunks(ITEMS_PER_CALL) {
            let mut items: Vec<UA_MonitoredItemCreateRequest> = chunk
                .iter()
                .map(|&id| {
                    let mut item = UA_MonitoredItemCreateRequest_default(UA_NODEID_NUMERIC(ns, id));
                    item.requestedParameters.samplingInterval = args.sampling_ms;
                    item.requestedParameters.queueSize = args.queue_size;
                    item.requestedParameters.discardOldest = true;
                    UA_ExtensionObject_setValueNoDelete(
                        &mut item.requestedParameters.filter,
                        &mut filter as *mut _ as *mut c_void,
                        &UA_TYPES[UA_TYPES_DATACHANGEFILTER as usize],
                    );
                    item
                })
                .collect();
            let mut contexts: Vec<*mut c_void> = vec![ptr::null_mut(); items.len()];
            let mut callbacks: Vec<UA_Client_DataChangeNotificationCallback> =
                vec![Some(on_change); items.len()];
            let mut deletes: Vec<UA_Client_DeleteMonitoredItemCallback> = vec![None; items.len()];
            let mut request: UA_CreateMonitoredItemsRequest = std::mem::zeroed();
            request.subscriptionId = sub;
            request.timestampsToReturn = UA_TimestampsToReturn::UA_TIMESTAMPSTORETURN_SOURCE;
            request.itemsToCreate = items.as_mut_ptr();
            request.itemsToCreateSize = items.len();
            let mut response = UA_Client_MonitoredItems_createDataChanges(
                client,
                request,
                contexts.as_mut_ptr(),
                callbacks.as_mut_ptr(),
                deletes.as_mut_ptr(),
            );
            if response.responseHeader.serviceResult != UA_STATUSCODE_GOOD {
                fail(
                    "cannot create monitored items",
                    response.responseHeader.serviceResult,
                );
            }
            let results = std::slice::from_raw_parts(response.results, response.resultsSize);
            created += results
                .iter()
                .filter(|r| r.statusCode == UA_STATUSCODE_GOOD)
                .count();
            UA_CreateMonitoredItemsResponse_clear(&mut response);
        }
        if created != ids.len() {
            eprintln!(
                "cellwatch-bare-client: {} of {} monitored items refused",
                ids.len() - created,
                ids.len()
            );
        }
        say(format!(
            "{{\"ready\": true, \"received\": {}}}",
            RECEIVED.load(Ordering::Relaxed)
        ));

        let answer = say.clone();
        std::thread::spawn(move || {
            for line in std::io::stdin().lock().lines().map_while(Result::ok) {
                if line.trim() == "quit" {
                    break;
                }
                answer(format!(
                    "{{\"received\": {}, \"alarms\": [], \"cpu\": {:.6}}}",
                    RECEIVED.load(Ordering::Relaxed),
                    cpu_seconds()
                ));
            }
            QUIT.store(true, Ordering::Relaxed);
        });

        while !QUIT.load(Ordering::Relaxed) {
            let s = UA_Client_run_iterate(client, 100);
            if s != UA_STATUSCODE_GOOD {
                fail("the connection failed", s);
            }
        }
        say(format!(
            "{{\"received\": {}, \"alarms\": [], \"cpu\": {:.6}, \"final\": true}}",
            RECEIVED.load(Ordering::Relaxed),
            cpu_seconds()
        ));
        UA_Client_disconnect(client);
        UA_Client_delete(client);
    }
}
