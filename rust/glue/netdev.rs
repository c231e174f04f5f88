// SPDX-License-Identifier: GPL-2.0

//! Network devices.
//!
//! * [`NetDev`]: a borrowed `struct net_device` (inside callbacks).
//! * [`DevRef`]: a counted reference (`dev_hold`/`dev_put`).
//! * [`Driver`] + [`Registration`]: a net_device whose ops are a Rust trait
//!   and whose private area holds `Driver::Priv`. `Registration::drop`
//!   unregisters (process context, takes RTNL) and frees the device.

use super::bindings;
use super::skb::Skb;
use core::marker::PhantomData;
use core::ptr::NonNull;
use kernel::error::{code, Result};
use kernel::prelude::*;

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

    pub(crate) fn ifindex(&self) -> i32 {
        // SAFETY: valid device (type invariant); ifindex is fixed while
        // registered.
        unsafe { (*self.as_ptr()).ifindex }
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

    /// The interface name ("can0").
    pub(crate) fn name(&self) -> &str {
        // SAFETY: valid device; `name` is a NUL-terminated array that only
        // changes under RTNL on rename (a torn read only garbles a log line).
        let name = unsafe { &(*self.as_ptr()).name };
        // SAFETY: c_char and u8 have the same layout.
        let bytes: &[u8] = unsafe { &*(name.as_slice() as *const [ffi::c_char] as *const [u8]) };
        let n = bytes.iter().position(|b| *b == 0).unwrap_or(bytes.len());
        core::str::from_utf8(&bytes[..n]).unwrap_or("?")
    }

    /// Counts a transmitted frame of `bytes` data bytes.
    pub(crate) fn stats_tx(&self, bytes: u32) {
        // SAFETY: valid device; DEV_STATS_* are atomic.
        unsafe { bindings::rcan_dev_stats_tx(self.as_ptr(), bytes) };
    }

    /// Counts a received frame.
    pub(crate) fn stats_rx(&self, bytes: u32) {
        // SAFETY: as above.
        unsafe { bindings::rcan_dev_stats_rx(self.as_ptr(), bytes) };
    }

    pub(crate) fn stats_tx_dropped(&self) {
        // SAFETY: as above.
        unsafe { bindings::rcan_dev_stats_tx_dropped(self.as_ptr()) };
    }

    pub(crate) fn stats_rx_dropped(&self) {
        // SAFETY: as above.
        unsafe { bindings::rcan_dev_stats_rx_dropped(self.as_ptr()) };
    }

    pub(crate) fn start_queue(&self) {
        // SAFETY: valid device.
        unsafe { bindings::rcan_netif_start_queue(self.as_ptr()) };
    }

    pub(crate) fn stop_queue(&self) {
        // SAFETY: valid device.
        unsafe { bindings::rcan_netif_stop_queue(self.as_ptr()) };
    }

    /// Hands a received frame to the network stack (`netif_rx`). Any context.
    pub(crate) fn rx(&self, skb: Skb) {
        let _ = self;
        // SAFETY: netif_rx consumes the skb reference in every case.
        unsafe { bindings::netif_rx(skb.into_raw()) };
    }
}

use kernel::ffi;

/// A counted reference to a network device.
///
/// # Invariants
///
/// Holds one `dev_hold` reference on a valid device.
pub(crate) struct DevRef(NonNull<bindings::net_device>);

// SAFETY: device references may move between threads.
unsafe impl Send for DevRef {}

impl DevRef {
    /// `dev_get_by_index(&init_net, ifindex)`. Process or softirq context.
    pub(crate) fn by_index(ifindex: i32) -> Option<DevRef> {
        // SAFETY: returns a held device or NULL.
        NonNull::new(unsafe { bindings::rcan_dev_get_by_index(ifindex) }).map(DevRef)
    }

    /// The CAN device (ARPHRD_CAN) with the smallest ifindex above `after`.
    pub(crate) fn next_can(after: i32) -> Option<DevRef> {
        // SAFETY: returns a held device or NULL.
        NonNull::new(unsafe { bindings::rcan_next_can_dev(after) }).map(DevRef)
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
        // SAFETY: we own one reference (type invariant).
        unsafe { bindings::rcan_dev_put(self.0.as_ptr()) };
    }
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
/// queue by the kernel's TX lock.
pub(crate) trait Driver: Sized + 'static {
    /// Per-device private data, in the netdev's private area.
    type Priv: Send + Sync;

    fn setup() -> Setup;
    fn open(dev: &NetDev, priv_: &Self::Priv) -> Result;
    fn stop(dev: &NetDev, priv_: &Self::Priv) -> Result;
    fn start_xmit(skb: Skb, dev: &NetDev, priv_: &Self::Priv) -> Xmit;
}

struct Adapter<T: Driver>(PhantomData<T>);

impl<T: Driver> Adapter<T> {
    const OPS: bindings::net_device_ops = bindings::net_device_ops {
        ndo_open: Some(Self::open),
        ndo_stop: Some(Self::stop),
        ndo_start_xmit: Some(Self::start_xmit),
        // SAFETY: all-zero is a valid net_device_ops (every hook NULL).
        ..unsafe { core::mem::zeroed() }
    };

    /// # Safety
    ///
    /// `dev` was allocated by [`Registration::register`] for `T`.
    unsafe fn priv_of<'a>(dev: *mut bindings::net_device) -> &'a T::Priv {
        // SAFETY: the private area holds an initialised `T::Priv` from
        // registration until free (see Registration).
        unsafe { &*bindings::rcan_netdev_priv(dev).cast::<T::Priv>() }
    }

    unsafe extern "C" fn setup(dev: *mut bindings::net_device) {
        let s = T::setup();
        // SAFETY: called by alloc_netdev_mqs on the new, unregistered device.
        unsafe {
            let d = &mut *dev;
            d.type_ = s.type_;
            d.flags = s.flags;
            d.mtu = s.mtu;
            d.min_mtu = s.mtu;
            d.max_mtu = s.mtu;
            d.hard_header_len = s.hard_header_len;
            d.tx_queue_len = s.tx_queue_len;
            d.netdev_ops = &Self::OPS;
        }
    }

    unsafe extern "C" fn open(dev: *mut bindings::net_device) -> ffi::c_int {
        // SAFETY: the kernel passes a registered device of ours.
        let (d, p) = unsafe { (NetDev::from_raw(dev), Self::priv_of(dev)) };
        match T::open(d, p) {
            Ok(()) => 0,
            Err(e) => e.to_errno(),
        }
    }

    unsafe extern "C" fn stop(dev: *mut bindings::net_device) -> ffi::c_int {
        // SAFETY: as in open().
        let (d, p) = unsafe { (NetDev::from_raw(dev), Self::priv_of(dev)) };
        match T::stop(d, p) {
            Ok(()) => 0,
            Err(e) => e.to_errno(),
        }
    }

    unsafe extern "C" fn start_xmit(
        skb: *mut bindings::sk_buff,
        dev: *mut bindings::net_device,
    ) -> bindings::netdev_tx_t {
        // SAFETY: the kernel hands us one skb reference and a registered
        // device of ours.
        let (skb, d, p) = unsafe {
            match Skb::from_raw(skb) {
                Some(s) => (s, NetDev::from_raw(dev), Self::priv_of(dev)),
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
    /// Allocates and registers a device named after `name` ("can%d").
    /// Process context; takes RTNL.
    pub(crate) fn register(name: &CStr, priv_: T::Priv) -> Result<Self> {
        // SAFETY: `name` is NUL-terminated; setup is our trampoline.
        let dev = unsafe {
            bindings::alloc_netdev_mqs(
                core::mem::size_of::<T::Priv>() as i32,
                name.as_char_ptr(),
                bindings::NET_NAME_ENUM as u8,
                Some(Adapter::<T>::setup),
                1,
                1,
            )
        };
        let dev = NonNull::new(dev).ok_or(code::ENOMEM)?;
        // SAFETY: the private area is sized and aligned (NETDEV_ALIGN) for
        // `T::Priv`, and nothing reads it before registration.
        unsafe {
            bindings::rcan_netdev_priv(dev.as_ptr())
                .cast::<T::Priv>()
                .write(priv_)
        };
        // SAFETY: a fully set-up, unregistered device.
        let ret = unsafe { bindings::register_netdev(dev.as_ptr()) };
        if ret < 0 {
            // SAFETY: never registered: drop the private data, free it.
            unsafe {
                core::ptr::drop_in_place(
                    bindings::rcan_netdev_priv(dev.as_ptr()).cast::<T::Priv>(),
                );
                bindings::free_netdev(dev.as_ptr());
            }
            return Err(Error::from_errno(ret));
        }
        // INVARIANT: registered with initialised private data.
        Ok(Registration {
            dev,
            _t: PhantomData,
        })
    }

    pub(crate) fn dev(&self) -> &NetDev {
        // SAFETY: registered device (type invariant) living as long as self.
        unsafe { NetDev::from_raw(self.dev.as_ptr()) }
    }

    pub(crate) fn priv_data(&self) -> &T::Priv {
        // SAFETY: type invariant.
        unsafe { Adapter::<T>::priv_of(self.dev.as_ptr()) }
    }
}

impl<T: Driver> Drop for Registration<T> {
    fn drop(&mut self) {
        // SAFETY: registered by us; unregister_netdev waits until no ops
        // run and every reference is gone, after which the private data can
        // be dropped and the device freed.
        unsafe {
            bindings::unregister_netdev(self.dev.as_ptr());
            core::ptr::drop_in_place(
                bindings::rcan_netdev_priv(self.dev.as_ptr()).cast::<T::Priv>(),
            );
            bindings::free_netdev(self.dev.as_ptr());
        }
    }
}
