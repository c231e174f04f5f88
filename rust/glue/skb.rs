// SPDX-License-Identifier: GPL-2.0

//! Owned socket buffers, typed by what their holder may do with them.
//!
//! An [`Skb`] owns one reference to a `struct sk_buff`. Dropping it is
//! `kfree_skb` (counted as a drop); [`Skb::consume`] frees it as
//! successfully used. CAN skbs are linear (allocated by rcan or by drivers
//! with the data in the head), so [`Skb::data`] covers the whole frame.
//!
//! # Ownership (issue 39)
//!
//! An skb may have several holders: other references (`skb_get`, a
//! MSG_PEEKed skb still on its queue: `skb_shared`) and clones (`skb_clone`:
//! a second `sk_buff` sharing the data buffer: `skb_cloned`). The C rule is
//! mainline's: the `sk_buff`'s own fields (headers, `cb`, `dev`, `tstamp`,
//! owner) are written only by its sole holder (`skb_share_check`), the data
//! only by the sole holder of an uncloned skb (`skb_unshare`). Here the rule
//! is the type parameter, so safe code cannot write what others read:
//!
//! * [`Skb`] (`Skb<Shared>`): a reference any holder may keep (a clone, a
//!   borrowed or peeked skb); reads only (`&[u8]`), clones.
//! * [`OwnedSkb`] (`Skb<Owned>`): the only reference to its `sk_buff`
//!   (`users == 1`); may be a clone, so its data stays read-only, but its
//!   own fields (CAN marking, `cb`, timestamp, owner socket) are writable.
//!   What a receiver queues ([`RxSkb::into_owned`](super::can::proto::RxSkb))
//!   and a driver keeps for the echo.
//! * [`UniqueSkb`] (`Skb<Unique>`): an [`OwnedSkb`] whose data no clone
//!   shares: every write. What the allocators return; cloning it is not
//!   offered (it would share the data), it first becomes an [`OwnedSkb`].
//!
//! Down the list is free ([`Skb::into_shared`], [`UniqueSkb::into_owned`]);
//! up the list is checked, never assumed: [`Skb::try_into_owned`] (no
//! copy), [`Skb::share_check`] (clones if shared), [`Skb::unshare`]
//! (copies if shared or cloned).
//!
//! # The device (`skb->dev`)
//!
//! No safe function reads `skb->dev` from an skb: a kept skb may outlive
//! its device. The device comes from a context that holds it: the receive
//! callback's [`RxSkb::dev`](super::can::proto::RxSkb::dev) and
//! [`KernelRx::rx`](super::can::proto::KernelRx)'s `dev`, a driver's
//! transmit or poll callback. Nor does a safe function store it to be
//! kept: `skb->dev` is written by the functions that hand the skb to the
//! kernel in the same call ([`NetDev::rx`](super::netdev::NetDev::rx),
//! [`Napi::receive`](super::netdev::Napi::receive), the CAN send and
//! transmit paths), from a device borrowed for that call; from there the
//! kernel's own rules keep the device alive while the skb uses it (the
//! transmit path holds it, unregistering flushes the backlogs). So no skb
//! reaches the kernel with a stale or NULL `dev`.

use super::bindings;
use core::marker::PhantomData;
use core::ptr::NonNull;

mod sealed {
    pub(crate) trait Sealed {}
}

/// What the holder of an [`Skb`] may do: [`Shared`], [`Owned`] or
/// [`Unique`]. Sealed: only this file names the rules.
pub(crate) trait Access: sealed::Sealed {}
/// Holders that may write the `sk_buff`'s own fields: [`Owned`], [`Unique`].
pub(crate) trait Exclusive: Access {}
/// Holders that may clone: [`Shared`], [`Owned`] (not [`Unique`], whose
/// data would then be shared).
pub(crate) trait Clonable: Access {}

/// Any reference: read only.
pub(crate) enum Shared {}
/// The only reference to the `sk_buff` (`!skb_shared`).
pub(crate) enum Owned {}
/// The only reference, data not shared with a clone (`!skb_shared &&
/// !skb_cloned`).
pub(crate) enum Unique {}

impl sealed::Sealed for Shared {}
impl sealed::Sealed for Owned {}
impl sealed::Sealed for Unique {}
impl Access for Shared {}
impl Access for Owned {}
impl Access for Unique {}
impl Exclusive for Owned {}
impl Exclusive for Unique {}
impl Clonable for Shared {}
impl Clonable for Owned {}

/// The only reference to its `sk_buff`: fields writable, data read-only.
pub(crate) type OwnedSkb = Skb<Owned>;
/// The only reference, data not cloned: everything writable.
pub(crate) type UniqueSkb = Skb<Unique>;

/// An owned reference to a socket buffer, with what its holder may do
/// with it in `A` (see the module documentation).
///
/// # Invariants
///
/// `self.0` points to a valid `sk_buff` on which we own one reference.
/// If `A` is [`Owned`] or [`Unique`], that reference is the only one
/// (`users == 1`), so nobody else reads or writes the `sk_buff`'s fields;
/// if `A` is [`Unique`], the data buffer is not shared with a clone
/// either (`!skb_cloned`), so nobody else reads it. Only references made
/// from this one can change that, and this type makes none for a
/// [`Unique`] skb (no clone, no `skb_get`).
#[repr(transparent)]
pub(crate) struct Skb<A: Access = Shared>(NonNull<bindings::sk_buff>, PhantomData<A>);

// SAFETY: an skb reference may be handed between contexts and CPUs; the
// kernel does so on every path (softirq to process context, etc.). The
// access rule `A` moves with the reference.
unsafe impl<A: Access> Send for Skb<A> {}

/// What every holder may do: read, give the reference away or free it,
/// and move down or (checked) up the ownership ladder.
impl<A: Access> Skb<A> {
    /// Takes ownership of one reference.
    ///
    /// # Safety
    ///
    /// `ptr` is NULL or a valid skb whose reference the caller gives away;
    /// with `A` = [`Owned`] that reference is the only one (`users == 1`),
    /// with `A` = [`Unique`] the skb is moreover not cloned (the type
    /// invariant).
    pub(crate) unsafe fn from_raw(ptr: *mut bindings::sk_buff) -> Option<Skb<A>> {
        // INVARIANT: non-NULL and owned (and as exclusive as `A` says) per
        // the safety contract.
        NonNull::new(ptr).map(|p| Skb(p, PhantomData))
    }

    /// Gives up our reference as the skb's address (exposed, never 0):
    /// what a slot of a lock-free queue holds ([`super::ring::SkbRing`]).
    /// [`Skb::from_addr`] takes it back.
    #[inline]
    pub(crate) fn into_addr(self) -> core::num::NonZeroUsize {
        let a = self.0.expose_provenance();
        core::mem::forget(self);
        a
    }

    /// Takes back the reference [`Skb::into_addr`] gave up.
    ///
    /// # Safety
    ///
    /// `addr` came from [`Skb::into_addr`] of an `Skb<A>` (the same `A`)
    /// and is taken back once.
    #[inline]
    pub(crate) unsafe fn from_addr(addr: core::num::NonZeroUsize) -> Skb<A> {
        // INVARIANT: the address of an skb whose reference an `Skb<A>`'s
        // `into_addr` gave up, taken back once (the safety contract); what
        // held for `A` then holds now: nothing could reach the skb meanwhile.
        Skb(NonNull::with_exposed_provenance(addr), PhantomData)
    }

    /// Gives the reference away (to a C function that consumes it).
    pub(crate) fn into_raw(self) -> *mut bindings::sk_buff {
        let p = self.0.as_ptr();
        core::mem::forget(self);
        p
    }

    pub(crate) fn as_ptr(&self) -> *mut bindings::sk_buff {
        self.0.as_ptr()
    }

    /// The pointer, our reference in it, without running `Drop`: for a
    /// new `Skb` of another access type.
    #[inline(always)]
    fn into_nonnull(self) -> NonNull<bindings::sk_buff> {
        let p = self.0;
        core::mem::forget(self);
        p
    }

    /// Forgets what the holder may write: a reference like any other.
    #[inline]
    pub(crate) fn into_shared(self) -> Skb {
        // INVARIANT: the same owned reference; `Shared` claims nothing more.
        Skb(self.into_nonnull(), PhantomData)
    }

    /// Bytes in the skb.
    #[inline]
    pub(crate) fn len(&self) -> u32 {
        // SAFETY: valid skb by the type invariant.
        unsafe { (*self.as_ptr()).len }
    }

    /// The linear data (the whole skb for the linear skbs CAN uses).
    #[inline]
    pub(crate) fn data(&self) -> &[u8] {
        // Nobody writes these bytes meanwhile: a writer needs a
        // `UniqueSkb`, the only reference to an uncloned skb, so while we
        // hold ours there is none (and if we are that one, `&self` excludes
        // `&mut self`).
        // SAFETY: `data` points to `len - data_len` readable bytes (the
        // linear part), valid while we hold the reference (`&self`).
        unsafe {
            let skb = &*self.as_ptr();
            let head_len = (skb.len - skb.data_len) as usize;
            if head_len == 0 {
                return &[];
            }
            core::slice::from_raw_parts(skb.data, head_len)
        }
    }

    /// Headroom in front of `data` (`skb_headroom`).
    #[inline]
    pub(crate) fn headroom(&self) -> u32 {
        // SAFETY: valid skb; `data` and `head` point into its one head
        // buffer, `data` not in front of `head`, less than 4 GiB apart.
        unsafe { (*self.as_ptr()).data.offset_from((*self.as_ptr()).head) as u32 }
    }

    /// The ethertype of the CAN frame the skb holds, told by its length as
    /// mainline tells it (`can_send`): ETH_P_CANFD for a 72-byte
    /// `struct canfd_frame`, ETH_P_CAN otherwise.
    pub(crate) fn can_eth_p(&self) -> u16 {
        if self.len() as usize == crate::rcan_core::frame::CANFD_MTU {
            bindings::ETH_P_CANFD as u16
        } else {
            bindings::ETH_P_CAN as u16
        }
    }

    /// Whether the sender asked for the frame to be echoed to local
    /// receivers (`PACKET_LOOPBACK`, set by `rcan_send` or
    /// [`Skb::can_xmit_start`]). For an IFF_ECHO driver's transmit path.
    pub(crate) fn wants_echo(&self) -> bool {
        self.pkt_type() == bindings::PACKET_LOOPBACK as u8
    }

    /// Whether someone else holds a reference too (`skb_shared`). Read
    /// here rather than through a C helper: it is on every frame's path.
    #[inline]
    fn is_shared(&self) -> bool {
        // `users` is a refcount_t, read as refcount_read does (one volatile
        // load of the counter, READ_ONCE).
        // SAFETY: valid skb by the type invariant; read through a raw place,
        // so no reference to a field that other CPUs change is made.
        let users = unsafe {
            core::ptr::read_volatile(core::ptr::addr_of!((*self.as_ptr()).users.refs.counter))
        };
        users != 1
    }

    /// The same reference as an [`OwnedSkb`] if it is the only one
    /// (`!skb_shared`), else back unchanged. Any context; copies nothing.
    #[inline]
    pub(crate) fn try_into_owned(self) -> Result<OwnedSkb, Self> {
        if self.is_shared() {
            return Err(self);
        }
        // INVARIANT: the only reference (just checked); no other can
        // appear, since making one needs a reference (ours is the only)
        // and this type makes none without the caller.
        Ok(Skb(self.into_nonnull(), PhantomData))
    }

    /// `skb_share_check(GFP_ATOMIC)`: this reference if it is the only
    /// one, else a clone of its own (the original reference is released).
    /// `None` without memory (the skb is then freed). Any context.
    #[inline]
    pub(crate) fn share_check(self) -> Option<OwnedSkb> {
        match self.try_into_owned() {
            Ok(o) => Some(o),
            Err(s) => {
                // SAFETY: valid skb; skb_clone returns a new reference or
                // NULL; a fresh clone's `sk_buff` has one user (ours).
                let c = unsafe {
                    Skb::<Owned>::from_raw(bindings::skb_clone(s.as_ptr(), super::GFP_ATOMIC))
                };
                s.consume();
                c
            }
        }
    }

    /// `skb_unshare` for a writer (GFP_ATOMIC): this reference if it is
    /// the only one and the data is not cloned, else a private copy (the
    /// sending socket kept, `can_skb_set_owner`) and the original released.
    /// `None` without memory (the skb is then freed). Any context.
    pub(crate) fn unshare(self) -> Option<UniqueSkb> {
        // SAFETY: we give our reference to the helper, which returns it
        // if it is the only one and the skb is not cloned, else releases
        // it and returns a fresh copy (one user, not cloned) or NULL.
        unsafe { Skb::from_raw(bindings::rcan_skb_unshare(self.into_raw(), super::GFP_ATOMIC)) }
    }

    /// The socket that sent the skb (`skb->sk`), for identity comparisons
    /// only; NULL for frames from the bus.
    #[inline]
    fn sk_ptr(&self) -> *mut bindings::sock {
        // SAFETY: valid skb; reading a pointer field.
        unsafe { (*self.as_ptr()).sk }
    }

    /// Whether the frame was sent from this host (`skb->sk` set: an echo
    /// of a local socket's frame); false for frames from the bus. Any
    /// context.
    #[inline]
    pub(crate) fn is_local(&self) -> bool {
        !self.sk_ptr().is_null()
    }

    /// Whether socket `sk` sent this frame (`skb->sk == sk`), by identity;
    /// the socket is not dereferenced. Any context.
    #[inline]
    pub(crate) fn sent_by<T: super::sock::Proto>(&self, sk: &super::sock::SockView<T>) -> bool {
        core::ptr::eq(self.sk_ptr(), sk.as_ptr())
    }

    /// `skb->dev` (NULL if none), read in place.
    #[inline]
    fn dev_ptr(&self) -> *mut bindings::net_device {
        // `dev` shares a union with `dev_scratch` (UDP's, on its own
        // receive queue) and `rbnode` (skbs in an rbtree: TCP, defrag,
        // netem); neither holds on an skb handed to us.
        // SAFETY: valid skb by the type invariant; the union holds `dev`
        // (above), the bytes C's `skb->dev` reads.
        unsafe {
            (*self.as_ptr())
                .__bindgen_anon_1
                .__bindgen_anon_1
                .__bindgen_anon_1
                .dev
        }
    }

    /// The device in `skb->dev`. Not for safe code: a kept skb may outlive
    /// its device (the module documentation); the glue's receive
    /// trampolines lend it to their callbacks for the call.
    ///
    /// # Safety
    ///
    /// `skb->dev` is NULL or a device the caller keeps alive (holds a
    /// reference, or runs in the receive or transmit path of that device)
    /// for `'a`.
    pub(crate) unsafe fn dev<'a>(&self) -> Option<&'a super::netdev::NetDev> {
        // SAFETY: valid skb; the device's lifetime per the contract.
        unsafe {
            let dev = self.dev_ptr();
            if dev.is_null() {
                None
            } else {
                Some(super::netdev::NetDev::from_raw(dev))
            }
        }
    }

    /// The receive timestamp (`skb->tstamp`, ns; 0: none).
    pub(crate) fn tstamp(&self) -> i64 {
        // SAFETY: valid skb.
        unsafe { bindings::rcan_skb_tstamp(self.as_ptr()) }
    }

    /// `ntohs(skb->protocol)`.
    #[inline]
    pub(crate) fn protocol(&self) -> u16 {
        // SAFETY: valid skb; reading a header field of an skb we hold
        // (only the sole holder writes it: see `pkt_type`).
        u16::from_be(unsafe {
            (*self.as_ptr())
                .__bindgen_anon_4
                .__bindgen_anon_1
                .as_ref()
                .protocol
        })
    }

    /// `skb->pkt_type` (PACKET_HOST, PACKET_LOOPBACK, ...). Read here
    /// rather than through a C helper: drivers ask on every frame.
    #[inline]
    pub(crate) fn pkt_type(&self) -> u8 {
        // The bitfield lives in the skb's header group, a union whose
        // anonymous-struct view bindgen generated from the kernel's layout.
        // SAFETY: valid skb by the type invariant, and we hold a reference;
        // only the sole holder (an `Exclusive` skb: us, if anyone) writes
        // its header fields.
        unsafe {
            (*self.as_ptr())
                .__bindgen_anon_4
                .__bindgen_anon_1
                .as_ref()
                .pkt_type()
        }
    }

    /// The first bytes of the 48-byte control buffer, owned by whoever queues
    /// the skb (rcan protocols store the receive ifindex there).
    pub(crate) fn cb_u32(&self, idx: usize) -> u32 {
        // SAFETY: valid skb; cb is a 48-byte array, idx bounded below.
        unsafe {
            let cb = &(*self.as_ptr()).cb;
            let i = idx.min(cb.len() / 4 - 1) * 4;
            u32::from_ne_bytes([
                cb[i] as u8,
                cb[i + 1] as u8,
                cb[i + 2] as u8,
                cb[i + 3] as u8,
            ])
        }
    }

    /// Reads `dst.len()` bytes of the control buffer from `off` (bytes
    /// beyond its 48 are left as they are).
    #[inline]
    pub(crate) fn cb_read(&self, off: usize, dst: &mut [u8]) {
        // SAFETY: valid skb; the copy is clamped to the 48-byte cb.
        unsafe {
            let cb = &(*self.as_ptr()).cb;
            let n = dst.len().min(cb.len().saturating_sub(off));
            core::ptr::copy_nonoverlapping(cb.as_ptr().add(off).cast::<u8>(), dst.as_mut_ptr(), n);
        }
    }

    /// Frees as dropped from any context, including hardirq and code
    /// holding an interrupt-disabling lock (`dev_kfree_skb_any`: there the
    /// free, and the skb's destructor, is deferred to softirq).
    pub(crate) fn drop_any(self) {
        // SAFETY: we own the reference and give it up.
        unsafe { bindings::rcan_dev_kfree_skb_any(self.into_raw()) };
    }

    /// Frees as successfully consumed (not a drop in drop monitors).
    pub(crate) fn consume(self) {
        // SAFETY: we own the reference and give it up.
        unsafe { bindings::rcan_consume_skb(self.into_raw()) };
    }

    /// [`Skb::consume`] from any context, like [`Skb::drop_any`]: in
    /// hardirq or with interrupts off the free (and the destructor) is
    /// deferred to softirq (`dev_consume_skb_any`).
    pub(crate) fn consume_any(self) {
        // SAFETY: we own the reference and give it up.
        unsafe { bindings::rcan_dev_consume_skb_any(self.into_raw()) };
    }
}

/// What a holder that may clone may do: clone ([`Shared`], [`Owned`]).
impl<A: Clonable> Skb<A> {
    /// `skb_clone(GFP_ATOMIC)`: a new head sharing the data (so both are
    /// cloned from then on: their data is read-only). Any context.
    pub(crate) fn clone_atomic(&self) -> Option<OwnedSkb> {
        // SAFETY: valid skb; skb_clone returns a new owned reference or
        // NULL, to a new `sk_buff` whose one user is us (`Owned`).
        unsafe { Skb::from_raw(bindings::skb_clone(self.as_ptr(), super::GFP_ATOMIC)) }
    }

    /// `skb_clone` keeping the sending socket (`can_skb_set_owner`, holds a
    /// reference on it): the copy a CAN device without IFF_ECHO loops back
    /// still tells receivers who sent it. Any context.
    pub(crate) fn clone_with_owner(&self) -> Option<OwnedSkb> {
        // SAFETY: valid skb; the helper clones it and, if the original has
        // an owner socket (kept alive by the original's reference), takes a
        // reference on it for the clone; a fresh clone has one user.
        unsafe {
            Skb::from_raw(bindings::rcan_skb_clone_owned(
                self.as_ptr(),
                super::GFP_ATOMIC,
            ))
        }
    }
}

impl OwnedSkb {
    /// The same skb seen as a [`Skb`], for code that takes any frame: a
    /// `Shared` view permits reading and cloning, which an `Owned` skb
    /// permits too.
    #[inline(always)]
    pub(crate) fn as_shared(&self) -> &Skb {
        // SAFETY: `Skb<A>` is `repr(transparent)` over the same pointer
        // (`PhantomData` is zero-sized), so the layouts are the same; the
        // view's rule (read, clone) asks less than ours.
        unsafe { &*(self as *const OwnedSkb).cast::<Skb>() }
    }
}

/// What the sole holder of an `sk_buff` may do: write its own fields
/// (not the data, which a clone may share).
impl<A: Exclusive> Skb<A> {
    /// Marks the skb as a CAN frame leaving by `dev` (mainline `can_send`):
    /// protocol ETH_P_CAN or ETH_P_CANFD ([`Skb::can_eth_p`]), headers
    /// reset, `CHECKSUM_UNNECESSARY` (built by the CAN stack, not by a
    /// packet socket), and `PACKET_LOOPBACK` if the sender asks for the
    /// echo ([`Skb::wants_echo`]), else `PACKET_HOST`. `skb->dev` is set
    /// by the transmit hand-off (the module documentation).
    #[inline]
    pub(crate) fn set_can_tx(&mut self, loopback: bool) {
        let pkt_type = if loopback {
            bindings::PACKET_LOOPBACK
        } else {
            bindings::PACKET_HOST
        };
        self.mark_can(pkt_type as u8);
    }

    /// Marks the skb as a CAN frame arriving, as mainline marks bus frames
    /// (`alloc_can_skb`) and echoes (`__can_get_echo_skb`, `vcan_rx`):
    /// `PACKET_BROADCAST`, `CHECKSUM_UNNECESSARY`, protocol ETH_P_CAN or
    /// ETH_P_CANFD ([`Skb::can_eth_p`]), headers reset. `skb->sk` is kept:
    /// an echo still names its sending socket, which is how protocols tell
    /// their own frames. `skb->dev` is set by the hand-off
    /// ([`NetDev::rx`](super::netdev::NetDev::rx),
    /// [`Napi::receive`](super::netdev::Napi::receive)).
    #[inline]
    pub(crate) fn set_can_rx(&mut self) {
        self.mark_can(bindings::PACKET_BROADCAST as u8);
    }

    /// [`Skb::set_can_tx`] and [`Skb::set_can_rx`]: the protocol,
    /// `pkt_type`, `CHECKSUM_UNNECESSARY` and the mac, network and
    /// transport headers reset to the data (`skb_reset_mac_header` and its
    /// twins), written here rather than by a C helper: every frame is
    /// marked once on the way out and once on the way in.
    #[inline]
    fn mark_can(&mut self, pkt_type: u8) {
        let eth_p = self.can_eth_p();
        let skb = self.as_ptr();
        // `data` and `head` point into the same buffer, `data` at most 64
        // KiB past `head` (the kernel's own `u16` header offsets rely on
        // that).
        // SAFETY: the skb is valid and ours alone (type invariant,
        // `Exclusive`; `&mut self`): nobody else touches these fields.
        unsafe {
            let off = (*skb).data.offset_from((*skb).head) as u16;
            let h = (*skb).__bindgen_anon_4.__bindgen_anon_1.as_mut();
            h.protocol = eth_p.to_be();
            h.set_pkt_type(pkt_type);
            h.set_ip_summed(bindings::CHECKSUM_UNNECESSARY as u8);
            h.mac_header = off;
            h.network_header = off;
            h.transport_header = off;
        }
    }

    /// Sets `skb->dev`, for the glue's hand-offs (the module
    /// documentation).
    ///
    /// # Safety
    ///
    /// The caller hands the skb to the kernel (which keeps `dev` alive
    /// while the skb uses it) before `dev`'s borrow ends, and reads
    /// nothing through `skb->dev` meanwhile: the pointer is never kept in
    /// an skb that safe code holds.
    #[inline]
    pub(crate) unsafe fn set_dev(&mut self, dev: &super::netdev::NetDev) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`); `dev`
        // is a live device (NetDev invariant); how long the pointer is
        // used is the caller's contract.
        unsafe {
            (*self.as_ptr())
                .__bindgen_anon_1
                .__bindgen_anon_1
                .__bindgen_anon_1
                .dev = dev.as_ptr()
        };
    }

    /// Copies the socket's priority and mark into the skb, as every
    /// protocol's sendmsg does for the qdisc layer.
    #[inline]
    pub(crate) fn set_sock_params<T: super::sock::Proto>(&mut self, sk: &super::sock::SockView<T>) {
        // READ_ONCE of the two socket fields (setsockopt writes them
        // without the caller's knowledge), as the kernel's sendmsg paths
        // read them; written here rather than by a C helper, once a frame.
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`); `sk`
        // is a live sock: a `Sock` is only made for a sock the caller holds
        // (a system call's own socket).
        unsafe {
            let sk = sk.as_ptr();
            let priority = core::ptr::read_volatile(core::ptr::addr_of!((*sk).sk_priority));
            let mark = core::ptr::read_volatile(core::ptr::addr_of!((*sk).sk_mark));
            let h = (*self.as_ptr()).__bindgen_anon_4.__bindgen_anon_1.as_mut();
            h.priority = priority;
            h.__bindgen_anon_4.mark = mark;
        }
    }

    /// Makes `sk` the skb's owner the way mainline's `can_skb_set_owner`
    /// does (a counted reference, released by `sock_efree` when the skb
    /// is freed; no send-buffer accounting), so that receivers see which
    /// socket sent the frame. For frames sent outside a system call (timer
    /// callbacks); an skb that has an owner keeps it. Any context.
    pub(crate) fn set_owner<T: super::sock::Proto>(&mut self, sk: &super::sock::SockView<T>) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`); `sk` is
        // a live sock (Sock invariant), on which we take the reference that
        // sock_efree drops.
        unsafe {
            let skb = &mut *self.as_ptr();
            if !skb.sk.is_null() || skb.__bindgen_anon_3.__bindgen_anon_1.destructor.is_some() {
                return;
            }
            bindings::rcan_sock_hold(sk.as_ptr());
            skb.sk = sk.as_ptr();
            skb.__bindgen_anon_3.__bindgen_anon_1.destructor = Some(bindings::sock_efree);
        }
    }

    /// Writes `src` into the control buffer at `off` (clamped to its 48
    /// bytes).
    #[inline]
    pub(crate) fn cb_write(&mut self, off: usize, src: &[u8]) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`); the
        // copy is clamped to the 48-byte cb.
        unsafe {
            let cb = &mut (*self.as_ptr()).cb;
            let n = src.len().min(cb.len().saturating_sub(off));
            core::ptr::copy_nonoverlapping(src.as_ptr(), cb.as_mut_ptr().add(off).cast::<u8>(), n);
        }
    }

    /// Writes the `idx`th `u32` of the control buffer (clamped to its 48
    /// bytes).
    pub(crate) fn set_cb_u32(&mut self, idx: usize, v: u32) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`); cb
        // bounds as in `cb_u32`.
        unsafe {
            let cb = &mut (*self.as_ptr()).cb;
            let i = idx.min(cb.len() / 4 - 1) * 4;
            for (k, b) in v.to_ne_bytes().iter().enumerate() {
                cb[i + k] = *b as _;
            }
        }
    }

    /// Sets the receive timestamp (`__net_timestamp`) unless one is set,
    /// as the core's receive path does.
    pub(crate) fn stamp_if_unset(&mut self) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`).
        unsafe { bindings::rcan_skb_stamp_if_unset(self.as_ptr()) };
    }

    /// Sets `skb->tstamp` (ns; 0: none), as a protocol does that hands
    /// user space a frame's receive time in a message of its own
    /// (SO_TIMESTAMP and friends report it).
    pub(crate) fn set_tstamp(&mut self, ns: i64) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`).
        unsafe { bindings::rcan_skb_set_tstamp(self.as_ptr(), ns) };
    }

    /// Marks the skb, which starts with an IPv4 header followed by a
    /// transport header, as an IPv4 packet received with a verified
    /// checksum (`skb->dev` is set by [`NetDev::rx`](super::netdev::NetDev::rx)).
    pub(crate) fn set_ipv4_rx(&mut self) {
        // SAFETY: valid skb, ours alone (`Exclusive`, `&mut self`); the
        // helper writes header fields only.
        unsafe { bindings::rcan_skb_set_ipv4_rx(self.as_ptr()) };
    }
}

/// What the holder of an skb nobody else reads may do: write its data.
impl UniqueSkb {
    /// Allocates a linear skb. Any context with the matching `gfp`.
    pub(crate) fn alloc(size: u32, gfp: bindings::gfp_t) -> Option<UniqueSkb> {
        // SAFETY: plain allocation, NULL on failure; a fresh skb has one
        // user and is not cloned.
        unsafe { Skb::from_raw(bindings::rcan_alloc_skb(size, gfp)) }
    }

    /// Gives up writing the data (to clone, or to keep beside a clone):
    /// the `sk_buff` stays ours alone.
    #[inline]
    pub(crate) fn into_owned(self) -> OwnedSkb {
        // INVARIANT: `Owned` claims less than `Unique`.
        Skb(self.into_nonnull(), PhantomData)
    }

    /// Reserves headroom in an empty skb.
    ///
    /// Only on an empty linear skb with at least `len` bytes of tailroom
    /// (a fresh one); anything else is left as it is (`skb_reserve` itself
    /// does not check), so the caller's later headroom test fails instead.
    #[inline]
    pub(crate) fn reserve(&mut self, len: u32) {
        // `skb_reserve` (data and tail move by `len`), written here rather
        // than by a C helper, with the bounds it leaves to its callers
        // checked first: data and tail stay inside the head.
        // SAFETY: valid skb, ours alone and not cloned (`Unique`, `&mut
        // self`: nobody else moves its data meanwhile); the bounds are
        // checked before anything moves.
        unsafe {
            let skb = &mut *self.as_ptr();
            if skb.len != 0 || skb.data_len != 0 || len > skb.end.saturating_sub(skb.tail) {
                return;
            }
            skb.data = skb.data.add(len as usize);
            skb.tail += len;
        }
    }

    /// Appends `src` (skb_put + copy); false (nothing appended) if the
    /// skb is not linear or its tailroom is too small.
    pub(crate) fn put_data(&mut self, src: &[u8]) -> bool {
        // SAFETY: valid skb; reading the tail/end offsets.
        let tailroom = unsafe {
            let skb = &*self.as_ptr();
            if skb.data_len != 0 {
                return false;
            }
            skb.end.saturating_sub(skb.tail)
        };
        if (src.len() as u64) > u64::from(tailroom) {
            return false;
        }
        // SAFETY: tailroom checked above; skb_put returns a pointer to
        // `src.len()` writable bytes inside the head, which nobody else
        // reads (`Unique`: no other reference, no clone).
        unsafe {
            let dst = bindings::skb_put(self.as_ptr(), src.len() as u32) as *mut u8;
            core::ptr::copy_nonoverlapping(src.as_ptr(), dst, src.len());
        }
        true
    }

    /// Writes `src` into the headroom just in front of `data` (for
    /// `struct can_skb_priv`); false if the headroom is too small.
    #[inline]
    pub(crate) fn write_headroom(&mut self, src: &[u8]) -> bool {
        if (src.len() as u64) > u64::from(self.headroom()) {
            return false;
        }
        // SAFETY: headroom checked; the bytes in front of `data` belong to
        // this skb's head, which nobody else reads (`Unique`).
        unsafe {
            let data = (*self.as_ptr()).data;
            core::ptr::copy_nonoverlapping(src.as_ptr(), data.sub(src.len()), src.len());
        }
        true
    }

    /// Appends `len` bytes copied from the user's buffers of `msg`
    /// (`skb_put` + `memcpy_from_msg`). EINVAL if the skb is not linear or
    /// its tailroom is too small; EFAULT on a bad user pointer. On either
    /// error the skb is as it was (its `len` and tail unchanged, so
    /// [`Skb::data`] never covers bytes that were not copied) and the
    /// message's iterator is where it was, as after mainline's failed
    /// `memcpy_from_msg` (whose callers drop the skb; ours may keep it).
    /// Process context (the copy may fault and sleep).
    #[inline]
    pub(crate) fn put_from_msg(
        &mut self,
        msg: &mut super::sock::Msg,
        len: usize,
    ) -> kernel::error::Result {
        // `skb_put` written here, after the copy instead of before it: the
        // bytes are copied into the tailroom first, and tail and len move
        // by `len` only once all of them are there. The test that makes
        // `skb_put` call `skb_over_panic` is done first instead: a linear
        // skb (`SKB_LINEAR_ASSERT`) whose tail stays inside the head; and
        // `check_copy_size`'s `INT_MAX` limit. (Its object-size test is
        // the tailroom test here; `check_object_size` is empty without
        // CONFIG_HARDENED_USERCOPY.)
        // The bounds are checked before anything is written, so `dst` and
        // the `len` bytes after it lie in the head buffer's tailroom
        // (`tail` and `end` are offsets from `head`).
        // SAFETY: a valid skb, ours alone and not cloned (`Unique`, `&mut
        // self`: nobody else moves its tail or reads its data or tailroom).
        let dst = unsafe {
            let skb = &*self.as_ptr();
            if skb.data_len != 0
                || len > i32::MAX as usize
                || len as u64 > u64::from(skb.end.saturating_sub(skb.tail))
            {
                return Err(kernel::error::code::EINVAL);
            }
            skb.head.add(skb.tail as usize)
        };
        // On a short copy the bytes it wrote stay outside the data.
        // SAFETY: `dst` points to `len` writable bytes of the tailroom
        // (above), outside the data, of an skb nobody else touches.
        unsafe { msg.copy_from_user_raw(dst, len) }?;
        // `len` fits an `int`, so neither `tail` nor `len` overflows (both
        // stay below `end`, a `u32` offset).
        // SAFETY: as above, nothing moved the tail since the bounds test
        // (`&mut self`); the `len` bytes after it are now initialised.
        unsafe {
            let skb = &mut *self.as_ptr();
            skb.tail += len as u32;
            skb.len += len as u32;
        }
        Ok(())
    }

    /// The linear data, writable.
    #[inline]
    pub(crate) fn data_mut(&mut self) -> &mut [u8] {
        // `&mut self` lends the slice for as long as no other use of this
        // skb; the head holds `len - data_len` initialised bytes from `data`.
        // SAFETY: we own the only reference and no clone shares the data
        // (`Unique`).
        unsafe {
            let skb = &*self.as_ptr();
            let head_len = (skb.len - skb.data_len) as usize;
            if head_len == 0 {
                return &mut [];
            }
            core::slice::from_raw_parts_mut(skb.data, head_len)
        }
    }

    /// Appends `len` zero bytes (`skb_put_zero`); false if the skb is not
    /// linear or has too little tailroom.
    pub(crate) fn put_zeroed(&mut self, len: u32) -> bool {
        // SAFETY: ours alone and not cloned (`Unique`); the helper checks
        // the room.
        unsafe { bindings::rcan_skb_put_zero(self.as_ptr(), len) }
    }

    /// Prepends `len` bytes (`skb_push`) and returns them; `None` if the
    /// headroom is too small.
    pub(crate) fn push(&mut self, len: u32) -> Option<&mut [u8]> {
        // SAFETY: ours alone and not cloned (`Unique`, `&mut self` lends
        // the area); the helper checks the headroom, and the returned area
        // is `len` bytes inside the head.
        unsafe {
            let p = bindings::rcan_skb_push(self.as_ptr(), len) as *mut u8;
            if p.is_null() {
                None
            } else {
                Some(core::slice::from_raw_parts_mut(p, len as usize))
            }
        }
    }
}

/// A driver's transmit path (`start_xmit` gets an [`Skb`]: the stack may
/// hold other references, taps may hold clones).
impl Skb {
    /// For a driver's `start_xmit` (mainline `can_skb_headroom_valid`):
    /// `None` (the skb freed) if it has no room for `struct can_skb_priv`.
    /// An skb written through a packet socket (`CHECKSUM_NONE`) gets the
    /// CAN fields a CAN socket's skb has, including the echo request
    /// (`PACKET_LOOPBACK`) on an IFF_ECHO device, so local CAN sockets see
    /// it as on mainline; that writes its head, so such an skb is first
    /// made the driver's own ([`Skb::unshare`]: a copy if it is shared or
    /// cloned, `None` without memory). Transmit path of `dev`.
    #[inline]
    fn can_tx_prepare(self, dev: &super::netdev::NetDev) -> Option<Skb> {
        // The common case, a CAN socket's skb with its private area, is
        // told here (the helper's own first two tests, read in place); only
        // a packet socket's skb, or one without room, goes to the helper.
        // SAFETY: valid skb we hold; reading its head, data and a header
        // bitfield, which only a sole holder writes (not while we hold
        // ours, unless we are it).
        let (headroom, ip_summed) = unsafe {
            let skb = self.as_ptr();
            (
                (*skb).data.offset_from((*skb).head),
                (*skb)
                    .__bindgen_anon_4
                    .__bindgen_anon_1
                    .as_ref()
                    .ip_summed(),
            )
        };
        if headroom >= core::mem::size_of::<bindings::can_skb_priv>() as isize
            && u32::from(ip_summed) != bindings::CHECKSUM_NONE
        {
            return Some(self);
        }
        let u = self.unshare()?;
        // The helper checks the headroom before writing; `dev` is the
        // transmitting device, live for the call.
        // SAFETY: a valid skb, ours alone and not cloned (`Unique`), so the
        // helper may write its headroom and header fields.
        let ok = unsafe { bindings::rcan_can_skb_tx_prepare(u.as_ptr(), dev.as_ptr()) };
        ok.then(|| u.into_shared())
    }

    /// For an IFF_ECHO driver's `start_xmit` (mainline
    /// `can_create_echo_skb`): the skb to keep for the echo, ours alone. A
    /// shared skb (someone else holds a reference) is not the driver's to
    /// re-mark: it is replaced by a clone that keeps the sending socket;
    /// `None` if that clone cannot be allocated (the original is then
    /// freed).
    pub(crate) fn into_echo(self) -> Option<OwnedSkb> {
        match self.try_into_owned() {
            Ok(o) => Some(o),
            Err(s) => {
                let c = s.clone_with_owner();
                s.consume();
                c
            }
        }
    }

    /// The start of every CAN driver's `start_xmit`: the classic frame the
    /// skb holds, with the skb prepared ([`Skb::can_tx_prepare`]) and made
    /// the driver's to keep and, if the sender wants an echo, to re-mark
    /// ([`Skb::into_echo`]). `None`: not a classic frame, no room for the
    /// CAN private area, or no memory for a clone or copy; the skb is
    /// freed and counted in `dev`'s `tx_dropped`. Transmit path of `dev`.
    pub(crate) fn can_xmit_start(
        self,
        dev: &super::netdev::NetDev,
    ) -> Option<(OwnedSkb, crate::rcan_core::frame::CanFrame)> {
        use crate::rcan_core::frame::{CanFrame, CAN_FRAME_LEN};
        let frame = <&[u8; CAN_FRAME_LEN]>::try_from(self.data())
            .ok()
            .map(CanFrame::from_bytes);
        let Some(frame) = frame else {
            dev.stats_tx_dropped();
            drop(self);
            return None;
        };
        self.xmit_keep(dev).map(|skb| (skb, frame))
    }

    /// [`Skb::can_xmit_start`] for a driver of a CAN FD capable device
    /// (MTU 72): the classic or CAN FD frame the skb holds. As mainline's
    /// `can_dropped_invalid_skb`, the skb's protocol must say which:
    /// ETH_P_CAN with a 16-byte frame (`len <= 8`) or ETH_P_CANFD with a
    /// 72-byte one (`len <= 64`); anything else is dropped and counted.
    /// Transmit path of `dev`.
    pub(crate) fn can_xmit_start_any(
        self,
        dev: &super::netdev::NetDev,
    ) -> Option<(OwnedSkb, crate::rcan_core::frame::AnyFrame)> {
        use crate::rcan_core::frame::AnyFrame;
        let frame = AnyFrame::parse(self.data()).filter(|f| {
            let want = if f.is_fd() {
                bindings::ETH_P_CANFD
            } else {
                bindings::ETH_P_CAN
            };
            u32::from(self.protocol()) == want
        });
        let Some(frame) = frame else {
            dev.stats_tx_dropped();
            drop(self);
            return None;
        };
        self.xmit_keep(dev).map(|skb| (skb, frame))
    }

    /// [`Skb::can_xmit_start_any`] for a driver that needs only the
    /// frame's flavour, not a copy of it (canloop, which reads the length
    /// byte from the skb): the same checks, drops and `tx_dropped` counts,
    /// through [`AnyFrame::kind`](crate::rcan_core::frame::AnyFrame::kind),
    /// which reads two bytes, instead of building the frame. Returns the
    /// skb and whether it holds a CAN FD frame. Transmit path of `dev`.
    pub(crate) fn can_xmit_start_kind(
        self,
        dev: &super::netdev::NetDev,
    ) -> Option<(OwnedSkb, bool)> {
        use crate::rcan_core::frame::AnyFrame;
        let fd = AnyFrame::kind(self.data()).filter(|&fd| {
            let want = if fd {
                bindings::ETH_P_CANFD
            } else {
                bindings::ETH_P_CAN
            };
            u32::from(self.protocol()) == want
        });
        let Some(fd) = fd else {
            dev.stats_tx_dropped();
            drop(self);
            return None;
        };
        self.xmit_keep(dev).map(|skb| (skb, fd))
    }

    /// The end of [`Skb::can_xmit_start`]: the skb prepared
    /// ([`Skb::can_tx_prepare`]) and made the driver's own: by
    /// [`Skb::into_echo`] if the sender wants an echo, else by
    /// [`Skb::share_check`]; `None` (and a `tx_dropped`) if that fails.
    #[inline]
    fn xmit_keep(self, dev: &super::netdev::NetDev) -> Option<OwnedSkb> {
        let Some(skb) = self.can_tx_prepare(dev) else {
            dev.stats_tx_dropped();
            return None;
        };
        let kept = if skb.wants_echo() {
            skb.into_echo()
        } else {
            skb.share_check()
        };
        if kept.is_none() {
            dev.stats_tx_dropped();
        }
        kept
    }
}

impl OwnedSkb {
    /// The end of an IFF_ECHO driver's transmission (mainline
    /// `can_get_echo_skb`), for the skb [`Skb::can_xmit_start`] returned,
    /// once the chip reports the frame sent: counts the frame in `dev`'s
    /// `tx_packets`/`tx_bytes` and, if its sender asked for the echo,
    /// returns it marked as a frame received ([`Skb::set_can_rx`]:
    /// `PACKET_BROADCAST`, the sending socket kept), for the driver to hand
    /// up its way ([`super::netdev::NetDev::rx`] or its NAPI queue);
    /// otherwise frees it as consumed and returns `None`. Any context,
    /// interrupts off included (the driver's interrupt handler under its
    /// chip lock): the free is deferred there ([`Skb::consume_any`]).
    pub(crate) fn can_echo_done(mut self, dev: &super::netdev::NetDev) -> Option<OwnedSkb> {
        use crate::rcan_core::frame::{CanFrame, CAN_FRAME_LEN};
        if let Ok(b) = <&[u8; CAN_FRAME_LEN]>::try_from(self.data()) {
            dev.stats_tx(CanFrame::from_bytes(b).dlc() as u32);
        }
        if self.wants_echo() {
            self.set_can_rx();
            Some(self)
        } else {
            self.consume_any();
            None
        }
    }
}

impl<A: Access> Drop for Skb<A> {
    fn drop(&mut self) {
        // SAFETY: we own one reference (type invariant).
        unsafe { bindings::rcan_kfree_skb(self.as_ptr()) };
    }
}
