// SPDX-License-Identifier: GPL-2.0

//! The module parameters of `rcan_dsor` (dsor.rst, "Loading"): read once
//! at load from the C side (`candsor_c.c`, which declares them with
//! `module_param`), validated, and kept in the engine as [`Config`]. Out
//! of range values fail the load with EINVAL and a `dmesg` line. Process
//! context (module init); `PARAM_REASM_TIMEOUT_MS` is also read later,
//! in any context (the value is fixed while the module is loaded: the
//! parameters are read-only in sysfs).

#![forbid(unsafe_code)]

use kernel::c_str;
use kernel::prelude::*;

use crate::engine::RX_SLOTS;
use crate::glue::params::{Param, ParamStr};
use crate::rcan_core;
use crate::rcan_core::dsor_wire::{self, Timers};

// Parameter numbers shared with candsor_c.c (its rcan_module_param and
// rcan_module_param_str).
const PARAM_NODE: Param<u32> = Param::new(0);
const PARAM_ACK_TIMEOUT_MS: Param<u32> = Param::new(1);
const PARAM_MAX_RETX: Param<u32> = Param::new(2);
pub(crate) const PARAM_REASM_TIMEOUT_MS: Param<u32> = Param::new(3);
const PARAM_MAX_LEN: Param<u32> = Param::new(4);
const PARAM_MAX_PER_PEER: Param<u32> = Param::new(5);
const PARAM_MAX_BYTES: Param<u32> = Param::new(6);
const PARAM_UDP_PRIO: Param<u32> = Param::new(7);
const PARAM_CANIP: Param<bool> = Param::new(8);
/// `ifname`: copied NUL-terminated, at most 15 bytes.
const PARAM_IFNAME: ParamStr = ParamStr::new(9);
/// `udp_saddr`: copied NUL-terminated, at most 15 bytes.
const PARAM_UDP_SADDR: ParamStr = ParamStr::new(10);

/// An interface name or address string of the C side: 16 bytes, NUL-padded.
#[derive(Clone, Copy)]
pub(crate) struct Name([u8; 16]);

impl Name {
    pub(crate) fn bytes(&self) -> &[u8] {
        let n = self.0.iter().position(|&b| b == 0).unwrap_or(15);
        &self.0[..n]
    }

    pub(crate) fn as_cstr(&self) -> &kernel::str::CStr {
        let n = self.bytes().len();
        kernel::str::CStr::from_bytes_with_nul(&self.0[..=n]).unwrap_or(c_str!("?"))
    }

    pub(crate) fn as_str(&self) -> &str {
        core::str::from_utf8(self.bytes()).unwrap_or("?")
    }
}

/// Settings fixed at load: the parameters, validated.
pub(crate) struct Config {
    pub(crate) node: u8,
    pub(crate) ifname: Name,
    pub(crate) timers: Timers,
    pub(crate) limits_max_len: u16,
    pub(crate) max_per_peer: u8,
    pub(crate) max_bytes: usize,
    pub(crate) udp_saddr: u32,
    pub(crate) udp_prio: u8,
    pub(crate) canip: bool,
}

/// Fails the load with EINVAL and a `dmesg` line naming the parameter, its
/// value and the allowed range (dsor.rst, "Loading").
fn bad_param(name: &str, value: impl core::fmt::Display, range: &str) -> Error {
    pr_err!("{}={}: out of range, allowed {}\n", name, value, range);
    EINVAL
}

/// The `ifname` rules of the kernel's `dev_valid_name`: 1 to 15 bytes, no
/// '/', ':' or white space, not "." or "..".
fn valid_ifname(name: &[u8]) -> bool {
    (1..IFNAMSIZ).contains(&name.len())
        && name != b"."
        && name != b".."
        && !name
            .iter()
            .any(|&c| c == b'/' || c == b':' || c.is_ascii_whitespace())
}

/// Bytes of an interface name including the NUL (`IFNAMSIZ`).
const IFNAMSIZ: usize = 16;

pub(crate) fn load_config() -> Result<Config> {
    let mut ifname = Name([0; 16]);
    let mut saddr = Name([0; 16]);
    let ifname_len = PARAM_IFNAME.read(&mut ifname.0);
    let saddr_len = PARAM_UDP_SADDR.read(&mut saddr.0);
    let node = PARAM_NODE.get();
    let timers = Timers {
        ack_timeout_ms: PARAM_ACK_TIMEOUT_MS.get(),
        max_retx: PARAM_MAX_RETX.get(),
        reasm_timeout_ms: PARAM_REASM_TIMEOUT_MS.get(),
    };
    let max_len = PARAM_MAX_LEN.get();
    let per_peer = PARAM_MAX_PER_PEER.get();
    let max_bytes = PARAM_MAX_BYTES.get();
    let udp_prio = PARAM_UDP_PRIO.get();
    if node > u32::from(dsor_wire::MAX_NODE) {
        return Err(bad_param("node", node, "0x00-0x7f"));
    }
    // The C side copies at most 15 bytes; the length is the whole string's.
    if ifname_len >= IFNAMSIZ || !valid_ifname(ifname.bytes()) {
        pr_err!(
            "ifname: not an interface name ({} bytes), allowed 1-15 bytes without '/', ':' or white space\n",
            ifname_len
        );
        return Err(EINVAL);
    }
    let Some(udp_saddr) =
        rcan_core::dsor_udp::parse_ipv4_addr(saddr.bytes()).filter(|_| saddr_len < IFNAMSIZ)
    else {
        pr_err!("udp_saddr: not an IPv4 address, allowed a.b.c.d\n");
        return Err(EINVAL);
    };
    if !(10..=60_000).contains(&timers.ack_timeout_ms) {
        return Err(bad_param(
            "ack_timeout_ms",
            timers.ack_timeout_ms,
            "10-60000",
        ));
    }
    if timers.max_retx > 100 {
        return Err(bad_param("max_retx", timers.max_retx, "0-100"));
    }
    let window = u64::from(timers.ack_timeout_ms) * (u64::from(timers.max_retx) + 1);
    if u64::from(timers.reasm_timeout_ms) <= window || timers.reasm_timeout_ms > 600_000 {
        pr_err!(
            "reasm_timeout_ms={}: out of range, allowed {}-600000 (more than ack_timeout_ms * (max_retx + 1))\n",
            timers.reasm_timeout_ms,
            window + 1
        );
        return Err(EINVAL);
    }
    if !(1..=dsor_wire::MAX_LEN as u32).contains(&max_len) {
        return Err(bad_param("max_len", max_len, "1-65535"));
    }
    if !(1..=(RX_SLOTS as u32)).contains(&per_peer) {
        pr_err!(
            "max_per_peer={}: out of range, allowed 1-{}\n",
            per_peer,
            RX_SLOTS
        );
        return Err(EINVAL);
    }
    if !(max_len..=MAX_BYTES_LIMIT).contains(&max_bytes) {
        pr_err!(
            "max_bytes={}: out of range, allowed max_len ({})-{}\n",
            max_bytes,
            max_len,
            MAX_BYTES_LIMIT
        );
        return Err(EINVAL);
    }
    if udp_prio > 0xff {
        return Err(bad_param("udp_prio", udp_prio, "0x00-0xff"));
    }
    Ok(Config {
        node: node as u8,
        ifname,
        timers,
        limits_max_len: max_len as u16,
        max_per_peer: per_peer as u8,
        max_bytes: max_bytes as usize,
        udp_saddr,
        udp_prio: udp_prio as u8,
        canip: PARAM_CANIP.get(),
    })
}

/// Largest `max_bytes`: 64 slots of the longest message.
const MAX_BYTES_LIMIT: u32 = RX_SLOTS as u32 * dsor_wire::MAX_LEN as u32;
