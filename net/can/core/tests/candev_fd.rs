// SPDX-License-Identifier: GPL-2.0
//! The CAN FD rules of the device layer (`rcan_core::candev`): data bit
//! timing, `fd on`/`fd off` and the MTU, `ip link set canX mtu 72|16`, and
//! `open`, as mainline 6.12's `can_changelink`, `can_change_mtu` and
//! `open_candev` (drivers/net/can/dev/netlink.c, dev.c) decide them, on
//! the CTU CAN FD's limits at the PCI card's 100 MHz clock (mainline
//! `ctucanfd`'s `ctu_can_fd_bit_timing_max` / `_data_max`).
//!
//! The expected data timings are worked out by hand with mainline's
//! `can_calc_bittiming` search (see each test), not taken from our code;
//! the VM test `ctucanfd_ip_fd_matches_mainline` checks the same
//! `ip -details` lines against mainline's ctucanfd_pci.

use rcan_core::bittiming::{
    Bittiming, CTUCANFD_DATA_CONST as DATA_CONST, CTUCANFD_NOMINAL_CONST as NOMINAL_CONST, EBUSY,
    EINVAL, EOPNOTSUPP, SJA1000_BITTIMING_CONST,
};
use rcan_core::candev::*;

const CTU: Device = Device {
    btc: Some(&NOMINAL_CONST),
    dbtc: Some(&DATA_CONST),
    clock_hz: 100_000_000,
    ctrlmode_supported: CTUCANFD_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: false,
};

const SJA: Device = Device {
    btc: Some(&SJA1000_BITTIMING_CONST),
    dbtc: None,
    clock_hz: 8_000_000,
    ctrlmode_supported: SJA1000_CTRLMODE_SUPPORTED,
    ctrlmode_static: 0,
    can_restart: true,
};

fn rate(bitrate: u32, sample_point: u32) -> Option<Bittiming> {
    Some(Bittiming {
        bitrate,
        sample_point,
        ..Bittiming::default()
    })
}

/// `ip link set canX type can bitrate B dbitrate D [dsample-point] fd on`.
fn fd_on(b: u32, d: u32, dsp: u32) -> Request {
    Request {
        ctrlmode: Some((ctrlmode::FD, ctrlmode::FD)),
        bittiming: rate(b, 0),
        data_bittiming: rate(d, dsp),
        ..Request::default()
    }
}

/// `ip link set canX type can fd off`.
const FD_OFF: Request = Request {
    ctrlmode: Some((0, ctrlmode::FD)),
    bittiming: None,
    restart_ms: None,
    restart: false,
    data_bittiming: None,
    tdc: false,
    termination: None,
};

/// (sample point, tq, prop, phase1, phase2, sjw, brp, bitrate).
fn fields(b: &Bittiming) -> [u32; 8] {
    [
        b.sample_point,
        b.tq,
        b.prop_seg,
        b.phase_seg1,
        b.phase_seg2,
        b.sjw,
        b.brp,
        b.bitrate,
    ]
}

/// 2 Mbit/s at 100 MHz, default sample point 75 %: the first exact bit
/// rate of the search is 50 quanta at prescaler 1; TSEG2 = 50 - 37 = 13
/// gives 74.0 % (14 would be 72 %, 12 is past 75 %). TSEG1 36 splits
/// 18/18; sjw = min(18, 13 / 2) = 6. Prescaler 2 (25 quanta) comes
/// nearest at 72 %, worse. Mainline prints "dbitrate 2000000
/// dsample-point 0.740 dtq 10 dprop-seg 18 dphase-seg1 18 dphase-seg2 13
/// dsjw 6 dbrp 1".
#[test]
fn fd_on_sets_both_timings_and_mtu_72() {
    let mut s = Settings::default();
    let req = fd_on(500_000, 2_000_000, 0);
    assert_eq!(validate(&req), Ok(()));
    let c = changelink(&CTU, &mut s, false, CanState::Stopped, &req).unwrap();
    assert_eq!(c.mtu, Some(72));
    assert_eq!(
        fields(&s.data_bittiming),
        [740, 10, 18, 18, 13, 6, 1, 2_000_000]
    );
    assert_eq!(c.data_bittiming.unwrap().bt, s.data_bittiming);
    assert_eq!(s.ctrlmode, ctrlmode::FD);
    assert_eq!(s.bittiming.bitrate, 500_000);
    assert_eq!(open(&s), Ok(()));
}

/// 5 Mbit/s: 20 quanta at prescaler 1, TSEG2 = 20 - 15 = 5 is exactly
/// 75 %, so the search stops there: 7/7/5, sjw min(7, 2) = 2.
/// 2 Mbit/s at `dsample-point 0.8`: TSEG2 = 50 - 40 = 10, exactly 80 %:
/// 19/20/10, sjw 5.
#[test]
fn data_timing_other_rates_and_sample_points() {
    let mut s = Settings::default();
    changelink(
        &CTU,
        &mut s,
        false,
        CanState::Stopped,
        &fd_on(1_000_000, 5_000_000, 0),
    )
    .unwrap();
    assert_eq!(
        fields(&s.data_bittiming),
        [750, 10, 7, 7, 5, 2, 1, 5_000_000]
    );
    changelink(
        &CTU,
        &mut s,
        false,
        CanState::Stopped,
        &fd_on(500_000, 2_000_000, 800),
    )
    .unwrap();
    assert_eq!(
        fields(&s.data_bittiming),
        [800, 10, 19, 20, 10, 5, 1, 2_000_000]
    );
}

/// A data bit rate the limits cannot reach (prescaler at most 2, 94 + 31
/// quanta: below 100 MHz / 2 / 126 = 396,825 bit/s) is refused as a
/// nominal one would be: EINVAL.
#[test]
fn data_bitrate_out_of_reach() {
    let mut s = Settings::default();
    let e = changelink(
        &CTU,
        &mut s,
        false,
        CanState::Stopped,
        &fd_on(125_000, 100_000, 0),
    )
    .unwrap_err();
    assert_eq!(e.errno, EINVAL);
}

#[test]
fn fd_off_clears_data_timing_and_mtu_16() {
    let mut s = Settings::default();
    changelink(
        &CTU,
        &mut s,
        false,
        CanState::Stopped,
        &fd_on(500_000, 2_000_000, 0),
    )
    .unwrap();
    let c = changelink(&CTU, &mut s, false, CanState::Stopped, &FD_OFF).unwrap();
    assert_eq!(c.mtu, Some(16));
    assert_eq!(s.ctrlmode & ctrlmode::FD, 0);
    assert_eq!(s.data_bittiming, Bittiming::default());
    assert_eq!(s.bittiming.bitrate, 500_000);
    assert_eq!(open(&s), Ok(()));
}

/// `fd on` without `dbitrate` (or without `bitrate`), and `dbitrate`
/// without `fd on`: EOPNOTSUPP from `can_validate`, before anything
/// changes.
#[test]
fn validate_wants_both_timings_with_fd() {
    let mut only_nominal = fd_on(500_000, 2_000_000, 0);
    only_nominal.data_bittiming = None;
    assert_eq!(validate(&only_nominal).unwrap_err().errno, EOPNOTSUPP);
    let no_fd = Request {
        ctrlmode: None,
        ..fd_on(500_000, 2_000_000, 0)
    };
    assert_eq!(validate(&no_fd).unwrap_err().errno, EOPNOTSUPP);
}

#[test]
fn fd_refused_while_up_and_on_classic_devices() {
    let mut s = Settings::default();
    let req = fd_on(500_000, 2_000_000, 0);
    assert_eq!(
        changelink(&CTU, &mut s, true, CanState::ErrorActive, &req)
            .unwrap_err()
            .errno,
        EBUSY
    );
    // Data bit timing alone while up (validate would refuse it without
    // fd on; the rule itself says EBUSY first).
    let dbt = Request {
        data_bittiming: rate(2_000_000, 0),
        ..Request::default()
    };
    assert_eq!(
        changelink(&CTU, &mut s, true, CanState::ErrorActive, &dbt)
            .unwrap_err()
            .errno,
        EBUSY
    );
    // The SJA1000: FD not supported (EOPNOTSUPP), its MTU untouched.
    let mut s = Settings::default();
    assert_eq!(
        changelink(&SJA, &mut s, false, CanState::Stopped, &req)
            .unwrap_err()
            .errno,
        EOPNOTSUPP
    );
    assert_eq!(s, Settings::default());
    assert_eq!(
        changelink(&SJA, &mut s, false, CanState::Stopped, &dbt)
            .unwrap_err()
            .errno,
        EOPNOTSUPP
    );
}

/// `ip link set canX mtu 72` turns FD on without a data bit timing: the
/// device then refuses to come up (open_candev's "incorrect/missing data
/// bit-timing"), as it does with a data bit rate below the nominal one.
#[test]
fn open_with_fd_needs_a_data_timing_not_slower() {
    let mut s = Settings::default();
    changelink(
        &CTU,
        &mut s,
        false,
        CanState::Stopped,
        &Request {
            bittiming: rate(1_000_000, 0),
            ..Request::default()
        },
    )
    .unwrap();
    assert_eq!(open(&s), Ok(()));
    change_mtu(&CTU, &mut s, false, 72).unwrap();
    assert_eq!(s.ctrlmode & ctrlmode::FD, ctrlmode::FD);
    assert_eq!(open(&s), Err(OPEN_BAD_DATA_BITTIMING));
    assert_eq!(OPEN_BAD_DATA_BITTIMING, "incorrect/missing data bit-timing");
    // 1 Mbit/s nominal, 500 kbit/s data: slower, refused.
    changelink(
        &CTU,
        &mut s,
        false,
        CanState::Stopped,
        &fd_on(1_000_000, 500_000, 0),
    )
    .unwrap();
    assert_eq!(open(&s), Err(OPEN_BAD_DATA_BITTIMING));
}

/// mainline `can_change_mtu`: EBUSY while up; 72 needs FD support
/// (EINVAL on the SJA1000); 16 turns FD off; nothing else.
#[test]
fn change_mtu_as_mainline() {
    let mut s = Settings::default();
    assert_eq!(change_mtu(&CTU, &mut s, true, 72).unwrap_err().errno, EBUSY);
    assert_eq!(change_mtu(&CTU, &mut s, true, 16).unwrap_err().errno, EBUSY);
    assert_eq!(
        change_mtu(&CTU, &mut s, false, 64).unwrap_err().errno,
        EINVAL
    );
    assert_eq!(
        change_mtu(&SJA, &mut s, false, 72).unwrap_err().errno,
        EINVAL
    );
    assert_eq!(s, Settings::default());
    change_mtu(&CTU, &mut s, false, 72).unwrap();
    assert_eq!(s.ctrlmode, ctrlmode::FD);
    change_mtu(&CTU, &mut s, false, 16).unwrap();
    assert_eq!(s.ctrlmode, 0);
    let fd_only = Device {
        ctrlmode_static: ctrlmode::FD,
        ..CTU
    };
    assert_eq!(
        change_mtu(&fd_only, &mut s, false, 16).unwrap_err().errno,
        EINVAL
    );
}

/// `fd on` on the SJA1000's neighbour modes: non-ISO FD needs support
/// too; the CTU has it. Triple sampling it has not (mainline `ctucanfd`
/// does not announce it).
#[test]
fn fd_non_iso_supported_on_the_ctu() {
    let mut s = Settings::default();
    let mut req = fd_on(500_000, 2_000_000, 0);
    req.ctrlmode = Some((
        ctrlmode::FD | ctrlmode::FD_NON_ISO,
        ctrlmode::FD | ctrlmode::FD_NON_ISO,
    ));
    changelink(&CTU, &mut s, false, CanState::Stopped, &req).unwrap();
    assert_eq!(s.ctrlmode, ctrlmode::FD | ctrlmode::FD_NON_ISO);
    let lo = Request {
        ctrlmode: Some((ctrlmode::THREE_SAMPLES, ctrlmode::THREE_SAMPLES)),
        ..Request::default()
    };
    assert_eq!(
        changelink(&CTU, &mut s, false, CanState::Stopped, &lo)
            .unwrap_err()
            .errno,
        EOPNOTSUPP
    );
}
