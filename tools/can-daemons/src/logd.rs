// SPDX-License-Identifier: GPL-2.0
//! `logd`'s pure parts: the `NODE:ID` sources it listens to and its log
//! line format.
//!
//! One line per DSOR segmented message:
//!
//! ```text
//! (SECONDS.MICROSECONDS) NODE ID LEN DATA
//! ```
//!
//! `NODE` the source node as 2 hex digits, `ID` the 32-bit message
//! identifier as 8 hex digits, `LEN` the message length in decimal, `DATA`
//! the bytes as lower-case hex without separators (`-` for an empty
//! message). Lines starting with `# ` are logd's notes (start, stop,
//! errors).

use std::fmt::Write;

/// `DSOR_NODE_ANY`.
pub const NODE_ANY: u8 = 0xff;
/// `DSOR_ID_ANY`.
pub const ID_ANY: u32 = 0xffff_ffff;

/// Parses a number in decimal or `0x` hexadecimal.
fn num(s: &str) -> Option<u64> {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16).ok(),
        None => s.parse().ok(),
    }
}

/// Parses `NODE:ID` (each decimal or `0x` hex, or `any`): a node 0-0x7f
/// and a 32-bit message identifier.
pub fn parse_source(s: &str) -> Result<(u8, u32), String> {
    let (n, i) = s
        .split_once(':')
        .ok_or_else(|| format!("{s}: expected NODE:ID"))?;
    let node = if n == "any" {
        NODE_ANY
    } else {
        match num(n) {
            Some(v) if v <= 0x7f => v as u8,
            _ => return Err(format!("{s}: node {n} is not 0-0x7f or any")),
        }
    };
    let id = if i == "any" {
        ID_ANY
    } else {
        match num(i) {
            Some(v) if v < u64::from(ID_ANY) => v as u32,
            _ => return Err(format!("{s}: id {i} is not 0-0xfffffffe or any")),
        }
    };
    Ok((node, id))
}

/// Appends one message's log line, newline included.
pub fn line(out: &mut String, sec: u64, usec: u32, node: u8, id: u32, data: &[u8]) {
    let _ = write!(
        out,
        "({sec:010}.{usec:06}) {node:02x} {id:08x} {} ",
        data.len()
    );
    if data.is_empty() {
        out.push('-');
    }
    for b in data {
        let _ = write!(out, "{b:02x}");
    }
    out.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources() {
        assert_eq!(parse_source("5:0x100"), Ok((5, 0x100)));
        assert_eq!(parse_source("0x7f:any"), Ok((0x7f, ID_ANY)));
        assert_eq!(parse_source("any:7"), Ok((NODE_ANY, 7)));
        for bad in ["5", "128:1", "5:0xffffffff", "x:1", "5:", ":1"] {
            assert!(parse_source(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn lines() {
        let mut s = String::new();
        line(&mut s, 1_700_000_000, 42, 5, 0x100, &[0, 0xAB]);
        line(&mut s, 1, 0, 0x7f, 0xdeadbeef, &[]);
        assert_eq!(
            s,
            "(1700000000.000042) 05 00000100 2 00ab\n(0000000001.000000) 7f deadbeef 0 -\n"
        );
    }
}
