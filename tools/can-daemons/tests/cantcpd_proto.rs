// SPDX-License-Identifier: GPL-2.0
//! cantcpd's protocol handling without a CAN interface (the host has
//! none): greeting, echo, refusals and errors, over real TCP on loopback.
//! Frames both ways are checked in the VM (tests/vm, daemons.rs).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Reads one `< ... >` message.
fn msg(s: &mut TcpStream) -> String {
    let mut out = Vec::new();
    let mut b = [0u8; 1];
    while out.last() != Some(&b'>') {
        assert_eq!(s.read(&mut b).expect("read"), 1, "closed after {out:?}");
        if !out.is_empty() || b[0] == b'<' {
            out.push(b[0]);
        }
    }
    String::from_utf8(out).expect("ASCII")
}

#[test]
fn greeting_echo_and_errors() {
    let mut srv = Command::new(env!("CARGO_BIN_EXE_cantcpd"))
        .args(["--listen", "127.0.0.1:0", "--max-clients", "1"])
        .stderr(Stdio::piped())
        .spawn()
        .expect("cantcpd");
    let mut err = BufReader::new(srv.stderr.take().expect("piped"));
    let mut line = String::new();
    err.read_line(&mut line).expect("stderr");
    let addr = line
        .trim()
        .strip_prefix("cantcpd: listening on ")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string();
    let mut c = TcpStream::connect(&addr).expect("connect");
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    assert_eq!(msg(&mut c), "< hi >");
    for (send, want) in [
        ("< echo >", "< echo >"),
        ("< send 123 1 1 >", "< error no interface open >"),
        ("< rawmode >", "< error no interface open >"),
        ("< bcmmode >", "< error no interface open >"),
        ("< subscribe 0 0 123 >", "< error no interface open >"),
        ("< isotpmode >", "< error unsupported command isotpmode >"),
        (
            "< add 0 1000000 123 0 >",
            "< error interval 0 s 1000000 us out of range >",
        ),
        ("< send 123 9 >", "< error dlc 9 over 8 >"),
        ("< >", "< error empty message >"),
    ] {
        c.write_all(send.as_bytes()).unwrap();
        assert_eq!(msg(&mut c), want, "after {send}");
    }
    c.write_all(b"< open nosuchcan0 >").unwrap();
    let m = msg(&mut c);
    assert!(m.starts_with("< error open nosuchcan0: "), "{m}");
    // --max-clients 1: a second client is refused.
    let mut c2 = TcpStream::connect(&addr).expect("connect");
    c2.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    assert_eq!(msg(&mut c2), "< error too many clients >");
    drop(c);
    drop(c2);
    // SIGTERM: exit status 0.
    Command::new("kill")
        .args(["-TERM", &srv.id().to_string()])
        .status()
        .expect("kill");
    let st = srv.wait().expect("wait");
    assert!(st.success(), "cantcpd after SIGTERM: {st}");
}
