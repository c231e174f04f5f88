// SPDX-License-Identifier: GPL-2.0

//! Module parameters, read from safe code.
//!
//! 6.12's `module!` macro has no parameters, so a module's parameters are
//! `module_param`s in its C shim (`*_c.c`). The shim gives Rust one way to
//! read them, the same in every module: it defines
//!
//! ```c
//! #include "rust/helpers/rcan_params.h"
//! u64 rcan_module_param(unsigned int which, unsigned int idx);
//! size_t rcan_module_param_str(unsigned int which, char *buf, size_t len);
//! ```
//!
//! (the second only if the module has string parameters) with this
//! contract, which each shim keeps once for all its parameters:
//!
//! * `rcan_module_param` is defined for **every** `which` and `idx`: an
//!   unknown parameter number or an index past an array's length reads 0.
//!   It reads the value with `READ_ONCE` (a parameter writable through
//!   sysfs may change at any time), has no side effect, takes no lock and
//!   may be called in any context. A signed C value is returned
//!   sign-extended; [`ParamValue`] truncates it back.
//! * `rcan_module_param_str` writes at most `len` bytes into `buf`, the
//!   last of them a NUL when `len > 0` (shorter copies NUL-padded), and
//!   returns the full length of the parameter (0 for NULL or an unknown
//!   `which`), so a caller can refuse a value that did not fit.
//!
//! Numbering: each module names its parameters with `const`s of type
//! [`Param`] (or [`ParamArray`]) whose numbers are the `case` labels of its
//! shim's switch; the value type is the Rust counterpart of the C type
//! (`byte` -> `u8`, `uint` -> `u32`, `int` -> `i32`, `ulong` -> `usize` or
//! `u64`, `bool` -> `bool`). A module that reads a parameter without
//! defining the getter fails to link (modpost reports the undefined
//! symbol); the accessors are `#[inline]`, so modules without parameters
//! never reference the getters.

use core::marker::PhantomData;

extern "C" {
    fn rcan_module_param(which: u32, idx: u32) -> u64;
    fn rcan_module_param_str(which: u32, buf: *mut u8, len: usize) -> usize;
}

/// The raw value of parameter `which`, element `idx`. Any context.
#[inline]
fn raw(which: u32, idx: u32) -> u64 {
    // SAFETY: the shim's getter is defined for every `which` and `idx`,
    // reads with READ_ONCE and may be called in any context (module
    // contract above); it takes no pointers.
    unsafe { rcan_module_param(which, idx) }
}

/// A Rust type a C parameter value converts to.
pub(crate) trait ParamValue: Copy {
    /// The value from the getter's `u64` (the C value, zero- or
    /// sign-extended).
    fn from_raw(raw: u64) -> Self;
}

macro_rules! param_value {
    ($($t:ty),* $(,)?) => {
        $(impl ParamValue for $t {
            #[inline]
            fn from_raw(raw: u64) -> Self {
                // Truncation undoes the getter's extension.
                raw as $t
            }
        })*
    };
}

param_value!(u8, u16, u32, u64, usize, i32);

impl ParamValue for bool {
    #[inline]
    fn from_raw(raw: u64) -> Self {
        raw != 0
    }
}

/// A scalar module parameter of this module's C shim, number `which`.
pub(crate) struct Param<T: ParamValue> {
    which: u32,
    _t: PhantomData<T>,
}

impl<T: ParamValue> Param<T> {
    /// The parameter the shim reads as `case which:`.
    pub(crate) const fn new(which: u32) -> Self {
        Param {
            which,
            _t: PhantomData,
        }
    }

    /// Its current value. Any context.
    #[inline]
    pub(crate) fn get(&self) -> T {
        T::from_raw(raw(self.which, 0))
    }
}

/// An array module parameter (`module_param_array`) of this module's C
/// shim, number `which`; its length is a separate [`Param`].
pub(crate) struct ParamArray<T: ParamValue> {
    which: u32,
    _t: PhantomData<T>,
}

impl<T: ParamValue> ParamArray<T> {
    /// The array the shim reads as `case which:`, element `idx`.
    pub(crate) const fn new(which: u32) -> Self {
        ParamArray {
            which,
            _t: PhantomData,
        }
    }

    /// Element `idx`; 0 past the given elements. Any context.
    #[inline]
    pub(crate) fn get(&self, idx: u32) -> T {
        T::from_raw(raw(self.which, idx))
    }
}

/// A string (`charp`) module parameter of this module's C shim, number
/// `which`.
pub(crate) struct ParamStr {
    which: u32,
}

impl ParamStr {
    /// The parameter the shim's string getter reads as `case which:`.
    pub(crate) const fn new(which: u32) -> Self {
        ParamStr { which }
    }

    /// Copies the value into `buf` (at most `buf.len() - 1` bytes, then
    /// NUL-padded) and returns its full length: a result of `buf.len()` or
    /// more means it did not fit. Process context.
    #[inline]
    pub(crate) fn read(&self, buf: &mut [u8]) -> usize {
        // SAFETY: `buf` is valid for writes of `buf.len()` bytes, and the
        // getter writes at most `len` bytes (module contract above).
        unsafe { rcan_module_param_str(self.which, buf.as_mut_ptr(), buf.len()) }
    }
}
