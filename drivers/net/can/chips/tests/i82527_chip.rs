// SPDX-License-Identifier: GPL-2.0
//! The 82527 driver core (`rcan_chips::i82527::Chip`) against the
//! register-level model (`rcan_chips::i82527_model`), two chips on one
//! simulated bus: probing, the thesis' message-object allocation (5.3.10),
//! transmit and receive of every frame kind, automatic remote answers,
//! the single transmit object, object 15's double buffer and overrun,
//! the interrupt priority order, error warning and bus-off with recovery,
//! the masks keeping unwanted frames out, and a host that falls behind
//! losing nothing on the simulated bus (`sim_bus::round`).

use rcan_chips::i82527::*;
use rcan_chips::i82527_model::{Fault, I82527Model, TxAttempt};
use rcan_chips::sja1000::Wanted;
use rcan_core::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_RTR_FLAG, CAN_SFF_MASK};
use rcan_core::frame::CanFrame;
use rcan_core::rxtable::{CanFilterKind, Filter};
use std::cell::RefCell;
use std::rc::Rc;

fn frame(can_id: u32, data: &[u8]) -> CanFrame {
    let mut f = CanFrame {
        can_id,
        len: data.len() as u8,
        ..CanFrame::default()
    };
    f.data[..data.len()].copy_from_slice(data);
    f
}

fn remote(can_id: u32, dlc: u8) -> CanFrame {
    CanFrame {
        can_id: can_id | CAN_RTR_FLAG,
        len: dlc,
        ..CanFrame::default()
    }
}

fn raw(id: u32, mask: u32) -> Filter {
    match Filter::from_can_filter(id, mask) {
        CanFilterKind::Frames(f) => f,
        CanFilterKind::Errors(_) => unreachable!(),
    }
}

type C = Chip<I82527Model>;

fn chip(masks: &Masks) -> C {
    let mut c = Chip::new(I82527Model::new(), Config::DEFAULT);
    c.probe().unwrap();
    c.init(masks);
    c.start();
    c
}

/// Moves frames between the chips until nobody has anything to send;
/// returns the frames that went on the bus, in order.
fn run_bus(chips: &mut [&mut C]) -> Vec<CanFrame> {
    let mut out = Vec::new();
    loop {
        let mut moved = false;
        for i in 0..chips.len() {
            if let Some(f) = chips[i].regs.transmit() {
                for (j, c) in chips.iter_mut().enumerate() {
                    if j != i {
                        c.regs.receive(&f);
                    }
                }
                out.push(f);
                moved = true;
            }
        }
        if !moved {
            return out;
        }
    }
}

fn irq(c: &mut C) -> Vec<Event> {
    let mut ev = Vec::new();
    c.irq(64, |e| ev.push(e));
    assert!(!c.regs.irq_line(), "interrupt line still raised");
    ev
}

fn rx_frames(ev: &[Event]) -> Vec<CanFrame> {
    ev.iter()
        .filter_map(|e| match e {
            Event::Rx(f) => Some(*f),
            _ => None,
        })
        .collect()
}

fn cfg_of(c: &mut C, n: u8) -> u8 {
    c.regs.read(reg::obj(n) + reg::CFG)
}

fn valid(c: &C, n: u8) -> bool {
    bits::is_set(c.regs.ctrl_bytes(n).0, bits::MSGVAL)
}

#[test]
fn probe_finds_the_chip_or_nothing() {
    let mut absent = I82527Model::new();
    absent.absent = true;
    let mut c = Chip::new(absent, Config::DEFAULT);
    assert_eq!(c.probe(), Err(I82527Error::NoChip));
    let mut c = Chip::new(I82527Model::new(), Config::DEFAULT);
    assert_eq!(c.probe(), Ok(()));
    assert!(c.regs.in_init());
    // Plain memory that keeps what is written is not an 82527.
    struct Ram([u8; 256]);
    impl Regs for Ram {
        fn read(&mut self, reg: u8) -> u8 {
            self.0[usize::from(reg)]
        }
        fn write(&mut self, reg: u8, val: u8) {
            self.0[usize::from(reg)] = val;
        }
    }
    let mut c = Chip::new(Ram([0; 256]), Config::DEFAULT);
    assert_eq!(c.probe(), Err(I82527Error::NoChip));
}

#[test]
fn init_programs_clocking_and_timing() {
    let cfg = Config {
        cpu_if: cpu_if::DSC | cpu_if::CEN,
        clkout: 0x03,
        bus_cfg: 0x40,
        bt0: 0x01,
        bt1: 0x2B,
    };
    let mut c = Chip::new(I82527Model::new(), cfg);
    c.probe().unwrap();
    c.init(&masks_for(&[], false));
    assert_eq!(c.regs.read(reg::BT0), 0x01);
    assert_eq!(c.regs.read(reg::BT1), 0x2B);
    assert_eq!(c.regs.read(reg::CLKOUT), 0x03);
    assert_eq!(c.regs.read(reg::CPU_IF), cpu_if::DSC | cpu_if::CEN);
    assert_eq!(bitrate(0x01, 0x2B, cfg.cpu_if, 16_000_000), 250_000);
    assert_eq!(clkout_hz(0x03, cfg.cpu_if, 16_000_000), 4_000_000);
    assert!(c.regs.in_init());
    // Bit timing is only writable with CCE: the model drops a write
    // without it, like the chip.
    c.start();
    c.regs.write(reg::BT0, 0x3F);
    assert_eq!(c.regs.read(reg::BT0), 0x01);
    assert!(!c.regs.in_init());
}

#[test]
fn allocation_follows_the_thesis() {
    let mut c = chip(&Masks::OPEN);
    // Object 1: standard receive; object 15: extended receive.
    assert!(valid(&c, STD_RX) && valid(&c, EXT_RX));
    assert_eq!(cfg_of(&mut c, STD_RX) & (mcfg::DIR | mcfg::XTD), 0);
    assert_eq!(cfg_of(&mut c, EXT_RX) & (mcfg::DIR | mcfg::XTD), mcfg::XTD);
    // Answer objects and the transmit object are invalid until used.
    for n in ANSWER_FIRST..=TX_OBJ {
        assert!(!valid(&c, n), "object {n}");
    }
    assert_eq!(ANSWERS, 12);
    // A transmission uses object 14 and only it.
    c.xmit(&frame(0x10, &[1])).unwrap();
    for n in 1..=15 {
        let busy = bits::is_set(c.regs.ctrl_bytes(n).1, bits::TXRQST);
        assert_eq!(busy, n == TX_OBJ, "object {n}");
    }
    assert_eq!(c.xmit(&frame(0x11, &[])), Err(I82527Error::Busy));
    // Twelve answers go to objects 2..13, a thirteenth is refused.
    for slot in 0..ANSWERS {
        c.set_answer(slot, Some(&frame(0x200 + slot as u32, &[slot as u8])))
            .unwrap();
        let n = ANSWER_FIRST + slot as u8;
        assert!(valid(&c, n));
        assert_ne!(cfg_of(&mut c, n) & mcfg::DIR, 0);
    }
    assert_eq!(
        c.set_answer(ANSWERS, Some(&frame(0x300, &[]))),
        Err(I82527Error::BadSlot)
    );
    assert_eq!(
        c.set_answer(0, Some(&remote(0x300, 0))),
        Err(I82527Error::BadFrame)
    );
}

#[test]
fn frames_both_ways_every_kind() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    let data = [1u8, 2, 3, 4, 5, 6, 7, 8];
    for dlc in 0..=8usize {
        for id in [0x000, 0x123 + dlc as u32, 0x7FF] {
            for ext in [false, true] {
                let id = if ext {
                    (id << 18 | 0x2A5A5) | CAN_EFF_FLAG
                } else {
                    id
                };
                let f = frame(id, &data[..dlc]);
                for dir in 0..2 {
                    let (tx, rx) = if dir == 0 {
                        (&mut a, &mut b)
                    } else {
                        (&mut b, &mut a)
                    };
                    tx.xmit(&f).unwrap();
                    let bus = run_bus(&mut [&mut *tx, &mut *rx]);
                    assert_eq!(bus, vec![f]);
                    assert_eq!(irq(tx), vec![Event::TxDone]);
                    assert!(!valid(tx, TX_OBJ), "transmit object left valid");
                    assert_eq!(irq(rx), vec![Event::Rx(f)]);
                }
            }
        }
    }
}

#[test]
fn remote_frame_is_answered_by_the_chip_without_the_host() {
    let mut a = chip(&Masks::OPEN);
    // B receives nothing: its global standard mask stays exact, so its
    // standard answer objects answer their own identifier only.
    let exact = masks_for(&[], false);
    assert!(exact.std_answers_exact());
    let mut b = chip(&exact);
    let answer = frame(0x321, &[0xDE, 0xAD]);
    let eanswer = frame(0x1234_5678 | CAN_EFF_FLAG, &[1, 2, 3, 4, 5]);
    b.set_answer(0, Some(&answer)).unwrap();
    b.set_answer(11, Some(&eanswer)).unwrap();
    for (req, ans) in [
        (remote(0x321, 2), answer),
        (remote(0x1234_5678 | CAN_EFF_FLAG, 5), eanswer),
    ] {
        a.xmit(&req).unwrap();
        let bus = run_bus(&mut [&mut a, &mut b]);
        assert_eq!(bus, vec![req, ans]);
        // B's host was never interrupted.
        assert!(!b.regs.irq_line());
        // A standard answer lands in object 1, which outranks the
        // transmit object in the interrupt register; an extended one in
        // the transmit object itself (14 comes before 15), read with the
        // completion.
        assert_eq!(irq(&mut a), vec![Event::Rx(ans), Event::TxDone]);
    }
    assert_eq!(b.regs.answered, 2);
    // A remote frame nobody answers is not seen by anybody's host: on
    // the 82527 only transmit objects react to remote frames.
    a.xmit(&remote(0x322, 0)).unwrap();
    assert_eq!(run_bus(&mut [&mut a, &mut b]).len(), 1);
    assert!(!b.regs.irq_line());
    assert_eq!(irq(&mut a), vec![Event::TxDone]);
    // Withdrawn: no answer any more.
    b.set_answer(0, None).unwrap();
    a.xmit(&remote(0x321, 2)).unwrap();
    assert_eq!(run_bus(&mut [&mut a, &mut b]).len(), 1);
    irq(&mut a);
    // The price of a loose global standard mask (B receiving every
    // standard frame): a standard answer object answers remote frames for
    // other identifiers too, with its own identifier.
    b.set_masks(&Masks::OPEN);
    assert!(!b.masks.std_answers_exact());
    b.set_answer(0, Some(&answer)).unwrap();
    a.xmit(&remote(0x322, 2)).unwrap();
    assert_eq!(
        run_bus(&mut [&mut a, &mut b]),
        vec![remote(0x322, 2), answer]
    );
}

#[test]
fn answer_updated_under_cpuupd_is_never_torn() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    b.set_answer(3, Some(&frame(0x55, &[1, 1]))).unwrap();
    // The host starts an update (CPUUpd), a request arrives meanwhile.
    let n = ANSWER_FIRST + 3;
    let k = bits::KEEP;
    b.regs
        .write(reg::obj(n) + reg::CTRL1, bits::byte(k, k, bits::SET, k));
    a.xmit(&remote(0x55, 2)).unwrap();
    assert_eq!(
        run_bus(&mut [&mut a, &mut b]).len(),
        1,
        "answered during update"
    );
    assert!(bits::is_set(b.regs.ctrl_bytes(n).1, bits::RMTPND));
    // The driver's republish finishes the update: the answer goes out
    // with the new data.
    b.set_answer(3, Some(&frame(0x55, &[2, 2]))).unwrap();
    assert_eq!(run_bus(&mut [&mut a, &mut b]), vec![frame(0x55, &[2, 2])]);
}

#[test]
fn one_transmit_object_because_masks_make_it_answer() {
    // Why the thesis has exactly one transmit object, invalidated after
    // use: with a loose global standard mask, a still-valid transmit object
    // matches remote frames of other identifiers and re-sends.
    let loose = masks_for(&[Wanted::of(&raw(0, 0))], false);
    assert_eq!(loose.gms, 0);
    let mut a = chip(&loose);
    let mut b = chip(&loose);
    a.xmit(&frame(0x100, &[9])).unwrap();
    assert_eq!(run_bus(&mut [&mut a, &mut b]).len(), 1);
    // Before the driver's interrupt handler ran, the object is valid: a
    // remote frame for 0x200 would make it re-send 0x100.
    b.xmit(&remote(0x200, 1)).unwrap();
    let bus = run_bus(&mut [&mut a, &mut b]);
    assert_eq!(bus, vec![remote(0x200, 1), frame(0x100, &[9])]);
    // After the handler invalidated it, it never does.
    let ev = irq(&mut a);
    assert_eq!(ev[0], Event::TxDone);
    let _ = irq(&mut b);
    b.xmit(&remote(0x200, 1)).unwrap();
    let bus = run_bus(&mut [&mut a, &mut b]);
    assert_eq!(bus, vec![remote(0x200, 1)]);
    // And a spurious second completion is not reported as a second
    // TxDone (the core counts only its own transmission).
    assert!(!irq(&mut a).contains(&Event::TxDone));
}

#[test]
fn object_15_double_buffer_and_overrun() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    let f = |i: u8| frame((0x1000 + u32::from(i)) | CAN_EFF_FLAG, &[i]);
    // Two frames before the host reads: the second waits in the shadow
    // buffer, nothing is lost.
    for i in 0..2 {
        a.xmit(&f(i)).unwrap();
        run_bus(&mut [&mut a, &mut b]);
        irq(&mut a);
    }
    assert!(b.regs.shadow_full());
    assert_eq!(irq(&mut b), vec![Event::Rx(f(0)), Event::Rx(f(1))]);
    // Three: the third overwrites the second in the shadow buffer; the
    // loss (MsgLst) is seen when the foreground is read.
    for i in 2..5 {
        a.xmit(&f(i)).unwrap();
        run_bus(&mut [&mut a, &mut b]);
        irq(&mut a);
    }
    assert_eq!(
        irq(&mut b),
        vec![
            Event::Overrun { obj: EXT_RX },
            Event::Rx(f(2)),
            Event::Rx(f(4))
        ]
    );
    // Object 1 has one buffer: a second frame overwrites the first.
    for i in 0..2u8 {
        a.xmit(&frame(0x10 + u32::from(i), &[i])).unwrap();
        run_bus(&mut [&mut a, &mut b]);
        irq(&mut a);
    }
    assert_eq!(
        irq(&mut b),
        vec![Event::Overrun { obj: STD_RX }, Event::Rx(frame(0x11, &[1]))]
    );
    let e = error_frame(&Event::Overrun { obj: STD_RX }).unwrap();
    assert_eq!(e.data[1], rcan_core::candev::err::CRTL_RX_OVERFLOW);
}

/// Chip `a` sends `f` to `b` (`pending_frame` shows it first); `a`'s
/// host handles the completion, `b`'s reads nothing.
fn send(a: &mut C, b: &mut C, f: CanFrame) {
    a.xmit(&f).unwrap();
    assert_eq!(a.regs.pending_frame(), Some(f));
    assert_eq!(run_bus(&mut [&mut *a, &mut *b]), vec![f]);
    assert_eq!(irq(a), vec![Event::TxDone]);
    assert_eq!(a.regs.pending_frame(), None);
}

/// `ready_for` tells beforehand whether taking a frame keeps every
/// frame the host has not read, in bus order: not when the frame's
/// object holds an unread one (object 1 once, object 15 once its shadow
/// buffer is full too), nor an extended frame while object 1 holds one
/// (the host reads object 15 first); a standard frame after unread
/// extended ones is fine. Remote frames, and any frame while the chip is
/// off the bus, always. Sent anyway, a frame overruns as predicted.
#[test]
fn ready_for_guards_frames_and_their_order() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    let s = |i: u8| frame(0x10 + u32::from(i), &[i]);
    let e = |i: u8| frame((0x1000 + u32::from(i)) | CAN_EFF_FLAG, &[i]);
    assert!(b.regs.ready_for(&s(0)) && b.regs.ready_for(&e(0)));
    assert_eq!(a.regs.pending_frame(), None);
    send(&mut a, &mut b, s(0));
    assert!(!b.regs.ready_for(&s(1)), "object 1 holds an unread frame");
    assert!(!b.regs.ready_for(&e(0)), "object 15 would be read first");
    assert!(b.regs.ready_for(&remote(0x11, 1)));
    assert_eq!(irq(&mut b), vec![Event::Rx(s(0))]);
    // Object 15: the foreground buffer, then the shadow buffer; a
    // standard frame after them is read after them.
    send(&mut a, &mut b, e(0));
    assert!(b.regs.ready_for(&e(1)), "the shadow buffer is free");
    send(&mut a, &mut b, e(1));
    assert!(!b.regs.ready_for(&e(2)));
    assert!(b.regs.ready_for(&s(1)));
    send(&mut a, &mut b, s(1));
    assert!(!b.regs.ready_for(&s(2)) && !b.regs.ready_for(&e(2)));
    assert_eq!(
        irq(&mut b),
        vec![Event::Rx(e(0)), Event::Rx(e(1)), Event::Rx(s(1))]
    );
    assert!(b.regs.ready_for(&s(2)) && b.regs.ready_for(&e(2)));
    // The prediction holds: sent anyway, the frame overruns.
    send(&mut a, &mut b, s(2));
    assert!(!b.regs.ready_for(&s(3)));
    send(&mut a, &mut b, s(3));
    assert_eq!(
        irq(&mut b),
        vec![Event::Overrun { obj: STD_RX }, Event::Rx(s(3))]
    );
    // Off the bus, a chip takes nothing and so loses nothing.
    send(&mut a, &mut b, s(4));
    b.stop();
    assert!(b.regs.ready_for(&s(5)));
}

/// The interrupt output off (`set_irq_enabled(false)`): the chip still
/// receives and keeps the cause pending; on again, the output is raised
/// and the frame read. INIT, which the chip sets by itself at bus-off,
/// is left alone either way.
#[test]
fn interrupt_output_off_keeps_causes_pending() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    b.set_irq_enabled(false);
    a.xmit(&frame(0x42, &[4, 2])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    irq(&mut a);
    assert!(!b.regs.irq_line(), "output raised while off");
    assert_ne!(b.regs.int_reg(), intid::NONE, "cause not pending");
    assert!(!b.regs.in_init());
    b.set_irq_enabled(true);
    assert!(b.regs.irq_line());
    assert_eq!(irq(&mut b), vec![Event::Rx(frame(0x42, &[4, 2]))]);
    b.regs.set_errors(256, 0);
    assert!(b.regs.in_init() && b.regs.bus_off());
    b.set_irq_enabled(false);
    b.set_irq_enabled(true);
    assert!(b.regs.in_init(), "INIT cleared: bus-off recovery started");
}

/// Register access of chip `.1` among the models on one shared bus, so
/// that the driver core (`Chip`) and the simulated bus's round
/// (`sim_bus::round`, as the simulated cards run it) reach the same
/// models.
struct OnBus(Rc<RefCell<Vec<I82527Model>>>, usize);

impl Regs for OnBus {
    fn read(&mut self, r: u8) -> u8 {
        self.0.borrow_mut()[self.1].read(r)
    }

    fn write(&mut self, r: u8, v: u8) {
        self.0.borrow_mut()[self.1].write(r, v)
    }
}

/// Two chips on a shared simulated bus, both started with open masks.
fn shared_bus() -> (Rc<RefCell<Vec<I82527Model>>>, [Chip<OnBus>; 2]) {
    let bus = Rc::new(RefCell::new(vec![I82527Model::new(), I82527Model::new()]));
    let mk = |i| {
        let mut c = Chip::new(OnBus(Rc::clone(&bus), i), Config::DEFAULT);
        c.probe().unwrap();
        c.init(&Masks::OPEN);
        c.start();
        c
    };
    let chips = [mk(0), mk(1)];
    (bus, chips)
}

/// Chip 0 sends `n` numbered frames (standard and extended alternately,
/// the next once the last completed) to chip 1 over `sim_bus::round` with
/// `fault`; chip 1's host is `behind(round)`: then its interrupt output is
/// off and it reads nothing (a driver whose receive queue is full), else
/// it reads whatever its chip raised. Returns chip 1's events and how
/// many rounds the bus held a frame back.
fn burst_to_a_slow_host(
    n: u32,
    fault: Fault,
    copies: usize,
    behind: impl Fn(usize) -> bool,
) -> (Vec<Event>, Vec<CanFrame>, usize) {
    let (bus, [mut a, mut b]) = shared_bus();
    let f = |i: u32| {
        if i % 2 == 0 {
            frame(0x100 + (i & 0x3FF), &i.to_le_bytes())
        } else {
            frame((0x0100_0000 + i) | CAN_EFF_FLAG, &i.to_le_bytes())
        }
    };
    let (mut sent, mut next, mut held) = (0u32, 0usize, 0usize);
    let (mut events, mut frames) = (Vec::new(), Vec::new());
    for r in 0..20 * n as usize {
        if sent < n && !a.tx_busy() {
            a.xmit(&f(sent)).unwrap();
            frames.push(f(sent));
            sent += 1;
        }
        let out = rcan_chips::sim_bus::round(&mut bus.borrow_mut()[..], &mut next, fault, copies);
        held += usize::from(out.held());
        if bus.borrow()[0].irq_line() {
            a.irq(64, |_| {});
        }
        if behind(r) {
            b.set_irq_enabled(false);
        } else {
            b.set_irq_enabled(true);
            if bus.borrow()[1].irq_line() {
                b.irq(64, |e| events.push(e));
            }
        }
        if sent == n && !a.tx_busy() && !behind(r) && !bus.borrow()[1].irq_line() {
            break;
        }
    }
    assert_eq!(sent, n, "the sender did not get all frames out");
    (events, frames, held)
}

/// The simulated bus does not outrun a host that falls behind: while the
/// host reads nothing (its interrupt output off, as the driver does when
/// its receive queue is full), the sender's next frame waits on the bus
/// instead of overrunning the unread object; once the host reads again,
/// every frame arrives, once, in order, and no MsgLst is seen.
#[test]
fn a_host_that_falls_behind_loses_nothing_on_the_simulated_bus() {
    let behind = |r: usize| r < 7 || (30..45).contains(&r) || r % 11 == 3;
    let (ev, sent, held) = burst_to_a_slow_host(60, Fault::None, 1, behind);
    assert!(held > 0, "the bus never held a frame back");
    assert!(
        !ev.iter().any(|e| matches!(e, Event::Overrun { .. })),
        "overrun: {ev:?}"
    );
    assert_eq!(rx_frames(&ev), sent);
}

proptest::proptest! {
    /// Whenever the host falls behind and for however long, as long as it
    /// comes back: every frame, once, in bus order, no overrun.
    #[test]
    fn any_slow_host_loses_nothing(
        pattern in proptest::collection::vec(proptest::bool::ANY, 1..40),
        n in 1u32..40,
    ) {
        let behind = |r: usize| r < 10 * n as usize && pattern[r % pattern.len()];
        let (ev, sent, _) = burst_to_a_slow_host(n, Fault::None, 1, behind);
        let overrun = ev.iter().any(|e| matches!(e, Event::Overrun { .. }));
        proptest::prop_assert!(!overrun, "overrun: {:?}", ev);
        proptest::prop_assert_eq!(rx_frames(&ev), sent);
    }
}

/// The `overrun` fault (every frame offered twice before the host can
/// read) still overruns: the wait before a frame goes out does not hide
/// what the fault injects. Object 1 loses the first copy of each
/// standard frame (MsgLst); object 15 keeps both copies of an extended
/// one (its shadow buffer).
#[test]
fn the_overrun_fault_still_overruns_on_the_simulated_bus() {
    let (ev, sent, held) = burst_to_a_slow_host(10, Fault::Overrun, 2, |_| false);
    assert_eq!(held, 0);
    let overruns = ev
        .iter()
        .filter(|e| matches!(e, Event::Overrun { obj: STD_RX }))
        .count();
    assert_eq!(overruns, 5, "{ev:?}");
    let want: Vec<CanFrame> = sent
        .iter()
        .flat_map(|f| {
            let copies = if f.can_id & CAN_EFF_FLAG != 0 { 2 } else { 1 };
            std::iter::repeat_n(*f, copies)
        })
        .collect();
    assert_eq!(rx_frames(&ev), want);
}

#[test]
fn interrupt_register_priority() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    b.regs.write(reg::CONTROL, ctrl::IE | ctrl::EIE);
    // Standard (object 1) and extended (object 15) frames pending, a
    // transmission done (object 14), and a status change.
    a.xmit(&frame(0x1, &[])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    irq(&mut a);
    a.xmit(&frame(0x1 | CAN_EFF_FLAG, &[])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    irq(&mut a);
    b.xmit(&frame(0x2, &[])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    b.regs.set_errors(100, 0);
    assert_eq!(b.regs.int_reg(), intid::STATUS);
    let _ = b.regs.read(reg::STATUS);
    assert_eq!(b.regs.int_reg(), intid::OBJ15);
    let k = bits::KEEP;
    b.regs
        .write(reg::obj(15) + reg::CTRL0, bits::byte(k, k, k, bits::RES));
    assert_eq!(b.regs.int_reg(), STD_RX + 2);
    b.regs
        .write(reg::obj(1) + reg::CTRL0, bits::byte(k, k, k, bits::RES));
    assert_eq!(b.regs.int_reg(), TX_OBJ + 2);
    b.regs
        .write(reg::obj(14) + reg::CTRL0, bits::byte(k, k, k, bits::RES));
    assert_eq!(b.regs.int_reg(), intid::NONE);
}

#[test]
fn events_come_in_priority_order() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    a.xmit(&frame(0x7, &[7])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    irq(&mut a);
    a.xmit(&frame(0x8 | CAN_EFF_FLAG, &[8])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    irq(&mut a);
    b.regs.set_errors(96, 0);
    assert_eq!(
        irq(&mut b),
        vec![
            Event::State(State::Warning),
            Event::Rx(frame(0x8 | CAN_EFF_FLAG, &[8])),
            Event::Rx(frame(0x7, &[7])),
        ]
    );
}

#[test]
fn warning_and_bus_off_with_restart() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    a.regs.set_errors(100, 0);
    assert_eq!(irq(&mut a), vec![Event::State(State::Warning)]);
    a.regs.set_errors(0, 0);
    assert_eq!(irq(&mut a), vec![Event::State(State::Active)]);
    // Bus-off with a frame waiting in the transmit object.
    a.xmit(&frame(0x42, &[1])).unwrap();
    a.regs.set_errors(256, 0);
    assert!(a.regs.in_init(), "the chip sets INIT at bus-off");
    assert_eq!(
        irq(&mut a),
        vec![Event::State(State::BusOff), Event::TxAborted]
    );
    assert_eq!(a.state(), State::BusOff);
    // The driver leaves the chip off the bus (mainline can_bus_off):
    // INIT stays, the idle bus changes nothing.
    assert!(a.regs.in_init());
    a.regs.bus_idle();
    assert!(a.regs.bus_off());
    assert!(irq(&mut a).is_empty());
    // The restart (restart-ms or `ip ... restart`): INIT cleared, the
    // chip waits for bus idle, sending nothing, then rejoins with no
    // second state event.
    a.restart(&Masks::OPEN);
    assert_eq!(a.state(), State::Active);
    assert!(!a.regs.in_init());
    assert!(a.regs.bus_off());
    a.xmit(&frame(0x43, &[2])).unwrap();
    assert_eq!(
        a.regs.attempt(Fault::None),
        TxAttempt::Idle,
        "a recovering chip sends nothing"
    );
    a.regs.bus_idle();
    assert!(!a.regs.bus_off());
    assert!(irq(&mut a).is_empty());
    assert_eq!(a.restarts, 1);
    assert_eq!(a.setup().restarts, 1);
    // Back on the bus.
    assert_eq!(run_bus(&mut [&mut a, &mut b]), vec![frame(0x43, &[2])]);
    assert_eq!(irq(&mut a), vec![Event::TxDone]);
    let e = error_frame(&Event::State(State::BusOff)).unwrap();
    assert_eq!(
        e.can_id & rcan_core::candev::err::BUSOFF,
        rcan_core::candev::err::BUSOFF
    );
}

/// Attempts on a faulty bus until the chip stops trying; the events of
/// each interrupt.
fn attempts(c: &mut C, fault: Fault, max: usize) -> Vec<Vec<Event>> {
    let mut out = Vec::new();
    for _ in 0..max {
        if c.regs.attempt(fault) != TxAttempt::Failed {
            break;
        }
        out.push(irq(c));
    }
    out
}

#[test]
fn bit_errors_to_bus_off_with_berr_reporting() {
    use rcan_core::candev::err;
    let mut a = chip(&Masks::OPEN);
    a.berr_reporting = true;
    a.start();
    a.xmit(&frame(0x10, &[1])).unwrap();
    let evs = attempts(&mut a, Fault::BitErr, 100);
    assert_eq!(evs.len(), 32, "bus-off after 32 bit errors");
    let be = Event::BusError { lec: 5 };
    for (i, e) in evs.iter().enumerate() {
        let want = match i {
            11 => vec![be, Event::State(State::Warning)],
            31 => vec![be, Event::State(State::BusOff), Event::TxAborted],
            _ => vec![be],
        };
        assert_eq!(e, &want, "attempt {i}");
    }
    assert!(a.regs.in_init());
    let f = error_frame(&be).unwrap();
    assert_eq!(
        f.can_id,
        rcan_core::arb::CAN_ERR_FLAG | err::PROT | err::BUSERROR
    );
    assert_eq!(f.data[2], err::PROT_BIT0);
    // Restart on a good bus: the frame sent next goes out.
    a.restart(&Masks::OPEN);
    a.regs.bus_idle();
    assert!(irq(&mut a).is_empty());
    let mut b = chip(&Masks::OPEN);
    a.xmit(&frame(0x11, &[2])).unwrap();
    assert_eq!(run_bus(&mut [&mut a, &mut b]), vec![frame(0x11, &[2])]);
}

#[test]
fn missing_ack_stops_at_error_passive() {
    use rcan_core::candev::err;
    let mut a = chip(&Masks::OPEN);
    a.berr_reporting = true;
    a.start();
    a.xmit(&frame(0x20, &[])).unwrap();
    let evs = attempts(&mut a, Fault::NoAck, 40);
    assert_eq!(evs.len(), 40, "a missing ACK never ends in bus-off");
    assert_eq!(a.regs.tec(), 128);
    assert_eq!(a.state(), State::Warning);
    assert!(evs[11].contains(&Event::State(State::Warning)));
    assert!(evs.iter().all(|e| e[0] == Event::BusError { lec: 3 }));
    let f = error_frame(&Event::BusError { lec: 3 }).unwrap();
    assert_eq!(
        f.can_id,
        rcan_core::arb::CAN_ERR_FLAG | err::ACK | err::BUSERROR
    );
    // Acknowledged at last: it goes out.
    assert!(matches!(a.regs.attempt(Fault::None), TxAttempt::Sent(_)));
    assert_eq!(irq(&mut a), vec![Event::TxDone]);
}

#[test]
fn without_berr_reporting_only_state_changes() {
    let mut a = chip(&Masks::OPEN);
    a.xmit(&frame(0x30, &[])).unwrap();
    let evs = attempts(&mut a, Fault::BitErr, 100);
    assert_eq!(evs.len(), 32);
    let seen: Vec<Event> = evs.into_iter().flatten().collect();
    assert_eq!(
        seen,
        vec![
            Event::State(State::Warning),
            Event::State(State::BusOff),
            Event::TxAborted
        ]
    );
}

#[test]
fn masks_keep_unwanted_frames_out() {
    const EXACT: u32 = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
    let w = [
        Wanted::of(&raw(0x123, EXACT)),
        Wanted::of(&raw(
            0x1234_5678 | CAN_EFF_FLAG,
            CAN_EFF_MASK | CAN_EFF_FLAG,
        )),
    ];
    let m = masks_for(&w, false);
    assert_eq!(m.gms, CAN_SFF_MASK);
    assert!(m.std_answers_exact());
    assert_eq!(m.m15, CAN_EFF_MASK);
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&m);
    for (f, want) in [
        (frame(0x123, &[1]), true),
        (frame(0x124, &[1]), false),
        (frame(0x1234_5678 | CAN_EFF_FLAG, &[]), true),
        (frame(0x1234_5679 | CAN_EFF_FLAG, &[]), false),
    ] {
        a.xmit(&f).unwrap();
        run_bus(&mut [&mut a, &mut b]);
        irq(&mut a);
        assert_eq!(m.receives(&f), want);
        assert_eq!(rx_frames(&irq(&mut b)), if want { vec![f] } else { vec![] });
    }
    // Nothing wanted: both receive objects invalid.
    let none = masks_for(&[], false);
    assert_eq!((none.std_rx, none.ext_rx), (None, None));
    let c = chip(&none);
    assert!(!valid(&c, STD_RX) && !valid(&c, EXT_RX));
    // Reprogramming a running chip.
    b.set_masks(&masks_for(&[Wanted::of(&raw(0x124, EXACT))], false));
    a.xmit(&frame(0x124, &[5])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    irq(&mut a);
    assert_eq!(rx_frames(&irq(&mut b)), vec![frame(0x124, &[5])]);
}

#[test]
fn answers_survive_reinit() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    b.set_answer(5, Some(&frame(0x77, &[7]))).unwrap();
    b.stop();
    b.init(&Masks::OPEN);
    b.start();
    assert_eq!(b.answer(5), Some(frame(0x77, &[7])));
    a.xmit(&remote(0x77, 1)).unwrap();
    assert_eq!(run_bus(&mut [&mut a, &mut b]).len(), 2);
}

#[test]
fn stopped_chip_is_off_the_bus() {
    let mut a = chip(&Masks::OPEN);
    let mut b = chip(&Masks::OPEN);
    b.stop();
    a.xmit(&frame(0x5, &[])).unwrap();
    run_bus(&mut [&mut a, &mut b]);
    assert!(!b.regs.irq_line());
    assert!(rx_frames(&irq(&mut b)).is_empty());
}
