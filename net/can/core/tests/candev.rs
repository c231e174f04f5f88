// SPDX-License-Identifier: GPL-2.0
//! The CAN device layer's rules (`rcan_core::candev`) against mainline.
//!
//! The errno of each refusal below was observed on 2026-11-25 in the VM,
//! with mainline 6.12's can-dev + sja1000 + kvaser_pci and iproute2 6.1
//! (tools/testing/rcan/bittiming-mainline.sh, the part after "CASE up"):
//! `fd on` EOPNOTSUPP; `restart` while down EINVAL; while up: `bitrate`,
//! `loopback on`, `restart-ms 100` EBUSY, `restart` (not bus-off,
//! restart-ms 0) EBUSY, `restart` with restart-ms 100 EINVAL; `ip link set
//! can1 up` with no bit timing EINVAL and "bit-timing not yet defined" in
//! the kernel log. The error frames' expected bytes are worked out by hand
//! from mainline's sja1000_err()/can_change_state()/cc770_err() and
//! <linux/can/error.h>, not from our code.

use rcan_core::arb::CAN_ERR_FLAG;
use rcan_core::bittiming::I82527_BITTIMING_CONST;
use rcan_core::bittiming::{Bittiming, Msg, EBUSY, EINVAL, EOPNOTSUPP, SJA1000_BITTIMING_CONST};
use rcan_core::candev::*;

const SJA: Device = Device {
    btc: Some(&SJA1000_BITTIMING_CONST),
    dbtc: None,
    clock_hz: 8_000_000,
    ctrlmode_supported: SJA1000_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: true,
};

const I82527: Device = Device {
    btc: Some(&I82527_BITTIMING_CONST),
    dbtc: None,
    clock_hz: 8_000_000,
    ctrlmode_supported: I82527_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: true,
};

fn rate(bitrate: u32) -> Option<Bittiming> {
    Some(Bittiming {
        bitrate,
        ..Bittiming::default()
    })
}

fn errno<T: core::fmt::Debug>(r: Result<T, rcan_core::bittiming::Error>) -> i32 {
    r.unwrap_err().errno
}

#[test]
fn fd_is_refused_before_anything_changes() {
    let fd = Request {
        ctrlmode: Some((ctrlmode::FD, ctrlmode::FD)),
        ..Request::default()
    };
    assert_eq!(errno(validate(&fd)), EOPNOTSUPP);
    // Even with both timings given, the SJA1000 has no FD.
    let both = Request {
        bittiming: rate(500_000),
        data_bittiming: rate(2_000_000),
        ..fd
    };
    assert_eq!(validate(&both), Ok(()));
    let mut s = Settings::default();
    assert_eq!(
        errno(changelink(&SJA, &mut s, false, CanState::Stopped, &both)),
        EOPNOTSUPP
    );
    let tdc_both = Request {
        ctrlmode: Some((ctrlmode::TDC_MASK, ctrlmode::TDC_MASK)),
        tdc: true,
        ..Request::default()
    };
    assert_eq!(errno(validate(&tdc_both)), EOPNOTSUPP);
    let sp100 = Request {
        bittiming: Some(Bittiming {
            bitrate: 500_000,
            sample_point: 1000,
            ..Bittiming::default()
        }),
        ..Request::default()
    };
    assert_eq!(
        validate(&sp100).unwrap_err().msg,
        Some(Msg::SamplePointRange)
    );
}

#[test]
fn settings_refused_while_up() {
    let mut s = Settings::default();
    let set = Request {
        bittiming: rate(500_000),
        ..Request::default()
    };
    let c = changelink(&SJA, &mut s, false, CanState::Stopped, &set).unwrap();
    assert_eq!(c.bittiming.unwrap().bt.brp, 1);
    assert_eq!(s.bittiming.bitrate, 500_000);
    assert_eq!(open(&s), Ok(()));
    let up = |r: Request, s: &mut Settings| changelink(&SJA, s, true, CanState::ErrorActive, &r);
    assert_eq!(
        errno(up(
            Request {
                bittiming: rate(250_000),
                ..Request::default()
            },
            &mut s
        )),
        EBUSY
    );
    let lo = Request {
        ctrlmode: Some((ctrlmode::LOOPBACK, ctrlmode::LOOPBACK)),
        ..Request::default()
    };
    assert_eq!(errno(up(lo, &mut s)), EBUSY);
    let ms = Request {
        restart_ms: Some(100),
        ..Request::default()
    };
    assert_eq!(errno(up(ms, &mut s)), EBUSY);
    assert_eq!(s.bittiming.bitrate, 500_000);
    assert_eq!((s.ctrlmode, s.restart_ms), (0, 0));
}

#[test]
fn restart_rules() {
    let restart = Request {
        restart: true,
        ..Request::default()
    };
    let mut s = Settings::default();
    // Down: EINVAL.
    assert_eq!(
        errno(changelink(&SJA, &mut s, false, CanState::Stopped, &restart)),
        EINVAL
    );
    // Up, error active, manual restart mode: EBUSY.
    assert_eq!(
        errno(changelink(
            &SJA,
            &mut s,
            true,
            CanState::ErrorActive,
            &restart
        )),
        EBUSY
    );
    // Up and bus-off: restart now.
    let c = changelink(&SJA, &mut s, true, CanState::BusOff, &restart).unwrap();
    assert!(c.restart_now);
    // Automatic restart on: a manual one is EINVAL, even when bus-off.
    s.restart_ms = 100;
    assert_eq!(
        errno(changelink(&SJA, &mut s, true, CanState::BusOff, &restart)),
        EINVAL
    );
    // A device without restart: EOPNOTSUPP with mainline's message, for
    // both attributes; restart-ms 0 is still accepted.
    let fixed = Device {
        can_restart: false,
        ..SJA
    };
    let e = changelink(&fixed, &mut s, true, CanState::BusOff, &restart).unwrap_err();
    assert_eq!((e.errno, e.msg), (EOPNOTSUPP, Some(Msg::NoRestart)));
    assert_eq!(
        e.msg.unwrap().to_string(),
        "Device doesn't support restart from Bus Off"
    );
    let ms = |v| Request {
        restart_ms: Some(v),
        ..Request::default()
    };
    assert_eq!(
        errno(changelink(
            &fixed,
            &mut s,
            false,
            CanState::Stopped,
            &ms(100)
        )),
        EOPNOTSUPP
    );
    assert!(changelink(&fixed, &mut s, false, CanState::Stopped, &ms(0)).is_ok());
    assert_eq!(s.restart_ms, 0);
}

#[test]
fn up_needs_a_bit_timing() {
    assert_eq!(open(&Settings::default()), Err(OPEN_NO_BITTIMING));
    assert_eq!(OPEN_NO_BITTIMING, "bit-timing not yet defined");
}

#[test]
fn control_modes() {
    let mut s = Settings::default();
    let all = SJA1000_CTRLMODE_SUPPORTED;
    let on = Request {
        ctrlmode: Some((all, all)),
        ..Request::default()
    };
    changelink(&SJA, &mut s, false, CanState::Stopped, &on).unwrap();
    assert_eq!(s.ctrlmode, all);
    // The mask says which flags change: listen-only off, the rest kept.
    let lo_off = Request {
        ctrlmode: Some((0, ctrlmode::LISTENONLY)),
        ..Request::default()
    };
    changelink(&SJA, &mut s, false, CanState::Stopped, &lo_off).unwrap();
    assert_eq!(s.ctrlmode, all & !ctrlmode::LISTENONLY);
    // A flag outside the mask is ignored, not refused.
    let ignored = Request {
        ctrlmode: Some((ctrlmode::FD, 0)),
        ..Request::default()
    };
    changelink(&SJA, &mut s, false, CanState::Stopped, &ignored).unwrap();
    assert_eq!(s.ctrlmode, all & !ctrlmode::LISTENONLY);
    // The 82527 has triple sampling only.
    let mut s = Settings::default();
    let lo = Request {
        ctrlmode: Some((ctrlmode::LOOPBACK, ctrlmode::LOOPBACK)),
        ..Request::default()
    };
    assert_eq!(
        errno(changelink(&I82527, &mut s, false, CanState::Stopped, &lo)),
        EOPNOTSUPP
    );
    let triple = Request {
        ctrlmode: Some((ctrlmode::THREE_SAMPLES, ctrlmode::THREE_SAMPLES)),
        bittiming: rate(500_000),
        ..Request::default()
    };
    changelink(&I82527, &mut s, false, CanState::Stopped, &triple).unwrap();
    assert_eq!(s.ctrlmode, ctrlmode::THREE_SAMPLES);
    // A static mode must be given whenever control modes are set.
    let stat = Device {
        ctrlmode_static: ctrlmode::PRESUME_ACK,
        ..SJA
    };
    let mut s = Settings::default();
    assert_eq!(
        errno(changelink(&stat, &mut s, false, CanState::Stopped, &lo)),
        EOPNOTSUPP
    );
}

#[test]
fn earlier_changes_stay_when_a_later_attribute_fails() {
    // As mainline: the control modes are set before the bit timing is
    // refused (sjw above the maximum).
    let mut s = Settings::default();
    let r = Request {
        ctrlmode: Some((ctrlmode::ONE_SHOT, ctrlmode::ONE_SHOT)),
        bittiming: Some(Bittiming {
            bitrate: 500_000,
            sjw: 5,
            ..Bittiming::default()
        }),
        ..Request::default()
    };
    let e = changelink(&SJA, &mut s, false, CanState::Stopped, &r).unwrap_err();
    assert_eq!((e.errno, e.msg), (EINVAL, Some(Msg::SjwAboveMax(5, 4))));
    assert_eq!(s.ctrlmode, ctrlmode::ONE_SHOT);
    assert_eq!(s.bittiming.bitrate, 0);
}

#[test]
fn counters_to_states() {
    for (n, st) in [
        (0, CanState::ErrorActive),
        (95, CanState::ErrorActive),
        (96, CanState::ErrorWarning),
        (127, CanState::ErrorWarning),
        (128, CanState::ErrorPassive),
        (255, CanState::ErrorPassive),
        (256, CanState::BusOff),
    ] {
        assert_eq!(state_of_counter(n), st, "{n}");
    }
}

#[test]
fn i82527_last_error_codes() {
    let frame = |lec| {
        let mut f = error_frame();
        i82527_lec(&mut f, lec);
        (f.can_id & !CAN_ERR_FLAG, f.data[2], f.data[3])
    };
    assert_eq!(frame(0), (0, 0, 0));
    assert_eq!(frame(1), (0x08, 0x04, 0));
    assert_eq!(frame(2), (0x08, 0x02, 0));
    assert_eq!(frame(3), (0x20, 0, 0));
    assert_eq!(frame(4), (0x08, 0x10, 0));
    assert_eq!(frame(5), (0x08, 0x08, 0));
    assert_eq!(frame(6), (0x08, 0, 0x08));
    assert_eq!(frame(7), (0, 0, 0));
    // Only bits 2..0 are the code (TXOK, RXOK, WARN, BOFF above it).
    assert_eq!(frame(0x80 | 3), (0x20, 0, 0));
}

/// Mainline `can_get_cc_dlc` and `can_frame_set_cc_len` (include/linux/
/// can/dev.h, length.h): the DLC a driver sends, and the length of a
/// received classic frame, with and without `cc-len8-dlc`.
#[test]
fn cc_len8_dlc_rules() {
    use rcan_core::frame::CanFrame;
    let f = |len: u8, l8: u8| CanFrame {
        len,
        len8_dlc: l8,
        ..CanFrame::default()
    };
    let on = ctrlmode::CC_LEN8_DLC;
    for (len, l8, mode, want) in [
        (8, 9, on, 9),
        (8, 15, on, 15),
        (8, 16, on, 8),
        (8, 8, on, 8),
        (8, 0, on, 8),
        (7, 12, on, 7),
        (8, 12, 0, 8),
        (0, 0, on, 0),
    ] {
        assert_eq!(
            cc_dlc(&f(len, l8), mode),
            want,
            "len {len} len8_dlc {l8} mode {mode:#x}"
        );
    }
    for dlc in 0..=15u8 {
        for mode in [0, on] {
            let mut g = CanFrame::default();
            set_cc_len(&mut g, dlc, mode);
            assert_eq!(g.len, dlc.min(8));
            let l8 = if mode != 0 && dlc > 8 { dlc } else { 0 };
            assert_eq!(g.len8_dlc, l8, "dlc {dlc} mode {mode:#x}");
        }
    }
}
