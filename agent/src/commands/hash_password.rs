//! `cellwatch hash-password`: the Argon2id hash (a PHC string) of a
//! password read from standard input, for the alarm server's users file.
//! The password is never an argument, so it stays out of shell histories
//! and process lists.

use std::io::{BufRead, Write};

use super::Failure;
use crate::services::alarm_server::users::hash_password;

/// Reads one line from `input` (its line ending dropped) and prints its hash.
pub(crate) fn run(input: &mut dyn BufRead, out: &mut dyn Write) -> Result<(), Failure> {
    let mut line = String::new();
    input
        .read_line(&mut line)
        .map_err(|e| Failure::Runtime(format!("cannot read standard input: {e}")))?;
    let password = line.trim_end_matches(['\n', '\r']);
    if password.is_empty() {
        return Err(Failure::Input(
            "no password on standard input: write it there, one line".into(),
        ));
    }
    writeln!(out, "{}", hash_password(password)).map_err(Failure::output)
}

#[derive(Debug, clap::Args)]
pub(crate) struct HashPasswordArgs {}

#[cfg(test)]
mod tests {
    use super::run;

    #[test]
    fn the_hash_is_a_phc_string_of_the_line() {
        let mut out = Vec::new();
        run(&mut &b"s3cret\n"[..], &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.starts_with("$argon2id$v=19$"), "{text}");
        let mut out = Vec::new();
        assert!(run(&mut &b"\n"[..], &mut out).is_err());
    }
}
