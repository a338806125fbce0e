//! The bus: everything cellwatch says on Zenoh, and how, in one place.
//!
//! - [`keys`]: the key layout under a cell's prefix (`cellwatch/<cell>` by
//!   default): `alarms/<id>`, `state`, `history`, `snapshot`, `command`,
//!   `agent/<zenoh id>`. No other module spells a key.
//! - [`envelope`]: the signed envelope (`cellwatch.signed.v1`) every alarm,
//!   state and answer is sealed in, the agent's signing key and the plant
//!   trust file clients open envelopes with.
//! - `session`: a session's configuration (TLS only, with the plant CA,
//!   whatever a Zenoh file says), the agent's access control (it routes for
//!   nobody), and opening a session for an agent or a client.
//! - [`certs`]: the plant CA and the certificates it issues.
//!
//! Who uses it: the Zenoh sink (`crate::sinks::zenoh`) publishes, the
//! services (`crate::services`) answer queries, the CLI's bus client asks
//! and listens. The bus itself reads only the configuration. Scaling to a
//! plant is Zenoh's job: agents run in client mode against `zenohd`
//! routers; nothing here changes.

pub mod certs;
pub(crate) mod client_tls;
pub(crate) mod config;
pub mod envelope;
pub(crate) mod keys;
mod session;

pub use session::{
    agent_access_control, open, open_agent, open_console, secure, session_config, ZenohError,
    CLIENT_CONNECT_TIMEOUT_MS, CLIENT_OPEN_TIMEOUT_MS, CONSOLE_MAX_MESSAGE_BYTES,
    MAX_MESSAGE_BYTES,
};
