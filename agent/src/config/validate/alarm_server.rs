//! Validating the configuration: `[alarm_server]`.

use std::net::SocketAddr;

use toml::Spanned;

use super::value_error::ValueError;
use super::Validator;
use crate::config::raw::RawAlarmServer;
use crate::config::AlarmServerConfig;

/// The server's PKI directory unless the configuration names one.
const DEFAULT_PKI_DIR: &str = "alarm-server-pki";

impl Validator<'_> {
    pub(super) fn alarm_server(
        &mut self,
        raw: Option<Spanned<RawAlarmServer>>,
    ) -> Option<AlarmServerConfig> {
        let raw = raw?;
        let table = raw.span();
        let raw = raw.into_inner();
        let listen = match &raw.listen {
            None => {
                self.problem(
                    table.clone(),
                    "alarm_server.listen",
                    "required: where the server listens, like \"opc.tcp://0.0.0.0:4855\"",
                );
                None
            }
            Some(l) => match listen_address(l.get_ref()) {
                Ok(a) => Some(a),
                Err(why) => {
                    self.problem(l.span(), "alarm_server.listen", why);
                    None
                }
            },
        };
        let users_file = match &raw.users_file {
            None => {
                self.problem(
                    table,
                    "alarm_server.users_file",
                    "required: the file of the OPC UA users and the operators they act as",
                );
                None
            }
            Some(f) => Some(self.path(f.get_ref())),
        };
        let pki_dir = self.path(
            raw.pki_dir
                .as_ref()
                .map_or(DEFAULT_PKI_DIR, |p| p.get_ref().as_str()),
        );
        Some(AlarmServerConfig {
            listen: listen?,
            pki_dir,
            users_file: users_file?,
        })
    }
}

/// The socket address of `opc.tcp://IP:PORT`, or why it is not one.
fn listen_address(text: &str) -> Result<SocketAddr, ValueError> {
    let rest = text
        .strip_prefix("opc.tcp://")
        .ok_or_else(|| ValueError::NotOpcTcp(text.into()))?;
    rest.trim_end_matches('/')
        .parse()
        .map_err(|_| ValueError::NoIpAndPort(text.into()))
}

#[cfg(test)]
mod tests {
    use super::listen_address;

    #[test]
    fn listen_is_an_opc_tcp_ip_and_port() {
        assert_eq!(
            listen_address("opc.tcp://127.0.0.1:4855/").unwrap(),
            "127.0.0.1:4855".parse().unwrap()
        );
        assert_eq!(
            listen_address("127.0.0.1:4855").unwrap_err().to_string(),
            "'127.0.0.1:4855' is not like opc.tcp://0.0.0.0:4855"
        );
        assert_eq!(
            listen_address("opc.tcp://scada:4855")
                .unwrap_err()
                .to_string(),
            "'opc.tcp://scada:4855': give an IP address and a port, like opc.tcp://0.0.0.0:4855"
        );
    }
}
