// SPDX-License-Identifier: GPL-2.0
//! The socketcand protocol's raw mode, the part cantcpd speaks: ASCII
//! messages `< ... >` over TCP.
//!
//! Server to client: `< hi >` on connect, `< ok >` after `open` and
//! `rawmode`, `< frame ID SEC.USEC DATA >` for every received frame (ID in
//! hex, 3 digits standard, 8 extended; DATA the bytes as two-digit hex,
//! without spaces), `< error TEXT >` for a command it cannot carry out,
//! `< echo >` in answer to `< echo >`.
//!
//! Client to server: `< open IFACE >`, `< rawmode >`,
//! `< send ID DLC B0 B1 ... >` (ID in hex, extended when written with 8
//! digits or above 0x7FF; DLC 0-8; each byte in hex, one or two digits),
//! `< echo >`.

use std::fmt::Write;

use crate::frame::{Frame, CAN_EFF_FLAG, CAN_EFF_MASK, CAN_RTR_FLAG, CAN_SFF_MASK};

/// Longest message a client may send, brackets included: a `send` with
/// 8 bytes is under 50; anything longer is garbage.
pub const MAX_MSG: usize = 256;

/// A client's command.
#[derive(Debug, PartialEq, Eq)]
pub enum Command {
    /// `< open IFACE >`.
    Open(String),
    /// `< rawmode >`.
    RawMode,
    /// `< send ID DLC DATA... >`.
    Send(Frame),
    /// `< echo >`.
    Echo,
    /// A well-formed message with a command cantcpd does not implement
    /// (`bcmmode`, `isotpmode`, `add`, ...): its first word.
    Unsupported(String),
}

/// Splits a byte stream into messages: feed bytes, take whole messages.
#[derive(Default)]
pub struct Splitter {
    buf: Vec<u8>,
}

impl Splitter {
    /// Appends received bytes.
    pub fn feed(&mut self, b: &[u8]) {
        self.buf.extend_from_slice(b);
    }

    /// The next whole message's text between `<` and `>`, trimmed; bytes
    /// before a `<` are skipped. `Err` for a message longer than
    /// [`MAX_MSG`] (the buffer is then cleared).
    pub fn next_msg(&mut self) -> Option<Result<String, String>> {
        let start = match self.buf.iter().position(|&c| c == b'<') {
            Some(s) => s,
            None => {
                self.buf.clear();
                return None;
            }
        };
        self.buf.drain(..start);
        match self.buf.iter().position(|&c| c == b'>') {
            Some(end) => {
                let text = String::from_utf8_lossy(&self.buf[1..end])
                    .trim()
                    .to_string();
                self.buf.drain(..=end);
                Some(Ok(text))
            }
            None if self.buf.len() > MAX_MSG => {
                self.buf.clear();
                Some(Err("message too long".into()))
            }
            None => None,
        }
    }
}

/// Parses one message's text (without the brackets).
pub fn parse(msg: &str) -> Result<Command, String> {
    let mut w = msg.split_ascii_whitespace();
    let cmd = w.next().ok_or("empty message")?;
    match cmd {
        "open" => {
            let iface = w.next().ok_or("open needs an interface")?;
            if w.next().is_some() {
                return Err("open takes one interface".into());
            }
            Ok(Command::Open(iface.to_string()))
        }
        "rawmode" => Ok(Command::RawMode),
        "echo" => Ok(Command::Echo),
        "send" => {
            let id_s = w.next().ok_or("send needs an id")?;
            let id = u32::from_str_radix(id_s, 16).map_err(|_| format!("bad id {id_s}"))?;
            let dlc_s = w.next().ok_or("send needs a dlc")?;
            let dlc = u8::from_str_radix(dlc_s, 16).map_err(|_| format!("bad dlc {dlc_s}"))?;
            if dlc > 8 {
                return Err(format!("dlc {dlc} over 8"));
            }
            let ext = id_s.len() == 8 || id > CAN_SFF_MASK;
            if ext && id > CAN_EFF_MASK {
                return Err(format!("id {id_s} over 29 bits"));
            }
            let mut f = Frame {
                id: if ext { id | CAN_EFF_FLAG } else { id },
                len: dlc,
                data: [0; 8],
            };
            let mut n = 0;
            for b in w {
                if n == usize::from(dlc) || b.len() > 2 {
                    return Err(format!("bad data byte {b} or more than {dlc} bytes"));
                }
                f.data[n] = u8::from_str_radix(b, 16).map_err(|_| format!("bad data byte {b}"))?;
                n += 1;
            }
            if n != usize::from(dlc) {
                return Err(format!("{n} data bytes for dlc {dlc}"));
            }
            Ok(Command::Send(f))
        }
        other => Ok(Command::Unsupported(other.to_string())),
    }
}

/// Appends `< frame ID SEC.USEC DATA >` for a received frame.
pub fn frame_msg(out: &mut String, f: &Frame, sec: i64, usec: i64) {
    if f.is_extended() {
        let _ = write!(out, "< frame {:08X} ", f.id & CAN_EFF_MASK);
    } else {
        let _ = write!(out, "< frame {:03X} ", f.id & CAN_SFF_MASK);
    }
    let _ = write!(out, "{sec}.{usec:06} ");
    // The protocol has no remote-frame flag: a remote frame is sent
    // without data, whatever its length.
    let data = if f.id & CAN_RTR_FLAG != 0 {
        &[][..]
    } else {
        f.payload()
    };
    for b in data {
        let _ = write!(out, "{b:02X}");
    }
    out.push_str(" >");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_and_parses() {
        let mut s = Splitter::default();
        s.feed(b"junk< open can0 >< rawmode ><se");
        assert_eq!(s.next_msg(), Some(Ok("open can0".into())));
        assert_eq!(s.next_msg(), Some(Ok("rawmode".into())));
        assert_eq!(s.next_msg(), None);
        s.feed(b"nd 123 2 a bb >");
        let m = s.next_msg().unwrap().unwrap();
        let mut want = Frame {
            id: 0x123,
            len: 2,
            data: [0; 8],
        };
        want.data[..2].copy_from_slice(&[0x0A, 0xBB]);
        assert_eq!(parse(&m), Ok(Command::Send(want)));
        assert_eq!(parse("open can1"), Ok(Command::Open("can1".into())));
        assert_eq!(parse("bcmmode"), Ok(Command::Unsupported("bcmmode".into())));
    }

    #[test]
    fn send_forms() {
        let Ok(Command::Send(f)) = parse("send 00000123 0") else {
            panic!()
        };
        assert_eq!(f.id, CAN_EFF_FLAG | 0x123);
        let Ok(Command::Send(f)) = parse("send 1ABCDEF 1 ff") else {
            panic!()
        };
        assert_eq!(
            (f.id, f.len, f.data[0]),
            (CAN_EFF_FLAG | 0x1ABCDEF, 1, 0xFF)
        );
        assert!(parse("send 123 2 1").is_err());
        assert!(parse("send 123 1 1 2").is_err());
        assert!(parse("send 123 9").is_err());
        assert!(parse("send 3FFFFFFF 0").is_err());
        assert!(parse("send 123 1 100").is_err());
    }

    #[test]
    fn too_long() {
        let mut s = Splitter::default();
        s.feed(&[b'<'; MAX_MSG + 2]);
        assert!(matches!(s.next_msg(), Some(Err(_))));
    }

    #[test]
    fn frame_text() {
        let mut s = String::new();
        let f = Frame {
            id: 0x12,
            len: 2,
            data: [1, 0xAB, 0, 0, 0, 0, 0, 0],
        };
        frame_msg(&mut s, &f, 1_700_000_000, 5);
        assert_eq!(s, "< frame 012 1700000000.000005 01AB >");
        s.clear();
        let f = Frame {
            id: CAN_EFF_FLAG | 0x1234,
            len: 0,
            data: [0; 8],
        };
        frame_msg(&mut s, &f, 1, 0);
        assert_eq!(s, "< frame 00001234 1.000000  >");
        s.clear();
        let f = Frame {
            id: CAN_RTR_FLAG | 0x7FF,
            len: 4,
            data: [0; 8],
        };
        frame_msg(&mut s, &f, 1, 0);
        assert_eq!(s, "< frame 7FF 1.000000  >");
    }
}
