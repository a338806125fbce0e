//! Every kind of bad input gives `FILE:LINE:COL: message` quoting the
//! offending text, exit status 2, and never a panic.

use crate::util::{cellwatch, Dir};

fn sf_error(program: impl AsRef<[u8]>) -> String {
    sf_error_with(program, &[])
}

fn sf_error_with(program: impl AsRef<[u8]>, options: &[&str]) -> String {
    let d = Dir::new();
    let p = d.file("p.il", program);
    let mut args = vec!["sf", p.as_str()];
    args.extend(options);
    let r = cellwatch(&args);
    assert_eq!(r.code, 2, "stdout: {}\nstderr: {}", r.stdout, r.stderr);
    assert!(!r.stderr.contains("panicked"));
    // Strip the temporary directory so the message can be pinned.
    r.stderr.replace(&p, "p.il")
}

#[test]
fn unknown_mnemonic() {
    assert_eq!(
        sf_error("RD X0.07\nRDX X0.05\n"),
        "error: p.il:2:1: unknown instruction 'RDX'\n"
    );
}

#[test]
fn unbalanced_stack() {
    assert_eq!(
        sf_error("RD X1\nRD.STK X2\nWRT Y1\n"),
        "error: p.il:3:1: unbalanced stack at 'WRT Y1': 'RD.STK X2' at line 2 pushed a result that is never combined (AND.STK/OR.STK)\n"
    );
    assert_eq!(
        sf_error("RD X1\nOR.STK\nWRT Y1\n"),
        "error: p.il:2:1: 'OR.STK' with nothing on the stack: no RD.STK before it\n"
    );
}

#[test]
fn unbalanced_parentheses() {
    assert_eq!(
        sf_error("LD a\nAND( b\nOR c\nST q\n"),
        "error: p.il:4:1: unbalanced parentheses at 'ST q': 'AND( b' at line 2 is never closed with ')'\n"
    );
    assert_eq!(
        sf_error("LD a\nAND b\n)\nST q\n"),
        "error: p.il:3:1: ')' closes no '('\n"
    );
}

#[test]
fn write_with_no_result() {
    assert_eq!(
        sf_error("; rung 1\n  WRT Y0.00\n"),
        "error: p.il:2:3: 'WRT Y0.00' with no result to write: no load (RD/LD) before it\n"
    );
}

#[test]
fn malformed_address() {
    assert_eq!(
        sf_error("RD X0.07\nAND.NOT X0.1G\nWRT Y0.00\n"),
        "error: p.il:2:9: malformed address 'X0.1G': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)\n"
    );
}

#[test]
fn empty_and_non_utf8_files() {
    assert_eq!(
        sf_error(""),
        "error: p.il:1:1: the program is empty: no instructions\n"
    );
    assert_eq!(sf_error("; only comments\n"), "error: p.il:1:1: cannot tell the dialect: no PMC (RD, WRT) or IEC (LD, ST) instruction found; pass --dialect pmc or --dialect iec\n");
    // Not UTF-8: read as Latin-1, where 0xE9 is 'é'.
    assert_eq!(
        sf_error(b"RD X0.07\nWRT Y0.\xE900\n".as_slice()),
        "error: p.il:2:5: malformed address 'Y0.é00': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)\n"
    );
    assert_eq!(
        sf_error_with(b"RD X0.07\nWRT Y0.\xE900\n".as_slice(), &["--encoding", "utf-8"]),
        "error: p.il:2:8: not UTF-8 text (byte 0xE9); pass --encoding latin1 (or the file's encoding), or save it as UTF-8\n"
    );
}

#[test]
fn unknown_coil() {
    let r = cellwatch(&["sf", "config/cnc/ese.il", "--coil", "G8.03"]);
    assert_eq!(r.code, 2);
    assert_eq!(
        r.stderr,
        "error: config/cnc/ese.il: unknown coil 'G8.03': the program writes R900.00, G8.02\n"
    );
    let r = cellwatch(&[
        "explain",
        "config/cnc/ese.il",
        "--coil",
        "Y7",
        "--snapshot",
        "X0.06=0",
    ]);
    assert_eq!(
        r.stderr,
        "error: config/cnc/ese.il: unknown coil 'Y7': the program writes R900.00, G8.02\n"
    );
}

#[test]
fn malformed_snapshot_lines() {
    let d = Dir::new();
    let s = d.file("s.values", "X0.06=0\nX0.07 1\n");
    let r = cellwatch(&[
        "explain",
        "config/cnc/ese.il",
        "--coil",
        "G8.02",
        "--snapshot",
        &s,
    ]);
    assert_eq!(r.code, 2);
    assert_eq!(
        r.stderr.replace(&s, "s.values"),
        "error: s.values:2:1: malformed line 'X0.07 1': expected ADDRESS=VALUE or ADDRESS,VALUE\n"
    );
    let r = cellwatch(&[
        "explain",
        "config/cnc/ese.il",
        "--coil",
        "G8.02",
        "--snapshot",
        "X0.06=0,X0.07=maybe",
    ]);
    assert_eq!(r.code, 2);
    assert_eq!(
        r.stderr,
        "error: --snapshot:1:15: value 'maybe' for X0.07 is not 0, 1, true, false, on or off\n"
    );
    let r = cellwatch(&[
        "explain",
        "config/cnc/ese.il",
        "--coil",
        "G8.02",
        "--snapshot",
        "no-such-file.values",
    ]);
    assert_eq!(r.stderr, "error: --snapshot 'no-such-file.values': no such file, and not inline ADDRESS=VALUE pairs\n");
}

#[test]
fn bad_comment_database() {
    let d = Dir::new();
    let c = d.file("c.csv", "address,comment\nX0.06,ok\nX0.0Z,bad\n");
    let r = cellwatch(&["sf", "config/cnc/ese.il", "--comments", &c]);
    assert_eq!(r.code, 2);
    assert_eq!(
        r.stderr.replace(&c, "c.csv"),
        "error: c.csv:3:1: malformed address 'X0.0Z': the bit after '.' must be a hex digit 0..F (as in X0.07 or X0.0A)\n"
    );
}

#[test]
fn missing_file_and_bad_options() {
    let r = cellwatch(&["sf", "nowhere.il"]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .starts_with("error: cannot read program 'nowhere.il': "),
        "{}",
        r.stderr
    );
    let r = cellwatch(&["sf", "config/cnc/ese.il", "--dialect", "st"]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr
            .contains("unknown dialect 'st': use pmc, iec or stl"),
        "{}",
        r.stderr
    );
}

/// Output that cannot be written is a runtime failure (1), not bad input.
#[test]
fn a_closed_stdout_exits_1_with_a_message() {
    let (reader, writer) = std::io::pipe().unwrap();
    // Nobody will ever read: every write fails with a broken pipe.
    drop(reader);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_cellwatch"))
        .args(["sf", "config/cnc/ese.il"])
        .current_dir(crate::util::root())
        .stdout(writer)
        .stderr(std::process::Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.starts_with("error: cannot write output: Broken pipe"),
        "{stderr}"
    );
}

#[test]
fn a_file_in_another_format_gets_one_line_saying_what_it_is() {
    let xml = "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<project xmlns=\"http://www.plcopen.org/xml/tc6_0201\">\n".to_string()
        + &"  <pou name=\"p\"/>\n".repeat(1200)
        + "</project>\n";
    // Read as PLCopen XML: this one has no body to read.
    assert_eq!(
        sf_error(&xml),
        "error: p.il:1:1: no ladder (LD), IL, ST, FBD or SFC body with anything in it in this XML file\n"
    );
    let e = sf_error_with(&xml, &["--dialect", "iec"]);
    assert_eq!(
        e,
        "error: p.il:1:1: this is an XML file (PLCopen XML?), not an instruction list: leave --dialect out, and its ladder and IL bodies are read\n"
    );
    assert_eq!(
        sf_error_with("U E 0.0\nUN E 0.1\n= A 4.0\n", &["--dialect", "iec"]),
        "error: p.il:1:1: this looks like Siemens STL (U, UN, =), not iec: pass --dialect stl, or leave --dialect out\n"
    );
}

#[test]
fn at_most_twenty_errors_then_a_count() {
    let program = "RD X0.07\n".to_string() + &"FROB X1\n".repeat(500);
    let e = sf_error(program);
    assert_eq!(e.lines().count(), 21, "{e}");
    assert!(
        e.starts_with("error: p.il:2:1: unknown instruction 'FROB'\np.il:3:1: "),
        "{e}"
    );
    assert!(
        e.ends_with("\n... and 480 more errors (500 in all)\n"),
        "{e}"
    );
}

#[test]
fn latin1_and_utf16_programs_are_read() {
    let d = Dir::new();
    // An old German STL source: Latin-1 comments.
    let latin1 = d.file(
        "foerder.awl",
        b"NETWORK\nTITLE = F\xF6rderband\n      U     E      0.0   // St\xF6rung quittiert\n      UN    E      0.1\n      =     A      4.0\n",
    );
    let r = cellwatch(&["sf", &latin1, "--coil", "A4.0"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains("SF:         A4.0 = E0.0 * -E0.1"),
        "{}",
        r.stdout
    );
    // A UTF-16 export with its byte-order mark.
    let utf16: Vec<u8> = [0xFF, 0xFE]
        .into_iter()
        .chain(
            "(* Förderband *)\nLD %IX0.0\nANDN %IX0.1\nST %QX4.0\n"
                .encode_utf16()
                .flat_map(u16::to_le_bytes),
        )
        .collect();
    let utf16 = d.file("export.il", utf16);
    let r = cellwatch(&["sf", &utf16, "--coil", "%QX4.0"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains("SF:         %QX4.0 = %IX0.0 * -%IX0.1"),
        "{}",
        r.stdout
    );
    // Told the wrong encoding: the first bad byte, located.
    let r = cellwatch(&["sf", &latin1, "--encoding", "utf-8"]);
    assert_eq!(r.code, 2);
    assert!(
        r.stderr.contains(":2:10: not UTF-8 text (byte 0xF6)"),
        "{}",
        r.stderr
    );
}

/// `discover` against a server that takes the connection and never
/// answers ends with an error naming the endpoint, rather than waiting for
/// ever.
#[test]
fn discover_gives_up_on_a_server_that_never_answers() {
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = silent.local_addr().unwrap().port();
    // Takes every connection and keeps it open, saying nothing.
    std::thread::spawn(move || {
        let mut held = Vec::new();
        for stream in silent.incoming().map_while(Result::ok) {
            held.push(stream);
        }
    });
    let dir = tempfile::tempdir().unwrap();
    let endpoint = format!("opc.tcp://127.0.0.1:{port}/");
    let run = crate::util::cellwatch(&[
        "discover",
        &endpoint,
        "--pki-dir",
        dir.path().join("pki").to_str().unwrap(),
    ]);
    assert_ne!(run.code, 0, "{}", run.stdout);
    assert!(
        run.stderr.contains(&format!(
            "{endpoint}: no answer to the request for its endpoints within 30 s"
        )),
        "{}",
        run.stderr
    );
}
