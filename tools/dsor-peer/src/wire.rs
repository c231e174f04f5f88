// SPDX-License-Identifier: GPL-2.0
//! DSOR frames: the 29-bit identifier and the header, body and ack payloads
//! (Documentation/networking/rcan/dsor-wire.rst; thesis 5.3.3).
//!
//! ```text
//! id = P<<21 | D<<14 | S<<7 | T<<5 | Q<<4 | C
//!      P priority 8 bits, D/S destination/source node 7 bits,
//!      T 0 header 1 body 2 ack 3 reserved, Q sequence bit, C channel 4 bits
//! ```

/// An extended CAN data frame (IDE 1, RTR 0): 29-bit id, a classic frame
/// of 0..=8 bytes or, on an interface in CAN FD mode, a CAN FD frame
/// (FDF 1) of one of the FD lengths (dsor-wire.rst, "FD lengths").
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Frame {
    /// 29-bit identifier.
    pub id: u32,
    /// Data length: 0..=8, or an FD length up to 64 if `fd`.
    pub len: u8,
    /// A CAN FD frame (FDF 1).
    pub fd: bool,
    /// Data; bytes past `len` are zero.
    pub data: [u8; 64],
}

impl Frame {
    /// A classic frame with the first `bytes.len()` (at most 8) data bytes.
    pub fn new(id: u32, bytes: &[u8]) -> Frame {
        let mut data = [0u8; 64];
        data[..bytes.len()].copy_from_slice(bytes);
        Frame {
            id: id & 0x1fff_ffff,
            len: bytes.len() as u8,
            fd: false,
            data,
        }
    }

    /// A CAN FD frame carrying `bytes` (at most 64), of the smallest FD
    /// length that holds them, padded with 0x00.
    pub fn new_fd(id: u32, bytes: &[u8]) -> Frame {
        let mut f = Frame::new(id, &[]);
        f.data[..bytes.len()].copy_from_slice(bytes);
        f.len = fd_len_round_up(bytes.len()) as u8;
        f.fd = true;
        f
    }

    /// The data bytes (padding included).
    pub fn bytes(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(64))]
    }
}

/// The data lengths a CAN FD frame can have above 8 (DLC 9..=15).
pub const FD_LONG_LENS: [usize; 7] = [12, 16, 20, 24, 32, 48, 64];

/// The smallest CAN FD length >= `r` (`r` <= 64).
pub fn fd_len_round_up(r: usize) -> usize {
    if r <= 8 {
        return r;
    }
    FD_LONG_LENS.into_iter().find(|&l| l >= r).unwrap_or(64)
}

/// Whether `b` is a body size: 8 (classic bodies) or an FD length above 8.
pub fn valid_body_size(b: u8) -> bool {
    b == 8 || FD_LONG_LENS.contains(&usize::from(b))
}

/// Frame type (identifier bits 6..5).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Type {
    /// First frame of a message: length and addressing.
    Header,
    /// Up to 8 message bytes.
    Body,
    /// Acknowledgement from the receiver.
    Ack,
    /// Type 3: ignored.
    Reserved,
}

/// The fields of a DSOR identifier.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Id {
    /// Priority, lower wins arbitration.
    pub prio: u8,
    /// Destination node 0..=0x7f.
    pub dst: u8,
    /// Source node 0..=0x7f.
    pub src: u8,
    /// Frame type.
    pub typ: Type,
    /// Sequence bit.
    pub q: bool,
    /// Channel 0..=15.
    pub chan: u8,
}

impl Id {
    /// Packs the fields into a 29-bit identifier.
    pub fn encode(&self) -> u32 {
        let t = match self.typ {
            Type::Header => 0,
            Type::Body => 1,
            Type::Ack => 2,
            Type::Reserved => 3,
        };
        u32::from(self.prio) << 21
            | u32::from(self.dst & 0x7f) << 14
            | u32::from(self.src & 0x7f) << 7
            | t << 5
            | u32::from(self.q) << 4
            | u32::from(self.chan & 0x0f)
    }

    /// Splits a 29-bit identifier.
    pub fn decode(id: u32) -> Id {
        Id {
            prio: (id >> 21) as u8,
            dst: ((id >> 14) & 0x7f) as u8,
            src: ((id >> 7) & 0x7f) as u8,
            typ: match (id >> 5) & 3 {
                0 => Type::Header,
                1 => Type::Body,
                2 => Type::Ack,
                _ => Type::Reserved,
            },
            q: id & 0x10 != 0,
            chan: (id & 0x0f) as u8,
        }
    }
}

/// Addressing of a message (the header's DLC tells which).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Kind {
    /// DLC 6: segmented message with a 32-bit message id.
    Segm {
        /// Message id.
        id: u32,
    },
    /// DLC 4: port message with destination and source sub-ports.
    Port {
        /// Destination sub-port.
        dport: u8,
        /// Source sub-port.
        sport: u8,
    },
    /// DLC 8: UDP/IP message.
    Udp {
        /// Destination UDP port.
        dport: u16,
        /// Destination IPv4 address, `a.b.c.d` = `a<<24 | b<<16 | c<<8 | d`.
        daddr: u32,
    },
}

/// A decoded header frame payload.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Header {
    /// Message length in bytes.
    pub len: u16,
    /// Addressing.
    pub kind: Kind,
}

impl Header {
    /// Header payload bytes (DLC 6, 4 or 8).
    pub fn encode(&self) -> ([u8; 8], u8) {
        let mut b = [0u8; 8];
        b[..2].copy_from_slice(&self.len.to_be_bytes());
        let dlc = match self.kind {
            Kind::Segm { id } => {
                b[2..6].copy_from_slice(&id.to_be_bytes());
                6
            }
            Kind::Port { dport, sport } => {
                b[2] = dport;
                b[3] = sport;
                4
            }
            Kind::Udp { dport, daddr } => {
                b[2..4].copy_from_slice(&dport.to_be_bytes());
                b[4..8].copy_from_slice(&daddr.to_be_bytes());
                8
            }
        };
        (b, dlc)
    }

    /// Parses header payload bytes; `None` for a DLC other than 4, 6, 8.
    pub fn decode(b: &[u8]) -> Option<Header> {
        let len = match b {
            [h, l, ..] => u16::from_be_bytes([*h, *l]),
            _ => return None,
        };
        let kind = match b.len() {
            6 => Kind::Segm {
                id: u32::from_be_bytes([b[2], b[3], b[4], b[5]]),
            },
            4 => Kind::Port {
                dport: b[2],
                sport: b[3],
            },
            8 => Kind::Udp {
                dport: u16::from_be_bytes([b[2], b[3]]),
                daddr: u32::from_be_bytes([b[4], b[5], b[6], b[7]]),
            },
            _ => return None,
        };
        Some(Header { len, kind })
    }
}

/// Ack status (byte 2 of an ack; absent = OK).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Status {
    /// 0: accepted.
    Ok,
    /// 1: nobody wants this message (ECONNREFUSED at the sender).
    Refused,
    /// 2: receiver out of reassembly memory or slots (ENOBUFS).
    NoMemory,
    /// 3: message longer than the receiver accepts (EMSGSIZE).
    TooLong,
}

impl Status {
    /// Wire value.
    pub fn code(self) -> u8 {
        match self {
            Status::Ok => 0,
            Status::Refused => 1,
            Status::NoMemory => 2,
            Status::TooLong => 3,
        }
    }

    /// From a wire value; 4..=255 are undefined (the ack is malformed).
    pub fn from_code(c: u8) -> Option<Status> {
        match c {
            0 => Some(Status::Ok),
            1 => Some(Status::Refused),
            2 => Some(Status::NoMemory),
            3 => Some(Status::TooLong),
            _ => None,
        }
    }
}

/// A decoded ack payload.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Ack {
    /// Index of the acknowledged frame: 0 header, k body k.
    pub index: u16,
    /// Status.
    pub status: Status,
}

impl Ack {
    /// Ack payload: DLC 2 for OK (the short form), DLC 3 otherwise.
    pub fn encode(&self) -> ([u8; 8], u8) {
        let mut b = [0u8; 8];
        b[..2].copy_from_slice(&self.index.to_be_bytes());
        if self.status == Status::Ok {
            (b, 2)
        } else {
            b[2] = self.status.code();
            (b, 3)
        }
    }

    /// Parses an ack payload; `None` unless DLC is 2 or 3 and the status
    /// is defined.
    pub fn decode(b: &[u8]) -> Option<Ack> {
        match b {
            [h, l] => Some(Ack {
                index: u16::from_be_bytes([*h, *l]),
                status: Status::Ok,
            }),
            [h, l, s] => Some(Ack {
                index: u16::from_be_bytes([*h, *l]),
                status: Status::from_code(*s)?,
            }),
            _ => None,
        }
    }
}

/// An FD header (dsor-wire.rst, "FD header frame (T = 0)"): the classic
/// header's fields and the largest body size the sender offers.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FdHeader {
    /// Length and addressing, as in the classic header.
    pub header: Header,
    /// B_max: 12, 16, 20, 24, 32, 48 or 64.
    pub b_max: u8,
}

impl FdHeader {
    /// The 12 data bytes: the classic header's bytes zero-filled to 8,
    /// its DLC, B_max, two reserved zero bytes.
    pub fn encode(&self) -> [u8; 12] {
        let (b, dlc) = self.header.encode();
        let mut out = [0u8; 12];
        out[..usize::from(dlc)].copy_from_slice(&b[..usize::from(dlc)]);
        out[8] = dlc;
        out[9] = self.b_max;
        out
    }

    /// Parses the data of a 12-byte header frame; `None` if byte 8 is not
    /// 4, 6 or 8, byte 9 is not an FD body size above 8, or L <= 8 (all
    /// malformed: ignored). The reserved bytes and the zero fill are not
    /// looked at.
    pub fn decode(b: &[u8]) -> Option<FdHeader> {
        if b.len() != 12 {
            return None;
        }
        let dlc = usize::from(b[8]);
        if !matches!(dlc, 4 | 6 | 8) || !FD_LONG_LENS.contains(&usize::from(b[9])) {
            return None;
        }
        let header = Header::decode(&b[..dlc])?;
        if header.len <= 8 {
            return None;
        }
        Some(FdHeader {
            header,
            b_max: b[9],
        })
    }
}

/// The ack of an FD header (index 0, a classic frame of DLC 4): status and
/// the body size the receiver chose.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FdAck {
    /// Status.
    pub status: Status,
    /// Body size: 8 or an FD length above 8 (8 with a non-zero status).
    pub b: u8,
}

impl FdAck {
    /// The 4 data bytes: index 0, status, B.
    pub fn encode(&self) -> [u8; 4] {
        [0, 0, self.status.code(), self.b]
    }

    /// Parses a 4-byte ack payload; `None` unless the index is 0, the
    /// status is defined and, with status OK, byte 3 is a body size (with
    /// a non-zero status byte 3 is ignored).
    pub fn decode(b: &[u8]) -> Option<FdAck> {
        let [0, 0, s, sz] = *b else { return None };
        let status = Status::from_code(s)?;
        if status == Status::Ok && !valid_body_size(sz) {
            return None;
        }
        Some(FdAck { status, b: sz })
    }
}

/// Number of body frames of a message of `len` bytes (body size 8).
pub fn bodies(len: u16) -> u16 {
    bodies_of(len, 8)
}

/// Number of body frames of a message of `len` bytes with body size `b`.
pub fn bodies_of(len: u16, b: u8) -> u16 {
    len.div_ceil(u16::from(b))
}

/// DLC of body `k` (1-based) of a message of `len` bytes (body size 8).
pub fn body_dlc(len: u16, k: u16) -> u8 {
    body_payload(len, 8, k) as u8
}

/// Message bytes in body `k` (1-based) of a message of `len` bytes with
/// body size `b`: `b`, or what is left for the last body.
pub fn body_payload(len: u16, b: u8, k: u16) -> usize {
    let start = usize::from(b) * usize::from(k - 1);
    (usize::from(len) - start).min(usize::from(b))
}

/// Frame length of body `k` with body size `b`: the payload for classic
/// bodies (`b` = 8); for FD bodies `b`, and the FD length that holds the
/// last body's payload.
pub fn body_frame_len(len: u16, b: u8, k: u16) -> usize {
    let p = body_payload(len, b, k);
    if b == 8 {
        p
    } else {
        fd_len_round_up(p)
    }
}

/// Deterministic test content: byte `i` of message `j` is
/// `(i*31 + j*7 + seed) & 0xff`.
pub fn pattern(len: usize, j: u64, seed: u64) -> Vec<u8> {
    (0..len as u64)
        .map(|i| {
            (i.wrapping_mul(31)
                .wrapping_add(j.wrapping_mul(7))
                .wrapping_add(seed)
                & 0xff) as u8
        })
        .collect()
}

/// 64-bit FNV-1a hash (offset basis 0xcbf29ce484222325, prime
/// 0x100000001b3), printed as `sha=` (16 hex digits).
pub fn fnv1a64(b: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &x in b {
        h ^= u64::from(x);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Formats an IPv4 address number as `a.b.c.d`.
pub fn fmt_ipv4(a: u32) -> String {
    let b = a.to_be_bytes();
    format!("{}.{}.{}.{}", b[0], b[1], b[2], b[3])
}

/// Parses `a.b.c.d`.
pub fn parse_ipv4(s: &str) -> Option<u32> {
    let parts: Vec<&str> = s.split('.').collect();
    if parts.len() != 4 {
        return None;
    }
    let mut a = 0u32;
    for p in parts {
        if p.is_empty() || p.len() > 3 || !p.bytes().all(|c| c.is_ascii_digit()) {
            return None;
        }
        let v: u32 = p.parse().ok()?;
        if v > 255 {
            return None;
        }
        a = a << 8 | v;
    }
    Some(a)
}
