// SPDX-License-Identifier: GPL-2.0

//! Loading modules on demand: `request_module`, as `af_can` uses it to
//! load a protocol on the first `socket()` that asks for it.

use super::bindings;
use kernel::error::{code, Error, Result};
use kernel::str::CStr;

/// Asks user space to load the module that `name` resolves to (a module
/// name or an alias, as `modprobe NAME` resolves it) and waits until
/// modprobe has finished.
///
/// Process context; sleeps for as long as modprobe runs, so the caller
/// must hold no spinlock, no RCU read-side section, and no lock that the
/// loaded module's init takes (its init runs while we wait).
///
/// `Ok` means modprobe ran and succeeded; it does not mean the module
/// registered what the caller wanted: look again. `ENOENT` if modprobe ran
/// and failed (no module of that name or alias, or its init failed), else
/// the kernel's error (`ENOSYS` without `CONFIG_MODULES`, `EPERM` while
/// module autoloading is disabled, ...).
pub(crate) fn request_module(name: &CStr) -> Result {
    // The helper may sleep, which the documented process context allows
    // (a violation is a might_sleep() report, not memory unsafety).
    // SAFETY: `name` is NUL-terminated and outlives the call; the helper
    // passes it as the argument of a "%s" format, never as the format.
    let ret = unsafe { bindings::rcan_request_module(name.as_char_ptr()) };
    match ret {
        0 => Ok(()),
        r if r < 0 => Err(Error::from_errno(r)),
        // modprobe's exit status: it ran and did not load the module.
        _ => Err(code::ENOENT),
    }
}
