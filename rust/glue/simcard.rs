// SPDX-License-Identifier: GPL-2.0

//! Simulated CAN cards on one simulated bus: what the simulated SJA1000
//! (`rcan_sja1000_sim`) and Intel 82527 (`rcan_i82527_sim`) front-ends
//! share. Nothing emulates those chips' bus errors or the 82527 at all
//! (DESIGN section 3), so such a front-end's register accesses go to a
//! register-level model of the chip (in `rcan_core`, the one the host
//! tests use) and the unchanged driver runs on top of it.
//!
//! A front-end describes its bus with [`SimBus`] (the models of its
//! cards, one attempt to send, the interrupt outputs, the register file,
//! the driver's probe of a card), keeps one [`SimCards`] in a `static`
//! and names `Scoped<SimModule<Bus>>` ([`SimModule`]) as its module type; this file
//! does the rest:
//!
//! * The bus: every card's model lives in one value under one spinlock
//!   (`SimCards::bus`, a [`StaticIrqSpinLock`] with a lockdep class of
//!   its own, named by the front-end), the registered cards in another
//!   (`SimCards::cards`). Lock order: cards -> a card's chip lock (the
//!   driver's) -> bus; the driver reads registers under its chip lock,
//!   so the bus lock is taken inside it, never the other way round.
//! * The wires: a register write that requests a transmission
//!   ([`SimBus::is_tx_request`]) kicks an hrtimer (soft mode). Its
//!   callback, in HRTIMER_SOFTIRQ softirq context, runs rounds: in each,
//!   one card with a pending frame makes one attempt under the fault the
//!   module parameters name ([`SimBus::round`]), a frame that went out
//!   reaches every other card's model, and then the driver's interrupt
//!   handler of each card whose interrupt output is raised is called
//!   (with only the cards lock held). The rounds go on until nothing
//!   moves; after [`FRAMES_PER_RUN`] frames the timer re-arms after
//!   [`REARM_NS`] instead (softirqs, NET_RX among them, run in between),
//!   and after a failed attempt (the chip retries by itself) after
//!   [`RETRY_NS`], so a faulty bus raises errors at a bounded rate.
//!   A front-end whose [`SimBus::bus_ns`] is 0 (the default) gives frames
//!   no bus time. One that tells how long the frame just sent takes at
//!   its bit timing gets a bus that paces itself as a real one: the bus
//!   is busy until that time has passed (`SimCards::busy_until`, which
//!   the frame's time extends from the end of the previous frame, or from
//!   [`LATE_NS`] ago if the bus was idle or the timer late), the timer
//!   runs next only then, and a transmission request meanwhile does not
//!   start it earlier. So a burst goes at most at the bit rate (plus
//!   [`LATE_NS`] of catching up), and frames never reach a receiver
//!   faster than a real bus would bring them.
//! * Flow control ([`Round::held`]): a front-end whose models tell which
//!   frame they send next and whether a receiver is ready for it (see
//!   `sim_bus`) gets a bus that keeps a frame pending while a receiving
//!   host has not read what is in its way, instead of overrunning it. The
//!   bus then waits without its timer; a register write of the host that
//!   reads a receive buffer ([`SimBus::frees_rx`]) kicks it again. Pacing
//!   alone does not keep a receiver from losing frames in a guest: the
//!   timer runs on one virtual CPU while the receiving host may run on
//!   another that the host machine does not schedule for many frame
//!   times.
//! * The interrupt lines: a register write that turns a card's interrupt
//!   output on ([`SimBus::enables_irq`], a driver that had turned it off
//!   while it had no room) kicks the timer too, whose run calls the
//!   handler if a cause is pending, as a real line would.
//! * Teardown ([`SimCards::stop`], from the module's exit): `dying` stops
//!   the callback from touching anything, the timer is cancelled, the
//!   cards are taken out of the cards lock and unregistered (their `stop`
//!   writes to the models, which no longer kicks), and the timer is
//!   cancelled once more before the bus is taken out and handed back.
//!
//! No `unsafe` here: the cards are reached only through the `static`, so
//! nothing can outlive what it points to.

use super::hrtimer::ktime_get_mono_ns;
use super::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use super::lock::StaticIrqSpinLock;
use super::module::{ModuleScope, ScopedModule};
use super::params::ParamStr;
use core::marker::PhantomData;
use core::sync::atomic::{AtomicBool, AtomicI64, Ordering};
use kernel::prelude::*;
use kernel::str::CStr;

/// Most cards on one simulated bus (module parameter `cards`, 1..=8).
pub(crate) const MAX_CARDS: usize = 8;
/// Frames moved per timer run. The simulated bus has no bit time; a run
/// that moved many frames would queue them all before the NET_RX softirq
/// could take any, and overflow receive queues that a real bus's pace
/// never fills. After this many the timer re-arms.
pub(crate) const FRAMES_PER_RUN: usize = 8;
/// Delay of that re-arm, ns: 8 frames at 1 Mbit/s would take 0.5-1 ms;
/// 20 us keeps the VM tests fast and still yields.
pub(crate) const REARM_NS: i64 = 20_000;
/// Rounds of a run (interrupt handling without frames moving included)
/// before re-arming.
pub(crate) const MAX_ROUNDS: usize = 64;
/// How far behind the wall clock a paced bus ([`SimBus::bus_ns`]) may
/// run, ns: a timer that fires late lets the frames queued meanwhile
/// catch up, back to back (a token bucket of 1 ms: some 8 frames at
/// 1 Mbit/s), instead of adding its latency to every frame. Over any
/// interval the bus still carries no more than the bit rate allows plus
/// this much.
pub(crate) const LATE_NS: i64 = 1_000_000;
/// Delay before a failed attempt is retried, ns: bounds the rate of
/// error interrupts on a faulty bus (2 ms: 500 attempts/s per card).
pub(crate) const RETRY_NS: i64 = 2_000_000;

/// What one round on the bus did ([`SimBus::round`]).
pub(crate) struct Round {
    /// A frame went out (and reached the other cards).
    pub(crate) moved: bool,
    /// An attempt failed: the chip retries it by itself.
    pub(crate) failed: bool,
    /// Nothing moved because a frame waits for a receiver's host to read
    /// ([`SimBus::frees_rx`] kicks the bus again).
    pub(crate) held: bool,
}

/// A simulated bus: the models of its cards, as a front-end describes
/// them. Every method but the associated functions runs with the bus
/// lock held (interrupts off): no sleeping, no calls into the stack.
pub(crate) trait SimBus: Sized + Send + 'static {
    /// The module name, for its log lines.
    const NAME: &'static str;
    /// A registered card: what the driver's probe returned (it
    /// unregisters its device when dropped).
    type Card: Send + 'static;
    /// The fault the module parameters name.
    type Fault: Copy;

    /// The front-end's `static` [`SimCards`] of this bus.
    fn sim() -> &'static SimCards<Self>;
    /// How many cards the module parameter asks for (checked by
    /// [`SimCards::start`]). Process context.
    fn cards_param() -> usize;
    /// Registers a device for card `i` (the driver's probe over the
    /// card's registers): `None` if its model does not answer. Process
    /// context (module init), no lock held.
    fn add_card(scope: &ModuleScope, i: usize) -> Result<Option<Self::Card>>;
    /// A bus of `cards` fresh models (1..=[`MAX_CARDS`]). Process context.
    fn new(cards: usize) -> Self;
    /// How many cards are on the bus.
    fn cards(&self) -> usize;
    /// The fault the module parameters name now (read at each timer
    /// run). Softirq context, no lock held.
    fn fault() -> Self::Fault;
    /// One round: the first card in turn with a pending frame makes one
    /// attempt under `fault`; a frame that goes out reaches every other
    /// card's model.
    fn round(&mut self, fault: Self::Fault) -> Round;
    /// Whether card `card`'s interrupt output is raised, after a round.
    fn irq_line(&mut self, card: usize) -> bool;
    /// Reads register `reg` of card `card`'s model.
    fn read(&mut self, card: usize, reg: u8) -> u8;
    /// Writes register `reg` of card `card`'s model.
    fn write(&mut self, card: usize, reg: u8, val: u8);
    /// Whether writing `val` to register `reg` requests a transmission
    /// (the bus then has work). Any context, no lock.
    fn is_tx_request(reg: u8, val: u8) -> bool;
    /// Whether writing `val` to register `reg` may free a receive buffer
    /// a held frame waits for ([`Round::held`]): the bus is kicked if one
    /// does. By default never (a front-end whose rounds never hold). Any
    /// context, no lock.
    fn frees_rx(_reg: u8, _val: u8) -> bool {
        false
    }
    /// Whether writing `val` to register `reg` turns a card's interrupt
    /// output on: the bus is kicked, so that a pending cause reaches the
    /// driver's handler. By default never. Any context, no lock.
    fn enables_irq(_reg: u8, _val: u8) -> bool {
        false
    }
    /// Runs the driver's interrupt handler of `card`; whether the chip
    /// had a cause. Softirq context, the cards lock held (not the bus
    /// lock).
    fn card_irq(card: &Self::Card) -> bool;
    /// Logs the bus's statistics at module exit. Process context.
    fn report(&self);
    /// The bus of `cards` cards on the heap (module init). By default
    /// [`SimBus::new`] boxed; a bus whose models are too large to be
    /// built on the stack (the CTU CAN FD core's RX buffer) allocates
    /// them here instead. Process context.
    fn alloc(cards: usize) -> Result<KBox<Self>> {
        Ok(KBox::new(Self::new(cards), GFP_KERNEL)?)
    }

    /// How long the frame the last [`SimBus::round`] sent takes on the
    /// bus, ns (its bits at the sender's bit timing); 0 (the default):
    /// frames take no bus time.
    fn bus_ns(&self) -> i64 {
        0
    }
}

/// The simulated cards of a front-end, on one bus: a `static` of the
/// front-end module (see the file's documentation for the locks, the
/// timer and the teardown).
pub(crate) struct SimCards<B: SimBus> {
    /// The bus; `None` outside the module's lifetime. Taken inside a
    /// card's chip lock, never the other way round.
    bus: StaticIrqSpinLock<Option<KBox<B>>>,
    /// The registered cards, in bus order; empty outside the module's
    /// lifetime. Lock order: cards -> a card's chip lock -> bus.
    cards: StaticIrqSpinLock<KVec<B::Card>>,
    /// Set while the module goes away: no kicks, no callback work.
    dying: AtomicBool,
    /// The last round held a frame for a receiver ([`Round::held`]).
    /// Written and read under the bus lock only (the round, and register
    /// writes that may free a receive buffer), so a write either comes
    /// before the round and is seen by it, or after it and kicks.
    held: AtomicBool,
    /// `CLOCK_MONOTONIC` ns until which the frame last sent occupies the
    /// bus ([`SimBus::bus_ns`]); the next round waits for it. Written by
    /// the timer callback, read by it and by kicks (any context).
    busy_until: AtomicI64,
    /// The bus and interrupt timer.
    timer: HrTimer<Wires<B>>,
}

/// The timer callback of a [`SimCards<B>`]: the bus and the interrupt
/// wires.
pub(crate) struct Wires<B>(PhantomData<B>);

impl<B: SimBus> HrTimerCallback for Wires<B> {
    type State = ();

    /// HRTIMER_SOFTIRQ softirq context.
    fn run(timer: &'static HrTimer<Self>, _st: &mut ()) {
        B::sim().run(timer);
    }
}

impl<B: SimBus> SimCards<B> {
    /// For the front-end's `static`; `bus` and `cards` name the two
    /// locks in lockdep reports (each a class of its own).
    pub(crate) const fn new(bus: &'static CStr, cards: &'static CStr) -> Self {
        SimCards {
            bus: StaticIrqSpinLock::new(None, bus),
            cards: StaticIrqSpinLock::new(KVec::new(), cards),
            dying: AtomicBool::new(false),
            held: AtomicBool::new(false),
            busy_until: AtomicI64::new(0),
            timer: HrTimer::new(),
        }
    }

    /// Register `reg` of card `card`; 0xFF (as an absent chip) outside
    /// the module's lifetime. Any context that may take the bus lock
    /// (the driver's, under its chip lock).
    pub(crate) fn read(&'static self, card: usize, reg: u8) -> u8 {
        match self.bus.lock().as_mut() {
            Some(b) => b.read(card, reg),
            None => 0xFF,
        }
    }

    /// Writes register `reg` of card `card`; a transmission request, a
    /// write that turns an interrupt output on, and one that may free a
    /// receive buffer while a frame is held for one kick the bus. Any
    /// context that may take the bus lock.
    pub(crate) fn write(&'static self, card: usize, reg: u8, val: u8) {
        let mut kick = B::is_tx_request(reg, val) || B::enables_irq(reg, val);
        if let Some(b) = self.bus.lock().as_mut() {
            b.write(card, reg, val);
            // Under the bus lock, as the round that sets it.
            kick |= B::frees_rx(reg, val) && self.held.load(Ordering::Relaxed);
        }
        if kick {
            self.kick();
        }
    }

    /// Runs `f` on the bus under the bus lock; `None` outside the
    /// module's lifetime. For a front-end whose registers are wider than
    /// [`SimCards::read`]'s bytes (the CTU CAN FD core's 32-bit words):
    /// it reads and writes its models here and calls
    /// [`SimCards::request_tx`] for a write that requests a
    /// transmission. Any context that may take the bus lock (the
    /// driver's, under its chip lock); `f` must not sleep.
    pub(crate) fn with_bus<T>(&'static self, f: impl FnOnce(&mut B) -> T) -> Option<T> {
        self.bus.lock().as_mut().map(|b| f(b))
    }

    /// A register write through [`SimCards::with_bus`] requested a
    /// transmission: runs the bus now. Any context; not under the bus
    /// lock.
    pub(crate) fn request_tx(&'static self) {
        self.kick();
    }

    /// How long the bus is still busy with the frame last sent, ns (0:
    /// free). Any context.
    fn busy_for(&self) -> i64 {
        (self.busy_until.load(Ordering::Relaxed) - ktime_get_mono_ns()).max(0)
    }

    /// Runs the bus now, or once the frame on it is through (unless the
    /// module is going away). Any context.
    fn kick(&'static self) {
        if !self.dying.load(Ordering::SeqCst) {
            self.timer.start(self.busy_for());
        }
    }

    /// Puts a bus of `n` cards in place and registers a device per card
    /// with `add(i)` (the driver's probe: `None` if the model does not
    /// answer, which fails with ENODEV). `n` outside 1..=[`MAX_CARDS`]
    /// fails with EINVAL. On failure everything is torn down again as by
    /// [`SimCards::stop`]. Process context (module init).
    pub(crate) fn start(
        &'static self,
        scope: &ModuleScope,
        n: usize,
        add: impl FnMut(&ModuleScope, usize) -> Result<Option<B::Card>>,
    ) -> Result {
        if n == 0 || n > MAX_CARDS {
            pr_err!("{}: cards must be 1..={}\n", B::NAME, MAX_CARDS);
            return Err(EINVAL);
        }
        let r = self.start_cards(scope, n, add);
        if r.is_err() {
            // The cards registered so far are already unregistered (the
            // local vector is gone).
            self.stop();
        }
        r
    }

    fn start_cards(
        &'static self,
        scope: &ModuleScope,
        n: usize,
        mut add: impl FnMut(&ModuleScope, usize) -> Result<Option<B::Card>>,
    ) -> Result {
        let bus = B::alloc(n)?;
        *self.bus.lock() = Some(bus);
        self.timer
            .init(scope, ClockId::Monotonic, HrTimerMode::RelativeSoft, ())?;
        self.dying.store(false, Ordering::SeqCst);
        let mut cards = KVec::with_capacity(n, GFP_KERNEL)?;
        for i in 0..n {
            let Some(c) = add(scope, i)? else {
                pr_err!("{}: model {} does not probe\n", B::NAME, i);
                return Err(ENODEV);
            };
            cards.push(c, GFP_KERNEL)?;
        }
        // The old (empty) vector is dropped with the guard held: it owns
        // no memory.
        *self.cards.lock() = cards;
        Ok(())
    }

    /// Tears the bus down (module exit): no more timer runs, the cards
    /// unregistered, then [`SimBus::report`] and the bus freed. Process
    /// context.
    pub(crate) fn stop(&'static self) {
        self.dying.store(true, Ordering::SeqCst);
        self.timer.cancel();
        // Unregisters the devices (stop, then free), outside the lock.
        let cards = core::mem::replace(&mut *self.cards.lock(), KVec::new());
        drop(cards);
        self.timer.cancel();
        let bus = self.bus.lock().take();
        if let Some(bus) = bus {
            bus.report();
        }
    }

    /// The timer's callback: rounds on the bus, then the interrupt
    /// handlers of the cards whose output is raised. HRTIMER_SOFTIRQ
    /// softirq context; calls into the stack only through the drivers'
    /// handlers, never with the bus lock held.
    fn run(&'static self, timer: &'static HrTimer<Wires<B>>) {
        if self.dying.load(Ordering::SeqCst) {
            return;
        }
        let busy = self.busy_for();
        if busy > 0 {
            // A kick started the timer while a frame was on the bus.
            timer.start(busy);
            return;
        }
        let fault = B::fault();
        let mut frames = 0;
        for _ in 0..MAX_ROUNDS {
            if frames == FRAMES_PER_RUN {
                break;
            }
            let mut lines = [false; MAX_CARDS];
            let (n, r, bus_ns) = {
                let mut g = self.bus.lock();
                let Some(b) = g.as_mut() else {
                    return;
                };
                let r = b.round(fault);
                self.held.store(r.held, Ordering::Relaxed);
                let bus_ns = if r.moved { b.bus_ns() } else { 0 };
                let n = b.cards();
                for (i, l) in lines.iter_mut().enumerate().take(n) {
                    *l = b.irq_line(i);
                }
                (n, r, bus_ns)
            };
            if bus_ns > 0 {
                // The frame follows the previous one on the bus, or
                // starts now if the bus has been idle (catching up at
                // most LATE_NS).
                let now = ktime_get_mono_ns();
                let start = self.busy_until.load(Ordering::Relaxed).max(now - LATE_NS);
                self.busy_until.store(start + bus_ns, Ordering::Relaxed);
            }
            // The bus lock is released: the handlers take their chip lock
            // and then the bus lock for each register access.
            let mut handled = false;
            {
                let cards = self.cards.lock();
                for (i, c) in cards.iter().enumerate().take(n) {
                    if lines[i] {
                        handled |= B::card_irq(c);
                    }
                }
            }
            if r.failed {
                // The chip retries by itself, a little later.
                timer.start(RETRY_NS);
                return;
            }
            let busy = self.busy_for();
            if busy > 0 {
                // The next frame goes out once this one is through.
                timer.start(busy);
                return;
            }
            frames += usize::from(r.moved);
            if !r.moved && !handled {
                // Idle, or a frame held for a receiver whose host reads
                // later (its write then kicks the bus).
                return;
            }
        }
        // Busy bus: let others (NET_RX) run, come back soon.
        timer.start(REARM_NS);
    }
}

/// The size of a simulated-card module's `fault` parameter buffer
/// (`RCAN_SIMCARD_FAULT_LEN` in `rust/helpers/rcan_simcard.h`).
pub(crate) const FAULT_LEN: usize = 16;

/// The name a string module parameter (a fault's) holds now, without
/// surrounding blanks or the newline `echo` leaves: `buf` holds it.
/// Any context (the C shims keep such parameters in fixed buffers,
/// `rcan_simcard.h`).
pub(crate) fn param_word<'a>(p: &ParamStr, buf: &'a mut [u8; FAULT_LEN]) -> &'a [u8] {
    let n = p.read(buf).min(buf.len() - 1);
    buf[..n].trim_ascii()
}

/// The module of a simulated-card front-end (its `module!` type is
/// `Scoped<SimModule<Bus>>`, through a type alias): init puts the bus in
/// place and registers the cards ([`SimCards::start`] with
/// [`SimBus::cards_param`] and [`SimBus::add_card`]); exit tears it down
/// ([`SimCards::stop`]).
pub(crate) struct SimModule<B: SimBus>(PhantomData<fn() -> B>);

impl<B: SimBus> ScopedModule for SimModule<B> {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        B::sim().start(scope, B::cards_param(), B::add_card)?;
        Ok(SimModule(PhantomData))
    }
}

impl<B: SimBus> Drop for SimModule<B> {
    fn drop(&mut self) {
        B::sim().stop();
    }
}
