// SPDX-License-Identifier: GPL-2.0
//! What the fuzzer knows about each protocol, as data: socket type and
//! protocol number, address layouts, socket options with their value
//! sizes, the longest message. Adding a protocol (BCM, CAN FD, ...) is
//! adding a [`Proto`] to [`PROTOS`]. Also the errnos each kind of call may
//! return (the documented set): anything else is a failure.

use libc::c_int;

/// `PF_CAN`.
pub const PF_CAN: c_int = 29;
/// `AF_CAN` as stored in an address.
pub const AF_CAN: u16 = 29;
/// `SOL_CAN_RAW` (`SOL_CAN_BASE` 100 + `CAN_RAW`).
pub const SOL_CAN_RAW: c_int = 101;
/// `SOL_CAN_ISOTP` (`SOL_CAN_BASE` 100 + `CAN_ISOTP`).
pub const SOL_CAN_ISOTP: c_int = 106;
/// `CAN_ISOTP` option names (isotp.rst, "Options").
pub const CAN_ISOTP_OPTS: c_int = 1;
pub const CAN_ISOTP_RECV_FC: c_int = 2;
pub const CAN_ISOTP_TX_STMIN: c_int = 3;
pub const CAN_ISOTP_RX_STMIN: c_int = 4;
pub const CAN_ISOTP_LL_OPTS: c_int = 5;
/// `SOL_CAN_J1939` (`SOL_CAN_BASE` 100 + `CAN_J1939`).
pub const SOL_CAN_J1939: c_int = 107;
/// `<linux/can/j1939.h>`: `J1939_NO_NAME`, `J1939_NO_PGN`, `J1939_NO_ADDR`
/// (broadcast as a destination), `J1939_IDLE_ADDR`.
pub const J1939_NO_NAME: u64 = 0;
pub const J1939_NO_PGN: u64 = 0x40000;
pub const J1939_NO_ADDR: u64 = 0xff;
pub const J1939_IDLE_ADDR: u64 = 0xfe;
/// `J1939_FILTER_MAX` and `sizeof(struct j1939_filter)` on x86_64 (two
/// u64, two u32, two u8, padded to 32).
pub const J1939_FILTER_MAX: usize = 512;
pub const J1939_FILTER_LEN: usize = 32;

/// The longest J1939 message the fuzzer sends (its transport sessions
/// must end well inside the watchdog, and `close` waits for its socket's
/// session): [`j1939_bound`].
///
/// * A message of 9..=1785 bytes to broadcast is a BAM: 50 ms between
///   its data packets, at most 255 of them, 12.8 s.
/// * A unicast TP or ETP session to an address nobody has ends after T3
///   (1.25 s) with an abort; to another fuzzer socket's address the
///   kernel is both ends and the session runs as fast as the frames'
///   echoes: [`J1939_MAX_SEND`] bytes are 1,143 packets.
/// * A peer's hold (CTS for 0 packets) delays a sender by T4 (550 ms)
///   each time; only random CAN_RAW frames send one, rarely.
///
/// A longer send is cut to a random length up to this. (Over the ETP
/// limit, 117,440,505 bytes, the kernel says EMSGSIZE before it copies
/// anything; the fuzzer's longest send is 70,000 bytes.)
pub const J1939_MAX_SEND: usize = 8000;

/// `n` bounded for a J1939 send ([`J1939_MAX_SEND`]).
pub fn j1939_bound(n: usize, pick: usize) -> usize {
    if n > J1939_MAX_SEND {
        1 + pick % J1939_MAX_SEND
    } else {
        n
    }
}

/// Every `CAN_ISOTP_OPTS` flag, LISTEN_MODE (0x1) to DYN_FC_PARMS
/// (0x2000).
pub const ISOTP_FLAGS: &[u32] = &[
    0x1, 0x2, 0x4, 0x8, 0x10, 0x20, 0x40, 0x80, 0x100, 0x200, 0x400, 0x800, 0x1000, 0x2000,
];
/// `CAN_ISOTP_FRAME_TXTIME_ZERO`: `frame_txtime` 0 ns.
pub const ISOTP_TXTIME_ZERO: u32 = 0xFFFF_FFFF;

/// How long an ISO-TP transfer started by the fuzzer may take, and why it
/// must be bounded. An ISO-TP `sendmsg` waits (without timeout, ignoring
/// `SO_SNDTIMEO`, as mainline) for the socket's running transfer, a
/// `CAN_ISOTP_WAIT_TX_DONE` sender and `close` wait for their own, and a
/// transfer runs as long as its consecutive frames (CFs) times the gap
/// between them. Unbounded, one 8300-byte PDU with STmin 127 ms is about
/// 150 s, beyond the watchdog. The gap is the larger of
///
/// * the STmin of the receiver's flow control plus `frame_txtime`: every
///   STmin byte means at most 127 ms (0x7F, and the reserved values the
///   sender reads as 0x7F), so the fuzzer draws `CAN_ISOTP_RECV_FC`'s
///   STmin from all 256 values, but `frame_txtime` only up to
///   [`ISOTP_MAX_TXTIME_NS`] (1 ms);
/// * a forced STmin (`CAN_ISOTP_TX_STMIN` with `CAN_ISOTP_FORCE_TXSTMIN`),
///   which the fuzzer draws up to [`ISOTP_MAX_TX_STMIN_NS`] (127 ms, the
///   longest STmin the wire can ask for).
///
/// So a gap is at most [`ISOTP_MAX_GAP_MS`], and [`isotp_max_send`] keeps
/// a PDU the kernel accepts to at most [`ISOTP_MAX_CFS`] CFs: at most
/// 12.8 s per transfer (plus 1 s per flow-control wait and 2 s for a lost
/// echo). Four workers queued behind one socket's transfers then wait at
/// most about 4 x 15 s, inside the 120-s watchdog with room to spare for
/// the debug kernel under load. Flow control frames with wait status come
/// only from random CAN_RAW frames (our sockets never send them), each
/// adds 1 s: rare enough not to matter.
pub const ISOTP_MAX_GAP_MS: u64 = 128;
// The worst transfer (every gap the longest) stays far inside the
// watchdog: 12.8 s.
const _: () = assert!(ISOTP_MAX_CFS as u64 * ISOTP_MAX_GAP_MS <= 15_000);

/// Longest `frame_txtime` the fuzzer sets (ns): 1 ms ([`ISOTP_MAX_GAP_MS`]).
pub const ISOTP_MAX_TXTIME_NS: u32 = 1_000_000;
/// Longest forced STmin the fuzzer sets (ns): 127 ms.
pub const ISOTP_MAX_TX_STMIN_NS: u32 = 127_000_000;
/// Most CFs of one transfer the fuzzer starts ([`ISOTP_MAX_GAP_MS`]).
pub const ISOTP_MAX_CFS: usize = 100;
/// The module's `max_pdu_size` (default 8300): longer sends are EINVAL
/// before any transfer starts, so the fuzzer tries them unbounded.
pub const ISOTP_MAX_PDU: usize = 8300;

/// Longest PDU the fuzzer sends on an ISO-TP socket whose link layer has
/// TX_DL `tx_dl` ([`ISOTP_MAX_GAP_MS`]): [`ISOTP_MAX_CFS`] CFs of
/// `tx_dl - 2` bytes (an extended address byte and the N_PCI byte) and a
/// first frame. Classic CAN (TX_DL 8): 606 bytes; CAN FD with TX_DL 64:
/// 6262 bytes, so the 32-bit FF_DL (PDUs over 4095 bytes) is reached.
pub fn isotp_max_send(tx_dl: u8) -> usize {
    let dl = match tx_dl {
        8 | 12 | 16 | 20 | 24 | 32 | 48 | 64 => tx_dl as usize,
        _ => 8,
    };
    (ISOTP_MAX_CFS + 1) * (dl - 2)
}

/// Bounds an ISO-TP option value about to be set, whatever produced it
/// (the generator, a random name that happens to be a real one): the
/// `frame_txtime` of `CAN_ISOTP_OPTS` to [`ISOTP_MAX_TXTIME_NS`] (0 and
/// [`ISOTP_TXTIME_ZERO`] kept) and `CAN_ISOTP_TX_STMIN` to
/// [`ISOTP_MAX_TX_STMIN_NS`]. Values of another size are left alone (the
/// kernel refuses them: the sizes must be exact).
pub fn isotp_bound(name: c_int, val: &mut [u8]) {
    let clamp = |v: &mut [u8], max: u32, keep: &[u32]| {
        let x = u32::from_ne_bytes(v[..4].try_into().unwrap());
        if x > max && !keep.contains(&x) {
            v[..4].copy_from_slice(&(x % (max + 1)).to_ne_bytes());
        }
    };
    match (name, val.len()) {
        (CAN_ISOTP_OPTS, 12) => clamp(&mut val[4..8], ISOTP_MAX_TXTIME_NS, &[ISOTP_TXTIME_ZERO]),
        (CAN_ISOTP_TX_STMIN, 4) => clamp(val, ISOTP_MAX_TX_STMIN_NS, &[]),
        _ => {}
    }
}

/// What a field of an address holds, so the generator can choose
/// interesting values for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    /// `sa_family` (u16): mostly `AF_CAN`, sometimes 0 or random.
    Family,
    /// An interface index (u32): a CAN device, 0, lo, a stale or unknown
    /// index.
    Ifindex,
    /// A thesis arbitration field (u32): standard, extended, RTR, bit 0
    /// set, standard with extension bits set.
    Arb,
    /// A filter mask (u32): exact, any, random.
    Mask,
    /// A DSOR node (u8): this node (0), another, the wildcard 0xff, random.
    Node,
    /// A DSOR port (u16): `node << 8 | sub`.
    Port,
    /// A DSOR message id (u32): small, the wildcard, random.
    MsgId,
    /// Anything (a priority, padding): random bytes.
    Any,
    /// An ISO-TP identifier (`can_addr.tp.rx_id`/`tx_id`, u32): mostly
    /// one of a few (so that sockets pair up and talk), sometimes
    /// extended, RTR/ERR flags or bits beyond the identifier.
    IsotpId,
    /// A J1939 NAME (`can_addr.j1939.name`, u64): mostly none
    /// (`J1939_NO_NAME`), sometimes one of a few, random.
    J1939Name,
    /// A J1939 PGN (`can_addr.j1939.pgn`, u32): none (`J1939_NO_PGN`), a
    /// PDU1 or PDU2 PGN, the kernel's own (request, address claim, the
    /// transport PGNs), beyond 18 bits.
    J1939Pgn,
    /// A J1939 address (`can_addr.j1939.addr`, u8): one of a few (so
    /// that sockets talk to each other), idle, broadcast, random.
    J1939Addr,
}

/// One address layout: its length and fields (offset, size, kind). Bytes
/// no field covers are zero (padding) or, sometimes, random.
#[derive(Debug)]
pub struct Layout {
    pub name: &'static str,
    pub len: usize,
    pub fields: &'static [(usize, usize, Field)],
}

/// How an option's value is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Val {
    /// A C int (4 bytes): 0, 1, -1, small, random.
    Int,
    /// An array of `elem`-byte elements (e.g. `struct can_filter[]`), of
    /// up to `max` elements (more sometimes).
    Array { elem: usize, max: usize },
    /// `size` random bytes.
    Bytes(usize),
    /// An ISO-TP option of `SOL_CAN_ISOTP` (its name), built field by
    /// field within the bounds of [`ISOTP_MAX_GAP_MS`].
    Isotp(c_int),
}

/// A socket option: level, name, value.
#[derive(Debug)]
pub struct Opt {
    pub level: c_int,
    pub name: c_int,
    pub label: &'static str,
    pub val: Val,
}

/// One protocol of the PF_CAN family.
#[derive(Debug)]
pub struct Proto {
    pub name: &'static str,
    pub sock_type: c_int,
    pub protocol: c_int,
    /// Address layouts bind/connect/sendto take.
    pub addrs: &'static [Layout],
    /// Protocol-level options (SOL_SOCKET ones are in [`SOCKET_OPTS`]).
    pub opts: &'static [Opt],
    /// Level of the protocol options, also tried with random names.
    pub level: Option<c_int>,
    /// Longest message a receive can return in full (the bound on a
    /// `MSG_TRUNC` receive's return value).
    pub max_msg: usize,
    /// Send lengths worth trying besides random ones.
    pub send_lens: &'static [usize],
    /// How a message body is built: random bytes, or a structure the
    /// protocol parses (mostly well-formed, so the paths past the first
    /// check run).
    pub msg: Msg,
    /// Errnos a send may return on this protocol besides [`Call::allowed`]
    /// (documented, protocol-specific ones; e.g. BCM's `EFAULT` for a
    /// message shorter than its `nframes`, as mainline; `ENOTCONN` before
    /// `connect`; `E2BIG` for an update with more frames).
    pub extra_send: &'static [c_int],
}

/// How the fuzzer builds a message for a protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Msg {
    /// Random bytes of a random or interesting length.
    Random,
    /// `struct bcm_msg_head` and frames ([`BCM_HEAD`] bytes, then 16- or
    /// 72-byte frames).
    Bcm,
    /// An ISO-TP PDU: random bytes, of a length bounded by the socket's
    /// link layer ([`isotp_max_send`]) unless the kernel refuses it
    /// before any transfer starts.
    Isotp,
    /// A J1939 message: random bytes, of a length bounded by
    /// [`J1939_MAX_SEND`].
    J1939,
}

/// `sizeof(struct bcm_msg_head)` on x86_64.
pub const BCM_HEAD: usize = 56;
/// BCM opcodes a user sends (1..=7); the replies are 8..=12.
pub const BCM_OPCODES: &[u32] = &[1, 2, 3, 4, 5, 6, 7];
/// BCM flags (bcm.rst): SETTIMER .. CAN_FD_FRAME.
pub const BCM_FLAGS: &[u32] = &[
    0x1, 0x2, 0x4, 0x8, 0x10, 0x20, 0x40, 0x80, 0x100, 0x200, 0x400, 0x800,
];

/// `struct sockaddr_can` (24 bytes): family, pad, ifindex, the 16-byte
/// union of transport addresses.
const SOCKADDR_CAN: Layout = Layout {
    name: "sockaddr_can",
    len: 24,
    fields: &[(0, 2, Field::Family), (4, 4, Field::Ifindex)],
};

/// `struct sockaddr_canarb` (16 bytes, rcan.h).
const SOCKADDR_CANARB: Layout = Layout {
    name: "sockaddr_canarb",
    len: 16,
    fields: &[
        (0, 2, Field::Family),
        (4, 4, Field::Arb),
        (8, 4, Field::Mask),
        (12, 4, Field::Ifindex),
    ],
};

/// `struct sockaddr_cansegm` (8 bytes, rcan_dsor.h).
const SOCKADDR_CANSEGM: Layout = Layout {
    name: "sockaddr_cansegm",
    len: 8,
    fields: &[
        (0, 2, Field::Family),
        (2, 1, Field::Any),
        (3, 1, Field::Node),
        (4, 4, Field::MsgId),
    ],
};

/// `struct sockaddr_canport` (6 bytes, rcan_dsor.h).
const SOCKADDR_CANPORT: Layout = Layout {
    name: "sockaddr_canport",
    len: 6,
    fields: &[
        (0, 2, Field::Family),
        (2, 2, Field::Port),
        (4, 1, Field::Any),
    ],
};

/// `struct sockaddr_can` as ISO-TP reads it (24 bytes, mainline's
/// `ISOTP_MIN_NAMELEN` 16): family, ifindex, `can_addr.tp.rx_id`,
/// `tx_id`.
const SOCKADDR_CAN_TP: Layout = Layout {
    name: "sockaddr_can (tp)",
    len: 24,
    fields: &[
        (0, 2, Field::Family),
        (4, 4, Field::Ifindex),
        (8, 4, Field::IsotpId),
        (12, 4, Field::IsotpId),
    ],
};

/// `struct sockaddr_can` as J1939 reads it (24 bytes, mainline's
/// `J1939_MIN_NAMELEN`): family, ifindex, `can_addr.j1939` {name, pgn,
/// addr}.
const SOCKADDR_CAN_J1939: Layout = Layout {
    name: "sockaddr_can (j1939)",
    len: 24,
    fields: &[
        (0, 2, Field::Family),
        (4, 4, Field::Ifindex),
        (8, 8, Field::J1939Name),
        (16, 4, Field::J1939Pgn),
        (20, 1, Field::J1939Addr),
    ],
};

/// CAN_J1939 options (j1939.rst): the filters (`struct j1939_filter[]`)
/// and three ints.
const J1939_OPTS: &[Opt] = &[
    Opt {
        level: SOL_CAN_J1939,
        name: 1,
        label: "SO_J1939_FILTER",
        val: Val::Array {
            elem: J1939_FILTER_LEN,
            max: J1939_FILTER_MAX,
        },
    },
    int(SOL_CAN_J1939, 2, "SO_J1939_PROMISC"),
    int(SOL_CAN_J1939, 3, "SO_J1939_SEND_PRIO"),
    int(SOL_CAN_J1939, 4, "SO_J1939_ERRQUEUE"),
];

/// CAN_ISOTP options (isotp.rst, "Options"), each of the size mainline
/// takes and nothing else.
const ISOTP_OPTS: &[Opt] = &[
    Opt {
        level: SOL_CAN_ISOTP,
        name: CAN_ISOTP_OPTS,
        label: "CAN_ISOTP_OPTS",
        val: Val::Isotp(CAN_ISOTP_OPTS),
    },
    Opt {
        level: SOL_CAN_ISOTP,
        name: CAN_ISOTP_RECV_FC,
        label: "CAN_ISOTP_RECV_FC",
        val: Val::Isotp(CAN_ISOTP_RECV_FC),
    },
    Opt {
        level: SOL_CAN_ISOTP,
        name: CAN_ISOTP_TX_STMIN,
        label: "CAN_ISOTP_TX_STMIN",
        val: Val::Isotp(CAN_ISOTP_TX_STMIN),
    },
    Opt {
        level: SOL_CAN_ISOTP,
        name: CAN_ISOTP_RX_STMIN,
        label: "CAN_ISOTP_RX_STMIN",
        val: Val::Isotp(CAN_ISOTP_RX_STMIN),
    },
    Opt {
        level: SOL_CAN_ISOTP,
        name: CAN_ISOTP_LL_OPTS,
        label: "CAN_ISOTP_LL_OPTS",
        val: Val::Isotp(CAN_ISOTP_LL_OPTS),
    },
];

const fn int(level: c_int, name: c_int, label: &'static str) -> Opt {
    Opt {
        level,
        name,
        label,
        val: Val::Int,
    }
}

/// CAN_RAW options (can-raw.rst).
const RAW_OPTS: &[Opt] = &[
    Opt {
        level: SOL_CAN_RAW,
        name: 1,
        label: "CAN_RAW_FILTER",
        val: Val::Array { elem: 8, max: 512 },
    },
    int(SOL_CAN_RAW, 2, "CAN_RAW_ERR_FILTER"),
    int(SOL_CAN_RAW, 3, "CAN_RAW_LOOPBACK"),
    int(SOL_CAN_RAW, 4, "CAN_RAW_RECV_OWN_MSGS"),
    int(SOL_CAN_RAW, 5, "CAN_RAW_FD_FRAMES"),
    int(SOL_CAN_RAW, 6, "CAN_RAW_JOIN_FILTERS"),
    int(SOL_CAN_RAW, 7, "CAN_RAW_XL_FRAMES"),
    Opt {
        level: SOL_CAN_RAW,
        name: 8,
        label: "CAN_RAW_XL_VCID_OPTS",
        val: Val::Bytes(4),
    },
];

/// Every protocol rcan registers.
pub const PROTOS: &[Proto] = &[
    Proto {
        name: "CAN_RAW",
        sock_type: libc::SOCK_RAW,
        protocol: 1,
        addrs: &[SOCKADDR_CAN],
        opts: RAW_OPTS,
        level: Some(SOL_CAN_RAW),
        max_msg: 72,
        send_lens: &[16, 72, 2060, 13],
        msg: Msg::Random,
        extra_send: &[],
    },
    Proto {
        name: "CANPROTO_CAN",
        sock_type: libc::SOCK_RAW,
        protocol: 16,
        addrs: &[SOCKADDR_CANARB],
        opts: &[],
        level: None,
        max_msg: 8,
        send_lens: &[0, 1, 8, 9],
        msg: Msg::Random,
        extra_send: &[],
    },
    Proto {
        name: "CANPROTO_DSOR",
        sock_type: libc::SOCK_DGRAM,
        protocol: 17,
        addrs: &[SOCKADDR_CANSEGM, SOCKADDR_CANPORT],
        opts: &[],
        level: None,
        max_msg: 65535,
        send_lens: &[0, 1, 5, 6, 7, 8, 13, 14, 100, 65535, 65536],
        msg: Msg::Random,
        extra_send: &[],
    },
    // CAN_BCM (bcm.rst): connect()-ed to an interface (sockaddr_can), no
    // protocol options; each write one bcm_msg_head and its frames, each
    // read one reply (at most the head and 257 CAN FD frames).
    Proto {
        name: "CAN_BCM",
        sock_type: libc::SOCK_DGRAM,
        protocol: 2,
        addrs: &[SOCKADDR_CAN],
        opts: &[],
        level: None,
        max_msg: BCM_HEAD + 257 * 72,
        send_lens: &[0, 55, 56, 57, 72, 88, 128, 200],
        msg: Msg::Bcm,
        extra_send: &[libc::EFAULT, libc::ENOTCONN, libc::E2BIG],
    },
    // CAN_ISOTP (isotp.rst): bound to {rx_id, tx_id} on an interface,
    // SOL_CAN_ISOTP options, one PDU per datagram (max_pdu_size 8300).
    // Its protocol errors come back as the socket's pending error from
    // the next send or receive ("Errno"): ECOMM, EILSEQ, EBADMSG (the
    // rest, ETIMEDOUT, EMSGSIZE, ENETDOWN, ENODEV, are in every set).
    Proto {
        name: "CAN_ISOTP",
        sock_type: libc::SOCK_DGRAM,
        protocol: 6,
        addrs: &[SOCKADDR_CAN_TP],
        opts: ISOTP_OPTS,
        level: Some(SOL_CAN_ISOTP),
        max_msg: ISOTP_MAX_PDU,
        send_lens: &[
            0, 1, 6, 7, 8, 62, 63, 64, 100, 606, 4095, 4096, 6262, 8300, 8301, 70_000,
        ],
        msg: Msg::Isotp,
        extra_send: ISOTP_ERRS,
    },
    // CAN_J1939 (j1939.rst): bound to a NAME or address on an interface,
    // SOL_CAN_J1939 options, one message per datagram: up to 8 bytes one
    // frame, longer ones a TP, BAM or ETP session ([`J1939_MAX_SEND`]).
    Proto {
        name: "CAN_J1939",
        sock_type: libc::SOCK_DGRAM,
        protocol: 7,
        addrs: &[SOCKADDR_CAN_J1939],
        opts: J1939_OPTS,
        level: Some(SOL_CAN_J1939),
        // What another thread's send of the fuzzer's longest random
        // length may leave on a J1939 socket (a descriptor reused between
        // the bound and the send, see `j1939_bound`'s caller).
        max_msg: 70_000,
        send_lens: &[0, 1, 8, 9, 1785, 1786, 1787, J1939_MAX_SEND],
        msg: Msg::J1939,
        extra_send: J1939_SEND_ERRS,
    },
];

/// What a session's end leaves as a J1939 socket's pending error, which
/// its next send or receive returns: the errno of each abort reason
/// (mainline's `j1939_xtp_abort_to_errno`: EALREADY busy, EMSGSIZE
/// resources, EHOSTUNREACH timeout, EBADMSG CTS during data,
/// ENOTRECOVERABLE maximum retransmissions, ENOTCONN unexpected data,
/// EILSEQ bad sequence, EPROTO the rest), ENETDOWN when its interface
/// goes down, ESHUTDOWN for a session cancelled by unbinding.
pub const J1939_PENDING: &[c_int] = &[
    libc::EALREADY,
    libc::EMSGSIZE,
    libc::EHOSTUNREACH,
    libc::EBADMSG,
    libc::ENOTRECOVERABLE,
    libc::ENOTCONN,
    libc::EILSEQ,
    libc::EPROTO,
    libc::ENETDOWN,
    libc::ESHUTDOWN,
];

/// A J1939 send's own errnos (j1939.rst, mainline's `j1939_sk_sendmsg`):
/// EBADFD unbound or without a source address, EACCES broadcast without
/// SO_BROADCAST, EDOM a transport PGN, EBUSY a session with the same
/// ends running, EADDRNOTAVAIL a NAME without an address, EPROTO or
/// ENODEV a bad address claim, EDESTADDRREQ ETP to broadcast; and the
/// pending errors ([`J1939_PENDING`]).
pub const J1939_SEND_ERRS: &[c_int] = &[
    libc::EBADFD,
    libc::EACCES,
    libc::EDOM,
    libc::EBUSY,
    libc::EADDRNOTAVAIL,
    libc::EPROTO,
    libc::EALREADY,
    libc::EHOSTUNREACH,
    libc::EBADMSG,
    libc::ENOTRECOVERABLE,
    libc::ENOTCONN,
    libc::EILSEQ,
    libc::ESHUTDOWN,
];

/// The errnos a call other than a send may return on a socket of
/// protocol number `protocol` besides [`Call::allowed`]:
///
/// * CAN_ISOTP: its protocol errors from a receive ([`ISOTP_ERRS`], its
///   pending error), `EISCONN` from a setsockopt ([`ISOTP_OPT_ERRS`]);
/// * CAN_J1939: the pending errors from a receive ([`J1939_PENDING`]),
///   `EACCES` from a connect to broadcast without SO_BROADCAST,
///   `EADDRNOTAVAIL` for the peer of an unconnected socket, `EFAULT`
///   from a getsockopt whose buffer is shorter than the value
///   (mainline's answer; the fuzzer's buffers are all valid).
pub fn extra_errs(protocol: c_int, call: Call) -> &'static [c_int] {
    match (protocol, call) {
        (6, Call::Recv | Call::Recvfrom | Call::Recvmsg) => ISOTP_ERRS,
        (6, Call::Setsockopt) => ISOTP_OPT_ERRS,
        (7, Call::Recv | Call::Recvfrom | Call::Recvmsg) => J1939_PENDING,
        (7, Call::Connect) => &[libc::EACCES],
        (7, Call::Getpeername) => &[libc::EADDRNOTAVAIL],
        (7, Call::Getsockopt) => &[libc::EFAULT],
        _ => &[],
    }
}

/// The ISO-TP protocol errors a send or receive may report (above), and
/// `EADDRNOTAVAIL` from a receive on an unbound socket (mainline "isotp:
/// return -EADDRNOTAVAIL when reading from unbound socket"; found by
/// seed 1 on the first run).
pub const ISOTP_ERRS: &[c_int] = &[
    libc::ECOMM,
    libc::EILSEQ,
    libc::EBADMSG,
    libc::EADDRNOTAVAIL,
];
/// What an ISO-TP `setsockopt` may give besides the common set:
/// `EISCONN` on a bound socket, for any name (mainline checks it before
/// the name and length; found by seed 1 on the second run).
pub const ISOTP_OPT_ERRS: &[c_int] = &[libc::EISCONN];

/// SOL_SOCKET options tried on every socket. Left out on purpose:
/// `SO_RCVTIMEO`/`SO_SNDTIMEO` (the fuzzer sets them so no call blocks
/// long), and options that take user pointers inside the value
/// (`SO_ATTACH_FILTER`, ...), which would test the BPF core, not rcan.
pub const SOCKET_OPTS: &[Opt] = &[
    int(libc::SOL_SOCKET, libc::SO_RCVBUF, "SO_RCVBUF"),
    int(libc::SOL_SOCKET, libc::SO_SNDBUF, "SO_SNDBUF"),
    int(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, "SO_RCVBUFFORCE"),
    int(libc::SOL_SOCKET, libc::SO_SNDBUFFORCE, "SO_SNDBUFFORCE"),
    int(libc::SOL_SOCKET, libc::SO_PRIORITY, "SO_PRIORITY"),
    int(libc::SOL_SOCKET, libc::SO_TIMESTAMP, "SO_TIMESTAMP"),
    int(libc::SOL_SOCKET, libc::SO_TIMESTAMPNS, "SO_TIMESTAMPNS"),
    int(libc::SOL_SOCKET, libc::SO_TIMESTAMPING, "SO_TIMESTAMPING"),
    int(libc::SOL_SOCKET, libc::SO_RXQ_OVFL, "SO_RXQ_OVFL"),
    int(libc::SOL_SOCKET, libc::SO_MARK, "SO_MARK"),
    int(libc::SOL_SOCKET, libc::SO_PASSCRED, "SO_PASSCRED"),
    int(libc::SOL_SOCKET, libc::SO_RCVLOWAT, "SO_RCVLOWAT"),
    int(libc::SOL_SOCKET, libc::SO_ERROR, "SO_ERROR"),
    int(libc::SOL_SOCKET, libc::SO_TYPE, "SO_TYPE"),
    int(libc::SOL_SOCKET, libc::SO_PROTOCOL, "SO_PROTOCOL"),
    int(libc::SOL_SOCKET, libc::SO_DOMAIN, "SO_DOMAIN"),
    int(libc::SOL_SOCKET, libc::SO_BROADCAST, "SO_BROADCAST"),
    int(
        libc::SOL_SOCKET,
        libc::SO_SELECT_ERR_QUEUE,
        "SO_SELECT_ERR_QUEUE",
    ),
    int(libc::SOL_SOCKET, libc::SO_ZEROCOPY, "SO_ZEROCOPY"),
    Opt {
        level: libc::SOL_SOCKET,
        name: libc::SO_LINGER,
        label: "SO_LINGER",
        val: Val::Bytes(8),
    },
    Opt {
        level: libc::SOL_SOCKET,
        name: libc::SO_BINDTODEVICE,
        label: "SO_BINDTODEVICE",
        val: Val::Bytes(16),
    },
];

/// The kinds of call, for the per-syscall counts and the errno sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Call {
    Socket,
    Close,
    Dup,
    Bind,
    Connect,
    Setsockopt,
    Getsockopt,
    Send,
    Sendto,
    Sendmsg,
    Recv,
    Recvfrom,
    Recvmsg,
    Ioctl,
    Shutdown,
    Poll,
    Getsockname,
    Getpeername,
    LinkUpDown,
    Mtu,
    Rmmod,
    Insmod,
}

impl Call {
    pub fn name(self) -> &'static str {
        match self {
            Call::Socket => "socket",
            Call::Close => "close",
            Call::Dup => "dup",
            Call::Bind => "bind",
            Call::Connect => "connect",
            Call::Setsockopt => "setsockopt",
            Call::Getsockopt => "getsockopt",
            Call::Send => "send",
            Call::Sendto => "sendto",
            Call::Sendmsg => "sendmsg",
            Call::Recv => "recv",
            Call::Recvfrom => "recvfrom",
            Call::Recvmsg => "recvmsg",
            Call::Ioctl => "ioctl",
            Call::Shutdown => "shutdown",
            Call::Poll => "poll",
            Call::Getsockname => "getsockname",
            Call::Getpeername => "getpeername",
            Call::LinkUpDown => "link-up/down",
            Call::Mtu => "set-mtu",
            Call::Rmmod => "rmmod",
            Call::Insmod => "insmod",
        }
    }

    /// The errnos this call may return on rcan sockets: from the
    /// protocol documents (canproto-can.rst, can-raw.rst, dsor.rst) and
    /// the socket layer's own checks. Any other errno, and any errno above
    /// 133 (a kernel-internal code such as ENOIOCTLCMD or ERESTARTSYS that
    /// leaked), is a failure.
    pub fn allowed(self) -> &'static [c_int] {
        use libc::*;
        // Every call on a descriptor may also see: EBADF/ENOTSOCK (another
        // thread closed it or reused its number), an asynchronous DSOR
        // delivery error or a CAN_RAW ENETDOWN/ENODEV reported by the next
        // call on the socket (SO_ERROR semantics: ETIMEDOUT, ECONNREFUSED,
        // ENOBUFS, EMSGSIZE, ENETDOWN, ENODEV) and EINTR. These head every
        // set below.
        const SOCKET: &[c_int] = &[
            EPROTONOSUPPORT,
            EPROTOTYPE,
            ESOCKTNOSUPPORT,
            EAFNOSUPPORT,
            EINVAL,
            EMFILE,
            ENOBUFS,
            ENOMEM,
        ];
        const ADDR: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            EINVAL,
            ENXIO,
            EADDRINUSE,
            EADDRNOTAVAIL,
            EOPNOTSUPP,
            EAFNOSUPPORT,
            EISCONN,
            ENOMEM,
        ];
        const OPT: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            EINVAL,
            ENOPROTOOPT,
            EOPNOTSUPP,
            ERANGE,
            EPERM,
            EDOM,
            ENOMEM,
        ];
        const SEND: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            EINVAL,
            ENXIO,
            EDESTADDRREQ,
            EAGAIN,
            EOPNOTSUPP,
            EADDRINUSE,
            EADDRNOTAVAIL,
            EAFNOSUPPORT,
            EISCONN,
            EPIPE,
            ENOMEM,
            // CAN_RAW sendto on a device that is not a CAN device (lo,
            // canip0) with a well-formed frame: mainline's can_send gives
            // EPERM, and so does ours (found by seed 2).
            EPERM,
        ];
        const RECV: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            EAGAIN,
            EINVAL,
            EOPNOTSUPP,
            ENOTCONN,
            ENOMEM,
        ];
        const IOCTL: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            ENOTTY,
            EINVAL,
            ENOENT,
            // SIOCSPGRP/FIOSETOWN with a pid that does not exist.
            ESRCH,
            EAGAIN,
            EOPNOTSUPP,
            EPERM,
        ];
        const NAME: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            ENOTCONN,
            EOPNOTSUPP,
            EINVAL,
        ];
        const SHUTDOWN: &[c_int] = &[
            EBADF,
            ENOTSOCK,
            ETIMEDOUT,
            ECONNREFUSED,
            ENOBUFS,
            EMSGSIZE,
            ENETDOWN,
            ENODEV,
            EINTR,
            EOPNOTSUPP,
            ENOTCONN,
            EINVAL,
        ];
        // close(2) of a socket never fails but with EBADF (raced) or
        // EINTR; dup only with EBADF/EMFILE.
        const CLOSE: &[c_int] = &[EBADF, EINTR, EMFILE];
        // Device churn: SIOCSIFMTU on canloop takes 16 or 72 (CAN FD)
        // while down (EBUSY up, EINVAL for other values); the device may
        // be gone (ENODEV); rmmod of a
        // module in use is EWOULDBLOCK/EBUSY, of one that is not loaded
        // ENOENT; insmod of a loaded one EEXIST.
        const DEV: &[c_int] = &[EINVAL, ENODEV, EBUSY, EAGAIN, ENOENT, EEXIST];
        match self {
            Call::Socket => SOCKET,
            Call::Close | Call::Dup => CLOSE,
            Call::Poll => &[EINTR, ENOMEM],
            Call::Bind | Call::Connect => ADDR,
            Call::Setsockopt | Call::Getsockopt => OPT,
            Call::Send | Call::Sendto | Call::Sendmsg => SEND,
            Call::Recv | Call::Recvfrom | Call::Recvmsg => RECV,
            Call::Ioctl => IOCTL,
            Call::Getsockname | Call::Getpeername => NAME,
            Call::Shutdown => SHUTDOWN,
            Call::LinkUpDown | Call::Mtu | Call::Rmmod | Call::Insmod => DEV,
        }
    }
}

/// The C name of an errno, for the histogram.
pub fn errno_name(e: c_int) -> String {
    use libc::*;
    let n = match e {
        0 => "OK",
        EPERM => "EPERM",
        ESRCH => "ESRCH",
        ENOENT => "ENOENT",
        EINTR => "EINTR",
        ENXIO => "ENXIO",
        EBADF => "EBADF",
        EAGAIN => "EAGAIN",
        ENOMEM => "ENOMEM",
        EFAULT => "EFAULT",
        EBUSY => "EBUSY",
        EEXIST => "EEXIST",
        ENODEV => "ENODEV",
        EINVAL => "EINVAL",
        EMFILE => "EMFILE",
        ENOTTY => "ENOTTY",
        EPIPE => "EPIPE",
        EDOM => "EDOM",
        ERANGE => "ERANGE",
        ENOTSOCK => "ENOTSOCK",
        EDESTADDRREQ => "EDESTADDRREQ",
        EMSGSIZE => "EMSGSIZE",
        EPROTOTYPE => "EPROTOTYPE",
        ENOPROTOOPT => "ENOPROTOOPT",
        EPROTONOSUPPORT => "EPROTONOSUPPORT",
        ESOCKTNOSUPPORT => "ESOCKTNOSUPPORT",
        EOPNOTSUPP => "EOPNOTSUPP",
        EAFNOSUPPORT => "EAFNOSUPPORT",
        EADDRINUSE => "EADDRINUSE",
        EADDRNOTAVAIL => "EADDRNOTAVAIL",
        ENETDOWN => "ENETDOWN",
        ENOBUFS => "ENOBUFS",
        EISCONN => "EISCONN",
        ENOTCONN => "ENOTCONN",
        ECOMM => "ECOMM",
        EILSEQ => "EILSEQ",
        EBADMSG => "EBADMSG",
        ETIMEDOUT => "ETIMEDOUT",
        ECONNREFUSED => "ECONNREFUSED",
        EACCES => "EACCES",
        EBADFD => "EBADFD",
        EALREADY => "EALREADY",
        EHOSTUNREACH => "EHOSTUNREACH",
        ENOTRECOVERABLE => "ENOTRECOVERABLE",
        EPROTO => "EPROTO",
        ESHUTDOWN => "ESHUTDOWN",
        ENETUNREACH => "ENETUNREACH",
        _ => return format!("errno{e}"),
    };
    n.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_fit() {
        for p in PROTOS {
            assert!(!p.addrs.is_empty(), "{}", p.name);
            for l in p.addrs {
                for &(off, size, _) in l.fields {
                    assert!(off + size <= l.len, "{} {}", p.name, l.name);
                }
                assert_eq!(l.fields[0], (0, 2, Field::Family), "{}", l.name);
            }
            for o in p.opts {
                assert_eq!(Some(o.level), p.level, "{}", o.label);
            }
        }
    }

    #[test]
    fn layouts_match_uapi() {
        // Sizes as in rcan.h / rcan_dsor.h / linux/can.h on x86_64.
        let len = |n: &str| {
            PROTOS
                .iter()
                .flat_map(|p| p.addrs)
                .find(|l| l.name == n)
                .unwrap()
                .len
        };
        assert_eq!(len("sockaddr_can"), 24);
        assert_eq!(len("sockaddr_canarb"), 16);
        assert_eq!(len("sockaddr_cansegm"), 8);
        assert_eq!(len("sockaddr_canport"), 6);
        assert_eq!(len("sockaddr_can (tp)"), 24);
        assert_eq!(len("sockaddr_can (j1939)"), 24);
    }

    #[test]
    fn isotp_bounds() {
        // Classic: 101 frames' worth of 6 bytes; FD 64 reaches the
        // 32-bit FF_DL; junk TX_DL counts as classic.
        assert_eq!(isotp_max_send(8), 606);
        assert_eq!(isotp_max_send(64), 6262);
        assert!(isotp_max_send(64) > 4095);
        assert_eq!(isotp_max_send(9), 606);
        // Worst transfer: ISOTP_MAX_CFS gaps of ISOTP_MAX_GAP_MS, well
        // inside the 120-s watchdog even four deep.
        assert!(4 * (ISOTP_MAX_CFS as u64 * ISOTP_MAX_GAP_MS + 3000) < 120_000);
        assert!(u64::from(ISOTP_MAX_TX_STMIN_NS) <= ISOTP_MAX_GAP_MS * 1_000_000);
        assert!(127 + u64::from(ISOTP_MAX_TXTIME_NS) / 1_000_000 <= ISOTP_MAX_GAP_MS);
        let mut o = [0u8; 12];
        o[4..8].copy_from_slice(&u32::MAX.to_ne_bytes());
        isotp_bound(CAN_ISOTP_OPTS, &mut o);
        assert_eq!(u32::from_ne_bytes(o[4..8].try_into().unwrap()), u32::MAX);
        o[4..8].copy_from_slice(&0x7fff_ffffu32.to_ne_bytes());
        isotp_bound(CAN_ISOTP_OPTS, &mut o);
        assert!(u32::from_ne_bytes(o[4..8].try_into().unwrap()) <= ISOTP_MAX_TXTIME_NS);
        let mut t = 4_000_000_000u32.to_ne_bytes();
        isotp_bound(CAN_ISOTP_TX_STMIN, &mut t);
        assert!(u32::from_ne_bytes(t) <= ISOTP_MAX_TX_STMIN_NS);
        let mut t = 5u32.to_ne_bytes();
        isotp_bound(CAN_ISOTP_TX_STMIN, &mut t);
        assert_eq!(u32::from_ne_bytes(t), 5);
    }

    #[test]
    fn j1939_bounds() {
        // TP and BAM stay whole, ETP is cut, over the ETP limit is left
        // to the kernel's EMSGSIZE.
        assert_eq!(j1939_bound(1785, 7), 1785);
        assert_eq!(j1939_bound(J1939_MAX_SEND, 7), J1939_MAX_SEND);
        assert!((1..=J1939_MAX_SEND).contains(&j1939_bound(70_000, 123_456)));
        assert!((1..=J1939_MAX_SEND).contains(&j1939_bound(117_440_506, 0)));
        // The errnos of a receive include every pending one.
        for e in J1939_PENDING {
            assert!(extra_errs(7, Call::Recvmsg).contains(e));
        }
        assert!(extra_errs(1, Call::Recv).is_empty());
    }

    #[test]
    fn errno_sets() {
        for c in [Call::Send, Call::Recv, Call::Bind, Call::Ioctl] {
            assert!(c.allowed().contains(&libc::EBADF), "{c:?}");
            // EFAULT never: the fuzzer passes only valid buffers.
            assert!(!c.allowed().contains(&libc::EFAULT), "{c:?}");
        }
        assert!(Call::Getpeername.allowed().contains(&libc::ENOTCONN));
        assert_eq!(errno_name(libc::EPROTOTYPE), "EPROTOTYPE");
        assert_eq!(errno_name(515), "errno515");
    }
}
