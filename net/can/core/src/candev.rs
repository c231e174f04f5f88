// SPDX-License-Identifier: GPL-2.0

//! The rules of the CAN device layer that `ip link set canX type can ...`
//! talks to (mainline `drivers/net/can/dev/netlink.c` and `dev.c`), as
//! pure functions: which attribute changes are refused and with which
//! errno ([`validate`], [`changelink`], [`open`]), the error states from
//! the error counters ([`state_of_counter`], [`change_state`]), and the
//! error frames of `<linux/can/error.h>` ([`err`], [`error_frame`],
//! [`i82527_lec`]; the SJA1000's decoder is in its chip file,
//! `sja1000::sja1000_error`).
//!
//! Nothing here registers the "can" link kind: this is the logic the
//! netlink glue (`rust/glue/can/link.rs`) calls, each function's context being its caller's
//! (the rtnetlink calls hold RTNL in process context; the error-frame
//! decoders run in the drivers' hardirq handlers and must not sleep, and
//! do not). [`Settings`] and [`CanState`] are owned by the device; the
//! caller serialises access as mainline does (RTNL for [`changelink`] and
//! [`open`], the driver's interrupt handler for the state).

use core::fmt;

use super::arb::CAN_ERR_FLAG;
use super::bittiming::{self, Bittiming, BittimingConst, Computed, Error, Msg};
use super::bittiming::{EBUSY, EINVAL, EOPNOTSUPP};
use super::frame::{CanFrame, CANFD_MTU, CAN_MTU};

/// Control modes (`CAN_CTRLMODE_*` of `<linux/can/netlink.h>`, the
/// `IFLA_CAN_CTRLMODE` flags).
pub mod ctrlmode {
    /// Loopback mode.
    pub const LOOPBACK: u32 = 0x01;
    /// Listen-only mode.
    pub const LISTENONLY: u32 = 0x02;
    /// Triple sampling.
    pub const THREE_SAMPLES: u32 = 0x04;
    /// One-shot mode (no retransmission).
    pub const ONE_SHOT: u32 = 0x08;
    /// Bus-error reporting.
    pub const BERR_REPORTING: u32 = 0x10;
    /// CAN FD.
    pub const FD: u32 = 0x20;
    /// Ignore missing CAN ACKs.
    pub const PRESUME_ACK: u32 = 0x40;
    /// Non-ISO CAN FD.
    pub const FD_NON_ISO: u32 = 0x80;
    /// Classic CAN DLC 9..15 option.
    pub const CC_LEN8_DLC: u32 = 0x100;
    /// Transmitter delay compensation, automatic.
    pub const TDC_AUTO: u32 = 0x200;
    /// Transmitter delay compensation, manual.
    pub const TDC_MANUAL: u32 = 0x400;
    /// Both TDC modes.
    pub const TDC_MASK: u32 = TDC_AUTO | TDC_MANUAL;
}

/// What the SJA1000 can do, as mainline's `sja1000.c` announces it:
/// loopback (self test), listen-only, triple sampling, one-shot, bus-error
/// reporting, presume-ack, DLC 9..15.
pub const SJA1000_CTRLMODE_SUPPORTED: u32 = ctrlmode::LOOPBACK
    | ctrlmode::LISTENONLY
    | ctrlmode::THREE_SAMPLES
    | ctrlmode::ONE_SHOT
    | ctrlmode::BERR_REPORTING
    | ctrlmode::PRESUME_ACK
    | ctrlmode::CC_LEN8_DLC;

/// What the 82527 can do: triple sampling (BTR1's SPL bit) only, as
/// mainline's `cc770.c` announces for the chip; it has no loopback,
/// listen-only or single-shot mode.
pub const I82527_CTRLMODE_SUPPORTED: u32 = ctrlmode::THREE_SAMPLES;

/// What the device layer knows of a device (mainline's `struct can_priv`
/// fields that the rules read).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Device {
    /// Bit-timing limits; `None`: the device takes no bit timing.
    pub btc: Option<&'static BittimingConst>,
    /// Data-phase bit-timing limits (CAN FD, `IFLA_CAN_DATA_BITTIMING_CONST`);
    /// `None`: the device takes no data bit timing.
    pub dbtc: Option<&'static BittimingConst>,
    /// The clock the bit timing counts, in Hz (`IFLA_CAN_CLOCK`).
    pub clock_hz: u32,
    /// Control modes that may be switched on (`ctrlmode_supported`).
    pub ctrlmode_supported: u32,
    /// Control modes that are always on and must be given when control
    /// modes are set (`can_get_static_ctrlmode`).
    pub ctrlmode_static: u32,
    /// The driver can restart the chip after bus-off (mainline: it has a
    /// `do_set_mode`).
    pub can_restart: bool,
}

/// The settings user space changes (mainline's `can_priv` fields), owned
/// by the device, changed under RTNL.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Settings {
    /// Control modes on.
    pub ctrlmode: u32,
    /// The bit timing; `bitrate` zero: none set yet.
    pub bittiming: Bittiming,
    /// The data-phase bit timing (CAN FD); `bitrate` zero: none set (and
    /// cleared whenever control modes are set without FD, as mainline).
    pub data_bittiming: Bittiming,
    /// Automatic restart delay after bus-off in ms; 0: manual restart.
    pub restart_ms: u32,
}

/// The attributes of one `RTM_NEWLINK` request for a "can" link that the
/// rules look at (`IFLA_CAN_*`; `None`/`false`: absent).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Request {
    /// `IFLA_CAN_CTRLMODE`: (flags, mask).
    pub ctrlmode: Option<(u32, u32)>,
    /// `IFLA_CAN_BITTIMING`.
    pub bittiming: Option<Bittiming>,
    /// `IFLA_CAN_RESTART_MS`.
    pub restart_ms: Option<u32>,
    /// `IFLA_CAN_RESTART`.
    pub restart: bool,
    /// `IFLA_CAN_DATA_BITTIMING` (CAN FD).
    pub data_bittiming: Option<Bittiming>,
    /// `IFLA_CAN_TDC` (CAN FD).
    pub tdc: bool,
    /// `IFLA_CAN_TERMINATION`.
    pub termination: Option<u16>,
}

/// Checks a request before anything is changed (mainline `can_validate`,
/// for what a classic CAN controller can meet): both TDC modes at once,
/// TDC flags without TDC parameters or the reverse, CAN FD without both
/// bit timings, or data bit timing or TDC without CAN FD: `EOPNOTSUPP`;
/// a sample point of 100 % or more: `EINVAL` ([`bittiming::validate`]).
/// (The nested TDC parameters are not parsed here: no controller of ours
/// has TDC, and [`changelink`] refuses them.)
pub fn validate(req: &Request) -> Result<(), Error> {
    let mut is_fd = false;
    if let Some((flags, mask)) = req.ctrlmode {
        let tdc = flags & ctrlmode::TDC_MASK;
        is_fd = flags & mask & ctrlmode::FD != 0;
        if tdc == ctrlmode::TDC_MASK || (tdc != 0) != req.tdc {
            return Err(Error::bare(EOPNOTSUPP));
        }
    }
    if let Some(bt) = &req.bittiming {
        bittiming::validate(bt)?;
    }
    if is_fd && (req.bittiming.is_none() || req.data_bittiming.is_none()) {
        return Err(Error::bare(EOPNOTSUPP));
    }
    if (req.data_bittiming.is_some() || req.tdc) && !is_fd {
        return Err(Error::bare(EOPNOTSUPP));
    }
    if let Some(dbt) = &req.data_bittiming {
        bittiming::validate(dbt)?;
    }
    Ok(())
}

/// What [`changelink`] asks of the driver once the settings changed.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Changed {
    /// A new bit timing was set: write it to the chip (mainline
    /// `do_set_bittiming`), and pass the warning, if any, to user space.
    pub bittiming: Option<Computed>,
    /// Restart the chip now (a manual `restart` of a bus-off device):
    /// mainline's `can_restart`.
    pub restart_now: bool,
    /// A new data bit timing was set (mainline `do_set_data_bittiming`),
    /// with its warning, if any.
    pub data_bittiming: Option<Computed>,
    /// Control modes were set: the device's MTU is now this
    /// ([`CANFD_MTU`] with FD on, else [`CAN_MTU`]), as mainline's
    /// `can_changelink` sets `dev->mtu`.
    pub mtu: Option<u32>,
}

/// Applies a validated request to `settings` of device `dev` that is up
/// (`IFF_UP`) or not and in error state `state` (mainline
/// `can_changelink`, for controllers without TDC or termination). Attributes are taken
/// in mainline's order and each change is kept as soon as it is made, so
/// a later refusal leaves the earlier changes in place, as in mainline:
///
/// 1. control modes: while up `EBUSY`; modes outside supported + static,
///    or a static mode missing: `EOPNOTSUPP`; else the masked flags are
///    set, and the MTU becomes 72 with FD on, else 16 ([`Changed::mtu`]);
///    without FD the data bit timing and the TDC modes are cleared;
/// 2. bit timing: while up `EBUSY`; a device without limits
///    `EOPNOTSUPP`; else [`bittiming::get`] and its errors;
/// 3. `restart-ms`: non-zero on a device that cannot restart
///    `EOPNOTSUPP` ("Device doesn't support restart from Bus Off"); while
///    up `EBUSY`;
/// 4. `restart`: on a device that cannot restart `EOPNOTSUPP` (same
///    message); while down `EINVAL`; with automatic restart on
///    (`restart-ms` not 0) `EINVAL`; not bus-off `EBUSY`; else
///    [`Changed::restart_now`];
/// 5. data bit timing: while up `EBUSY`; a device without data limits
///    ([`Device::dbtc`], no CAN FD) `EOPNOTSUPP`; else [`bittiming::get`]
///    with the data limits and its errors (the same computation and
///    default sample points as the nominal timing, mainline
///    `can_get_bittiming` with `data_bittiming_const`); TDC parameters
///    with it `EOPNOTSUPP` (no TDC limits), the TDC modes off;
/// 6. termination: `EOPNOTSUPP` (no switchable termination).
pub fn changelink(
    dev: &Device,
    settings: &mut Settings,
    up: bool,
    state: CanState,
    req: &Request,
) -> Result<Changed, Error> {
    let mut out = Changed::default();
    if let Some((flags, mask)) = req.ctrlmode {
        if up {
            return Err(Error::bare(EBUSY));
        }
        let mut fixed = dev.ctrlmode_static;
        let masked = flags & mask;
        if masked & !(dev.ctrlmode_supported | fixed) != 0 {
            return Err(Error::bare(EOPNOTSUPP));
        }
        if masked & ctrlmode::FD == 0 {
            fixed &= !ctrlmode::FD_NON_ISO;
        }
        if masked & fixed != fixed {
            return Err(Error::bare(EOPNOTSUPP));
        }
        settings.ctrlmode = (settings.ctrlmode & !mask) | masked;
        if settings.ctrlmode & ctrlmode::FD != 0 {
            out.mtu = Some(CANFD_MTU as u32);
        } else {
            out.mtu = Some(CAN_MTU as u32);
            settings.data_bittiming = Bittiming::default();
            settings.ctrlmode &= !ctrlmode::TDC_MASK;
        }
        if mask & ctrlmode::TDC_MASK != 0 {
            settings.ctrlmode &= flags | !ctrlmode::TDC_MASK;
        }
    }
    if let Some(user) = &req.bittiming {
        if up {
            return Err(Error::bare(EBUSY));
        }
        let btc = dev.btc.ok_or(Error::bare(EOPNOTSUPP))?;
        let c = bittiming::get(btc, dev.clock_hz, user)?;
        settings.bittiming = c.bt;
        out.bittiming = Some(c);
    }
    if let Some(ms) = req.restart_ms {
        if ms != 0 && !dev.can_restart {
            return Err(Error::new(EOPNOTSUPP, Msg::NoRestart));
        }
        if up {
            return Err(Error::bare(EBUSY));
        }
        settings.restart_ms = ms;
    }
    if req.restart {
        if !dev.can_restart {
            return Err(Error::new(EOPNOTSUPP, Msg::NoRestart));
        }
        if !up || settings.restart_ms != 0 {
            return Err(Error::bare(EINVAL));
        }
        if state != CanState::BusOff {
            return Err(Error::bare(EBUSY));
        }
        out.restart_now = true;
    }
    if let Some(user) = &req.data_bittiming {
        if up {
            return Err(Error::bare(EBUSY));
        }
        let dbtc = dev.dbtc.ok_or(Error::bare(EOPNOTSUPP))?;
        let c = bittiming::get(dbtc, dev.clock_hz, user)?;
        if req.tdc {
            // Mainline's can_tdc_changelink on a device without TDC
            // limits: the TDC modes are switched off, EOPNOTSUPP.
            settings.ctrlmode &= !ctrlmode::TDC_MASK;
            return Err(Error::bare(EOPNOTSUPP));
        }
        settings.data_bittiming = c.bt;
        out.data_bittiming = Some(c);
    }
    if req.termination.is_some() {
        return Err(Error::bare(EOPNOTSUPP));
    }
    Ok(out)
}

/// The kernel log line of a refused `open` (mainline `open_candev`,
/// `netdev_err`).
pub const OPEN_NO_BITTIMING: &str = "bit-timing not yet defined";

/// The kernel log line of an `open` refused for FD without a usable data
/// bit timing (mainline `open_candev`).
pub const OPEN_BAD_DATA_BITTIMING: &str = "incorrect/missing data bit-timing";

/// Whether the device may come up (mainline `open_candev`): without a bit
/// timing `EINVAL` (and [`OPEN_NO_BITTIMING`] in the kernel log; `ip`
/// gets no extended ack); with FD on and no data bit timing, or one
/// slower than the nominal one, `EINVAL` ([`OPEN_BAD_DATA_BITTIMING`]).
/// The error is the kernel log line; the errno is always `EINVAL`.
pub fn open(settings: &Settings) -> Result<(), &'static str> {
    if settings.bittiming.bitrate == 0 {
        return Err(OPEN_NO_BITTIMING);
    }
    if settings.ctrlmode & ctrlmode::FD != 0
        && (settings.data_bittiming.bitrate == 0
            || settings.data_bittiming.bitrate < settings.bittiming.bitrate)
    {
        return Err(OPEN_BAD_DATA_BITTIMING);
    }
    Ok(())
}

/// The settings of a device whose bit timing registers hold a preset at
/// probe (SJA1000 BTR0/BTR1 from its module parameters, 82527 BT0/BT1
/// from its configuration): the timing they program at `clock_hz` and
/// triple sampling as a control mode. What `ip -details` then shows until
/// user space sets a timing. Any context.
pub fn settings_from_btr(btr0: u8, btr1: u8, clock_hz: u32) -> Settings {
    let (bittiming, triple) = bittiming::from_btr(btr0, btr1, clock_hz);
    Settings {
        bittiming,
        ctrlmode: if triple { ctrlmode::THREE_SAMPLES } else { 0 },
        ..Settings::default()
    }
}

/// The bit rates a driver's module parameters give its devices at probe
/// (`bitrate=`, `dbitrate=` of `rcan_ctucanfd_pci`), in bit/s; 0: none.
/// The initial setting of every device: `ip link set canX type can`
/// replaces it where the link kind is registered, and it is the only way
/// to a bit timing where it is not (`rcan_dev rtnl_link=N`).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Preset {
    /// `bitrate=`: the nominal rate.
    pub bitrate: u32,
    /// `dbitrate=`: the data-phase rate (CAN FD).
    pub dbitrate: u32,
}

/// A refused [`Preset`]: the parameter at fault and, if the bit timing
/// search gave one, why (its [`Display`](fmt::Display) is the kernel log
/// line's tail).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct PresetError {
    /// `"bitrate"` or `"dbitrate"`.
    pub param: &'static str,
    /// The search's reason; `None` for `dbitrate` without `bitrate` or
    /// below it.
    pub why: Option<Msg>,
}

impl fmt::Display for PresetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.why {
            Some(m) => write!(f, "{}: {}", self.param, m),
            None if self.param == "dbitrate" => {
                f.write_str("dbitrate: needs bitrate, and at least its value")
            }
            None => write!(f, "{}: no bit timing for this rate", self.param),
        }
    }
}

impl Preset {
    /// The settings `dev` starts with: each rate computed by the same
    /// search as `ip link set canX type can bitrate N` (mainline
    /// `can_calc_bittiming`, [`bittiming::get`], the default sample
    /// point) against the device's limits and clock; CAN FD stays off
    /// (MTU 16) until `ip link set canX mtu 72`, which needs no link kind.
    /// Refused with the parameter's name and the reason: a rate the
    /// device cannot meet within 5 %, `dbitrate` without `bitrate` or
    /// below it (mainline `open_candev` would refuse that data bit timing
    /// with FD on), `dbitrate` on a device without a data phase, any rate
    /// on a device without bit timing limits. No preset: the default
    /// settings. Any context.
    pub fn settings(&self, dev: &Device) -> Result<Settings, PresetError> {
        let mut s = Settings::default();
        if self.bitrate == 0 && self.dbitrate == 0 {
            return Ok(s);
        }
        if self.bitrate == 0 || (self.dbitrate != 0 && self.dbitrate < self.bitrate) {
            return Err(PresetError {
                param: "dbitrate",
                why: None,
            });
        }
        let calc = |param: &'static str, btc: Option<&BittimingConst>, rate: u32| {
            let btc = btc.ok_or(PresetError { param, why: None })?;
            let want = Bittiming {
                bitrate: rate,
                ..Bittiming::default()
            };
            bittiming::get(btc, dev.clock_hz, &want)
                .map(|c| c.bt)
                .map_err(|e| PresetError { param, why: e.msg })
        };
        s.bittiming = calc("bitrate", dev.btc, self.bitrate)?;
        if self.dbitrate != 0 {
            s.data_bittiming = calc("dbitrate", dev.dbtc, self.dbitrate)?;
        }
        Ok(s)
    }
}

/// `ip link set canX mtu N` on a device whose driver has mainline's
/// `can_change_mtu`: while up `EBUSY`; 16 turns FD off (`EINVAL` on an
/// FD-only device, FD static); 72 turns FD on (`EINVAL` on a device
/// without FD); any other value `EINVAL`. The data bit timing is kept
/// (mainline clears it only when control modes are set). The kernel has
/// already answered a request for the current MTU (success, no call).
pub fn change_mtu(
    dev: &Device,
    settings: &mut Settings,
    up: bool,
    new_mtu: u32,
) -> Result<(), Error> {
    if up {
        return Err(Error::bare(EBUSY));
    }
    let fixed = dev.ctrlmode_static;
    match new_mtu as usize {
        CAN_MTU => {
            if fixed & ctrlmode::FD != 0 {
                return Err(Error::bare(EINVAL));
            }
            settings.ctrlmode &= !ctrlmode::FD;
        }
        CANFD_MTU => {
            if (dev.ctrlmode_supported | fixed) & ctrlmode::FD == 0 {
                return Err(Error::bare(EINVAL));
            }
            settings.ctrlmode |= ctrlmode::FD;
        }
        _ => return Err(Error::bare(EINVAL)),
    }
    Ok(())
}

/// What the CTU CAN FD can do, as mainline's `ctucanfd` announces it:
/// loopback (MODE.ILBP), listen-only (MODE.BMM), CAN FD (FDE), presume-ack
/// (STM), bus-error reporting (the BEI and ALI interrupts), non-ISO CAN
/// FD (NISOFD), one-shot (RTRLE with a retransmit limit of 0).
pub const CTUCANFD_CTRLMODE_SUPPORTED: u32 = ctrlmode::LOOPBACK
    | ctrlmode::LISTENONLY
    | ctrlmode::FD
    | ctrlmode::PRESUME_ACK
    | ctrlmode::BERR_REPORTING
    | ctrlmode::FD_NON_ISO
    | ctrlmode::ONE_SHOT;

/// Controller states (`enum can_state` of `<linux/can/netlink.h>`, the
/// `IFLA_CAN_STATE` values), ordered by severity up to bus-off.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Debug, Default)]
pub enum CanState {
    /// Both error counters below 96.
    #[default]
    ErrorActive = 0,
    /// A counter at 96 or more.
    ErrorWarning = 1,
    /// A counter at 128 or more.
    ErrorPassive = 2,
    /// The transmit counter reached 256: off the bus.
    BusOff = 3,
    /// The device is down.
    Stopped = 4,
    /// The controller sleeps.
    Sleeping = 5,
}

/// Counter value at which the warning state begins
/// (`CAN_ERROR_WARNING_THRESHOLD`).
pub const WARNING_THRESHOLD: u16 = 96;
/// Counter value at which the error-passive state begins
/// (`CAN_ERROR_PASSIVE_THRESHOLD`).
pub const PASSIVE_THRESHOLD: u16 = 128;
/// Counter value at which the controller goes bus-off
/// (`CAN_BUS_OFF_THRESHOLD`).
pub const BUS_OFF_THRESHOLD: u16 = 256;

/// The state one error counter stands for: below 96 active, below 128
/// warning, below 256 passive, else bus-off (mainline
/// `can_state_err_to_state`).
pub fn state_of_counter(count: u16) -> CanState {
    if count < WARNING_THRESHOLD {
        CanState::ErrorActive
    } else if count < PASSIVE_THRESHOLD {
        CanState::ErrorWarning
    } else if count < BUS_OFF_THRESHOLD {
        CanState::ErrorPassive
    } else {
        CanState::BusOff
    }
}

/// The CAN device statistics (`struct can_device_stats`, what `ip -s -d`
/// prints under "re-started bus-errors arbit-lost error-warn error-pass
/// bus-off").
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct CanStats {
    /// Bus errors.
    pub bus_error: u32,
    /// Changes to the warning state.
    pub error_warning: u32,
    /// Changes to the error-passive state.
    pub error_passive: u32,
    /// Changes to bus-off.
    pub bus_off: u32,
    /// Arbitrations lost.
    pub arbitration_lost: u32,
    /// Restarts after bus-off.
    pub restarts: u32,
}

/// Moves the device to the worse of `tx_state` and `rx_state` (mainline
/// `can_change_state`): counts a move to a worse state in `stats`, and
/// fills in error frame `cf`: bus-off sets [`err::BUSOFF`]; any other
/// state sets [`err::CRTL`] and in data byte 1 the state of the side
/// (TX, RX, or both when equal) that is at least as bad as the other.
/// No change (mainline warns "state did not change"): nothing.
pub fn change_state(
    state: &mut CanState,
    stats: &mut CanStats,
    cf: Option<&mut CanFrame>,
    tx_state: CanState,
    rx_state: CanState,
) {
    let new = tx_state.max(rx_state);
    if new == *state {
        return;
    }
    if new > *state {
        match new {
            CanState::ErrorWarning => stats.error_warning += 1,
            CanState::ErrorPassive => stats.error_passive += 1,
            CanState::BusOff => stats.bus_off += 1,
            _ => {}
        }
    }
    *state = new;
    let Some(cf) = cf else {
        return;
    };
    if new == CanState::BusOff {
        cf.can_id |= err::BUSOFF;
        return;
    }
    cf.can_id |= err::CRTL;
    let bits = |s: CanState, warning: u8, passive: u8| match s {
        CanState::ErrorActive => err::CRTL_ACTIVE,
        CanState::ErrorWarning => warning,
        CanState::ErrorPassive => passive,
        _ => 0,
    };
    if tx_state >= rx_state {
        cf.data[1] |= bits(tx_state, err::CRTL_TX_WARNING, err::CRTL_TX_PASSIVE);
    }
    if tx_state <= rx_state {
        cf.data[1] |= bits(rx_state, err::CRTL_RX_WARNING, err::CRTL_RX_PASSIVE);
    }
}

/// `<linux/can/error.h>`: error classes (in `can_id` beside
/// `CAN_ERR_FLAG`) and the meaning of the data bytes.
pub mod err {
    /// Data length of error frames.
    pub const DLC: u8 = 8;
    /// TX timeout (by the driver).
    pub const TX_TIMEOUT: u32 = 0x0001;
    /// Lost arbitration (data[0]: bit number).
    pub const LOSTARB: u32 = 0x0002;
    /// Controller problems (data[1]).
    pub const CRTL: u32 = 0x0004;
    /// Protocol violations (data[2], data[3]).
    pub const PROT: u32 = 0x0008;
    /// Transceiver status (data[4]).
    pub const TRX: u32 = 0x0010;
    /// No ACK on transmission.
    pub const ACK: u32 = 0x0020;
    /// Bus-off.
    pub const BUSOFF: u32 = 0x0040;
    /// Bus error.
    pub const BUSERROR: u32 = 0x0080;
    /// Controller restarted.
    pub const RESTARTED: u32 = 0x0100;
    /// data[6]/data[7] hold the TX/RX error counters.
    pub const CNT: u32 = 0x0200;
    /// data[0]: arbitration lost at an unspecified bit.
    pub const LOSTARB_UNSPEC: u8 = 0x00;
    /// data[1]: receive buffer overflow.
    pub const CRTL_RX_OVERFLOW: u8 = 0x01;
    /// data[1]: transmit buffer overflow.
    pub const CRTL_TX_OVERFLOW: u8 = 0x02;
    /// data[1]: RX warning level.
    pub const CRTL_RX_WARNING: u8 = 0x04;
    /// data[1]: TX warning level.
    pub const CRTL_TX_WARNING: u8 = 0x08;
    /// data[1]: RX error passive.
    pub const CRTL_RX_PASSIVE: u8 = 0x10;
    /// data[1]: TX error passive.
    pub const CRTL_TX_PASSIVE: u8 = 0x20;
    /// data[1]: back to error active.
    pub const CRTL_ACTIVE: u8 = 0x40;
    /// data[2]: single bit error.
    pub const PROT_BIT: u8 = 0x01;
    /// data[2]: frame format error.
    pub const PROT_FORM: u8 = 0x02;
    /// data[2]: bit stuffing error.
    pub const PROT_STUFF: u8 = 0x04;
    /// data[2]: unable to send a dominant bit.
    pub const PROT_BIT0: u8 = 0x08;
    /// data[2]: unable to send a recessive bit.
    pub const PROT_BIT1: u8 = 0x10;
    /// data[2]: bus overload.
    pub const PROT_OVERLOAD: u8 = 0x20;
    /// data[2]: active error announcement.
    pub const PROT_ACTIVE: u8 = 0x40;
    /// data[2]: the error occurred on transmission.
    pub const PROT_TX: u8 = 0x80;
    /// data[3]: in the CRC sequence.
    pub const PROT_LOC_CRC_SEQ: u8 = 0x08;
    /// data[3]: in the ACK slot.
    pub const PROT_LOC_ACK: u8 = 0x19;
}

/// Largest raw data length code of a classic frame on the wire (mainline
/// `CAN_MAX_RAW_DLC`): DLC 9..15 carry 8 data bytes.
pub const CAN_MAX_RAW_DLC: u8 = 15;

/// The data length code a driver puts in the controller's DLC field for
/// `frame` (mainline `can_get_cc_dlc`): with `cc-len8-dlc` on, a frame of
/// 8 bytes whose `len8_dlc` is 9..15 is sent with that DLC; otherwise
/// (mode off, `len` below 8, `len8_dlc` 0..8 or above 15) its `len`.
/// Any context.
pub fn cc_dlc(frame: &CanFrame, ctrlmode: u32) -> u8 {
    let len = frame.dlc() as u8;
    if ctrlmode & ctrlmode::CC_LEN8_DLC != 0
        && usize::from(frame.len) == super::arb::MAX_DLC
        && frame.len8_dlc > 8
        && frame.len8_dlc <= CAN_MAX_RAW_DLC
    {
        frame.len8_dlc
    } else {
        len
    }
}

/// Sets the length of a received classic frame from the controller's raw
/// DLC `dlc` (mainline `can_frame_set_cc_len`): `len` is `dlc` clamped to
/// 8; with `cc-len8-dlc` on, a DLC of 9..15 is kept in `len8_dlc` too
/// (else `len8_dlc` is left 0). Any context.
pub fn set_cc_len(frame: &mut CanFrame, dlc: u8, ctrlmode: u32) {
    let dlc = dlc & 0x0F;
    frame.len = dlc.min(super::arb::MAX_DLC as u8);
    if ctrlmode & ctrlmode::CC_LEN8_DLC != 0 && dlc > 8 {
        frame.len8_dlc = dlc;
    }
}

/// An empty error frame (mainline `alloc_can_err_skb`'s frame):
/// `CAN_ERR_FLAG`, DLC 8, all data zero.
pub fn error_frame() -> CanFrame {
    CanFrame {
        can_id: CAN_ERR_FLAG,
        len: err::DLC,
        ..CanFrame::default()
    }
}

/// Interface statistics an SJA1000 error interrupt counts (`struct
/// net_device_stats` fields).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct NetErrStats {
    /// Receive errors.
    pub rx_errors: u32,
    /// Transmit errors.
    pub tx_errors: u32,
    /// Receive overruns.
    pub rx_over_errors: u32,
}

/// 82527 status register: last error code (bits 2..0).
pub const I82527_LEC_MASK: u8 = 0x07;

/// Adds to error frame `cf` what the 82527's last error code `lec`
/// (status register bits 2..0) says, as mainline's `cc770_err` does for
/// the same register: 1 stuff, 2 form, 4 bit 1 (recessive not sent), 5 bit
/// 0 (dominant not sent) in [`err::PROT`] data[2]; 6 CRC as location
/// [`err::PROT_LOC_CRC_SEQ`] in data[3]; 3 (no ACK) as [`err::ACK`]; 0
/// (no error) and 7 (unused, "not updated by the CPU") add nothing.
pub fn i82527_lec(cf: &mut CanFrame, lec: u8) {
    match lec & I82527_LEC_MASK {
        3 => cf.can_id |= err::ACK,
        l @ (1 | 2 | 4 | 5 | 6) => {
            cf.can_id |= err::PROT;
            match l {
                1 => cf.data[2] |= err::PROT_STUFF,
                2 => cf.data[2] |= err::PROT_FORM,
                4 => cf.data[2] |= err::PROT_BIT1,
                5 => cf.data[2] |= err::PROT_BIT0,
                _ => cf.data[3] = err::PROT_LOC_CRC_SEQ,
            }
        }
        _ => {}
    }
}
