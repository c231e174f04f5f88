// SPDX-License-Identifier: GPL-2.0
//! The DSOR higher-layer protocol's frames (thesis 5.2.6 and 5.3.3; the wire
//! format is `Documentation/networking/rcan/dsor-wire.rst`, "Message
//! transfer"): the 29-bit identifier, header, body and ack frames, timers.
//!
//! Identifiers here are the 29 bits of a CAN 2.0B extended identifier
//! *without* the `CAN_EFF_FLAG`; the caller adds or strips it.

/// Largest message length (the header's 16-bit length field).
pub const MAX_LEN: usize = 65535;
/// Largest node number (7 bits).
pub const MAX_NODE: u8 = 0x7f;
/// Channels per (source, destination) pair (4 bits).
pub const CHANNELS: u8 = 16;
/// Largest priority value (8 bits).
pub const MAX_PRIO: u8 = 0xff;
/// Mask of the 29 identifier bits.
pub const ID_MASK: u32 = 0x1fff_ffff;

const P_SHIFT: u32 = 21;
const D_SHIFT: u32 = 14;
const S_SHIFT: u32 = 7;
const T_SHIFT: u32 = 5;
const Q_SHIFT: u32 = 4;

/// Frame type, identifier bits 6-5.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum FrameType {
    /// 0: header frame, starts a message.
    Header,
    /// 1: body frame, up to 8 message bytes.
    Body,
    /// 2: ack frame, from the receiver to the sender.
    Ack,
}

impl FrameType {
    /// The 2-bit wire value.
    pub const fn bits(self) -> u32 {
        match self {
            FrameType::Header => 0,
            FrameType::Body => 1,
            FrameType::Ack => 2,
        }
    }

    /// The type for a 2-bit wire value; `None` for the reserved value 3.
    pub const fn from_bits(b: u32) -> Option<FrameType> {
        match b & 3 {
            0 => Some(FrameType::Header),
            1 => Some(FrameType::Body),
            2 => Some(FrameType::Ack),
            _ => None,
        }
    }
}

/// The fields of a DSOR identifier:
/// `P << 21 | D << 14 | S << 7 | T << 5 | Q << 4 | C`.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct DsorId {
    /// Priority (8 bits, lower wins arbitration).
    pub prio: u8,
    /// Destination node (7 bits).
    pub dst: u8,
    /// Source node (7 bits).
    pub src: u8,
    /// Frame type.
    pub ftype: FrameType,
    /// Sequence bit Q.
    pub seq: bool,
    /// Channel (4 bits).
    pub chan: u8,
}

impl DsorId {
    /// The 29-bit identifier (no `CAN_EFF_FLAG`). Out-of-range node and
    /// channel values are truncated to their field width.
    pub const fn to_can_id(&self) -> u32 {
        (self.prio as u32) << P_SHIFT
            | ((self.dst & MAX_NODE) as u32) << D_SHIFT
            | ((self.src & MAX_NODE) as u32) << S_SHIFT
            | self.ftype.bits() << T_SHIFT
            | (self.seq as u32) << Q_SHIFT
            | (self.chan & (CHANNELS - 1)) as u32
    }

    /// Split a 29-bit identifier (bits above 28 are ignored, so a
    /// `can_id` with `CAN_EFF_FLAG` works too). `None` for the reserved
    /// frame type 3.
    pub const fn from_can_id(id29: u32) -> Option<Self> {
        let id = id29 & ID_MASK;
        let ftype = match FrameType::from_bits(id >> T_SHIFT) {
            Some(t) => t,
            None => return None,
        };
        Some(DsorId {
            prio: (id >> P_SHIFT) as u8,
            dst: ((id >> D_SHIFT) & 0x7f) as u8,
            src: ((id >> S_SHIFT) & 0x7f) as u8,
            ftype,
            seq: (id >> Q_SHIFT) & 1 != 0,
            chan: (id & 0xf) as u8,
        })
    }

    /// The identifier of the ack of the frame with this identifier: source
    /// and destination swapped, type ack, same priority, Q and channel.
    pub const fn ack_id(&self) -> DsorId {
        DsorId {
            prio: self.prio,
            dst: self.src,
            src: self.dst,
            ftype: FrameType::Ack,
            seq: self.seq,
            chan: self.chan,
        }
    }
}

/// Message type and addressing, told by the header frame's DLC.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum MsgKind {
    /// DLC 6: segmented message with a 32-bit message id
    /// (`sockaddr_cansegm`).
    Segm {
        /// Message id.
        id: u32,
    },
    /// DLC 4: port message (`sockaddr_canport`); only the sub-ports (low
    /// bytes of the 16-bit ports) are on the wire.
    Port {
        /// Destination sub-port.
        dport: u8,
        /// Source sub-port.
        sport: u8,
    },
    /// DLC 8: UDP/IP message; the message is the UDP payload.
    Udp {
        /// Destination UDP port.
        dport: u16,
        /// Destination IPv4 address (host value; big-endian on the wire).
        daddr: u32,
    },
}

impl MsgKind {
    /// The header frame's DLC for this type.
    pub const fn dlc(&self) -> u8 {
        match self {
            MsgKind::Segm { .. } => 6,
            MsgKind::Port { .. } => 4,
            MsgKind::Udp { .. } => 8,
        }
    }
}

/// Contents of a header frame.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Header {
    /// Message length in bytes.
    pub len: u16,
    /// Type and addressing.
    pub kind: MsgKind,
}

impl Header {
    /// Write the header's data bytes into `out` (unused bytes zeroed) and
    /// return the DLC (4, 6 or 8).
    pub fn encode(&self, out: &mut [u8; 8]) -> u8 {
        *out = [0; 8];
        out[0..2].copy_from_slice(&self.len.to_be_bytes());
        match self.kind {
            MsgKind::Segm { id } => out[2..6].copy_from_slice(&id.to_be_bytes()),
            MsgKind::Port { dport, sport } => {
                out[2] = dport;
                out[3] = sport;
            }
            MsgKind::Udp { dport, daddr } => {
                out[2..4].copy_from_slice(&dport.to_be_bytes());
                out[4..8].copy_from_slice(&daddr.to_be_bytes());
            }
        }
        self.kind.dlc()
    }

    /// Parse a header frame's data (its length is the DLC); `None` unless
    /// the DLC is 4, 6 or 8.
    pub fn decode(data: &[u8]) -> Option<Self> {
        let len = match data {
            [a, b, ..] => u16::from_be_bytes([*a, *b]),
            _ => return None,
        };
        let kind = match *data {
            [_, _, a, b, c, d] => MsgKind::Segm {
                id: u32::from_be_bytes([a, b, c, d]),
            },
            [_, _, dport, sport] => MsgKind::Port { dport, sport },
            [_, _, p0, p1, a, b, c, d] => MsgKind::Udp {
                dport: u16::from_be_bytes([p0, p1]),
                daddr: u32::from_be_bytes([a, b, c, d]),
            },
            _ => return None,
        };
        Some(Header { len, kind })
    }

    /// Number of body frames of this message.
    pub const fn bodies(&self) -> u16 {
        body_count(self.len)
    }
}

/// Status byte of an ack.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum AckStatus {
    /// 0: frame received.
    Ok,
    /// 1: nobody on the receiver wants the message (`ECONNREFUSED`).
    Refused,
    /// 2: receiver out of reassembly memory or slots (`ENOBUFS`).
    NoMemory,
    /// 3: message longer than the receiver accepts (`EMSGSIZE`).
    TooLong,
}

impl AckStatus {
    /// The wire value.
    pub const fn code(self) -> u8 {
        match self {
            AckStatus::Ok => 0,
            AckStatus::Refused => 1,
            AckStatus::NoMemory => 2,
            AckStatus::TooLong => 3,
        }
    }

    /// The status for a wire value; `None` for 4-255 (malformed ack).
    pub const fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(AckStatus::Ok),
            1 => Some(AckStatus::Refused),
            2 => Some(AckStatus::NoMemory),
            3 => Some(AckStatus::TooLong),
            _ => None,
        }
    }
}

/// Contents of an ack frame.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Ack {
    /// Index of the acknowledged frame: 0 the header, k body k.
    pub index: u16,
    /// Status (non-`Ok` only for headers).
    pub status: AckStatus,
}

impl Ack {
    /// Write the ack's data into `out` (unused bytes zeroed) and return the
    /// DLC: 2 for `Ok`, 3 otherwise.
    pub fn encode(&self, out: &mut [u8; 8]) -> u8 {
        *out = [0; 8];
        out[0..2].copy_from_slice(&self.index.to_be_bytes());
        match self.status {
            AckStatus::Ok => 2,
            s => {
                out[2] = s.code();
                3
            }
        }
    }

    /// Parse an ack frame's data: DLC 2 (status `Ok`) or 3; `None` for any
    /// other DLC or a status above 3.
    pub fn decode(data: &[u8]) -> Option<Self> {
        match *data {
            [a, b] => Some(Ack {
                index: u16::from_be_bytes([a, b]),
                status: AckStatus::Ok,
            }),
            [a, b, s] => Some(Ack {
                index: u16::from_be_bytes([a, b]),
                status: AckStatus::from_code(s)?,
            }),
            _ => None,
        }
    }
}

/// A CAN frame as DSOR sends it: extended data frame, 29-bit identifier
/// without `CAN_EFF_FLAG`.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Frame {
    /// 29-bit identifier (no `CAN_EFF_FLAG`).
    pub id: u32,
    /// DLC, 0-8.
    pub len: u8,
    /// Data; bytes from `len` on are zero.
    pub data: [u8; 8],
}

impl Frame {
    /// The data bytes (`data[..len]`).
    pub fn payload(&self) -> &[u8] {
        &self.data[..(self.len as usize).min(8)]
    }

    /// A header frame.
    pub fn header(id: &DsorId, h: &Header) -> Frame {
        let mut data = [0; 8];
        let len = h.encode(&mut data);
        Frame {
            id: id.to_can_id(),
            len,
            data,
        }
    }

    /// An ack frame.
    pub fn ack(id: &DsorId, a: &Ack) -> Frame {
        let mut data = [0; 8];
        let len = a.encode(&mut data);
        Frame {
            id: id.to_can_id(),
            len,
            data,
        }
    }
}

/// Number of body frames of an `len`-byte message: ceil(len / 8).
pub const fn body_count(len: u16) -> u16 {
    (len as u32).div_ceil(8) as u16
}

/// DLC of body `k` (1-based) of an `len`-byte message: min(8, len - 8(k-1));
/// 0 if there is no such body.
pub const fn body_dlc(len: u16, k: u16) -> u8 {
    if k == 0 || k > body_count(len) {
        return 0;
    }
    let off = 8 * (k as u32 - 1);
    let rest = len as u32 - off;
    if rest > 8 {
        8
    } else {
        rest as u8
    }
}

/// `(id, mask)` over 29-bit identifiers that accepts every DSOR frame
/// addressed to node `local` (destination field equal to `local`; other
/// fields free). The caller adds "extended, not remote" to the filter.
pub const fn rx_filter(local: u8) -> (u32, u32) {
    (
        ((local & MAX_NODE) as u32) << D_SHIFT,
        (MAX_NODE as u32) << D_SHIFT,
    )
}

/// Protocol timers (dsor-wire.rst, "Timers and limits").
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct Timers {
    /// T_ack: sender's wait for an ack before retransmitting (ms).
    pub ack_timeout_ms: u32,
    /// N_retx: retransmissions of one frame before the message fails.
    pub max_retx: u32,
    /// T_reasm: receiver's lifetime of a state without frames (ms).
    pub reasm_timeout_ms: u32,
}

impl Timers {
    /// The defaults: 100 ms, 10, 2000 ms.
    pub const DEFAULT: Timers = Timers {
        ack_timeout_ms: 100,
        max_retx: 10,
        reasm_timeout_ms: 2000,
    };

    /// Whether T_reasm > T_ack * (N_retx + 1), the condition of the
    /// delivery guarantees.
    pub const fn consistent(&self) -> bool {
        (self.reasm_timeout_ms as u64) > self.ack_timeout_ms as u64 * (self.max_retx as u64 + 1)
    }
}

impl Default for Timers {
    fn default() -> Self {
        Timers::DEFAULT
    }
}

// ---------------------------------------------------------------------------
// CAN FD bodies (dsor-wire.rst, "Message transfer with CAN FD bodies
// (extension)"). Here rather than in `dsor_fd` because the receiver
// (`dsor_rx`) needs them; `dsor_fd` re-exports them without the `fd_`
// prefix and adds the sender.
// ---------------------------------------------------------------------------

/// Largest CAN FD payload.
pub const FD_MAX_LEN: usize = 64;
/// The CAN FD lengths above 8 (DLC 9-15), ISO 11898-1:2015.
pub const FD_LENS: [u8; 7] = [12, 16, 20, 24, 32, 48, 64];
/// Length of an FD header frame (DLC 9).
pub const FD_HEADER_LEN: u8 = 12;
/// DLC of the ack of an FD header.
pub const FD_ACK_LEN: u8 = 4;

/// The smallest valid CAN FD length >= `r` (0-8 are themselves); `None`
/// for `r` > 64.
pub const fn fd_len_round_up(r: usize) -> Option<u8> {
    if r <= 8 {
        return Some(r as u8);
    }
    let mut i = 0;
    while i < FD_LENS.len() {
        if FD_LENS[i] as usize >= r {
            return Some(FD_LENS[i]);
        }
        i += 1;
    }
    None
}

/// Whether `len` is a valid CAN FD frame length (0-8, 12, 16, 20, 24, 32,
/// 48, 64).
pub const fn is_fd_len(len: usize) -> bool {
    matches!(fd_len_round_up(len), Some(l) if l as usize == len)
}

/// The DLC (0-15) of a valid CAN FD length; `None` otherwise.
pub const fn fd_len_to_dlc(len: usize) -> Option<u8> {
    if len <= 8 {
        return Some(len as u8);
    }
    let mut i = 0;
    while i < FD_LENS.len() {
        if FD_LENS[i] as usize == len {
            return Some(9 + i as u8);
        }
        i += 1;
    }
    None
}

/// The length of a CAN FD DLC (0-15; higher bits ignored).
pub const fn fd_dlc_to_len(dlc: u8) -> u8 {
    let d = dlc & 0xf;
    if d <= 8 {
        d
    } else {
        FD_LENS[(d - 9) as usize]
    }
}

/// The body size B of a message: 8 (classic bodies) or a CAN FD length
/// 12-64.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Debug)]
pub struct BodySize(u8);

impl BodySize {
    /// 8: classic bodies.
    pub const CLASSIC: BodySize = BodySize(8);
    /// 64: the largest.
    pub const MAX: BodySize = BodySize(64);
    /// Every body size, smallest first.
    pub const ALL: [BodySize; 8] = [
        BodySize(8),
        BodySize(12),
        BodySize(16),
        BodySize(20),
        BodySize(24),
        BodySize(32),
        BodySize(48),
        BodySize(64),
    ];

    /// The body size `b`, if it is 8 or one of the FD lengths 12-64.
    pub const fn new(b: u8) -> Option<Self> {
        if b == 8 || (b > 8 && is_fd_len(b as usize)) {
            Some(BodySize(b))
        } else {
            None
        }
    }

    /// The size in bytes.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Whether bodies of this size are CAN FD frames (B > 8).
    pub const fn is_fd(self) -> bool {
        self.0 > 8
    }
}

/// Number of bodies of an `len`-byte message with body size `b`:
/// ceil(len / B).
pub const fn fd_body_count(len: u16, b: BodySize) -> u16 {
    // `max(1)`: a BodySize is never 0, but the compiler cannot see it;
    // this keeps a division-by-zero panic path out of the kernel build.
    (len as u32).div_ceil(if b.0 == 0 { 1 } else { b.0 as u32 }) as u16
}

/// Payload bytes of body `k` (1-based): min(B, len - B(k-1)); 0 if there
/// is no such body.
pub const fn fd_body_payload(len: u16, b: BodySize, k: u16) -> usize {
    if k == 0 || k > fd_body_count(len, b) {
        return 0;
    }
    let rest = len as usize - b.0 as usize * (k as usize - 1);
    if rest > b.0 as usize {
        b.0 as usize
    } else {
        rest
    }
}

/// On-wire length of body `k`: its payload rounded up to a CAN FD length
/// (only the last body can need padding); 0 if there is no such body. For
/// [`BodySize::CLASSIC`] this is `dsor_wire::body_dlc`.
pub const fn fd_body_frame_len(len: u16, b: BodySize, k: u16) -> u8 {
    match fd_len_round_up(fd_body_payload(len, b, k)) {
        Some(l) => l,
        None => 0,
    }
}

/// A DSOR frame that may be a CAN FD frame.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct FdFrame {
    /// 29-bit identifier (no `CAN_EFF_FLAG`).
    pub id: u32,
    /// Length in bytes: 0-8 or a CAN FD length (12-64 only with `fdf`).
    pub len: u8,
    /// Whether this is a CAN FD frame (FDF 1).
    pub fdf: bool,
    /// Data; bytes from `len` on, and padding, are zero.
    pub data: [u8; FD_MAX_LEN],
}

impl FdFrame {
    /// The data bytes (`data[..len]`), padding included.
    pub fn payload(&self) -> &[u8] {
        &self.data[..(self.len as usize).min(FD_MAX_LEN)]
    }

    /// The classic frame, if this is one (not FD).
    pub fn classic(&self) -> Option<Frame> {
        if self.fdf || self.len > 8 {
            return None;
        }
        let mut data = [0; 8];
        data.copy_from_slice(&self.data[..8]);
        Some(Frame {
            id: self.id,
            len: self.len,
            data,
        })
    }
}

impl From<Frame> for FdFrame {
    fn from(f: Frame) -> Self {
        let mut data = [0; FD_MAX_LEN];
        data[..8].copy_from_slice(&f.data);
        FdFrame {
            id: f.id,
            len: f.len,
            fdf: false,
            data,
        }
    }
}

/// Contents of an FD header frame: the classic header plus the largest
/// body size the sender offers (12-64).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct FdHeader {
    /// Length and addressing, as in a classic header.
    pub header: Header,
    /// B_max: the largest body size offered; an FD size (12-64).
    pub max_body: BodySize,
}

impl FdHeader {
    /// Length of an FD header frame ([`FD_HEADER_LEN`]).
    pub const LEN: usize = FD_HEADER_LEN as usize;

    /// An FD header for `header` offering `max_body`; `None` if the
    /// message is too short for one (L <= 8) or `max_body` is not an FD
    /// size.
    pub const fn new(header: Header, max_body: BodySize) -> Option<Self> {
        if header.len <= 8 || !max_body.is_fd() {
            return None;
        }
        Some(FdHeader { header, max_body })
    }

    /// Write the 12 data bytes into `out` (the rest zeroed); returns
    /// [`FD_HEADER_LEN`].
    pub fn encode(&self, out: &mut [u8; FD_MAX_LEN]) -> u8 {
        *out = [0; FD_MAX_LEN];
        let mut classic = [0; 8];
        let dlc = self.header.encode(&mut classic);
        out[..8].copy_from_slice(&classic);
        out[8] = dlc;
        out[9] = self.max_body.get();
        FD_HEADER_LEN
    }

    /// Parse an FD header frame's data (its length is the frame's): `None`
    /// unless it is 12 bytes with a type byte of 4, 6 or 8, an FD size in
    /// byte 9 and L > 8. Bytes 10-11 and the bytes past the classic
    /// header's length are ignored.
    pub fn decode(data: &[u8]) -> Option<Self> {
        if data.len() != FD_HEADER_LEN as usize {
            return None;
        }
        let dlc = data[8] as usize;
        if !matches!(dlc, 4 | 6 | 8) {
            return None;
        }
        let header = Header::decode(&data[..dlc])?;
        let max_body = BodySize::new(data[9])?;
        FdHeader::new(header, max_body)
    }

    /// The FD header frame with identifier `id` (its type is set to
    /// header).
    pub fn frame(&self, id: &DsorId) -> FdFrame {
        let mut data = [0; FD_MAX_LEN];
        let len = self.encode(&mut data);
        FdFrame {
            id: DsorId {
                ftype: FrameType::Header,
                ..*id
            }
            .to_can_id(),
            len,
            fdf: true,
            data,
        }
    }

    /// The message type (as for the classic header).
    pub fn kind(&self) -> MsgKind {
        self.header.kind
    }
}

/// Contents of the ack of an FD header (index 0, DLC 4).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub struct FdAck {
    /// Status, as for classic acks.
    pub status: AckStatus,
    /// The body size the receiver chose (8 with a non-OK status).
    pub body: BodySize,
}

impl FdAck {
    /// Write the ack's data into `out` (unused bytes zeroed); returns
    /// [`FD_ACK_LEN`].
    pub fn encode(&self, out: &mut [u8; 8]) -> u8 {
        *out = [0; 8];
        out[2] = self.status.code();
        out[3] = self.body.get();
        FD_ACK_LEN
    }

    /// Parse an ack frame's data as the ack of an FD header that offered
    /// `offered`: `None` unless it is 4 bytes, index 0, a known status
    /// and (for status OK) a body size not above `offered`.
    pub fn decode(data: &[u8], offered: BodySize) -> Option<Self> {
        let [0, 0, s, b] = *data else {
            return None;
        };
        let status = AckStatus::from_code(s)?;
        let body = match status {
            AckStatus::Ok => match BodySize::new(b) {
                Some(b) if b <= offered => b,
                _ => return None,
            },
            _ => BodySize::CLASSIC,
        };
        Some(FdAck { status, body })
    }

    /// The ack frame with identifier `id` (a classic frame).
    pub fn frame(&self, id: &DsorId) -> Frame {
        let mut data = [0; 8];
        let len = self.encode(&mut data);
        Frame {
            id: id.to_can_id(),
            len,
            data,
        }
    }
}

/// Body `k` (1 ..= n) of the `len`-byte message `msg` with body size `b`,
/// identifier `id` (type set to body; the caller sets Q). The payload is
/// `msg[B(k-1) ..]` (missing bytes are sent as zero, as in
/// `Transfer::frame`), padded with zeros to [`fd_body_frame_len`]. An FD
/// frame for B > 8, a classic one (identical to the classic body) for
/// B = 8. Length 0 if there is no body `k`.
pub fn fd_body_frame(id: &DsorId, msg: &[u8], len: u16, b: BodySize, k: u16) -> FdFrame {
    let r = fd_body_payload(len, b, k);
    let off = if k == 0 {
        0
    } else {
        b.get() as usize * (k as usize - 1)
    };
    let mut data = [0; FD_MAX_LEN];
    for (i, d) in data.iter_mut().enumerate().take(r) {
        *d = msg.get(off + i).copied().unwrap_or(0);
    }
    FdFrame {
        id: DsorId {
            ftype: FrameType::Body,
            ..*id
        }
        .to_can_id(),
        len: fd_body_frame_len(len, b, k),
        fdf: b.is_fd(),
        data,
    }
}

/// Whether `frame_len` is the right length of body `k` of an `len`-byte
/// message with body size `b`.
pub const fn fd_body_len_ok(len: u16, b: BodySize, k: u16, frame_len: usize) -> bool {
    let want = fd_body_frame_len(len, b, k);
    want != 0 && frame_len == want as usize
}

/// Store received body `k` (its frame's data bytes, padding included) of
/// an `len`-byte message with body size `b` into `buf`, the message
/// buffer (at least `len` bytes). Returns the payload bytes stored, or
/// `None` (nothing stored) if the body's length is wrong (malformed) or
/// `buf` is too short. Padding values are ignored.
pub fn fd_store_body(buf: &mut [u8], len: u16, b: BodySize, k: u16, data: &[u8]) -> Option<usize> {
    if !fd_body_len_ok(len, b, k, data.len()) {
        return None;
    }
    let r = fd_body_payload(len, b, k);
    let off = b.get() as usize * (k as usize - 1);
    buf.get_mut(off..off + r)?.copy_from_slice(&data[..r]);
    Some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn id_fields() {
        let id = DsorId {
            prio: 0x40,
            dst: 0,
            src: 5,
            ftype: FrameType::Header,
            seq: false,
            chan: 0,
        };
        assert_eq!(id.to_can_id(), 0x0800_0280);
        assert_eq!(DsorId::from_can_id(0x0800_0280), Some(id));
        assert_eq!(id.ack_id().to_can_id(), 0x0801_4040);
        assert_eq!(DsorId::from_can_id(0x60), None);
        assert_eq!(DsorId::from_can_id(0x8800_0280), Some(id));
    }

    #[test]
    fn lengths() {
        assert_eq!(body_count(0), 0);
        assert_eq!(body_count(1), 1);
        assert_eq!(body_count(8), 1);
        assert_eq!(body_count(9), 2);
        assert_eq!(body_count(65535), 8192);
        assert_eq!(body_dlc(10, 1), 8);
        assert_eq!(body_dlc(10, 2), 2);
        assert_eq!(body_dlc(16, 2), 8);
        assert_eq!(body_dlc(16, 3), 0);
        assert_eq!(body_dlc(65535, 8192), 7);
    }

    #[test]
    fn header_and_ack() {
        let mut b = [0; 8];
        let h = Header {
            len: 10,
            kind: MsgKind::Segm { id: 0x1234_5678 },
        };
        assert_eq!(h.encode(&mut b), 6);
        assert_eq!(b, [0, 10, 0x12, 0x34, 0x56, 0x78, 0, 0]);
        assert_eq!(Header::decode(&b[..6]), Some(h));
        for dlc in [0, 1, 2, 3, 5, 7] {
            assert_eq!(Header::decode(&b[..dlc]), None);
        }
        let a = Ack {
            index: 0x102,
            status: AckStatus::TooLong,
        };
        assert_eq!(a.encode(&mut b), 3);
        assert_eq!(&b[..3], &[1, 2, 3]);
        assert_eq!(Ack::decode(&b[..3]), Some(a));
        assert_eq!(Ack::decode(&[0, 1, 4]), None);
        assert_eq!(Ack::decode(&[0]), None);
        assert_eq!(Ack::decode(&[0, 1, 0, 0]), None);
        assert_eq!(rx_filter(0x21), (0x84000, 0x1fc000));
        assert!(Timers::default().consistent());
    }
}
