// SPDX-License-Identifier: GPL-2.0

//! The rcan glue layer: the only place where rcan code touches raw kernel
//! pointers.
//!
//! Every rcan module compiles this directory into itself
//! (`#[path = "../../rust/glue/mod.rs"] mod glue;`), together with
//! bindgen's output for the networking headers that the 6.12 `kernel` crate
//! does not cover (`rust/bindings/rcan_bindings.h`). Protocol and driver code
//! above it is safe Rust; each `unsafe` block here says who guarantees it.
//!
//! One file per kernel concept: [`sync`] (RCU, RTNL, C-defined mutexes),
//! [`lock`] (spinlocks and wait queues, each with its own lockdep class),
//! [`skb`] (owned socket buffers, typed by ownership: read-only, sole
//! holder, unique), [`sock`] (socket protocols from a Rust trait),
//! [`netdev`] (network devices from a Rust trait), [`module`] (a
//! module's exit duties, owned by the glue), [`hrtimer`]
//! (high-resolution timers in statics), [`jobtimer`] (timers of jobs
//! allocated at run time, cancelled when dropped), [`pci`] (PCI drivers and BARs),
//! [`isa`] (claimed memory/port windows, interrupt autoprobe), [`percpu`]
//! (per-CPU counters), [`params`] (module parameters of the C shims),
//! [`kmod`] (loading modules on demand), [`net`] (network namespaces),
//! [`ring`] (a driver's fixed-capacity receive queue),
//! [`can`] (the CAN framework: the receive table), [`simcard`]
//! (simulated CAN cards on a simulated bus, for the drivers' simulated
//! front-ends), [`kaddr`] (a kernel object's address as an opaque
//! identity, printed as `%pK`).
#![allow(dead_code)]

#[allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    unreachable_pub,
    missing_docs,
    improper_ctypes,
    unsafe_op_in_unsafe_fn,
    clippy::all,
    rustdoc::all
)]
pub(crate) mod bindings {
    use kernel::ffi;
    include!("../bindings/bindings_generated.rs");
    // The kernel blocklists these so that they map to Rust's own types.
    pub type __kernel_size_t = usize;
    pub type __kernel_ssize_t = isize;
    pub type __kernel_ptrdiff_t = isize;
}

pub(crate) mod can;
pub(crate) mod ctx;
pub(crate) mod hrtimer;
pub(crate) mod iomap;
pub(crate) mod isa;
pub(crate) mod jobtimer;
pub(crate) mod kaddr;
pub(crate) mod kmod;
pub(crate) mod lock;
pub(crate) mod module;
pub(crate) mod net;
pub(crate) mod netdev;
pub(crate) mod params;
pub(crate) mod pci;
pub(crate) mod percpu;
pub(crate) mod procfs;
pub(crate) mod ring;
pub(crate) mod simcard;
pub(crate) mod skb;
pub(crate) mod sock;
pub(crate) mod sync;

use kernel::error::{code, Error};

/// Allocation flags, from the `kernel` crate (bindgen cannot see them).
pub(crate) const GFP_KERNEL: bindings::gfp_t = kernel::bindings::GFP_KERNEL;
pub(crate) const GFP_ATOMIC: bindings::gfp_t = kernel::bindings::GFP_ATOMIC;
/// `GFP_ATOMIC | __GFP_NOWARN`: an atomic allocation whose size a peer
/// chose (a J1939 transport message), which may fail without a warning.
pub(crate) const GFP_ATOMIC_NOWARN: bindings::gfp_t =
    kernel::bindings::GFP_ATOMIC | kernel::bindings::__GFP_NOWARN;

/// This module's `struct module`, for `owner` fields and module references.
pub(crate) fn this_module() -> *mut bindings::module {
    #[allow(improper_ctypes)]
    extern "C" {
        static __this_module: kernel::types::Opaque<bindings::module>;
    }
    // SAFETY: `__this_module` is defined by modpost for every module and
    // lives as long as the module's code; taking its address is always valid.
    unsafe { __this_module.get() }
}

/// A random number (`get_random_u32`). Any context.
pub(crate) fn random_u32() -> u32 {
    // SAFETY: get_random_u32 may be called in any context.
    unsafe { bindings::rcan_get_random_u32() }
}

/// The jiffies counter. Any context.
pub(crate) fn jiffies() -> u64 {
    // SAFETY: reads the global tick counter.
    unsafe { bindings::rcan_jiffies() as u64 }
}

/// `msecs_to_jiffies`. Any context.
pub(crate) fn msecs_to_jiffies(ms: u32) -> i64 {
    // SAFETY: a pure conversion.
    unsafe { bindings::rcan_msecs_to_jiffies(ms) as i64 }
}

/// Converts a negative C return value into an [`Error`].
pub(crate) fn to_result(ret: i32) -> kernel::error::Result<i32> {
    if ret < 0 {
        Err(Error::from_errno(ret))
    } else {
        Ok(ret)
    }
}

/// `EINVAL` and friends as [`Error`]s from the pure crates' positive errnos.
pub(crate) fn errno(positive: i32) -> Error {
    if positive <= 0 {
        return code::EINVAL;
    }
    Error::from_errno(-positive)
}

/// Networking errno values that the 6.12 `kernel` crate does not declare,
/// as functions (`Error::from_errno` is not `const` there).
#[allow(non_snake_case)]
pub(crate) mod neterr {
    use super::{bindings, errno};
    use kernel::error::Error;

    macro_rules! net_errors {
        ($($name:ident),* $(,)?) => {
            $(pub(crate) fn $name() -> Error {
                errno(bindings::$name as i32)
            })*
        };
    }

    net_errors!(
        EADDRINUSE,
        EADDRNOTAVAIL,
        ECONNREFUSED,
        EAFNOSUPPORT,
        EDESTADDRREQ,
        EISCONN,
        EMSGSIZE,
        ENETDOWN,
        ENOBUFS,
        ENOPROTOOPT,
        ENOTCONN,
        EOPNOTSUPP,
        EPROTONOSUPPORT,
        EPROTOTYPE,
        ETIMEDOUT,
    );
}

/// Shortens `v` to `len` elements (6.12's `KVec` has no `truncate`); a
/// `len` beyond the current length does nothing. The elements are `Copy`,
/// so nothing needs dropping.
pub(crate) fn kvec_truncate<T: Copy>(v: &mut kernel::alloc::KVec<T>, len: usize) {
    if len < v.len() {
        // SAFETY: `len` is below the current length; the elements past it
        // are `Copy` (no drop needed) and are simply forgotten.
        unsafe { v.set_len(len) };
    }
}

/// Removes and returns element `idx` of `v`, moving the last element into
/// its place (6.12's `KVec` has no `swap_remove`). `None` if out of range.
pub(crate) fn kvec_swap_remove<T>(v: &mut kernel::alloc::KVec<T>, idx: usize) -> Option<T> {
    let len = v.len();
    if idx >= len {
        return None;
    }
    v.as_mut_slice().swap(idx, len - 1);
    // SAFETY: `len - 1` is in bounds and initialised; after set_len the
    // vector no longer owns that slot, so the value is moved out exactly
    // once.
    unsafe {
        let x = core::ptr::read(v.as_ptr().add(len - 1));
        v.set_len(len - 1);
        Some(x)
    }
}

/// A new box holding a copy of `*v`, copied from `v` straight into the
/// allocation, never through the stack: for tables too large for a
/// kernel stack (CAN_J1939's claim table, 18 KiB, from a `static` empty
/// table), which `KBox::new(value)` may build on the stack first. ENOMEM.
/// Process context with `GFP_KERNEL`.
pub(crate) fn kbox_copy<T: Copy>(
    v: &T,
    flags: kernel::alloc::Flags,
) -> kernel::error::Result<kernel::alloc::KBox<T>> {
    let mut b = kernel::alloc::KBox::<T>::new_uninit(flags)?;
    // SAFETY: `b` is a fresh allocation for one `T`, not overlapping `v`;
    // `T: Copy`, so a bitwise copy is a valid `T` and duplicates nothing
    // that needs dropping. After the copy the box is initialised.
    unsafe {
        core::ptr::copy_nonoverlapping(core::ptr::from_ref(v), b.as_mut_ptr(), 1);
        Ok(b.assume_init())
    }
}

/// Removes every element equal to `x` from `v` (6.12's `KVec` has no
/// `retain`). Order is not kept.
pub(crate) fn kvec_remove_all<T: Copy + PartialEq>(v: &mut kernel::alloc::KVec<T>, x: T) {
    let mut len = v.len();
    let mut i = 0;
    while i < len {
        if v[i] == x {
            v.as_mut_slice().swap(i, len - 1);
            len -= 1;
        } else {
            i += 1;
        }
    }
    // SAFETY: `len <= v.len()`; the elements past it are `Copy` (no drop
    // needed) and are simply forgotten.
    unsafe { v.set_len(len) };
}

/// The `msg_flags` bits of sendmsg and recvmsg (`<linux/socket.h>`) that
/// protocols test and set, named so that protocol code needs no
/// `bindings`.
pub(crate) mod msg {
    use super::bindings;

    /// Out-of-band data (refused by every CAN protocol).
    pub(crate) const OOB: u32 = bindings::MSG_OOB;
    /// Received: the frame came from this host (CAN_RAW, CAN_BCM).
    pub(crate) const DONTROUTE: u32 = bindings::MSG_DONTROUTE;
    /// Received: truncated; asked for in recvmsg: return the full length.
    pub(crate) const TRUNC: u32 = bindings::MSG_TRUNC;
    /// Do not block.
    pub(crate) const DONTWAIT: u32 = bindings::MSG_DONTWAIT;
    /// Received: the frame came from the reading socket itself.
    pub(crate) const CONFIRM: u32 = bindings::MSG_CONFIRM;
    /// Read the error queue.
    pub(crate) const ERRQUEUE: u32 = bindings::MSG_ERRQUEUE;
}
