// SPDX-License-Identifier: GPL-2.0
//! CAN_ISOTP (ISO 15765-2) socket ABI: the constants, option layouts and
//! option checks of mainline's `include/uapi/linux/can/isotp.h` (6.12)
//! and `isotp_setsockopt`/`isotp_getsockopt`, rewritten; plus the limits,
//! timeouts and errno values the state machines of [`super::isotp_tx`]
//! and [`super::isotp_rx`] use, and the routing of a received frame to one
//! of them (mainline's `isotp_rcv`).
//!
//! One [`Config`] exists per socket. It changes only while the socket is
//! unbound ([`Config::setsockopt`] gives `EISCONN` otherwise), so the
//! state machines take it by shared reference on every event.
//! Documentation/networking/rcan/isotp.rst describes the whole protocol.

use super::arb::EINVAL;

/// `CAN_ISOTP`: the protocol number of `socket(PF_CAN, SOCK_DGRAM, 6)`.
pub const CAN_ISOTP: i32 = 6;
/// `SOL_CAN_BASE` of `linux/can.h`.
pub const SOL_CAN_BASE: i32 = 100;
/// `SOL_CAN_ISOTP`: the socket option level of this protocol.
pub const SOL_CAN_ISOTP: i32 = SOL_CAN_BASE + CAN_ISOTP;

/// Option `CAN_ISOTP_OPTS`: a [`IsotpOptions`].
pub const CAN_ISOTP_OPTS: i32 = 1;
/// Option `CAN_ISOTP_RECV_FC`: a [`FcOptions`] (what our FCs announce).
pub const CAN_ISOTP_RECV_FC: i32 = 2;
/// Option `CAN_ISOTP_TX_STMIN`: `u32` ns used instead of the received
/// STmin with [`CAN_ISOTP_FORCE_TXSTMIN`].
pub const CAN_ISOTP_TX_STMIN: i32 = 3;
/// Option `CAN_ISOTP_RX_STMIN`: `u32` ns; with [`CAN_ISOTP_FORCE_RXSTMIN`]
/// consecutive frames closer together than this are dropped.
pub const CAN_ISOTP_RX_STMIN: i32 = 4;
/// Option `CAN_ISOTP_LL_OPTS`: a [`LlOptions`].
pub const CAN_ISOTP_LL_OPTS: i32 = 5;

/// Listen only: never send flow control frames.
pub const CAN_ISOTP_LISTEN_MODE: u32 = 0x0001;
/// Extended (or mixed) addressing: the first data byte is an address.
pub const CAN_ISOTP_EXTEND_ADDR: u32 = 0x0002;
/// Pad transmitted frames to a valid length with `txpad_content`.
pub const CAN_ISOTP_TX_PADDING: u32 = 0x0004;
/// Received frames are expected padded (with `rxpad_content`).
pub const CAN_ISOTP_RX_PADDING: u32 = 0x0008;
/// Check the length of received frames (padded or optimised).
pub const CAN_ISOTP_CHK_PAD_LEN: u32 = 0x0010;
/// Check the padding bytes of received frames.
pub const CAN_ISOTP_CHK_PAD_DATA: u32 = 0x0020;
/// Half duplex: no reception while sending, no FC while receiving.
pub const CAN_ISOTP_HALF_DUPLEX: u32 = 0x0040;
/// Use [`CAN_ISOTP_TX_STMIN`] instead of the STmin of received FCs.
pub const CAN_ISOTP_FORCE_TXSTMIN: u32 = 0x0080;
/// Drop consecutive frames closer than [`CAN_ISOTP_RX_STMIN`].
pub const CAN_ISOTP_FORCE_RXSTMIN: u32 = 0x0100;
/// A separate extended address for reception (`rx_ext_address`).
pub const CAN_ISOTP_RX_EXT_ADDR: u32 = 0x0200;
/// `sendmsg` blocks until the whole PDU is sent.
pub const CAN_ISOTP_WAIT_TX_DONE: u32 = 0x0400;
/// 1-to-N functional addressing: single frames only, no reception.
pub const CAN_ISOTP_SF_BROADCAST: u32 = 0x0800;
/// 1-to-N transmission of FF and CFs without waiting for flow control.
pub const CAN_ISOTP_CF_BROADCAST: u32 = 0x1000;
/// Take BS and STmin from every received FC, not only the first.
pub const CAN_ISOTP_DYN_FC_PARMS: u32 = 0x2000;

/// Every flag mainline 6.12 defines. Mainline stores unknown bits as
/// given (and so do we); this is for tests and documentation.
pub const CAN_ISOTP_ALL_FLAGS: u32 = 0x3FFF;

/// `CAN_ISOTP_DEFAULT_PAD_CONTENT`: also the fill of the padding that CAN
/// FD frames need when [`CAN_ISOTP_TX_PADDING`] is off.
pub const CAN_ISOTP_DEFAULT_PAD_CONTENT: u8 = 0xCC;
/// `CAN_ISOTP_DEFAULT_FRAME_TXTIME`: 50 µs, in ns.
pub const CAN_ISOTP_DEFAULT_FRAME_TXTIME: u32 = 50_000;
/// `CAN_ISOTP_FRAME_TXTIME_ZERO`: a `frame_txtime` meaning "zero" (0
/// itself means "unchanged").
pub const CAN_ISOTP_FRAME_TXTIME_ZERO: u32 = 0xFFFF_FFFF;

/// `CAN_MTU`: classic frames on the link layer.
pub const LL_MTU_CLASSIC: u8 = 16;
/// `CANFD_MTU`: CAN FD frames on the link layer.
pub const LL_MTU_FD: u8 = 72;

/// Default of the `max_pdu_size` module parameter (mainline's
/// `DEFAULT_MAX_PDU_SIZE`).
pub const DEFAULT_MAX_PDU_SIZE: u32 = 8300;
/// Largest PDU before the 32-bit FF_DL escape (`MAX_12BIT_PDU_SIZE`).
pub const MAX_12BIT_PDU_SIZE: u32 = 4095;
/// Upper bound of `max_pdu_size` (`MAX_PDU_SIZE`, 1025 KiB).
pub const MAX_PDU_SIZE: u32 = 1025 * 1024;

/// N_Bs and N_Cr: how long a sender waits for a flow control frame and a
/// receiver for the next consecutive frame (mainline's
/// `ISOTP_FC_TIMEOUT`, 1 s), in ns.
pub const FC_TIMEOUT_NS: u64 = 1_000_000_000;
/// N_As: how long a sender waits for the echo of a frame it sent
/// (`ISOTP_ECHO_TIMEOUT`, 2 s), in ns.
pub const ECHO_TIMEOUT_NS: u64 = 2_000_000_000;

/// The protocol's timeouts in ns, read by both machines from
/// [`Config::timeouts`]: mainline's fixed values by default. rcan_isotp
/// takes others from its test-only module parameters `fc_timeout_ms` and
/// `echo_timeout_ms` (not mainline's; isotp.rst, "Module parameters"), so
/// that tests whose subject is not the timers survive a guest vCPU that
/// waits seconds for its host.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Timeouts {
    /// N_Bs and N_Cr ([`FC_TIMEOUT_NS`] by default).
    pub fc_ns: u64,
    /// N_As, the wait for an echo ([`ECHO_TIMEOUT_NS`] by default).
    pub echo_ns: u64,
}

/// Bounds of the timeout parameters, ms: 1 ms to 10 minutes.
pub const TIMEOUT_MS_MIN: u32 = 1;
/// See [`TIMEOUT_MS_MIN`].
pub const TIMEOUT_MS_MAX: u32 = 600_000;

impl Default for Timeouts {
    fn default() -> Self {
        Timeouts {
            fc_ns: FC_TIMEOUT_NS,
            echo_ns: ECHO_TIMEOUT_NS,
        }
    }
}

impl Timeouts {
    /// The timeouts of the parameters `fc_ms` and `echo_ms`, each clamped
    /// to [`TIMEOUT_MS_MIN`]..=[`TIMEOUT_MS_MAX`].
    pub const fn from_ms(fc_ms: u32, echo_ms: u32) -> Self {
        const fn ns(ms: u32) -> u64 {
            let ms = if ms < TIMEOUT_MS_MIN {
                TIMEOUT_MS_MIN
            } else if ms > TIMEOUT_MS_MAX {
                TIMEOUT_MS_MAX
            } else {
                ms
            };
            ms as u64 * 1_000_000
        }
        Timeouts {
            fc_ns: ns(fc_ms),
            echo_ns: ns(echo_ms),
        }
    }
}

/// `EAGAIN`: a transfer is running (the caller blocks or returns it).
pub const EAGAIN: i32 = 11;
/// `EFAULT`: an option buffer could not be read.
pub const EFAULT: i32 = 14;
/// `ECOMM`: no flow control frame or echo in time (sender).
pub const ECOMM: i32 = 70;
/// `EBADMSG`: a malformed frame or bad padding, or a reserved flow status.
pub const EBADMSG: i32 = 74;
/// `EILSEQ`: a consecutive frame with the wrong sequence number.
pub const EILSEQ: i32 = 84;
/// `EMSGSIZE`: the receiver answered with flow status overflow.
pub const EMSGSIZE: i32 = 90;
/// `ENOPROTOOPT`: an unknown option name.
pub const ENOPROTOOPT: i32 = 92;
/// `EISCONN`: options cannot change while the socket is bound.
pub const EISCONN: i32 = 106;
/// `ETIMEDOUT`: no consecutive frame in time (receiver).
pub const ETIMEDOUT: i32 = 110;

/// Mainline `max_pdu_size` after module load: at least 4095, at most
/// [`MAX_PDU_SIZE`].
pub const fn clamp_max_pdu_size(param: u32) -> u32 {
    if param < MAX_12BIT_PDU_SIZE {
        MAX_12BIT_PDU_SIZE
    } else if param > MAX_PDU_SIZE {
        MAX_PDU_SIZE
    } else {
        param
    }
}

/// The largest PDU a socket sends or receives for the module parameter
/// `max_pdu_size`: the clamped value ([`clamp_max_pdu_size`]), but never
/// under [`DEFAULT_MAX_PDU_SIZE`]. Mainline's buffers start at 8300 bytes
/// and only grow towards the parameter, so a parameter below 8300 (4095,
/// say) takes PDUs of up to 8300 bytes all the same; ours matches.
pub const fn pdu_limit(param: u32) -> u32 {
    let p = clamp_max_pdu_size(param);
    if p < DEFAULT_MAX_PDU_SIZE {
        DEFAULT_MAX_PDU_SIZE
    } else {
        p
    }
}

/// Mainline `struct can_isotp_options` (12 bytes, native endian).
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct IsotpOptions {
    /// `CAN_ISOTP_*` flags.
    pub flags: u32,
    /// N_As in ns added to every STmin gap; 0: unchanged,
    /// [`CAN_ISOTP_FRAME_TXTIME_ZERO`]: zero.
    pub frame_txtime: u32,
    /// Extended address of transmitted frames.
    pub ext_address: u8,
    /// Padding byte of transmitted frames.
    pub txpad_content: u8,
    /// Expected padding byte of received frames.
    pub rxpad_content: u8,
    /// Extended address of received frames (with
    /// [`CAN_ISOTP_RX_EXT_ADDR`]; else `ext_address`).
    pub rx_ext_address: u8,
}

const _: () = assert!(core::mem::size_of::<IsotpOptions>() == IsotpOptions::SIZE);

impl IsotpOptions {
    /// Size of the structure in bytes.
    pub const SIZE: usize = 12;

    /// The native-endian image.
    pub fn to_bytes(&self) -> [u8; Self::SIZE] {
        let f = self.flags.to_ne_bytes();
        let t = self.frame_txtime.to_ne_bytes();
        [
            f[0],
            f[1],
            f[2],
            f[3],
            t[0],
            t[1],
            t[2],
            t[3],
            self.ext_address,
            self.txpad_content,
            self.rxpad_content,
            self.rx_ext_address,
        ]
    }

    /// Parses a native-endian image.
    pub fn from_bytes(b: &[u8; Self::SIZE]) -> Self {
        IsotpOptions {
            flags: u32::from_ne_bytes([b[0], b[1], b[2], b[3]]),
            frame_txtime: u32::from_ne_bytes([b[4], b[5], b[6], b[7]]),
            ext_address: b[8],
            txpad_content: b[9],
            rxpad_content: b[10],
            rx_ext_address: b[11],
        }
    }
}

/// Mainline `struct can_isotp_fc_options` (3 bytes): what the flow
/// control frames we send announce.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct FcOptions {
    /// Block size; 0: no further FC.
    pub bs: u8,
    /// STmin as sent on the wire (not checked, as in mainline).
    pub stmin: u8,
    /// N_WFTmax; stored and reported only (we never send wait frames).
    pub wftmax: u8,
}

const _: () = assert!(core::mem::size_of::<FcOptions>() == 3);

/// Mainline `struct can_isotp_ll_options` (3 bytes): the link layer.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct LlOptions {
    /// [`LL_MTU_CLASSIC`] or [`LL_MTU_FD`]: the only frames sent and
    /// accepted.
    pub mtu: u8,
    /// TX_DL: 8, 12, 16, 20, 24, 32, 48 or 64 (8 for classic).
    pub tx_dl: u8,
    /// `canfd_frame.flags` of transmitted frames (e.g. `CANFD_BRS`); 0
    /// for classic.
    pub tx_flags: u8,
}

const _: () = assert!(core::mem::size_of::<LlOptions>() == 3);

impl Default for LlOptions {
    fn default() -> Self {
        LlOptions {
            mtu: LL_MTU_CLASSIC,
            tx_dl: 8,
            tx_flags: 0,
        }
    }
}

impl LlOptions {
    /// Whether the link layer is CAN FD.
    pub fn is_fd(&self) -> bool {
        self.mtu == LL_MTU_FD
    }
}

/// The options of one socket, as mainline's `isotp_init` sets them and
/// `isotp_setsockopt` changes them. Owned by the socket and changed only
/// under its socket lock while unbound; the protocol reads it lock-free
/// while bound (it is immutable then).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Config {
    /// `CAN_ISOTP_OPTS` as last set (its `frame_txtime` as given).
    pub opt: IsotpOptions,
    /// N_As in ns in effect (see [`IsotpOptions::frame_txtime`]).
    pub frame_txtime: u32,
    /// `CAN_ISOTP_RECV_FC`.
    pub rxfc: FcOptions,
    /// `CAN_ISOTP_TX_STMIN` in ns.
    pub force_tx_stmin: u32,
    /// `CAN_ISOTP_RX_STMIN` in ns.
    pub force_rx_stmin: u32,
    /// `CAN_ISOTP_LL_OPTS`.
    pub ll: LlOptions,
    /// The timeouts (not an option: rcan_isotp sets them at bind from
    /// its module parameters).
    pub timeouts: Timeouts,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            opt: IsotpOptions {
                flags: 0,
                frame_txtime: CAN_ISOTP_DEFAULT_FRAME_TXTIME,
                ext_address: 0,
                txpad_content: CAN_ISOTP_DEFAULT_PAD_CONTENT,
                rxpad_content: CAN_ISOTP_DEFAULT_PAD_CONTENT,
                rx_ext_address: 0,
            },
            frame_txtime: CAN_ISOTP_DEFAULT_FRAME_TXTIME,
            rxfc: FcOptions::default(),
            force_tx_stmin: 0,
            force_rx_stmin: 0,
            ll: LlOptions::default(),
            timeouts: Timeouts::default(),
        }
    }
}

/// The largest option image ([`IsotpOptions::SIZE`]).
pub const MAX_OPTLEN: usize = IsotpOptions::SIZE;

impl Config {
    /// Whether `flag` is set.
    pub fn has(&self, flag: u32) -> bool {
        self.opt.flags & flag != 0
    }

    /// Bytes before the N_PCI: 1 with extended addressing, else 0.
    pub fn ae(&self) -> usize {
        usize::from(self.has(CAN_ISOTP_EXTEND_ADDR))
    }

    /// The broadcast flags ([`CAN_ISOTP_SF_BROADCAST`],
    /// [`CAN_ISOTP_CF_BROADCAST`]) that are set.
    pub fn bc_flags(&self) -> u32 {
        self.opt.flags & (CAN_ISOTP_SF_BROADCAST | CAN_ISOTP_CF_BROADCAST)
    }

    /// Whether the socket receives on `rx_id` (no broadcast flag): only
    /// then are SF/FF/CF received and FCs expected.
    pub fn registers_rx_id(&self) -> bool {
        self.bc_flags() == 0
    }

    /// Mainline `isotp_setsockopt`: `level`, `optname` and the option
    /// image `val` (its length is `optlen`). `bound`: `EISCONN`. A
    /// [`CAN_ISOTP_OPTS`] with both broadcast flags is stored without
    /// [`CAN_ISOTP_CF_BROADCAST`] and still answered `EINVAL`, as
    /// mainline does; every other error leaves the configuration alone.
    pub fn setsockopt(
        &mut self,
        level: i32,
        optname: i32,
        val: &[u8],
        bound: bool,
    ) -> Result<(), i32> {
        if level != SOL_CAN_ISOTP {
            return Err(EINVAL);
        }
        if bound {
            return Err(EISCONN);
        }
        match optname {
            CAN_ISOTP_OPTS => {
                let b: &[u8; IsotpOptions::SIZE] = val.try_into().map_err(|_| EINVAL)?;
                self.opt = IsotpOptions::from_bytes(b);
                if !self.has(CAN_ISOTP_RX_EXT_ADDR) {
                    self.opt.rx_ext_address = self.opt.ext_address;
                }
                let mut ret = Ok(());
                if self.bc_flags() == CAN_ISOTP_SF_BROADCAST | CAN_ISOTP_CF_BROADCAST {
                    self.opt.flags &= !CAN_ISOTP_CF_BROADCAST;
                    ret = Err(EINVAL);
                }
                match self.opt.frame_txtime {
                    0 => {}
                    CAN_ISOTP_FRAME_TXTIME_ZERO => self.frame_txtime = 0,
                    t => self.frame_txtime = t,
                }
                ret
            }
            CAN_ISOTP_RECV_FC => {
                let b: &[u8; 3] = val.try_into().map_err(|_| EINVAL)?;
                self.rxfc = FcOptions {
                    bs: b[0],
                    stmin: b[1],
                    wftmax: b[2],
                };
                Ok(())
            }
            CAN_ISOTP_TX_STMIN | CAN_ISOTP_RX_STMIN => {
                let b: &[u8; 4] = val.try_into().map_err(|_| EINVAL)?;
                let v = u32::from_ne_bytes(*b);
                if optname == CAN_ISOTP_TX_STMIN {
                    self.force_tx_stmin = v;
                } else {
                    self.force_rx_stmin = v;
                }
                Ok(())
            }
            CAN_ISOTP_LL_OPTS => {
                let b: &[u8; 3] = val.try_into().map_err(|_| EINVAL)?;
                let ll = LlOptions {
                    mtu: b[0],
                    tx_dl: b[1],
                    tx_flags: b[2],
                };
                if ll.tx_dl != super::isotp_pci::padlen(ll.tx_dl) {
                    return Err(EINVAL);
                }
                if ll.mtu != LL_MTU_CLASSIC && ll.mtu != LL_MTU_FD {
                    return Err(EINVAL);
                }
                if ll.mtu == LL_MTU_CLASSIC && (ll.tx_dl > 8 || ll.tx_flags != 0) {
                    return Err(EINVAL);
                }
                self.ll = ll;
                Ok(())
            }
            _ => Err(ENOPROTOOPT),
        }
    }

    /// Mainline `isotp_getsockopt` for `level`, `optname` and a user
    /// buffer of `len` bytes (negative: `EINVAL`): the image, of which the
    /// first `n` bytes are copied out and `n` is written back as the
    /// length (`n` = the smaller of `len` and the option's size).
    pub fn getsockopt(
        &self,
        level: i32,
        optname: i32,
        len: i32,
    ) -> Result<([u8; MAX_OPTLEN], usize), i32> {
        if level != SOL_CAN_ISOTP || len < 0 {
            return Err(EINVAL);
        }
        let mut img = [0u8; MAX_OPTLEN];
        let size = match optname {
            CAN_ISOTP_OPTS => {
                img.copy_from_slice(&self.opt.to_bytes());
                IsotpOptions::SIZE
            }
            CAN_ISOTP_RECV_FC => {
                img[..3].copy_from_slice(&[self.rxfc.bs, self.rxfc.stmin, self.rxfc.wftmax]);
                3
            }
            CAN_ISOTP_TX_STMIN => {
                img[..4].copy_from_slice(&self.force_tx_stmin.to_ne_bytes());
                4
            }
            CAN_ISOTP_RX_STMIN => {
                img[..4].copy_from_slice(&self.force_rx_stmin.to_ne_bytes());
                4
            }
            CAN_ISOTP_LL_OPTS => {
                img[..3].copy_from_slice(&[self.ll.mtu, self.ll.tx_dl, self.ll.tx_flags]);
                3
            }
            _ => return Err(ENOPROTOOPT),
        };
        // len >= 0 was checked above.
        Ok((img, size.min(len as usize)))
    }

    /// The `sendmsg` size check of mainline before anything is sent:
    /// `EINVAL` for an empty PDU, one over `max_pdu_size` (the clamped
    /// module parameter), or, with only [`CAN_ISOTP_SF_BROADCAST`], one
    /// that does not fit a single frame of TX_DL.
    pub fn check_send_len(&self, len: usize, max_pdu_size: u32) -> Result<(), i32> {
        if len == 0 || len > max_pdu_size as usize {
            return Err(EINVAL);
        }
        if self.bc_flags() == CAN_ISOTP_SF_BROADCAST && len > super::isotp_pci::sf_max(self) {
            return Err(EINVAL);
        }
        Ok(())
    }
}

/// `ENODEV`: `bind` without an interface index.
pub const ENODEV: i32 = 19;
/// `EADDRNOTAVAIL`: `bind` with `rx_id` equal to `tx_id`.
pub const EADDRNOTAVAIL: i32 = 99;

/// Bytes of `struct sockaddr_can` up to and including `can_addr.tp`
/// (mainline `ISOTP_MIN_NAMELEN`): family, pad, ifindex, rx_id, tx_id.
pub const ISOTP_MIN_NAMELEN: usize = 16;

/// The address of an ISO-TP socket: `sockaddr_can` with
/// `can_addr.tp = {rx_id, tx_id}`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct TpAddr {
    /// Interface index (`can_ifindex`).
    pub ifindex: i32,
    /// Identifier we receive SF/FF/CF on (and FCs, when sending).
    pub rx_id: u32,
    /// Identifier we send on.
    pub tx_id: u32,
}

impl TpAddr {
    /// Mainline `isotp_bind`'s checks of the address itself, in its
    /// order: shorter than [`ISOTP_MIN_NAMELEN`] or not `AF_CAN`:
    /// `EINVAL`; a `tx_id` (and, unless a broadcast flag is set, an
    /// `rx_id`) with bits outside its 11- or 29-bit identifier and
    /// `CAN_EFF_FLAG`: `EINVAL`; interface index 0: `ENODEV`. The
    /// checks that need the socket's state or the device (already bound,
    /// a transfer still draining, [`TpAddr::check_distinct`], device
    /// type and MTU) are the module's.
    pub fn parse(cfg: &Config, b: &[u8]) -> Result<TpAddr, i32> {
        use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_SFF_MASK};
        let b: &[u8; ISOTP_MIN_NAMELEN] = b
            .get(..ISOTP_MIN_NAMELEN)
            .and_then(|h| h.try_into().ok())
            .ok_or(EINVAL)?;
        if u16::from_ne_bytes([b[0], b[1]]) != super::sockaddr::AF_CAN {
            return Err(EINVAL);
        }
        let word = |i: usize| [b[i], b[i + 1], b[i + 2], b[i + 3]];
        let a = TpAddr {
            ifindex: i32::from_ne_bytes(word(4)),
            rx_id: u32::from_ne_bytes(word(8)),
            tx_id: u32::from_ne_bytes(word(12)),
        };
        let clean = |id: u32| {
            if id & CAN_EFF_FLAG != 0 {
                id & (CAN_EFF_FLAG | CAN_EFF_MASK) == id
            } else {
                id & CAN_SFF_MASK == id
            }
        };
        if !clean(a.tx_id) || (cfg.registers_rx_id() && !clean(a.rx_id)) {
            return Err(EINVAL);
        }
        if a.ifindex == 0 {
            return Err(ENODEV);
        }
        Ok(a)
    }

    /// `EADDRNOTAVAIL` when the socket receives on `rx_id` and it equals
    /// `tx_id` (mainline checks it after "already bound" and "busy").
    pub fn check_distinct(&self, cfg: &Config) -> Result<(), i32> {
        if cfg.registers_rx_id() && self.rx_id == self.tx_id {
            Err(EADDRNOTAVAIL)
        } else {
            Ok(())
        }
    }

    /// The `getsockname` image (mainline `isotp_getname`: 16 bytes).
    pub fn to_bytes(&self) -> [u8; ISOTP_MIN_NAMELEN] {
        let mut b = [0u8; ISOTP_MIN_NAMELEN];
        b[..2].copy_from_slice(&super::sockaddr::AF_CAN.to_ne_bytes());
        b[4..8].copy_from_slice(&self.ifindex.to_ne_bytes());
        b[8..12].copy_from_slice(&self.rx_id.to_ne_bytes());
        b[12..].copy_from_slice(&self.tx_id.to_ne_bytes());
        b
    }
}

/// The receive filter mask for exactly one identifier (mainline's
/// `SINGLE_MASK`): all identifier bits of its format, `CAN_EFF_FLAG` and
/// `CAN_RTR_FLAG` (so remote frames never match).
pub const fn single_mask(id: u32) -> u32 {
    use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_RTR_FLAG, CAN_SFF_MASK};
    if id & CAN_EFF_FLAG != 0 {
        CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG
    } else {
        CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG
    }
}

/// What to do with a state machine's one timer after an event. Times are
/// absolute (ns, monotonic); a machine ignores an expiry reported before
/// its deadline, so a stale callback of a timer that was re-armed in the
/// meantime does no harm.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum TimerCmd {
    /// Leave it as it is.
    Keep,
    /// (Re)arm it to expire at this time.
    Arm(u64),
    /// Cancel it.
    Cancel,
}

/// Where a received frame goes (mainline `isotp_rcv`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Route {
    /// Not for this socket: wrong frame type (classic/FD) for the link
    /// layer, wrong extended address, too short to hold the N_PCI (or
    /// longer than its frame type allows), or
    /// dropped by [`CAN_ISOTP_HALF_DUPLEX`].
    Drop,
    /// A flow control frame: to the sender
    /// ([`super::isotp_tx::Tx::on_fc`]).
    Tx,
    /// SF, FF or CF (or a reserved N_PCI type, which the receiver
    /// ignores): to the receiver ([`super::isotp_rx::Rx::on_frame`]).
    Rx,
}

/// Routes a received frame with payload `data` (`cf->data[..len]`); `fd`:
/// it arrived as a CAN FD frame; `tx_idle`/`rx_idle`: the states of the
/// socket's sender and receiver (only [`CAN_ISOTP_HALF_DUPLEX`] looks).
///
/// Differs from mainline in one corner: a frame too short to hold its
/// N_PCI byte (and extended address) is dropped here, where mainline
/// reads the stale bytes behind `len` in the frame buffer.
pub fn route(cfg: &Config, fd: bool, data: &[u8], tx_idle: bool, rx_idle: bool) -> Route {
    let ae = cfg.ae();
    let max = if fd { 64 } else { 8 };
    if fd != cfg.ll.is_fd() || data.len() <= ae || data.len() > max {
        return Route::Drop;
    }
    if ae == 1 && data[0] != cfg.opt.rx_ext_address {
        return Route::Drop;
    }
    let is_fc = data[ae] & 0xF0 == super::isotp_pci::N_PCI_FC;
    if cfg.has(CAN_ISOTP_HALF_DUPLEX) && ((!tx_idle && !is_fc) || (!rx_idle && is_fc)) {
        return Route::Drop;
    }
    if is_fc {
        Route::Tx
    } else {
        Route::Rx
    }
}

#[cfg(test)]
// Tests start from the defaults and change what they exercise.
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::*;

    #[test]
    fn layouts_match_mainline() {
        // Offsets of struct can_isotp_options: flags 0, frame_txtime 4,
        // ext_address 8, txpad 9, rxpad 10, rx_ext_address 11.
        let o = IsotpOptions {
            flags: 0x0102_0304,
            frame_txtime: 0x0506_0708,
            ext_address: 9,
            txpad_content: 10,
            rxpad_content: 11,
            rx_ext_address: 12,
        };
        let b = o.to_bytes();
        assert_eq!(&b[..4], &0x0102_0304u32.to_ne_bytes());
        assert_eq!(&b[4..8], &0x0506_0708u32.to_ne_bytes());
        assert_eq!(&b[8..], &[9, 10, 11, 12]);
        assert_eq!(IsotpOptions::from_bytes(&b), o);
        assert_eq!(SOL_CAN_ISOTP, 106);
        assert_eq!(CAN_ISOTP_ALL_FLAGS, 0x3FFF);
    }

    fn set(c: &mut Config, name: i32, v: &[u8]) -> Result<(), i32> {
        c.setsockopt(SOL_CAN_ISOTP, name, v, false)
    }

    #[test]
    fn defaults_are_mainlines() {
        let c = Config::default();
        let (img, n) = c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_OPTS, 100).unwrap();
        assert_eq!(n, 12);
        let o = IsotpOptions::from_bytes(&img);
        assert_eq!((o.flags, o.frame_txtime), (0, 50_000));
        assert_eq!((o.txpad_content, o.rxpad_content), (0xCC, 0xCC));
        let (img, n) = c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_LL_OPTS, 3).unwrap();
        assert_eq!(&img[..n], &[16, 8, 0]);
        let (img, n) = c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_RECV_FC, 2).unwrap();
        assert_eq!(&img[..n], &[0, 0]);
    }

    #[test]
    fn opts_rx_ext_address_and_txtime() {
        let mut c = Config::default();
        let mut o = c.opt;
        o.ext_address = 0x55;
        o.rx_ext_address = 0x66;
        o.frame_txtime = 0;
        set(&mut c, CAN_ISOTP_OPTS, &o.to_bytes()).unwrap();
        // No CAN_ISOTP_RX_EXT_ADDR: rx address follows ext_address.
        assert_eq!(c.opt.rx_ext_address, 0x55);
        // frame_txtime 0: unchanged.
        assert_eq!(c.frame_txtime, 50_000);
        o.flags = CAN_ISOTP_RX_EXT_ADDR;
        o.frame_txtime = CAN_ISOTP_FRAME_TXTIME_ZERO;
        set(&mut c, CAN_ISOTP_OPTS, &o.to_bytes()).unwrap();
        assert_eq!((c.opt.rx_ext_address, c.frame_txtime), (0x66, 0));
        o.frame_txtime = 1234;
        set(&mut c, CAN_ISOTP_OPTS, &o.to_bytes()).unwrap();
        assert_eq!(c.frame_txtime, 1234);
    }

    #[test]
    fn both_broadcast_flags_stored_as_sf_and_einval() {
        let mut c = Config::default();
        let mut o = c.opt;
        o.flags = CAN_ISOTP_SF_BROADCAST | CAN_ISOTP_CF_BROADCAST | CAN_ISOTP_TX_PADDING;
        assert_eq!(set(&mut c, CAN_ISOTP_OPTS, &o.to_bytes()), Err(EINVAL));
        assert_eq!(c.opt.flags, CAN_ISOTP_SF_BROADCAST | CAN_ISOTP_TX_PADDING);
    }

    #[test]
    fn option_errors() {
        let mut c = Config::default();
        let before = c;
        assert_eq!(
            c.setsockopt(SOL_CAN_ISOTP + 1, CAN_ISOTP_OPTS, &[0; 12], false),
            Err(EINVAL)
        );
        assert_eq!(
            c.setsockopt(SOL_CAN_ISOTP, CAN_ISOTP_OPTS, &[0; 12], true),
            Err(EISCONN)
        );
        assert_eq!(set(&mut c, CAN_ISOTP_OPTS, &[0; 11]), Err(EINVAL));
        assert_eq!(set(&mut c, CAN_ISOTP_OPTS, &[0; 13]), Err(EINVAL));
        assert_eq!(set(&mut c, CAN_ISOTP_RECV_FC, &[0; 4]), Err(EINVAL));
        assert_eq!(set(&mut c, CAN_ISOTP_TX_STMIN, &[0; 3]), Err(EINVAL));
        assert_eq!(set(&mut c, CAN_ISOTP_RX_STMIN, &[0; 8]), Err(EINVAL));
        assert_eq!(set(&mut c, 6, &[0; 4]), Err(ENOPROTOOPT));
        assert_eq!(set(&mut c, 0, &[0; 4]), Err(ENOPROTOOPT));
        assert_eq!(c, before);
        assert_eq!(c.getsockopt(SOL_CAN_ISOTP, 6, 4), Err(ENOPROTOOPT));
        assert_eq!(c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_OPTS, -1), Err(EINVAL));
        assert_eq!(c.getsockopt(0, CAN_ISOTP_OPTS, 4), Err(EINVAL));
    }

    #[test]
    fn ll_opts_checked_like_mainline() {
        let mut c = Config::default();
        for dl in 0..=255u8 {
            for (mtu, flags) in [(16u8, 0u8), (16, 1), (72, 0), (72, 1), (0, 0), (17, 0)] {
                let ok = matches!(dl, 8 | 12 | 16 | 20 | 24 | 32 | 48 | 64)
                    && (mtu == 72 || (mtu == 16 && dl == 8 && flags == 0));
                let r = set(&mut c, CAN_ISOTP_LL_OPTS, &[mtu, dl, flags]);
                assert_eq!(r.is_ok(), ok, "mtu {mtu} tx_dl {dl} flags {flags}");
                if ok {
                    assert_eq!(
                        c.ll,
                        LlOptions {
                            mtu,
                            tx_dl: dl,
                            tx_flags: flags
                        }
                    );
                } else {
                    assert_eq!(r, Err(EINVAL));
                }
            }
        }
        assert_eq!(set(&mut c, CAN_ISOTP_LL_OPTS, &[72, 64]), Err(EINVAL));
    }

    #[test]
    fn stmin_and_fc_options_round_trip() {
        let mut c = Config::default();
        set(&mut c, CAN_ISOTP_TX_STMIN, &7u32.to_ne_bytes()).unwrap();
        set(&mut c, CAN_ISOTP_RX_STMIN, &9u32.to_ne_bytes()).unwrap();
        set(&mut c, CAN_ISOTP_RECV_FC, &[4, 0xF3, 2]).unwrap();
        let (img, n) = c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_TX_STMIN, 8).unwrap();
        assert_eq!(&img[..n], &7u32.to_ne_bytes());
        let (img, n) = c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_RX_STMIN, 4).unwrap();
        assert_eq!(&img[..n], &9u32.to_ne_bytes());
        let (img, n) = c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_RECV_FC, 3).unwrap();
        assert_eq!(&img[..n], &[4, 0xF3, 2]);
        assert_eq!(
            c.getsockopt(SOL_CAN_ISOTP, CAN_ISOTP_RECV_FC, 0).unwrap().1,
            0
        );
    }

    #[test]
    fn max_pdu_size_clamped() {
        assert_eq!(clamp_max_pdu_size(0), 4095);
        assert_eq!(clamp_max_pdu_size(8300), 8300);
        assert_eq!(clamp_max_pdu_size(u32::MAX), 1025 * 1024);
        // Mainline's buffers never shrink under 8300 bytes.
        assert_eq!(pdu_limit(0), 8300);
        assert_eq!(pdu_limit(5000), 8300);
        assert_eq!(pdu_limit(8300), 8300);
        assert_eq!(pdu_limit(10000), 10000);
        assert_eq!(pdu_limit(u32::MAX), 1025 * 1024);
    }

    #[test]
    fn send_len_checks() {
        let mut c = Config::default();
        assert_eq!(c.check_send_len(0, 8300), Err(EINVAL));
        assert_eq!(c.check_send_len(8300, 8300), Ok(()));
        assert_eq!(c.check_send_len(8301, 8300), Err(EINVAL));
        c.opt.flags = CAN_ISOTP_SF_BROADCAST;
        assert_eq!(c.check_send_len(7, 8300), Ok(()));
        assert_eq!(c.check_send_len(8, 8300), Err(EINVAL));
        c.opt.flags |= CAN_ISOTP_EXTEND_ADDR;
        assert_eq!(c.check_send_len(7, 8300), Err(EINVAL));
        c.opt.flags = CAN_ISOTP_SF_BROADCAST;
        c.ll = LlOptions {
            mtu: 72,
            tx_dl: 64,
            tx_flags: 0,
        };
        assert_eq!(c.check_send_len(62, 8300), Ok(()));
        assert_eq!(c.check_send_len(63, 8300), Err(EINVAL));
        // CF_BROADCAST has no single-frame limit.
        c.opt.flags = CAN_ISOTP_CF_BROADCAST;
        assert_eq!(c.check_send_len(4000, 8300), Ok(()));
    }

    fn addr(family: u16, ifindex: i32, rx: u32, tx: u32) -> Vec<u8> {
        let mut v = family.to_ne_bytes().to_vec();
        v.extend_from_slice(&[0, 0]);
        v.extend_from_slice(&ifindex.to_ne_bytes());
        v.extend_from_slice(&rx.to_ne_bytes());
        v.extend_from_slice(&tx.to_ne_bytes());
        v
    }

    #[test]
    fn bind_address_checks() {
        let mut c = Config::default();
        let a = TpAddr::parse(&c, &addr(29, 3, 0x7E8, 0x7E0)).unwrap();
        assert_eq!(
            a,
            TpAddr {
                ifindex: 3,
                rx_id: 0x7E8,
                tx_id: 0x7E0
            }
        );
        assert_eq!(&a.to_bytes()[..], &addr(29, 3, 0x7E8, 0x7E0)[..]);
        // Longer sockaddr_can (with j1939/padding) is fine.
        let mut long = addr(29, 3, 0x7E8, 0x7E0);
        long.extend_from_slice(&[0; 8]);
        assert!(TpAddr::parse(&c, &long).is_ok());
        assert_eq!(TpAddr::parse(&c, &long[..15]), Err(EINVAL));
        assert_eq!(TpAddr::parse(&c, &addr(2, 3, 1, 2)), Err(EINVAL));
        assert_eq!(TpAddr::parse(&c, &addr(29, 3, 1, 0x800)), Err(EINVAL));
        assert_eq!(TpAddr::parse(&c, &addr(29, 3, 0x800, 2)), Err(EINVAL));
        assert_eq!(TpAddr::parse(&c, &addr(29, 3, 1, 0x4000_0002)), Err(EINVAL));
        let eff = 0x8000_0000 | 0x18DA_F110;
        assert!(TpAddr::parse(&c, &addr(29, 3, eff, 0x8000_0000 | 0x18DA_10F1)).is_ok());
        assert_eq!(TpAddr::parse(&c, &addr(29, 0, 1, 2)), Err(ENODEV));
        // Tx before ifindex: a bad tx_id wins over ifindex 0.
        assert_eq!(TpAddr::parse(&c, &addr(29, 0, 1, 0x800)), Err(EINVAL));
        let same = TpAddr::parse(&c, &addr(29, 3, 5, 5)).unwrap();
        assert_eq!(same.check_distinct(&c), Err(EADDRNOTAVAIL));
        // Broadcast sockets do not receive: rx_id unchecked.
        c.opt.flags = CAN_ISOTP_SF_BROADCAST;
        assert!(TpAddr::parse(&c, &addr(29, 3, 0xFFFF_FFFF, 2)).is_ok());
        assert_eq!(same.check_distinct(&c), Ok(()));
        assert_eq!(single_mask(0x123), 0xC000_07FF);
        assert_eq!(single_mask(eff), 0xDFFF_FFFF);
    }

    #[test]
    fn routing() {
        let mut c = Config::default();
        assert_eq!(route(&c, false, &[0x30, 0, 0], true, true), Route::Tx);
        assert_eq!(route(&c, false, &[0x02, 1, 2], true, true), Route::Rx);
        assert_eq!(route(&c, true, &[0x02, 1, 2], true, true), Route::Drop);
        assert_eq!(route(&c, false, &[], true, true), Route::Drop);
        c.opt.flags = CAN_ISOTP_HALF_DUPLEX;
        assert_eq!(route(&c, false, &[0x30, 0, 0], true, false), Route::Drop);
        assert_eq!(route(&c, false, &[0x02, 1, 2], false, true), Route::Drop);
        assert_eq!(route(&c, false, &[0x30, 0, 0], false, true), Route::Tx);
        assert_eq!(route(&c, false, &[0x21, 1, 2], true, false), Route::Rx);
        c.opt.flags = CAN_ISOTP_EXTEND_ADDR;
        c.opt.rx_ext_address = 0xF1;
        assert_eq!(route(&c, false, &[0xF1, 0x30, 0, 0], true, true), Route::Tx);
        assert_eq!(
            route(&c, false, &[0xF2, 0x30, 0, 0], true, true),
            Route::Drop
        );
        assert_eq!(route(&c, false, &[0xF1], true, true), Route::Drop);
        c.ll = LlOptions {
            mtu: 72,
            tx_dl: 64,
            tx_flags: 0,
        };
        assert_eq!(route(&c, true, &[0xF1, 0x01, 9], true, true), Route::Rx);
        assert_eq!(route(&c, false, &[0xF1, 0x01, 9], true, true), Route::Drop);
    }
}
