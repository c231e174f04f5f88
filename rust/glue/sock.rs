// SPDX-License-Identifier: GPL-2.0

//! Socket protocols from a Rust trait.
//!
//! A protocol implements [`Proto`]; [`proto_ops_template`] builds its
//! `struct proto_ops`, [`ProtoReg`] registers its `struct proto` (whose
//! objects are a `struct sock` followed by `Proto::Data`), and [`create`]
//! makes a new socket of it. `Proto::Data` is constructed in `create` and
//! dropped when the last reference to the sock goes, in process context:
//! in `sk_destruct` when that runs in process context, else by the
//! module's deferred-drop work ([`destruct`]).
//!
//! Locking: `Proto::Data` is protected by the socket lock (`lock_sock`),
//! reached through [`Sock::lock`]; only process context takes it, and
//! only process context gets a [`Sock`]. The receive path (softirq) and
//! timers get a [`SockView`], which has no `lock()`: they never touch
//! `Data`, and queue skbs with [`SockView::queue_rcv`], which uses the
//! receive queue's own spinlock.

use super::bindings;
use super::net::Net;
use super::skb::{OwnedSkb, Shared, Skb, UniqueSkb};
use super::lock::StaticIrqSpinLock;
use super::sync::CCell;
use kernel::alloc::flags::GFP_ATOMIC;
use core::marker::PhantomData;
use core::sync::atomic::{AtomicBool, Ordering};
use kernel::alloc::KBox;
use kernel::error::{code, Error, Result};
use kernel::ffi;

/// The object sk_alloc() allocates for protocol `T`.
#[repr(C)]
struct SockObj<D, S> {
    sk: bindings::sock,
    /// The sock's place on its protocol module's socket set.
    set: SetLink,
    /// The sock's reserved receiver (`can::proto`, protocols with
    /// `CanProtocol::RESERVE_RX`): pf_can's handle, or NULL. Kept by the
    /// glue in the sock itself, so no two socks can share one.
    rx: core::sync::atomic::AtomicPtr<ffi::c_void>,
    shared: S,
    data: D,
}

/// A sock's links on its protocol module's socket set
/// (`can::proto::SockSet`, a doubly linked list through the socks): the
/// addresses of its neighbours, 0 at either end and off the set. Read
/// and written only by that set, under RTNL, which protects it.
pub(in crate::glue) struct SetLink {
    pub(in crate::glue) prev: core::cell::Cell<usize>,
    pub(in crate::glue) next: core::cell::Cell<usize>,
    /// On the set. Written by the set only, under RTNL; true from the
    /// sock's creation until its removal, never again afterwards, so the
    /// release trampoline may read it without RTNL: `false` is final.
    pub(in crate::glue) listed: core::sync::atomic::AtomicBool,
}

/// The sock object of protocol `T`.
type ObjOf<T> = SockObj<<T as Proto>::Data, <T as Proto>::Shared>;

/// A socket protocol. All methods run in process context, called through
/// the socket layer on behalf of a system call, and may sleep.
pub(crate) trait Proto: Sized + 'static {
    /// Per-socket state, protected by the socket lock.
    type Data: Send;
    /// Per-socket state read without the socket lock (atomics): what a
    /// hot path such as sendmsg needs, as mainline reads its option
    /// fields without the lock. Writers still hold the socket lock.
    type Shared: Send + Sync;

    /// Initial state of a new socket.
    fn new_data() -> Self::Data;
    /// Initial shared state of a new socket.
    fn new_shared() -> Self::Shared;
    /// The socket is being closed. Undo everything that makes other code
    /// reach the sock (receivers, lists) before returning. A CAN
    /// protocol's socket set is the glue's: the glue takes the sock off
    /// it after `release` returns if the protocol did not do it earlier
    /// (`can::proto::SockSet::remove`, for a protocol that wants it off
    /// before its own teardown). A receiver left subscribed holds its
    /// reference on the sock: leaked, never freed under the subscription.
    fn release(sk: &Sock<Self>);
    fn bind(sk: &Sock<Self>, addr: &[u8]) -> Result;
    fn connect(sk: &Sock<Self>, addr: &[u8], flags: i32) -> Result;
    /// Writes the local or peer address into `out` ([`name_room`] bytes,
    /// zeroed: [`NAME_ROOM`], or [`SOCKADDR_CAN_ROOM`] with
    /// [`Proto::SOCKADDR_CAN_NAMES`]); returns its length, at most
    /// `out.len()` (a longer one is EINVAL to the caller). Process context.
    fn getname(sk: &Sock<Self>, peer: bool, out: &mut [u8]) -> Result<usize>;
    fn sendmsg(sk: &Sock<Self>, msg: &mut Msg, len: usize) -> Result<usize>;
    fn recvmsg(sk: &Sock<Self>, msg: &mut Msg, len: usize, flags: i32) -> Result<usize>;
    /// `setsockopt` at a level other than SOL_SOCKET (which the socket
    /// layer handles itself).
    fn setsockopt(_sk: &Sock<Self>, _level: i32, _name: i32, _opt: &OptIn) -> Result {
        Err(super::neterr::ENOPROTOOPT())
    }
    /// `getsockopt` at a level other than SOL_SOCKET.
    fn getsockopt(_sk: &Sock<Self>, _level: i32, _name: i32, _opt: &OptOut) -> Result {
        Err(super::neterr::ENOPROTOOPT())
    }
    /// Whether [`Proto::writable`] is asked: `poll` then reports
    /// `EPOLLOUT` only when the generic test (send-buffer space) and
    /// `writable` both say so. Protocols that set it call
    /// [`Sock::wake_writers`] when `writable` may have become true.
    const HAS_WRITABLE: bool = false;
    /// Whether the protocol's addresses are whole `struct sockaddr_can`s
    /// (24 bytes, CAN_J1939's `can_addr.j1939`): its `getname` buffer and
    /// its recvmsg's [`Msg::set_name`] then take [`SOCKADDR_CAN_ROOM`]
    /// bytes instead of [`NAME_ROOM`] (why that is sound: at
    /// [`SOCKADDR_CAN_ROOM`]). A choice between two bounds the glue
    /// proves, not a number the protocol picks.
    const SOCKADDR_CAN_NAMES: bool = false;
    /// The `sk_priority` of a new socket (`sock_init_data` leaves 0):
    /// mainline CAN_J1939 starts its sockets at J1939 priority 6, which
    /// it keeps as `sk_priority` 1.
    const SK_PRIORITY: u32 = 0;
    /// Whether a write would not block on the protocol's own state (a
    /// CAN_ISOTP transfer running), for `poll`. Process context (a
    /// `poll` call); must not sleep.
    fn writable(_sk: &Sock<Self>) -> bool {
        true
    }
}

/// The value of a `setsockopt` call: user (or, for in-kernel callers,
/// kernel) memory of `len()` bytes.
pub(crate) struct OptIn {
    val: bindings::sockptr_t,
    len: usize,
}

impl OptIn {
    /// The option length the caller passed.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Copies the first `dst.len()` bytes of the value (the caller checked
    /// `dst.len() <= len()`); EFAULT on a bad pointer.
    pub(crate) fn read(&self, dst: &mut [u8]) -> Result {
        if dst.len() > self.len {
            return Err(code::EINVAL);
        }
        // SAFETY: `dst` is a writable kernel buffer of dst.len() bytes; the
        // helper checks the user pointer (copy_from_sockptr).
        let ret = unsafe {
            bindings::rcan_copy_from_sockptr(dst.as_mut_ptr().cast(), self.val, dst.len())
        };
        super::to_result(ret).map(|_| ())
    }
}

/// The result buffer of a `getsockopt` call: `optval` and `optlen` are
/// user pointers (`do_sock_getsockopt` refuses kernel ones before calling
/// a protocol's `getsockopt`).
///
/// `*optlen` is the size of the user's buffer. It is read once, as
/// mainline's protocols read it into a local (`get_user(len, optlen)`),
/// and that value bounds every [`OptOut::write`]: no safe caller writes
/// past what the user said the buffer holds, whatever it passes (mainline
/// protocols cut the value themselves, `if (len > sizeof(int)) len =
/// sizeof(int)`; the glue makes that cut a refusal it checks, not a duty
/// of each caller).
///
/// # Invariants
///
/// Made only by the `getsockopt` trampoline of this file, with `optval`
/// and `optlen` of the call; `first`, once set, is `*optlen` as first
/// read.
pub(crate) struct OptOut {
    val: *mut ffi::c_char,
    len: *mut ffi::c_int,
    first: core::cell::Cell<Option<ffi::c_int>>,
}

impl OptOut {
    /// The buffer length the caller passed in `*optlen`; EFAULT on a bad
    /// pointer. Read from user memory once: later calls return that first
    /// value, which is also the bound of [`OptOut::write`].
    pub(crate) fn len(&self) -> Result<i32> {
        if let Some(v) = self.first.get() {
            return Ok(v);
        }
        let mut v: ffi::c_int = 0;
        // SAFETY: `len` is a user pointer; the helper uses get_user.
        super::to_result(unsafe { bindings::rcan_get_user_int(self.len, &mut v) })?;
        // INVARIANT: the first value read.
        self.first.set(Some(v));
        Ok(v)
    }

    /// Stores `n` in `*optlen` (the length written, or the length needed,
    /// as mainline's ERANGE for `CAN_RAW_FILTER`). The bound of
    /// [`OptOut::write`] stays the length first read.
    pub(crate) fn set_len(&self, n: i32) -> Result {
        // SAFETY: as in len(); put_user checks the pointer.
        super::to_result(unsafe { bindings::rcan_put_user_int(self.len, n) }).map(|_| ())
    }

    /// Copies `src` to `optval`. EINVAL, nothing written, if `src` is
    /// longer than the user's buffer (`*optlen` as first read, 0 if
    /// negative; read here if [`OptOut::len`] was not called): the caller
    /// cuts the value to [`OptOut::len`] first, as mainline does. EFAULT
    /// on a bad pointer. Process context (may fault pages in).
    pub(crate) fn write(&self, src: &[u8]) -> Result {
        let room = usize::try_from(self.len()?).unwrap_or(0);
        if src.len() > room {
            return Err(code::EINVAL);
        }
        // `src.len()` is at most the size of the user's buffer as the user
        // gave it (`room`, checked above), so the copy stays inside that
        // buffer; copy_to_user checks that the range is user memory
        // (access_ok) and faults are EFAULT.
        // SAFETY: `src` is readable for `src.len()` bytes; `val` is the
        // user pointer of the call.
        let ret = unsafe {
            bindings::rcan_copy_to_user(self.val.cast(), src.as_ptr().cast(), src.len() as _)
        };
        super::to_result(ret).map(|_| ())
    }
}

/// A `struct sock` of protocol `T`, borrowed, in any context: what may
/// be done with a socket without its lock and without sleeping. The
/// receive callback (`can::proto::CanProtocol::rx`, NET_RX softirq) and
/// everything that reaches a sock through a counted reference
/// ([`SockRef::sock`]: timer and job callbacks, softirq or hardirq) get
/// this view only, so `lock()`, which sleeps, cannot be called there: it
/// is not a method of this type. [`Sock`] adds what process context may
/// do.
///
/// # Invariants
///
/// `sk` is a live sock created by [`create`] for `T` while the value is
/// borrowed (the glue lends it only by reference, for a call or for the
/// life of a counted reference).
pub(crate) struct SockView<T: Proto> {
    sk: *mut bindings::sock,
    _t: PhantomData<T>,
}

/// A `struct sock` of protocol `T`, borrowed by process context: a
/// system call on the socket (the protocol's `proto_ops` methods), its
/// release, a netdevice event (RTNL held), a /proc read. Adds to
/// [`SockView`] (which it derefs to) what may sleep: the socket lock,
/// blocking allocation and receive.
///
/// # Invariants
///
/// Those of [`SockView`], and every borrow of it runs in process context.
pub(crate) struct Sock<T: Proto> {
    view: SockView<T>,
}

impl<T: Proto> core::ops::Deref for Sock<T> {
    type Target = SockView<T>;
    fn deref(&self) -> &SockView<T> {
        &self.view
    }
}

impl<T: Proto> Sock<T> {
    /// # Safety
    ///
    /// `sk` is a live sock created by [`create`] for `T`, and stays alive
    /// while the returned value is used; it is used in process context
    /// only.
    pub(crate) unsafe fn from_raw(sk: *mut bindings::sock) -> Sock<T> {
        Sock {
            // SAFETY: our own contract includes `SockView::from_raw`'s.
            view: unsafe { SockView::from_raw(sk) },
        }
    }
}

impl<T: Proto> SockView<T> {
    /// # Safety
    ///
    /// `sk` is a live sock created by [`create`] for `T`, and stays alive
    /// while the returned value is used.
    pub(crate) unsafe fn from_raw(sk: *mut bindings::sock) -> SockView<T> {
        SockView {
            sk,
            _t: PhantomData,
        }
    }

    /// The raw sock, for the glue's own C calls: nothing above the glue
    /// sees it.
    pub(in crate::glue) fn as_ptr(&self) -> *mut bindings::sock {
        self.sk
    }

    /// Whether `self` and `other` are the same socket (identity, not
    /// contents). Any context.
    pub(crate) fn same(&self, other: &SockView<T>) -> bool {
        core::ptr::eq(self.sk, other.sk)
    }

    /// The socket's network namespace (`sock_net`), fixed for its life.
    /// A user socket holds a reference on it (`sk_alloc` with `kern` 0);
    /// a kernel socket's creator closes it before its namespace exits, by
    /// the kernel's rule for kernel sockets. Any context.
    #[inline]
    pub(crate) fn net(&self) -> &Net {
        // `read_pnet(&sk->sk_net)` (CONFIG_NET_NS), read in place: every
        // sendmsg asks.
        // SAFETY: a live sock (type invariant), whose namespace outlives
        // it (above); `skc_net` is set at `sk_alloc` and never changes.
        unsafe { Net::from_raw((*self.sk).__sk_common.skc_net.net) }
    }

    /// The sock's links on its protocol's socket set, for that set only
    /// (which touches them under RTNL).
    pub(in crate::glue) fn set_link(&self) -> &SetLink {
        // SAFETY: a live sock created by `create` for `T` (type
        // invariant), so it is an `ObjOf<T>` with an initialised link;
        // only its cells are written, and only by the set.
        unsafe { &(*self.sk.cast::<ObjOf<T>>()).set }
    }

    /// The sock's reserved-receiver slot, for `can::proto` only (which
    /// reads and writes it as its functions say: under the socket lock
    /// after `socket()`).
    pub(in crate::glue) fn rx_slot(&self) -> &core::sync::atomic::AtomicPtr<ffi::c_void> {
        // SAFETY: a live sock created by `create` for `T` (type
        // invariant), so it is an `ObjOf<T>` with an initialised slot, an
        // atomic, which may be shared.
        unsafe { &(*self.sk.cast::<ObjOf<T>>()).rx }
    }

    /// The state readable without the socket lock.
    pub(crate) fn shared(&self) -> &T::Shared {
        // SAFETY: a live sock created by `create` for `T` (type
        // invariant), so it is an `ObjOf<T>` with initialised shared state,
        // which is `Sync`.
        unsafe { &(*self.sk.cast::<ObjOf<T>>()).shared }
    }

    /// The inode number of the socket's file (`sock_i_ino`; 0 without
    /// one), which names it in /proc files.
    pub(crate) fn ino(&self) -> u64 {
        // SAFETY: live sock (type invariant).
        unsafe { bindings::sock_i_ino(self.sk) as u64 }
    }

    /// The address of the sock's `struct socket` (`sk->sk_socket`; 0
    /// once orphaned), for /proc files that print it with `%pK`. Any
    /// context.
    ///
    /// `sk_socket` changes while others read the sock: `sock_orphan` (at
    /// close, which can run while a /proc reader holds the sock) and
    /// `sock_graft` write it with `sk_set_socket`, a `WRITE_ONCE`. It is
    /// read here once with `READ_ONCE` semantics, never through a
    /// reference: the value as of some moment, as mainline's `%pK` of
    /// `sk->sk_socket` prints it.
    pub(in crate::glue) fn socket_addr(&self) -> usize {
        // A volatile read is READ_ONCE, paired with the WRITE_ONCE of every
        // writer (`sk_set_socket`): no data race in the kernel's model.
        // SAFETY: live sock (type invariant), so the field is valid to
        // read.
        let p = unsafe { core::ptr::read_volatile(core::ptr::addr_of!((*self.sk).sk_socket)) };
        p as usize
    }

    /// A counted reference to this sock (`sock_hold`). Any context.
    pub(crate) fn to_ref(&self) -> SockRef<T> {
        // SAFETY: live sock (type invariant); SockRef drops the reference.
        unsafe { bindings::rcan_sock_hold(self.sk) };
        // INVARIANT: one reference, taken just above, on our live sock;
        // the `Sock` inside is lent out as a `Sock` only with a proof of
        // process context (`SockRef::in_process`).
        SockRef {
            // SAFETY: our live sock, kept alive by the reference taken
            // above for as long as the `SockRef` holds it.
            sock: unsafe { Sock::from_raw(self.sk) },
        }
    }

    /// Queues `skb` on the receive queue (charging the receive buffer) and
    /// wakes readers. Softirq or process context. The skb is freed if the
    /// queue is full. It must be ours alone ([`OwnedSkb`]): the queue makes
    /// the socket its owner (`skb_set_owner_r`) and keeps its `cb`.
    #[inline(always)]
    pub(crate) fn queue_rcv(&self, skb: OwnedSkb) -> Result {
        let p = skb.into_raw();
        // SAFETY: live sock; on success the queue owns the skb. This is
        // the inline sock_queue_rcv_skb (no drop reason asked for).
        let ret = unsafe { bindings::sock_queue_rcv_skb_reason(self.sk, p, core::ptr::null_mut()) };
        if ret < 0 {
            // SAFETY: on failure the reference is still ours.
            drop(unsafe { Skb::<Shared>::from_raw(p) });
            return Err(Error::from_errno(ret));
        }
        Ok(())
    }

    /// Sets `sk_err` and reports it to waiters (recv/poll see it once);
    /// a socket already closed (SOCK_DEAD) is not woken.
    pub(crate) fn report_error(&self, errno: i32) {
        // SAFETY: live sock; sk_err is written like this by every protocol.
        unsafe { bindings::rcan_sk_report_error(self.sk, errno) };
    }

    /// Takes the pending error (`sock_error`): returns `sk_err` (a
    /// positive errno; 0: none) and clears it, so that the next call,
    /// `poll` and `SO_ERROR` do not see it again. Any context.
    pub(crate) fn take_error(&self) -> i32 {
        // The writers of a PF_CAN socket's `sk_err` are
        // `rcan_sk_report_error` (WRITE_ONCE) and `sock_error` (`xchg`),
        // its readers use READ_ONCE (`sock_error`, `datagram_poll`): all
        // marked accesses, so viewing it as an `AtomicI32` for this call
        // races with no plain access.
        // SAFETY: live sock (type invariant), so `sk_err`, an aligned `int`
        // of it, is valid for the sock's life, which outlives this call.
        let err = unsafe {
            core::sync::atomic::AtomicI32::from_ptr(core::ptr::addr_of_mut!((*self.sk).sk_err))
        };
        if err.load(core::sync::atomic::Ordering::Relaxed) == 0 {
            return 0;
        }
        err.swap(0, core::sync::atomic::Ordering::SeqCst)
    }

    /// Wakes pollers and writers waiting on the socket for `EPOLLOUT`
    /// (a protocol's [`Proto::writable`] became true). Any context.
    pub(crate) fn wake_writers(&self) {
        // SAFETY: live sock (type invariant); the helper reads its wait
        // queue under RCU, as `sk_write_space` callbacks do.
        unsafe { bindings::rcan_sk_wake_writers(self.sk) };
    }

    /// The socket's `sk_priority` (SO_PRIORITY, or what the protocol set
    /// with [`Sock::set_priority`]), read once as the kernel's send
    /// paths read it (`READ_ONCE`: setsockopt writes it without the
    /// socket lock). Any context.
    pub(crate) fn priority(&self) -> u32 {
        // SAFETY: live sock (type invariant); `sk_priority` is a plain
        // u32 field that the kernel reads and writes with
        // READ_ONCE/WRITE_ONCE.
        unsafe { core::ptr::read_volatile(core::ptr::addr_of!((*self.sk).sk_priority)) }
    }

    /// Whether SO_BROADCAST is set (`sock_flag(sk, SOCK_BROADCAST)`),
    /// read once. Any context.
    pub(crate) fn broadcast(&self) -> bool {
        // SAFETY: live sock (type invariant); the flag word is read once,
        // as `sock_flag`'s `test_bit` reads it (setsockopt sets the bit
        // atomically).
        let flags = unsafe {
            core::ptr::read_volatile(core::ptr::addr_of!(
                (*self.sk).__sk_common.__bindgen_anon_5.skc_flags
            ))
        };
        flags & (1 << bindings::sock_flags_SOCK_BROADCAST) != 0
    }

    /// The socket's `sk_tsflags` (`SOF_TIMESTAMPING_*`, set by
    /// SO_TIMESTAMPING without the socket lock), read once. Any context.
    pub(crate) fn tsflags(&self) -> u32 {
        // SAFETY: live sock (type invariant); the helper is a READ_ONCE.
        unsafe { bindings::rcan_sock_tsflags(self.sk) }
    }

    /// The next timestamp key of a send (`sk_tskey`, incremented
    /// atomically, for `SOF_TIMESTAMPING_OPT_ID`). Any context.
    pub(crate) fn next_tskey(&self) -> u32 {
        // SAFETY: live sock (type invariant); `sk_tskey` is an atomic_t.
        unsafe { bindings::rcan_sock_next_tskey(self.sk) }
    }

    /// Frees every notification on the error queue (`skb_queue_purge`
    /// of `sk_error_queue`, under the queue's own IRQ-safe lock): what
    /// turning a protocol's error queue off does. Process or softirq
    /// context, not hardirq: each notification's destructor
    /// (`sock_rmem_free`) runs here.
    pub(crate) fn purge_errqueue(&self) {
        // SAFETY: live sock (type invariant); its error queue is an
        // initialised `sk_buff_head` for the sock's whole life.
        unsafe { bindings::rcan_sock_purge_errqueue(self.sk) }
    }

    /// Queues a notification on the error queue (`sock_queue_err_skb`),
    /// stamped now, for `recvmsg(MSG_ERRQUEUE)`: `note`'s errno, origin,
    /// info and data in its `sock_extended_err`, its statistics as the
    /// data (reported as `SCM_TIMESTAMPING_OPT_STATS`). Any context
    /// (`GFP_ATOMIC`). `ENOMEM`, or the queue's refusal (a full receive
    /// buffer), when it is dropped.
    pub(crate) fn queue_err(&self, note: &ErrNote<'_>) -> Result {
        let len = u32::try_from(note.stats.len()).map_err(|_| code::EINVAL)?;
        // SAFETY: live sock (type invariant); `stats` is valid for `len`
        // bytes for the call (a borrowed slice), which copies them.
        let ret = unsafe {
            bindings::rcan_sock_queue_err(
                self.sk,
                note.stats.as_ptr().cast(),
                len,
                note.errno,
                note.origin,
                note.info,
                note.data,
                true,
            )
        };
        super::to_result(ret).map(|_| ())
    }
}

/// An error queue notification for [`SockView::queue_err`]: the fields of
/// its `struct sock_extended_err` and its statistics (netlink attributes).
pub(crate) struct ErrNote<'a> {
    /// `ee_errno` (positive).
    pub(crate) errno: u32,
    /// `ee_origin` (`SO_EE_ORIGIN_*`).
    pub(crate) origin: u8,
    /// `ee_info`.
    pub(crate) info: u32,
    /// `ee_data`.
    pub(crate) data: u32,
    /// The statistics.
    pub(crate) stats: &'a [u8],
}

impl<T: Proto> Sock<T> {
    /// Sets the socket's `sk_priority` (`WRITE_ONCE`, as `sock_setsockopt`
    /// writes SO_PRIORITY): for a protocol option that sets it too
    /// (mainline CAN_J1939's `SO_J1939_SEND_PRIO`). Process context.
    pub(crate) fn set_priority(&self, priority: u32) {
        // SAFETY: live sock (type invariant); `sk_priority` is a plain
        // u32 field read with READ_ONCE by lockless readers.
        unsafe { core::ptr::write_volatile(core::ptr::addr_of_mut!((*self.sk).sk_priority), priority) };
    }

    /// The send timeout in jiffies (`sock_sndtimeo`): 0 if `nonblock`,
    /// else SO_SNDTIMEO (`MAX_SCHEDULE_TIMEOUT` when unset).
    pub(crate) fn sndtimeo(&self, nonblock: bool) -> i64 {
        // SAFETY: live sock.
        unsafe { bindings::rcan_sock_sndtimeo(self.sk, nonblock) as i64 }
    }

    /// Takes the socket lock (`lock_sock`). Process context (the type's
    /// invariant); sleeps.
    pub(crate) fn lock(&self) -> SockGuard<'_, T> {
        // SAFETY: live sock (type invariant); released in the guard's Drop.
        unsafe { bindings::rcan_lock_sock(self.sk) };
        SockGuard {
            sock: self,
            _not_send: PhantomData,
        }
    }

    /// Waits for and dequeues one skb (`skb_recv_datagram`), honouring
    /// MSG_DONTWAIT, MSG_PEEK, SO_RCVTIMEO and pending `sk_err`. A
    /// [`Skb`], read-only: with MSG_PEEK it is still on the queue.
    #[inline(always)]
    pub(crate) fn recv_datagram(&self, flags: i32) -> Result<Skb> {
        let mut err: ffi::c_int = 0;
        // SAFETY: live sock.
        let skb = unsafe { bindings::skb_recv_datagram(self.sk, flags as u32, &mut err) };
        // SAFETY: an owned skb or NULL with `err` set.
        unsafe { Skb::from_raw(skb) }.ok_or_else(|| Error::from_errno(err))
    }

    /// Frees an skb obtained from [`Sock::recv_datagram`]
    /// (`skb_free_datagram`).
    #[inline(always)]
    pub(crate) fn free_datagram(&self, skb: Skb) {
        // SAFETY: live sock; `skb` came from skb_recv_datagram on it and we
        // give its reference away.
        unsafe { bindings::skb_free_datagram(self.sk, skb.into_raw()) };
    }

    /// Allocates an skb charged to the send buffer, blocking while it is
    /// full unless `nonblock` (then EAGAIN); honours SO_SNDTIMEO.
    /// Inline: it is a call and an error conversion on every frame sent.
    #[inline]
    pub(crate) fn alloc_send_skb(&self, size: u32, nonblock: bool) -> Result<UniqueSkb> {
        let mut err: ffi::c_int = 0;
        // SAFETY: live sock; `err` is a valid place for the error. This is
        // the body of the inline sock_alloc_send_skb (no paged part).
        let skb = unsafe {
            bindings::sock_alloc_send_pskb(self.sk, size as _, 0, nonblock as i32, &mut err, 0)
        };
        // SAFETY: a fresh skb (one user, not cloned) or NULL with `err` set.
        unsafe { Skb::from_raw(skb) }.ok_or_else(|| Error::from_errno(err))
    }

    /// Dequeues from the error queue (`sock_recv_errqueue`); EAGAIN when
    /// it is empty.
    pub(crate) fn recv_errqueue(
        &self,
        msg: &mut Msg,
        len: usize,
        level: i32,
        type_: i32,
    ) -> Result<usize> {
        // SAFETY: live sock and a valid msghdr of the current recvmsg.
        let ret = unsafe { bindings::sock_recv_errqueue(self.sk, msg.0, len as i32, level, type_) };
        super::to_result(ret).map(|n| n as usize)
    }
}

/// A counted reference to a sock of protocol `T` (`sock_hold`); dropping
/// it is `sock_put` (any context). The sock is reached by borrowing
/// ([`SockRef::sock`]), so no use of it can outlive the reference.
///
/// # Invariants
///
/// Holds one reference on `sock`, a sock created by [`create`] for `T`.
pub(crate) struct SockRef<T: Proto> {
    sock: Sock<T>,
}

// SAFETY: sock references may be dropped from any thread and context.
unsafe impl<T: Proto> Send for SockRef<T> {}

// SAFETY: shared access only lends `&Sock`s, whose methods may be called
// from any thread (each names its context).
unsafe impl<T: Proto> Sync for SockRef<T> {}

impl<T: Proto> SockRef<T> {
    /// The sock, borrowed for as long as this reference is, as a
    /// [`SockView`]: a counted reference is held by timers and jobs whose
    /// callbacks run in softirq or hardirq context, where the socket lock
    /// must not be taken. Any context.
    pub(crate) fn sock(&self) -> &SockView<T> {
        // Our reference keeps the sock alive while `self` lives, and the
        // borrow cannot outlive `self` (type invariant).
        &self.sock
    }

    /// The sock with its process-context methods (the socket lock), for
    /// a caller that proves it runs in process context.
    pub(crate) fn in_process<'a>(&'a self, _ctx: &'a super::ctx::Process) -> &'a Sock<T> {
        // INVARIANT: the borrow is as long as the proof's, which is lent
        // only to process context and cannot leave it (`ctx::Process`).
        &self.sock
    }
}

impl<T: Proto> Drop for SockRef<T> {
    fn drop(&mut self) {
        // SAFETY: we own one reference (type invariant).
        unsafe { bindings::rcan_sock_put(self.sock.sk) };
    }
}

/// The socket lock held; gives access to `Proto::Data`.
pub(crate) struct SockGuard<'a, T: Proto> {
    sock: &'a Sock<T>,
    _not_send: PhantomData<*mut ()>,
}

impl<'a, T: Proto> SockGuard<'a, T> {
    /// The locked socket: holding the guard proves its lock is held.
    pub(crate) fn sock(&self) -> &'a Sock<T> {
        self.sock
    }
}

impl<T: Proto> core::ops::Deref for SockGuard<'_, T> {
    type Target = T::Data;
    fn deref(&self) -> &T::Data {
        // SAFETY: the sock was created by `create` for `T`, so it is a
        // `ObjOf<T>` with initialised data; the socket lock is held.
        unsafe { &(*self.sock.sk.cast::<ObjOf<T>>()).data }
    }
}

impl<T: Proto> core::ops::DerefMut for SockGuard<'_, T> {
    fn deref_mut(&mut self) -> &mut T::Data {
        // SAFETY: as above; the socket lock gives exclusive access.
        unsafe { &mut (*self.sock.sk.cast::<ObjOf<T>>()).data }
    }
}

impl<T: Proto> Drop for SockGuard<'_, T> {
    fn drop(&mut self) {
        // SAFETY: paired with lock_sock in Sock::lock.
        unsafe { bindings::rcan_release_sock(self.sock.sk) };
    }
}

/// The bytes of a socket address the glue writes for a protocol
/// ([`Proto::getname`]'s buffer, [`Msg::set_name`]): `sizeof(struct
/// sockaddr)`, the smallest buffer the kernel types a socket address with
/// (why that bound, at those two places). Every address of ours fits
/// (`sockaddr_can` up to `can_ifindex` 8, the thesis' `sockaddr_can` 16,
/// DSOR's 8 and 6).
pub(crate) const NAME_ROOM: usize = core::mem::size_of::<bindings::sockaddr>();
const _: () = assert!(NAME_ROOM == 16);

/// The bytes of a socket address the glue writes for a protocol with
/// [`Proto::SOCKADDR_CAN_NAMES`]: `sizeof(struct sockaddr_can)` (family,
/// padding, `can_ifindex`, the 16-byte `can_addr` union), which is what
/// mainline's own PF_CAN protocols write through the same two pointers
/// (`j1939_sk_getname` and `j1939_sk_recvmsg` write
/// `J1939_MIN_NAMELEN`, 24 bytes; `isotp_getname` 16). So every caller
/// that can reach the `getname` or `recvmsg` of a PF_CAN socket already
/// gives at least this much, or mainline would overrun it: the socket
/// layer (`__sys_getsockname`, `__sys_getpeername`, `SO_PEERNAME`,
/// `____sys_recvmsg`, io_uring) a `sockaddr_storage` (128 bytes); the
/// in-kernel `kernel_getsockname`/`kernel_getpeername` callers of 6.12
/// use sockets of their own families (INET, INET6, QRTR, SMC's TCP) or
/// check the socket is TCP (iscsi_tcp, on a user's descriptor, with a
/// 28-byte `sockaddr_in6`), and no in-kernel `kernel_recvmsg` caller
/// opens PF_CAN sockets.
pub(crate) const SOCKADDR_CAN_ROOM: usize = 24;
const _: () = assert!(SOCKADDR_CAN_ROOM > NAME_ROOM && SOCKADDR_CAN_ROOM <= 128);

/// The bound for protocol `T`'s addresses: [`NAME_ROOM`] or, for a
/// protocol with [`Proto::SOCKADDR_CAN_NAMES`], [`SOCKADDR_CAN_ROOM`].
pub(crate) const fn name_room<T: Proto>() -> usize {
    if T::SOCKADDR_CAN_NAMES {
        SOCKADDR_CAN_ROOM
    } else {
        NAME_ROOM
    }
}

/// A `struct msghdr` of a sendmsg/recvmsg call.
///
/// # Invariants
///
/// Made only by the sendmsg and recvmsg trampolines of this file, from
/// the socket layer's argument: a valid msghdr for the duration of the
/// call, used by nobody else meanwhile; the second field is
/// [`name_room`] of the socket's protocol, which those trampolines
/// alone set.
pub(crate) struct Msg(*mut bindings::msghdr, usize);

impl Msg {
    pub(crate) fn as_ptr(&self) -> *mut bindings::msghdr {
        self.0
    }

    /// The destination address of a sendmsg (a kernel copy), if any;
    /// `None` in a recvmsg, whose `msg_name` is the buffer for the source
    /// address, not an address.
    pub(crate) fn name(&self) -> Option<&[u8]> {
        // In a sendmsg (a source iterator) `msg_name`, if set, is an
        // address of `msg_namelen` initialised bytes: the socket layer's
        // copy in a sockaddr_storage (`move_addr_to_kernel` refuses a
        // longer one), or a `kernel_sendmsg` caller's address of that
        // length; the cap is the socket layer's. In a recvmsg it is a
        // buffer the caller may not have initialised (with
        // `kernel_recvmsg`, `msg_namelen` is whatever the caller left).
        // SAFETY: a valid msghdr of the current call (type invariant); a
        // slice only over a sendmsg's name (above).
        unsafe {
            let m = &*self.0;
            if m.msg_name.is_null() || !m.msg_iter.data_source {
                None
            } else {
                let len = (m.msg_namelen.max(0) as usize).min(128);
                Some(core::slice::from_raw_parts(m.msg_name as *const u8, len))
            }
        }
    }

    /// Stores a source address for recvmsg (if the caller asked for one):
    /// at most [`name_room`] bytes of `addr` for the socket's protocol
    /// ([`NAME_ROOM`], or [`SOCKADDR_CAN_ROOM`] for a protocol with
    /// [`Proto::SOCKADDR_CAN_NAMES`]; more are cut), and `msg_namelen`
    /// says how many.
    #[inline]
    pub(crate) fn set_name(&mut self, addr: &[u8]) {
        // `msg_name` is NULL or the buffer the recvmsg's caller gave for
        // the source address, and `msg_namelen` is not its size (the socket layer sets it to 0 before calling
        // us), so the bound comes from what every caller gives: the socket
        // layer's recvmsg paths (`____sys_recvmsg`, io_uring) a
        // `sockaddr_storage` ("We assume all kernel code knows the size of
        // sockaddr_storage", net/socket.c), in-kernel `kernel_recvmsg`
        // callers a buffer for a socket address, of which the smallest
        // type is `struct sockaddr`. We write at most `NAME_ROOM`, that
        // size: within any such buffer, and no more than mainline's own
        // PF_CAN protocols write there (isotp 16 bytes, j1939 24); for a
        // protocol with `SOCKADDR_CAN_NAMES`, `SOCKADDR_CAN_ROOM` (24),
        // what mainline's j1939 writes (the argument at that constant).
        // `self.1` is one of the two (type invariant).
        // SAFETY: a valid msghdr of the current call, used by nobody else
        // meanwhile (type invariant); `msg_name`, when set, has room for
        // `self.1` bytes (above).
        unsafe {
            let m = &mut *self.0;
            if m.msg_name.is_null() {
                return;
            }
            let n = addr.len().min(self.1).min(SOCKADDR_CAN_ROOM);
            core::ptr::copy_nonoverlapping(addr.as_ptr(), m.msg_name as *mut u8, n);
            m.msg_namelen = n as i32;
        }
    }

    /// Copies `dst.len()` bytes from the user's buffers of a sendmsg
    /// (mainline `memcpy_from_msg`); EFAULT on a bad pointer or a short
    /// copy (the iterator is then where it was). Process context; may
    /// fault pages in.
    #[inline]
    pub(crate) fn copy_from_user(&mut self, dst: &mut [u8]) -> Result {
        // SAFETY: a slice we borrow mutably: its `len` bytes are writable
        // and nobody else touches them during the call.
        unsafe { self.copy_from_user_raw(dst.as_mut_ptr(), dst.len()) }
    }

    /// [`Msg::copy_from_user`] into raw memory (bytes that may not be
    /// initialised yet, such as the tailroom [`UniqueSkb::put_from_msg`]
    /// fills before it puts the bytes).
    ///
    /// This is `memcpy_from_msg`'s inline `copy_from_iter_full` written
    /// out: `check_copy_size` comes down, for a buffer whose size is
    /// `len`, to `len` fitting an `int`; the exported `_copy_from_iter`
    /// copies (it warns and copies nothing from a destination iterator,
    /// a recvmsg's, so that is refused here first); a short copy is
    /// undone on the iterator (`iov_iter_revert`) and is EFAULT.
    ///
    /// # Safety
    ///
    /// `dst` points to `len` bytes that are writable and that nothing
    /// else reads or writes during the call.
    #[inline(always)]
    pub(crate) unsafe fn copy_from_user_raw(&mut self, dst: *mut u8, len: usize) -> Result {
        // Msg is only made by the sendmsg/recvmsg trampolines from the
        // socket layer's argument.
        // SAFETY: so `self.0` is the valid msghdr of the current call; its
        // iterator is not used by anyone else during the call.
        let iter = unsafe { core::ptr::addr_of_mut!((*self.0).msg_iter) };
        // SAFETY: `iter` is valid (above); plain read of the direction.
        let source = unsafe { (*iter).data_source };
        if !source || len > i32::MAX as usize {
            return Err(code::EFAULT);
        }
        // `iter` is the message's source iterator: `_copy_from_iter`
        // advances it by what it copied, `iov_iter_revert` moves it back.
        // SAFETY: as said; `dst` is writable for `len` bytes (our contract).
        let copied = unsafe {
            let copied = bindings::_copy_from_iter(dst.cast(), len, iter);
            if copied != len {
                bindings::iov_iter_revert(iter, copied);
            }
            copied
        };
        if copied == len {
            Ok(())
        } else {
            Err(code::EFAULT)
        }
    }

    /// Copies `src` to the user's buffers of a recvmsg (mainline
    /// `memcpy_to_msg`); EFAULT on a bad pointer or a short copy, and on
    /// a message whose buffers are a source (a sendmsg's). Process
    /// context; may fault pages in.
    ///
    /// This is the inline `copy_to_iter` written out: its
    /// `check_copy_size` comes down, for a slice (whose object size is
    /// its length), to the length fitting an `int`; `_copy_to_iter`
    /// (exported) would warn and copy nothing into a source iterator,
    /// which is refused here first.
    #[inline(always)]
    pub(crate) fn copy_to_user(&mut self, src: &[u8]) -> Result {
        // Msg is only made by the sendmsg/recvmsg trampolines from the
        // socket layer's argument.
        // SAFETY: so `self.0` is the valid msghdr of the current call; its
        // iterator is not used by anyone else during the call.
        let iter = unsafe { core::ptr::addr_of_mut!((*self.0).msg_iter) };
        // SAFETY: `iter` is valid (above); plain read of the direction.
        let source = unsafe { (*iter).data_source };
        if source || src.len() > i32::MAX as usize {
            return Err(code::EFAULT);
        }
        // SAFETY: `src` is readable for `src.len()` bytes; `iter` is the
        // message's destination iterator, which `_copy_to_iter` advances
        // by what it copied.
        let n = unsafe { bindings::_copy_to_iter(src.as_ptr().cast(), src.len(), iter) };
        if n == src.len() {
            Ok(())
        } else {
            Err(code::EFAULT)
        }
    }

    /// Copies `len` bytes of `skb` from `offset` to the user's buffers.
    pub(crate) fn copy_from_skb(&mut self, skb: &Skb, offset: usize, len: usize) -> Result {
        // SAFETY: valid msghdr and skb; the kernel checks the skb bounds.
        let ret = unsafe {
            bindings::rcan_skb_copy_datagram_msg(skb.as_ptr(), offset as i32, self.0, len as i32)
        };
        super::to_result(ret).map(|_| ())
    }

    /// The flags of a sendmsg call.
    pub(crate) fn flags(&self) -> u32 {
        // SAFETY: valid msghdr.
        unsafe { (*self.0).msg_flags }
    }

    /// Adds a control message (`put_cmsg`) to a recvmsg's answer: level,
    /// type and the bytes of its data. Like mainline's callers, ignores
    /// a control buffer that is too small (the kernel sets MSG_CTRUNC).
    /// Does nothing in a sendmsg, whose control buffer holds the
    /// caller's messages. Process context (may fault pages in).
    pub(crate) fn put_cmsg(&mut self, level: i32, type_: i32, data: &[u8]) {
        // A cmsg's length is an int; ours are a few bytes.
        let Ok(len) = ffi::c_int::try_from(data.len()) else {
            return;
        };
        // The valid msghdr of the current call, used by nobody else
        // meanwhile (type invariant); only a recvmsg's (a destination
        // iterator), whose control buffer `put_cmsg` fills within
        // `msg_controllen` (user or kernel memory, as the msghdr says).
        // SAFETY: that, and `data` is readable for `len` bytes.
        unsafe {
            if (*self.0).msg_iter.data_source {
                return;
            }
            let _ = bindings::put_cmsg(self.0, level, type_, len, data.as_ptr() as *mut ffi::c_void);
        }
    }

    /// Adds `flag` (e.g. MSG_TRUNC) to the flags returned to the user.
    #[inline]
    pub(crate) fn add_flags(&mut self, flag: u32) {
        // SAFETY: valid msghdr.
        unsafe { (*self.0).msg_flags |= flag };
    }

    /// Timestamps and other control messages the socket asked for
    /// (mainline's inline `sock_recv_cmsgs`, written out: its test reads
    /// `sk_flags` and `sk_tsflags` in place, so `__sock_recv_cmsgs` is
    /// called only when SO_TIMESTAMP*, SO_RXQ_OVFL, SO_RCVMARK or
    /// SO_TIMESTAMPING asks for a message; otherwise only the socket's
    /// last-packet stamp (`sk_stamp`, for SIOCGSTAMP) is kept as the
    /// kernel keeps it). Process context.
    #[inline(always)]
    pub(crate) fn recv_cmsgs<T: Proto>(&mut self, sk: &Sock<T>, skb: &Skb) {
        const FLAGS_RECV_CMSGS: ffi::c_ulong = (1 << bindings::sock_flags_SOCK_RXQ_OVFL)
            | (1 << bindings::sock_flags_SOCK_RCVTSTAMP)
            | (1 << bindings::sock_flags_SOCK_RCVMARK);
        const TSFLAGS_ANY: u32 =
            bindings::SOF_TIMESTAMPING_SOFTWARE | bindings::SOF_TIMESTAMPING_RAW_HARDWARE;
        const SOCK_TIMESTAMP: ffi::c_ulong = 1 << bindings::sock_flags_SOCK_TIMESTAMP;
        /// `SK_DEFAULT_STAMP`: no packet stamped yet.
        const SK_DEFAULT_STAMP: i64 = -1_000_000_000;
        // `sk_stamp` is read and written with READ_ONCE/WRITE_ONCE on
        // 64-bit kernels only (32-bit ones take a seqlock).
        const _: () = assert!(usize::BITS == 64);
        let sk = sk.as_ptr();
        // READ_ONCE of the two flag words, as the kernel's inline reads
        // them (setsockopt may change them concurrently).
        // SAFETY: `sk` is live (a `Sock` is only made for a sock the
        // caller holds: here the recvmsg's own socket).
        let (flags, tsflags) = unsafe {
            (
                core::ptr::read_volatile(core::ptr::addr_of!(
                    (*sk).__sk_common.__bindgen_anon_5.skc_flags
                )),
                core::ptr::read_volatile(core::ptr::addr_of!((*sk).sk_tsflags)),
            )
        };
        if flags & FLAGS_RECV_CMSGS != 0 || tsflags & TSFLAGS_ANY != 0 {
            // SAFETY: the valid msghdr of the current recvmsg (Msg's
            // invariant), a live sock and a valid skb we hold.
            unsafe { bindings::__sock_recv_cmsgs(self.0, sk, skb.as_ptr()) };
            return;
        }
        // SAFETY: live sock (above); `sk_stamp` is a plain 64-bit field
        // that the kernel reads and writes with READ_ONCE/WRITE_ONCE.
        let stamp = unsafe { core::ptr::addr_of_mut!((*sk).sk_stamp) };
        if flags & SOCK_TIMESTAMP != 0 {
            let t = skb.tstamp();
            // SAFETY: `stamp` is valid (above); WRITE_ONCE.
            unsafe { core::ptr::write_volatile(stamp, t) };
            return;
        }
        // SAFETY: `stamp` is valid (above); READ_ONCE.
        if unsafe { core::ptr::read_volatile(stamp) } == SK_DEFAULT_STAMP {
            // SAFETY: as above; WRITE_ONCE.
            unsafe { core::ptr::write_volatile(stamp, 0) };
        }
    }
}

/// A registered `struct proto` (the sock allocator of protocol `T`).
///
/// It lives in a static of the protocol module ([`ProtoReg::new`] is const);
/// [`ProtoReg::register`] in module init, [`ProtoReg::unregister`] in exit.
pub(crate) struct ProtoReg<T: Proto> {
    proto: core::cell::UnsafeCell<bindings::proto>,
    ops: core::cell::UnsafeCell<bindings::proto_ops>,
    _t: PhantomData<T>,
}

// SAFETY: the C structs are written only in `register`, which module init
// calls before anything else can see them; afterwards they are read-only.
unsafe impl<T: Proto> Sync for ProtoReg<T> {}

impl<T: Proto> ProtoReg<T> {
    pub(in crate::glue) const fn new() -> Self {
        ProtoReg {
            // SAFETY: all-zero is a valid `struct proto` / `proto_ops`
            // before registration; `register` fills in what is needed.
            proto: core::cell::UnsafeCell::new(unsafe { core::mem::zeroed() }),
            ops: core::cell::UnsafeCell::new(unsafe { core::mem::zeroed() }),
            _t: PhantomData,
        }
    }

    /// Fills in and registers the proto, with `release` as its
    /// `proto_ops::release` (a trampoline that ends in [`release_then`]
    /// for `T`). Module init only (process context, before any socket of
    /// `T` can exist). `name` must be static.
    pub(in crate::glue) fn register(
        &self,
        name: &'static kernel::str::CStr,
        family: i32,
        release: unsafe extern "C" fn(*mut bindings::socket) -> ffi::c_int,
    ) -> Result {
        // Before any sock of the module can exist (their `destruct` may
        // need it).
        defer_init();
        // SAFETY: module init is single-threaded with respect to these
        // structs: nothing else references them before registration.
        unsafe {
            let p = &mut *self.proto.get();
            let n = name.as_bytes_with_nul();
            for (i, b) in n.iter().take(p.name.len() - 1).enumerate() {
                p.name[i] = *b as ffi::c_char;
            }
            p.owner = super::this_module();
            p.obj_size = core::mem::size_of::<ObjOf<T>>() as u32;
            let o = &mut *self.ops.get();
            *o = proto_ops_template::<T>();
            o.release = Some(release);
            o.family = family;
            o.owner = super::this_module();
            super::to_result(bindings::proto_register(p, 0))?;
        }
        Ok(())
    }

    /// Module exit only, after the last socket is gone (guaranteed by the
    /// module reference each socket holds): glue-private, so only
    /// `can::proto`'s exit sweep calls it.
    pub(in crate::glue) fn unregister(&self) {
        // SAFETY: registered in `register`.
        unsafe { bindings::proto_unregister(self.proto.get()) };
    }

    /// Creates a socket of this protocol: allocates the sock, initialises
    /// `T::Data`. Process context.
    ///
    /// # Safety
    ///
    /// `net` and `sock` come from the socket layer's `create` call;
    /// `register` succeeded.
    pub(in crate::glue) unsafe fn create(
        &self,
        net: *mut bindings::net,
        sock: *mut bindings::socket,
        protocol: i32,
        kern: i32,
    ) -> Result {
        // SAFETY: per the contract; sk_alloc zeroes the whole object.
        unsafe {
            (*sock).ops = self.ops.get();
            let sk = bindings::sk_alloc(
                net,
                bindings::PF_CAN as i32,
                super::GFP_KERNEL,
                self.proto.get(),
                kern,
            );
            if sk.is_null() {
                return Err(code::ENOMEM);
            }
            bindings::sock_init_data(sock, sk);
            (*sk).sk_protocol = protocol as u16;
            (*sk).sk_priority = T::SK_PRIORITY;
            core::ptr::addr_of_mut!((*sk.cast::<ObjOf<T>>()).set).write(SetLink {
                prev: core::cell::Cell::new(0),
                next: core::cell::Cell::new(0),
                listed: core::sync::atomic::AtomicBool::new(false),
            });
            core::ptr::addr_of_mut!((*sk.cast::<ObjOf<T>>()).rx)
                .write(core::sync::atomic::AtomicPtr::new(core::ptr::null_mut()));
            core::ptr::addr_of_mut!((*sk.cast::<ObjOf<T>>()).data).write(T::new_data());
            core::ptr::addr_of_mut!((*sk.cast::<ObjOf<T>>()).shared).write(T::new_shared());
            (*sk).sk_destruct = Some(destruct::<T>);
        }
        Ok(())
    }
}

/// `sk_destruct`: the last reference is gone. Any context: the final
/// `sock_put` can come from an skb destructor or a timer in softirq, or
/// from process context under a spinlock or an RCU read lock. The
/// `Proto::Data` and `Proto::Shared` of `T` are dropped here where the
/// caller may sleep (preemptible, outside RCU read-side sections; a kernel
/// without `CONFIG_PREEMPT_COUNT` cannot tell, so never here); elsewhere
/// they are moved out of the sock (which the socket layer frees when this
/// returns) and dropped by the module's deferred-drop work
/// ([`defer_drop`]), in process context, since their `Drop` may sleep (a
/// device registration, a job's timers, anything a protocol keeps).
unsafe extern "C" fn destruct<T: Proto>(sk: *mut bindings::sock) {
    let obj = sk.cast::<ObjOf<T>>();
    // SAFETY: the sock was created by `ProtoReg::create` for `T` with
    // initialised data; nothing can reach it any more, so its data may be
    // dropped, or moved out (read) and never used in the sock again.
    unsafe {
        bindings::rcan_sk_purge_queues(sk);
        let data = core::ptr::addr_of_mut!((*obj).data);
        let shared = core::ptr::addr_of_mut!((*obj).shared);
        let needs_drop =
            core::mem::needs_drop::<T::Data>() || core::mem::needs_drop::<T::Shared>();
        if !needs_drop || bindings::rcan_may_sleep() {
            core::ptr::drop_in_place(data);
            core::ptr::drop_in_place(shared);
        } else {
            defer_drop(data.read(), shared.read());
        }
    }
}

/// A sock's `Proto::Data` and `Proto::Shared`, moved out of it when it was
/// freed outside process context, on this module's [`DEFERRED`] list until
/// the deferred-drop work drops them. `hdr` first (`repr(C)`): the list
/// links headers.
#[repr(C)]
struct Deferred<D, S> {
    hdr: DeferHdr,
    data: D,
    shared: S,
}

/// The type-erased head of a [`Deferred`].
#[repr(C)]
struct DeferHdr {
    next: *mut DeferHdr,
    /// `drop_deferred::<D, S>` of this node's `D` and `S`.
    drop_fn: unsafe fn(*mut DeferHdr),
}

/// The [`Deferred`] nodes not dropped yet, newest first (null: none).
///
/// # Invariants
///
/// Every node is a `Deferred<D, S>` from `KBox::into_raw` whose `hdr.drop_fn`
/// is `drop_deferred::<D, S>`, owned by the list.
struct DeferList(*mut DeferHdr);

// SAFETY: the list owns its nodes, whose data is `Send` (`Proto::Data:
// Send`, `Proto::Shared: Send + Sync`), and is only used under its lock.
unsafe impl Send for DeferList {}

/// This module's deferred drops (the glue is compiled into each module: one
/// list per module). Irqsave: `destruct` may run in any context.
static DEFERRED: StaticIrqSpinLock<DeferList> =
    StaticIrqSpinLock::new(DeferList(core::ptr::null_mut()), kernel::c_str!("rcan_glue_deferred"));

/// The work item that empties [`DEFERRED`]; initialised once by
/// [`defer_init`] (module init) before any sock of the module exists.
static DEFER_WORK: CCell<bindings::work_struct> =
    // SAFETY: all-zero is a valid (not yet initialised) work_struct.
    CCell::new(unsafe { core::mem::zeroed() });

/// [`DEFER_WORK`] is initialised. Set once, in module init.
static DEFER_READY: AtomicBool = AtomicBool::new(false);

/// Initialises [`DEFER_WORK`] if it is not. Module init (process context;
/// module init is serialised), before the module's first sock.
fn defer_init() {
    if DEFER_READY.load(Ordering::Acquire) {
        return;
    }
    // Its function is in this module's text, and the module's exit
    // flushes it ([`flush_deferred_drops`]).
    // SAFETY: a static work_struct, initialised once here before anything
    // can queue it (no sock of this module exists yet).
    unsafe { bindings::rcan_init_work(DEFER_WORK.get(), Some(defer_work)) };
    DEFER_READY.store(true, Ordering::Release);
}

/// Hands `data` and `shared` to process context: onto [`DEFERRED`], and the
/// work scheduled. Any context. Without memory for the node (GFP_ATOMIC)
/// they leak: dropping them here is what must not happen.
fn defer_drop<D: Send, S: Send>(data: D, shared: S) {
    let node = match KBox::<Deferred<D, S>>::new_uninit(GFP_ATOMIC) {
        Ok(b) if DEFER_READY.load(Ordering::Acquire) => KBox::write(
            b,
            Deferred {
                hdr: DeferHdr {
                    next: core::ptr::null_mut(),
                    drop_fn: drop_deferred::<D, S>,
                },
                data,
                shared,
            },
        ),
        _ => {
            core::mem::forget((data, shared));
            return;
        }
    };
    // CAST: `hdr` is the first field of the `repr(C)` `Deferred`.
    let p = KBox::into_raw(node).cast::<DeferHdr>();
    {
        let mut l = DEFERRED.lock();
        // SAFETY: `p` is our new node, not on the list yet.
        unsafe { (*p).next = l.0 };
        // INVARIANT: from KBox::into_raw, with its own drop_fn.
        l.0 = p;
    }
    // SAFETY: DEFER_WORK was initialised (DEFER_READY, checked above).
    unsafe { bindings::rcan_schedule_work(DEFER_WORK.get()) };
}

/// Drops one [`Deferred`] node.
///
/// # Safety
///
/// `h` is a node taken off [`DEFERRED`], a `Deferred<D, S>` of these `D`
/// and `S` (its `drop_fn`), owned by the caller.
unsafe fn drop_deferred<D, S>(h: *mut DeferHdr) {
    // SAFETY: per the contract (DeferList invariant).
    drop(unsafe { KBox::from_raw(h.cast::<Deferred<D, S>>()) });
}

/// [`DEFER_WORK`]'s function: drops every deferred node. Process context
/// (the system workqueue); sleeps if the drops do.
unsafe extern "C" fn defer_work(_work: *mut bindings::work_struct) {
    loop {
        let mut p = core::mem::replace(&mut DEFERRED.lock().0, core::ptr::null_mut());
        if p.is_null() {
            return;
        }
        while !p.is_null() {
            // SAFETY: a node we took off the list, so ours (DeferList
            // invariant); read before it is freed.
            let (next, drop_fn) = unsafe { ((*p).next, (*p).drop_fn) };
            // SAFETY: as above; `drop_fn` is the node's own.
            unsafe { drop_fn(p) };
            p = next;
        }
    }
}

/// Waits until every deferred drop queued so far has run (module exit,
/// process context). After the module's last sock is freed (each pins the
/// module until then, after its `destruct` queued what it had), nothing
/// queues more, so afterwards nothing of the work runs in module text.
pub(super) fn flush_deferred_drops() {
    if DEFER_READY.load(Ordering::Acquire) {
        // SAFETY: initialised (DEFER_READY); a static.
        unsafe { bindings::rcan_flush_work(DEFER_WORK.get()) };
    }
}

/// The `struct proto_ops` of protocol `T`: our hooks plus the kernel's
/// "not supported" ones. `family` and `owner` are set by `ProtoReg`.
pub(crate) const fn proto_ops_template<T: Proto>() -> bindings::proto_ops {
    bindings::proto_ops {
        release: Some(release::<T>),
        bind: Some(bind::<T>),
        connect: Some(connect::<T>),
        socketpair: Some(bindings::sock_no_socketpair),
        accept: Some(bindings::sock_no_accept),
        getname: Some(getname::<T>),
        poll: if T::HAS_WRITABLE {
            Some(poll::<T>)
        } else {
            Some(bindings::datagram_poll)
        },
        ioctl: Some(no_ioctl),
        listen: Some(bindings::sock_no_listen),
        shutdown: Some(bindings::sock_no_shutdown),
        setsockopt: Some(setsockopt::<T>),
        getsockopt: Some(getsockopt::<T>),
        gettstamp: Some(bindings::sock_gettstamp),
        sendmsg: Some(sendmsg::<T>),
        recvmsg: Some(recvmsg::<T>),
        mmap: Some(bindings::sock_no_mmap),
        // SAFETY: all-zero is valid for the remaining (optional) hooks.
        ..unsafe { core::mem::zeroed() }
    }
}

fn ret(r: Result) -> ffi::c_int {
    match r {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

/// # Safety
///
/// `sock` is a socket of protocol `T` (called through its proto_ops).
unsafe fn sock_of<T: Proto>(sock: *mut bindings::socket) -> Option<Sock<T>> {
    // SAFETY: the socket layer passes a valid socket; `sk` is NULL after
    // release or a sock of ours kept alive by the socket.
    unsafe {
        let sk = (*sock).sk;
        if sk.is_null() {
            None
        } else {
            Some(Sock::from_raw(sk))
        }
    }
}

unsafe extern "C" fn release<T: Proto>(sock: *mut bindings::socket) -> ffi::c_int {
    // SAFETY: our contract (the socket layer's release call) is
    // `release_then`'s.
    unsafe { release_then::<T>(sock, |_| ()) }
}

/// `proto_ops::release` of protocol `T` with the glue's own teardown:
/// `after` runs on the sock once `T::release` has returned, before the
/// sock is orphaned and the socket's reference dropped (`can::proto`
/// takes the sock off its protocol's socket set there). Process context.
///
/// # Safety
///
/// `sock` is a socket of protocol `T` being closed: the socket layer's
/// `release` call through `T`'s proto_ops, once.
pub(in crate::glue) unsafe fn release_then<T: Proto>(
    sock: *mut bindings::socket,
    after: impl FnOnce(&Sock<T>),
) -> ffi::c_int {
    // SAFETY: called by the socket layer on close, once (our contract).
    let Some(sk) = (unsafe { sock_of::<T>(sock) }) else {
        return 0;
    };
    T::release(&sk);
    after(&sk);
    // Orphan the sock, detach it from the socket and drop the socket's
    // reference. This does not rest on what `T::release` did: every other
    // holder of the sock has a reference of its own (a subscription's
    // `sock_hold`, a `SockRef`), and the borrows lent to `T::release` and
    // `after` have ended; an orphaned sock stays valid for those holders,
    // as for mainline's.
    // SAFETY: the socket layer's release call, once (our contract): the
    // socket's own reference on `sk` is the one dropped here.
    unsafe {
        bindings::rcan_sock_orphan(sk.as_ptr());
        (*sock).sk = core::ptr::null_mut();
        bindings::rcan_sock_put(sk.as_ptr());
    }
    0
}

/// # Safety
///
/// `addr` points to `len` readable bytes (a kernel copy made by the socket
/// layer) or is NULL.
unsafe fn addr_slice<'a>(addr: *mut bindings::sockaddr, len: ffi::c_int) -> &'a [u8] {
    if addr.is_null() || len <= 0 {
        return &[];
    }
    // SAFETY: per the contract; the socket layer caps len at
    // sizeof(struct sockaddr_storage).
    unsafe { core::slice::from_raw_parts(addr as *const u8, (len as usize).min(128)) }
}

unsafe extern "C" fn bind<T: Proto>(
    sock: *mut bindings::socket,
    addr: *mut bindings::sockaddr,
    len: ffi::c_int,
) -> ffi::c_int {
    // SAFETY: socket-layer call with a kernel copy of the address.
    let (sk, a) = unsafe { (sock_of::<T>(sock), addr_slice(addr, len)) };
    match sk {
        Some(sk) => ret(T::bind(&sk, a)),
        None => code::EBADF.to_errno(),
    }
}

unsafe extern "C" fn connect<T: Proto>(
    sock: *mut bindings::socket,
    addr: *mut bindings::sockaddr,
    len: ffi::c_int,
    flags: ffi::c_int,
) -> ffi::c_int {
    // SAFETY: as in bind.
    let (sk, a) = unsafe { (sock_of::<T>(sock), addr_slice(addr, len)) };
    match sk {
        Some(sk) => ret(T::connect(&sk, a, flags)),
        None => code::EBADF.to_errno(),
    }
}

/// `proto_ops::getname`. Process context.
///
/// # Safety
///
/// Called by the socket layer: `sock` is a socket of protocol `T`, `addr`
/// a kernel `struct sockaddr` the caller lets us fill.
unsafe extern "C" fn getname<T: Proto>(
    sock: *mut bindings::socket,
    addr: *mut bindings::sockaddr,
    peer: ffi::c_int,
) -> ffi::c_int {
    // `addr` is typed `struct sockaddr *`, so the caller gives at least
    // that much: the socket layer (`__sys_getsockname`, `__sys_getpeername`,
    // `SO_PEERNAME`) a `sockaddr_storage`, the in-kernel
    // `kernel_getsockname`/`kernel_getpeername` an "address holder" of the
    // caller's choice. `NAME_ROOM` bytes of it are all we rely on (every
    // address of ours fits; mainline's PF_CAN protocols write up to 24),
    // or `SOCKADDR_CAN_ROOM` for a protocol with `SOCKADDR_CAN_NAMES`
    // (the argument at that constant).
    let room = name_room::<T>();
    // They may be uninitialised (a buffer on the caller's stack): zeroed
    // first, so the slice below covers initialised bytes.
    // SAFETY: so `addr` is valid for `room` bytes of writes, and
    // nothing else uses it during the call.
    let out = unsafe {
        core::ptr::write_bytes(addr.cast::<u8>(), 0, room);
        core::slice::from_raw_parts_mut(addr.cast::<u8>(), room)
    };
    // SAFETY: socket-layer call.
    match unsafe { sock_of::<T>(sock) } {
        // The length is what the caller copies out of `addr`
        // (`move_addr_to_user`, which BUG()s above a sockaddr_storage):
        // never more than we let the protocol write.
        Some(sk) => match T::getname(&sk, peer != 0, out) {
            Ok(n) if n <= room => n as ffi::c_int,
            Ok(_) => code::EINVAL.to_errno(),
            Err(e) => e.to_errno(),
        },
        None => code::EBADF.to_errno(),
    }
}

unsafe extern "C" fn sendmsg<T: Proto>(
    sock: *mut bindings::socket,
    msg: *mut bindings::msghdr,
    len: usize,
) -> ffi::c_int {
    let mut m = Msg(msg, name_room::<T>());
    // SAFETY: socket-layer call.
    match unsafe { sock_of::<T>(sock) } {
        Some(sk) => match T::sendmsg(&sk, &mut m, len) {
            Ok(n) => n as ffi::c_int,
            Err(e) => e.to_errno(),
        },
        None => code::EBADF.to_errno(),
    }
}

unsafe extern "C" fn recvmsg<T: Proto>(
    sock: *mut bindings::socket,
    msg: *mut bindings::msghdr,
    len: usize,
    flags: ffi::c_int,
) -> ffi::c_int {
    let mut m = Msg(msg, name_room::<T>());
    // SAFETY: socket-layer call.
    match unsafe { sock_of::<T>(sock) } {
        Some(sk) => match T::recvmsg(&sk, &mut m, len, flags) {
            Ok(n) => n as ffi::c_int,
            Err(e) => e.to_errno(),
        },
        None => code::EBADF.to_errno(),
    }
}

/// `proto_ops::poll` of a protocol with [`Proto::HAS_WRITABLE`]:
/// `datagram_poll` (which registers on the socket's wait queue, where
/// [`Sock::wake_writers`] wakes), then `EPOLLOUT` withheld while
/// [`Proto::writable`] says no (mainline `isotp_poll`).
///
/// # Safety
///
/// Called by the socket layer with its `file`, `sock` (of protocol `T`)
/// and `wait`.
unsafe extern "C" fn poll<T: Proto>(
    file: *mut bindings::file,
    sock: *mut bindings::socket,
    wait: *mut bindings::poll_table_struct,
) -> bindings::__poll_t {
    // SAFETY: the socket layer's arguments, passed on unchanged.
    let mask = unsafe { bindings::datagram_poll(file, sock, wait) };
    // EPOLLOUT | EPOLLWRNORM | EPOLLWRBAND (<uapi/linux/eventpoll.h>;
    // bindgen cannot evaluate their `__poll_t` casts).
    const OUT: bindings::__poll_t = 0x004 | 0x100 | 0x200;
    if mask & OUT == 0 {
        return mask;
    }
    // SAFETY: socket-layer call.
    match unsafe { sock_of::<T>(sock) } {
        Some(sk) if !T::writable(&sk) => mask & !OUT,
        _ => mask,
    }
}

/// Lets the socket layer fall back to the generic device ioctls.
unsafe extern "C" fn no_ioctl(
    _sock: *mut bindings::socket,
    _cmd: ffi::c_uint,
    _arg: ffi::c_ulong,
) -> ffi::c_int {
    -(bindings::ENOIOCTLCMD as ffi::c_int)
}

unsafe extern "C" fn setsockopt<T: Proto>(
    sock: *mut bindings::socket,
    level: ffi::c_int,
    name: ffi::c_int,
    val: bindings::sockptr_t,
    len: ffi::c_uint,
) -> ffi::c_int {
    let opt = OptIn {
        val,
        len: len as usize,
    };
    // SAFETY: socket-layer call.
    match unsafe { sock_of::<T>(sock) } {
        Some(sk) => ret(T::setsockopt(&sk, level, name, &opt)),
        None => code::EBADF.to_errno(),
    }
}

unsafe extern "C" fn getsockopt<T: Proto>(
    sock: *mut bindings::socket,
    level: ffi::c_int,
    name: ffi::c_int,
    val: *mut ffi::c_char,
    len: *mut ffi::c_int,
) -> ffi::c_int {
    // INVARIANT: `optval` and `optlen` of this call, `*optlen` not read yet.
    let opt = OptOut {
        val,
        len,
        first: core::cell::Cell::new(None),
    };
    // SAFETY: socket-layer call; `val` and `len` are user pointers that
    // OptOut only passes to the uaccess helpers.
    match unsafe { sock_of::<T>(sock) } {
        Some(sk) => ret(T::getsockopt(&sk, level, name, &opt)),
        None => code::EBADF.to_errno(),
    }
}
