//! The fixed label values of the metrics whose values the code says in
//! words rather than through a typed enum: what a refusal and a command's
//! result are called. The metrics reference lists them (a test holds it to
//! the registry); the series of [`REFUSED`] exist from the start. And the
//! one label every metric has: its cell ([`opts`]).

/// A metric's options with its cell as a constant label: every series
/// carries `cell`, for Prometheus federation across cells.
pub(super) fn opts(name: &str, help: &str, cell: &str) -> prometheus::Opts {
    prometheus::Opts::new(name, help).const_label("cell", cell)
}

/// Every service and reason `cellwatch_requests_refused_total` counts,
/// each series at 0 from the start: queries refused (`busy`: too many at
/// once, `too_large`, `invalid`: not a request) and commands refused
/// before a known operator's signature was verified (the reasons of
/// `operator::Refusal::unauthenticated`).
pub const REFUSED: [(&str, &str); 10] = [
    ("history", "busy"),
    ("history", "invalid"),
    ("snapshot", "busy"),
    ("command", "busy"),
    ("command", "too_large"),
    ("command", "invalid"),
    ("command", "unsigned"),
    ("command", "unknown_operator"),
    ("command", "bad_signature"),
    ("command", "malformed"),
];

/// The results of `cellwatch_commands_total`.
pub const COMMAND_RESULTS: [&str; 2] = ["accepted", "refused"];

#[cfg(test)]
mod tests {
    use super::REFUSED;
    use crate::operator::Refusal;

    #[test]
    fn every_reason_a_command_is_refused_before_its_signature_is_counted() {
        let refusals = [
            Refusal::Unsigned,
            Refusal::UnknownOperator("kim".into()),
            Refusal::SignatureNotHex,
            Refusal::BadSignature,
            Refusal::ControlCharacter("alarm"),
            Refusal::BadNonce,
        ];
        for r in refusals {
            let reason = r.unauthenticated().unwrap();
            assert!(REFUSED.contains(&("command", reason)), "{reason}");
        }
    }
}
