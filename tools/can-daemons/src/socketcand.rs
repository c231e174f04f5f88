// SPDX-License-Identifier: GPL-2.0
//! The socketcand protocol (linux-can/socketcand, doc/protocol.md), the
//! parts cantcpd speaks: ASCII messages `< ... >` over TCP, in BCM mode
//! (the default after `open`) and raw mode.
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
//! `< echo >`, `< rawmode >`, `< bcmmode >`, and in BCM mode
//! `< add SEC USEC ID DLC B0 ... >`, `< update ID DLC B0 ... >`,
//! `< delete ID >`, `< filter SEC USEC ID DLC M0 ... >`,
//! `< subscribe SEC USEC ID >`, `< unsubscribe ID >`. In BCM mode frames
//! reach the client as `< frame ID SEC.USEC B0 B1 ... >` (bytes separated
//! by spaces, as socketcand writes them in that mode).

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
    /// `< bcmmode >`.
    BcmMode,
    /// `< add SEC USEC ID DLC DATA... >`: a cyclic transmission job.
    Add {
        /// Cycle: (seconds, microseconds).
        ival: (u64, u64),
        /// The frame sent every cycle.
        frame: Frame,
    },
    /// `< update ID DLC DATA... >`: new content for a job, timer untouched.
    Update(Frame),
    /// `< delete ID >`: remove the job of `ID` (flags included).
    Delete(u32),
    /// `< filter SEC USEC ID DLC MASK... >`: receive `ID` when the bytes
    /// under the mask (the frame's data) change; throttled to one per ival.
    Filter {
        /// Throttle: (seconds, microseconds).
        ival: (u64, u64),
        /// Identifier (flags included), DLC and mask bytes.
        mask: Frame,
    },
    /// `< subscribe SEC USEC ID >`: receive every frame of `ID`,
    /// throttled to one per ival.
    Subscribe {
        /// Throttle: (seconds, microseconds).
        ival: (u64, u64),
        /// Identifier, flags included.
        id: u32,
    },
    /// `< unsubscribe ID >`: remove the filter or subscription of `ID`.
    Unsubscribe(u32),
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
        "bcmmode" => Ok(Command::BcmMode),
        "send" => Ok(Command::Send(frame_args(&mut w, "send")?)),
        "update" => Ok(Command::Update(frame_args(&mut w, "update")?)),
        "add" => {
            let ival = ival_args(&mut w, "add")?;
            Ok(Command::Add {
                ival,
                frame: frame_args(&mut w, "add")?,
            })
        }
        "filter" => {
            let ival = ival_args(&mut w, "filter")?;
            Ok(Command::Filter {
                ival,
                mask: frame_args(&mut w, "filter")?,
            })
        }
        "subscribe" => {
            let ival = ival_args(&mut w, "subscribe")?;
            let id = id_arg(&mut w, "subscribe")?;
            no_more(&mut w, "subscribe")?;
            Ok(Command::Subscribe { ival, id })
        }
        "delete" | "unsubscribe" => {
            let id = id_arg(&mut w, cmd)?;
            no_more(&mut w, cmd)?;
            Ok(if cmd == "delete" {
                Command::Delete(id)
            } else {
                Command::Unsubscribe(id)
            })
        }
        other => Ok(Command::Unsupported(other.to_string())),
    }
}

/// An identifier in hex: extended when written with 8 digits or above
/// 0x7FF (socketcand: 8 digits); `CAN_EFF_FLAG` set then.
fn id_arg<'a>(w: &mut impl Iterator<Item = &'a str>, cmd: &str) -> Result<u32, String> {
    let id_s = w.next().ok_or(format!("{cmd} needs an id"))?;
    let id = u32::from_str_radix(id_s, 16).map_err(|_| format!("bad id {id_s}"))?;
    let ext = id_s.len() == 8 || id > CAN_SFF_MASK;
    if ext && id > CAN_EFF_MASK {
        return Err(format!("id {id_s} over 29 bits"));
    }
    Ok(if ext { id | CAN_EFF_FLAG } else { id })
}

/// `SEC USEC` in decimal; at most 2^31 - 1 seconds, USEC under 10^6.
fn ival_args<'a>(w: &mut impl Iterator<Item = &'a str>, cmd: &str) -> Result<(u64, u64), String> {
    let mut num = |what: &str| -> Result<u64, String> {
        let s = w.next().ok_or(format!("{cmd} needs {what}"))?;
        s.parse::<u64>().map_err(|_| format!("bad {what} {s}"))
    };
    let sec = num("seconds")?;
    let usec = num("microseconds")?;
    if sec > i32::MAX as u64 || usec >= 1_000_000 {
        return Err(format!("interval {sec} s {usec} us out of range"));
    }
    Ok((sec, usec))
}

/// `ID DLC B0 B1 ...` to the end of the message: a frame.
fn frame_args<'a>(w: &mut impl Iterator<Item = &'a str>, cmd: &str) -> Result<Frame, String> {
    let id = id_arg(w, cmd)?;
    let dlc_s = w.next().ok_or(format!("{cmd} needs a dlc"))?;
    let dlc = u8::from_str_radix(dlc_s, 16).map_err(|_| format!("bad dlc {dlc_s}"))?;
    if dlc > 8 {
        return Err(format!("dlc {dlc} over 8"));
    }
    let mut f = Frame {
        id,
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
    Ok(f)
}

fn no_more<'a>(w: &mut impl Iterator<Item = &'a str>, cmd: &str) -> Result<(), String> {
    match w.next() {
        Some(x) => Err(format!("{cmd}: unexpected {x}")),
        None => Ok(()),
    }
}

/// Appends `< frame ID SEC.USEC B0 B1 ... >` (BCM mode's form: bytes
/// separated by spaces).
pub fn bcm_frame_msg(out: &mut String, f: &Frame, sec: i64, usec: i64) {
    if f.is_extended() {
        let _ = write!(out, "< frame {:08X} ", f.id & CAN_EFF_MASK);
    } else {
        let _ = write!(out, "< frame {:03X} ", f.id & CAN_SFF_MASK);
    }
    let _ = write!(out, "{sec}.{usec:06} ");
    if f.id & CAN_RTR_FLAG == 0 {
        for b in f.payload() {
            let _ = write!(out, "{b:02X} ");
        }
    }
    out.push('>');
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
        assert_eq!(parse("bcmmode"), Ok(Command::BcmMode));
        assert_eq!(
            parse("isotpmode"),
            Ok(Command::Unsupported("isotpmode".into()))
        );
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
    fn bcm_commands() {
        let f = |id, d: &[u8]| {
            let mut f = Frame {
                id,
                len: d.len() as u8,
                data: [0; 8],
            };
            f.data[..d.len()].copy_from_slice(d);
            f
        };
        assert_eq!(
            parse("add 1 0 123 8 11 22 33 44 55 66 77 88"),
            Ok(Command::Add {
                ival: (1, 0),
                frame: f(0x123, &[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88])
            })
        );
        assert_eq!(
            parse("add 0 20000 00000123 1 42"),
            Ok(Command::Add {
                ival: (0, 20000),
                frame: f(CAN_EFF_FLAG | 0x123, &[0x42])
            })
        );
        assert_eq!(
            parse("update 123 3 11 22 33"),
            Ok(Command::Update(f(0x123, &[0x11, 0x22, 0x33])))
        );
        assert_eq!(parse("delete 123"), Ok(Command::Delete(0x123)));
        assert_eq!(
            parse("unsubscribe 1AAAAAAA"),
            Ok(Command::Unsubscribe(CAN_EFF_FLAG | 0x1AAAAAAA))
        );
        assert_eq!(
            parse("filter 1 500000 123 8 FF 00 F8 00 00 00 00 00"),
            Ok(Command::Filter {
                ival: (1, 500_000),
                mask: f(0x123, &[0xFF, 0, 0xF8, 0, 0, 0, 0, 0])
            })
        );
        assert_eq!(
            parse("subscribe 0 0 123"),
            Ok(Command::Subscribe {
                ival: (0, 0),
                id: 0x123
            })
        );
        for bad in [
            "add 1 123 1 1",
            "add 0 1000000 123 0",
            "add -1 0 123 0",
            "add 0 0 123 2 1",
            "update 123",
            "delete",
            "delete 123 4",
            "subscribe 0 0",
            "subscribe 0 0 123 1",
            "unsubscribe 3FFFFFFF",
            "filter 0 0 123 9",
        ] {
            assert!(parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn bcm_frame_text() {
        let mut s = String::new();
        let f = Frame {
            id: 0x12,
            len: 2,
            data: [1, 0xAB, 0, 0, 0, 0, 0, 0],
        };
        bcm_frame_msg(&mut s, &f, 7, 5);
        assert_eq!(s, "< frame 012 7.000005 01 AB >");
        s.clear();
        let f = Frame {
            id: CAN_EFF_FLAG | 0x1234,
            len: 0,
            data: [0; 8],
        };
        bcm_frame_msg(&mut s, &f, 1, 0);
        assert_eq!(s, "< frame 00001234 1.000000 >");
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
