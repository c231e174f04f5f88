// SPDX-License-Identifier: GPL-2.0

//! CAN bit timing: the rules of mainline's CAN device layer
//! (`drivers/net/can/dev/calc_bittiming.c`, `bittiming.c`), written anew,
//! and the SJA1000/82527 bus timing registers.
//!
//! A CAN bit is divided into time quanta (tq) of `brp` clock periods each:
//! one synchronisation quantum, then `prop_seg + phase_seg1` quanta (the
//! chip's TSEG1) up to the sample point, then `phase_seg2` quanta (TSEG2).
//! `sjw` is how many quanta the chip may move the sample point by to
//! resynchronise. A controller's [`BittimingConst`] bounds each field;
//! user space (`ip link set canX type can ...`) either gives a bit rate
//! (and optionally a sample point), which [`calc`] turns into a timing, or
//! the timing itself (tq in ns and the segments), which [`fixup`] checks.
//! Each result is exactly what mainline computes for the same constants
//! and clock, its failures carry mainline's errno and extended-ack text
//! ([`Msg`]); the tests compare with values recorded from mainline
//! (`net/can/core/tests/bittiming.rs`).
//!
//! Everything is integer arithmetic on `u32` with mainline's wrap-around
//! where mainline's `unsigned int` arithmetic wraps, so that absurd input
//! gives mainline's answer too, except where mainline's code would divide
//! by zero (absurd limits or bit rates): there a candidate is skipped or
//! the result is `EINVAL`. The functions are pure (no locks, no
//! allocation, no sleeping) and may be called in any context; the netlink
//! glue will call them in process context under RTNL, the tools in user
//! space.

use core::fmt;

/// Linux `EINVAL`.
pub const EINVAL: i32 = 22;
/// Linux `EBUSY`.
pub const EBUSY: i32 = 16;
/// Linux `EOPNOTSUPP`.
pub const EOPNOTSUPP: i32 = 95;

/// The synchronisation segment: always one quantum (`CAN_SYNC_SEG`).
pub const SYNC_SEG: u32 = 1;

/// Largest bit-rate error [`calc`] accepts, in tenths of a percent (5 %,
/// mainline's `CAN_CALC_MAX_ERROR`).
pub const MAX_ERROR_PERMILLE: u32 = 50;

/// A controller's bit-timing limits (mainline `struct
/// can_bittiming_const`, the `IFLA_CAN_BITTIMING_CONST` attribute; `name`
/// is what `ip -details` prints before them).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct BittimingConst {
    /// Controller name (at most 15 bytes: the C field is 16 with the NUL).
    pub name: &'static str,
    /// Least TSEG1 (`prop_seg + phase_seg1`), in quanta.
    pub tseg1_min: u32,
    /// Most TSEG1, in quanta.
    pub tseg1_max: u32,
    /// Least TSEG2 (`phase_seg2`), in quanta.
    pub tseg2_min: u32,
    /// Most TSEG2, in quanta.
    pub tseg2_max: u32,
    /// Most synchronisation jump width, in quanta.
    pub sjw_max: u32,
    /// Least prescaler (clock periods per quantum).
    pub brp_min: u32,
    /// Most prescaler.
    pub brp_max: u32,
    /// Prescaler step.
    pub brp_inc: u32,
}

/// The CTU CAN FD's nominal bit-timing limits (mainline `ctu_can_fd_bit_timing_max`):
/// PROP 7 bits plus PH1 6 bits make TSEG1 up to 190 quanta, PH2 6 bits,
/// SJW 5 bits. The prescaler field has 8 bits; mainline limits it to 8,
/// and so do we, so that both drivers compute the same timing.
pub const CTUCANFD_NOMINAL_CONST: BittimingConst = BittimingConst {
    name: "ctu_can_fd",
    tseg1_min: 2,
    tseg1_max: 190,
    tseg2_min: 1,
    tseg2_max: 63,
    sjw_max: 31,
    brp_min: 1,
    brp_max: 8,
    brp_inc: 1,
};

/// The CTU CAN FD's data-phase limits (mainline `ctu_can_fd_bit_timing_data_max`):
/// PROP_FD 6 bits plus PH1_FD 5 bits make TSEG1 up to 94, PH2_FD 5 bits;
/// prescaler up to 2 as mainline's.
pub const CTUCANFD_DATA_CONST: BittimingConst = BittimingConst {
    name: "ctu_can_fd",
    tseg1_min: 2,
    tseg1_max: 94,
    tseg2_min: 1,
    tseg2_max: 31,
    sjw_max: 31,
    brp_min: 1,
    brp_max: 2,
    brp_inc: 1,
};

/// The SJA1000's limits, as mainline's `sja1000_bittiming_const`
/// (datasheet 6.5.1/6.5.2: BRP 6 bits, SJW 2 bits, TSEG1 4 bits, TSEG2 3
/// bits, each field holding its value minus one). The clock these count
/// in is half the crystal: tq = 2 (BRP + 1) / f_XTAL.
pub const SJA1000_BITTIMING_CONST: BittimingConst = BittimingConst {
    name: "sja1000",
    tseg1_min: 1,
    tseg1_max: 16,
    tseg2_min: 1,
    tseg2_max: 8,
    sjw_max: 4,
    brp_min: 1,
    brp_max: 64,
    brp_inc: 1,
};

/// The Intel 82527's limits. Mainline 6.12 drives this chip only through
/// `cc770` (the Bosch CC770 is its pin-compatible successor), which
/// copies the SJA1000's limits; ours follow the 82527 datasheet as the
/// driver's `i82527::timing_for` always has: bit timing registers
/// laid out like the SJA1000's (BRP 6 bits, SJW 2 bits, TSEG1 4 bits,
/// TSEG2 3 bits, SPL for three samples in BTR1 bit 7), but programmed
/// TSEG1 2..15 and TSEG2 1..7, that is TSEG1 3..16 and TSEG2 2..8 quanta.
/// The clock is the system clock (the crystal, halved when the CPU
/// interface register's DSC bit is set): tq = (BRP + 1) / f_SYS.
pub const I82527_BITTIMING_CONST: BittimingConst = BittimingConst {
    name: "i82527",
    tseg1_min: 3,
    tseg1_max: 16,
    tseg2_min: 2,
    tseg2_max: 8,
    sjw_max: 4,
    brp_min: 1,
    brp_max: 64,
    brp_inc: 1,
};

/// A bit timing (mainline `struct can_bittiming`, the
/// `IFLA_CAN_BITTIMING` attribute): what user space asks for and what the
/// device layer reports back. Zero means "not given" for `bitrate`,
/// `sample_point`, `tq` and `sjw`.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Bittiming {
    /// Bits per second.
    pub bitrate: u32,
    /// Sample point in tenths of a percent (875 = 87.5 %).
    pub sample_point: u32,
    /// Time quantum in nanoseconds.
    pub tq: u32,
    /// Propagation segment, in quanta.
    pub prop_seg: u32,
    /// Phase buffer segment 1, in quanta.
    pub phase_seg1: u32,
    /// Phase buffer segment 2, in quanta.
    pub phase_seg2: u32,
    /// Synchronisation jump width, in quanta.
    pub sjw: u32,
    /// Prescaler: clock periods per quantum.
    pub brp: u32,
}

/// Size of `struct can_bittiming`.
pub const BITTIMING_LEN: usize = 32;

impl Bittiming {
    /// Quanta per bit (mainline `can_bit_time`).
    pub fn bit_time(&self) -> u32 {
        SYNC_SEG
            .wrapping_add(self.prop_seg)
            .wrapping_add(self.phase_seg1)
            .wrapping_add(self.phase_seg2)
    }

    /// TSEG1: the quanta between the synchronisation segment and the
    /// sample point.
    pub fn tseg1(&self) -> u32 {
        self.prop_seg.wrapping_add(self.phase_seg1)
    }

    /// The attribute's layout: eight native-endian 32-bit words in field
    /// order.
    pub fn to_ne_bytes(&self) -> [u8; BITTIMING_LEN] {
        let w = [
            self.bitrate,
            self.sample_point,
            self.tq,
            self.prop_seg,
            self.phase_seg1,
            self.phase_seg2,
            self.sjw,
            self.brp,
        ];
        let mut b = [0u8; BITTIMING_LEN];
        for (i, v) in w.iter().enumerate() {
            b[4 * i..4 * i + 4].copy_from_slice(&v.to_ne_bytes());
        }
        b
    }

    /// Parses the attribute's layout.
    pub fn from_ne_bytes(b: &[u8; BITTIMING_LEN]) -> Bittiming {
        let w = |i: usize| u32::from_ne_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]]);
        Bittiming {
            bitrate: w(0),
            sample_point: w(1),
            tq: w(2),
            prop_seg: w(3),
            phase_seg1: w(4),
            phase_seg2: w(5),
            sjw: w(6),
            brp: w(7),
        }
    }
}

/// What the device layer tells user space through the extended ack (the
/// text `ip` prints after `Error:`), worded as mainline words it; the
/// numbers are the ones mainline fills in.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Msg {
    /// The nearest reachable bit rate is off by this many tenths of a
    /// percent (a warning: the timing is set).
    BitrateError(u32),
    /// The nearest reachable bit rate is off by more than 5 % (or no
    /// prescaler fits at all): `EINVAL`.
    BitrateErrorTooHigh(u32),
    /// The sample point is 100 % or more.
    SamplePointRange,
    /// `sjw` above the controller's maximum (sjw, maximum).
    SjwAboveMax(u32, u32),
    /// `sjw` above `phase_seg1` (sjw, phase_seg1).
    SjwAbovePhaseSeg1(u32, u32),
    /// `sjw` above `phase_seg2` (sjw, phase_seg2).
    SjwAbovePhaseSeg2(u32, u32),
    /// TSEG1 below the minimum (tseg1, minimum).
    Tseg1BelowMin(u32, u32),
    /// TSEG1 above the maximum (tseg1, maximum).
    Tseg1AboveMax(u32, u32),
    /// `phase_seg2` below the minimum (phase_seg2, minimum).
    PhaseSeg2BelowMin(u32, u32),
    /// `phase_seg2` above the maximum (phase_seg2, maximum).
    PhaseSeg2AboveMax(u32, u32),
    /// The prescaler that `tq` needs is below the minimum (brp, minimum).
    BrpBelowMin(u32, u32),
    /// The prescaler that `tq` needs is above the maximum (brp, maximum).
    BrpAboveMax(u32, u32),
    /// `restart-ms` or `restart` on a device without a restart method.
    NoRestart,
}

impl fmt::Display for Msg {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Msg::BitrateError(e) => write!(f, "bitrate error: {}.{}%", e / 10, e % 10),
            Msg::BitrateErrorTooHigh(e) => {
                write!(f, "bitrate error: {}.{}% too high", e / 10, e % 10)
            }
            Msg::SamplePointRange => f.write_str("sample point must be between 0 and 100%"),
            Msg::SjwAboveMax(s, m) => write!(f, "sjw: {s} greater than max sjw: {m}"),
            Msg::SjwAbovePhaseSeg1(s, p) => write!(f, "sjw: {s} greater than phase-seg1: {p}"),
            Msg::SjwAbovePhaseSeg2(s, p) => write!(f, "sjw: {s} greater than phase-seg2: {p}"),
            Msg::Tseg1BelowMin(t, m) => {
                write!(f, "prop-seg + phase-seg1: {t} less than tseg1-min: {m}")
            }
            Msg::Tseg1AboveMax(t, m) => {
                write!(f, "prop-seg + phase-seg1: {t} greater than tseg1-max: {m}")
            }
            Msg::PhaseSeg2BelowMin(p, m) => write!(f, "phase-seg2: {p} less than tseg2-min: {m}"),
            Msg::PhaseSeg2AboveMax(p, m) => {
                write!(f, "phase-seg2: {p} greater than tseg2-max: {m}")
            }
            Msg::BrpBelowMin(b, m) => write!(f, "resulting brp: {b} less than brp-min: {m}"),
            Msg::BrpAboveMax(b, m) => write!(f, "resulting brp: {b} greater than brp-max: {m}"),
            Msg::NoRestart => f.write_str("Device doesn't support restart from Bus Off"),
        }
    }
}

/// A refused setting: the errno the netlink request fails with and the
/// extended-ack text, if mainline gives one.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Error {
    /// Positive Linux errno.
    pub errno: i32,
    /// The extended-ack message.
    pub msg: Option<Msg>,
}

impl Error {
    /// `errno` with message `msg`.
    pub const fn new(errno: i32, msg: Msg) -> Error {
        Error {
            errno,
            msg: Some(msg),
        }
    }

    /// `errno` without a message.
    pub const fn bare(errno: i32) -> Error {
        Error { errno, msg: None }
    }
}

/// A timing that was set, with the warning mainline sends along
/// ([`Msg::BitrateError`] when the bit rate is not exact).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Computed {
    /// The complete timing (every field filled in).
    pub bt: Bittiming,
    /// The extended-ack warning, if any.
    pub warning: Option<Msg>,
}

/// `|a - b|` as mainline's `abs()` computes it on the difference of two
/// `unsigned int`s (the difference taken as a signed `int`).
fn abs_diff(a: u32, b: u32) -> u32 {
    (a.wrapping_sub(b) as i32).unsigned_abs()
}

/// The sample point mainline aims at when user space gives none (the CiA
/// recommendation): 75 % above 800 kbit/s, 80 % above 500 kbit/s, else
/// 87.5 %. In tenths of a percent.
pub fn default_sample_point(bitrate: u32) -> u32 {
    if bitrate > 800_000 {
        750
    } else if bitrate > 500_000 {
        800
    } else {
        875
    }
}

/// Splits `tseg` quanta (TSEG1 + TSEG2) for a sample point at or before
/// `nominal` (tenths of a percent), as near to it as the limits allow.
///
/// Two candidates for TSEG2 are tried: the quanta after the nominal
/// sample point (rounded down) and one fewer, each clamped to the TSEG2
/// limits, TSEG1 taking the rest but at most its maximum (TSEG2 then
/// taking what is left). A candidate counts only if its sample point is
/// not later than the nominal one; the nearer one wins and is written to
/// `tseg1`/`tseg2`. If neither counts, `tseg1`/`tseg2` keep what they
/// held (mainline's behaviour, which [`calc`] relies on) and the error
/// is `u32::MAX`. Returns (sample point, its distance from `nominal`).
fn split_tseg(
    btc: &BittimingConst,
    nominal: u32,
    tseg: u32,
    tseg1: &mut u32,
    tseg2: &mut u32,
) -> (u32, u32) {
    let all = tseg.wrapping_add(SYNC_SEG);
    let (mut best_sp, mut best_err) = (0, u32::MAX);
    for fewer in 0..=1u32 {
        let after = all
            .wrapping_sub(nominal.wrapping_mul(all) / 1000)
            .wrapping_sub(fewer);
        // C's clamp(): max with the least, then min with the most.
        let mut t2 = after.max(btc.tseg2_min).min(btc.tseg2_max);
        let mut t1 = tseg.wrapping_sub(t2);
        if t1 > btc.tseg1_max {
            t1 = btc.tseg1_max;
            t2 = tseg.wrapping_sub(t1);
        }
        // `all` is 0 only for a TSEG total of u32::MAX (absurd limits),
        // where mainline divides by zero: skip the candidate. (A checked
        // division also keeps a panic path, which objtool cannot follow,
        // out of the modules.)
        let Some(sp) = 1000u32.wrapping_mul(all.wrapping_sub(t2)).checked_div(all) else {
            continue;
        };
        let err = abs_diff(nominal, sp);
        if sp <= nominal && err < best_err {
            best_sp = sp;
            best_err = err;
            *tseg1 = t1;
            *tseg2 = t2;
        }
    }
    (best_sp, best_err)
}

/// Fills in `sjw` if user space gave none: half of `phase_seg2`, at most
/// `phase_seg1`, at least one (mainline `can_sjw_set_default`).
pub fn sjw_default(bt: &mut Bittiming) {
    if bt.sjw == 0 {
        bt.sjw = bt.phase_seg1.min(bt.phase_seg2 / 2).max(1);
    }
}

/// Checks `sjw` against the controller's maximum and both phase segments
/// (mainline `can_sjw_check`): `EINVAL` with the first limit broken.
pub fn sjw_check(bt: &Bittiming, btc: &BittimingConst) -> Result<(), Error> {
    if bt.sjw > btc.sjw_max {
        return Err(Error::new(EINVAL, Msg::SjwAboveMax(bt.sjw, btc.sjw_max)));
    }
    if bt.sjw > bt.phase_seg1 {
        return Err(Error::new(
            EINVAL,
            Msg::SjwAbovePhaseSeg1(bt.sjw, bt.phase_seg1),
        ));
    }
    if bt.sjw > bt.phase_seg2 {
        return Err(Error::new(
            EINVAL,
            Msg::SjwAbovePhaseSeg2(bt.sjw, bt.phase_seg2),
        ));
    }
    Ok(())
}

/// Computes the timing for `want.bitrate` (and `want.sample_point`, 0 for
/// the default, and `want.sjw`, 0 for the default) on a controller with
/// limits `btc` counting a clock of `clock_hz` (mainline
/// `can_calc_bittiming`).
///
/// The search, from the longest bit the limits allow to the shortest:
/// for each TSEG1 + TSEG2 total (each total tried twice, with the
/// prescaler rounded down and rounded up), the prescaler giving the
/// nearest bit rate (a multiple of `brp_inc`, skipped when outside the
/// limits); among the totals with the smallest bit-rate error, the one
/// whose best split (see [`split_tseg`]) comes nearest the nominal sample
/// point without passing it; the first such wins, and an exact bit rate
/// with an exact sample point ends the search. Then TSEG1 is divided into
/// `prop_seg` (the smaller half) and `phase_seg1`, `sjw` defaults to half
/// of `phase_seg2` and is checked ([`sjw_check`]), `tq` is the prescaler
/// in nanoseconds rounded down, and `bitrate` and `sample_point` become
/// the real ones.
///
/// One deliberate difference from mainline: a result whose TSEG1 or TSEG2
/// is outside the limits (mainline's search can leave TSEG1 below its
/// minimum at low sample points, which matters for the 82527's limits
/// only) is refused with `EINVAL` and the message [`fixup`] gives for it,
/// instead of being set.
///
/// Errors: `EINVAL` with [`Msg::BitrateErrorTooHigh`] when the nearest
/// bit rate is more than 5 % off (also when no prescaler fits at all;
/// the percentage is then mainline's, computed from an error of
/// `u32::MAX`), `EINVAL` from [`sjw_check`]. A bit-rate error of 5 % or
/// less sets the timing with the warning [`Msg::BitrateError`].
pub fn calc(btc: &BittimingConst, clock_hz: u32, want: &Bittiming) -> Result<Computed, Error> {
    let bitrate = want.bitrate;
    if bitrate == 0 {
        return Err(Error::bare(EINVAL));
    }
    let nominal = if want.sample_point != 0 {
        want.sample_point
    } else {
        default_sample_point(bitrate)
    };
    let inc = btc.brp_inc.max(1);
    let (mut best_rate_err, mut best_sp_err) = (u32::MAX, u32::MAX);
    let (mut best_tseg, mut best_brp) = (0u32, 0u32);
    let (mut tseg1, mut tseg2) = (0u32, 0u32);
    // `twice` is twice the TSEG1 + TSEG2 total plus one bit that says
    // whether to round the prescaler up.
    let top = btc.tseg1_max.wrapping_add(btc.tseg2_max).wrapping_mul(2) + 1;
    let bottom = btc.tseg1_min.wrapping_add(btc.tseg2_min).wrapping_mul(2);
    let mut twice = top;
    while twice >= bottom {
        let tseg = twice / 2;
        let all = SYNC_SEG + tseg;
        let per_bit = all.wrapping_mul(bitrate);
        let next = twice.checked_sub(1);
        let mut candidate = || {
            if per_bit == 0 {
                return false;
            }
            let brp = (clock_hz / per_bit + twice % 2) / inc * inc;
            if brp < btc.brp_min || brp > btc.brp_max || brp == 0 {
                return false;
            }
            let per_brp = brp.wrapping_mul(all);
            if per_brp == 0 {
                return false;
            }
            let rate = clock_hz / per_brp;
            let rate_err = abs_diff(bitrate, rate);
            if rate_err > best_rate_err {
                return false;
            }
            if rate_err < best_rate_err {
                best_sp_err = u32::MAX;
            }
            let (_, sp_err) = split_tseg(btc, nominal, tseg, &mut tseg1, &mut tseg2);
            if sp_err >= best_sp_err {
                return false;
            }
            best_sp_err = sp_err;
            best_rate_err = rate_err;
            best_tseg = tseg;
            best_brp = brp;
            rate_err == 0 && sp_err == 0
        };
        if candidate() {
            break;
        }
        match next {
            Some(n) => twice = n,
            None => break,
        }
    }
    let mut warning = None;
    if best_rate_err != 0 {
        // Tenths of a percent, truncated to 32 bits as mainline does.
        let permille = (u64::from(best_rate_err) * 1000 / u64::from(bitrate)) as u32;
        if permille > MAX_ERROR_PERMILLE || best_brp == 0 {
            return Err(Error::new(EINVAL, Msg::BitrateErrorTooHigh(permille)));
        }
        warning = Some(Msg::BitrateError(permille));
    }
    let sample_point = split_tseg(btc, nominal, best_tseg, &mut tseg1, &mut tseg2).0;
    // Mainline's search clamps TSEG2 and caps TSEG1 but never raises TSEG1
    // to its minimum: with a low sample point it can return a TSEG1 below
    // it. With the SJA1000's limits (TSEG1 from 1) that does not happen
    // (5,615 mainline results at 4..24 MHz checked); with the 82527's
    // (TSEG1 from 3) it does, and the chip must not be given such a value:
    // refuse it as `fixup` would.
    if tseg1 < btc.tseg1_min {
        return Err(Error::new(EINVAL, Msg::Tseg1BelowMin(tseg1, btc.tseg1_min)));
    }
    if tseg2 < btc.tseg2_min || tseg2 > btc.tseg2_max {
        let m = if tseg2 < btc.tseg2_min {
            Msg::PhaseSeg2BelowMin(tseg2, btc.tseg2_min)
        } else {
            Msg::PhaseSeg2AboveMax(tseg2, btc.tseg2_max)
        };
        return Err(Error::new(EINVAL, m));
    }
    let mut bt = Bittiming {
        sample_point,
        tq: (u64::from(best_brp) * 1_000_000_000 / u64::from(clock_hz.max(1))) as u32,
        prop_seg: tseg1 / 2,
        phase_seg1: tseg1 - tseg1 / 2,
        phase_seg2: tseg2,
        sjw: want.sjw,
        brp: best_brp,
        bitrate: 0,
    };
    sjw_default(&mut bt);
    sjw_check(&bt, btc)?;
    let per_bit = bt.brp.wrapping_mul(bt.bit_time());
    if per_bit == 0 {
        return Err(Error::bare(EINVAL));
    }
    bt.bitrate = clock_hz / per_bit;
    Ok(Computed { bt, warning })
}

/// Checks a timing given directly (`tq` in ns, `prop_seg`, `phase_seg1`,
/// `phase_seg2`, optional `sjw`; `bitrate` zero) against the limits, and
/// completes it (mainline `can_fixup_bittiming`).
///
/// In order, each failure `EINVAL` with its message: TSEG1
/// (`prop_seg + phase_seg1`) below or above its limits, `phase_seg2`
/// below or above TSEG2's, then `sjw` (defaulted as in [`sjw_default`])
/// by [`sjw_check`], then the prescaler: `tq` times the clock, in whole
/// `brp_inc` steps, rounded to the nearest integer (halves down), must be
/// within the prescaler limits. The result has the real `bitrate`,
/// `sample_point` (rounded down) and `tq` (the prescaler's, rounded to the
/// nearest nanosecond).
pub fn fixup(btc: &BittimingConst, clock_hz: u32, given: &Bittiming) -> Result<Computed, Error> {
    let mut bt = *given;
    let tseg1 = bt.tseg1();
    if tseg1 < btc.tseg1_min {
        return Err(Error::new(EINVAL, Msg::Tseg1BelowMin(tseg1, btc.tseg1_min)));
    }
    if tseg1 > btc.tseg1_max {
        return Err(Error::new(EINVAL, Msg::Tseg1AboveMax(tseg1, btc.tseg1_max)));
    }
    if bt.phase_seg2 < btc.tseg2_min {
        return Err(Error::new(
            EINVAL,
            Msg::PhaseSeg2BelowMin(bt.phase_seg2, btc.tseg2_min),
        ));
    }
    if bt.phase_seg2 > btc.tseg2_max {
        return Err(Error::new(
            EINVAL,
            Msg::PhaseSeg2AboveMax(bt.phase_seg2, btc.tseg2_max),
        ));
    }
    sjw_default(&mut bt);
    sjw_check(&bt, btc)?;
    let mut brp = u64::from(clock_hz) * u64::from(bt.tq);
    if btc.brp_inc > 1 {
        brp /= u64::from(btc.brp_inc);
    }
    brp = (brp + 500_000_000 - 1) / 1_000_000_000;
    if btc.brp_inc > 1 {
        brp *= u64::from(btc.brp_inc);
    }
    bt.brp = brp as u32;
    if bt.brp < btc.brp_min {
        return Err(Error::new(EINVAL, Msg::BrpBelowMin(bt.brp, btc.brp_min)));
    }
    if bt.brp > btc.brp_max {
        return Err(Error::new(EINVAL, Msg::BrpAboveMax(bt.brp, btc.brp_max)));
    }
    let bit = bt.bit_time();
    let per_bit = bt.brp.wrapping_mul(bit);
    if per_bit == 0 || bit == 0 || clock_hz == 0 {
        return Err(Error::bare(EINVAL));
    }
    bt.bitrate = clock_hz / per_bit;
    bt.sample_point = (SYNC_SEG + tseg1).wrapping_mul(1000) / bit;
    let ns = u64::from(bt.brp) * 1_000_000_000;
    bt.tq = ((ns + u64::from(clock_hz) / 2) / u64::from(clock_hz)) as u32;
    Ok(Computed { bt, warning: None })
}

/// The sample-point check of mainline's `can_validate` (run before any
/// other attribute is looked at): below 100 %, else `EINVAL`.
pub fn validate(bt: &Bittiming) -> Result<(), Error> {
    if bt.sample_point >= 1000 {
        return Err(Error::new(EINVAL, Msg::SamplePointRange));
    }
    Ok(())
}

/// A bit timing from user space, as mainline's `can_get_bittiming`
/// treats it on a controller with limits: a bit rate without `tq` is
/// computed ([`calc`]), a `tq` without a bit rate is checked
/// ([`fixup`]); both or neither: `EINVAL` without a message. The caller
/// has run [`validate`] first, as mainline does.
pub fn get(btc: &BittimingConst, clock_hz: u32, user: &Bittiming) -> Result<Computed, Error> {
    match (user.tq, user.bitrate) {
        (0, b) if b != 0 => calc(btc, clock_hz, user),
        (t, 0) if t != 0 => fixup(btc, clock_hz, user),
        _ => Err(Error::bare(EINVAL)),
    }
}

/// BTR1 bit 7 (SJA1000 SAM, 82527 SPL): sample the bus three times.
pub const BTR1_TRIPLE: u8 = 0x80;

/// The bus timing registers BTR0/BTR1 for `bt`, the same layout on the
/// SJA1000 and the 82527 (mainline `sja1000_set_bittiming`,
/// `cc770_set_bittiming`): BTR0 = SJW-1 (bits 7..6) | BRP-1 (5..0);
/// BTR1 = three samples (bit 7) | TSEG2-1 (6..4) | TSEG1-1 (3..0). Fields
/// are masked to their width, as mainline writes them; `bt` must be
/// within the chip's limits for the registers to mean it.
pub fn to_btr(bt: &Bittiming, triple: bool) -> (u8, u8) {
    let btr0 = (bt.brp.wrapping_sub(1) & 0x3F) | ((bt.sjw.wrapping_sub(1) & 0x3) << 6);
    let btr1 = (bt.tseg1().wrapping_sub(1) & 0xF)
        | ((bt.phase_seg2.wrapping_sub(1) & 0x7) << 4)
        | if triple { u32::from(BTR1_TRIPLE) } else { 0 };
    (btr0 as u8, btr1 as u8)
}

/// The timing that BTR0/BTR1 program on a chip whose bit-timing clock is
/// `clock_hz` (SJA1000: half the crystal; 82527: the system clock), and
/// whether three samples are taken. TSEG1 is divided into `prop_seg` and
/// `phase_seg1` as [`calc`] divides it (the registers hold only their
/// sum); `tq` is rounded to the nearest nanosecond, `bitrate` and
/// `sample_point` down. A zero clock gives zero rate and tq.
pub fn from_btr(btr0: u8, btr1: u8, clock_hz: u32) -> (Bittiming, bool) {
    let brp = u32::from(btr0 & 0x3F) + 1;
    let tseg1 = u32::from(btr1 & 0x0F) + 1;
    let mut bt = Bittiming {
        brp,
        sjw: u32::from(btr0 >> 6) + 1,
        prop_seg: tseg1 / 2,
        phase_seg1: tseg1 - tseg1 / 2,
        phase_seg2: u32::from((btr1 >> 4) & 0x07) + 1,
        ..Bittiming::default()
    };
    let bit = bt.bit_time();
    bt.sample_point = (SYNC_SEG + tseg1) * 1000 / bit;
    if clock_hz != 0 {
        bt.bitrate = clock_hz / (brp * bit);
        let ns = u64::from(brp) * 1_000_000_000;
        bt.tq = ((ns + u64::from(clock_hz) / 2) / u64::from(clock_hz)) as u32;
    }
    (bt, btr1 & BTR1_TRIPLE != 0)
}

/// Bits a classic CAN data or remote frame of identifier `can_id` (with
/// `CAN_EFF_FLAG`/`CAN_RTR_FLAG`) and length `len` (0..=8) occupies on
/// the bus, without stuff bits, with the 3-bit intermission before the
/// next frame: a standard frame's 19 bits of header (SOF, identifier,
/// RTR, IDE, r0, DLC), an extended frame's 39 (SOF, base identifier,
/// SRR, IDE, extension, RTR, r1, r0, DLC), then the data (none in a
/// remote frame), 15 CRC bits, CRC delimiter, ACK slot and delimiter, 7
/// EOF bits and the intermission (ISO 11898-1). The simulated cards'
/// bus uses it to give a frame its bus time. Any context.
pub const fn frame_bits(can_id: u32, len: u8) -> u32 {
    let header = if can_id & 0x8000_0000 != 0 { 39 } else { 19 };
    let data = if can_id & 0x4000_0000 != 0 {
        0
    } else {
        8 * if len > 8 { 8 } else { len as u32 }
    };
    header + data + 15 + 1 + 2 + 7 + 3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_bits_classic() {
        // ISO 11898-1 without stuff bits: 44 + 8n (standard), 64 + 8n
        // (extended), plus the intermission.
        assert_eq!(frame_bits(0x123, 0), 47);
        assert_eq!(frame_bits(0x123, 8), 111);
        assert_eq!(frame_bits(0x8000_0000 | 0x1234_5678, 8), 131);
        assert_eq!(frame_bits(0x8000_0000 | 0x1234_5678, 0), 67);
        // A remote frame carries no data, whatever its DLC.
        assert_eq!(frame_bits(0x4000_0000 | 0x123, 8), 47);
        assert_eq!(frame_bits(0xC000_0000 | 0x1234_5678, 4), 67);
    }

    fn want(bitrate: u32, sample_point: u32) -> Bittiming {
        Bittiming {
            bitrate,
            sample_point,
            ..Bittiming::default()
        }
    }

    #[test]
    fn default_sample_points() {
        assert_eq!(default_sample_point(1_000_000), 750);
        assert_eq!(default_sample_point(800_001), 750);
        assert_eq!(default_sample_point(800_000), 800);
        assert_eq!(default_sample_point(500_001), 800);
        assert_eq!(default_sample_point(500_000), 875);
    }

    #[test]
    fn btr_round_trip() {
        let c = calc(&SJA1000_BITTIMING_CONST, 8_000_000, &want(500_000, 0)).unwrap();
        assert_eq!(c.warning, None);
        let (b0, b1) = to_btr(&c.bt, false);
        assert_eq!((b0, b1), (0x00, 0x1c));
        assert_eq!(to_btr(&c.bt, true), (0x00, 0x9c));
        let (bt, triple) = from_btr(b0, b1 | BTR1_TRIPLE, 8_000_000);
        assert!(triple);
        assert_eq!(bt, c.bt);
    }

    #[test]
    fn messages_read_as_mainline() {
        let s = |m: Msg| {
            use core::fmt::Write;
            let mut out = std::string::String::new();
            write!(out, "{m}").unwrap();
            out
        };
        assert_eq!(
            s(Msg::BitrateErrorTooHigh(63)),
            "bitrate error: 6.3% too high"
        );
        assert_eq!(s(Msg::BitrateError(8)), "bitrate error: 0.8%");
        assert_eq!(s(Msg::SjwAboveMax(5, 4)), "sjw: 5 greater than max sjw: 4");
        assert_eq!(
            s(Msg::SamplePointRange),
            "sample point must be between 0 and 100%"
        );
    }

    #[test]
    fn attribute_layout() {
        let bt = Bittiming {
            bitrate: 1,
            sample_point: 2,
            tq: 3,
            prop_seg: 4,
            phase_seg1: 5,
            phase_seg2: 6,
            sjw: 7,
            brp: 8,
        };
        let b = bt.to_ne_bytes();
        assert_eq!(&b[28..32], &8u32.to_ne_bytes());
        assert_eq!(Bittiming::from_ne_bytes(&b), bt);
    }
}
