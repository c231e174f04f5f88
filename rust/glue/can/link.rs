// SPDX-License-Identifier: GPL-2.0

//! The rtnetlink link kind "can" (mainline `drivers/net/can/dev/netlink.c`),
//! compiled into `rcan_dev` only (by `candev_mod.rs`): the callbacks of
//! `rcan_can_link_ops` (defined with its attribute policy in
//! `drivers/net/can/dev/candev_c.c`) and [`LinkKind`], the registration.
//!
//! These functions only turn netlink attributes into the typed request of
//! [`crate::glue::can::dev::LinkReq`] and the driver's [`super::dev::LinkInfo`] into
//! attributes; the rules (what is refused, with which errno and message)
//! are `rcan_core::candev`'s, applied by the driver's side
//! (`glue::can::dev`), which owns the device's settings.
//!
//! Every callback runs in process context with RTNL held (rtnetlink's
//! `RTM_NEWLINK`, `RTM_GETLINK` and its dumps, and the notifications
//! after a change; 6.12 dumps links under RTNL).
#![allow(clippy::missing_safety_doc, improper_ctypes)]

use crate::glue::bindings;
use crate::glue::can::dev::{CanDevHooks, CanDeviceStats, LinkInfo, LinkMsg, LinkReq};
use crate::rcan_core::bittiming::{Bittiming, BITTIMING_LEN};
use crate::rcan_core::candev;
use kernel::ffi;
use kernel::prelude::*;

// `IFLA_CAN_*` of <linux/can/netlink.h>.
const IFLA_CAN_BITTIMING: usize = 1;
const IFLA_CAN_BITTIMING_CONST: i32 = 2;
const IFLA_CAN_CLOCK: i32 = 3;
const IFLA_CAN_STATE: i32 = 4;
const IFLA_CAN_CTRLMODE: usize = 5;
const IFLA_CAN_RESTART_MS: usize = 6;
const IFLA_CAN_RESTART: usize = 7;
const IFLA_CAN_BERR_COUNTER: i32 = 8;
const IFLA_CAN_DATA_BITTIMING: usize = 9;
const IFLA_CAN_DATA_BITTIMING_CONST: i32 = 10;
const IFLA_CAN_TERMINATION: usize = 11;
const IFLA_CAN_BITRATE_MAX: i32 = 15;
const IFLA_CAN_TDC: usize = 16;
const IFLA_CAN_CTRLMODE_EXT: i32 = 17;
/// `IFLA_CAN_MAX`: the policy array has this many entries plus one.
const IFLA_CAN_MAX: usize = 17;
/// `IFLA_CAN_CTRLMODE_SUPPORTED`, inside `IFLA_CAN_CTRLMODE_EXT`.
const IFLA_CAN_CTRLMODE_SUPPORTED: i32 = 1;

/// `sizeof(struct can_bittiming_const)`: a 16-byte name, eight u32.
const BITTIMING_CONST_LEN: usize = 48;
/// `sizeof(struct can_device_stats)`.
const DEVICE_STATS_LEN: usize = core::mem::size_of::<CanDeviceStats>();

extern "C" {
    fn rcan_can_link_register() -> ffi::c_int;
    fn rcan_can_link_unregister();
    fn rcan_nla_data(nla: *const bindings::nlattr, len: *mut ffi::c_int) -> *const ffi::c_void;
    fn rcan_nla_put(
        skb: *mut bindings::sk_buff,
        type_: ffi::c_int,
        len: ffi::c_int,
        data: *const ffi::c_void,
    ) -> ffi::c_int;
    fn rcan_nla_put_nested_u32(
        skb: *mut bindings::sk_buff,
        outer: ffi::c_int,
        inner: ffi::c_int,
        val: u32,
    ) -> ffi::c_int;
    fn rcan_nla_total_size(payload: ffi::c_int) -> usize;
    fn rcan_extack_msg(extack: *mut bindings::netlink_ext_ack, msg: *const ffi::c_char);
}

/// The registered "can" link kind; dropping it unregisters.
pub(crate) struct LinkKind(());

impl LinkKind {
    /// Registers the "can" link kind. `EEXIST` if another module holds
    /// it (mainline's `can-dev`: only one stack can own the kind, as with
    /// PF_CAN). Process context.
    pub(crate) fn register() -> Result<LinkKind> {
        // SAFETY: registers the static ops table of candev_c.c, whose
        // callbacks are the functions below; unregistered in Drop.
        crate::glue::to_result(unsafe { rcan_can_link_register() })?;
        Ok(LinkKind(()))
    }
}

impl Drop for LinkKind {
    fn drop(&mut self) {
        // Each driver module that made a device references
        // `rcan_can_link_ops`, so this module outlives those devices.
        // SAFETY: registered by `register`; no device can still point to
        // the ops (above).
        unsafe { rcan_can_link_unregister() };
    }
}

/// Attribute `i` of `data` (`IFLA_INFO_DATA` parsed with our policy),
/// copied into `out` (shorter payloads leave the rest zero); whether it
/// was present.
///
/// # Safety
///
/// `data` is NULL or an array of `IFLA_CAN_MAX + 1` attribute pointers
/// (each NULL or an attribute the policy checked), valid for the call.
unsafe fn attr(data: *mut *mut bindings::nlattr, i: usize, out: &mut [u8]) -> bool {
    if data.is_null() || i > IFLA_CAN_MAX {
        return false;
    }
    // SAFETY: in bounds of the array (contract, checked index).
    let nla = unsafe { *data.add(i) };
    if nla.is_null() {
        return false;
    }
    let mut len: ffi::c_int = 0;
    // SAFETY: a valid attribute (contract).
    let p = unsafe { rcan_nla_data(nla, &mut len) }.cast::<u8>();
    let n = usize::try_from(len).unwrap_or(0).min(out.len());
    // SAFETY: the payload has `len` >= n readable bytes.
    out[..n].copy_from_slice(unsafe { core::slice::from_raw_parts(p, n) });
    true
}

/// The "can" attributes of a request.
///
/// # Safety
///
/// As for [`attr`].
unsafe fn parse(data: *mut *mut bindings::nlattr) -> LinkReq {
    let mut r = LinkReq::default();
    let mut cm = [0u8; 8];
    let mut u32b = [0u8; 4];
    let mut u16b = [0u8; 2];
    // SAFETY (all calls below): per our contract.
    unsafe {
        if attr(data, IFLA_CAN_CTRLMODE, &mut cm) {
            // struct can_ctrlmode { __u32 mask; __u32 flags; }
            r.has_ctrlmode = true;
            r.ctrlmode_mask = u32::from_ne_bytes([cm[0], cm[1], cm[2], cm[3]]);
            r.ctrlmode_flags = u32::from_ne_bytes([cm[4], cm[5], cm[6], cm[7]]);
        }
        r.has_bittiming = attr(data, IFLA_CAN_BITTIMING, &mut r.bittiming);
        if attr(data, IFLA_CAN_RESTART_MS, &mut u32b) {
            r.has_restart_ms = true;
            r.restart_ms = u32::from_ne_bytes(u32b);
        }
        r.restart = attr(data, IFLA_CAN_RESTART, &mut u32b);
        r.has_data_bittiming = attr(data, IFLA_CAN_DATA_BITTIMING, &mut r.data_bittiming);
        r.tdc = attr(data, IFLA_CAN_TDC, &mut []);
        if attr(data, IFLA_CAN_TERMINATION, &mut u16b) {
            r.has_termination = true;
            r.termination = u16::from_ne_bytes(u16b);
        }
    }
    r
}

/// Copies a non-empty message into the extended ack.
///
/// # Safety
///
/// `extack` is NULL or the request's ack.
unsafe fn set_msg(extack: *mut bindings::netlink_ext_ack, msg: &LinkMsg) {
    if !extack.is_null() && !msg.is_empty() {
        // SAFETY: NUL-terminated (LinkMsg::set leaves room), valid ack.
        unsafe { rcan_extack_msg(extack, msg.text.as_ptr().cast()) };
    }
}

/// `rtnl_link_ops.validate`: the checks that need no device (mainline
/// `can_validate`).
#[no_mangle]
unsafe extern "C" fn rcan_can_validate(
    _tb: *mut *mut bindings::nlattr,
    data: *mut *mut bindings::nlattr,
    extack: *mut bindings::netlink_ext_ack,
) -> ffi::c_int {
    // SAFETY: rtnetlink passes NULL or the array parsed with our policy
    // (`maxtype` IFLA_CAN_MAX).
    let req = unsafe { parse(data) }.to_request();
    match candev::validate(&req) {
        Ok(()) => 0,
        Err(e) => {
            let mut msg = LinkMsg::new();
            if let Some(m) = &e.msg {
                msg.set(m);
            }
            // SAFETY: the request's ack or NULL.
            unsafe { set_msg(extack, &msg) };
            crate::glue::errno(e.errno).to_errno()
        }
    }
}

/// The driver's hooks of `dev`.
///
/// # Safety
///
/// `dev` is a device whose `rtnl_link_ops` are `rcan_can_link_ops`:
/// rtnetlink calls our ops only for those, and only
/// `glue::can::dev::link_setup` puts our ops in a device, together with the
/// driver's 'static hooks in `ml_priv`.
unsafe fn hooks<'a>(dev: *const bindings::net_device) -> &'a CanDevHooks {
    // SAFETY: per the contract.
    unsafe { &*(*dev).ml_priv.cast::<CanDevHooks>() }
}

/// `rtnl_link_ops.changelink`.
#[no_mangle]
unsafe extern "C" fn rcan_can_changelink(
    dev: *mut bindings::net_device,
    _tb: *mut *mut bindings::nlattr,
    data: *mut *mut bindings::nlattr,
    extack: *mut bindings::netlink_ext_ack,
) -> ffi::c_int {
    // SAFETY: as in validate.
    let req = unsafe { parse(data) };
    let mut msg = LinkMsg::new();
    // SAFETY: a device of ours (see `hooks`), RTNL held; the request and
    // message live for the call.
    let ret = unsafe { (hooks(dev).changelink)(dev, &req, &mut msg) };
    // SAFETY: the request's ack or NULL.
    unsafe { set_msg(extack, &msg) };
    ret
}

/// The device's state, from its driver.
///
/// # Safety
///
/// As for [`hooks`]; RTNL held.
unsafe fn info(dev: *const bindings::net_device) -> LinkInfo {
    let mut out = core::mem::MaybeUninit::<LinkInfo>::uninit();
    // SAFETY: a device of ours; `info` writes the whole struct.
    unsafe {
        (hooks(dev).info)(dev, out.as_mut_ptr());
        out.assume_init()
    }
}

/// `rtnl_link_ops.get_size`: room for everything `fill_info` may put.
#[no_mangle]
unsafe extern "C" fn rcan_can_get_size(_dev: *const bindings::net_device) -> usize {
    let sizes = [
        BITTIMING_LEN, // IFLA_CAN_BITTIMING
        BITTIMING_CONST_LEN,
        4,                   // IFLA_CAN_CLOCK
        4,                   // IFLA_CAN_STATE
        8,                   // IFLA_CAN_CTRLMODE
        4,                   // IFLA_CAN_RESTART_MS
        4,                   // IFLA_CAN_BERR_COUNTER
        BITTIMING_LEN,       // IFLA_CAN_DATA_BITTIMING
        BITTIMING_CONST_LEN, // IFLA_CAN_DATA_BITTIMING_CONST
        4,                   // IFLA_CAN_BITRATE_MAX
    ];
    let mut n = 0;
    for s in sizes {
        // SAFETY: pure arithmetic.
        n += unsafe { rcan_nla_total_size(s as ffi::c_int) };
    }
    // IFLA_CAN_CTRLMODE_EXT: a nest holding one u32.
    // SAFETY: pure arithmetic.
    n + unsafe { rcan_nla_total_size(rcan_nla_total_size(4) as ffi::c_int) }
}

/// Puts one attribute; `Err` when the skb is full.
///
/// # Safety
///
/// `skb` is the message being filled.
unsafe fn put(skb: *mut bindings::sk_buff, type_: i32, data: &[u8]) -> Result {
    // SAFETY: `data` is readable for its length; valid skb (contract).
    let ret = unsafe { rcan_nla_put(skb, type_, data.len() as ffi::c_int, data.as_ptr().cast()) };
    crate::glue::to_result(ret).map(|_| ())
}

/// `struct can_bittiming_const` from a name and the eight limits.
fn limits(name: &[u8; 16], v: &[u32; 8]) -> [u8; BITTIMING_CONST_LEN] {
    let mut btc = [0u8; BITTIMING_CONST_LEN];
    btc[..16].copy_from_slice(name);
    for (k, v) in v.iter().enumerate() {
        btc[16 + 4 * k..20 + 4 * k].copy_from_slice(&v.to_ne_bytes());
    }
    btc
}

/// `rtnl_link_ops.fill_info`: what `ip -details link show` prints (in
/// mainline's order; `bitrate-max` 0 as mainline's SJA1000 reports; the
/// data bit timing once set and the data limits of an FD controller).
#[no_mangle]
unsafe extern "C" fn rcan_can_fill_info(
    skb: *mut bindings::sk_buff,
    dev: *const bindings::net_device,
) -> ffi::c_int {
    // SAFETY: a device of ours, RTNL held.
    let i = unsafe { info(dev) };
    let fill = || -> Result {
        // SAFETY (every put): `skb` is the message rtnetlink fills.
        unsafe {
            if Bittiming::from_ne_bytes(&i.bittiming).bitrate != 0 {
                put(skb, IFLA_CAN_BITTIMING as i32, &i.bittiming)?;
            }
            put(skb, IFLA_CAN_BITTIMING_CONST, &limits(&i.btc_name, &i.btc))?;
            put(skb, IFLA_CAN_CLOCK, &i.clock_hz.to_ne_bytes())?;
            put(skb, IFLA_CAN_STATE, &i.state.to_ne_bytes())?;
            // struct can_ctrlmode: mask 0, the flags on.
            let mut cm = [0u8; 8];
            cm[4..].copy_from_slice(&i.ctrlmode.to_ne_bytes());
            put(skb, IFLA_CAN_CTRLMODE as i32, &cm)?;
            put(skb, IFLA_CAN_RESTART_MS as i32, &i.restart_ms.to_ne_bytes())?;
            let mut bec = [0u8; 4];
            bec[..2].copy_from_slice(&i.txerr.to_ne_bytes());
            bec[2..].copy_from_slice(&i.rxerr.to_ne_bytes());
            put(skb, IFLA_CAN_BERR_COUNTER, &bec)?;
            if Bittiming::from_ne_bytes(&i.data_bittiming).bitrate != 0 {
                put(skb, IFLA_CAN_DATA_BITTIMING as i32, &i.data_bittiming)?;
            }
            if i.has_dbtc {
                put(
                    skb,
                    IFLA_CAN_DATA_BITTIMING_CONST,
                    &limits(&i.dbtc_name, &i.dbtc),
                )?;
            }
            put(skb, IFLA_CAN_BITRATE_MAX, &0u32.to_ne_bytes())?;
            crate::glue::to_result(rcan_nla_put_nested_u32(
                skb,
                IFLA_CAN_CTRLMODE_EXT,
                IFLA_CAN_CTRLMODE_SUPPORTED,
                i.ctrlmode_supported,
            ))?;
        }
        Ok(())
    };
    match fill() {
        Ok(()) => 0,
        Err(_) => crate::glue::neterr::EMSGSIZE().to_errno(),
    }
}

/// `rtnl_link_ops.get_xstats_size`.
#[no_mangle]
unsafe extern "C" fn rcan_can_get_xstats_size(_dev: *const bindings::net_device) -> usize {
    DEVICE_STATS_LEN
}

/// `rtnl_link_ops.fill_xstats`: `struct can_device_stats` (what
/// `ip -s -d` prints under "re-started bus-errors arbit-lost error-warn
/// error-pass bus-off"), as the `IFLA_INFO_XSTATS` payload.
#[no_mangle]
unsafe extern "C" fn rcan_can_fill_xstats(
    skb: *mut bindings::sk_buff,
    dev: *const bindings::net_device,
) -> ffi::c_int {
    // SAFETY: a device of ours, RTNL held.
    let s = unsafe { info(dev) }.stats;
    let mut b = [0u8; DEVICE_STATS_LEN];
    for (k, v) in [
        s.bus_error,
        s.error_warning,
        s.error_passive,
        s.bus_off,
        s.arbitration_lost,
        s.restarts,
    ]
    .iter()
    .enumerate()
    {
        b[4 * k..4 * k + 4].copy_from_slice(&v.to_ne_bytes());
    }
    // IFLA_INFO_XSTATS of <linux/if_link.h>.
    const IFLA_INFO_XSTATS: i32 = 3;
    // SAFETY: the message rtnetlink fills.
    match unsafe { put(skb, IFLA_INFO_XSTATS, &b) } {
        Ok(()) => 0,
        Err(_) => crate::glue::neterr::EMSGSIZE().to_errno(),
    }
}
