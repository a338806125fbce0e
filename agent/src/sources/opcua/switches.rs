//! The charts' force and stop switches on an OPC UA PLC: pulses (on, read back, off, read
//! back), and every switch written off on a new session and at shutdown.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use opcua::client::Session;
use opcua::types::{NodeId, ReadValueId, TimestampsToReturn, Variant};

use tokio::sync::mpsc;

use super::client::namespace_array;
use super::requests::Requests;
use super::OpcUaError;
use crate::sources::opcua::node::TagNode;

use crate::sources::WriteRequest;

/// The writes a source takes: pulses of its switches only.
pub(super) struct Writes {
    pub(super) rx: Option<mpsc::Receiver<WriteRequest>>,
    /// The switches, each with its name and address.
    pub(super) switches: BTreeMap<usize, String>,
}

impl Writes {
    pub(super) async fn next(&mut self) -> Option<WriteRequest> {
        match self.rx.as_mut() {
            Some(rx) => match rx.recv().await {
                Some(w) => Some(w),
                None => {
                    self.rx = None;
                    std::future::pending().await
                }
            },
            None => std::future::pending().await,
        }
    }
}

/// Pulses a switch on the PLC: on, read back, held, off, read back. Once
/// it was written on, it is always written off again, whatever failed.
pub(super) async fn pulse(
    session: Arc<Session>,
    node: TagNode,
    name: String,
    held: Duration,
    requests: Requests,
) -> Result<String, OpcUaError> {
    let requests = &requests;
    let namespaces =
        namespace_array(&session, requests)
            .await
            .map_err(|e| OpcUaError::SwitchNamespaces {
                name: name.clone(),
                source: Box::new(e),
            })?;
    let id = node
        .resolve(&namespaces)
        .ok_or_else(|| OpcUaError::NoNamespace { name: name.clone() })?;
    set_switch(&session, &id, &name, true, requests).await?;
    let on = read_back(&session, &id, &name, true, requests).await;
    if on.is_ok() {
        tokio::time::sleep(held).await;
    }
    let off = set_switch(&session, &id, &name, false, requests).await;
    let off = match off {
        Ok(()) => read_back(&session, &id, &name, false, requests).await,
        Err(e) => Err(e),
    };
    on?;
    off?;
    Ok(format!(
        "{name} on for {} ms, read back on, then off",
        held.as_millis()
    ))
}

pub(super) async fn set_switch(
    session: &Session,
    id: &NodeId,
    name: &str,
    on: bool,
    requests: &Requests,
) -> Result<(), OpcUaError> {
    let value = opcua::types::WriteValue {
        node_id: id.clone(),
        attribute_id: opcua::types::AttributeId::Value as u32,
        index_range: opcua::types::NumericRange::None,
        value: opcua::types::DataValue::value_only(on),
    };
    let status = session.write(&[value]).await;
    requests.answered("Write", &status);
    let status = status.map_err(|source| OpcUaError::SwitchWrite {
        name: name.to_string(),
        on,
        source,
    })?;
    match status.first() {
        Some(s) if s.is_good() => Ok(()),
        Some(s) => Err(OpcUaError::SwitchRefused {
            name: name.to_string(),
            on,
            status: *s,
        }),
        None => Err(OpcUaError::SwitchNoAnswer {
            name: name.to_string(),
        }),
    }
}

/// Writes off every switch that reads anything but off (their safe
/// state), each read back; how many were written, or what failed.
pub(super) async fn switches_off(
    session: &Session,
    switches: &[(String, TagNode)],
    requests: &Requests,
) -> Result<usize, OpcUaError> {
    if switches.is_empty() {
        return Ok(0);
    }
    let namespaces = namespace_array(session, requests)
        .await
        .map_err(|e| OpcUaError::Namespaces(Box::new(e)))?;
    let mut written = 0;
    let mut failed = Vec::new();
    for (name, node) in switches {
        let Some(id) = node.resolve(&namespaces) else {
            failed.push(OpcUaError::NoNamespace { name: name.clone() });
            continue;
        };
        let read = session
            .read(
                &[ReadValueId::from(id.clone())],
                TimestampsToReturn::Neither,
                0.0,
            )
            .await;
        requests.answered("Read", &read);
        if let Ok(values) = &read {
            if matches!(
                values.first().and_then(|v| v.value.as_ref()),
                Some(Variant::Boolean(false))
            ) {
                continue;
            }
        }
        match set_switch(session, &id, name, false, requests).await {
            Ok(()) => match read_back(session, &id, name, false, requests).await {
                Ok(()) => written += 1,
                Err(e) => failed.push(e),
            },
            Err(e) => failed.push(e),
        }
    }
    if failed.is_empty() {
        Ok(written)
    } else {
        Err(OpcUaError::Switches(failed))
    }
}

/// [`switches_off`], its outcome logged: `when` says why.
pub(super) async fn reset_switches(
    session: &Session,
    switches: &[(String, TagNode)],
    when: &str,
    requests: &Requests,
) {
    match switches_off(session, switches, requests).await {
        Ok(0) => tracing::debug!(when, "chart switches all off"),
        Ok(n) => tracing::warn!(switches = n, when, "chart switches found on, written off"),
        Err(e) => tracing::error!(error = %e, when, "chart switches not written off"),
    }
}

/// How long a written switch may take to read back as written.
pub(super) const READ_BACK: Duration = Duration::from_secs(2);

pub(super) async fn read_back(
    session: &Session,
    id: &NodeId,
    name: &str,
    on: bool,
    requests: &Requests,
) -> Result<(), OpcUaError> {
    let until = tokio::time::Instant::now() + READ_BACK;
    loop {
        let read = session
            .read(
                &[ReadValueId::from(id.clone())],
                TimestampsToReturn::Neither,
                0.0,
            )
            .await;
        requests.answered("Read", &read);
        let read = read.map_err(|source| OpcUaError::ReadBack {
            name: name.to_string(),
            source,
        })?;
        let last = match read.first().and_then(|v| v.value.clone()) {
            Some(Variant::Boolean(b)) if b == on => return Ok(()),
            other => other,
        };
        if tokio::time::Instant::now() >= until {
            return Err(OpcUaError::ReadBackDiffers {
                name: name.to_string(),
                on,
                read: last,
                within: READ_BACK,
            });
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
