// SPDX-License-Identifier: GPL-2.0

//! The `CANPROTO_DSOR` sockets of `rcan_dsor` (thesis 5.3.3,
//! `dsor/socket.c`): [`DsorProto`], registered with pf_can, and its
//! socket calls (bind, connect, getname, sendmsg, recvmsg, release) in
//! process context. A socket's own state ([`DsorSock`]) is under its
//! socket lock; its bind is also in the engine (`Engine::binds`, under
//! ENGINE), where the receive path finds it. Blocking senders sleep on
//! [`WAITQ`] (the socket lock is not held while they sleep).

#![forbid(unsafe_code)]

use core::sync::atomic::Ordering;
use kernel::alloc::{flags::GFP_KERNEL, KVec};
use kernel::prelude::*;

use crate::engine::{now_ms, restart_over_ms, Bind, Owner, TxEntry, ENGINE, NODE, WAITQ};
use crate::glue;
use crate::glue::lock::Waited;
use crate::glue::net::Net;
use crate::glue::netdev::{DevRef, NetDev};
use crate::glue::neterr;
use crate::glue::sock::{Msg, Sock};
use crate::glue::sync::Rtnl;
use crate::rcan_api::{CanProtocol, NetdevEvent, ProtoModule, Sockets, SOCK_DGRAM};
use crate::rcan_core::dsor_addr::{self, DsorAddr, DSOR_EPHEMERAL_MIN};
use crate::rcan_core::dsor_wire::{self, Header, MsgKind};
use crate::rcan_core::frame::CANFD_MTU;

/// `CANPROTO_DSOR` in `<linux/can/rcan.h>`.
pub(crate) const CANPROTO_DSOR: i32 = 17;

/// A DSOR socket's state, protected by its socket lock.
#[derive(Default)]
pub(crate) struct DsorSock {
    /// The bound address (also in `Engine::binds` while set).
    bound: Option<DsorAddr>,
    /// The default destination given to connect.
    peer: Option<DsorAddr>,
}

pub(crate) struct DsorProto;

pub(crate) static MODULE: ProtoModule<DsorProto> = ProtoModule::new();

impl CanProtocol for DsorProto {
    const PROTOCOL: i32 = CANPROTO_DSOR;
    const SOCK_TYPE: i32 = SOCK_DGRAM;
    // ALL_NAMESPACES stays off: one engine, node id, port table and
    // `canip0` per host (Documentation/networking/rcan/netns.rst), so
    // socket() outside the initial namespace fails with EAFNOSUPPORT.

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// The DSOR interface went down or away: every running transfer fails
    /// with ENETDOWN, partial messages are dropped. Process context, RTNL
    /// held. (DSOR sockets take frames through the engine's in-kernel
    /// receiver, not per socket: the default `rx` is never called.)
    fn netdev_event(_event: NetdevEvent, dev: &NetDev, _sockets: &Sockets<'_, Self>) {
        {
            let mut g = ENGINE.lock();
            if let Some(e) = g.as_mut() {
                if dev.name().as_bytes() == e.cfg.ifname.bytes() {
                    e.fail_all(neterr::ENETDOWN().to_errno());
                }
            }
        }
        WAITQ.wake_all();
    }
}

type S = Sock<DsorProto>;

fn errno(e: i32) -> kernel::error::Error {
    glue::errno(e)
}

/// Adds `sk`'s bind to the engine (EADDRINUSE for a taken port).
fn add_bind(sk: &S, addr: DsorAddr) -> Result {
    let mut g = ENGINE.lock();
    let e = g.as_mut().ok_or(ENODEV)?;
    if let DsorAddr::Port { port, .. } = addr {
        if e.binds
            .iter()
            .any(|b| matches!(b.addr, DsorAddr::Port { port: p, .. } if p == port))
        {
            return Err(neterr::EADDRINUSE());
        }
    }
    e.binds
        .push(
            Bind {
                sk: sk.to_ref(),
                addr,
            },
            kernel::alloc::flags::GFP_ATOMIC,
        )
        .map_err(|_| ENOMEM)
}

fn remove_bind(sk: &S) {
    let mut g = ENGINE.lock();
    if let Some(e) = g.as_mut() {
        let mut i = 0;
        let mut removed = false;
        while i < e.binds.len() {
            if e.binds[i].sk.sock().same(sk) {
                glue::kvec_swap_remove(&mut e.binds, i);
                removed = true;
            } else {
                i += 1;
            }
        }
        if removed {
            e.refuse_orphans();
        }
    }
}

/// Binds an unbound socket to a free ephemeral port (for port messages
/// sent before bind). Caller holds the socket lock.
fn autobind(sk: &S, s: &mut DsorSock) -> Result<u8> {
    let local = NODE.load(Ordering::Relaxed) as u8;
    for sub in (DSOR_EPHEMERAL_MIN..=u8::MAX).rev() {
        let addr = DsorAddr::Port {
            prio: 0,
            port: dsor_addr::make_port(local, sub),
        };
        match add_bind(sk, addr) {
            Ok(()) => {
                s.bound = Some(addr);
                return Ok(sub);
            }
            Err(e) if e == neterr::EADDRINUSE() => continue,
            Err(e) => return Err(e),
        }
    }
    Err(neterr::EADDRINUSE())
}

impl glue::sock::Proto for DsorProto {
    type Data = DsorSock;
    type Shared = ();

    fn new_data() -> DsorSock {
        DsorSock::default()
    }

    fn new_shared() {}

    fn release(sk: &S) {
        {
            let mut rtnl = Rtnl::lock();
            MODULE.sockets.get(&mut rtnl).remove(sk);
        }
        let mut s = sk.lock();
        remove_bind(sk);
        s.bound = None;
        s.peer = None;
    }

    fn bind(sk: &S, addr: &[u8]) -> Result {
        let a = DsorAddr::parse(addr).map_err(errno)?;
        a.check_bind(NODE.load(Ordering::Relaxed) as u8)
            .map_err(errno)?;
        let mut s = sk.lock();
        if s.bound.is_some() {
            return Err(EINVAL);
        }
        add_bind(sk, a)?;
        s.bound = Some(a);
        Ok(())
    }

    fn connect(sk: &S, addr: &[u8], _flags: i32) -> Result {
        if addr.len() >= 2 && u16::from_ne_bytes([addr[0], addr[1]]) == 0 {
            sk.lock().peer = None;
            return Ok(());
        }
        let a = DsorAddr::parse(addr).map_err(errno)?;
        a.check_dest().map_err(errno)?;
        sk.lock().peer = Some(a);
        Ok(())
    }

    fn getname(sk: &S, peer: bool, out: &mut [u8]) -> Result<usize> {
        let s = sk.lock();
        let a = if peer {
            s.peer.ok_or(neterr::ENOTCONN())?
        } else {
            s.bound.unwrap_or(DsorAddr::Segm {
                prio: 0,
                node: 0,
                id: 0,
            })
        };
        let (b, n) = a.encode();
        out[..n].copy_from_slice(&b[..n]);
        Ok(n)
    }

    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        let flags = msg.flags();
        if flags & glue::msg::OOB != 0 {
            return Err(neterr::EOPNOTSUPP());
        }
        let dest = match msg.name() {
            Some(name) => {
                let a = DsorAddr::parse(name).map_err(errno)?;
                a.check_dest().map_err(errno)?;
                a
            }
            None => sk.lock().peer.ok_or(neterr::EDESTADDRREQ())?,
        };
        let max_len = {
            let g = ENGINE.lock();
            g.as_ref().map_or(0, |e| usize::from(e.cfg.limits_max_len))
        };
        if len > max_len {
            return Err(neterr::EMSGSIZE());
        }
        let (dst, prio, kind) = match dest {
            DsorAddr::Segm { prio, node, id } => (node, prio, MsgKind::Segm { id }),
            DsorAddr::Port { prio, port } => {
                let mut s = sk.lock();
                let sport = match s.bound {
                    Some(DsorAddr::Port { port: own, .. }) => dsor_addr::port_sub(own),
                    Some(DsorAddr::Segm { .. }) => return Err(EINVAL),
                    None => autobind(sk, &mut s)?,
                };
                (
                    dsor_addr::port_node(port),
                    prio,
                    MsgKind::Port {
                        dport: dsor_addr::port_sub(port),
                        sport,
                    },
                )
            }
        };
        let mut data = KVec::from_elem(0u8, len, GFP_KERNEL).map_err(|_| ENOMEM)?;
        msg.copy_from_user(&mut data)?;
        let nonblock = flags & glue::msg::DONTWAIT != 0;
        let timeo = sk.sndtimeo(nonblock);
        let header = Header {
            len: len as u16,
            kind,
        };
        let fd_iface = check_device()?;
        if len == 0 {
            restart_hold(timeo)?;
        }
        let owner = if timeo == 0 {
            Owner::Sock(sk.to_ref())
        } else {
            Owner::Waiter
        };
        // Start the transfer, waiting for a free slot and channel.
        let mut pending = Some((data, owner));
        let mut started = None;
        let mut remaining = timeo;
        loop {
            let (data, owner) = pending.take().ok_or(EINVAL)?;
            {
                let mut g = ENGINE.lock();
                let e = g.as_mut().ok_or(ENODEV)?;
                e.fd_iface = fd_iface;
                match e.start(dst, prio, header.clone(), data, owner) {
                    Ok(slot) => {
                        e.kick();
                        started = Some(slot);
                    }
                    Err(back) => pending = Some(back),
                }
            }
            if started.is_some() {
                break;
            }
            if timeo == 0 {
                return Err(EAGAIN);
            }
            let t0 = glue::jiffies();
            match WAITQ.wait(remaining, &|| can_start(dst)) {
                Waited::Ready => {}
                Waited::TimedOut => return Err(neterr::ETIMEDOUT()),
                Waited::Interrupted => return Err(EINTR),
            }
            if remaining != i64::MAX {
                remaining -= glue::jiffies().wrapping_sub(t0) as i64;
            }
            if remaining <= 0 {
                return Err(neterr::ETIMEDOUT());
            }
        }
        let Some((slot, gen)) = started else {
            return Err(EINVAL);
        };
        if timeo == 0 {
            return Ok(len);
        }
        let waited = WAITQ.wait(remaining, &|| finished(slot, gen));
        let result = {
            let mut g = ENGINE.lock();
            let Some(e) = g.as_mut() else {
                return Err(ENODEV);
            };
            let abort = match waited {
                Waited::Interrupted => EINTR.to_errno(),
                _ => neterr::ETIMEDOUT().to_errno(),
            };
            e.abandon(slot, gen, abort)
        };
        // A freed slot or channel may let another sender start.
        WAITQ.wake_all();
        if result == 0 {
            Ok(len)
        } else {
            Err(kernel::error::Error::from_errno(result))
        }
    }

    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        if flags as u32 & (glue::msg::OOB | glue::msg::ERRQUEUE) != 0 {
            return Err(neterr::EOPNOTSUPP());
        }
        let skb = sk.recv_datagram(flags)?;
        let total = skb.len() as usize;
        let n = total.min(len);
        if let Err(e) = msg.copy_from_skb(&skb, 0, n) {
            sk.free_datagram(skb);
            return Err(e);
        }
        if n < total {
            msg.add_flags(glue::msg::TRUNC);
        }
        msg.recv_cmsgs(sk, &skb);
        let mut cb = [0u8; 12];
        skb.cb_read(0, &mut cb);
        let (src, prio) = (cb[0], cb[1]);
        let addr = if cb[2] == 1 {
            DsorAddr::Port {
                prio,
                port: dsor_addr::make_port(src, cb[3]),
            }
        } else {
            DsorAddr::Segm {
                prio,
                node: src,
                id: u32::from_ne_bytes([cb[4], cb[5], cb[6], cb[7]]),
            }
        };
        let (b, an) = addr.encode();
        msg.set_name(&b[..an]);
        sk.free_datagram(skb);
        Ok(if flags as u32 & glue::msg::TRUNC != 0 {
            total
        } else {
            n
        })
    }
}

/// The restart rule of the wire specification ("Sequence bit"): every
/// stream starts at Q = 0 after a load, so during the first
/// `reasm_timeout_ms` a receiver may still remember a zero-length message
/// with Q = 0 that the previous instance of this module sent, and would
/// take an identical new one for its retransmission. Zero-length messages
/// therefore wait until that time has passed (longer messages cannot be
/// mistaken: a receiver restarts on every header it has not acknowledged
/// as the last frame). EAGAIN for a non-blocking sender.
/// A sleep can end up to a jiffy before `until` (the first jiffy of a
/// timeout is already partly over), so it loops until the hold is over
/// or the sender's own timeout `timeo` (jiffies, `i64::MAX` for none) is
/// used up. Process context.
fn restart_hold(timeo: i64) -> Result {
    let until = restart_over_ms();
    let mut remaining = timeo;
    loop {
        let wait_ms = until.saturating_sub(now_ms());
        if wait_ms == 0 {
            return Ok(());
        }
        if timeo == 0 {
            return Err(EAGAIN);
        }
        if remaining <= 0 {
            return Err(neterr::ETIMEDOUT());
        }
        let j = glue::msecs_to_jiffies(wait_ms as u32).clamp(1, remaining);
        let t0 = glue::jiffies();
        if let Waited::Interrupted = WAITQ.wait(j, &|| now_ms() >= until) {
            return Err(EINTR);
        }
        if remaining != i64::MAX {
            remaining -= glue::jiffies().wrapping_sub(t0) as i64;
        }
    }
}

/// Whether a transfer to `dst` could start now (wait condition).
fn can_start(dst: u8) -> bool {
    let g = ENGINE.lock();
    match g.as_ref() {
        Some(e) => {
            e.tx.iter().any(|x| matches!(x, TxEntry::Free))
                && e.streams.in_use(dst) < u32::from(dsor_wire::CHANNELS)
        }
        None => true,
    }
}

/// Whether transfer `(slot, gen)` has finished (wait condition).
fn finished(slot: usize, gen: u32) -> bool {
    let g = ENGINE.lock();
    match g.as_ref() {
        Some(e) => !matches!(&e.tx[slot], TxEntry::Running(r) if r.gen == gen),
        None => true,
    }
}

/// ENODEV if the DSOR interface does not exist, ENETDOWN if it is down;
/// else whether it is in CAN FD mode (MTU 72), which decides whether the
/// message may use FD bodies.
fn check_device() -> Result<bool> {
    let ifname = {
        let g = ENGINE.lock();
        g.as_ref().ok_or(ENODEV)?.cfg.ifname
    };
    let dev = DevRef::by_name(Net::init(), ifname.as_cstr()).ok_or(ENODEV)?;
    if !dev.is_can() {
        return Err(ENODEV);
    }
    if !dev.is_up() {
        return Err(neterr::ENETDOWN());
    }
    Ok(dev.mtu() as usize == CANFD_MTU)
}
