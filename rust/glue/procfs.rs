// SPDX-License-Identifier: GPL-2.0

//! Files in `/proc/net`: a protocol's directory ([`ProcDir`], in a
//! `static`) and one read-only file per object in it ([`ProcEntry`]),
//! whose text a [`ProcShow`] callback writes when the file is read
//! (`proc_create_single_data`, `seq_file` with `single_open`). For
//! mainline-compatible views such as `/proc/net/can-bcm/<inode>`.
//!
//! The directory is in the initial network namespace (mainline makes one
//! per namespace).
//!
//! Lifetimes, without trust in the caller:
//!
//! * An entry's data is a `KBox` owned by the [`ProcEntry`]; dropping the
//!   entry first removes the file with `proc_remove`, which waits for
//!   every read that is running its `show` (procfs' `proc_entry_rundown`)
//!   and makes later reads of an already open file fail with EIO; only
//!   then is the data freed. So `show` never sees freed data.
//! * The directory counts its entries. [`ProcDir::remove`] removes it only
//!   when no entry exists and none can be made any more (the count and a
//!   "gone" mark are one atomic word); with entries left it leaves the
//!   directory and returns false. So no entry outlives its parent.

use super::bindings;
use core::fmt;
use core::marker::PhantomData;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicPtr, AtomicUsize, Ordering};
use kernel::alloc::{flags::GFP_KERNEL, KBox};
use kernel::error::{code, Result};
use kernel::ffi;
use kernel::str::CStr;

/// In [`ProcDir::users`]: the directory does not exist (not created yet,
/// or removed); entries cannot be made.
const GONE: usize = 1 << (usize::BITS - 1);

/// A directory `/proc/net/<name>` in a `static`.
pub(crate) struct ProcDir {
    name: &'static CStr,
    /// The directory while it exists (set before `users` leaves GONE).
    pde: AtomicPtr<bindings::proc_dir_entry>,
    /// Entries in it, or GONE.
    users: AtomicUsize,
}

/// Removes the directory when dropped (module exit): see
/// [`ProcDir::remove`].
pub(crate) struct ProcDirReg(&'static ProcDir);

impl Drop for ProcDirReg {
    fn drop(&mut self) {
        if !self.0.remove() {
            kernel::pr_warn!(
                "/proc/net/{} left in place: it still has files\n",
                self.0.name
            );
        }
    }
}

impl ProcDir {
    pub(crate) const fn new(name: &'static CStr) -> Self {
        ProcDir {
            name,
            pde: AtomicPtr::new(core::ptr::null_mut()),
            users: AtomicUsize::new(GONE),
        }
    }

    /// Creates `/proc/net/<name>`. Process context (module init). ENOMEM
    /// if procfs refuses it (for instance, the name exists), EBUSY if this
    /// directory exists already.
    pub(crate) fn create(&'static self) -> Result<ProcDirReg> {
        if !self.pde.load(Ordering::Acquire).is_null() {
            return Err(code::EBUSY);
        }
        // SAFETY: a NUL-terminated 'static name; procfs copies it.
        let p = unsafe { bindings::rcan_proc_net_mkdir(self.name.as_char_ptr()) };
        if p.is_null() {
            return Err(code::ENOMEM);
        }
        if self
            .pde
            .compare_exchange(
                core::ptr::null_mut(),
                p,
                Ordering::AcqRel,
                Ordering::Acquire,
            )
            .is_err()
        {
            // A concurrent create won (two module inits of one static
            // cannot happen, but stay sound): undo ours.
            // SAFETY: `p` is the directory just made, known to nobody.
            unsafe { bindings::rcan_proc_remove(p) };
            return Err(code::EBUSY);
        }
        self.users.store(0, Ordering::Release);
        Ok(ProcDirReg(self))
    }

    /// Removes the directory if it has no entries; marks it gone first,
    /// so that none can be added. False (and the directory stays) while
    /// entries exist. Process context.
    fn remove(&'static self) -> bool {
        if self
            .users
            .compare_exchange(0, GONE, Ordering::AcqRel, Ordering::Acquire)
            .is_err()
        {
            return false;
        }
        let p = self.pde.swap(core::ptr::null_mut(), Ordering::AcqRel);
        if !p.is_null() {
            // SAFETY: the directory made by `create`; no entry is in it and
            // none can be made (GONE), so nothing else refers to it.
            unsafe { bindings::rcan_proc_remove(p) };
        }
        true
    }

    /// Counts a new entry; its directory. None when the directory is gone.
    fn get(&'static self) -> Option<NonNull<bindings::proc_dir_entry>> {
        self.users
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |u| {
                (u & GONE == 0).then_some(u + 1)
            })
            .ok()?;
        // Non-null while `users` is not GONE (stored before `users` left
        // GONE, cleared only after it returned to GONE).
        match NonNull::new(self.pde.load(Ordering::Acquire)) {
            Some(p) => Some(p),
            None => {
                self.put();
                None
            }
        }
    }

    fn put(&'static self) {
        self.users.fetch_sub(1, Ordering::AcqRel);
    }
}

/// What a file shows.
pub(crate) trait ProcShow: Send + Sync + 'static {
    /// Writes the file's text into `m`. Process context (a `read` of the
    /// file; may sleep and take sleeping locks, but not one held around
    /// the drop of this file's [`ProcEntry`], which waits for this call).
    fn show(&self, m: &mut SeqFile<'_>);
}

/// The text of a file being read: `core::fmt::Write` into the
/// `seq_file` (text beyond the buffer makes procfs call `show` again with
/// a larger one).
pub(crate) struct SeqFile<'a> {
    m: NonNull<bindings::seq_file>,
    _call: PhantomData<&'a mut bindings::seq_file>,
}

impl SeqFile<'_> {
    /// Writes `addr` as `%pK` does (hashed, or zeros when kptr_restrict
    /// hides it): the address is printed, never dereferenced.
    pub(crate) fn write_kptr(&mut self, addr: usize) {
        // SAFETY: the seq_file of the running show; %pK only prints.
        unsafe { bindings::rcan_seq_kptr(self.m.as_ptr(), addr as ffi::c_ulong) };
    }
}

impl fmt::Write for SeqFile<'_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        // SAFETY: the seq_file of the running show (valid for 'a); `s` is
        // readable for its length.
        unsafe { bindings::rcan_seq_write(self.m.as_ptr(), s.as_ptr().cast(), s.len()) };
        Ok(())
    }
}

/// A file `/proc/net/<dir>/<name>` showing a `T`.
///
/// # Invariants
///
/// `pde` is the file made by `proc_create_single_data` with
/// `show_trampoline::<T>` and `data` (from `KBox::into_raw`, owned here)
/// as its private data; `dir` counted this entry ([`ProcDir::get`]).
pub(crate) struct ProcEntry<T: ProcShow> {
    dir: &'static ProcDir,
    pde: NonNull<bindings::proc_dir_entry>,
    data: NonNull<T>,
}

// SAFETY: the data is Send + Sync; the entry is removed through procfs,
// which may be done from any thread (process context).
unsafe impl<T: ProcShow> Send for ProcEntry<T> {}
// SAFETY: shared access reaches nothing.
unsafe impl<T: ProcShow> Sync for ProcEntry<T> {}

impl<T: ProcShow> ProcEntry<T> {
    /// Makes the file `name` (mode 0644, as mainline's can-bcm files) in
    /// `dir`, showing `data`. Process context. ENOENT if the directory
    /// does not exist; ENOMEM.
    pub(crate) fn new(dir: &'static ProcDir, name: &CStr, data: T) -> Result<Self> {
        let data = KBox::new(data, GFP_KERNEL)?;
        let parent = dir.get().ok_or(code::ENOENT)?;
        let d = KBox::into_raw(data);
        // SAFETY: `parent` is alive (counted above, see the module
        // documentation); procfs copies `name`; `d` stays valid until the
        // file is removed (Drop).
        let pde = unsafe {
            bindings::rcan_proc_create_single(
                name.as_char_ptr(),
                parent.as_ptr(),
                Some(show_trampoline::<T>),
                d.cast(),
            )
        };
        let Some(pde) = NonNull::new(pde) else {
            // SAFETY: from into_raw above; procfs never saw it.
            drop(unsafe { KBox::from_raw(d) });
            dir.put();
            return Err(code::ENOMEM);
        };
        // INVARIANT: made above; `dir` counted it.
        Ok(ProcEntry {
            dir,
            pde,
            // SAFETY: KBox::into_raw never returns NULL.
            data: unsafe { NonNull::new_unchecked(d) },
        })
    }
}

impl<T: ProcShow> Drop for ProcEntry<T> {
    /// Process context; waits for running reads of the file.
    fn drop(&mut self) {
        // SAFETY: our file (invariant); proc_remove waits for reads that
        // are in `show` and lets no new one start.
        unsafe { bindings::rcan_proc_remove(self.pde.as_ptr()) };
        // SAFETY: from KBox::into_raw (invariant); no reader is left.
        drop(unsafe { KBox::from_raw(self.data.as_ptr()) });
        self.dir.put();
    }
}

/// The `show` of every [`ProcEntry`] file.
///
/// # Safety
///
/// Called by procfs for a file made by `ProcEntry::<T>::new` (the only
/// place that installs this function), whose private data is a live `T`
/// (freed only after `proc_remove` returned).
unsafe extern "C" fn show_trampoline<T: ProcShow>(
    m: *mut bindings::seq_file,
    _v: *mut ffi::c_void,
) -> ffi::c_int {
    let Some(m) = NonNull::new(m) else {
        return 0;
    };
    // SAFETY: single_open stored the file's data as the seq_file's
    // private pointer: a live `T` (this function's contract).
    let data = unsafe { &*(bindings::rcan_seq_private(m.as_ptr()) as *const T) };
    data.show(&mut SeqFile {
        m,
        _call: PhantomData,
    });
    0
}
