// SPDX-License-Identifier: GPL-2.0
//! The bit timing a device starts with at probe (`rcan_core::candev`):
//! the `bitrate=`/`dbitrate=` module parameters of `rcan_ctucanfd_pci`
//! ([`Preset`]) and the BTR registers' preset of the SJA1000 and 82527
//! front-ends ([`settings_from_btr`]). The VM test `ctucanfd_bitrate_params`
//! checks the same rates through `ip -details` and the refused loads.

use proptest::prelude::*;
use rcan_core::bittiming::{Bittiming, Msg, EINVAL};
use rcan_core::candev::*;

#[path = "common/devices.rs"]
mod devices;
use devices::{CTU, I82527, SJA};

/// `ip link set canX type can bitrate B`.
fn ip_bitrate(bitrate: u32) -> Request {
    Request {
        bittiming: Some(Bittiming {
            bitrate,
            ..Bittiming::default()
        }),
        ..Request::default()
    }
}

#[test]
fn no_preset_is_no_bit_timing() {
    for dev in [&CTU, &SJA, &I82527] {
        let s = Preset::default().settings(dev).unwrap();
        assert_eq!(s, Settings::default());
        // As mainline: the device does not come up until user space
        // gives a bit timing.
        assert_eq!(open(&s), Err(OPEN_NO_BITTIMING));
    }
}

/// 500 kbit/s nominal and 2 Mbit/s data on a CTU core at 100 MHz: the
/// data timing is the one `ip ... dbitrate 2000000 fd on` gives (worked
/// out by hand in candev_fd.rs: 74.0 %, 18/18/13, sjw 6, brp 1), the
/// nominal one what `ip ... bitrate 500000` gives; FD stays off.
#[test]
fn ctu_nominal_and_data_rates() {
    let p = Preset {
        bitrate: 500_000,
        dbitrate: 2_000_000,
    };
    let s = p.settings(&CTU).unwrap();
    let d = &s.data_bittiming;
    assert_eq!(
        [
            d.sample_point,
            d.tq,
            d.prop_seg,
            d.phase_seg1,
            d.phase_seg2,
            d.sjw,
            d.brp,
            d.bitrate
        ],
        [740, 10, 18, 18, 13, 6, 1, 2_000_000]
    );
    let mut by_ip = Settings::default();
    changelink(
        &CTU,
        &mut by_ip,
        false,
        CanState::Stopped,
        &ip_bitrate(500_000),
    )
    .unwrap();
    assert_eq!(s.bittiming, by_ip.bittiming);
    assert_eq!(s.ctrlmode & ctrlmode::FD, 0);
    assert_eq!(s.restart_ms, 0);
    assert_eq!(open(&s), Ok(()));
}

#[test]
fn data_rate_needs_a_nominal_rate_not_faster() {
    for (bitrate, dbitrate) in [(0, 2_000_000), (1_000_000, 500_000)] {
        let e = Preset { bitrate, dbitrate }.settings(&CTU).unwrap_err();
        assert_eq!(
            e,
            PresetError {
                param: "dbitrate",
                why: None
            }
        );
        assert_eq!(
            e.to_string(),
            "dbitrate: needs bitrate, and at least its value"
        );
    }
    // Equal rates are allowed (mainline's open_candev accepts them).
    let s = Preset {
        bitrate: 1_000_000,
        dbitrate: 1_000_000,
    }
    .settings(&CTU)
    .unwrap();
    assert_eq!(s.data_bittiming.bitrate, 1_000_000);
}

/// A data rate below what the CTU's data limits reach (prescaler at most
/// 2, at most 126 quanta: under 396,825 bit/s at 100 MHz) is refused with
/// the search's reason, as `ip ... dbitrate` would be (EINVAL); a data
/// rate on a device without a data phase names the parameter.
#[test]
fn unreachable_rates_name_the_parameter() {
    let e = Preset {
        bitrate: 100_000,
        dbitrate: 100_000,
    }
    .settings(&CTU)
    .unwrap_err();
    assert_eq!(e.param, "dbitrate");
    assert!(matches!(e.why, Some(Msg::BitrateErrorTooHigh(_))), "{e:?}");
    assert!(e.to_string().starts_with("dbitrate: "), "{e}");
    let e = Preset {
        bitrate: 500_000,
        dbitrate: 2_000_000,
    }
    .settings(&SJA)
    .unwrap_err();
    assert_eq!(
        e,
        PresetError {
            param: "dbitrate",
            why: None
        }
    );
    // 3 bit/s: no prescaler of the SJA1000 at 8 MHz gets near.
    let e = Preset {
        bitrate: 3,
        dbitrate: 0,
    }
    .settings(&SJA)
    .unwrap_err();
    assert_eq!(e.param, "bitrate");
    assert!(e.why.is_some());
}

/// BTR0 0x01, BTR1 0x14 (the VM tests' `PRESET_500K`) at the Kvaser
/// card's 8 MHz: prescaler 2 (tq 250 ns), TSEG1 5, TSEG2 2, sjw 1: 8
/// quanta, 500 kbit/s, sample point 75 %. BTR1's top bit is triple
/// sampling.
#[test]
fn btr_preset_decoded() {
    let s = settings_from_btr(0x01, 0x14, 8_000_000);
    let b = &s.bittiming;
    assert_eq!(
        (b.bitrate, b.sample_point, b.tq, b.brp, b.sjw),
        (500_000, 750, 250, 2, 1)
    );
    assert_eq!(b.prop_seg + b.phase_seg1, 5);
    assert_eq!(b.phase_seg2, 2);
    assert_eq!(s.ctrlmode, 0);
    assert_eq!(s.data_bittiming, Bittiming::default());
    assert_eq!(open(&s), Ok(()));
    let t = settings_from_btr(0x01, 0x94, 8_000_000);
    assert_eq!(t.ctrlmode, ctrlmode::THREE_SAMPLES);
    assert_eq!(t.bittiming, s.bittiming);
}

proptest! {
    /// A `bitrate=` preset is exactly what `ip link set canX type can
    /// bitrate N` sets on the same device, or refused where `ip` is
    /// refused (EINVAL), on each controller.
    #[test]
    fn preset_agrees_with_ip(rate in 1u32..=2_000_000, which in 0usize..3) {
        let dev = [&CTU, &SJA, &I82527][which];
        let preset = Preset { bitrate: rate, dbitrate: 0 }.settings(dev);
        let mut by_ip = Settings::default();
        let ip = changelink(dev, &mut by_ip, false, CanState::Stopped, &ip_bitrate(rate));
        match (preset, ip) {
            (Ok(s), Ok(_)) => prop_assert_eq!(s.bittiming, by_ip.bittiming),
            (Err(e), Err(ie)) => {
                prop_assert_eq!(e.param, "bitrate");
                prop_assert_eq!(ie.errno, EINVAL);
                prop_assert_eq!(e.why, ie.msg);
            }
            (p, i) => prop_assert!(false, "preset {:?} but ip {:?}", p, i),
        }
    }
}
