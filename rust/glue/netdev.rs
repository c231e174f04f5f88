// SPDX-License-Identifier: GPL-2.0

//! Network devices.
//!
//! * [`NetDev`]: a borrowed `struct net_device` (inside callbacks).
//! * [`DevRef`]: a counted reference (`dev_hold`/`dev_put`).
//! * [`Driver`] + [`Registration`]: a net_device whose ops are a Rust trait
//!   and whose private area holds `Driver::Priv`. `Registration::drop`
//!   unregisters (process context, takes RTNL) and frees the device.
//! * NAPI, for a driver with `Driver::NAPI_WEIGHT` > 0: one NAPI instance
//!   per device, added at registration, enabled from before `open` until
//!   `stop`; [`Dev::napi_schedule`] from the interrupt, `Driver::poll` in
//!   NET_RX softirq hands frames up through [`Napi::receive`].

use super::bindings;
use super::module::{ExitList, ExitNode, ModuleScope, SweepKind};
use super::net::Net;
use super::skb::{OwnedSkb, Skb};
use super::sync::{RcuReadGuard, Rtnl};
use core::marker::PhantomData;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicPtr, AtomicU32, Ordering};
use kernel::error::{code, Result};
use kernel::prelude::*;

/// `netdev_priv(dev)`: the driver's private area, the flexible array at
/// the end of the C struct (`dev->priv`). Computed here rather than by a C
/// helper: drivers reach their state through it on every frame.
///
/// # Safety
///
/// `dev` points to a valid `net_device`.
#[inline]
unsafe fn netdev_priv(dev: *const bindings::net_device) -> *mut ffi::c_void {
    // SAFETY: `dev` is valid (contract); only the address of the field is
    // taken, nothing is read.
    unsafe { core::ptr::addr_of!((*dev).priv_).cast_mut().cast() }
}

/// Bytes of an interface name, its NUL included (`IFNAMSIZ`; the type of
/// `net_device::name` in [`NetDev::name`] checks it).
const IFNAMSIZ: usize = 16;

/// An interface name as [`NetDev::name`] copied it: up to 15 bytes, no
/// NUL. Printed with `{}`; compared with [`IfName::as_bytes`].
#[derive(Clone, Copy)]
pub(crate) struct IfName {
    buf: [u8; IFNAMSIZ],
    len: u8,
}

impl IfName {
    /// The name's bytes, without the NUL.
    pub(crate) fn as_bytes(&self) -> &[u8] {
        &self.buf[..usize::from(self.len)]
    }

    /// The name as text ("?" if it is not UTF-8).
    pub(crate) fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("?")
    }
}

impl core::fmt::Display for IfName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.pad(self.as_str())
    }
}

/// A `struct net_device` borrowed for the duration of a callback.
#[repr(transparent)]
pub(crate) struct NetDev(kernel::types::Opaque<bindings::net_device>);

impl NetDev {
    /// # Safety
    ///
    /// `ptr` is a valid device that outlives `'a`.
    pub(crate) unsafe fn from_raw<'a>(ptr: *mut bindings::net_device) -> &'a NetDev {
        // SAFETY: `NetDev` is transparent over the C struct; validity per
        // the caller's contract.
        unsafe { &*ptr.cast::<NetDev>() }
    }

    pub(crate) fn as_ptr(&self) -> *mut bindings::net_device {
        self.0.get()
    }

    /// `__dev_get_by_index(net, ifindex)` with RTNL held (`_rtnl`), for as
    /// long as it stays held: no reference is taken (no `dev_hold` and
    /// `dev_put`, no RCU section), as mainline's RTNL callers do. A device
    /// leaves its namespace's index (unregistration, a move) only under
    /// RTNL and is freed only after that, so the borrow, which cannot
    /// outlive the guard, stays valid. Process context.
    pub(crate) fn by_index_rtnl<'a>(
        net: &Net,
        ifindex: i32,
        _rtnl: &'a Rtnl,
    ) -> Option<&'a NetDev> {
        // SAFETY: `net` is alive and RTNL held (`_rtnl`), as required; NULL
        // or a device listed in `net`, valid while RTNL is held (above).
        NonNull::new(unsafe { bindings::__dev_get_by_index(net.as_ptr(), ifindex) })
            // SAFETY: a listed device, valid for 'a (above).
            .map(|p| unsafe { NetDev::from_raw(p.as_ptr()) })
    }

    /// A counted reference to this device (`dev_hold`), e.g. to send on
    /// the device a frame was received on without looking it up again.
    /// Any context.
    pub(crate) fn hold(&self) -> DevRef {
        // SAFETY: a valid device for as long as `self` is borrowed; the
        // reference taken here keeps it valid after.
        unsafe { bindings::rcan_dev_hold(self.as_ptr()) };
        // INVARIANT: one reference, just taken.
        DevRef(NonNull::from(self).cast())
    }

    pub(crate) fn ifindex(&self) -> i32 {
        // SAFETY: valid device (type invariant); ifindex is fixed while
        // registered in one namespace (a move may change it, under RTNL).
        unsafe { (*self.as_ptr()).ifindex }
    }

    /// The device's namespace (`dev_net`), for the read-side section `_g`:
    /// a device moves between namespaces only under RTNL, and a namespace
    /// it left is freed only after a grace period. Any context.
    #[inline]
    pub(crate) fn net<'g>(&self, _g: &'g RcuReadGuard) -> &'g Net {
        // SAFETY: a valid device; `nd_net.net` is what `dev_net` reads
        // (`read_pnet`, CONFIG_NET_NS), and that namespace stays valid
        // until `_g` ends (above).
        unsafe { Net::from_raw((*self.as_ptr()).nd_net.net) }
    }

    /// Whether the device is in namespace `net` now. Any context.
    pub(crate) fn is_in(&self, net: &Net) -> bool {
        let g = RcuReadGuard::new();
        *self.net(&g) == *net
    }

    /// ARPHRD_CAN device.
    pub(crate) fn is_can(&self) -> bool {
        // SAFETY: valid device; `type` is set before registration.
        unsafe { u32::from((*self.as_ptr()).type_) == bindings::ARPHRD_CAN }
    }

    /// Administratively up (IFF_UP).
    pub(crate) fn is_up(&self) -> bool {
        // SAFETY: valid device; a racy read of flags is what dev_get_flags
        // callers do too (the transmit path rechecks).
        unsafe { (*self.as_ptr()).flags & bindings::net_device_flags_IFF_UP != 0 }
    }

    /// IFF_ECHO: the driver loops sent frames back itself.
    pub(crate) fn has_echo(&self) -> bool {
        // SAFETY: valid device; flags are set before registration and
        // IFF_ECHO never changes afterwards.
        unsafe { (*self.as_ptr()).flags & bindings::net_device_flags_IFF_ECHO != 0 }
    }

    /// The device MTU.
    pub(crate) fn mtu(&self) -> u32 {
        // SAFETY: valid device; a racy read of the MTU is what the core's
        // transmit checks do too.
        unsafe { (*self.as_ptr()).mtu }
    }

    /// The interface name ("can0"), copied out of the device. Any context.
    ///
    /// A copy, not a borrow: a rename (`dev_change_name`, under RTNL)
    /// rewrites `dev->name` while others read it. The kernel's readers
    /// take `netdev_rename_lock` (`netdev_copy_name`, not exported) or
    /// RTNL, or read it as a racy `%s`; here each byte is read once with
    /// `READ_ONCE` semantics into the copy, so no Rust reference ever
    /// covers bytes being written. A read concurrent with a rename may
    /// see a mix of the two names (as a lockless `%s` may): good for a
    /// log line or one comparison, never for memory safety.
    pub(crate) fn name(&self) -> IfName {
        let mut name = IfName {
            buf: [0; IFNAMSIZ],
            len: 0,
        };
        // SAFETY: valid device (`&self`): `name` is an array of IFNAMSIZ
        // bytes inside it (the type says so); only its address is taken.
        let src: *const [ffi::c_char; IFNAMSIZ] =
            unsafe { core::ptr::addr_of!((*self.as_ptr()).name) };
        // CAST: c_char and u8 have the same size and alignment.
        let src = src.cast::<u8>();
        // The last byte is always NUL (names are shorter than IFNAMSIZ).
        for i in 0..IFNAMSIZ - 1 {
            // A volatile byte read is READ_ONCE, which may race with the
            // plain stores of a rename (the kernel's memory model, not
            // Rust's references: no `&` to the array is made).
            // SAFETY: `src + i` lies in the array (i < IFNAMSIZ, its
            // length).
            let b = unsafe { core::ptr::read_volatile(src.add(i)) };
            if b == 0 {
                break;
            }
            name.buf[i] = b;
            name.len += 1;
        }
        name
    }

    /// Counts a transmitted frame of `bytes` data bytes. Any context.
    #[inline]
    pub(crate) fn stats_tx(&self, bytes: u32) {
        let d = self.as_ptr();
        // SAFETY: valid device; `stats` lives as long as it.
        unsafe {
            stat_add(&raw mut (*d).stats.__bindgen_anon_2.__tx_packets, 1);
            stat_add(
                &raw mut (*d).stats.__bindgen_anon_4.__tx_bytes,
                bytes.into(),
            );
        }
    }

    /// Counts a received frame. Any context.
    #[inline]
    pub(crate) fn stats_rx(&self, bytes: u32) {
        let d = self.as_ptr();
        // SAFETY: as above.
        unsafe {
            stat_add(&raw mut (*d).stats.__bindgen_anon_1.__rx_packets, 1);
            stat_add(
                &raw mut (*d).stats.__bindgen_anon_3.__rx_bytes,
                bytes.into(),
            );
        }
    }

    pub(crate) fn stats_tx_dropped(&self) {
        let d = self.as_ptr();
        // SAFETY: as above.
        unsafe { stat_add(&raw mut (*d).stats.__bindgen_anon_8.__tx_dropped, 1) };
    }

    pub(crate) fn stats_rx_dropped(&self) {
        let d = self.as_ptr();
        // SAFETY: as above.
        unsafe { stat_add(&raw mut (*d).stats.__bindgen_anon_7.__rx_dropped, 1) };
    }

    /// Restarts a stopped transmit queue (`netif_wake_queue`). Any context.
    pub(crate) fn wake_queue(&self) {
        // SAFETY: valid device.
        unsafe { bindings::rcan_netif_wake_queue(self.as_ptr()) };
    }

    /// `netif_carrier_on`/`off`.
    pub(crate) fn set_carrier(&self, on: bool) {
        // SAFETY: valid device.
        unsafe { bindings::rcan_netif_carrier(self.as_ptr(), on) };
    }

    /// Counts an error of kind `which` (`Stat`).
    pub(crate) fn stats_err(&self, which: Stat) {
        // SAFETY: valid device; DEV_STATS_* are atomic.
        unsafe { bindings::rcan_dev_stats_err(self.as_ptr(), which as i32) };
    }

    /// Whether a packet socket (tcpdump) taps this device or all devices.
    pub(crate) fn has_taps(&self) -> bool {
        // SAFETY: valid device; reads list heads (racy by design, as in
        // the core's own check).
        unsafe { bindings::rcan_dev_nit_active(self.as_ptr()) }
    }

    /// IFF_PROMISC: a packet socket wants every frame.
    pub(crate) fn is_promisc(&self) -> bool {
        // SAFETY: valid device; a racy read of flags, rechecked on every
        // ndo_set_rx_mode.
        unsafe { (*self.as_ptr()).flags & bindings::net_device_flags_IFF_PROMISC != 0 }
    }

    pub(crate) fn start_queue(&self) {
        // SAFETY: valid device.
        unsafe { bindings::rcan_netif_start_queue(self.as_ptr()) };
    }

    pub(crate) fn stop_queue(&self) {
        // SAFETY: valid device.
        unsafe { bindings::rcan_netif_stop_queue(self.as_ptr()) };
    }

    /// Hands a received frame to the network stack (`netif_rx`): it is
    /// queued on this CPU's backlog and reaches the protocol handlers
    /// (pf_can's `can_rcv`, packet sockets, tc) in NET_RX softirq.
    /// Hardirq, softirq, or process context with interrupts enabled:
    /// never in process context with interrupts off (under an irqsave
    /// lock), where `netif_rx`'s `local_bh_enable` warns and may run
    /// NET_RX, and with it receivers that transmit, on the spot.
    ///
    /// `skb->dev` becomes this device here, at the hand-off, so the skb
    /// reaches the stack with a live device and never with a NULL or
    /// stale one; from the backlog on, unregistering the device flushes
    /// the skb before the device goes (`flush_all_backlogs`).
    pub(crate) fn rx(&self, mut skb: OwnedSkb) {
        // SAFETY: handed to the kernel right below, `self` borrowed
        // meanwhile.
        unsafe { skb.set_dev(self) };
        // SAFETY: netif_rx consumes the skb reference in every case; its
        // `dev` is this device, live for the call (`&self`).
        unsafe { bindings::netif_rx(skb.into_raw()) };
    }
}

use kernel::ffi;

/// `DEV_STATS_ADD(dev, field, n)`: the kernel's `atomic_long_add` on the
/// counter's atomic view (`__tx_packets` etc. of `struct
/// net_device_stats`), done in place as a relaxed atomic add (the same
/// locked add instruction), so the device statistics cost no call into a
/// C helper per frame. Any context.
///
/// # Safety
///
/// `counter` is the atomic view of a counter of a valid device's `stats`.
#[inline]
unsafe fn stat_add(counter: *mut bindings::atomic_long_t, n: u64) {
    // SAFETY: `atomic_long_t` is a naturally aligned `s64` that the kernel
    // only accesses atomically (DEV_STATS_*), valid per the contract.
    let c = unsafe { core::sync::atomic::AtomicI64::from_ptr(&raw mut (*counter).counter) };
    c.fetch_add(n as i64, Ordering::Relaxed);
}

/// Error counters of `struct net_device_stats` (see `rcan_dev_stats_err`).
#[derive(Clone, Copy)]
#[repr(i32)]
pub(crate) enum Stat {
    RxErrors = bindings::RCAN_STAT_RX_ERRORS as i32,
    /// Also counts an rx error.
    RxOverErrors = bindings::RCAN_STAT_RX_OVER_ERRORS as i32,
    TxErrors = bindings::RCAN_STAT_TX_ERRORS as i32,
    /// Also counts a tx error.
    TxAborted = bindings::RCAN_STAT_TX_ABORTED as i32,
}

/// A counted reference to a network device.
///
/// # Invariants
///
/// Holds one `dev_hold` reference on a valid device.
pub(crate) struct DevRef(NonNull<bindings::net_device>);

// SAFETY: device references may move between threads.
unsafe impl Send for DevRef {}

impl DevRef {
    /// `dev_get_by_index(net, ifindex)`: an interface index means a device
    /// of one namespace (a socket's: [`Sock::net`](super::sock::Sock::net)).
    /// Process or softirq context. Called directly (exported), once a
    /// frame on CAN_RAW's send path.
    #[inline]
    pub(crate) fn by_index(net: &Net, ifindex: i32) -> Option<DevRef> {
        // SAFETY: `net` is alive for the call; returns a held device or
        // NULL.
        NonNull::new(unsafe { bindings::dev_get_by_index(net.as_ptr(), ifindex) }).map(DevRef)
    }

    /// `dev_get_by_name(net, name)`. Process or softirq context.
    pub(crate) fn by_name(net: &Net, name: &kernel::str::CStr) -> Option<DevRef> {
        // SAFETY: `net` is alive and `name` NUL-terminated for the call;
        // the function returns a held device or NULL.
        NonNull::new(unsafe { bindings::rcan_dev_get_by_name(net.as_ptr(), name.as_char_ptr()) })
            .map(DevRef)
    }

    /// The CAN device (ARPHRD_CAN) of `net` with the smallest ifindex above
    /// `after`. Process or softirq context.
    pub(crate) fn next_can(net: &Net, after: i32) -> Option<DevRef> {
        // SAFETY: `net` is alive for the call; returns a held device or
        // NULL.
        NonNull::new(unsafe { bindings::rcan_next_can_dev(net.as_ptr(), after) }).map(DevRef)
    }
}

impl core::ops::Deref for DevRef {
    type Target = NetDev;
    fn deref(&self) -> &NetDev {
        // SAFETY: we hold a reference, so the device stays valid while
        // `self` lives.
        unsafe { NetDev::from_raw(self.0.as_ptr()) }
    }
}

impl Drop for DevRef {
    fn drop(&mut self) {
        // `dev_put` stays a C helper: it is `static inline`, and with
        // CONFIG_PCPU_DEV_REFCNT its body is `this_cpu_dec`, a per-CPU
        // (%gs-relative on x86-64) decrement that the kernel's Rust (6.12)
        // has no accessor for; open-coding it would take inline assembly
        // tied to the architecture, SMP and the refcount-tracker options,
        // for a call and a return a frame.
        // SAFETY: we own one reference (type invariant).
        unsafe { bindings::rcan_dev_put(self.0.as_ptr()) };
    }
}

/// Link-layer types (`ARPHRD_*`) for [`Setup::type_`].
pub(crate) mod arphrd {
    use super::bindings;

    /// A CAN controller or virtual CAN device.
    pub(crate) const CAN: u16 = bindings::ARPHRD_CAN as u16;
    /// No link-layer header and no hardware address (DSOR's UDP/IP device).
    pub(crate) const VOID: u16 = bindings::ARPHRD_VOID as u16;
}

/// Interface flags (`IFF_*`) for [`Setup::flags`].
pub(crate) mod iff {
    use super::bindings;

    /// No ARP.
    pub(crate) const NOARP: u32 = bindings::net_device_flags_IFF_NOARP;
    /// Point-to-point link.
    pub(crate) const POINTOPOINT: u32 = bindings::net_device_flags_IFF_POINTOPOINT;
    /// The driver loops sent frames back itself (CAN).
    pub(crate) const ECHO: u32 = bindings::net_device_flags_IFF_ECHO;
}

/// Device parameters a driver sets before registration.
pub(crate) struct Setup {
    /// ARPHRD_* type.
    pub(crate) type_: u16,
    /// IFF_* flags.
    pub(crate) flags: u32,
    pub(crate) mtu: u32,
    pub(crate) hard_header_len: u16,
    pub(crate) tx_queue_len: u32,
    /// IFF_NO_QUEUE: no qdisc (`noqueue`), for virtual devices whose
    /// `start_xmit` never stops the queue.
    pub(crate) no_queue: bool,
}

/// What `ndo_start_xmit` did with the frame.
pub(crate) enum Xmit {
    /// The driver took the skb (sent, queued or dropped and counted).
    Ok,
}

/// A network device driver.
///
/// Contexts: `open`/`stop` run in process context under RTNL; `start_xmit`
/// runs in softirq or process context with BH disabled, serialised per
/// queue by the kernel's TX lock; `set_rx_mode` runs with BH disabled
/// under the device's address lock; `irq` in hardirq context.
pub(crate) trait Driver: Sized + 'static {
    /// Per-device private data, in the netdev's private area.
    type Priv: Send + Sync;
    /// Whether `set_rx_mode` is implemented (fills `ndo_set_rx_mode`).
    const HAS_SET_RX_MODE: bool = false;
    /// The device stays in the namespace it was registered in (the
    /// initial one): `ip link set DEV netns ...` is refused (EINVAL), as
    /// for `lo` (`netns_immutable`). For devices that belong to state of
    /// the initial namespace (DSOR's `canip0`). Default: movable.
    const NETNS_IMMUTABLE: bool = false;

    fn setup() -> Setup;
    fn open(dev: &Dev<Self>, priv_: &Self::Priv) -> Result;
    fn stop(dev: &Dev<Self>, priv_: &Self::Priv) -> Result;
    /// The transmit path of `dev` (BH off, TX lock held). The skb is a
    /// [`Skb`], read-only: the stack may hold other references and taps
    /// clones; [`Skb::can_xmit_start`] makes it the driver's own
    /// ([`OwnedSkb`]) to keep for the echo.
    fn start_xmit(skb: Skb, dev: &Dev<Self>, priv_: &Self::Priv) -> Xmit;
    /// The receive mode changed (IFF_PROMISC, ...). Atomic context.
    fn set_rx_mode(_dev: &Dev<Self>, _priv: &Self::Priv) {}
    /// Whether `private_ioctl` is implemented (fills
    /// `ndo_siocdevprivate`).
    const HAS_PRIVATE_IOCTL: bool = false;
    /// A device-private ioctl (`SIOCDEVPRIVATE` + 0..15; `cmd` is the
    /// full number), `data` the user's `ifr_data`. Process context, RTNL
    /// not held.
    fn private_ioctl(_dev: &Dev<Self>, _priv: &Self::Priv, _cmd: u32, _data: &UserBuf) -> Result {
        Err(super::neterr::EOPNOTSUPP())
    }
    /// Interrupt handler for a line requested with [`Dev::request_irq`].
    /// Hardirq context. Returns whether the device raised the interrupt.
    fn irq(_dev: &Dev<Self>, _priv: &Self::Priv) -> bool {
        false
    }
    /// NAPI weight (frames per poll); 0: the device has no NAPI instance
    /// and `poll` is never called.
    const NAPI_WEIGHT: u32 = 0;
    /// NAPI poll: hands at most `budget` received frames up with
    /// [`Napi::receive`] and returns how many; fewer than `budget` means
    /// the driver's queue is empty (the glue then completes the poll, and
    /// the next [`Dev::napi_schedule`] starts another). NET_RX softirq
    /// context, interrupts enabled; never runs concurrently with itself
    /// for one device, so frames handed up in queue order stay in order
    /// whichever CPU polls.
    fn poll(_dev: &Dev<Self>, _priv: &Self::Priv, _napi: &Napi, _budget: usize) -> usize {
        0
    }
    /// For a CAN controller driver: the device layer's link ops and hooks
    /// (`glue::can::dev::link_setup::<Self>()`), so that `ip link set
    /// canX type can ...` reaches it. Called at allocation.
    fn link() -> Option<super::can::dev::LinkSetup> {
        None
    }
    /// Whether `change_mtu` is implemented (fills `ndo_change_mtu`; the
    /// device then has no `min_mtu`/`max_mtu`, so every value reaches
    /// `change_mtu`, as for mainline's vcan).
    const HAS_CHANGE_MTU: bool = false;
    /// `ip link set DEV mtu N`: whether the device takes `new_mtu` (the
    /// glue then stores it). Process context, RTNL held; the kernel has
    /// already returned for a value equal to the current MTU.
    fn change_mtu(_dev: &Dev<Self>, _priv: &Self::Priv, _new_mtu: u32) -> Result {
        Err(EINVAL)
    }
}

/// Proof of running inside a device's NAPI poll (NET_RX softirq,
/// interrupts enabled), handed to [`Driver::poll`]; only the glue makes
/// one.
///
/// # Invariants
///
/// `dev` is the polled device, live while the `Napi` is (the glue lends
/// a `Napi` only by reference, for the poll).
pub(crate) struct Napi {
    dev: NonNull<NetDev>,
    _not_send: PhantomData<*mut ()>,
}

impl Napi {
    /// Hands a received frame to the protocol handlers at once
    /// (`netif_receive_skb`: packet taps, tc ingress, pf_can's `can_rcv`),
    /// in this NET_RX softirq. Consumes `skb`.
    /// `skb->dev` becomes the polled device here, at the hand-off (as
    /// [`NetDev::rx`] does).
    pub(crate) fn receive(&self, mut skb: OwnedSkb) {
        // SAFETY: `dev` is the polled device, live for the poll (type
        // invariant), and `&self` does not outlive the poll; the skb is
        // handed to the kernel right below.
        unsafe { skb.set_dev(self.dev.as_ref()) };
        // We are in a NAPI poll (only the glue makes a `Napi`, and only
        // there): softirq context with interrupts enabled, which is what
        // netif_receive_skb requires.
        // SAFETY: so the call may be made; it consumes the reference; its
        // `dev` is the polled device (just set).
        unsafe { bindings::netif_receive_skb(skb.into_raw()) };
    }

    /// Hands up to `budget` frames to [`receive`](Self::receive), one
    /// `pop()` per frame, and returns how many it handed up (the value a
    /// [`Driver::poll`] returns). `pop` takes the driver's receive queue
    /// off its lock and returns the next frame, `None` when the queue is
    /// empty: the lock is held for one `pop()` only and released before
    /// the frame goes up, so the protocol handlers run unlocked, with
    /// interrupts on, and may send on the same device.
    #[inline]
    pub(crate) fn drain(&self, budget: usize, mut pop: impl FnMut() -> Option<OwnedSkb>) -> usize {
        let mut done = 0;
        while done < budget {
            let Some(skb) = pop() else {
                break;
            };
            self.receive(skb);
            done += 1;
        }
        done
    }
}

/// A device of driver `T`, borrowed inside one of `T`'s callbacks.
#[repr(transparent)]
pub(crate) struct Dev<T: Driver>(NetDev, PhantomData<T>);

impl<T: Driver> core::ops::Deref for Dev<T> {
    type Target = NetDev;
    fn deref(&self) -> &NetDev {
        &self.0
    }
}

// Only `Registration::register`, which takes the scope, makes a device
// of `T`.
impl<T: Driver> super::module::sealed::Sealed for Dev<T> {}
impl<T: Driver> super::module::InScopedModule for Dev<T> {}

impl<T: Driver> Dev<T> {
    /// # Safety
    ///
    /// `ptr` is a valid device registered by [`Registration`] for `T` that
    /// outlives `'a`.
    unsafe fn from_raw<'a>(ptr: *mut bindings::net_device) -> &'a Dev<T> {
        // SAFETY: transparent over NetDev, which is transparent over the C
        // struct; validity per the contract.
        unsafe { &*ptr.cast::<Dev<T>>() }
    }

    fn state(&self) -> &PrivBox<T::Priv> {
        // SAFETY: a device of `T` holds an initialised PrivBox (invariant
        // of Registration).
        unsafe { &*netdev_priv(self.as_ptr()).cast::<PrivBox<T::Priv>>() }
    }

    /// The driver's private data of this device (what the trait methods
    /// get beside it). Any context.
    pub(crate) fn priv_data(&self) -> &T::Priv {
        &self.state().inner
    }

    /// Requests interrupt line `irq` (shared) for this device; `T::irq`
    /// handles it until [`Dev::free_irq`] (or unregistration, as a safety
    /// net). Process context (`open`); EBUSY if one is already requested.
    pub(crate) fn request_irq(&self, irq: u32) -> Result {
        let st = self.state();
        if st.irq.load(Ordering::Acquire) != 0 {
            return Err(code::EBUSY);
        }
        // The handler gets this device as its cookie; the device outlives
        // the registration (freed in free_irq, called by `stop` or by
        // Registration's Drop before free_netdev). The name is the device
        // name, which lives in the device.
        // SAFETY: cookie and name outlive the registration (above).
        let ret = unsafe {
            bindings::request_threaded_irq(
                irq,
                Some(Adapter::<T>::irq),
                None,
                bindings::IRQF_SHARED as ffi::c_ulong,
                (*self.as_ptr()).name.as_ptr(),
                self.as_ptr().cast(),
            )
        };
        super::to_result(ret)?;
        st.irq.store(irq, Ordering::Release);
        Ok(())
    }

    /// Schedules the device's NAPI poll (`napi_schedule`): `T::poll` runs
    /// soon in NET_RX softirq; if it is running now, it runs once more.
    /// Any context (hardirq, softirq, interrupts off). Does nothing for a
    /// driver without NAPI (`T::NAPI_WEIGHT` 0) or while the device is
    /// down (the instance is disabled then).
    pub(crate) fn napi_schedule(&self) {
        if T::NAPI_WEIGHT > 0 {
            // (`napi_schedule` inlined: two exported calls, no C helper.)
            let napi = self.state().napi.get();
            // SAFETY: added at registration (NAPI_WEIGHT > 0), the instance
            // lives as long as the device; prep fails on a disabled one, so
            // `__napi_schedule` runs only for an instance it just claimed.
            if unsafe { bindings::napi_schedule_prep(napi) } {
                // SAFETY: claimed above (NAPI_STATE_SCHED is ours).
                unsafe { bindings::__napi_schedule(napi) };
            }
        }
    }

    /// Frees the line requested with [`Dev::request_irq`]; waits for a
    /// running handler. Process context.
    pub(crate) fn free_irq(&self) {
        let irq = self.state().irq.swap(0, Ordering::AcqRel);
        if irq != 0 {
            // SAFETY: requested by request_irq with this cookie.
            unsafe { bindings::free_irq(irq, self.as_ptr().cast()) };
        }
    }
}

/// The device and driver data behind a cookie handed out as
/// `Registration::dev().as_ptr()`.
///
/// # Safety
///
/// `ptr` is a device registered by [`Registration`] for `T`, and stays
/// registered (its Registration alive) for `'a`.
pub(crate) unsafe fn from_cookie<'a, T: Driver>(
    ptr: *mut bindings::net_device,
) -> (&'a Dev<T>, &'a T::Priv) {
    // SAFETY: per the contract.
    unsafe { (Dev::<T>::from_raw(ptr), Adapter::<T>::priv_of(ptr)) }
}

/// A user-space buffer of an ioctl (`ifr_data`).
pub(crate) struct UserBuf(*mut ffi::c_void);

impl UserBuf {
    /// Copies `dst.len()` bytes from user space; EFAULT on a bad pointer.
    pub(crate) fn read(&self, dst: &mut [u8]) -> Result {
        // SAFETY: `dst` is writable; copy_from_user checks the user pointer.
        let ret = unsafe {
            bindings::rcan_copy_from_user(dst.as_mut_ptr().cast(), self.0, dst.len() as _)
        };
        super::to_result(ret).map(|_| ())
    }

    /// Copies `src` to user space; EFAULT on a bad pointer.
    pub(crate) fn write(&self, src: &[u8]) -> Result {
        // SAFETY: `src` is readable; copy_to_user checks the user pointer.
        let ret =
            unsafe { bindings::rcan_copy_to_user(self.0, src.as_ptr().cast(), src.len() as _) };
        super::to_result(ret).map(|_| ())
    }
}

/// Whether the calling task has CAP_NET_ADMIN (in the initial user
/// namespace). Process context.
pub(crate) fn capable_net_admin() -> bool {
    // SAFETY: capable() only inspects the current task's credentials.
    unsafe { bindings::rcan_capable_net_admin() }
}

/// What the netdev private area holds: the driver's data and the glue's
/// bookkeeping.
struct PrivBox<P> {
    /// The device on its module's [`DEVICES`] list from registration
    /// until its [`Registration`] is dropped or the module's exit
    /// unregisters it. Does not move: the private area never does.
    exit: ExitNode,
    /// What must be undone before the device is unregistered, set by the
    /// glue's `Listening` (its filter listener's removal, an `unsafe
    /// fn(*mut net_device)`), taken back by whoever undoes it first: the
    /// listening's drop, or the teardown of a device whose listening was
    /// forgotten. Null: nothing.
    before_teardown: AtomicPtr<()>,
    /// Requested interrupt line, 0 = none.
    irq: AtomicU32,
    /// The NAPI instance (added at registration if `Driver::NAPI_WEIGHT`
    /// > 0; otherwise unused). Pinned: the private area never moves.
    napi: kernel::types::Opaque<bindings::napi_struct>,
    inner: P,
}

struct Adapter<T: Driver>(PhantomData<T>);

impl<T: Driver> Adapter<T> {
    const OPS: bindings::net_device_ops = bindings::net_device_ops {
        ndo_open: Some(Self::open),
        ndo_stop: Some(Self::stop),
        ndo_start_xmit: Some(Self::start_xmit),
        ndo_siocdevprivate: if T::HAS_PRIVATE_IOCTL {
            Some(Self::siocdevprivate)
        } else {
            None
        },
        ndo_set_rx_mode: if T::HAS_SET_RX_MODE {
            Some(Self::set_rx_mode)
        } else {
            None
        },
        ndo_change_mtu: if T::HAS_CHANGE_MTU {
            Some(Self::change_mtu)
        } else {
            None
        },
        // SAFETY: all-zero is a valid net_device_ops (every hook NULL).
        ..unsafe { core::mem::zeroed() }
    };

    /// # Safety
    ///
    /// `dev` was allocated by [`Registration::register`] for `T`.
    unsafe fn priv_of<'a>(dev: *mut bindings::net_device) -> &'a T::Priv {
        // SAFETY: the private area holds an initialised `PrivBox<T::Priv>`
        // from registration until free (see Registration).
        unsafe { &(*netdev_priv(dev).cast::<PrivBox<T::Priv>>()).inner }
    }

    unsafe extern "C" fn siocdevprivate(
        dev: *mut bindings::net_device,
        _ifr: *mut bindings::ifreq,
        data: *mut ffi::c_void,
        cmd: ffi::c_int,
    ) -> ffi::c_int {
        // SAFETY: the kernel passes a registered device of ours; `data` is
        // the caller's user pointer, only used through uaccess helpers.
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        match T::private_ioctl(d, p, cmd as u32, &UserBuf(data)) {
            Ok(()) => 0,
            Err(e) => e.to_errno(),
        }
    }

    unsafe extern "C" fn change_mtu(
        dev: *mut bindings::net_device,
        new_mtu: ffi::c_int,
    ) -> ffi::c_int {
        // SAFETY: the kernel passes a registered device of ours, under RTNL.
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        let Ok(mtu) = u32::try_from(new_mtu) else {
            return EINVAL.to_errno();
        };
        match T::change_mtu(d, p, mtu) {
            Ok(()) => {
                // Readers (the transmit paths) read the MTU without RTNL
                // (READ_ONCE); this is mainline's WRITE_ONCE(dev->mtu, ...).
                // SAFETY: a live device; we hold RTNL, the MTU's writers' lock.
                unsafe { core::ptr::write_volatile(&raw mut (*dev).mtu, mtu) };
                0
            }
            Err(e) => e.to_errno(),
        }
    }

    unsafe extern "C" fn set_rx_mode(dev: *mut bindings::net_device) {
        // SAFETY: the kernel passes a registered device of ours.
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        T::set_rx_mode(d, p);
    }

    unsafe extern "C" fn irq(_irq: ffi::c_int, cookie: *mut ffi::c_void) -> bindings::irqreturn_t {
        let dev = cookie.cast::<bindings::net_device>();
        // SAFETY: the cookie is the device given to request_threaded_irq,
        // alive until free_irq returns.
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        if T::irq(d, p) {
            bindings::irqreturn_IRQ_HANDLED
        } else {
            bindings::irqreturn_IRQ_NONE
        }
    }

    unsafe extern "C" fn setup(dev: *mut bindings::net_device) {
        let s = T::setup();
        // SAFETY: called by alloc_netdev_mqs on the new, unregistered device.
        unsafe {
            let d = &mut *dev;
            d.type_ = s.type_;
            d.flags = s.flags;
            d.mtu = s.mtu;
            // With change_mtu the driver decides every value (0: no bound).
            let (min, max) = if T::HAS_CHANGE_MTU {
                (0, 0)
            } else {
                (s.mtu, s.mtu)
            };
            d.min_mtu = min;
            d.max_mtu = max;
            d.hard_header_len = s.hard_header_len;
            d.tx_queue_len = s.tx_queue_len;
            if s.no_queue {
                bindings::rcan_netdev_set_no_queue(dev);
            }
            if T::NETNS_IMMUTABLE {
                bindings::rcan_netdev_set_netns_immutable(dev);
            }
            d.netdev_ops = &Self::OPS;
            if let Some(l) = T::link() {
                // rtnetlink calls these ops for this device only; they
                // find the driver through `ml_priv` (type ML_PRIV_NONE:
                // mainline af_can, which looks for ML_PRIV_CAN, never
                // takes it for its own).
                d.rtnl_link_ops = l.ops;
                d.ml_priv = l.hooks.cast_mut().cast();
                // No carrier until `open` (mainline register_candev), so
                // the operstate follows: UP once open, not UNKNOWN.
                bindings::rcan_netif_carrier(dev, false);
            }
        }
    }

    unsafe extern "C" fn open(dev: *mut bindings::net_device) -> ffi::c_int {
        // SAFETY: the kernel passes a registered device of ours.
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        let napi = d.state().napi.get();
        if T::NAPI_WEIGHT > 0 {
            // SAFETY: added at registration; disabled (a new instance, or
            // disabled by `stop`), RTNL held: open and stop alternate.
            unsafe { bindings::rcan_napi_enable(napi) };
        }
        match T::open(d, p) {
            Ok(()) => 0,
            Err(e) => {
                if T::NAPI_WEIGHT > 0 {
                    // SAFETY: enabled just above.
                    unsafe { bindings::rcan_napi_disable(napi) };
                }
                e.to_errno()
            }
        }
    }

    unsafe extern "C" fn stop(dev: *mut bindings::net_device) -> ffi::c_int {
        // SAFETY: as in open().
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        if T::NAPI_WEIGHT > 0 {
            // Waits for a running poll, after which none starts until the
            // next open, so `T::stop` may empty the driver's receive queue.
            // SAFETY: enabled by a successful open (stop only follows one).
            unsafe { bindings::rcan_napi_disable(d.state().napi.get()) };
        }
        match T::stop(d, p) {
            Ok(()) => 0,
            Err(e) => e.to_errno(),
        }
    }

    /// The NAPI poll of a device of `T` (NET_RX softirq).
    unsafe extern "C" fn poll(napi: *mut bindings::napi_struct, budget: ffi::c_int) -> ffi::c_int {
        // SAFETY: the instance was added by `register` for a device of `T`
        // and lives in its private area; the core polls only enabled
        // instances, i.e. between open and stop of the registered device.
        let dev = unsafe { (*napi).dev };
        // SAFETY: as above: a registered device of ours.
        let (d, p) = unsafe { (Dev::<T>::from_raw(dev), Self::priv_of(dev)) };
        let budget = usize::try_from(budget).unwrap_or(0);
        // INVARIANT: the polled device, live for the poll; the token is
        // lent to `T::poll` by reference only.
        let token = Napi {
            dev: NonNull::from(&**d),
            _not_send: PhantomData,
        };
        let done = T::poll(d, p, &token, budget).min(budget);
        if done < budget {
            // SAFETY: our instance, inside its poll, which did less than
            // its budget (so it may complete; a budget of 0 never does).
            unsafe { bindings::napi_complete_done(napi, done as ffi::c_int) };
        }
        done as ffi::c_int
    }

    unsafe extern "C" fn start_xmit(
        skb: *mut bindings::sk_buff,
        dev: *mut bindings::net_device,
    ) -> bindings::netdev_tx_t {
        // SAFETY: the kernel hands us one skb reference (a `Skb`: others
        // may hold more) and a registered device of ours.
        let (skb, d, p) = unsafe {
            match Skb::from_raw(skb) {
                Some(s) => (s, Dev::<T>::from_raw(dev), Self::priv_of(dev)),
                None => return bindings::netdev_tx_NETDEV_TX_OK,
            }
        };
        match T::start_xmit(skb, d, p) {
            Xmit::Ok => bindings::netdev_tx_NETDEV_TX_OK,
        }
    }
}

/// A registered network device of driver `T`.
///
/// # Invariants
///
/// `dev` is registered, its private area holds an initialised `T::Priv`.
pub(crate) struct Registration<T: Driver> {
    dev: NonNull<bindings::net_device>,
    _t: PhantomData<T>,
}

// SAFETY: the registration only unregisters in Drop (process context, any
// thread); `T::Priv: Send + Sync`.
unsafe impl<T: Driver> Send for Registration<T> {}
// SAFETY: shared access only reads the device pointer.
unsafe impl<T: Driver> Sync for Registration<T> {}

impl<T: Driver> Registration<T> {
    /// Allocates and registers a device named after `name` ("can%d"). The
    /// device stays registered until the returned guard is dropped, and
    /// at the latest until the module's exit, which the `scope` proves the
    /// glue runs ([`Scoped`](super::module::Scoped)): a forgotten
    /// registration cannot leave a device with ops in freed module text.
    /// Process context; takes RTNL.
    pub(crate) fn register(name: &CStr, priv_: T::Priv, _scope: &ModuleScope) -> Result<Self> {
        // SAFETY: `name` is NUL-terminated; setup is our trampoline.
        let dev = unsafe {
            bindings::alloc_netdev_mqs(
                core::mem::size_of::<PrivBox<T::Priv>>() as i32,
                name.as_char_ptr(),
                bindings::NET_NAME_ENUM as u8,
                Some(Adapter::<T>::setup),
                1,
                1,
            )
        };
        let dev = NonNull::new(dev).ok_or(code::ENOMEM)?;
        // SAFETY: an all-zero napi_struct is what netif_napi_add expects
        // (the private area of alloc_netdev is zeroed too).
        let napi = kernel::types::Opaque::new(unsafe { core::mem::zeroed() });
        // SAFETY: the private area is sized and aligned (NETDEV_ALIGN) for
        // `PrivBox<T::Priv>`, and nothing reads it before registration.
        unsafe {
            netdev_priv(dev.as_ptr())
                .cast::<PrivBox<T::Priv>>()
                .write(PrivBox {
                    exit: ExitNode::new(),
                    before_teardown: AtomicPtr::new(core::ptr::null_mut()),
                    irq: AtomicU32::new(0),
                    napi,
                    inner: priv_,
                })
        };
        if T::NAPI_WEIGHT > 0 {
            // The instance lives in the private area (it does not move)
            // until free_netdev deletes it (also on the error path below).
            // SAFETY: see above; `poll` is our trampoline for `T`.
            unsafe {
                bindings::rcan_napi_add(
                    dev.as_ptr(),
                    (*netdev_priv(dev.as_ptr()).cast::<PrivBox<T::Priv>>())
                        .napi
                        .get(),
                    Some(Adapter::<T>::poll),
                    T::NAPI_WEIGHT as ffi::c_int,
                )
            };
        }
        // SAFETY: a fully set-up, unregistered device.
        let ret = unsafe { bindings::register_netdev(dev.as_ptr()) };
        if ret < 0 {
            // SAFETY: never registered: drop the private data, free it.
            unsafe {
                core::ptr::drop_in_place(netdev_priv(dev.as_ptr()).cast::<PrivBox<T::Priv>>());
                bindings::free_netdev(dev.as_ptr());
            }
            return Err(Error::from_errno(ret));
        }
        // The node is in the private area, which stays in place until
        // `teardown::<T>` frees it; `teardown::<T>` of this registered
        // device of `T` may run once, in process context, at any time (it
        // is `Registration::drop`'s body).
        // SAFETY: so this is push's contract.
        unsafe {
            DEVICES.push(
                &(*netdev_priv(dev.as_ptr()).cast::<PrivBox<T::Priv>>()).exit,
                dev.as_ptr().cast(),
                teardown::<T>,
                SweepKind::Devices,
                devices_sweep,
            )
        };
        // INVARIANT: registered with initialised private data.
        Ok(Registration {
            dev,
            _t: PhantomData,
        })
    }

    pub(crate) fn dev(&self) -> &Dev<T> {
        // SAFETY: registered device of `T` (type invariant) living as long
        // as self.
        unsafe { Dev::from_raw(self.dev.as_ptr()) }
    }

    pub(crate) fn priv_data(&self) -> &T::Priv {
        // SAFETY: type invariant.
        unsafe { Adapter::<T>::priv_of(self.dev.as_ptr()) }
    }

    /// Makes the device's teardown call `f(dev)` before it unregisters
    /// the device, unless [`Registration::take_before_teardown`] takes it
    /// back first: the glue's `Listening` removes its filter listener so
    /// even when it is forgotten and the module's exit tears the device
    /// down. One hook per device (a second replaces the first). Any
    /// context.
    ///
    /// # Safety
    ///
    /// Calling `f` once with this device, in process context, before it
    /// is unregistered, is sound until the hook is taken back.
    pub(super) unsafe fn set_before_teardown(&self, f: unsafe fn(*mut bindings::net_device)) {
        self.dev()
            .state()
            .before_teardown
            .store(f as *mut (), Ordering::Release);
    }

    /// Takes back the hook of [`Registration::set_before_teardown`]:
    /// true if it was set (the caller undoes what it stood for itself),
    /// false if not. Any context.
    pub(super) fn take_before_teardown(&self) -> bool {
        !self
            .dev()
            .state()
            .before_teardown
            .swap(core::ptr::null_mut(), Ordering::AcqRel)
            .is_null()
    }
}

impl<T: Driver> Drop for Registration<T> {
    fn drop(&mut self) {
        // SAFETY: the device is registered (type invariant), so its
        // private area holds our `PrivBox`, with the node.
        let node = unsafe { &(*netdev_priv(self.dev.as_ptr()).cast::<PrivBox<T::Priv>>()).exit };
        // Off the module's list first: from here on the device is ours to
        // tear down. If the exit's sweep took it (a registration dropped
        // while the module goes, from a context the module forgot), the
        // sweep tears it down: it is not touched here.
        if DEVICES.remove(node) {
            // SAFETY: a registered device of `T` that nobody else will
            // tear down (taken off the list just now).
            unsafe { teardown::<T>(self.dev.as_ptr().cast()) };
        }
    }
}

/// The network devices this module registered and has not unregistered
/// (the glue is compiled into each module: one list per module), through
/// the nodes in their private areas ([`PrivBox::exit`]); swept at exit
/// by [`devices_sweep`]. An intrusive list rather than a bounded table:
/// a module has any number of devices (`rcan_loop` up to 16, a PCI driver
/// one per channel of each card), and registering one must not fail for
/// want of a slot the kernel itself does not have.
static DEVICES: ExitList = ExitList::new(kernel::c_str!("rcan_glue_devices"));

/// The exit's sweep ([`Scoped`](super::module::Scoped), step 3):
/// unregisters and frees every device of this module still registered,
/// as its `Registration`'s drop would have. Process context, after the
/// module's value was dropped; takes RTNL, sleeps.
fn devices_sweep() {
    DEVICES.sweep();
}

/// Unregisters device `dev` of `T` and frees it: `Registration::drop`'s
/// body, and the undo the module's exit calls for a registration never
/// dropped. Process context; takes RTNL, sleeps.
///
/// # Safety
///
/// `dev` is a device registered by `Registration::<T>::register`, taken
/// off [`DEVICES`] by the caller, and torn down by nobody else.
unsafe fn teardown<T: Driver>(dev: *mut ()) {
    let dev = dev.cast::<bindings::net_device>();
    // SAFETY: a device of `T` with our private area, still registered.
    let hook = unsafe { Dev::<T>::from_raw(dev) }
        .state()
        .before_teardown
        .swap(core::ptr::null_mut(), Ordering::AcqRel);
    if !hook.is_null() {
        // SAFETY: stored by set_before_teardown from an `unsafe
        // fn(*mut net_device)`.
        let f = unsafe {
            core::mem::transmute::<*mut (), unsafe fn(*mut bindings::net_device)>(hook)
        };
        // SAFETY: taken (swapped to null) here, so called once, before
        // the device is unregistered, in process context (its contract).
        unsafe { f(dev) };
    }
    // SAFETY: registered by us (contract); unregister_netdev closes the
    // device (`stop`) and waits until no ops run and every reference is
    // gone.
    unsafe { bindings::unregister_netdev(dev) };
    // A driver that left its interrupt requested: free it before the
    // device goes.
    // SAFETY: a device of `T` with our private area, still allocated.
    unsafe { Dev::<T>::from_raw(dev) }.free_irq();
    // SAFETY: unregistered, no handler or op can run any more: drop the
    // private data and free the device.
    unsafe {
        core::ptr::drop_in_place(netdev_priv(dev).cast::<PrivBox<T::Priv>>());
        bindings::free_netdev(dev);
    }
}
