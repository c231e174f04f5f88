// SPDX-License-Identifier: GPL-2.0
//! CAN_RAW helpers shared by the `raw_*`, `canutils`, `capture` and `mixed`
//! tests: sockets from the `socketcan` crate with the suite's timeouts,
//! frame constructors, "receive exactly this" and "receive nothing" checks,
//! option and address helpers. Everything here works the same on our stack
//! and on mainline SocketCAN.

use std::os::fd::AsFd;
use std::thread;
use std::time::{Duration, SystemTime};

use rcan_uapi::raw;
use socketcan::{
    CanErrorFrame, CanFrame, CanSocket, EmbeddedFrame, ExtendedId, Socket, SocketOptions,
    StandardId,
};

use crate::check::{ensure, errno_text, OrFail, TestResult, QUIET};

pub use libc::{
    CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_ERR_MASK, CAN_INV_FILTER, CAN_RAW,
    CAN_RAW_ERR_FILTER, CAN_RAW_FD_FRAMES, CAN_RAW_FILTER, CAN_RAW_JOIN_FILTERS, CAN_RAW_LOOPBACK,
    CAN_RAW_RECV_OWN_MSGS, CAN_RTR_FLAG, CAN_SFF_MASK, SOL_CAN_RAW,
};

/// `CAN_RAW_FILTER_MAX`: the most filters one socket may have.
pub const FILTER_MAX: usize = 512;
/// `sizeof(struct can_filter)`.
pub const FILTER_LEN: usize = 8;
/// `CAN_MTU`: a classic frame is exactly this long on the socket.
pub const CAN_MTU: usize = 16;
/// `CANFD_MTU`.
pub const CANFD_MTU: usize = 72;
/// Length of the `sockaddr_can` prefix mainline reads and writes
/// (`can_family`, padding, `can_ifindex`).
pub const MIN_NAMELEN: usize = 8;

/// Error classes of `<linux/can/error.h>` used as `can_id` bits.
pub const CAN_ERR_CRTL: u32 = 0x0000_0004;
/// Bus off.
pub const CAN_ERR_BUSOFF: u32 = 0x0000_0040;

/// Receive timeout of CAN_RAW test sockets: generous, since the VM may be
/// software-emulated and shared; only a missing frame waits this long.
pub const RAW_RX_TIMEOUT: Duration = Duration::from_secs(10);

/// A CAN_RAW socket bound to `ifindex` (0: every CAN interface), with
/// [`RAW_RX_TIMEOUT`].
pub fn open(ifindex: u32) -> Result<CanSocket, String> {
    let s = CanSocket::open_iface(ifindex)
        .or_fail(format_args!("CAN_RAW socket bound to ifindex {ifindex}"))?;
    s.set_read_timeout(RAW_RX_TIMEOUT).or_fail("SO_RCVTIMEO")?;
    Ok(s)
}

/// A CAN_RAW socket bound to `ifindex` whose filters are set before the
/// bind, so that it never queues a frame they do not pass. With
/// [`open`] and then `set_filters`, every frame received between the
/// bind and the setsockopt passes the default filter (all frames) and is
/// queued: `teardown_bcm_cyclic_jobs` read a frame of its 100 cyclic jobs
/// (0x15C, still on its way after their close) on the socket it had set
/// to 0x7FF alone (make soak, loaded host, 2026-11-29).
pub fn open_filtered(
    ifindex: u32,
    filters: &[socketcan::CanFilter],
) -> Result<CanSocket, String> {
    let s = unbound()?;
    s.set_filters(filters).or_fail("CAN_RAW_FILTER before bind")?;
    raw::bind(&s, &addr_bytes(libc::AF_CAN as u16, ifindex))
        .or_fail(format_args!("bind to ifindex {ifindex}"))?;
    Ok(s)
}

/// A CAN_RAW socket as a plain descriptor, bound to `ifindex` with
/// `filters` (identifier, mask) set before the bind (none: the default,
/// every frame), and with CAN_RAW_FD_FRAMES on if `fd_frames`: the raw
/// peer or bus recorder of the protocol tests, which read and write
/// frame images themselves.
pub fn open_fd(ifindex: u32, filters: &[(u32, u32)], fd_frames: bool) -> Result<std::os::fd::OwnedFd, String> {
    const SOL_CAN_RAW: libc::c_int = 101;
    const CAN_RAW_FILTER: libc::c_int = 1;
    const CAN_RAW_FD_FRAMES: libc::c_int = 5;
    let s = raw::socket(libc::AF_CAN, libc::SOCK_RAW, CAN_RAW).or_fail("socket(CAN_RAW)")?;
    if fd_frames {
        raw::setsockopt(&s, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &1i32.to_ne_bytes())
            .or_fail("CAN_RAW_FD_FRAMES")?;
    }
    if !filters.is_empty() {
        raw::setsockopt(&s, SOL_CAN_RAW, CAN_RAW_FILTER, &filter_bytes(filters))
            .or_fail("CAN_RAW_FILTER")?;
    }
    raw::bind(&s, &addr_bytes(libc::AF_CAN as u16, ifindex)).or_fail("bind CAN_RAW")?;
    Ok(s)
}

/// A CAN_RAW socket that is not bound. The crate binds in every
/// constructor, so the socket is made with socket(2) and handed to it.
pub fn unbound() -> Result<CanSocket, String> {
    let fd = raw::socket(libc::PF_CAN, libc::SOCK_RAW, CAN_RAW)
        .or_fail("socket(PF_CAN, SOCK_RAW, CAN_RAW)")?;
    let s = CanSocket::from(fd);
    s.set_read_timeout(RAW_RX_TIMEOUT).or_fail("SO_RCVTIMEO")?;
    Ok(s)
}

/// A standard data frame.
pub fn std(id: u16, data: &[u8]) -> CanFrame {
    let id = StandardId::new(id).expect("11-bit identifier");
    CanFrame::new(id, data).expect("at most 8 data bytes")
}

/// An extended data frame.
pub fn ext(id: u32, data: &[u8]) -> CanFrame {
    let id = ExtendedId::new(id).expect("29-bit identifier");
    CanFrame::new(id, data).expect("at most 8 data bytes")
}

/// A standard remote frame with DLC `dlc`.
pub fn rtr_std(id: u16, dlc: usize) -> CanFrame {
    let id = StandardId::new(id).expect("11-bit identifier");
    CanFrame::new_remote(id, dlc).expect("DLC at most 8")
}

/// An extended remote frame with DLC `dlc`.
pub fn rtr_ext(id: u32, dlc: usize) -> CanFrame {
    let id = ExtendedId::new(id).expect("29-bit identifier");
    CanFrame::new_remote(id, dlc).expect("DLC at most 8")
}

/// An error frame: `CAN_ERR_FLAG | class`, DLC 8, `data` zero-padded.
pub fn err_frame(class: u32, data: &[u8]) -> CanFrame {
    CanFrame::Error(CanErrorFrame::new_error(class, data).expect("at most 8 data bytes"))
}

/// The candump spelling of a frame (`123#DEADBEEF`), for messages.
pub fn show(f: &CanFrame) -> String {
    let c: &libc::can_frame = f.as_ref();
    if c.can_id & CAN_ERR_FLAG != 0 {
        return format!("{:08X}#{} (error)", c.can_id & CAN_ERR_MASK, hex(&c.data));
    }
    let id = if c.can_id & CAN_EFF_FLAG != 0 {
        format!("{:08X}", c.can_id & CAN_EFF_MASK)
    } else {
        format!("{:03X}", c.can_id & CAN_SFF_MASK)
    };
    if c.can_id & CAN_RTR_FLAG != 0 {
        format!("{id}#R{}", c.can_dlc)
    } else {
        let n = usize::from(c.can_dlc).min(8);
        format!("{id}#{}", hex(&c.data[..n]))
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02X}")).collect()
}

/// The 16 bytes of `struct can_frame` a frame built by this module has on
/// the wire (its padding bytes are zero).
pub fn wire(f: &CanFrame) -> [u8; CAN_MTU] {
    let c: &libc::can_frame = f.as_ref();
    let mut b = [0u8; CAN_MTU];
    b[..4].copy_from_slice(&c.can_id.to_ne_bytes());
    b[4] = c.can_dlc;
    b[7] = c.len8_dlc;
    b[8..].copy_from_slice(&c.data);
    b
}

/// The 16 bytes of a standard data frame `id` with `len` data bytes
/// (`0x10 + i`) and `tail` in the data bytes past `len`: what a writer
/// may leave there (CAN_RAW passes them through).
pub fn sff_with_tail(id: u16, len: u8, tail: u8) -> [u8; CAN_MTU] {
    let mut b = [0u8; CAN_MTU];
    b[..4].copy_from_slice(&u32::from(id & 0x7FF).to_ne_bytes());
    b[4] = len;
    for (i, d) in b[8..].iter_mut().enumerate() {
        *d = if i < usize::from(len) {
            0x10 + i as u8
        } else {
            tail
        };
    }
    b
}

/// Whether two frames have the same `can_id`, `len`, `len8_dlc` and all
/// eight data bytes (the padding bytes the crate does not expose aside).
pub fn same(a: &CanFrame, b: &CanFrame) -> bool {
    wire(a) == wire(b)
}

/// Renders the bytes a receive call returned: the frame if they are one
/// (with any non-zero padding byte called out), else hex.
pub fn show_wire(b: &[u8]) -> String {
    let Ok(w) = <[u8; CAN_MTU]>::try_from(b) else {
        return format!("{} bytes {}", b.len(), hex(b));
    };
    let mut c = socketcan::frame::can_frame_default();
    c.can_id = u32::from_ne_bytes(w[..4].try_into().unwrap());
    c.can_dlc = w[4];
    c.len8_dlc = w[7];
    c.data.copy_from_slice(&w[8..]);
    let mut s = show(&CanFrame::from(c));
    if w[4] > 8 {
        s += &format!(" (len {})", w[4]);
    }
    if w[5..8] != [0, 0, 0] {
        s += &format!(" (__pad, __res0, len8_dlc: {:02X?})", &w[5..8]);
    }
    let n = usize::from(w[4]).min(8);
    if w[8 + n..].iter().any(|&x| x != 0) && c.can_id & CAN_ERR_FLAG == 0 {
        s += &format!(" (data bytes past len: {:02X?})", &w[8 + n..]);
    }
    s
}

/// Receives one frame with recvmsg(2) (the crate does not report
/// `msg_flags`) and checks it is `want`, and whether `MSG_DONTROUTE`
/// (sent from this host) and `MSG_CONFIRM` (sent by this socket) are set.
pub fn expect_msg(
    s: &CanSocket,
    want: &CanFrame,
    dontroute: bool,
    confirm: bool,
    who: &str,
) -> TestResult {
    let r = crate::sys::recvmsg(s, CAN_MTU, 0)
        .or_fail(format_args!("{who}: recvmsg waiting for {}", show(want)))?;
    let got = &r.data[..r.len.min(CAN_MTU)];
    ensure!(
        got == wire(want),
        "{who}: expected {}, got {}",
        show(want),
        show_wire(got)
    );
    let has = |flag| r.flags & flag != 0;
    ensure!(
        has(libc::MSG_DONTROUTE) == dontroute && has(libc::MSG_CONFIRM) == confirm,
        "{who}: {}: msg_flags {:#x}: MSG_DONTROUTE {}, MSG_CONFIRM {}; expected {} and {}",
        show(want),
        r.flags,
        has(libc::MSG_DONTROUTE),
        has(libc::MSG_CONFIRM),
        dontroute,
        confirm
    );
    Ok(())
}

/// Writes one frame with the crate.
pub fn send(s: &CanSocket, f: &CanFrame) -> TestResult {
    s.write_frame(f).or_fail(format_args!("write {}", show(f)))
}

/// Reads one frame with the crate, waiting up to the socket's timeout.
pub fn recv(s: &CanSocket) -> Result<CanFrame, String> {
    s.read_frame().or_fail("read_frame")
}

/// Reads one frame and checks that it is `want`; `who` names the socket.
pub fn expect(s: &CanSocket, want: &CanFrame, who: &str) -> TestResult {
    let got = recv(s).map_err(|e| format!("{who}: waiting for {}: {e}", show(want)))?;
    ensure!(
        same(&got, want),
        "{who}: expected {}, got {}",
        show(want),
        show(&got)
    );
    Ok(())
}

/// Reads `want.len()` frames and checks them in order.
pub fn expect_seq(s: &CanSocket, want: &[CanFrame], who: &str) -> TestResult {
    want.iter().try_for_each(|f| expect(s, f, who))
}

/// Waits [`QUIET`], then checks that none of `socks` (name, socket) has a
/// frame queued.
pub fn expect_quiet(socks: &[(&str, &CanSocket)]) -> TestResult {
    // Not synchronisation: a negative check ("nothing arrives"), which has
    // no event to wait for; the window only gives a wrong frame the chance
    // to show up.
    thread::sleep(QUIET);
    for (who, s) in socks {
        s.set_nonblocking(true).or_fail("O_NONBLOCK")?;
        let r = s.read_frame();
        s.set_nonblocking(false).or_fail("clear O_NONBLOCK")?;
        match r {
            Ok(f) => return Err(format!("{who}: unexpected frame {}", show(&f))),
            Err(e) if e.raw_os_error() == Some(libc::EAGAIN) => {}
            Err(e) => return Err(format!("{who}: non-blocking read: {}", errno_text(&e))),
        }
    }
    Ok(())
}

/// Sends `cases` (frame, should it reach `rx`) from `tx`, then `marker`,
/// which must reach `rx`; checks that `rx` gets exactly the passing frames
/// and the marker, in order, and nothing after. Frames arrive in order, so
/// a wrongly accepted frame shows up in place of the next expected one,
/// whatever the speed of the VM.
pub fn check_delivery(
    tx: &CanSocket,
    rx: &CanSocket,
    cases: &[(CanFrame, bool)],
    marker: &CanFrame,
    what: &str,
) -> TestResult {
    for (f, _) in cases {
        send(tx, f)?;
    }
    send(tx, marker)?;
    let want: Vec<CanFrame> = cases
        .iter()
        .filter(|(_, pass)| *pass)
        .map(|(f, _)| *f)
        .chain([*marker])
        .collect();
    expect_seq(rx, &want, what)?;
    expect_quiet(&[(what, rx)])
}

/// The filters of a socket (`CAN_RAW_FILTER`), as (can_id, can_mask).
pub fn filters(s: &CanSocket) -> Result<Vec<(u32, u32)>, String> {
    let mut buf = vec![0u8; FILTER_MAX * FILTER_LEN];
    let n = s
        .get_socket_option_bytes(SOL_CAN_RAW, CAN_RAW_FILTER, &mut buf)
        .or_fail("getsockopt CAN_RAW_FILTER")?;
    ensure!(
        n % FILTER_LEN == 0,
        "getsockopt CAN_RAW_FILTER: length {n} is not a multiple of {FILTER_LEN}"
    );
    Ok(buf[..n]
        .chunks_exact(FILTER_LEN)
        .map(|c| {
            let w = |i: usize| u32::from_ne_bytes(c[i..i + 4].try_into().unwrap());
            (w(0), w(4))
        })
        .collect())
}

/// The bytes of a filter list as setsockopt takes them.
pub fn filter_bytes(f: &[(u32, u32)]) -> Vec<u8> {
    f.iter()
        .flat_map(|&(id, mask)| id.to_ne_bytes().into_iter().chain(mask.to_ne_bytes()))
        .collect()
}

/// An int option at `SOL_CAN_RAW`.
pub fn int_opt(s: &CanSocket, name: libc::c_int) -> Result<i32, String> {
    s.get_socket_option_int(SOL_CAN_RAW, name)
        .or_fail(format_args!("getsockopt({})", opt_name(name)))
}

/// Symbolic name of a `SOL_CAN_RAW` option, for messages.
pub fn opt_name(name: libc::c_int) -> String {
    match name {
        CAN_RAW_FILTER => "CAN_RAW_FILTER".into(),
        CAN_RAW_ERR_FILTER => "CAN_RAW_ERR_FILTER".into(),
        CAN_RAW_LOOPBACK => "CAN_RAW_LOOPBACK".into(),
        CAN_RAW_RECV_OWN_MSGS => "CAN_RAW_RECV_OWN_MSGS".into(),
        CAN_RAW_FD_FRAMES => "CAN_RAW_FD_FRAMES".into(),
        CAN_RAW_JOIN_FILTERS => "CAN_RAW_JOIN_FILTERS".into(),
        n => format!("option {n}"),
    }
}

/// A `struct sockaddr_can` (24 bytes) with `family` and `ifindex`, the
/// rest zero: lets tests pass malformed addresses.
pub fn addr_bytes(family: u16, ifindex: u32) -> [u8; crate::sys::SOCKADDR_CAN_LEN] {
    let mut a = [0u8; crate::sys::SOCKADDR_CAN_LEN];
    a[..2].copy_from_slice(&family.to_ne_bytes());
    a[4..8].copy_from_slice(&ifindex.to_ne_bytes());
    a
}

/// The ifindex in a `sockaddr_can` returned by the kernel, after checking
/// the family and the padding bytes.
pub fn addr_ifindex(name: &[u8]) -> Result<u32, String> {
    ensure!(name.len() >= MIN_NAMELEN, "address of {} bytes", name.len());
    let family = u16::from_ne_bytes([name[0], name[1]]);
    ensure!(
        family == libc::AF_CAN as u16,
        "address family {family} (expected AF_CAN {})",
        libc::AF_CAN
    );
    ensure!(
        name[2..4] == [0, 0],
        "address padding bytes 2..4 are {:02X?}, expected zero",
        &name[2..4]
    );
    Ok(u32::from_ne_bytes(name[4..8].try_into().unwrap()))
}

/// The frame bytes of a socket write that is not a frame built by the
/// crate: `len` bytes of a valid frame, cut or zero-extended.
pub fn frame_of_len(f: &CanFrame, len: usize) -> Vec<u8> {
    let mut b = wire(f).to_vec();
    b.resize(len, 0);
    b
}

/// `write` of raw bytes (lengths the crate would never produce).
pub fn write_bytes(s: impl AsFd, b: &[u8]) -> std::io::Result<usize> {
    raw::write(s, b)
}

/// Checks that `t` lies between `before` and `after`, give or take a
/// second: a timestamp of the same clock, taken in between. Not a timing
/// assertion: the slack only absorbs clock granularity.
pub fn within(t: SystemTime, before: SystemTime, after: SystemTime, what: &str) -> TestResult {
    let slack = Duration::from_secs(1);
    let show = |t: SystemTime| match t.duration_since(SystemTime::UNIX_EPOCH) {
        Ok(d) => format!("{}.{:09}", d.as_secs(), d.subsec_nanos()),
        Err(_) => "before 1970".into(),
    };
    ensure!(t != SystemTime::UNIX_EPOCH, "{what}: timestamp is zero");
    ensure!(
        t + slack >= before && t <= after + slack,
        "{what}: timestamp {} is not between {} and {} (the send and the receive)",
        show(t),
        show(before),
        show(after)
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_on_the_wire() {
        let f = std(0x123, &[0xDE, 0xAD]);
        assert_eq!(show(&f), "123#DEAD");
        let w = wire(&f);
        assert_eq!(u32::from_ne_bytes(w[..4].try_into().unwrap()), 0x123);
        assert_eq!(&w[4..10], &[2, 0, 0, 0, 0xDE, 0xAD]);
        assert_eq!(show(&ext(0x1234_5678, &[])), "12345678#");
        assert_eq!(show(&rtr_std(0x7FF, 3)), "7FF#R3");
        let r = wire(&rtr_ext(5, 8));
        assert_eq!(
            u32::from_ne_bytes(r[..4].try_into().unwrap()),
            5 | CAN_EFF_FLAG | CAN_RTR_FLAG
        );
        let e = wire(&err_frame(CAN_ERR_BUSOFF, &[1]));
        assert_eq!(
            u32::from_ne_bytes(e[..4].try_into().unwrap()),
            CAN_ERR_FLAG | CAN_ERR_BUSOFF
        );
        assert_eq!(e[4], 8);
        assert!(!same(&std(1, &[1]), &std(1, &[2])));
    }

    #[test]
    fn addresses_and_filters() {
        let a = addr_bytes(libc::AF_CAN as u16, 7);
        assert_eq!(addr_ifindex(&a), Ok(7));
        assert!(addr_ifindex(&addr_bytes(2, 7)).is_err());
        let b = filter_bytes(&[(1, 2), (3, 4)]);
        assert_eq!(b.len(), 16);
        assert_eq!(u32::from_ne_bytes(b[12..16].try_into().unwrap()), 4);
        assert_eq!(frame_of_len(&std(1, &[]), 17).len(), 17);
    }
}
