// SPDX-License-Identifier: GPL-2.0
//! Fault confinement of the CTU CAN FD model (`rcan_chips::ctucanfd_model`)
//! as the driver's pure core (`rcan_chips::ctucanfd::Chip`) decodes it:
//! two cores on a bus moved as the simulated card `rcan_ctucanfd_sim`
//! moves it (one attempt per round under a named fault, the frame
//! offered to the other core, then each core's interrupt handled), with
//! the error frames, states and statistics the driver reports, up to
//! bus-off and back. The VM tests in tests/vm/src/cases/ctucanfd_sim.rs
//! expect the same sequences from the kernel.

use rcan_chips::ctucanfd::*;
use rcan_chips::ctucanfd_model::{
    err_capt, err_pos, err_type, Confinement, CtuModel, Fault, TxAttempt,
};
use rcan_core::arb::CAN_ERR_FLAG;
use rcan_core::bittiming::{self, Bittiming};
use rcan_core::candev::{err, CanState};
use rcan_core::frame::{AnyFrame, CanFrame};

fn nominal() -> Bittiming {
    let want = Bittiming {
        bitrate: 500_000,
        ..Bittiming::default()
    };
    bittiming::calc(&NOMINAL_CONST, 100_000_000, &want)
        .unwrap()
        .bt
}

fn cfg(berr: bool) -> Config {
    Config {
        nominal: nominal(),
        data: nominal(),
        berr_reporting: berr,
        ..Config::default()
    }
}

fn running(cfg: &Config) -> Chip<CtuModel> {
    let mut c = Chip::new(CtuModel::new());
    c.probe().unwrap();
    c.start(cfg);
    c
}

fn frame(id: u32, d: &[u8]) -> AnyFrame {
    let mut f = CanFrame {
        can_id: id,
        len: d.len() as u8,
        ..CanFrame::default()
    };
    f.data[..d.len()].copy_from_slice(d);
    AnyFrame::Classic(f)
}

/// One round of the simulated bus: `a` makes one attempt under `fault`
/// (acknowledged if `b` acknowledges), `b` gets what went out, then both
/// interrupts are handled. Returns the attempt and `a`'s and `b`'s
/// events.
fn round(
    a: &mut Chip<CtuModel>,
    b: &mut Chip<CtuModel>,
    fault: Fault,
) -> (TxAttempt, Vec<Event>, Vec<Event>) {
    let acked = b.regs.acks();
    let t = a.regs.transmit(fault, acked);
    if let TxAttempt::Sent(f) = t {
        b.regs.deliver(&f);
    }
    let mut ea = Vec::new();
    if a.regs.irq_line() {
        a.irq(|e| ea.push(e));
    }
    let mut eb = Vec::new();
    if b.regs.irq_line() {
        b.irq(|e| eb.push(e));
    }
    (t, ea, eb)
}

fn errors(ev: &[Event]) -> Vec<ErrReport> {
    ev.iter()
        .filter_map(|e| match e {
            Event::Error(r) => Some(*r),
            _ => None,
        })
        .collect()
}

fn err_frame(class: u32, data: [u8; 8]) -> CanFrame {
    CanFrame {
        can_id: CAN_ERR_FLAG | class,
        len: 8,
        data,
        ..CanFrame::default()
    }
}

/// Bit errors on every attempt, berr-reporting off (BEI masked): only the
/// state changes interrupt: warning at the 12th attempt (TEC 96), passive
/// at the 16th (128), bus-off at the 32nd, where the frame is given up
/// (TX failed: its echo is dropped). The restart makes the core error
/// active with the counters at 0, and it sends again.
#[test]
fn biterr_warning_passive_bus_off_and_restart() {
    let mut a = running(&cfg(false));
    let mut b = running(&cfg(false));
    a.xmit(&frame(0x123, &[1, 2])).unwrap();
    let biterr = Fault::BusError {
        capt: err_capt(err_type::BIT, err_pos::DATA),
    };
    let mut reports = Vec::new();
    let mut done = Vec::new();
    for attempt in 1..=32 {
        let (t, ea, eb) = round(&mut a, &mut b, biterr);
        assert_eq!(t, TxAttempt::Failed, "attempt {attempt}");
        assert!(eb.is_empty());
        for r in errors(&ea) {
            reports.push((attempt, r));
        }
        done.extend(
            ea.iter()
                .filter(|e| matches!(e, Event::TxDone { .. }))
                .copied(),
        );
    }
    let frames: Vec<(u32, CanFrame)> = reports.iter().map(|(n, r)| (*n, r.frame)).collect();
    assert_eq!(
        frames,
        [
            (
                12,
                err_frame(
                    err::CRTL | err::CNT,
                    [0, err::CRTL_TX_WARNING, 0, 0, 0, 0, 96, 0]
                )
            ),
            (
                16,
                err_frame(
                    err::CRTL | err::CNT,
                    [0, err::CRTL_TX_PASSIVE, 0, 0, 0, 0, 128, 0]
                )
            ),
            (32, err_frame(err::BUSOFF, [0; 8])),
        ]
    );
    assert!(reports[2].1.bus_off);
    assert_eq!(a.state(), CanState::BusOff);
    assert_eq!(a.regs.confinement(), Confinement::BusOff);
    assert_eq!(a.berr_counter(), (256, 0));
    assert_eq!(done, [Event::TxDone { buf: 0, ok: false }]);
    // Off the bus: nothing to send, nothing received, no acknowledgement.
    assert!(!a.regs.acks());
    assert_eq!(a.regs.transmit(Fault::None, true), TxAttempt::Idle);
    a.restart();
    assert_eq!(a.state(), CanState::ErrorActive);
    assert_eq!(a.berr_counter(), (0, 0));
    assert_eq!(a.regs.confinement(), Confinement::Active);
    a.xmit(&frame(0x124, &[3])).unwrap();
    let (t, ea, eb) = round(&mut a, &mut b, Fault::None);
    assert!(matches!(t, TxAttempt::Sent(f) if f.id == 0x124));
    assert_eq!(ea, [Event::TxDone { buf: 0, ok: true }]);
    assert_eq!(eb, [Event::Rx(frame(0x124, &[3]))]);
}

/// With berr-reporting: one error frame per failed attempt (bus error,
/// type and location unspecified as mainline's), the 12th and 16th with
/// the state change too, the 32nd with bus-off; ERR_CAPT holds the
/// injected bit error in the data field for the log; 32 bus errors, one
/// warning, passive, bus-off counted.
#[test]
fn biterr_with_berr_reporting_one_frame_per_attempt() {
    let mut a = running(&cfg(true));
    let mut b = running(&cfg(true));
    a.xmit(&frame(0x7, &[])).unwrap();
    let capt = err_capt(err_type::BIT, err_pos::DATA);
    let mut reports = Vec::new();
    for _ in 0..32 {
        let (_, ea, _) = round(&mut a, &mut b, Fault::BusError { capt });
        let r = errors(&ea);
        assert_eq!(r.len(), 1);
        reports.push(r[0]);
    }
    let berr = err::PROT | err::BUSERROR;
    for (i, r) in reports.iter().enumerate() {
        let want = match i + 1 {
            12 => err_frame(
                berr | err::CRTL | err::CNT,
                [0, err::CRTL_TX_WARNING, 0, 0, 0, 0, 96, 0],
            ),
            16 => err_frame(
                berr | err::CRTL | err::CNT,
                [0, err::CRTL_TX_PASSIVE, 0, 0, 0, 0, 128, 0],
            ),
            32 => err_frame(berr | err::BUSOFF, [0; 8]),
            _ => err_frame(berr, [0; 8]),
        };
        assert_eq!(r.frame, want, "attempt {}", i + 1);
        assert_eq!(r.err_capt & 0xFF, u32::from(capt));
    }
    let sum = |f: fn(&ErrReport) -> u32| reports.iter().map(f).sum::<u32>();
    assert_eq!(sum(|r| r.stats.bus_error), 32);
    assert_eq!(sum(|r| r.net.rx_errors), 32);
    assert_eq!(
        (
            sum(|r| r.stats.error_warning),
            sum(|r| r.stats.error_passive),
            sum(|r| r.stats.bus_off)
        ),
        (1, 1, 1)
    );
}

/// No acknowledgement: TEC +8 per attempt to error passive (128), where a
/// missing acknowledgement no longer counts, so the core never goes
/// bus-off. Once acknowledged, the frame goes out, TEC drops to 127 and
/// the core is error active again (FCSI: CRTL_ACTIVE) but still above
/// the warning limit.
#[test]
fn noack_stops_at_error_passive() {
    let mut a = running(&cfg(true));
    let mut b = running(&cfg(true));
    a.xmit(&frame(0x55, &[0x55])).unwrap();
    for _ in 0..40 {
        let (t, ea, _) = round(&mut a, &mut b, Fault::NoAck);
        assert_eq!(t, TxAttempt::Failed);
        let r = errors(&ea);
        assert!(r.iter().all(|r| r.frame.can_id & err::BUSERROR != 0));
    }
    assert_eq!(a.state(), CanState::ErrorPassive);
    assert_eq!(a.berr_counter(), (128, 0));
    assert_eq!(
        a.regs.read32(reg::ERR_CAPT) & 0xFF,
        u32::from(err_capt(err_type::ACK, err_pos::ACK))
    );
    let (t, ea, eb) = round(&mut a, &mut b, Fault::None);
    assert!(matches!(t, TxAttempt::Sent(_)));
    assert_eq!(eb.len(), 1);
    let r = errors(&ea);
    assert_eq!(r.len(), 1);
    assert_eq!(
        r[0].state,
        Some((CanState::ErrorPassive, CanState::ErrorWarning))
    );
    assert_eq!(r[0].frame.data[1], err::CRTL_TX_WARNING);
    assert_eq!(a.berr_counter(), (127, 0));
}

/// A core alone on the bus (the other one down) gets no acknowledgement;
/// a bus-off core does not acknowledge either; presume-ack (self-test
/// mode) needs none.
#[test]
fn acknowledgement_needs_another_core_on_the_bus() {
    let mut a = running(&cfg(false));
    let mut b = running(&cfg(false));
    b.stop();
    a.xmit(&frame(0x1, &[1])).unwrap();
    assert_eq!(round(&mut a, &mut b, Fault::None).0, TxAttempt::Failed);
    assert_eq!(a.berr_counter(), (8, 0));
    let mut c = running(&Config {
        presume_ack: true,
        ..cfg(false)
    });
    c.xmit(&frame(0x2, &[2])).unwrap();
    assert!(matches!(
        round(&mut c, &mut b, Fault::None).0,
        TxAttempt::Sent(_)
    ));
}

/// Lost arbitration: ALI with the bit in ALC (ERR_CAPT bits 20..16, the
/// base identifier field), LOSTARB unspecified as mainline, no counter
/// moves; the retry goes out.
#[test]
fn arbitration_lost_once_then_sent() {
    let mut a = running(&cfg(true));
    let mut b = running(&cfg(true));
    a.xmit(&frame(0x300, &[5])).unwrap();
    let lost = Fault::ArbitrationLost { bit: 5 };
    let (t, ea, _) = round(&mut a, &mut b, lost);
    assert_eq!(t, TxAttempt::Failed);
    let r = errors(&ea);
    assert_eq!(r.len(), 1);
    assert_eq!(
        r[0].frame,
        err_frame(err::LOSTARB, [err::LOSTARB_UNSPEC, 0, 0, 0, 0, 0, 0, 0])
    );
    assert_eq!(r[0].stats.arbitration_lost, 1);
    assert_eq!((r[0].err_capt >> 16) & 0x1F, 5);
    assert_eq!(a.berr_counter(), (0, 0));
    let (t, _, eb) = round(&mut a, &mut b, lost);
    assert!(matches!(t, TxAttempt::Sent(_)));
    assert_eq!(eb.len(), 1);
}

/// One-shot (RTRLE, RTRTH 0): the first failure gives the frame up (TX
/// failed, its echo dropped); the next frame is sent.
#[test]
fn one_shot_gives_up_after_one_failure() {
    let one_shot = Config {
        one_shot: true,
        ..cfg(false)
    };
    let mut a = running(&one_shot);
    let mut b = running(&cfg(false));
    a.xmit(&frame(0x10, &[1])).unwrap();
    let (t, ea, _) = round(&mut a, &mut b, Fault::NoAck);
    assert_eq!(t, TxAttempt::Failed);
    assert_eq!(ea, [Event::TxDone { buf: 0, ok: false }]);
    assert!(!a.regs.tx_pending());
    a.xmit(&frame(0x11, &[2])).unwrap();
    let (t, ea, _) = round(&mut a, &mut b, Fault::None);
    assert!(matches!(t, TxAttempt::Sent(f) if f.id == 0x11));
    assert_eq!(ea, [Event::TxDone { buf: 1, ok: true }]);
}

/// The receiver's counter: a frame received without error counts REC
/// down (from above 127 back to 119); injected through set_fault.
/// ERCRST leaves bus-off at once (FCSI), as the reintegration would.
#[test]
fn receive_counter_and_ercrst() {
    let mut m = CtuModel::new();
    m.write32(reg::MODE, mode::ENA);
    m.set_fault(96 | 128 << 8 | fault::ERP, 130, 0);
    let f = rcan_chips::ctucanfd_model::BusFrame {
        id: 1,
        ext: false,
        rtr: false,
        fd: false,
        brs: false,
        esi: false,
        len: 0,
        data: [0; 64],
    };
    assert!(m.deliver(&f));
    assert_eq!(m.error_counters(), (119, 0));
    assert!(m.deliver(&f));
    assert_eq!(m.error_counters(), (118, 0));
    m.set_fault(96 | 128 << 8 | fault::BOF, 0, 256);
    assert!(!m.deliver(&f), "bus-off: nothing received");
    m.write32(reg::INT_ENA_SET, int::ALL);
    m.write32(reg::COMMAND, command::ERCRST);
    assert_eq!(m.confinement(), Confinement::Active);
    assert_eq!(m.error_counters(), (0, 0));
    assert!(m.read32(reg::INT_STAT) & int::FCSI != 0);
}
