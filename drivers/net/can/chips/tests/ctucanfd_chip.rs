// SPDX-License-Identifier: GPL-2.0
//! The CTU CAN FD driver core (`rcan_chips::ctucanfd::Chip`) against the
//! register-level model (`rcan_chips::ctucanfd_model`): two cores on one
//! bus as on QEMU's ctucan_pci card, classic and FD frames both ways,
//! the TX ring's order, the RX budget, data overrun, stop, and the bit
//! timing registers. The model encodes frames by its own reading of the
//! datasheet, so a round trip checks the driver's encoding against it.

use proptest::prelude::*;
use rcan_chips::ctucanfd::*;
use rcan_chips::ctucanfd_model::{BusFrame, CtuModel, Fault};
use rcan_core::arb::CAN_ERR_FLAG;
use rcan_core::arb::{CAN_EFF_FLAG, CAN_RTR_FLAG};
use rcan_core::bittiming::{self, Bittiming};
use rcan_core::candev::{err, CanState};
use rcan_core::frame::{
    can_fd_dlc2len, AnyFrame, CanFdFrame, CanFrame, CANFD_BRS, CANFD_ESI, CANFD_FDF,
};

fn nominal(rate: u32) -> Bittiming {
    let want = Bittiming {
        bitrate: rate,
        ..Bittiming::default()
    };
    bittiming::calc(&NOMINAL_CONST, 100_000_000, &want)
        .unwrap()
        .bt
}

fn data(rate: u32) -> Bittiming {
    let want = Bittiming {
        bitrate: rate,
        ..Bittiming::default()
    };
    bittiming::calc(&DATA_CONST, 100_000_000, &want).unwrap().bt
}

fn cfg() -> Config {
    Config {
        nominal: nominal(500_000),
        data: data(2_000_000),
        fd: true,
        ..Config::default()
    }
}

fn running(cfg: &Config) -> Chip<CtuModel> {
    let mut c = Chip::new(CtuModel::new());
    c.probe().unwrap();
    c.start(cfg);
    c
}

/// Moves every ready frame of `a` onto the bus, where `b` receives it.
fn pump(a: &mut Chip<CtuModel>, b: &mut Chip<CtuModel>) -> Vec<BusFrame> {
    let mut sent = Vec::new();
    while let Some(f) = a.regs.transmit(Fault::None, true).sent() {
        b.regs.deliver(&f);
        sent.push(f);
    }
    sent
}

fn events<R: Regs>(c: &mut Chip<R>) -> Vec<Event> {
    let mut v = Vec::new();
    c.irq(|e| v.push(e));
    v
}

fn classic(can_id: u32, d: &[u8]) -> AnyFrame {
    let mut f = CanFrame {
        can_id,
        len: d.len() as u8,
        ..CanFrame::default()
    };
    f.data[..d.len()].copy_from_slice(d);
    AnyFrame::Classic(f)
}

fn fd(can_id: u32, flags: u8, d: &[u8]) -> AnyFrame {
    let mut f = CanFdFrame {
        can_id,
        len: d.len() as u8,
        flags: flags | CANFD_FDF,
        ..CanFdFrame::default()
    };
    f.data[..d.len()].copy_from_slice(d);
    AnyFrame::Fd(f)
}

struct Dead;
impl Regs for Dead {
    fn read32(&mut self, _off: usize) -> u32 {
        u32::MAX
    }
    fn write32(&mut self, _off: usize, _val: u32) {}
}

#[test]
fn probe_finds_core_or_nothing() {
    let mut c = Chip::new(CtuModel::new());
    assert_eq!(c.probe(), Ok(()));
    assert_eq!(c.ring().buffers(), 4);
    assert_eq!(c.state(), CanState::Stopped);
    let mut d = Chip::new(Dead);
    assert_eq!(d.probe(), Err(CtuError::NoChip));
    assert!(!d.irq(|_| panic!("no events from a dead device")));
}

#[test]
fn start_programs_timing_mode_and_interrupts() {
    let cfg = cfg();
    let c = running(&cfg);
    assert!(c.regs.enabled());
    assert_eq!(c.state(), CanState::ErrorActive);
    let (b, bfd) = c.regs.bit_timing();
    assert_eq!(btr_fields(b).bitrate(100_000_000), 500_000);
    assert_eq!(btr_fd_fields(bfd).bitrate(100_000_000), 2_000_000);
    let mut c = c;
    let m = c.regs.read32(reg::MODE);
    assert_eq!(m & (mode::FDE | mode::ENA), mode::FDE | mode::ENA);
    assert_eq!(c.regs.read32(reg::INT_ENA_SET), int_enable(&cfg));
    assert!(!c.regs.irq_line());
}

#[test]
fn classic_frames_both_ways() {
    let cfg = cfg();
    let mut a = running(&cfg);
    let mut b = running(&cfg);
    let f = classic(0x123, &[0xDE, 0xAD, 0xBE, 0xEF, 1]);
    assert_eq!(a.xmit(&f), Ok((0, false)));
    let sent = pump(&mut a, &mut b);
    assert_eq!(sent.len(), 1);
    assert!(!sent[0].fd);
    assert_eq!((sent[0].id, sent[0].len), (0x123, 5));
    assert!(b.regs.irq_line());
    assert_eq!(events(&mut b), vec![Event::Rx(f)]);
    assert!(!b.regs.irq_line(), "RBNEI stays only while frames remain");
    assert!(a.regs.irq_line());
    assert_eq!(events(&mut a), vec![Event::TxDone { buf: 0, ok: true }]);
    assert!(!a.regs.irq_line());
    // And back, extended and remote.
    let g = classic(CAN_EFF_FLAG | 0x1BAD_CAFE, &[9; 8]);
    let r = classic(CAN_EFF_FLAG | CAN_RTR_FLAG | 0x42, &[0; 3]);
    b.xmit(&g).unwrap();
    b.xmit(&r).unwrap();
    pump(&mut b, &mut a);
    assert_eq!(events(&mut a), vec![Event::Rx(g), Event::Rx(r)]);
}

#[test]
fn fd_frames_every_dlc_with_flags() {
    let cfg = cfg();
    let mut a = running(&cfg);
    let mut b = running(&cfg);
    let payload: [u8; 64] = core::array::from_fn(|i| i as u8 * 3);
    for dlc in 0..16u8 {
        let n = usize::from(can_fd_dlc2len(dlc));
        for flags in [0, CANFD_BRS, CANFD_ESI, CANFD_BRS | CANFD_ESI] {
            let f = fd(0x7FF, flags, &payload[..n]);
            a.xmit(&f).unwrap();
            let sent = pump(&mut a, &mut b);
            assert!(sent[0].fd);
            assert_eq!(sent[0].brs, flags & CANFD_BRS != 0);
            assert_eq!(sent[0].esi, flags & CANFD_ESI != 0);
            assert_eq!(events(&mut b), vec![Event::Rx(f)]);
            events(&mut a);
        }
    }
}

#[test]
fn fd_frame_refused_without_fd() {
    let cfg = Config { fd: false, ..cfg() };
    let mut a = running(&cfg);
    assert_eq!(a.xmit(&fd(1, 0, &[1; 12])), Err(CtuError::BadFrame));
    assert_eq!(a.regs.read32(reg::MODE) & mode::FDE, 0);
}

#[test]
fn ring_keeps_queue_order_and_fills() {
    let cfg = cfg();
    let mut a = running(&cfg);
    let mut b = running(&cfg);
    let mut next_id = 0u32;
    let mut expect = Vec::new();
    // Batches of varying size so the oldest buffer moves around the ring.
    for batch in [4usize, 3, 1, 4, 2, 4, 3, 3, 4, 1] {
        for _ in 0..batch {
            let f = classic(next_id, &[next_id as u8]);
            expect.push(next_id);
            next_id += 1;
            let (_, full) = a.xmit(&f).unwrap();
            assert_eq!(full, a.ring().in_flight() == 4);
        }
        if batch == 4 {
            assert_eq!(a.xmit(&classic(0x7FF, &[])), Err(CtuError::Busy));
        }
        let sent = pump(&mut a, &mut b);
        let order: Vec<u32> = sent.iter().map(|f| f.id).collect();
        assert_eq!(order, expect, "bus order = queue order");
        expect.clear();
        let done: Vec<Event> = events(&mut a);
        assert_eq!(done.len(), batch);
        assert!(done
            .iter()
            .all(|e| matches!(e, Event::TxDone { ok: true, .. })));
        assert_eq!(a.ring().in_flight(), 0);
        events(&mut b);
    }
}

#[test]
fn rx_budget_leaves_the_rest_pending() {
    let cfg = cfg();
    let mut b = running(&cfg);
    let mut a = running(&cfg);
    for i in 0..(RX_BUDGET + 10) as u32 {
        a.xmit(&classic(i & 0x7FF, &[i as u8])).unwrap();
        pump(&mut a, &mut b);
        events(&mut a);
    }
    let first = events(&mut b);
    assert_eq!(first.len(), RX_BUDGET);
    assert!(b.regs.irq_line(), "frames left: the interrupt stays");
    let rest = events(&mut b);
    assert_eq!(rest.len(), 10);
    assert_eq!(
        rest[9],
        Event::Rx(classic((RX_BUDGET + 9) as u32, &[(RX_BUDGET + 9) as u8]))
    );
    assert!(!b.regs.irq_line());
}

#[test]
fn overrun_reported_and_buffer_kept() {
    let cfg = cfg();
    let mut b = running(&cfg);
    let big = BusFrame {
        id: 5,
        ext: false,
        rtr: false,
        fd: true,
        brs: true,
        esi: false,
        len: 64,
        data: [0x5A; 64],
    };
    let mut stored = 0;
    while b.regs.deliver(&big) {
        stored += 1;
    }
    assert_eq!(stored, rcan_chips::ctucanfd_model::RX_BUF_BYTES / 80);
    let mut rx = 0;
    let mut overruns = 0;
    while b.regs.irq_line() {
        b.irq(|e| match e {
            Event::Rx(AnyFrame::Fd(f)) => {
                assert_eq!((f.len, f.flags), (64, CANFD_FDF | CANFD_BRS));
                rx += 1
            }
            Event::Error(r) => {
                // Mainline ctucan_rx_poll: CAN_ERR_CRTL, RX overflow.
                assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::CRTL);
                assert_eq!(r.frame.data, [0, err::CRTL_RX_OVERFLOW, 0, 0, 0, 0, 0, 0]);
                assert_eq!((r.net.rx_over_errors, r.net.rx_errors), (1, 1));
                assert!(!r.bus_off && r.state.is_none());
                overruns += 1
            }
            other => panic!("{other:?}"),
        });
    }
    assert_eq!((rx, overruns), (stored, 1));
    assert_eq!(
        b.regs.read32(reg::STATUS) & status::DOR,
        0,
        "CDO cleared it"
    );
}

#[test]
fn stop_takes_the_core_off_the_bus() {
    let cfg = cfg();
    let mut a = running(&cfg);
    let mut b = running(&cfg);
    a.xmit(&classic(1, &[])).unwrap();
    b.stop();
    assert_eq!(b.state(), CanState::Stopped);
    assert!(pump(&mut a, &mut b).len() == 1);
    assert_eq!(b.regs.rx_frames(), 0);
    assert!(!b.regs.irq_line());
    // A restart brings it back with an empty ring.
    b.start(&cfg);
    a.xmit(&classic(2, &[])).unwrap();
    events(&mut a);
    pump(&mut a, &mut b);
    assert_eq!(events(&mut b), vec![Event::Rx(classic(2, &[]))]);
}

fn any_frame() -> impl Strategy<Value = AnyFrame> {
    let id = prop_oneof![
        (0u32..0x800),
        (0u32..0x2000_0000).prop_map(|i| i | CAN_EFF_FLAG)
    ];
    let cls = (
        id.clone(),
        proptest::collection::vec(any::<u8>(), 0..=8),
        any::<bool>(),
    )
        .prop_map(|(id, d, rtr)| {
            if rtr {
                classic(id | CAN_RTR_FLAG, &vec![0; d.len()])
            } else {
                classic(id, &d)
            }
        });
    let fdf = (id, 0u8..16, any::<[u8; 64]>(), 0u8..4)
        .prop_map(|(id, dlc, d, flags)| fd(id, flags, &d[..usize::from(can_fd_dlc2len(dlc))]));
    prop_oneof![cls, fdf]
}

proptest! {
    /// Any sequence of frames queued on one core arrives unchanged and
    /// in order at the other.
    #[test]
    fn frames_arrive_unchanged(frames in proptest::collection::vec(any_frame(), 1..20)) {
        let cfg = cfg();
        let mut a = running(&cfg);
        let mut b = running(&cfg);
        let mut got = Vec::new();
        for chunk in frames.chunks(3) {
            for f in chunk {
                a.xmit(f).unwrap();
            }
            pump(&mut a, &mut b);
            events(&mut a);
            b.irq(|e| if let Event::Rx(f) = e { got.push(f) });
        }
        prop_assert_eq!(got, frames);
    }
}

/// Two modelled cores on one interrupt line driven as QEMU's ctucan_pci
/// drives it: after each register write (but a TX buffer word), and
/// after a core receives a frame, the line is set from that one core's
/// state, so a core with nothing pending lowers it for both.
mod shared_line {
    use super::*;
    use std::cell::RefCell;
    use std::rc::Rc;

    struct Card {
        cores: [CtuModel; 2],
        line: bool,
    }

    struct CoreRegs {
        card: Rc<RefCell<Card>>,
        idx: usize,
        sync: bool,
    }

    impl Regs for CoreRegs {
        fn read32(&mut self, off: usize) -> u32 {
            self.card.borrow_mut().cores[self.idx].read32(off)
        }
        fn write32(&mut self, off: usize, val: u32) {
            let mut c = self.card.borrow_mut();
            let c = &mut *c;
            c.cores[self.idx].write32(off, val);
            if off >= reg::TXTB1 {
                return;
            }
            // QEMU sends within the TX_COMMAND write: the receiver
            // drives the line, then the sender.
            let other = 1 - self.idx;
            while let Some(f) = c.cores[self.idx].transmit(Fault::None, true).sent() {
                c.cores[other].deliver(&f);
                c.line = c.cores[other].irq_line();
            }
            c.line = c.cores[self.idx].irq_line();
        }
        fn irq_sync(&mut self) {
            if !self.sync {
                return;
            }
            // What the PCI front-end does: a 0 write to INT_STAT of each
            // core with a cause pending.
            for i in 0..2 {
                let pending = {
                    let mut c = self.card.borrow_mut();
                    let core = &mut c.cores[i];
                    core.read32(reg::INT_STAT) & core.read32(reg::INT_ENA_SET) != 0
                };
                if pending {
                    let mut c = self.card.borrow_mut();
                    c.cores[i].write32(reg::INT_STAT, 0);
                    c.line = c.cores[i].irq_line();
                }
            }
        }
    }

    fn card(sync: bool) -> (Rc<RefCell<Card>>, Chip<CoreRegs>, Chip<CoreRegs>) {
        let card = Rc::new(RefCell::new(Card {
            cores: [CtuModel::new(), CtuModel::new()],
            line: false,
        }));
        let mk = |idx| {
            let mut c = Chip::new(CoreRegs {
                card: card.clone(),
                idx,
                sync,
            });
            c.probe().unwrap();
            c.start(&cfg());
            c
        };
        let (a, b) = (mk(0), mk(1));
        (card, a, b)
    }

    /// Core 1 sends f1 (core 0 receives it); core 0's handler takes it;
    /// core 1 sends f2 before its own handler ran (another CPU); core 1's
    /// handler then acknowledges its two completions. Returns whether the
    /// line is up while core 0 holds f2.
    fn scenario(sync: bool) -> bool {
        let (card, mut a, mut b) = card(sync);
        b.xmit(&classic(1, &[1])).unwrap();
        assert!(card.borrow().line);
        assert_eq!(events(&mut a), vec![Event::Rx(classic(1, &[1]))]);
        b.xmit(&classic(2, &[2])).unwrap();
        let done = events(&mut b);
        assert_eq!(done.len(), 2);
        assert_eq!(card.borrow().cores[0].rx_frames(), 1, "f2 waits in core 0");
        let line = card.borrow().line;
        line
    }

    #[test]
    fn a_core_lowers_the_line_under_the_other_without_irq_sync() {
        assert!(
            !scenario(false),
            "QEMU's line semantics lose core 0's request"
        );
    }

    #[test]
    fn irq_sync_keeps_the_line_up_while_a_core_has_a_cause() {
        assert!(scenario(true));
    }
}

/// Register accesses the driver core makes per frame, classic 8 bytes
/// and FD 64 bytes, sender and receiver, in steady state (one frame at a
/// time, one interrupt each); without the PCI front-end's `irq_sync`,
/// which adds two reads per core and operation. Bounds, so that a change
/// that adds accesses to the hot path shows up here.
#[test]
fn register_accesses_per_frame() {
    let cfg = cfg();
    let mut a = running(&cfg);
    let mut b = running(&cfg);
    let mut count = |f: &AnyFrame| {
        let (ra, wa) = a.regs.accesses;
        let (rb, wb) = b.regs.accesses;
        a.xmit(f).unwrap();
        pump(&mut a, &mut b);
        events(&mut a);
        events(&mut b);
        let tx = (a.regs.accesses.0 - ra, a.regs.accesses.1 - wa);
        let rx = (b.regs.accesses.0 - rb, b.regs.accesses.1 - wb);
        (tx, rx)
    };
    let classic8 = count(&classic(0x123, &[1; 8]));
    let fd64 = count(&fd(0x123, CANFD_BRS, &[2; 64]));
    println!(
        "classic 8 bytes: tx (reads, writes) {:?}, rx {:?}",
        classic8.0, classic8.1
    );
    println!(
        "fd 64 bytes: tx (reads, writes) {:?}, rx {:?}",
        fd64.0, fd64.1
    );
    // TX: 6 buffer words, TX_COMMAND; interrupt: INT_STAT and TX_STATUS
    // read, two INT_STAT acknowledgements, the TXCE command, TX_PRIORITY.
    assert_eq!(classic8.0, (2, 11));
    // RX: INT_STAT, RX_STATUS x2, RX_DATA x 6, two acknowledgements.
    assert_eq!(classic8.1, (9, 2));
    assert_eq!(fd64.0, (2, 25));
    assert_eq!(fd64.1, (23, 2));
}

// ---------------------------------------------------------------------
// Error states and error frames (fault injection in the model; QEMU's
// core has no fault confinement, so these are host-tested only).
// ---------------------------------------------------------------------

/// EWL word: warning limit 96, error-passive limit 128, FAULT_STATE `fs`.
fn ewl(fs: u32) -> u32 {
    96 | 128 << 8 | fs
}

/// Injects a fault state and counters, raises `ints`, and returns the
/// error reports of one interrupt round.
fn inject(c: &mut Chip<CtuModel>, fs: u32, rec: u16, tec: u16, ints: u32) -> Vec<ErrReport> {
    c.regs.set_fault(ewl(fs), rec, tec);
    c.regs.raise_error(ints, 0x0023_0011);
    events(c)
        .into_iter()
        .map(|e| match e {
            Event::Error(r) => r,
            other => panic!("unexpected {other:?}"),
        })
        .collect()
}

#[test]
fn error_warning_passive_busoff_active_as_mainline() {
    let mut c = running(&cfg());
    assert_eq!(c.state(), CanState::ErrorActive);
    // Warning: TEC above the limit, TEC > REC: TX warning.
    let r = inject(&mut c, fault::ERA, 3, 100, int::EWLI);
    assert_eq!(r.len(), 1);
    let r = r[0];
    assert_eq!(c.state(), CanState::ErrorWarning);
    assert_eq!(
        r.state,
        Some((CanState::ErrorActive, CanState::ErrorWarning))
    );
    assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::CRTL | err::CNT);
    assert_eq!(r.frame.data, [0, err::CRTL_TX_WARNING, 0, 0, 0, 0, 100, 3]);
    assert_eq!((r.stats.error_warning, r.stats.error_passive), (1, 0));
    assert!(!r.bus_off);
    // Warning with REC the larger: RX warning.
    let r = inject(&mut c, fault::ERA, 110, 20, int::EWLI)[0];
    assert_eq!(r.frame.data[1], err::CRTL_RX_WARNING);
    // Passive from the RX side (REC > 127), then from the TX side.
    let r = inject(&mut c, fault::ERP, 130, 20, int::FCSI)[0];
    assert_eq!(c.state(), CanState::ErrorPassive);
    assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::CRTL | err::CNT);
    assert_eq!(r.frame.data, [0, err::CRTL_RX_PASSIVE, 0, 0, 0, 0, 20, 130]);
    assert_eq!(r.stats.error_passive, 1);
    let r = inject(&mut c, fault::ERP, 0, 200, int::FCSI)[0];
    assert_eq!(r.frame.data[1], err::CRTL_TX_PASSIVE);
    // Bus-off: CAN_ERR_BUSOFF alone, no counters.
    let r = inject(&mut c, fault::BOF, 0, 256, int::FCSI)[0];
    assert_eq!(c.state(), CanState::BusOff);
    assert!(r.bus_off);
    assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::BUSOFF);
    assert_eq!(r.frame.data, [0; 8]);
    assert_eq!(r.stats.bus_off, 1);
    // Restart: reset and start again, error active, counters cleared.
    c.restart();
    assert_eq!(c.state(), CanState::ErrorActive);
    assert_eq!(c.berr_counter(), (0, 0));
    assert!(c.regs.enabled());
    // Back to active by FCSI: CRTL_ACTIVE with the counters.
    let r = inject(&mut c, fault::ERA, 1, 2, int::FCSI)[0];
    assert_eq!(c.state(), CanState::ErrorActive);
    assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::CRTL | err::CNT);
    assert_eq!(r.frame.data, [0, err::CRTL_ACTIVE, 0, 0, 0, 0, 2, 1]);
    assert_eq!(r.stats, Default::default());
    assert!(!c.regs.irq_line(), "every cause acknowledged");
}

#[test]
fn state_kept_when_fault_state_reads_zero() {
    // QEMU's core: FAULT_STATE 0. An FCSI then changes nothing and
    // makes no error frame.
    let mut c = running(&cfg());
    let r = inject(&mut c, 0, 0, 0, int::FCSI);
    assert!(r.is_empty(), "no empty error frame: {r:?}");
    assert_eq!(c.state(), CanState::ErrorActive);
    assert!(!c.regs.irq_line());
}

#[test]
fn bus_errors_and_arbitration_lost_only_with_berr_reporting() {
    // Without berr-reporting BEI and ALI are masked: never latched.
    let mut c = running(&cfg());
    assert!(inject(&mut c, fault::ERA, 0, 0, int::BEI | int::ALI).is_empty());
    assert!(!c.regs.irq_line());
    let mut c = running(&Config {
        berr_reporting: true,
        ..cfg()
    });
    let r = inject(&mut c, fault::ERA, 0, 8, int::BEI)[0];
    assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::PROT | err::BUSERROR);
    // Mainline: type and location unspecified.
    assert_eq!(r.frame.data, [0; 8]);
    assert_eq!((r.stats.bus_error, r.net.rx_errors), (1, 1));
    assert_eq!(r.err_capt, 0x0023_0011, "ERR_CAPT read for the log");
    let r = inject(&mut c, fault::ERA, 0, 8, int::ALI)[0];
    assert_eq!(r.frame.can_id, CAN_ERR_FLAG | err::LOSTARB);
    assert_eq!(r.frame.data[0], err::LOSTARB_UNSPEC);
    assert_eq!(r.stats.arbitration_lost, 1);
    // All at once: one frame with every class.
    let r = inject(&mut c, fault::ERP, 0, 130, int::BEI | int::ALI | int::FCSI)[0];
    assert_eq!(
        r.frame.can_id,
        CAN_ERR_FLAG | err::PROT | err::BUSERROR | err::LOSTARB | err::CRTL | err::CNT
    );
    assert_eq!(r.frame.data[1], err::CRTL_TX_PASSIVE);
    assert_eq!(
        (
            r.stats.bus_error,
            r.stats.arbitration_lost,
            r.stats.error_passive
        ),
        (1, 1, 1)
    );
    assert!(!c.regs.irq_line());
}

#[test]
fn control_modes_in_the_mode_register() {
    // Mainline ctucan_set_mode: ILBP, BMM, STM, RTRLE (RTRTH 0), FDE,
    // NISOFD; ENA set last by start.
    let cases: [(Config, u32); 6] = [
        (
            Config {
                loopback: true,
                ..cfg()
            },
            mode::ILBP,
        ),
        (
            Config {
                listen_only: true,
                ..cfg()
            },
            mode::BMM,
        ),
        (
            Config {
                presume_ack: true,
                ..cfg()
            },
            mode::STM,
        ),
        (
            Config {
                one_shot: true,
                ..cfg()
            },
            mode::RTRLE,
        ),
        (
            Config {
                fd_non_iso: true,
                ..cfg()
            },
            mode::NISOFD,
        ),
        (cfg(), 0),
    ];
    let others = mode::ILBP | mode::BMM | mode::STM | mode::RTRLE | mode::NISOFD;
    for (c, bit) in cases {
        let chip = running(&c);
        let mut regs = chip.regs;
        let m = regs.read32(reg::MODE);
        assert_eq!(m & others, bit, "{c:?}");
        assert_eq!(m & (mode::ENA | mode::FDE), mode::ENA | mode::FDE);
        assert_eq!(m & (0xF << mode::RTRTH_SHIFT), 0, "retransmit limit 0");
    }
    // Interrupts: BEI and ALI with berr-reporting only.
    let e = int_enable(&Config {
        berr_reporting: true,
        ..cfg()
    });
    assert_eq!(e & (int::BEI | int::ALI), int::BEI | int::ALI);
    assert_eq!(int_enable(&cfg()) & (int::BEI | int::ALI), 0);
}
