// SPDX-License-Identifier: GPL-2.0
//! Info-leak checks (issue 15, item 2): every buffer the kernel may write
//! is filled with [`POISON`] before the call; afterwards the bytes it
//! reports written (the return value, `msg_namelen`, `optlen`,
//! `msg_controllen`) are checked against the layout of what it wrote, and
//! the bytes past them must still be poison. A byte of padding inside a
//! reported structure that is neither zero nor poison is kernel memory
//! that was never initialised (the CVE-2021-34693 pattern: a stack struct
//! copied out with its holes); a byte past the reported length that is
//! not poison was written without being reported.
//!
//! What is checked, per call:
//!
//! * `recv`/`recvfrom`/`recvmsg` data: nothing written past
//!   `min(return value, buffer)`. The frame and message bytes themselves
//!   come from other sockets' random sends, so their content is not
//!   checked here (frames the kernel builds itself are, by the VM tests
//!   `leak_*`).
//! * Addresses (`recvfrom`, `recvmsg` `msg_name`, `getsockname`,
//!   `getpeername`): nothing past `min(reported, buffer)`; the padding of
//!   the protocol's address layout ([`addr_padding`]) zero or poison.
//! * `getsockopt`: nothing past the returned `optlen`; nothing at all on
//!   failure at a protocol level (`SOL_SOCKET` is the socket layer's).
//! * Control messages: a well-formed chain up to `msg_controllen`
//!   (`cmsg_len` at least a header, inside the buffer), the alignment gaps
//!   between messages and the padding of the payloads we know
//!   (`struct sock_extended_err`) zero or poison, nothing past
//!   `msg_controllen`.

use libc::c_int;

/// What every buffer the kernel may write holds before the call.
pub const POISON: u8 = 0xAA;

/// `SOL_CAN_RAW`.
const SOL_CAN_RAW: c_int = 101;
/// `SCM_CAN_RAW_ERRQUEUE`: a `struct sock_extended_err`.
const SCM_CAN_RAW_ERRQUEUE: c_int = 1;
/// `SOL_CAN_J1939` and `SCM_J1939_ERRQUEUE`: a `struct sock_extended_err`
/// too.
const SOL_CAN_J1939: c_int = 107;
const SCM_J1939_ERRQUEUE: c_int = 4;
/// `sizeof(struct cmsghdr)` on x86_64.
const CMSG_HDR: usize = 16;

/// What a socket is, as far as the layout of what the kernel writes to
/// user space goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// CAN_RAW: `struct sockaddr_can`.
    Raw,
    /// CANPROTO_CAN: `struct sockaddr_canarb`.
    Arb,
    /// CANPROTO_DSOR: `struct sockaddr_cansegm` or `sockaddr_canport`.
    Dsor,
    /// CAN_BCM: `struct sockaddr_can` (mainline reports 16 bytes), and
    /// replies that start with a `struct bcm_msg_head`.
    Bcm,
    /// CAN_ISOTP: `struct sockaddr_can` of 16 bytes (family, ifindex and,
    /// from getsockname, `can_addr.tp`; zeros from recvmsg).
    Isotp,
    /// CAN_J1939: `struct sockaddr_can` of 24 bytes (family, ifindex,
    /// `can_addr.j1939` {name, pgn, addr}, three bytes of padding).
    J1939,
}

/// Offsets of the padding bytes in an address of `kind` that the kernel
/// reported as `len` bytes long (the length tells DSOR's two layouts
/// apart); bytes of no field.
///
/// * `sockaddr_can` (CAN_RAW): family (0..2), two bytes of padding, ifindex
///   (4..8), and the 16-byte union of transport addresses, which CAN_RAW
///   does not use (mainline reports 8 bytes; if more are reported they
///   must be zero);
/// * `sockaddr_can` (CAN_ISOTP): family, two bytes of padding, ifindex,
///   `rx_id`, `tx_id` (16 bytes reported; more must be zero);
/// * `sockaddr_can` (CAN_J1939): family, two bytes of padding, ifindex,
///   name (8..16), pgn (16..20), addr (20), three bytes of padding (24
///   bytes reported; more must be zero);
/// * `sockaddr_canarb`: family, two bytes of padding, arb, mask, ifindex;
/// * `sockaddr_cansegm` (8 bytes): family, priority, node, id: no padding;
/// * `sockaddr_canport` (6 bytes): family, port, priority, one byte of
///   padding.
pub fn addr_padding(kind: Kind, len: usize) -> Vec<usize> {
    match (kind, len) {
        (Kind::Raw | Kind::Bcm, _) => [2, 3].into_iter().chain(8..len.max(8)).collect(),
        (Kind::Arb, _) => vec![2, 3],
        (Kind::Isotp, _) => [2, 3].into_iter().chain(16..len.max(16)).collect(),
        (Kind::J1939, _) => [2, 3].into_iter().chain(21..len.max(24)).collect(),
        (Kind::Dsor, 6) => vec![5],
        (Kind::Dsor, _) => vec![],
    }
}

fn is_clean(b: u8) -> bool {
    b == 0 || b == POISON
}

/// Fails if any byte of `buf` from `from` on is not poison.
pub fn untouched(buf: &[u8], from: usize, what: &str) -> Result<(), String> {
    match buf.iter().skip(from).position(|&b| b != POISON) {
        Some(i) => Err(format!(
            "{what}: byte {} written past the {from} reported ({:#04x})",
            from + i,
            buf[from + i]
        )),
        None => Ok(()),
    }
}

/// An address the kernel reported as `reported` bytes long into `buf`
/// (poisoned before): nothing past it, the padding of `kind`'s layout
/// zero or poison. `kind` None: only the first check.
pub fn check_addr(
    kind: Option<Kind>,
    buf: &[u8],
    reported: usize,
    what: &str,
) -> Result<(), String> {
    let written = reported.min(buf.len());
    untouched(buf, written, what)?;
    let Some(kind) = kind else { return Ok(()) };
    for off in addr_padding(kind, reported) {
        if off < written && !is_clean(buf[off]) {
            return Err(format!(
                "{what}: padding byte {off} of a {reported}-byte {kind:?} address is {:#04x} \
                 (neither zero nor the 0x{POISON:02x} poison): uninitialised kernel memory? [{}]",
                buf[off],
                hex(&buf[..written])
            ));
        }
    }
    Ok(())
}

/// Bytes 12..16 of a `struct bcm_msg_head` on x86_64: the hole between
/// `count` (8..12) and `ival1` (16, 8-byte aligned). Mainline's
/// CVE-2021-34693 was exactly these bytes, copied from the stack.
pub const BCM_HEAD_HOLE: std::ops::Range<usize> = 12..16;

/// A BCM reply of `ret` bytes in `buf`: if it holds a whole
/// `bcm_msg_head`, its hole is zero or poison.
pub fn check_bcm_reply(buf: &[u8], ret: usize, what: &str) -> Result<(), String> {
    if ret < 56 || buf.len() < 56 {
        return Ok(());
    }
    for off in BCM_HEAD_HOLE {
        if !is_clean(buf[off]) {
            return Err(format!(
                "{what}: byte {off} of a bcm_msg_head (the hole after count) is {:#04x} \
                 (neither zero nor the 0x{POISON:02x} poison): uninitialised kernel memory? [{}]",
                buf[off],
                hex(&buf[..56])
            ));
        }
    }
    Ok(())
}

/// Receive data: nothing written past `min(ret, buffer)`.
pub fn check_data(buf: &[u8], ret: usize, what: &str) -> Result<(), String> {
    untouched(buf, ret.min(buf.len()), what)
}

/// A `getsockopt` value buffer (poisoned before): on success nothing past
/// the returned `optlen`; on failure at a protocol level, nothing at all.
pub fn check_opt(
    buf: &[u8],
    res: Result<usize, c_int>,
    level: c_int,
    what: &str,
) -> Result<(), String> {
    match res {
        Ok(len) => untouched(buf, len.min(buf.len()), what),
        Err(_) if level != libc::SOL_SOCKET => untouched(buf, 0, &format!("{what} (failed)")),
        Err(_) => Ok(()),
    }
}

/// Control messages: `buf` is the whole (poisoned) control buffer, of
/// which the kernel reported `controllen` bytes used.
pub fn check_cmsgs(buf: &[u8], controllen: usize, what: &str) -> Result<(), String> {
    if controllen > buf.len() {
        return Err(format!(
            "{what}: msg_controllen {controllen} > {}",
            buf.len()
        ));
    }
    untouched(buf, controllen, what)?;
    let mut off = 0;
    while off < controllen {
        if controllen - off < CMSG_HDR {
            return gap(buf, off, controllen, what);
        }
        let len = u64::from_ne_bytes(buf[off..off + 8].try_into().unwrap()) as usize;
        let level = c_int::from_ne_bytes(buf[off + 8..off + 12].try_into().unwrap());
        let ty = c_int::from_ne_bytes(buf[off + 12..off + 16].try_into().unwrap());
        if len < CMSG_HDR || len > controllen - off {
            return Err(format!(
                "{what}: control message at {off}: cmsg_len {len} (level {level}, type {ty}) \
                 outside {CMSG_HDR}..={} [{}]",
                controllen - off,
                hex(&buf[off..controllen])
            ));
        }
        let data = &buf[off + CMSG_HDR..off + len];
        if matches!(
            (level, ty),
            (SOL_CAN_RAW, SCM_CAN_RAW_ERRQUEUE) | (SOL_CAN_J1939, SCM_J1939_ERRQUEUE)
        ) && data.len() >= 8
            && !is_clean(data[7])
        {
            return Err(format!(
                "{what}: sock_extended_err.ee_pad is {:#04x}: uninitialised kernel memory? [{}]",
                data[7],
                hex(data)
            ));
        }
        let next = (off + len).next_multiple_of(8).min(controllen);
        gap(buf, off + len, next, what)?;
        off = next;
    }
    Ok(())
}

/// Alignment bytes between control messages: zero or poison.
fn gap(buf: &[u8], from: usize, to: usize, what: &str) -> Result<(), String> {
    match (from..to).find(|&i| !is_clean(buf[i])) {
        Some(i) => Err(format!(
            "{what}: alignment byte {i} after a control message is {:#04x}: uninitialised kernel memory?",
            buf[i]
        )),
        None => Ok(()),
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().take(48).map(|x| format!("{x:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poisoned(n: usize) -> Vec<u8> {
        vec![POISON; n]
    }

    #[test]
    fn bcm_reply_hole() {
        // A reply head: opcode TX_STATUS, flags, count 0, then the hole.
        let mut b = poisoned(128);
        b[..56].fill(0);
        b[0] = 8;
        assert!(check_bcm_reply(&b, 56, "x").is_ok());
        b[12..16].fill(POISON);
        assert!(check_bcm_reply(&b, 72, "x").is_ok());
        b[14] = 0x5c;
        let e = check_bcm_reply(&b, 56, "x").unwrap_err();
        assert!(e.contains("byte 14"), "{e}");
        // Shorter than a head (a short buffer): not checked.
        assert!(check_bcm_reply(&b, 55, "x").is_ok());
        assert!(check_bcm_reply(&b[..40], 56, "x").is_ok());
        // A BCM address is a sockaddr_can: padding 2..4 and past 8.
        let mut a = poisoned(24);
        a[..16].copy_from_slice(&[29, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
        assert!(check_addr(Some(Kind::Bcm), &a, 16, "x").is_ok());
        a[9] = 1;
        assert!(check_addr(Some(Kind::Bcm), &a, 16, "x").is_err());
    }

    #[test]
    fn j1939_address() {
        // family, padding, ifindex 3, NAME, PGN 0x12300, address 0x20,
        // three bytes of padding.
        let mut a = poisoned(32);
        a[..24].copy_from_slice(&[
            29, 0, 0, 0, 3, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 0, 0x23, 1, 0, 0x20, 0, 0, 0,
        ]);
        assert!(check_addr(Some(Kind::J1939), &a, 24, "x").is_ok());
        // The NAME, PGN and address are fields; the bytes after the
        // address are padding.
        a[22] = 0x5c;
        let e = check_addr(Some(Kind::J1939), &a, 24, "x").unwrap_err();
        assert!(e.contains("padding byte 22"), "{e}");
    }

    #[test]
    fn addresses() {
        // CAN_RAW, mainline's 8 bytes: family, zero padding, ifindex.
        let mut a = poisoned(24);
        a[..8].copy_from_slice(&[29, 0, 0, 0, 3, 0, 0, 0]);
        assert!(check_addr(Some(Kind::Raw), &a, 8, "x").is_ok());
        // A stack byte in the padding.
        a[2] = 0x5c;
        let e = check_addr(Some(Kind::Raw), &a, 8, "x").unwrap_err();
        assert!(e.contains("padding byte 2"), "{e}");
        a[2] = 0;
        // Written past the reported length.
        a[8] = 0;
        assert!(check_addr(Some(Kind::Raw), &a, 8, "x")
            .unwrap_err()
            .contains("byte 8 written past"));
        // Reported 24: the union must be clean.
        let mut b = poisoned(24);
        b[..8].copy_from_slice(&[29, 0, 0, 0, 3, 0, 0, 0]);
        b[8..].fill(0);
        assert!(check_addr(Some(Kind::Raw), &b, 24, "x").is_ok());
        b[20] = 7;
        assert!(check_addr(Some(Kind::Raw), &b, 24, "x").is_err());
        // A buffer shorter than the address: only what fits is checked.
        let mut c = poisoned(2);
        c.copy_from_slice(&[29, 0]);
        assert!(check_addr(Some(Kind::Raw), &c, 8, "x").is_ok());
        // DSOR port: byte 5 is padding; segm has none.
        let mut p = poisoned(8);
        p[..6].copy_from_slice(&[29, 0, 0x05, 0x80, 3, 0x11]);
        assert!(check_addr(Some(Kind::Dsor), &p, 6, "x").is_err());
        assert!(check_addr(None, &p, 6, "x").is_ok());
        let mut s = poisoned(8);
        s.copy_from_slice(&[29, 0, 0x11, 0x22, 1, 2, 3, 4]);
        assert!(check_addr(Some(Kind::Dsor), &s, 8, "x").is_ok());
        // canarb: padding 2..4.
        let mut r = poisoned(16);
        r.fill(0x11);
        assert!(check_addr(Some(Kind::Arb), &r, 16, "x").is_err());
        r[2] = 0;
        r[3] = POISON;
        assert!(check_addr(Some(Kind::Arb), &r, 16, "x").is_ok());
    }

    #[test]
    fn data_and_options() {
        let mut d = poisoned(72);
        d[..16].fill(0x33);
        assert!(check_data(&d, 16, "x").is_ok());
        assert!(check_data(&d, 100, "x").is_ok());
        assert!(check_data(&d, 15, "x").is_err());
        let mut o = poisoned(16);
        o[..4].copy_from_slice(&1i32.to_ne_bytes());
        assert!(check_opt(&o, Ok(4), 101, "x").is_ok());
        assert!(check_opt(&o, Ok(2), 101, "x").is_err());
        assert!(check_opt(&o, Err(libc::EINVAL), 101, "x").is_err());
        assert!(check_opt(&o, Err(libc::EINVAL), libc::SOL_SOCKET, "x").is_ok());
        assert!(check_opt(&poisoned(16), Err(libc::ERANGE), 101, "x").is_ok());
    }

    fn cmsg(level: c_int, ty: c_int, data: &[u8]) -> Vec<u8> {
        let mut b = ((CMSG_HDR + data.len()) as u64).to_ne_bytes().to_vec();
        b.extend_from_slice(&level.to_ne_bytes());
        b.extend_from_slice(&ty.to_ne_bytes());
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn control_messages() {
        // SO_RXQ_OVFL (4 bytes) then SCM_TIMESTAMP (16): the first is
        // followed by 4 alignment bytes the kernel does not write.
        let mut buf = poisoned(256);
        let a = cmsg(libc::SOL_SOCKET, 40, &7u32.to_ne_bytes());
        let b = cmsg(libc::SOL_SOCKET, 29, &[1; 16]);
        buf[..a.len()].copy_from_slice(&a);
        buf[24..24 + b.len()].copy_from_slice(&b);
        assert!(check_cmsgs(&buf, 24 + 32, "x").is_ok());
        // A stack byte in the alignment gap.
        buf[21] = 0x42;
        assert!(check_cmsgs(&buf, 56, "x")
            .unwrap_err()
            .contains("alignment byte 21"));
        buf[21] = POISON;
        // Written past msg_controllen.
        assert!(check_cmsgs(&buf, 24, "x").is_err());
        // Truncated (MSG_CTRUNC): cmsg_len as far as it went.
        let mut t = poisoned(64);
        t[..20].copy_from_slice(&a);
        assert!(check_cmsgs(&t, 20, "x").is_ok());
        // A header cut short at the end of the buffer.
        assert!(check_cmsgs(&t, 20 + 4, "x").is_ok());
        t[22] = 0x13;
        assert!(check_cmsgs(&t, 24, "x").is_err());
        // A cmsg_len beyond the buffer.
        let mut bad = poisoned(64);
        bad[..16].copy_from_slice(&cmsg(1, 2, &[])[..16]);
        bad[..8].copy_from_slice(&40u64.to_ne_bytes());
        assert!(check_cmsgs(&bad, 24, "x").is_err());
        // sock_extended_err with its pad byte dirty.
        let mut ee = [0u8; 16];
        ee[7] = 0x99;
        let mut e = poisoned(64);
        let m = cmsg(SOL_CAN_RAW, SCM_CAN_RAW_ERRQUEUE, &ee);
        e[..m.len()].copy_from_slice(&m);
        assert!(check_cmsgs(&e, 32, "x").unwrap_err().contains("ee_pad"));
    }
}
