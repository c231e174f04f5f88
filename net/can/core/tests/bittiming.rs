// SPDX-License-Identifier: GPL-2.0
//! Bit timing against mainline: every row of `common/bittiming_table.rs`
//! (recorded from mainline's CAN device layer in the VM, and from
//! mainline's own bit-timing C code on the host; how is said at the top of
//! that file) must come out of `rcan_core::bittiming` the same: errno,
//! extended-ack text, every field of the timing, and the BTR0/BTR1 that
//! mainline's sja1000 driver wrote.

#[path = "common/bittiming_table.rs"]
mod table;

use rcan_core::bittiming::*;
use table::{Row, HARNESS, VM};

/// Whether mainline's answer is a timing outside the limits (TSEG1 below
/// its minimum: mainline's search does not prevent it), which `calc`
/// refuses on purpose (see its documentation).
fn outside_limits(r: &Row) -> bool {
    r.bt.is_some_and(|b| {
        let (tseg1, tseg2) = (b[3] + b[4], b[5]);
        tseg1 < r.btc.tseg1_min || tseg2 < r.btc.tseg2_min || tseg2 > r.btc.tseg2_max
    })
}

fn check(r: &Row) {
    let [bitrate, sample_point, tq, prop_seg, phase_seg1, phase_seg2, sjw] = r.input;
    let user = Bittiming {
        bitrate,
        sample_point,
        tq,
        prop_seg,
        phase_seg1,
        phase_seg2,
        sjw,
        brp: 0,
    };
    let got = validate(&user).and_then(|()| get(r.btc, r.clock, &user));
    let what = format!("{} at {} Hz, input {:?}", r.btc.name, r.clock, r.input);
    if outside_limits(r) {
        let b = r.bt.unwrap();
        let e = got.expect_err(&what);
        assert_eq!(e.errno, EINVAL, "{what}");
        assert_eq!(
            e.msg,
            Some(Msg::Tseg1BelowMin(b[3] + b[4], r.btc.tseg1_min)),
            "{what}"
        );
        return;
    }
    match got {
        Ok(c) => {
            assert_eq!(r.errno, 0, "{what}: mainline refused it, we set {:?}", c.bt);
            assert_eq!(
                c.warning.map(|m| m.to_string()).unwrap_or_default(),
                r.msg,
                "{what}: warning"
            );
            let b = c.bt;
            let fields = [
                b.bitrate,
                b.sample_point,
                b.tq,
                b.prop_seg,
                b.phase_seg1,
                b.phase_seg2,
                b.sjw,
                b.brp,
            ];
            assert_eq!(Some(fields), r.bt, "{what}: timing");
            if let Some(btr) = r.btr {
                assert_eq!(to_btr(&b, r.triple), btr, "{what}: BTR0/BTR1");
            }
        }
        Err(e) => {
            assert_eq!(e.errno, r.errno, "{what}: errno");
            assert_eq!(
                e.msg.map(|m| m.to_string()).unwrap_or_default(),
                r.msg,
                "{what}: message"
            );
        }
    }
}

#[test]
fn as_mainline_in_the_vm() {
    assert!(VM.len() > 80);
    VM.iter().for_each(check);
}

#[test]
fn as_mainline_c_code() {
    assert!(HARNESS.len() > 500);
    HARNESS.iter().for_each(check);
    // The deliberate difference concerns the 82527's limits only, at low
    // sample points; never the SJA1000's.
    let outside: Vec<_> = HARNESS.iter().filter(|r| outside_limits(r)).collect();
    assert!(!outside.is_empty());
    assert!(outside
        .iter()
        .all(|r| r.btc.name == "i82527" && r.input[1] != 0 && r.input[1] < 700));
    assert!(!VM.iter().any(outside_limits));
}

/// The 82527 rows really exercise its own limits: somewhere they give a
/// different answer from the SJA1000's limits at the same clock.
#[test]
fn i82527_limits_matter() {
    let differs = HARNESS.iter().filter(|r| r.btc.name == "i82527").any(|r| {
        HARNESS.iter().any(|s| {
            s.btc.name == "sja1000" && s.clock == r.clock && s.input == r.input && s.bt != r.bt
        })
    });
    assert!(differs);
}

/// Decoding the registers gives back the timing mainline computed (the
/// registers hold TSEG1 only as a sum, which is split as `calc` splits it).
#[test]
fn btr_decode_inverts_encode() {
    for r in VM.iter().filter(|r| r.btr.is_some() && r.input[2] == 0) {
        let (b0, b1) = r.btr.unwrap();
        let (bt, triple) = from_btr(b0, b1, r.clock);
        assert_eq!(triple, r.triple);
        let want = r.bt.unwrap();
        assert_eq!(
            [
                bt.bitrate,
                bt.sample_point,
                bt.prop_seg,
                bt.phase_seg1,
                bt.phase_seg2,
                bt.sjw,
                bt.brp
            ],
            [want[0], want[1], want[3], want[4], want[5], want[6], want[7]],
            "{:?}",
            r.input
        );
    }
}

mod prop {
    use proptest::prelude::*;
    use rcan_core::bittiming::*;

    proptest! {
        /// Whatever `calc` sets is within the controller's limits, says
        /// its own bit rate and sample point truly, and survives the
        /// registers: what mainline would write to BTR0/BTR1 decodes to
        /// the same timing.
        #[test]
        fn calc_results_are_consistent(
            bitrate in 1_000u32..=1_000_000,
            sp in prop_oneof![Just(0u32), 1u32..1000],
            clock in prop::sample::select(vec![4_000_000u32, 8_000_000, 10_000_000, 16_000_000, 24_000_000]),
            i82527 in any::<bool>(),
            triple in any::<bool>(),
        ) {
            let btc = if i82527 { &I82527_BITTIMING_CONST } else { &SJA1000_BITTIMING_CONST };
            let want = Bittiming { bitrate, sample_point: sp, ..Bittiming::default() };
            let Ok(c) = calc(btc, clock, &want) else { return Ok(()); };
            let bt = c.bt;
            prop_assert!((btc.tseg1_min..=btc.tseg1_max).contains(&bt.tseg1()));
            prop_assert!((btc.tseg2_min..=btc.tseg2_max).contains(&bt.phase_seg2));
            prop_assert!((btc.brp_min..=btc.brp_max).contains(&bt.brp));
            prop_assert!(bt.sjw >= 1 && bt.sjw <= btc.sjw_max);
            prop_assert!(bt.sjw <= bt.phase_seg1 && bt.sjw <= bt.phase_seg2);
            prop_assert_eq!(bt.bitrate, clock / (bt.brp * bt.bit_time()));
            prop_assert!(bt.bitrate.abs_diff(bitrate) * 1000 / bitrate <= MAX_ERROR_PERMILLE);
            prop_assert_eq!(c.warning.is_some(), bt.bitrate != bitrate);
            let (b0, b1) = to_btr(&bt, triple);
            let (back, t) = from_btr(b0, b1, clock);
            prop_assert_eq!(t, triple);
            prop_assert_eq!(
                (back.bitrate, back.sample_point, back.prop_seg, back.phase_seg1, back.phase_seg2, back.sjw, back.brp),
                (bt.bitrate, bt.sample_point, bt.prop_seg, bt.phase_seg1, bt.phase_seg2, bt.sjw, bt.brp)
            );
            // Giving the computed timing back directly is accepted and
            // gives the same bit rate (what `ip` shows can be typed in).
            let direct = Bittiming { bitrate: 0, sample_point: 0, brp: 0, ..bt };
            let f = fixup(btc, clock, &direct).unwrap();
            prop_assert_eq!(f.bt.bitrate, bt.bitrate);
            prop_assert_eq!(f.bt.brp, bt.brp);
        }
    }
}
