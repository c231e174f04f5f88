// SPDX-License-Identifier: GPL-2.0

//! Files in `/proc/net`: a protocol's directory in every network
//! namespace ([`NetProcDir`], in a `static`; mainline makes its
//! protocols' directories per namespace, `net->can.bcmproc_dir`) and one
//! read-only file per object in it ([`ProcEntry`]), whose text a
//! [`ProcShow`] callback writes when the file is read
//! (`proc_create_single_data`, `seq_file` with `single_open`). For
//! mainline-compatible views such as `/proc/net/can-bcm/<inode>`.
//!
//! Lifetimes, without trust in the caller:
//!
//! * An entry's data is a `KBox` owned by the [`ProcEntry`]; dropping the
//!   entry first removes the file with `proc_remove`, which waits for
//!   every read that is running its `show` (procfs' `proc_entry_rundown`)
//!   and makes later reads of an already open file fail with EIO; only
//!   then is the data freed. So `show` never sees freed data.
//! * A namespace's directory is shared (`Arc`) by the namespace's data
//!   (a [`Pernet`], dropped at the namespace's exit or when the module
//!   unregisters) and by every entry in it; the last one to go removes
//!   it. So no entry outlives its directory.
//! * An entry also holds a reference on its namespace (`maybe_get_net`):
//!   the namespace's own `/proc/net`, the directory's parent, cannot go
//!   (at the namespace's exit) while a file in it exists.

use super::bindings;
use super::net::{Net, NetRef, Pernet, PernetData, PernetReg};
use super::sync::RcuReadGuard;
use core::fmt;
use core::marker::PhantomData;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicPtr, Ordering};
use kernel::alloc::{flags::GFP_KERNEL, KBox};
use kernel::error::{code, Result};
use kernel::ffi;
use kernel::str::CStr;
use kernel::sync::Arc;

/// A directory `/proc/net/<name>` in every network namespace: a `static`
/// of the module, at most one per module (the namespaces' data behind it
/// is one [`Pernet`] of this file). [`NetProcDir::register`] makes it in
/// every namespace that exists and in each one created later;
/// [`NetProcDir::entry`] makes a file in one namespace's.
pub(crate) struct NetProcDir {
    name: &'static CStr,
}

/// Registered [`NetProcDir`]: dropping it (module exit) removes the
/// directory from every namespace, or, where files are still left in one,
/// when the last of them goes. Process context; sleeps.
pub(crate) struct NetProcDirReg {
    pernet: Option<PernetReg<NetDir>>,
}

impl Drop for NetProcDirReg {
    fn drop(&mut self) {
        // Unregisters: every namespace's data is dropped (after
        // pre_exit and a grace period, see `NetProcDir::entry`).
        drop(self.pernet.take());
        DIR_NAME.store(core::ptr::null_mut(), Ordering::Release);
    }
}

/// The registered directory's name (null while none is): what each
/// namespace's `init` makes.
static DIR_NAME: AtomicPtr<ffi::c_char> = AtomicPtr::new(core::ptr::null_mut());

/// Every namespace's directory.
static NET_DIRS: Pernet<NetDir> = Pernet::new();

/// One namespace's directory: `None` if procfs refused it (sockets work
/// without their files, as in mainline, whose `proc_net_mkdir` failure is
/// not an error either).
struct NetDir {
    dir: Option<Arc<DirInner>>,
}

/// A directory made by `proc_net_mkdir`, removed when the last holder
/// drops it (see the module documentation).
///
/// # Invariants
///
/// `pde` is a directory in a namespace's `/proc/net` that nobody else
/// removes; that `/proc/net` exists while this value does.
struct DirInner {
    pde: NonNull<bindings::proc_dir_entry>,
}

// SAFETY: the directory is only passed to procfs, which locks for itself.
unsafe impl Send for DirInner {}
// SAFETY: shared access reaches nothing but the pointer's value.
unsafe impl Sync for DirInner {}

impl Drop for DirInner {
    /// Process context.
    fn drop(&mut self) {
        // SAFETY: our directory (invariant); no file is left in it, since
        // every file holds this value.
        unsafe { bindings::rcan_proc_remove(self.pde.as_ptr()) };
    }
}

impl PernetData for NetDir {
    fn pernet() -> &'static Pernet<Self> {
        &NET_DIRS
    }

    /// Process context (namespace creation, or registration).
    fn init(net: &Net) -> Result<Self> {
        let name = DIR_NAME.load(Ordering::Acquire);
        if name.is_null() {
            return Ok(NetDir { dir: None });
        }
        // SAFETY: `net` is being set up or alive (the pernet core calls
        // init with a valid namespace); `name` is a registered 'static
        // NUL-terminated name, which procfs copies.
        let pde = unsafe { bindings::rcan_proc_net_mkdir(net.as_ptr(), name) };
        // INVARIANT: a new directory in `net`'s /proc/net, which lives
        // until `net`'s exit; this value is dropped before that (the
        // namespace's data) or holds `net` (inside an entry's NetHold).
        // An Arc that cannot be allocated drops the value: the directory
        // is removed at once.
        let dir = NonNull::new(pde).and_then(|pde| Arc::new(DirInner { pde }, GFP_KERNEL).ok());
        Ok(NetDir { dir })
    }
}

impl NetProcDir {
    pub(crate) const fn new(name: &'static CStr) -> Self {
        NetProcDir { name }
    }

    /// Makes `/proc/net/<name>` in every namespace, now and in those
    /// created later. Process context (module init). EBUSY if this
    /// module has registered one already.
    pub(crate) fn register(&'static self) -> Result<NetProcDirReg> {
        let name = self.name.as_char_ptr().cast_mut();
        DIR_NAME
            .compare_exchange(
                core::ptr::null_mut(),
                name,
                Ordering::AcqRel,
                Ordering::Acquire,
            )
            .map_err(|_| code::EBUSY)?;
        // Why no `get` can run into dropped data: `Pernet::get` of
        // NET_DIRS runs only in `entry`, inside an RCU read-side section.
        // Dropping the registration clears the flag `get` checks first,
        // then unregisters, and the pernet core lets a grace period pass
        // between `pre_exit` and `exit` (which drops the data): a `get`
        // that saw the flag set ends before any data is dropped; one that
        // starts later sees it clear.
        // SAFETY: `register`'s contract holds by the argument above.
        let reg = unsafe { NET_DIRS.register() };
        match reg {
            Ok(r) => Ok(NetProcDirReg { pernet: Some(r) }),
            Err(e) => {
                DIR_NAME.store(core::ptr::null_mut(), Ordering::Release);
                Err(e)
            }
        }
    }

    /// Makes the file `name` (mode 0644, as mainline's can-bcm files) in
    /// `net`'s directory, showing `data`. Process context. ENOENT if
    /// `net` has no directory (not registered, procfs refused it, or the
    /// namespace is going away); ENOMEM.
    pub(crate) fn entry<T: ProcShow>(
        &'static self,
        net: &Net,
        name: &CStr,
        data: T,
    ) -> Result<ProcEntry<T>> {
        let dir = {
            let _rcu = RcuReadGuard::new();
            NET_DIRS.get(net).and_then(|d| d.dir.clone())
        }
        .ok_or(code::ENOENT)?;
        let hold = NetHold {
            dir: Some(dir),
            _net: net.hold().ok_or(code::ENOENT)?,
        };
        ProcEntry::new(hold, name, data)
    }
}

/// What a file holds of its place: its directory and a reference on the
/// directory's namespace, dropped in that order.
///
/// `dir` (`Some` until dropped) is a directory in `_net`'s /proc/net.
struct NetHold {
    dir: Option<Arc<DirInner>>,
    _net: NetRef,
}

impl Drop for NetHold {
    /// Process context.
    fn drop(&mut self) {
        // The directory first (possibly its removal), while its parent is
        // held alive by `net`, dropped after this.
        drop(self.dir.take());
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

impl<'a> SeqFile<'a> {
    /// Proof of process context: a `show` runs in the reading task's
    /// process context (`seq_read`), for the whole call (`'a`).
    pub(crate) fn process(&self) -> &'a super::ctx::Process {
        super::ctx::Process::PROOF
    }
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

/// A file `/proc/net/<dir>/<name>` showing a `T`, made by
/// [`NetProcDir::entry`].
///
/// # Invariants
///
/// `pde` is the file made by `proc_create_single_data` with
/// `show_trampoline::<T>` and `data` (from `KBox::into_raw`, owned here)
/// as its private data, in the directory `hold` holds.
pub(crate) struct ProcEntry<T: ProcShow> {
    pde: NonNull<bindings::proc_dir_entry>,
    data: NonNull<T>,
    /// Dropped after the file is removed (Drop's body runs first).
    hold: NetHold,
}

// SAFETY: the data is Send + Sync; the entry is removed through procfs,
// which may be done from any thread (process context).
unsafe impl<T: ProcShow> Send for ProcEntry<T> {}
// SAFETY: shared access reaches nothing.
unsafe impl<T: ProcShow> Sync for ProcEntry<T> {}

impl<T: ProcShow> ProcEntry<T> {
    /// Makes the file `name` in `hold`'s directory. Process context.
    /// ENOENT without a directory; ENOMEM.
    fn new(hold: NetHold, name: &CStr, data: T) -> Result<Self> {
        let parent = hold.dir.as_ref().ok_or(code::ENOENT)?.pde;
        let data = KBox::new(data, GFP_KERNEL)?;
        let d = KBox::into_raw(data);
        // SAFETY: `parent` is alive while `hold` is (DirInner invariant);
        // procfs copies `name`; `d` stays valid until the file is removed
        // (Drop).
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
            return Err(code::ENOMEM);
        };
        // INVARIANT: made above, in `hold`'s directory.
        Ok(ProcEntry {
            pde,
            // SAFETY: KBox::into_raw never returns NULL.
            data: unsafe { NonNull::new_unchecked(d) },
            hold,
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
        // `hold` is dropped after this body: the directory and the
        // namespace go after the file.
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
