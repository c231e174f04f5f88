// SPDX-License-Identifier: GPL-2.0

//! The incremental receive table (mainline `af_can.c`'s receive lists):
//! which receivers want a frame. One [`RxTable`] exists, a static of
//! `rcan_pf`; every protocol's sockets and every in-kernel receiver are
//! registrations in it.
//!
//! Layout (where each filter goes is pure logic, `rcan_core::rxtable`,
//! host-tested against a naive model):
//!
//! * `buckets`: `1 << BUCKET_BITS` RCU lists of [`KeyEntry`]s, one per
//!   distinct key `(ifindex, mask, id & mask)` in use, each with the list
//!   of hashed filter [`Node`]s (one per socket filter) that want it.
//!   `groups` (an RCU-published snapshot) lists the distinct
//!   `(ifindex, mask)` pairs in use, so a frame costs one probe per group
//!   of its interface and of "all interfaces", and a probe walks distinct
//!   keys, never the sockets of another id that shares the bucket.
//! * `scanned`: per registration, at most one node holding its filters
//!   that cannot be hashed (or all of them, joined), tested one by one.
//! * `err`: per registration, at most one node with its error mask.
//! * `by_if`: per registration with frame filters, one node hashed by
//!   interface, for drivers computing their hardware filter.
//! * `rcvs` (writer side only): the receivers, hashed by id and chained
//!   through the receivers themselves, so a new receiver is added without
//!   an allocation and a socket's registration is found without a scan;
//!   a reserved receiver's owner names it by its [`RcvHandle`] instead,
//!   and then the map is not walked at all (only linked to and unlinked
//!   from, at reservation and final removal).
//!
//! Each registration belongs to a *receiver* ([`Receiver::id`]); a
//! receiver has at most one live registration, and replacing it links the
//! new nodes before unlinking the old, so no frame that both want is
//! missed. A receiver's per-CPU "seen" mark, shared by its successive
//! registrations, makes every frame reach a receiver at most once, however
//! many of its nodes match (mainline's raw.c keeps the same mark per
//! socket).
//!
//! Concurrency:
//!
//! * Readers ([`RxTable::for_each_match`], [`RxTable::filters`]) take no
//!   lock: they walk the lists inside an RCU read-side section.
//! * Writers ([`RxTable::set`], process context) are serialised by the
//!   table's own mutex (`writer`, a `DEFINE_MUTEX` of the owning module's C
//!   file, so it has a lockdep class of its own). They link and unlink
//!   nodes with release stores; unlinked registrations (with their nodes),
//!   key entries left without members and replaced group snapshots are
//!   freed by `call_rcu` callbacks
//!   (softirq), so no writer waits for a grace period.
//! * A registration is reached from a node only while the node is
//!   reachable or a grace period has not passed since it was unlinked; the
//!   receiver outlives all of its registrations (freed with the last).
//!   A receiver's first registration is allocated inside it (see
//!   [`Rcv`]), so a socket's bind allocates one object and its close
//!   frees one.

use super::super::bindings;
use super::super::percpu::{rx_stamp, CpuMarks};
use super::super::sync::{CMutex, RcuPtr, RcuReadGuard, StaticMutex};
use crate::rcan_core::arb::CAN_ERR_FLAG;
use crate::rcan_core::rxtable::{self, frame_key, Filter, Place, BUCKET_BITS};
use core::cell::{Cell, UnsafeCell};
use core::ptr::{self, NonNull};
use core::sync::atomic::{AtomicPtr, Ordering};
use kernel::alloc::{flags::GFP_KERNEL, KBox, KVBox, KVec};
use kernel::error::Result;

const NBUCKETS: usize = 1 << BUCKET_BITS;
/// Interface lists for [`RxTable::filters`] (a power of two).
const IF_BUCKETS: usize = 64;
/// Receiver map buckets of the writer side (a power of two): a few
/// receivers per chain at 10,000 sockets, so finding a socket's receiver
/// touches one or two of them.
const ID_BUCKETS: usize = 4096;

/// What the table's user keeps per receiver: typically the callback and
/// its owner. Dropped when the receiver's last registration is freed: in
/// a `call_rcu` callback (softirq) once it was published, else in the
/// writer's process context.
pub(crate) trait Receiver: Send + Sync + 'static {
    /// The receiver's identity: at most one live registration per id.
    fn id(&self) -> usize;
}

/// A registration's frame filters: one kept inline, more in a vector, so
/// the common registration (a socket with one filter) allocates nothing
/// for them. Derefs to the slice of filters.
pub(crate) struct Filters {
    /// The only filter, if there is one and `more` was never allocated.
    one: Option<Filter>,
    /// Every filter, once there are two (or room for two was reserved).
    more: KVec<Filter>,
}

impl Filters {
    /// No filters.
    const fn new() -> Self {
        Filters {
            one: None,
            more: KVec::new(),
        }
    }

    /// A copy of `fs`: one filter inline, more in a vector. Process
    /// context (may allocate and sleep).
    fn from_slice(fs: &[Filter]) -> Result<Self> {
        match fs {
            [] => Ok(Filters::new()),
            [f] => Ok(Filters {
                one: Some(*f),
                more: KVec::new(),
            }),
            _ => {
                let mut more = KVec::with_capacity(fs.len(), GFP_KERNEL)?;
                more.extend_from_slice(fs, GFP_KERNEL)?;
                Ok(Filters { one: None, more })
            }
        }
    }
}

impl core::ops::Deref for Filters {
    type Target = [Filter];

    fn deref(&self) -> &[Filter] {
        match &self.one {
            Some(f) => core::slice::from_ref(f),
            None => &self.more,
        }
    }
}

/// What a registration asks for. Borrowed: the table copies what it
/// keeps (the filters, into the registration).
#[derive(Clone, Copy)]
pub(crate) struct Spec<'a> {
    /// Interface, 0 = all.
    pub(crate) ifindex: i32,
    /// Filters for data and remote frames (none: no such frames), in the
    /// table's own form.
    pub(crate) filters: &'a [Filter],
    /// Deliver only frames that pass every filter.
    pub(crate) join: bool,
    /// Error classes wanted (0: no error frames).
    pub(crate) err_mask: u32,
    /// Handed to the receiver with every frame.
    pub(crate) cookie: u32,
}

/// What a [`RxTable::set`] changed, for the drivers that follow the
/// filters of their interface.
#[derive(Clone, Copy, Default)]
pub(crate) struct Changed {
    /// Interfaces whose wanted filters changed (0 = all interfaces).
    pub(crate) ifindex: [Option<i32>; 2],
    /// A receiver was removed entirely (its last registration retired).
    pub(crate) removed: bool,
}

/// A receiver made by [`RxTable::reserve`], named without a lookup: its
/// owner keeps it from the reservation until it removes the receiver for
/// good ([`RxTable::set_reserved`] with `keep` false), and hands it to
/// every [`RxTable::set_reserved`] in between, which then walks no
/// receiver map. Opaque above the glue; crosses the module boundary as a
/// raw pointer ([`RcvHandle::into_raw`], [`RcvHandle::from_raw`]).
///
/// # Invariants
///
/// Points at a receiver of one table, leaked from its KBox and on that
/// table's receiver map (not removed for good).
pub(crate) struct RcvHandle(NonNull<core::ffi::c_void>);

impl RcvHandle {
    /// The receiver's address, for the C interface.
    pub(crate) fn into_raw(self) -> *mut core::ffi::c_void {
        self.0.as_ptr()
    }

    /// The handle `into_raw` gave.
    ///
    /// # Safety
    ///
    /// `p` came from [`RcvHandle::into_raw`] of a handle of a table of
    /// receivers of the type the caller will use it with, and its receiver
    /// has not been removed for good since (no `set_reserved` with `keep`
    /// false on it).
    pub(crate) unsafe fn from_raw(p: NonNull<core::ffi::c_void>) -> Self {
        // INVARIANT: the caller's contract.
        RcvHandle(p)
    }
}

/// Which list a node is on.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Hashed,
    Scanned,
    Err,
    ByIf,
}

/// The link fields of an element of an RCU [`List`].
struct Link<T> {
    /// Next element (RCU: readers follow it with acquire loads).
    next: AtomicPtr<T>,
    /// Writer side only (under `writer`): the link that points at us.
    pprev: Cell<*const AtomicPtr<T>>,
}

impl<T> Link<T> {
    const fn new() -> Self {
        Link {
            next: AtomicPtr::new(ptr::null_mut()),
            pprev: Cell::new(ptr::null()),
        }
    }
}

/// An element of an RCU [`List`].
trait Linked: Sized {
    fn link(&self) -> &Link<Self>;
}

/// A filter, scanned, error or interface entry of a registration. Lives
/// inside its registration's `nodes` (allocated with its final capacity
/// before linking, so never moved while linked).
struct Node<R: Receiver> {
    link: Link<Node<R>>,
    kind: Kind,
    ifindex: i32,
    /// Hashed: group mask; Err: error mask.
    mask: u32,
    /// Hashed: `id & mask`.
    value: u32,
    reg: *const Reg<R>,
    /// Hashed, writer side only: the key entry whose `members` we are on
    /// (before linking: the linked entry `new_keys` found, or NULL).
    key: Cell<*const KeyEntry<R>>,
}

impl<R: Receiver> Linked for Node<R> {
    fn link(&self) -> &Link<Self> {
        &self.link
    }
}

impl<R: Receiver> Node<R> {
    /// An unlinked node of no registration yet (`reg` NULL until the
    /// registration is placed, [`Reg::place`], or the common bind sets
    /// it): for the general path and the common bind's alike.
    fn new(kind: Kind, ifindex: i32, mask: u32, value: u32) -> Self {
        Node {
            link: Link::new(),
            kind,
            ifindex,
            mask,
            value,
            reg: ptr::null(),
            key: Cell::new(ptr::null()),
        }
    }
}

/// One distinct hash key `(ifindex, mask, value)` in a bucket, with the
/// hashed nodes of every registration that wants it: a frame walks the
/// distinct keys of its bucket, not every socket's filter, so receivers of
/// a popular id do not slow down frames that merely share its bucket.
/// Freed by `call_rcu` once its last member is unlinked.
#[repr(C)]
struct KeyEntry<R: Receiver> {
    /// For call_rcu; first, so the callback finds the entry.
    rcu: bindings::callback_head,
    link: Link<KeyEntry<R>>,
    ifindex: i32,
    mask: u32,
    value: u32,
    members: List<Node<R>>,
    /// Writer side only: number of members.
    count: Cell<usize>,
}

impl<R: Receiver> KeyEntry<R> {
    /// A new, unlinked entry without members. Process context (may
    /// allocate and sleep). ENOMEM.
    fn new_boxed(ifindex: i32, mask: u32, value: u32) -> Result<KBox<Self>> {
        Ok(KBox::new(
            KeyEntry {
                // SAFETY: an all-zero callback_head is what call_rcu
                // expects.
                rcu: unsafe { core::mem::zeroed() },
                link: Link::new(),
                ifindex,
                mask,
                value,
                members: List::new(),
                count: Cell::new(0),
            },
            GFP_KERNEL,
        )?)
    }
}

impl<R: Receiver> Linked for KeyEntry<R> {
    fn link(&self) -> &Link<Self> {
        &self.link
    }
}

/// An RCU list (the kernel's `hlist` discipline: readers only follow
/// `next`; writers, serialised, keep `pprev`).
struct List<T: Linked> {
    first: AtomicPtr<T>,
}

impl<T: Linked> List<T> {
    const fn new() -> Self {
        List {
            first: AtomicPtr::new(ptr::null_mut()),
        }
    }

    /// The elements, for as long as the read-side section lasts.
    fn iter<'g>(&'g self, _g: &'g RcuReadGuard) -> impl Iterator<Item = &'g T> + 'g {
        let mut p = self.first.load(Ordering::Acquire);
        core::iter::from_fn(move || {
            // `p` was read from a link reachable in this read-side section:
            // elements are published (release) after they are initialised.
            // SAFETY: freed only a grace period after being unlinked, which
            // `_g` prevents from ending; see above for initialisation.
            let n = unsafe { p.as_ref() }?;
            p = n.link().next.load(Ordering::Acquire);
            Some(n)
        })
    }

    /// The elements, for the writer.
    ///
    /// # Safety
    ///
    /// The caller holds the table's writer mutex for `'w` (nothing is
    /// unlinked or freed meanwhile).
    unsafe fn iter_locked<'w>(&'w self) -> impl Iterator<Item = &'w T> + 'w {
        let mut p = self.first.load(Ordering::Acquire);
        core::iter::from_fn(move || {
            // SAFETY: linked elements, which only the writer (the caller,
            // for 'w) unlinks or frees.
            let n = unsafe { p.as_ref() }?;
            p = n.link().next.load(Ordering::Acquire);
            Some(n)
        })
    }

    /// Links `n` at the head.
    ///
    /// # Safety
    ///
    /// The caller holds the table's writer mutex; `n` is initialised, not
    /// linked, and stays at its address until a grace period after it is
    /// unlinked.
    unsafe fn push(&self, n: &T) {
        let first = self.first.load(Ordering::Relaxed);
        n.link().next.store(first, Ordering::Relaxed);
        n.link().pprev.set(&self.first);
        // SAFETY: `first` is NULL or a linked element; writers are
        // serialised (caller), so its `pprev` is ours to change.
        if let Some(f) = unsafe { first.as_ref() } {
            f.link().pprev.set(&n.link().next);
        }
        // rcu_assign_pointer: the element's fields before the link.
        self.first.store(n as *const T as *mut T, Ordering::Release);
    }

    /// Unlinks `n` (`hlist_del_rcu`); readers on it may still follow its
    /// `next`.
    ///
    /// # Safety
    ///
    /// The caller holds the table's writer mutex and `n` is linked.
    unsafe fn unlink(n: &T) {
        let next = n.link().next.load(Ordering::Relaxed);
        // SAFETY: `pprev` points at the live link to `n` (list head or the
        // previous element's `next`), maintained under the writer mutex.
        unsafe { (*n.link().pprev.get()).store(next, Ordering::Release) };
        // SAFETY: `next` is NULL or a linked element (writer mutex held).
        if let Some(x) = unsafe { next.as_ref() } {
            x.link().pprev.set(n.link().pprev.get());
        }
    }
}

/// A receiver: the user's data and its per-CPU "seen" mark, its first
/// registration, and, for the writer only, its place in the receiver map
/// and its live registration.
///
/// The first registration (a socket's bind) lives inside the receiver, so
/// a new receiver costs one allocation, not two, and its removal one
/// `call_rcu` and one free; a receiver made ahead of time
/// ([`RxTable::reserve`], at `socket()`) makes that first registration
/// allocate nothing. Later registrations (filter changes) are boxed on
/// their own; the inline one, once replaced, is never reused and is freed
/// with the receiver, after the last registration's grace period (which
/// ends after the inline one's, unlinked earlier).
#[repr(C)]
struct Rcv<R: Receiver> {
    /// For call_rcu when the inline registration is retired as the last
    /// one; first, so the callback finds the receiver.
    rcu: bindings::callback_head,
    data: R,
    seen: CpuMarks,
    /// Writer side only: the chain of the receiver map (`RxTable::rcvs`)
    /// the receiver is on from its reservation or first registration
    /// until its removal.
    chain: Link<Rcv<R>>,
    /// Writer side only: made by [`RxTable::reserve`], whose caller holds
    /// an [`RcvHandle`] to it: then only [`RxTable::set_reserved`] with
    /// `keep` false removes it for good, and `set(id, None)` only retires
    /// its registration (so the handle stays valid).
    reserved: Cell<bool>,
    /// Writer side only: the live registration (NULL: a reserved
    /// receiver that has had none yet, or whose registration was retired
    /// with `keep`, [`RxTable::set_reserved`]).
    reg: Cell<*const Reg<R>>,
    /// The table the receiver is in, which outlives it (a static, or a
    /// namespace's table, freed at the namespace's exit after its
    /// sockets): [`RxTable::set_reserved`] finds it from the handle, with
    /// no namespace lookup.
    table: NonNull<RxTable<R>>,
    /// Writer side only: `first` has been filled (and stays so, even once
    /// replaced, until the receiver is freed; cleared again only if its
    /// linking could not be prepared, ENOMEM, before any node was linked).
    first_used: Cell<bool>,
    /// The first registration. Unused (`first_used` false) it is the
    /// empty registration ([`Reg::empty`]): no filters, no nodes, so that
    /// the first registration is written into it field by field, where it
    /// stays, instead of being built elsewhere and moved in (~230 bytes).
    /// Filled once, under the writer mutex, before any of its nodes is
    /// linked, and never changed afterwards (then only read, through the
    /// table's lists and `reg`).
    first: UnsafeCell<Reg<R>>,
}

impl<R: Receiver> Rcv<R> {
    /// A receiver of `table` without registration. Process context (may
    /// allocate).
    fn new(data: R, table: &RxTable<R>) -> Result<Self> {
        Ok(Rcv {
            // SAFETY: an all-zero callback_head is what call_rcu expects.
            rcu: unsafe { core::mem::zeroed() },
            data,
            seen: CpuMarks::new()?,
            chain: Link::new(),
            reserved: Cell::new(false),
            reg: Cell::new(ptr::null()),
            table: NonNull::from(table),
            first_used: Cell::new(false),
            first: UnsafeCell::new(Reg::empty()),
        })
    }

    /// The inline first registration, if filled. Writer mutex held (the
    /// slot is filled only under it).
    fn first(&self) -> Option<&Reg<R>> {
        // SAFETY: the slot is written only under the writer mutex that our
        // caller holds (filled while unused, emptied before anything of it
        // was linked); a filled slot is never written again.
        self.first_used.get().then(|| unsafe { &*self.first.get() })
    }

    /// Whether `reg` is this receiver's inline first registration. Writer
    /// mutex held.
    fn is_first(&self, reg: &Reg<R>) -> bool {
        self.first().is_some_and(|f| ptr::eq(f, reg))
    }

    /// The unused first slot, to be written in place; the caller marks it
    /// used ([`Rcv::first_used`]) once written, and places it.
    ///
    /// # Safety
    ///
    /// The caller holds the writer mutex, the slot is unused, no other
    /// reference into it is live, and `self` is at its final address
    /// (leaked from its KBox).
    #[allow(clippy::mut_from_ref)]
    unsafe fn first_slot(&self) -> &mut Reg<R> {
        // An unused slot: readers reach a registration only through its
        // linked nodes, and it has none; the caller holds no other reference.
        // SAFETY: so nothing refers into the slot, and the writer mutex
        // (caller) excludes other writers.
        unsafe { &mut *self.first.get() }
    }

    /// Puts `reg` into the unused first slot and places it there
    /// ([`Reg::place`]); returns it, to be linked.
    ///
    /// # Safety
    ///
    /// As for [`Rcv::first_slot`].
    unsafe fn fill_first(&self, reg: Reg<R>) -> &Reg<R> {
        // SAFETY: the caller's contract.
        let f = unsafe { self.first_slot() };
        *f = reg;
        // SAFETY: `f` is our own first slot, freed with us.
        unsafe { f.place(NonNull::from(self)) };
        self.first_used.set(true);
        f
    }

    /// Builds the registration for `spec` in the unused first slot
    /// ([`RxTable::make_reg_into`]) and places it ([`Reg::place`]);
    /// returns it, to be linked. On error the slot stays unused.
    ///
    /// # Safety
    ///
    /// As for [`Rcv::first_slot`].
    unsafe fn fill_first_with(&self, spec: &Spec<'_>) -> Result<&Reg<R>> {
        // SAFETY: the caller's contract.
        let f = unsafe { self.first_slot() };
        RxTable::<R>::make_reg_into(spec, f)?;
        // SAFETY: `f` is our own first slot, freed with us.
        unsafe { f.place(NonNull::from(self)) };
        self.first_used.set(true);
        Ok(f)
    }

    /// Empties the first slot again, after [`Rcv::fill_first_with`] when
    /// linking its registration cannot be prepared (ENOMEM).
    ///
    /// # Safety
    ///
    /// The caller holds the writer mutex, and the slot's registration was
    /// never linked and is no longer referred to.
    unsafe fn empty_first(&self) {
        self.first_used.set(false);
        // SAFETY: never linked, so no reader or node refers to it; no
        // reference into the slot is live (caller's contract).
        unsafe { *self.first.get() = Reg::empty() };
    }
}

impl<R: Receiver> Linked for Rcv<R> {
    fn link(&self) -> &Link<Self> {
        &self.chain
    }
}

/// One registration of a receiver.
#[repr(C)]
struct Reg<R: Receiver> {
    /// For call_rcu; first, so the callback finds the registration.
    rcu: bindings::callback_head,
    rcv: NonNull<Rcv<R>>,
    /// Set when a boxed registration is retired as its receiver's last
    /// one: the RCU callback then frees the receiver too. (The inline first
    /// registration is never freed on its own; see [`Rcv`].)
    last: Cell<bool>,
    cookie: u32,
    ifindex: i32,
    /// Every frame filter, for [`RxTable::filters`].
    filters: Filters,
    /// The scanned node's filters.
    scanned: KVec<Filter>,
    /// The scanned node's filters must all pass.
    join: bool,
    nodes: Nodes<R>,
}

/// Inline room for a registration's nodes: a socket with one filter has
/// two (its key's member and its interface entry); more (an error mask,
/// more filters) go to `more`, so the common bind allocates no node
/// vector. Two, not three: with three a registration no longer fits
/// kmalloc-256 and takes 512 bytes.
const INLINE_NODES: usize = 2;

/// A registration's nodes. Filled before any is linked and never changed
/// afterwards, so their addresses (inside the boxed registration, or in
/// `more`'s buffer) stay put while linked.
struct Nodes<R: Receiver> {
    inline: [Option<Node<R>>; INLINE_NODES],
    more: KVec<Node<R>>,
}

impl<R: Receiver> Nodes<R> {
    fn new() -> Self {
        Nodes {
            inline: [const { None }; INLINE_NODES],
            more: KVec::new(),
        }
    }

    /// Adds a node. Only before the registration is linked.
    fn push(&mut self, n: Node<R>) -> Result {
        match self.inline.iter_mut().find(|s| s.is_none()) {
            Some(slot) => *slot = Some(n),
            None => self.more.push(n, GFP_KERNEL)?,
        }
        Ok(())
    }

    fn iter(&self) -> impl Iterator<Item = &Node<R>> {
        self.inline.iter().flatten().chain(self.more.iter())
    }

    fn iter_mut(&mut self) -> impl Iterator<Item = &mut Node<R>> {
        self.inline.iter_mut().flatten().chain(self.more.iter_mut())
    }

    fn len(&self) -> usize {
        self.iter().count()
    }
}

impl<R: Receiver> Reg<R> {
    /// The empty registration: no filters, no nodes, not placed. What an
    /// unused first slot holds ([`Rcv::first`]) and what the general path
    /// fills ([`RxTable::make_reg_into`]).
    fn empty() -> Self {
        Reg {
            // SAFETY: an all-zero callback_head is what call_rcu expects.
            rcu: unsafe { core::mem::zeroed() },
            rcv: NonNull::dangling(),
            last: Cell::new(false),
            cookie: 0,
            ifindex: 0,
            filters: Filters::new(),
            scanned: KVec::new(),
            join: false,
            nodes: Nodes::new(),
        }
    }

    fn rcv(&self) -> &Rcv<R> {
        // SAFETY: the receiver is freed only with (after) its last
        // registration.
        unsafe { self.rcv.as_ref() }
    }

    /// Points the registration at its receiver and its nodes at the
    /// registration, once it is at its final address (boxed, or inside its
    /// receiver). Before it is linked.
    ///
    /// # Safety
    ///
    /// `rcv` is the receiver this registration belongs to (it sits in its
    /// first slot, or is boxed for it), which is freed only with or after
    /// its last registration: [`Reg::rcv`] dereferences it.
    unsafe fn place(&mut self, rcv: NonNull<Rcv<R>>) {
        self.rcv = rcv;
        let me: *const Reg<R> = self;
        for n in self.nodes.iter_mut() {
            n.reg = me;
        }
    }
}

/// The published list of hashed groups `(ifindex, mask)`.
#[repr(C)]
struct Groups {
    rcu: bindings::callback_head,
    list: KVec<(i32, u32)>,
}

/// The writer side, under `writer`.
struct Writer {
    /// Hashed groups with their number of nodes; mirrors `groups` but for
    /// groups whose count fell to 0 and are still published.
    groups: KVec<(i32, u32, usize)>,
}

/// The receive table. See the module documentation.
pub(crate) struct RxTable<R: Receiver> {
    writer: CMutex<Writer>,
    /// The receiver map, writer side only (under `writer`): receivers
    /// hashed by id, chained through [`Rcv::chain`]; a receiver is on it
    /// from its reservation or first registration until its removal. Intrusive,
    /// so adding a receiver allocates nothing and removing one searches
    /// nothing but its chain.
    rcvs: [List<Rcv<R>>; ID_BUCKETS],
    buckets: [List<KeyEntry<R>>; NBUCKETS],
    scanned: List<Node<R>>,
    err: List<Node<R>>,
    by_if: [List<Node<R>>; IF_BUCKETS],
    groups: RcuPtr<Groups>,
}

// SAFETY: shared access to nodes, registrations and receivers is read-only
// (but for the atomic links and the per-CPU marks); `R: Sync`. Writer-only
// cells (`pprev`, `last`, `reg`) and the receiver map are touched under the
// writer mutex only.
unsafe impl<R: Receiver> Sync for RxTable<R> {}
// SAFETY: plain data once published; freed by an RCU callback.
unsafe impl Send for Groups {}
// SAFETY: read-only once published.
unsafe impl Sync for Groups {}

fn if_bucket(ifindex: i32) -> usize {
    (ifindex as u32 as usize) & (IF_BUCKETS - 1)
}

fn id_bucket(id: usize) -> usize {
    ((id as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - ID_BUCKETS.trailing_zeros())) as usize
}

/// Whether `s` wants anything (frames or error frames); a spec that does
/// not removes its receiver's registration.
fn wants(s: &Spec<'_>) -> bool {
    !s.filters.is_empty() || s.err_mask != 0
}

/// `call_rcu` callback: frees a retired registration, its nodes and, if it
/// was the last one, its receiver. Softirq context.
unsafe extern "C" fn free_reg<R: Receiver>(head: *mut bindings::callback_head) {
    // SAFETY: `head` is the first field of a `Reg<R>` leaked from a KBox
    // by `retire`; its nodes were unlinked before, and the grace period
    // since then has ended, so no reader can still reach it.
    let reg = unsafe { KBox::from_raw(head.cast::<Reg<R>>()) };
    if reg.last.get() {
        // SAFETY: leaked from a KBox when the receiver was made; this was
        // its last registration, so nothing else refers to it.
        drop(unsafe { KBox::from_raw(reg.rcv.as_ptr()) });
    }
}

/// `call_rcu` callback: frees a receiver whose inline first registration
/// was its last (with that registration), or a reserved receiver removed
/// for good after its registrations were retired (`keep`). Softirq
/// context.
unsafe extern "C" fn free_rcv<R: Receiver>(head: *mut bindings::callback_head) {
    // Its last registration was unlinked and the receiver taken off the
    // map a grace period ago; a boxed registration retired earlier does
    // not refer to it when freed (free_reg with `last` false).
    // SAFETY: `head` is the first field of an `Rcv<R>` leaked from a KBox
    // by `set` or `reserve`, and nothing refers to it any more (above).
    drop(unsafe { KBox::from_raw(head.cast::<Rcv<R>>()) });
}

/// `call_rcu` callback: frees a key entry without members. Softirq
/// context.
unsafe extern "C" fn free_key<R: Receiver>(head: *mut bindings::callback_head) {
    // SAFETY: `head` is the first field of a `KeyEntry<R>` leaked from a
    // KBox by `link_reg`, unlinked a grace period ago.
    drop(unsafe { KBox::from_raw(head.cast::<KeyEntry<R>>()) });
}

/// `call_rcu` callback: frees a replaced group snapshot. Softirq context.
unsafe extern "C" fn free_groups(head: *mut bindings::callback_head) {
    // SAFETY: `head` is the first field of a `Groups` leaked from a KBox
    // by `publish_groups`, unreachable for a grace period now.
    drop(unsafe { KBox::from_raw(head.cast::<Groups>()) });
}

/// Hands `p` to `call_rcu`.
///
/// # Safety
///
/// `head` is the `rcu` field of an object that is unreachable for new
/// readers and that `func` frees.
unsafe fn defer(
    head: *mut bindings::callback_head,
    func: unsafe extern "C" fn(*mut bindings::callback_head),
) {
    // `func` is this module's: its exit must wait for it (rcu_barrier).
    crate::glue::module::note_rcu_callback();
    // SAFETY: per the caller's contract.
    unsafe { bindings::call_rcu(head, Some(func)) };
}

/// Where a new registration goes ([`RxTable::set`]).
enum Home<'a, R: Receiver> {
    /// Into the empty first slot of a reserved receiver.
    Slot(&'a Rcv<R>, Reg<R>),
    /// Into the first slot of a new receiver.
    New(KBox<Rcv<R>>, Reg<R>),
    /// Boxed on its own (the receiver has had a registration: a filter
    /// change).
    Boxed(&'a Rcv<R>, KBox<Reg<R>>),
}

impl<R: Receiver> Home<'_, R> {
    /// The registration, unplaced: its values only.
    fn reg(&self) -> &Reg<R> {
        match self {
            Home::Slot(_, r) | Home::New(_, r) => r,
            Home::Boxed(_, b) => b,
        }
    }
}

impl<R: Receiver> RxTable<R> {
    /// An empty table whose writers are serialised by the C mutex `lock`
    /// (the table's own: it must guard nothing else).
    pub(crate) const fn new(lock: StaticMutex) -> Self {
        RxTable {
            writer: CMutex::new(
                lock,
                Writer {
                    groups: KVec::new(),
                },
            ),
            rcvs: [const { List::new() }; ID_BUCKETS],
            buckets: [const { List::new() }; NBUCKETS],
            scanned: List::new(),
            err: List::new(),
            by_if: [const { List::new() }; IF_BUCKETS],
            groups: RcuPtr::null(),
        }
    }

    /// An empty table on the heap, for a network namespace other than the
    /// initial one (whose table is a static). Built in place: at about
    /// 66 KB the table does not fit on a kernel stack. Process context;
    /// sleeps. ENOMEM.
    pub(crate) fn new_boxed(lock: StaticMutex) -> Result<KVBox<Self>> {
        let mut b = KVBox::<Self>::new_uninit(GFP_KERNEL)?;
        let p = b.as_mut_ptr();
        // `p` is our allocation of one table. All-zero is a valid value
        // of every field but `writer` (NULL list heads and group pointer,
        // whose atomics are plain integers), which is written right after;
        // then every field is initialised.
        // SAFETY: as said above.
        unsafe {
            ptr::write_bytes(p, 0, 1);
            ptr::addr_of_mut!((*p).writer).write(CMutex::new(
                lock,
                Writer {
                    groups: KVec::new(),
                },
            ));
            Ok(b.assume_init())
        }
    }

    /// Calls `f(receiver, cookie)` once for every receiver that wants the
    /// frame `can_id` received on `ifindex`. NET_RX softirq context only
    /// (the per-CPU marks assume one frame at a time per CPU); `f` runs
    /// inside the read-side section of `g`.
    #[inline(always)]
    pub(crate) fn for_each_match<'g>(
        &'g self,
        g: &'g RcuReadGuard,
        ifindex: i32,
        can_id: u32,
        mut f: impl FnMut(&'g R, u32),
    ) {
        let stamp = rx_stamp();
        let mut hit = |reg: *const Reg<R>| {
            // SAFETY: a node reachable in this read-side section names a
            // registration freed only a grace period after the node was
            // unlinked.
            let reg: &'g Reg<R> = unsafe { &*reg };
            let rcv = reg.rcv();
            if rcv.seen.mark(&stamp) {
                f(&rcv.data, reg.cookie);
            }
        };
        let on_if = |i: i32| i == 0 || i == ifindex;
        if can_id & CAN_ERR_FLAG != 0 {
            for n in self.err.iter(g) {
                if on_if(n.ifindex) && can_id & n.mask != 0 {
                    hit(n.reg);
                }
            }
            return;
        }
        let key = frame_key(can_id);
        if let Some(groups) = self.groups.read(g) {
            for &(gi, gm) in groups.list.iter() {
                if !on_if(gi) {
                    continue;
                }
                let v = key & gm;
                for e in self.buckets[rxtable::bucket(gi, gm, v)].iter(g) {
                    if e.value == v && e.mask == gm && e.ifindex == gi {
                        for n in e.members.iter(g) {
                            hit(n.reg);
                        }
                        // Keys are distinct within a bucket.
                        break;
                    }
                }
            }
        }
        for n in self.scanned.iter(g) {
            if !on_if(n.ifindex) {
                continue;
            }
            // SAFETY: as in `hit`.
            let reg = unsafe { &*n.reg };
            let pass = if reg.join {
                reg.scanned.iter().all(|f| f.matches(key))
            } else {
                reg.scanned.iter().any(|f| f.matches(key))
            };
            if pass {
                hit(n.reg);
            }
        }
    }

    /// Copies into `out` every frame filter that applies to frames
    /// received on `ifindex` (registrations on it and on every interface);
    /// `None` if they do not fit. Any context.
    pub(crate) fn filters(&self, ifindex: i32, out: &mut [Filter]) -> Option<usize> {
        let g = RcuReadGuard::new();
        let mut n = 0;
        let mut scan = |bucket: &List<Node<R>>, want: i32| -> Option<()> {
            for node in bucket.iter(&g) {
                if node.ifindex != want {
                    continue;
                }
                // SAFETY: as in `for_each_match`.
                let reg = unsafe { &*node.reg };
                for f in reg.filters.iter() {
                    *out.get_mut(n)? = *f;
                    n += 1;
                }
            }
            Some(())
        };
        scan(&self.by_if[if_bucket(ifindex)], ifindex)?;
        if ifindex != 0 {
            scan(&self.by_if[if_bucket(0)], 0)?;
        }
        Some(n)
    }

    /// Makes receiver `id` (with `data`) ahead of its first registration,
    /// so that registration allocates nothing, and returns its handle, with
    /// which [`RxTable::set_reserved`] finds it without a lookup; if the
    /// receiver exists already, `data` is dropped and the handle names the
    /// existing one. A reserved receiver receives nothing until set, and
    /// stays until removed for good by `set_reserved` with `keep` false
    /// (`set(id, None)` only retires its registration). Process context;
    /// sleeps. ENOMEM.
    pub(crate) fn reserve(&self, id: usize, data: R) -> Result<RcvHandle> {
        // Allocated before locking; freed again if the receiver exists.
        let s = KBox::new(Rcv::new(data, self)?, GFP_KERNEL)?;
        let _w = self.writer.lock();
        let chain = &self.rcvs[id_bucket(id)];
        // SAFETY: writer mutex held (`_w`) while the chain is walked.
        if let Some(r) = unsafe { chain.iter_locked() }.find(|r| r.data.id() == id) {
            r.reserved.set(true);
            // INVARIANT: on the map, leaked (as below, earlier); removed
            // for good only by `set_reserved` now (`reserved`).
            return Ok(RcvHandle(NonNull::from(r).cast()));
        }
        let s: &Rcv<R> = KBox::leak(s);
        s.reserved.set(true);
        // Removed later by `set_reserved` or `set`, freed at once if it
        // never had a registration, else after a grace period.
        // SAFETY: writer mutex held; a new receiver, not on the map, at a
        // stable address until removed.
        unsafe { chain.push(s) };
        // INVARIANT: leaked above and on the map.
        Ok(RcvHandle(NonNull::from(s).cast()))
    }

    /// Sets the registration of receiver `id`: `new` is the spec and the
    /// receiver's data (used only if the receiver does not exist yet;
    /// else dropped here), `None` removes the receiver (a reserved one
    /// only loses its registration: its handle's holder removes it). A
    /// spec that wants nothing (no filters, no error mask) removes it too. On error (ENOMEM)
    /// the previous registration stays; removal never fails. Process
    /// context; sleeps.
    ///
    /// Allocations: none for the first registration of a reserved
    /// receiver ([`RxTable::reserve`]); one for a new receiver (the
    /// receiver with its first registration inside); one for a filter
    /// change (the boxed registration); in each case plus a key entry per
    /// key the table lacks and a group snapshot when a group is new. A
    /// removal allocates nothing.
    pub(crate) fn set(&self, id: usize, new: Option<(Spec<'_>, R)>) -> Result<Changed> {
        let new = new.filter(|(s, _)| wants(s));
        // The registration is built before locking (unplaced); where it
        // goes (inside its receiver, or boxed) is decided under the lock.
        let prepared = match new {
            Some((spec, data)) => Some((Self::make_reg(&spec)?, Some(data))),
            None => None,
        };
        let mut w = self.writer.lock();
        let chain = &self.rcvs[id_bucket(id)];
        // SAFETY: writer mutex held (`w`) for as long as `old` is used: the
        // map's receivers are unlinked and freed only under it.
        let old: Option<&Rcv<R>> = unsafe { chain.iter_locked() }.find(|r| r.data.id() == id);
        // A reserved receiver's owner holds its handle: only that removes
        // it for good.
        let keep = old.is_some_and(|r| r.reserved.get());
        self.apply(&mut w, id, old, prepared, keep)
    }

    /// Like [`RxTable::set`] for the reserved receiver `rcv`, found without
    /// a lookup and without new receiver data (it has its own), in the
    /// table it was reserved in (the receiver knows it: no namespace
    /// lookup): `new` is its new registration; `None` (or a spec that
    /// wants nothing) retires its registration, and with `keep` the
    /// receiver stays reserved (and `rcv` valid) for a later registration,
    /// else it is removed for good (which consumes `rcv`; pass `keep` false
    /// exactly once). The new registration is built under the writer
    /// mutex: the receiver's first in its slot ([`RxTable::set_first`]), a
    /// later one boxed. Process context; sleeps. ENOMEM, as `set`.
    pub(crate) fn set_reserved(
        rcv: RcvHandle,
        new: Option<Spec<'_>>,
        keep: bool,
    ) -> Result<Changed> {
        // A receiver on its table's map (RcvHandle invariant) lives until a
        // removal for good, which only a `set_reserved` with `keep` false on
        // this handle makes (its owner serialises them).
        // SAFETY: so it is alive until this call ends; `table` is immutable
        // and the table outlives its receivers.
        let table: &RxTable<R> = unsafe { rcv.0.cast::<Rcv<R>>().as_ref().table.as_ref() };
        let new = new.filter(wants);
        let mut w = table.writer.lock();
        // SAFETY: as above; freed only by a removal under the writer
        // mutex, which we hold (`w`) while `r` is used.
        let r: &Rcv<R> = unsafe { rcv.0.cast::<Rcv<R>>().as_ref() };
        // Registrations are built under the mutex: whether this is the
        // receiver's first (built in its slot) is known only under it.
        let prepared = match new {
            Some(spec) if r.first().is_none() => return table.set_first(&mut w, r, &spec),
            Some(spec) => Some((Self::make_reg(&spec)?, None)),
            None if !keep => return Ok(table.remove_rcv(&mut w, r)),
            None => None,
        };
        table.apply(&mut w, r.data.id(), Some(r), prepared, keep)
    }

    /// The first registration of the reserved receiver `r` (its slot is
    /// unused, so it has no live registration), built in its slot and
    /// linked: a socket's first bind, which then moves no registration
    /// and allocates nothing but missing key entries and group snapshots.
    /// Writer mutex held (`w` is its data). ENOMEM leaves `r` as it was.
    fn set_first(&self, w: &mut Writer, r: &Rcv<R>, spec: &Spec<'_>) -> Result<Changed> {
        if let Some(g) = self.one_hashed_group(w, spec) {
            return self.set_first_one(w, r, spec, g);
        }
        // SAFETY: writer mutex held (`w`); the slot is unused (our caller
        // checked under the mutex) and not referred to; `r` is leaked and
        // on the map.
        let reg = unsafe { r.fill_first_with(spec) }?;
        // Everything that can fail comes before anything is linked.
        let fresh = match self
            .new_keys(w, reg)
            .and_then(|fresh| self.grow_groups(w, reg).map(|()| fresh))
        {
            Ok(fresh) => fresh,
            Err(e) => {
                // SAFETY: writer mutex held; the registration was never
                // linked (nothing refers to it) and `reg` is not used
                // again.
                unsafe { r.empty_first() };
                return Err(e);
            }
        };
        self.link_reg(w, reg, fresh);
        r.reg.set(reg);
        // Nothing was unlinked, so no group lost its last node: no
        // `shrink_groups` (an empty group left by a shrink that failed for
        // ENOMEM waits for the next removal, as in `apply`).
        let mut changed = Changed::default();
        changed.ifindex[0] = (!reg.filters.is_empty()).then_some(reg.ifindex);
        Ok(changed)
    }

    /// The common bind's shape, for [`Self::set_first_one`]: exactly one
    /// frame filter, hashed, no error mask, and its group `(ifindex,
    /// mask)` already counted in `w.groups`. Returns the group's index,
    /// with the filter, its mask and value. Writer mutex held (`w`).
    fn one_hashed_group(&self, w: &Writer, spec: &Spec<'_>) -> Option<(usize, Filter, u32, u32)> {
        if spec.err_mask != 0 {
            return None;
        }
        let [f] = spec.filters else {
            return None;
        };
        let Place::Hashed { mask, value } = f.place() else {
            return None;
        };
        let g = w
            .groups
            .iter()
            .position(|g| g.0 == spec.ifindex && g.1 == mask)?;
        Some((g, *f, mask, value))
    }

    /// [`Self::set_first`] for the shape [`Self::one_hashed_group`] found
    /// (a socket with one filter, the common bind): the registration is
    /// written into the receiver's unused slot field by field (nothing is
    /// built elsewhere and moved in), with its two nodes (the hashed one
    /// and the interface entry, in the order [`Self::make_reg_into`] gives
    /// them), its key looked up once, and no group snapshot is published
    /// (the group exists); the same table state as the general path,
    /// without its loops over nodes and filters. Allocates only a missing
    /// key entry (ENOMEM, before anything is filled or linked). Writer
    /// mutex held (`w`).
    fn set_first_one(
        &self,
        w: &mut Writer,
        r: &Rcv<R>,
        spec: &Spec<'_>,
        (g, f, mask, value): (usize, Filter, u32, u32),
    ) -> Result<Changed> {
        let ifindex = spec.ifindex;
        // The entry of the filter's key if linked, else a new one (Err).
        // A pointer, not a reference: `w` is borrowed mutably below.
        let key: core::result::Result<NonNull<KeyEntry<R>>, KBox<KeyEntry<R>>> =
            match self.find_key(w, ifindex, mask, value) {
                Some(e) => Ok(NonNull::from(e)),
                None => Err(KeyEntry::new_boxed(ifindex, mask, value)?),
            };
        // SAFETY: writer mutex held (`w`); the slot is unused (our caller
        // checked under the mutex) and not referred to; `r` is leaked and
        // on the map.
        let slot = unsafe { r.first_slot() };
        // An unused slot is the empty registration: only what differs is
        // written (one filter is never joined, `rxtable::join_scanned`).
        let me: *const Reg<R> = slot;
        slot.rcv = NonNull::from(r);
        slot.cookie = spec.cookie;
        slot.ifindex = ifindex;
        slot.filters.one = Some(f);
        slot.nodes.inline[0] = Some(Node {
            reg: me,
            ..Node::new(Kind::Hashed, ifindex, mask, value)
        });
        slot.nodes.inline[1] = Some(Node {
            reg: me,
            ..Node::new(Kind::ByIf, ifindex, 0, 0)
        });
        r.first_used.set(true);
        let reg: &Reg<R> = slot;
        let e: &KeyEntry<R> = match key {
            // SAFETY: the entry find_key found, linked, under the writer
            // mutex held since (nothing was unlinked in between).
            Ok(e) => unsafe { e.as_ref() },
            Err(b) => {
                let e: &KeyEntry<R> = KBox::leak(b);
                // SAFETY: writer mutex held; a new, initialised entry,
                // freed only by free_key a grace period after it is
                // unlinked.
                unsafe { self.buckets[rxtable::bucket(ifindex, mask, value)].push(e) };
                e
            }
        };
        if let [Some(hashed), Some(by_if)] = &reg.nodes.inline {
            hashed.key.set(e);
            e.count.set(e.count.get() + 1);
            // SAFETY: writer mutex held; the nodes are initialised, not
            // linked, and stay in the receiver's slot until the receiver
            // is freed (after their unlinking and a grace period).
            unsafe {
                e.members.push(hashed);
                self.by_if[if_bucket(ifindex)].push(by_if);
            }
        }
        if let Some(c) = w.groups.get_mut(g) {
            c.2 += 1;
        }
        r.reg.set(reg);
        let mut changed = Changed::default();
        changed.ifindex[0] = Some(ifindex);
        Ok(changed)
    }

    /// The body of [`RxTable::set`] and [`RxTable::set_reserved`], under
    /// the writer mutex (`w` is its data): `old` is receiver `id` if it
    /// exists, `prepared` the new registration (unplaced) and, for a
    /// receiver to be made, its data; `None` retires the receiver's
    /// registration and, unless `keep`, the receiver.
    fn apply(
        &self,
        w: &mut Writer,
        id: usize,
        old: Option<&Rcv<R>>,
        prepared: Option<(Reg<R>, Option<R>)>,
        keep: bool,
    ) -> Result<Changed> {
        let chain = &self.rcvs[id_bucket(id)];
        let mut changed = Changed::default();
        let Some((reg, data)) = prepared else {
            // Removal.
            let Some(rcv) = old else {
                return Ok(changed);
            };
            if !keep {
                return Ok(self.remove_rcv(w, rcv));
            }
            // The registration goes, the receiver stays reserved.
            let live = rcv.reg.get();
            // SAFETY: NULL or the receiver's live registration.
            if let Some(o) = unsafe { live.as_ref() } {
                changed.ifindex[0] = (!o.filters.is_empty()).then_some(o.ifindex);
                self.unlink_reg(w, o);
                self.shrink_groups(w);
                rcv.reg.set(ptr::null());
                if !rcv.is_first(o) {
                    // SAFETY: unlinked and no longer the receiver's live
                    // registration; the receiver stays (`last` false);
                    // free_reg frees it.
                    unsafe { defer(live.cast_mut().cast(), free_reg::<R>) };
                }
            }
            return Ok(changed);
        };
        let home = match old {
            Some(r) => {
                // The existing receiver stays; `data` is not needed.
                drop(data);
                match r.first() {
                    // A filter change: the new registration is boxed.
                    Some(_) => Home::Boxed(r, KBox::new(reg, GFP_KERNEL)?),
                    // A reserved receiver's first registration.
                    None => Home::Slot(r, reg),
                }
            }
            None => {
                // `set` always brings data; `set_reserved` always has `old`.
                let data = data.ok_or(kernel::error::code::EINVAL)?;
                Home::New(KBox::new(Rcv::new(data, self)?, GFP_KERNEL)?, reg)
            }
        };
        // Everything that can fail comes before anything is linked.
        let fresh = self.new_keys(w, home.reg())?;
        self.grow_groups(w, home.reg())?;
        let (rcv, reg): (&Rcv<R>, &Reg<R>) = match home {
            Home::Boxed(r, mut b) => {
                // SAFETY: `b` is a registration of `r`, which is freed only
                // after its last registration.
                unsafe { b.place(NonNull::from(r)) };
                (r, KBox::leak(b))
            }
            // SAFETY: writer mutex held; a reserved receiver without a
            // registration has an empty slot; it is on the map, leaked.
            Home::Slot(r, reg) => (r, unsafe { r.fill_first(reg) }),
            Home::New(s, reg) => {
                let s: &Rcv<R> = KBox::leak(s);
                // free_rcv or free_reg frees it after its last
                // registration, which takes it off the map first.
                // SAFETY: writer mutex held; a new receiver, not on the
                // map, at a stable address until then.
                unsafe { chain.push(s) };
                // SAFETY: writer mutex held; a new receiver's slot is
                // empty; leaked above.
                (s, unsafe { s.fill_first(reg) })
            }
        };
        self.link_reg(w, reg, fresh);
        changed.ifindex[0] = (!reg.filters.is_empty()).then_some(reg.ifindex);
        let prev = rcv.reg.replace(reg as *const Reg<R>);
        // SAFETY: NULL, or the receiver's previous live registration,
        // still linked.
        if let Some(o) = unsafe { prev.as_ref() } {
            if !o.filters.is_empty() && Some(o.ifindex) != changed.ifindex[0] {
                changed.ifindex[1] = Some(o.ifindex);
            }
            self.unlink_reg(w, o);
            if !rcv.is_first(o) {
                // SAFETY: unlinked and no longer the receiver's live
                // registration; the receiver lives on in the new one
                // (`last` stays false); free_reg frees it.
                unsafe { defer(prev.cast_mut().cast(), free_reg::<R>) };
            }
            // An inline first registration stays in its receiver, unused,
            // until the receiver is freed.
        }
        self.shrink_groups(w);
        Ok(changed)
    }

    /// Removes the receiver `rcv` (on the map) for good: its live
    /// registration is unlinked, and it is freed at once if it never had
    /// one, else after a grace period. The removal of [`Self::apply`],
    /// called directly by [`Self::set_reserved`] for a socket's close, so
    /// that a close does not go through the general body. Writer mutex
    /// held (`w` is its data).
    fn remove_rcv(&self, w: &mut Writer, rcv: &Rcv<R>) -> Changed {
        let mut changed = Changed::default();
        let live = rcv.reg.get();
        // SAFETY: writer mutex held; `rcv` is on the map.
        unsafe { List::unlink(rcv) };
        if live.is_null() {
            if rcv.first().is_none() {
                // Readers reach receivers only through registrations.
                // SAFETY: a reserved receiver that never had one: leaked
                // from a KBox by `reserve`, now off the map, never
                // reachable by readers, so it is freed at once.
                drop(unsafe { KBox::from_raw((rcv as *const Rcv<R>).cast_mut()) });
            } else {
                // Its registrations were retired earlier (`keep`):
                // readers may still hold the last one until a grace
                // period has passed.
                // SAFETY: off the map, every registration unlinked:
                // unreachable for new readers and writers; free_rcv
                // frees it (with its inline registration).
                unsafe { defer((rcv as *const Rcv<R>).cast_mut().cast(), free_rcv::<R>) };
            }
            return changed;
        }
        // SAFETY: a non-NULL `reg` is the receiver's live registration.
        let o = unsafe { &*live };
        changed.ifindex[0] = (!o.filters.is_empty()).then_some(o.ifindex);
        changed.removed = true;
        self.unlink_reg(w, o);
        self.shrink_groups(w);
        if rcv.is_first(o) {
            // SAFETY: the receiver's only registration ever (inline) is
            // unlinked and the receiver is off the map: unreachable
            // for new readers and writers; free_rcv frees both.
            unsafe { defer((rcv as *const Rcv<R>).cast_mut().cast(), free_rcv::<R>) };
        } else {
            o.last.set(true);
            // free_reg frees it and the receiver (with its inline
            // registration, retired earlier).
            // SAFETY: unlinked above and the receiver is off the map:
            // unreachable for new readers and writers.
            unsafe { defer((o as *const Reg<R>).cast_mut().cast(), free_reg::<R>) };
        }
        changed
    }

    /// Builds an unlinked, unplaced registration for `spec` (receiver and
    /// the nodes' back pointers still unset: [`Reg::place`]).
    fn make_reg(spec: &Spec<'_>) -> Result<Reg<R>> {
        let mut reg = Reg::empty();
        Self::make_reg_into(spec, &mut reg)?;
        Ok(reg)
    }

    /// [`Self::make_reg`] writing into the empty registration `reg`, so
    /// that a reserved receiver's first registration is built where it
    /// stays instead of being moved there (a registration is ~230 bytes).
    /// On error `reg` is empty again. Process context (may allocate and
    /// sleep).
    fn make_reg_into(spec: &Spec<'_>, reg: &mut Reg<R>) -> Result {
        let join = rxtable::join_scanned(spec.filters, spec.join);
        let mut scanned = KVec::new();
        let mut hashed = 0;
        for f in spec.filters {
            match f.place() {
                Place::Hashed { .. } if !join => hashed += 1,
                _ => scanned.push(*f, GFP_KERNEL)?,
            }
        }
        let extra = (hashed
            + usize::from(!scanned.is_empty())
            + usize::from(spec.err_mask != 0)
            + usize::from(!spec.filters.is_empty()))
        .saturating_sub(INLINE_NODES);
        let more = if extra > 0 {
            KVec::with_capacity(extra, GFP_KERNEL)?
        } else {
            KVec::new()
        };
        let filters = Filters::from_slice(spec.filters)?;
        let (ifindex, err_mask) = (spec.ifindex, spec.err_mask);
        // Nothing below allocates: the nodes fit the inline room and the
        // capacity reserved above.
        reg.cookie = spec.cookie;
        reg.ifindex = ifindex;
        reg.filters = filters;
        reg.scanned = scanned;
        reg.join = join;
        reg.nodes.more = more;
        let node = |kind, mask, value| Node::new(kind, ifindex, mask, value);
        // All nodes are added before any is linked.
        let mut res = Ok(());
        if !join {
            for f in reg.filters.iter() {
                if let Place::Hashed { mask, value } = f.place() {
                    res = res.and(reg.nodes.push(node(Kind::Hashed, mask, value)));
                }
            }
        }
        if !reg.scanned.is_empty() {
            res = res.and(reg.nodes.push(node(Kind::Scanned, 0, 0)));
        }
        if err_mask != 0 {
            res = res.and(reg.nodes.push(node(Kind::Err, err_mask, 0)));
        }
        if !reg.filters.is_empty() {
            res = res.and(reg.nodes.push(node(Kind::ByIf, 0, 0)));
        }
        if res.is_err() {
            *reg = Reg::empty();
        }
        res
    }

    /// The list a non-hashed node belongs on.
    fn list_of(&self, n: &Node<R>) -> &List<Node<R>> {
        match n.kind {
            Kind::Scanned => &self.scanned,
            Kind::Err => &self.err,
            _ => &self.by_if[if_bucket(n.ifindex)],
        }
    }

    /// The key entry of `(ifindex, mask, value)`, if linked. Writer mutex
    /// held (`w`).
    fn find_key<'w>(
        &'w self,
        w: &'w Writer,
        ifindex: i32,
        mask: u32,
        value: u32,
    ) -> Option<&'w KeyEntry<R>> {
        let _ = w;
        let bucket = &self.buckets[rxtable::bucket(ifindex, mask, value)];
        // SAFETY: `w` is the writer mutex's data, borrowed for 'w: the
        // mutex is held that long.
        unsafe { bucket.iter_locked() }
            .find(|e| e.ifindex == ifindex && e.mask == mask && e.value == value)
    }

    /// Allocates the key entries `reg`'s hashed nodes need and the table
    /// lacks (one per distinct key), so that linking cannot fail; a node
    /// whose key the table has gets it in its `key` now, so that
    /// [`Self::link_reg`] does not look it up again. Writer mutex held
    /// (the entries found stay linked until `link_reg`: nothing is
    /// unlinked in between).
    fn new_keys(&self, w: &Writer, reg: &Reg<R>) -> Result<KVec<KBox<KeyEntry<R>>>> {
        let mut fresh: KVec<KBox<KeyEntry<R>>> = KVec::new();
        for n in reg.nodes.iter().filter(|n| n.kind == Kind::Hashed) {
            if let Some(e) = self.find_key(w, n.ifindex, n.mask, n.value) {
                n.key.set(e);
                continue;
            }
            let known = fresh
                .iter()
                .any(|e| e.ifindex == n.ifindex && e.mask == n.mask && e.value == n.value);
            if !known {
                let e = KeyEntry::new_boxed(n.ifindex, n.mask, n.value)?;
                fresh.push(e, GFP_KERNEL)?;
            }
        }
        Ok(fresh)
    }

    /// Links every node of `reg`, into the key entry [`Self::new_keys`]
    /// found for it, else one taken from `fresh` (made by `new_keys` for
    /// this registration), else (a key two of its nodes share) the one
    /// linked for the first of them. Writer mutex held.
    fn link_reg(&self, w: &Writer, reg: &Reg<R>, mut fresh: KVec<KBox<KeyEntry<R>>>) {
        for n in reg.nodes.iter() {
            if n.kind != Kind::Hashed {
                // SAFETY: writer mutex held; the nodes are initialised, not
                // linked, and stay put inside the boxed registration until
                // free_reg.
                unsafe { self.list_of(n).push(n) };
                continue;
            }
            // SAFETY: NULL, or the linked entry new_keys found, under the
            // writer mutex held since (nothing unlinked it).
            let found = unsafe { n.key.get().as_ref() };
            let i = match found {
                Some(_) => None,
                None => fresh
                    .iter()
                    .position(|e| e.ifindex == n.ifindex && e.mask == n.mask && e.value == n.value),
            };
            let e: &KeyEntry<R> = match (found, i) {
                (Some(e), _) => e,
                (None, None) => match self.find_key(w, n.ifindex, n.mask, n.value) {
                    Some(e) => e,
                    // new_keys made one for every missing key.
                    None => continue,
                },
                (None, Some(i)) => {
                    let Some(e) = super::super::kvec_swap_remove(&mut fresh, i) else {
                        continue;
                    };
                    let e: &KeyEntry<R> = KBox::leak(e);
                    // SAFETY: writer mutex held; a new, initialised entry,
                    // freed only by free_key a grace period after it is
                    // unlinked.
                    unsafe { self.buckets[rxtable::bucket(e.ifindex, e.mask, e.value)].push(e) };
                    e
                }
            };
            n.key.set(e);
            e.count.set(e.count.get() + 1);
            // SAFETY: as for the other nodes.
            unsafe { e.members.push(n) };
        }
    }

    /// Unlinks every node of `reg` and drops its group counts. Writer
    /// mutex held (`w` is its data).
    fn unlink_reg(&self, w: &mut Writer, reg: &Reg<R>) {
        if let ([Some(hashed), Some(by_if)], true) = (&reg.nodes.inline, reg.nodes.more.is_empty())
        {
            if hashed.kind == Kind::Hashed && by_if.kind == Kind::ByIf {
                return self.unlink_one(w, hashed, by_if);
            }
        }
        for n in reg.nodes.iter() {
            // SAFETY: writer mutex held (`w` is its data); `reg` is linked.
            unsafe { List::unlink(n) };
            if n.kind == Kind::Hashed {
                Self::leave_key(w, n);
            }
        }
    }

    /// [`Self::unlink_reg`] for the shape [`Self::set_first_one`] makes
    /// (the common close: one hashed filter and the interface entry, no
    /// other node), the mirror of that fast path: both nodes unlinked
    /// directly, the key entry reached through the node, with no loop
    /// over nodes and no list lookup by kind; the same table state as the
    /// general loop. Writer mutex held (`w` is its data).
    fn unlink_one(&self, w: &mut Writer, hashed: &Node<R>, by_if: &Node<R>) {
        // SAFETY: writer mutex held (`w` is its data); both nodes are
        // linked (the registration is).
        unsafe {
            List::unlink(hashed);
            List::unlink(by_if);
        }
        Self::leave_key(w, hashed);
    }

    /// A hashed node just unlinked leaves its key entry (unlinked, and
    /// freed after a grace period, when it was the last member) and its
    /// group's count. Shared by [`Self::unlink_reg`] and
    /// [`Self::unlink_one`]. Writer mutex held (`w` is its data); `n` was
    /// linked under it until now.
    #[inline]
    fn leave_key(w: &mut Writer, n: &Node<R>) {
        // SAFETY: set when the node was linked; the entry lives while it
        // has members (writer mutex held).
        let e = unsafe { &*n.key.get() };
        let left = e.count.get() - 1;
        e.count.set(left);
        if left == 0 {
            // SAFETY: writer mutex held; the entry is linked.
            unsafe { List::unlink(e) };
            // SAFETY: unlinked: unreachable for new readers; free_key
            // frees it.
            unsafe {
                defer(
                    e as *const KeyEntry<R> as *mut bindings::callback_head,
                    free_key::<R>,
                )
            };
        }
        if let Some(g) = w
            .groups
            .iter_mut()
            .find(|g| g.0 == n.ifindex && g.1 == n.mask)
        {
            g.2 -= 1;
        }
    }

    /// Counts `reg`'s hashed nodes in their groups, publishing a new group
    /// snapshot first if a group is new. ENOMEM leaves the counts as they
    /// were. Writer mutex held.
    fn grow_groups(&self, w: &mut Writer, reg: &Reg<R>) -> Result {
        let hashed = || reg.nodes.iter().filter(|n| n.kind == Kind::Hashed);
        let missing =
            |w: &Writer, n: &Node<R>| !w.groups.iter().any(|g| g.0 == n.ifindex && g.1 == n.mask);
        if hashed().any(|n| missing(w, n)) {
            let mut grown = KVec::with_capacity(w.groups.len() + reg.nodes.len(), GFP_KERNEL)?;
            for g in w.groups.iter() {
                grown.push(*g, GFP_KERNEL)?;
            }
            for n in hashed() {
                if !grown.iter().any(|g| g.0 == n.ifindex && g.1 == n.mask) {
                    grown.push((n.ifindex, n.mask, 0), GFP_KERNEL)?;
                }
            }
            self.publish_groups(&grown)?;
            w.groups = grown;
        }
        for n in hashed() {
            if let Some(g) = w
                .groups
                .iter_mut()
                .find(|g| g.0 == n.ifindex && g.1 == n.mask)
            {
                g.2 += 1;
            }
        }
        Ok(())
    }

    /// Drops groups without nodes from the published snapshot; on ENOMEM
    /// they stay (a probe of an empty group costs time, not correctness).
    /// Writer mutex held. Inline: every removal asks, and usually no group
    /// is empty, which is a loop over the few groups, without the call
    /// and the register saves of the rebuild ([`Self::shrink_groups_now`]).
    #[inline(always)]
    fn shrink_groups(&self, w: &mut Writer) {
        if w.groups.iter().all(|g| g.2 != 0) {
            return;
        }
        self.shrink_groups_now(w);
    }

    /// [`Self::shrink_groups`] once a group without nodes is known.
    #[inline(never)]
    fn shrink_groups_now(&self, w: &mut Writer) {
        let Ok(mut kept) = KVec::with_capacity(w.groups.len(), GFP_KERNEL) else {
            return;
        };
        for g in w.groups.iter().filter(|g| g.2 > 0) {
            // Within capacity.
            let _ = kept.push(*g, GFP_KERNEL);
        }
        if self.publish_groups(&kept).is_ok() {
            w.groups = kept;
        }
    }

    /// Publishes a snapshot of `groups` and retires the old one. Writer
    /// mutex held.
    fn publish_groups(&self, groups: &[(i32, u32, usize)]) -> Result {
        let mut list = KVec::with_capacity(groups.len(), GFP_KERNEL)?;
        for g in groups {
            list.push((g.0, g.1), GFP_KERNEL)?;
        }
        let snap = KBox::new(
            Groups {
                // SAFETY: an all-zero callback_head is what call_rcu expects.
                rcu: unsafe { core::mem::zeroed() },
                list,
            },
            GFP_KERNEL,
        )?;
        // SAFETY: writer mutex held (`w`); a fully built snapshot, freed
        // only through `defer` after it is replaced; `old` is ours.
        let old = unsafe { self.groups.replace(KBox::into_raw(snap)) };
        if !old.is_null() {
            // SAFETY: replaced above, so unreachable for new readers;
            // free_groups frees it.
            unsafe { defer(old.cast(), free_groups) };
        }
        Ok(())
    }

    /// Module exit (or a namespace's), once every receiver is removed:
    /// frees the writer's bookkeeping and the group snapshot; false (with
    /// a warning) if receivers are left, whose registrations then leak.
    /// Process context; sleeps. The module's exit waits for the
    /// callbacks queued here (`rcu_barrier`, [`crate::glue::module::Scoped`]).
    pub(crate) fn shutdown(&self) -> bool {
        let mut empty = true;
        let old = {
            let mut w = self.writer.lock();
            if self
                .rcvs
                .iter()
                .any(|c| !c.first.load(Ordering::Relaxed).is_null())
            {
                kernel::pr_warn!("receive table not empty at exit: registrations leaked\n");
                empty = false;
            }
            w.groups = KVec::new();
            // SAFETY: writer mutex held (`w`); NULL is always valid; the
            // old snapshot is ours and goes through `defer` below.
            unsafe { self.groups.replace(ptr::null_mut()) }
        };
        if !old.is_null() {
            // SAFETY: unpublished above; free_groups frees it.
            unsafe { defer(old.cast(), free_groups) };
        }
        empty
    }
}
