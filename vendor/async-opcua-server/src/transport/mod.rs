// cellwatch's patch: which OpenSecureChannel requests are decrypted.
pub(crate) mod admission;
mod connect;
mod reverse_tcp;
pub(crate) mod tcp;
pub(crate) use connect::Connector;
pub(crate) use reverse_tcp::ReverseTcpConnector;
