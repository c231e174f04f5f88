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
];

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
        ETIMEDOUT => "ETIMEDOUT",
        ECONNREFUSED => "ECONNREFUSED",
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
