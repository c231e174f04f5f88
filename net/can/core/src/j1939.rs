// SPDX-License-Identifier: GPL-2.0
//! CAN_J1939 (SAE J1939-21/-81) socket ABI and addressing: the constants
//! and layouts of mainline's `include/uapi/linux/can/j1939.h` (6.12), the
//! 29-bit identifier <-> (priority, PGN, source, destination) mapping,
//! the PGN checks of `bind`/`connect`/`sendmsg`, the socket options'
//! checks and the receive matching of a socket (destination, source, PGN
//! and `SO_J1939_FILTER`), all rewritten from what mainline's
//! `net/can/j1939/` does. Pure functions, no state: one set exists.
//!
//! The address claim table is [`super::j1939_ac`], the transport
//! protocols are [`super::j1939_tp`]. Documentation/networking/rcan/j1939.rst
//! describes the whole and lists where we chose mainline's behaviour over
//! the standard's, or the other way.
//!
//! Identifier layout (J1939-21 5.2, extended frames only):
//!
//! ```text
//!  bit 28..26  priority (0 highest, 7 lowest)
//!  bit 25      reserved (R, "extended data page" in later editions)
//!  bit 24      data page (DP)
//!  bit 23..16  PDU format (PF)
//!  bit 15..8   PDU specific (PS): destination address if PF < 240 (PDU1),
//!              group extension otherwise (PDU2, always broadcast)
//!  bit 7..0    source address
//! ```
//!
//! The PGN is bits 25..8 (18 bits): R, DP, PF and PS, with PS = 0 for
//! PDU1 PGNs, whose PS byte is the destination instead.

use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, EINVAL};

/// `AF_CAN` (here rather than from `sockaddr`, so that the module needs
/// only `arb` besides the J1939 files).
pub const AF_CAN: u16 = 29;

/// `CAN_J1939` (`<linux/can.h>`): `socket(PF_CAN, SOCK_DGRAM, 7)`.
pub const CAN_J1939: i32 = 7;
/// `SOL_CAN_BASE` of `<linux/can.h>`.
pub const SOL_CAN_BASE: i32 = 100;
/// `SOL_CAN_J1939`: the socket option level.
pub const SOL_CAN_J1939: i32 = SOL_CAN_BASE + CAN_J1939;

/// The highest unicast address; 0xFE and 0xFF are special.
pub const J1939_MAX_UNICAST_ADDR: u8 = 0xfd;
/// The "null" address of a node that could not claim one.
pub const J1939_IDLE_ADDR: u8 = 0xfe;
/// No address (bind) or the global (broadcast) destination.
pub const J1939_NO_ADDR: u8 = 0xff;
/// No NAME (a socket or destination given by address only).
pub const J1939_NO_NAME: u64 = 0;
/// The Request PGN (59904).
pub const J1939_PGN_REQUEST: u32 = 0x0ea00;
/// The Address Claimed PGN (60928).
pub const J1939_PGN_ADDRESS_CLAIMED: u32 = 0x0ee00;
/// The Commanded Address PGN (65240).
pub const J1939_PGN_ADDRESS_COMMANDED: u32 = 0x0fed8;
/// The PGN mask of a PDU1 PGN (PS is the destination).
pub const J1939_PGN_PDU1_MAX: u32 = 0x3ff00;
/// The largest PGN (18 bits).
pub const J1939_PGN_MAX: u32 = 0x3ffff;
/// No PGN: in a socket address, "not given".
pub const J1939_NO_PGN: u32 = 0x40000;

/// `SO_J1939_FILTER`: an array of [`Filter`] images (none: receive all).
pub const SO_J1939_FILTER: i32 = 1;
/// `SO_J1939_PROMISC`: an `int` flag, receive what is not for us too.
pub const SO_J1939_PROMISC: i32 = 2;
/// `SO_J1939_SEND_PRIO`: an `int` 0..=7, the priority of sent frames.
pub const SO_J1939_SEND_PRIO: i32 = 3;
/// `SO_J1939_ERRQUEUE`: an `int` flag, report sessions on the error queue.
pub const SO_J1939_ERRQUEUE: i32 = 4;

/// cmsg `SCM_J1939_DEST_ADDR` (`u8`).
pub const SCM_J1939_DEST_ADDR: i32 = 1;
/// cmsg `SCM_J1939_DEST_NAME` (`u64`).
pub const SCM_J1939_DEST_NAME: i32 = 2;
/// cmsg `SCM_J1939_PRIO` (`u8`).
pub const SCM_J1939_PRIO: i32 = 3;
/// cmsg level/type of error queue messages.
pub const SCM_J1939_ERRQUEUE: i32 = 4;

/// Netlink attribute padding in error-queue statistics.
pub const J1939_NLA_PAD: i32 = 0;
/// `u32`: bytes the peer acknowledged (CTS) or, for a simple send, sent.
pub const J1939_NLA_BYTES_ACKED: i32 = 1;
/// `u32`: the size of a session announced by RTS.
pub const J1939_NLA_TOTAL_SIZE: i32 = 2;
/// `u32`: the PGN of the session.
pub const J1939_NLA_PGN: i32 = 3;
/// `u64`: the source NAME.
pub const J1939_NLA_SRC_NAME: i32 = 4;
/// `u64`: the destination NAME.
pub const J1939_NLA_DEST_NAME: i32 = 5;
/// `u8`: the source address.
pub const J1939_NLA_SRC_ADDR: i32 = 6;
/// `u8`: the destination address.
pub const J1939_NLA_DEST_ADDR: i32 = 7;

/// `ee_info` of an error queue message: nothing.
pub const J1939_EE_INFO_NONE: i32 = 0;
/// `ee_info`: a transmit session was aborted (`ee_errno` says why).
pub const J1939_EE_INFO_TX_ABORT: i32 = 1;
/// `ee_info`: a receive session started (RTS or BAM).
pub const J1939_EE_INFO_RX_RTS: i32 = 2;
/// `ee_info`: an ETP receive session got a data packet offset.
pub const J1939_EE_INFO_RX_DPO: i32 = 3;
/// `ee_info`: a receive session was aborted.
pub const J1939_EE_INFO_RX_ABORT: i32 = 4;

/// Most filters one `SO_J1939_FILTER` takes.
pub const J1939_FILTER_MAX: usize = 512;

/// `J1939_MIN_NAMELEN`: the bytes of `struct sockaddr_can` up to the end
/// of `can_addr.j1939` (family, padding, ifindex, then name, pgn, addr
/// and 3 bytes of padding).
pub const SOCKADDR_J1939_LEN: usize = 24;

/// Smallest payload sent with TP (`J1939_MIN_TP_PACKET_SIZE`).
pub const MIN_TP_SIZE: usize = 9;
/// Largest payload of TP: 255 packets of 7 bytes.
pub const MAX_TP_SIZE: usize = 7 * 0xff;
/// Largest payload of ETP: 0xFFFFFF packets of 7 bytes (117,440,505).
pub const MAX_ETP_SIZE: usize = 7 * 0x00ff_ffff;

/// The priority of a new socket's frames (`SO_J1939_SEND_PRIO`).
pub const DEFAULT_PRIO: u8 = 6;

/// `EPERM`: a priority below 2 without `CAP_NET_ADMIN`.
pub const EPERM: i32 = 1;
/// `EAGAIN`: an identical session is active.
pub const EAGAIN: i32 = 11;
/// `EACCES`: broadcast without `SO_BROADCAST`.
pub const EACCES: i32 = 13;
/// `EBUSY`: the socket's send queue cannot activate a session.
pub const EBUSY: i32 = 16;
/// `ENODEV`: interface index 0, or no such ECU for a NAME.
pub const ENODEV: i32 = 19;
/// `EDOM`: a priority outside 0..=7, or a send on a TP/ETP PGN.
pub const EDOM: i32 = 33;
/// `ETIME`: a simple (single-frame) send not echoed in time.
pub const ETIME: i32 = 62;
/// `EPROTO`: a malformed address claim, or most abort reasons.
pub const EPROTO: i32 = 71;
/// `EBADMSG`: abort reason 4.
pub const EBADMSG: i32 = 74;
/// `EBADFD`: send on an unbound socket or one without source.
pub const EBADFD: i32 = 77;
/// `EILSEQ`: abort reason 7.
pub const EILSEQ: i32 = 84;
/// `EDESTADDRREQ`: no address given, or ETP to broadcast.
pub const EDESTADDRREQ: i32 = 89;
/// `EMSGSIZE`: abort reason 2, or a message over the size limit.
pub const EMSGSIZE: i32 = 90;
/// `ENOPROTOOPT`: an unknown socket option.
pub const ENOPROTOOPT: i32 = 92;
/// `EADDRNOTAVAIL`: a NAME without a claimed address.
pub const EADDRNOTAVAIL: i32 = 99;
/// `ENETDOWN`: the interface went down.
pub const ENETDOWN: i32 = 100;
/// `ENETUNREACH`: the device kept refusing frames (retry limit).
pub const ENETUNREACH: i32 = 101;
/// `ENOTCONN`: abort reason 6.
pub const ENOTCONN: i32 = 107;
/// `ESHUTDOWN`: a session cancelled by ifdown or socket close.
pub const ESHUTDOWN: i32 = 108;
/// `EHOSTUNREACH`: abort reason 3 (a timeout).
pub const EHOSTUNREACH: i32 = 113;
/// `EALREADY`: abort reason 1.
pub const EALREADY: i32 = 114;
/// `ENOTRECOVERABLE`: abort reason 5.
pub const ENOTRECOVERABLE: i32 = 131;

/// Whether `addr` is a unicast address (0..=0xFD).
pub const fn addr_is_unicast(addr: u8) -> bool {
    addr <= J1939_MAX_UNICAST_ADDR
}

/// Whether `pgn` is a PDU1 PGN (PF < 240; DP and R are not looked at).
pub const fn pgn_is_pdu1(pgn: u32) -> bool {
    (pgn & 0xff00) < 0xf000
}

/// Whether `pgn` is a PGN at all (a socket address with a larger value,
/// [`J1939_NO_PGN`] say, gives none).
pub const fn pgn_is_valid(pgn: u32) -> bool {
    pgn <= J1939_PGN_MAX
}

/// Whether a PDU1 `pgn` has a zero PS byte (the destination is never
/// written into the PGN); PDU2 PGNs are always clean.
pub const fn pgn_is_clean_pdu(pgn: u32) -> bool {
    !pgn_is_pdu1(pgn) || pgn & 0xff == 0
}

/// The PGN as transmitted (`j1939_send_one`): a PDU1 PGN loses its PS
/// byte, any PGN its bits above 17.
pub const fn pgn_for_send(pgn: u32) -> u32 {
    if pgn_is_pdu1(pgn) {
        pgn & J1939_PGN_PDU1_MAX
    } else {
        pgn & J1939_PGN_MAX
    }
}

/// `SO_J1939_SEND_PRIO` as `sk_priority`: J1939 priority 0 is the most
/// urgent, `sk_priority` 7 the highest, so they are mirrored.
pub const fn prio_to_sk_priority(prio: u8) -> u32 {
    7 - (prio & 7) as u32
}

/// The J1939 priority of an `sk_priority` (clamped to 7 first, so a
/// large `SO_PRIORITY` becomes J1939 priority 0).
pub const fn sk_priority_to_prio(sk_priority: u32) -> u8 {
    let p = if sk_priority > 7 { 7 } else { sk_priority };
    (7 - p) as u8
}

/// The addressing of one J1939 frame: what the identifier carries.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Id {
    /// Priority 0..=7.
    pub prio: u8,
    /// The PGN, PS zero for PDU1.
    pub pgn: u32,
    /// Source address.
    pub sa: u8,
    /// Destination address; [`J1939_NO_ADDR`] for PDU2 (broadcast).
    pub da: u8,
}

impl Id {
    /// The `can_id` (with `CAN_EFF_FLAG`) mainline's `j1939_send_one`
    /// builds: the PGN is cut as [`pgn_for_send`] does, a priority over
    /// 7 becomes 6, and for a PDU1 PGN the destination fills PS.
    pub const fn to_can_id(self) -> u32 {
        let pgn = pgn_for_send(self.pgn);
        let prio = if self.prio > 7 { 6 } else { self.prio };
        let mut id = CAN_EFF_FLAG | (prio as u32) << 26 | pgn << 8 | self.sa as u32;
        if pgn_is_pdu1(pgn) {
            id |= (self.da as u32) << 8;
        }
        id
    }

    /// The addressing of a received `can_id` (mainline's
    /// `j1939_can_recv`): `None` for a standard, remote or error frame,
    /// and for source address 0xFF, which mainline drops.
    pub const fn from_can_id(can_id: u32) -> Option<Id> {
        if can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG) != CAN_EFF_FLAG {
            return None;
        }
        let id = can_id & CAN_EFF_MASK;
        let sa = (id & 0xff) as u8;
        if sa == J1939_NO_ADDR {
            return None;
        }
        let pgn = (id >> 8) & J1939_PGN_MAX;
        let (pgn, da) = if pgn_is_pdu1(pgn) {
            (pgn & J1939_PGN_PDU1_MAX, (pgn & 0xff) as u8)
        } else {
            (pgn, J1939_NO_ADDR)
        };
        Some(Id {
            prio: ((id >> 26) & 7) as u8,
            pgn,
            sa,
            da,
        })
    }

    /// Whether the frame goes to everyone (destination 0xFF).
    pub const fn is_broadcast(&self) -> bool {
        self.da == J1939_NO_ADDR
    }
}

/// One J1939 frame: its addressing and up to 8 data bytes.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Frame {
    /// The addressing.
    pub id: Id,
    /// Data length, 0..=8.
    pub len: u8,
    /// Data; bytes from `len` on are zero.
    pub data: [u8; 8],
}

impl Frame {
    /// A frame with `data` (at most 8 bytes are taken).
    pub fn new(id: Id, data: &[u8]) -> Frame {
        let n = data.len().min(8);
        let mut d = [0u8; 8];
        d[..n].copy_from_slice(&data[..n]);
        Frame {
            id,
            len: n as u8,
            data: d,
        }
    }

    /// The data bytes.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len).min(8)]
    }
}

/// A socket address's J1939 part with its interface
/// (`struct sockaddr_can` with `can_addr.j1939`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct SockAddr {
    /// `can_ifindex`.
    pub ifindex: i32,
    /// `can_addr.j1939.name`; [`J1939_NO_NAME`]: none.
    pub name: u64,
    /// `can_addr.j1939.pgn`; above [`J1939_PGN_MAX`]: none.
    pub pgn: u32,
    /// `can_addr.j1939.addr`.
    pub addr: u8,
}

impl SockAddr {
    /// Reads the first [`SOCKADDR_J1939_LEN`] bytes of `b` (native
    /// endian; the family is checked by the callers' checks below).
    /// `EINVAL` when shorter, or when the family is not `AF_CAN`.
    pub fn parse(b: &[u8]) -> Result<SockAddr, i32> {
        let b: &[u8; SOCKADDR_J1939_LEN] = b
            .get(..SOCKADDR_J1939_LEN)
            .and_then(|h| h.try_into().ok())
            .ok_or(EINVAL)?;
        if u16::from_ne_bytes([b[0], b[1]]) != AF_CAN {
            return Err(EINVAL);
        }
        Ok(SockAddr {
            ifindex: i32::from_ne_bytes([b[4], b[5], b[6], b[7]]),
            name: u64::from_ne_bytes([b[8], b[9], b[10], b[11], b[12], b[13], b[14], b[15]]),
            pgn: u32::from_ne_bytes([b[16], b[17], b[18], b[19]]),
            addr: b[20],
        })
    }

    /// The address `bind` and `connect` accept (mainline's
    /// `j1939_sk_sanity_check`): `EINVAL` for a short address or another
    /// family, `ENODEV` for interface 0, `EINVAL` for a PDU1 PGN whose
    /// PS byte is not zero. (A missing address, `EDESTADDRREQ`, is the
    /// caller's.)
    pub fn parse_for_bind(b: &[u8]) -> Result<SockAddr, i32> {
        let a = Self::parse(b)?;
        if a.ifindex == 0 {
            return Err(ENODEV);
        }
        if pgn_is_valid(a.pgn) && !pgn_is_clean_pdu(a.pgn) {
            return Err(EINVAL);
        }
        Ok(a)
    }

    /// The destination of `sendmsg` with `msg_name` (mainline's order of
    /// checks): `EINVAL` short or other family, `EBADFD` another
    /// interface than `bound_ifindex` (0 means the bound one), `EINVAL`
    /// an unclean PDU1 PGN, `EACCES` broadcast (no NAME and address
    /// 0xFF) without `SO_BROADCAST`.
    pub fn parse_for_send(
        b: &[u8],
        bound_ifindex: i32,
        so_broadcast: bool,
    ) -> Result<SockAddr, i32> {
        let a = Self::parse(b)?;
        if a.ifindex != 0 && a.ifindex != bound_ifindex {
            return Err(EBADFD);
        }
        if pgn_is_valid(a.pgn) && !pgn_is_clean_pdu(a.pgn) {
            return Err(EINVAL);
        }
        if a.is_broadcast() && !so_broadcast {
            return Err(EACCES);
        }
        Ok(a)
    }

    /// No NAME and address 0xFF: the broadcast destination.
    pub const fn is_broadcast(&self) -> bool {
        self.name == J1939_NO_NAME && self.addr == J1939_NO_ADDR
    }

    /// The image `getsockname`/`getpeername`/`recvmsg` write: padding
    /// zeroed.
    pub fn to_bytes(self) -> [u8; SOCKADDR_J1939_LEN] {
        let mut b = [0u8; SOCKADDR_J1939_LEN];
        b[..2].copy_from_slice(&AF_CAN.to_ne_bytes());
        b[4..8].copy_from_slice(&self.ifindex.to_ne_bytes());
        b[8..16].copy_from_slice(&self.name.to_ne_bytes());
        b[16..20].copy_from_slice(&self.pgn.to_ne_bytes());
        b[20] = self.addr;
        b
    }
}

/// `SO_J1939_SEND_PRIO` from the option image `val`: `EINVAL` unless 4
/// bytes, `EDOM` outside 0..=7, `EPERM` for 0 and 1 without
/// `CAP_NET_ADMIN` (`net_admin`).
pub fn send_prio_option(val: &[u8], net_admin: bool) -> Result<u8, i32> {
    let b: [u8; 4] = val.try_into().map_err(|_| EINVAL)?;
    let v = i32::from_ne_bytes(b);
    if !(0..=7).contains(&v) {
        return Err(EDOM);
    }
    if v < 2 && !net_admin {
        return Err(EPERM);
    }
    Ok(v as u8)
}

/// A boolean option (`SO_J1939_PROMISC`, `SO_J1939_ERRQUEUE`): `EINVAL`
/// unless 4 bytes; any non-zero `int` is true.
pub fn flag_option(val: &[u8]) -> Result<bool, i32> {
    let b: [u8; 4] = val.try_into().map_err(|_| EINVAL)?;
    Ok(i32::from_ne_bytes(b) != 0)
}

/// One `struct j1939_filter` (32 bytes, native endian): a frame passes
/// when its PGN, source address and source NAME, each masked, equal the
/// filter's values.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Filter {
    /// NAME to match (after masking).
    pub name: u64,
    /// Bits of the NAME that count.
    pub name_mask: u64,
    /// PGN to match (after masking).
    pub pgn: u32,
    /// Bits of the PGN that count.
    pub pgn_mask: u32,
    /// Source address to match (after masking).
    pub addr: u8,
    /// Bits of the source address that count.
    pub addr_mask: u8,
}

impl Filter {
    /// `sizeof(struct j1939_filter)`.
    pub const SIZE: usize = 32;

    /// Parses one image; the values are masked, as mainline stores them
    /// (so that a value bit outside its mask can never fail a match).
    pub fn from_bytes(b: &[u8; Self::SIZE]) -> Filter {
        let u64_at = |i: usize| {
            u64::from_ne_bytes([
                b[i],
                b[i + 1],
                b[i + 2],
                b[i + 3],
                b[i + 4],
                b[i + 5],
                b[i + 6],
                b[i + 7],
            ])
        };
        let u32_at = |i: usize| u32::from_ne_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let (name_mask, pgn_mask, addr_mask) = (u64_at(8), u32_at(20), b[25]);
        Filter {
            name: u64_at(0) & name_mask,
            name_mask,
            pgn: u32_at(16) & pgn_mask,
            pgn_mask,
            addr: b[24] & addr_mask,
            addr_mask,
        }
    }

    /// The image (padding zero).
    pub fn to_bytes(self) -> [u8; Self::SIZE] {
        let mut b = [0u8; Self::SIZE];
        b[0..8].copy_from_slice(&self.name.to_ne_bytes());
        b[8..16].copy_from_slice(&self.name_mask.to_ne_bytes());
        b[16..20].copy_from_slice(&self.pgn.to_ne_bytes());
        b[20..24].copy_from_slice(&self.pgn_mask.to_ne_bytes());
        b[24] = self.addr;
        b[25] = self.addr_mask;
        b
    }

    /// Whether a frame with this PGN, source address and source NAME
    /// ([`J1939_NO_NAME`] when the source has none) passes.
    pub const fn matches(&self, pgn: u32, sa: u8, src_name: u64) -> bool {
        pgn & self.pgn_mask == self.pgn
            && sa & self.addr_mask == self.addr
            && src_name & self.name_mask == self.name
    }
}

/// The number of filters in an `SO_J1939_FILTER` image of `optlen`
/// bytes: `EINVAL` when not a multiple of [`Filter::SIZE`] or over
/// [`J1939_FILTER_MAX`] filters. 0 (or no buffer) removes the filters.
pub const fn filter_count(optlen: usize) -> Result<usize, i32> {
    if !optlen.is_multiple_of(Filter::SIZE) || optlen > J1939_FILTER_MAX * Filter::SIZE {
        Err(EINVAL)
    } else {
        Ok(optlen / Filter::SIZE)
    }
}

/// Whether a frame passes a socket's filter list: any filter matches, or
/// the list is empty.
pub fn filters_match(filters: &[Filter], pgn: u32, sa: u8, src_name: u64) -> bool {
    filters.is_empty() || filters.iter().any(|f| f.matches(pgn, sa, src_name))
}

/// What a received message carries for matching and for `recvmsg`.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct RxMeta {
    /// The addressing of the (first) frame; the PGN of the session for a
    /// transport message.
    pub id: Id,
    /// Source NAME from the address claim table, or [`J1939_NO_NAME`].
    pub src_name: u64,
    /// Destination NAME from the address claim table, or
    /// [`J1939_NO_NAME`].
    pub dst_name: u64,
}

/// The receive side of one socket's state, as mainline's
/// `j1939_sk_match_dst` reads it.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct SockRx {
    /// `SO_J1939_PROMISC`.
    pub promisc: bool,
    /// `SO_BROADCAST`.
    pub broadcast: bool,
    /// Bound NAME.
    pub src_name: u64,
    /// Bound address.
    pub sa: u8,
    /// `connect` was called.
    pub connected: bool,
    /// Connected NAME.
    pub dst_name: u64,
    /// Connected address.
    pub da: u8,
    /// The PGN given to `bind`, or [`J1939_NO_PGN`].
    pub pgn_rx_filter: u32,
}

impl Default for SockRx {
    fn default() -> Self {
        SockRx {
            promisc: false,
            broadcast: false,
            src_name: J1939_NO_NAME,
            sa: J1939_NO_ADDR,
            connected: false,
            dst_name: J1939_NO_NAME,
            da: J1939_NO_ADDR,
            pgn_rx_filter: J1939_NO_PGN,
        }
    }
}

impl SockRx {
    /// Mainline's `j1939_sk_match_dst`: promiscuous sockets take
    /// everything; else the destination must be our NAME (when both have
    /// one) or our address, or a broadcast with `SO_BROADCAST`; a
    /// connected socket takes only its peer's frames (by NAME when both
    /// have one); a PGN given to `bind` must match.
    pub const fn match_dst(&self, m: &RxMeta) -> bool {
        if self.promisc {
            return true;
        }
        if self.src_name != 0 && m.dst_name != 0 {
            if self.src_name != m.dst_name {
                return false;
            }
        } else if addr_is_unicast(m.id.da) {
            if self.sa != m.id.da {
                return false;
            }
        } else if !self.broadcast {
            return false;
        }
        if self.connected {
            if self.dst_name != 0 && m.src_name != 0 {
                if self.dst_name != m.src_name {
                    return false;
                }
            } else if self.da != m.id.sa {
                return false;
            }
        }
        !(pgn_is_valid(self.pgn_rx_filter) && self.pgn_rx_filter != m.id.pgn)
    }

    /// Whether the socket receives `m`: [`SockRx::match_dst`] and the
    /// filters (mainline's `j1939_sk_recv_match_one`, for a bound
    /// socket).
    pub fn accepts(&self, filters: &[Filter], m: &RxMeta) -> bool {
        self.match_dst(m) && filters_match(filters, m.id.pgn, m.id.sa, m.src_name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uapi_values() {
        assert_eq!(SOL_CAN_J1939, 107);
        assert_eq!(MAX_ETP_SIZE, 117_440_505);
        assert_eq!(MAX_TP_SIZE, 1785);
        assert_eq!(core::mem::size_of::<[u8; Filter::SIZE]>(), 32);
    }

    #[test]
    fn pdu1_and_pdu2_identifiers() {
        // Request (PDU1) from 0x80 to 0x20, priority 6.
        let id = Id {
            prio: 6,
            pgn: J1939_PGN_REQUEST,
            sa: 0x80,
            da: 0x20,
        };
        assert_eq!(id.to_can_id(), CAN_EFF_FLAG | 0x18EA_2080);
        assert_eq!(Id::from_can_id(id.to_can_id()), Some(id));
        // PDU2 (PF 0xFE): PS is the group extension, always broadcast.
        let id = Id {
            prio: 3,
            pgn: 0xFEF1,
            sa: 0x00,
            da: 0x20,
        };
        assert_eq!(id.to_can_id(), CAN_EFF_FLAG | 0x0CFE_F100);
        let back = Id::from_can_id(id.to_can_id()).unwrap();
        assert_eq!(back.pgn, 0xFEF1);
        assert_eq!(back.da, J1939_NO_ADDR);
        // Data page and reserved bit.
        let id = Id {
            prio: 7,
            pgn: 0x3_1200,
            sa: 1,
            da: 2,
        };
        assert_eq!(id.to_can_id() & CAN_EFF_MASK, 7 << 26 | 0x3_1202 << 8 | 1);
        assert_eq!(Id::from_can_id(id.to_can_id()), Some(id));
    }

    #[test]
    fn send_normalises_like_mainline() {
        // A PDU1 PGN's PS byte is replaced by the destination; bits above
        // 17 are cut; priority over 7 becomes 6.
        let id = Id {
            prio: 9,
            pgn: 0x7_EA55,
            sa: 0x11,
            da: 0x22,
        };
        assert_eq!(
            id.to_can_id(),
            CAN_EFF_FLAG | 6 << 26 | 0x3_EA22 << 8 | 0x11
        );
        assert_eq!(pgn_for_send(0x7_FFFF), 0x3_FFFF);
        assert_eq!(pgn_for_send(0x1_2345), 0x1_2300);
    }

    #[test]
    fn received_frames_mainline_ignores() {
        assert_eq!(Id::from_can_id(0x123), None);
        assert_eq!(
            Id::from_can_id(CAN_EFF_FLAG | CAN_RTR_FLAG | 0x18EA_2080),
            None
        );
        assert_eq!(Id::from_can_id(CAN_EFF_FLAG | CAN_ERR_FLAG | 0x80), None);
        assert_eq!(Id::from_can_id(CAN_EFF_FLAG | 0x18EA_20FF), None);
        // Source 0xFE (idle) is a valid sender (address claim "cannot claim").
        assert_eq!(
            Id::from_can_id(CAN_EFF_FLAG | 0x18EE_FFFE).unwrap().sa,
            0xFE
        );
    }

    #[test]
    fn pgn_checks() {
        assert!(pgn_is_pdu1(0xEA00) && !pgn_is_pdu1(0xF000) && !pgn_is_pdu1(0x1_FEF1));
        assert!(pgn_is_pdu1(0x1_EF00) && pgn_is_pdu1(0x2_0000));
        assert!(pgn_is_valid(0x3_FFFF) && !pgn_is_valid(J1939_NO_PGN));
        assert!(pgn_is_clean_pdu(0xEA00) && !pgn_is_clean_pdu(0xEA01));
        assert!(pgn_is_clean_pdu(0xFEF1));
    }

    fn sa_bytes(family: u16, ifindex: i32, name: u64, pgn: u32, addr: u8) -> [u8; 24] {
        let mut b = SockAddr {
            ifindex,
            name,
            pgn,
            addr,
        }
        .to_bytes();
        b[..2].copy_from_slice(&family.to_ne_bytes());
        b
    }

    #[test]
    fn sockaddr_checks() {
        let b = sa_bytes(29, 3, 0x1122, 0xEA00, 0x20);
        let a = SockAddr::parse_for_bind(&b).unwrap();
        assert_eq!(
            (a.ifindex, a.name, a.pgn, a.addr),
            (3, 0x1122, 0xEA00, 0x20)
        );
        assert_eq!(SockAddr::parse_for_bind(&b[..23]), Err(EINVAL));
        assert_eq!(
            SockAddr::parse_for_bind(&sa_bytes(2, 3, 0, 0, 0)),
            Err(EINVAL)
        );
        assert_eq!(
            SockAddr::parse_for_bind(&sa_bytes(29, 0, 0, 0, 0)),
            Err(ENODEV)
        );
        assert_eq!(
            SockAddr::parse_for_bind(&sa_bytes(29, 3, 0, 0xEA01, 0)),
            Err(EINVAL)
        );
        // An invalid PGN (no PGN) is not checked for cleanliness.
        assert!(SockAddr::parse_for_bind(&sa_bytes(29, 3, 0, 0x4_0001, 0)).is_ok());
        let bc = sa_bytes(29, 0, 0, J1939_NO_PGN, 0xFF);
        assert_eq!(SockAddr::parse_for_send(&bc, 3, false), Err(EACCES));
        assert!(SockAddr::parse_for_send(&bc, 3, true).is_ok());
        assert_eq!(
            SockAddr::parse_for_send(&sa_bytes(29, 4, 0, 0, 1), 3, false),
            Err(EBADFD)
        );
        // A NAME is not a broadcast even with address 0xFF.
        assert!(SockAddr::parse_for_send(&sa_bytes(29, 3, 9, 0, 0xFF), 3, false).is_ok());
    }

    #[test]
    fn options() {
        assert_eq!(send_prio_option(&5i32.to_ne_bytes(), false), Ok(5));
        assert_eq!(send_prio_option(&1i32.to_ne_bytes(), false), Err(EPERM));
        assert_eq!(send_prio_option(&1i32.to_ne_bytes(), true), Ok(1));
        assert_eq!(send_prio_option(&8i32.to_ne_bytes(), true), Err(EDOM));
        assert_eq!(send_prio_option(&(-1i32).to_ne_bytes(), true), Err(EDOM));
        assert_eq!(send_prio_option(&[0; 2], true), Err(EINVAL));
        assert_eq!(flag_option(&7i32.to_ne_bytes()), Ok(true));
        assert_eq!(flag_option(&[0; 8]), Err(EINVAL));
        for p in 0..=7u8 {
            assert_eq!(sk_priority_to_prio(prio_to_sk_priority(p)), p);
        }
        assert_eq!(sk_priority_to_prio(100), 0);
        assert_eq!(prio_to_sk_priority(DEFAULT_PRIO), 1);
    }

    #[test]
    fn filters() {
        assert_eq!(filter_count(0), Ok(0));
        assert_eq!(filter_count(64), Ok(2));
        assert_eq!(filter_count(33), Err(EINVAL));
        assert_eq!(filter_count(512 * 32), Ok(512));
        assert_eq!(filter_count(513 * 32), Err(EINVAL));
        let f = Filter {
            name: 0xFFFF,
            name_mask: 0xFF00,
            pgn: 0xFEFF,
            pgn_mask: 0x3_FF00,
            addr: 0x21,
            addr_mask: 0xF0,
        };
        let f = Filter::from_bytes(&f.to_bytes());
        // Values masked when set.
        assert_eq!((f.name, f.pgn, f.addr), (0xFF00, 0xFE00, 0x20));
        assert!(f.matches(0xFE42, 0x2F, 0xFF12));
        assert!(!f.matches(0xFD42, 0x2F, 0xFF12));
        assert!(!f.matches(0xFE42, 0x3F, 0xFF12));
        assert!(!f.matches(0xFE42, 0x2F, 0xFE12));
        assert!(filters_match(&[], 0, 0, 0));
        assert!(filters_match(&[Filter::default(), f], 1, 2, 3));
        assert!(!filters_match(&[f], 1, 2, 3));
    }

    #[test]
    fn destination_matching() {
        let m = |sa, da, pgn, src_name, dst_name| RxMeta {
            id: Id {
                prio: 6,
                pgn,
                sa,
                da,
            },
            src_name,
            dst_name,
        };
        let mut s = SockRx {
            sa: 0x20,
            ..SockRx::default()
        };
        assert!(s.match_dst(&m(0x30, 0x20, 0xEF00, 0, 0)));
        assert!(!s.match_dst(&m(0x30, 0x21, 0xEF00, 0, 0)));
        // Broadcast only with SO_BROADCAST.
        assert!(!s.match_dst(&m(0x30, 0xFF, 0xFEF1, 0, 0)));
        s.broadcast = true;
        assert!(s.match_dst(&m(0x30, 0xFF, 0xFEF1, 0, 0)));
        // By NAME when both sides have one, whatever the address.
        s.src_name = 0xAA;
        assert!(s.match_dst(&m(0x30, 0x55, 0xEF00, 0, 0xAA)));
        assert!(!s.match_dst(&m(0x30, 0x20, 0xEF00, 0, 0xAB)));
        // Connected: the peer only.
        s.connected = true;
        s.da = 0x30;
        assert!(s.match_dst(&m(0x30, 0x20, 0xEF00, 0, 0)));
        assert!(!s.match_dst(&m(0x31, 0x20, 0xEF00, 0, 0)));
        s.dst_name = 0xBB;
        assert!(s.match_dst(&m(0x31, 0x20, 0xEF00, 0xBB, 0)));
        assert!(!s.match_dst(&m(0x30, 0x20, 0xEF00, 0xBC, 0)));
        // PGN of bind.
        s.pgn_rx_filter = 0xEF00;
        assert!(s.match_dst(&m(0x30, 0x20, 0xEF00, 0, 0)));
        assert!(!s.match_dst(&m(0x30, 0x20, 0xEE00, 0, 0)));
        // Promiscuous: anything.
        s.promisc = true;
        assert!(s.match_dst(&m(0x99, 0x77, 0x1234, 5, 6)));
        let f = Filter {
            pgn: 0xEF00,
            pgn_mask: J1939_PGN_MAX,
            ..Filter::default()
        };
        assert!(s.accepts(&[f], &m(0x30, 0x20, 0xEF00, 0, 0)));
        assert!(!s.accepts(&[f], &m(0x30, 0x20, 0xEE00, 0, 0)));
    }
}
