// SPDX-License-Identifier: GPL-2.0
//! Loading and unloading the two CAN stacks under test.
//!
//! Only one stack can own PF_CAN at a time, so each is loaded, measured and
//! removed completely before the other:
//!
//! - mainline: `can.ko`, `can-raw.ko` and `vcan.ko echo=1` (plus `can-dev.ko`
//!   if this kernel's `vcan.ko` depends on it) from the test kernel's build
//!   directory (`RCAN_KBUILD`), then `ip link add dev can0 type vcan`;
//! - ours: `rcan_pf`, `rcan_can`, `rcan_raw` and `rcan_loop` from the
//!   project tree; `rcan_loop` creates `can0` itself.
//!
//! The table part loads two devices (`load_devices`): a second `vcan`
//! device, or `rcan_loop count=2` (`can0` and `can1`).
//!
//! Both devices echo (`IFF_ECHO`): a frame sent with `CAN_RAW_LOOPBACK` on
//! comes back into the receive path through the driver.

use std::fmt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// Module names of both stacks in unload order (users before providers).
/// Anything else of ours (`rcan_*`) is unloaded first.
const MAINLINE_MODULES: &[&str] = &[
    "can_raw",
    "can_bcm",
    "can_isotp",
    "can_gw",
    "vcan",
    "can_dev",
    "can",
];
const OURS_MODULES: &[&str] = &["rcan_loop", "rcan_raw", "rcan_can", "rcan_pf"];

/// Which stack to measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stack {
    /// Mainline SocketCAN: `can.ko` + `can-raw.ko` + `vcan.ko echo=1`.
    Mainline,
    /// rcan: `rcan_pf` + `rcan_can` + `rcan_raw` + `rcan_loop`.
    Ours,
}

impl fmt::Display for Stack {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stack::Mainline => "mainline",
            Stack::Ours => "ours",
        })
    }
}

/// Where the modules are.
#[derive(Debug, PartialEq)]
pub struct Paths {
    /// The project tree (`RCAN_ROOT`, else the current directory).
    pub root: PathBuf,
    /// The test kernel's build directory (`RCAN_KBUILD`), for mainline.
    pub kbuild: Option<PathBuf>,
}

/// Runs a command, echoing it; fails on a non-zero exit status.
fn run(cmd: &str, args: &[&str]) -> Result<(), String> {
    println!("+ {cmd} {}", args.join(" "));
    let out = Command::new(cmd)
        .args(args)
        .output()
        .map_err(|e| format!("{cmd}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`{cmd} {}` failed ({}): {}",
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Runs a command quietly, ignoring failure (cleanup).
fn run_quiet(cmd: &str, args: &[&str]) {
    let _ = Command::new(cmd).args(args).output();
}

fn insmod(path: &Path, params: &[&str]) -> Result<(), String> {
    if !path.is_file() {
        return Err(format!("{} not found", path.display()));
    }
    let p = path.to_string_lossy();
    let mut args = vec![p.as_ref()];
    args.extend_from_slice(params);
    run("insmod", &args)
}

/// Names of the loaded modules (first column of `/proc/modules`).
fn loaded_modules() -> Vec<String> {
    std::fs::read_to_string("/proc/modules")
        .unwrap_or_default()
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

/// `rmmod`, retried for a few seconds: the last socket reference can be
/// dropped a little after `close()` (RCU-deferred destruction).
fn rmmod(name: &str) -> Result<(), String> {
    for _ in 0..50 {
        if !loaded_modules().iter().any(|m| m == name) {
            return Ok(());
        }
        if Command::new("rmmod")
            .arg(name)
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false)
        {
            println!("+ rmmod {name}");
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Err(format!("rmmod {name}: still in use after 5 s"))
}

/// Removes `iface` and every module of both stacks that is loaded, so that
/// PF_CAN is free. Fails if a module stays.
pub fn unload_all(iface: &str) -> Result<(), String> {
    let loaded = loaded_modules();
    if !loaded
        .iter()
        .any(|m| m.starts_with("rcan_") || MAINLINE_MODULES.contains(&m.as_str()))
    {
        return Ok(());
    }
    // A vcan device must be deleted; rcan_loop's devices go with the module.
    run_quiet("ip", &["link", "set", iface, "down"]);
    if loaded.iter().any(|m| m == "vcan") {
        run_quiet("ip", &["link", "del", "dev", iface]);
    }
    let mut err = Ok(());
    let extra_ours = loaded
        .iter()
        .filter(|m| m.starts_with("rcan_") && !OURS_MODULES.contains(&m.as_str()))
        .map(String::as_str);
    for m in extra_ours
        .chain(OURS_MODULES.iter().copied())
        .chain(MAINLINE_MODULES.iter().copied())
    {
        if let Err(e) = rmmod(m) {
            err = Err(e);
        }
    }
    err
}

/// Loads `stack` and brings `iface` up. Call `unload_all` first.
pub fn load(stack: Stack, paths: &Paths, iface: &str) -> Result<(), String> {
    load_devices(stack, paths, &[iface])
}

/// Loads `stack` with one device per name in `ifaces` and brings them all
/// up. Mainline: one `ip link add dev NAME type vcan` each; ours:
/// `rcan_loop count=N`, whose devices are named `can0`, `can1`, ... by the
/// kernel, so `ifaces` must be those names (checked). Call `unload_all`
/// first.
pub fn load_devices(stack: Stack, paths: &Paths, ifaces: &[&str]) -> Result<(), String> {
    match stack {
        Stack::Mainline => {
            let kb = paths
                .kbuild
                .as_ref()
                .ok_or("RCAN_KBUILD is not set: cannot find the mainline modules (can.ko, can-raw.ko, vcan.ko)")?;
            insmod(&kb.join("net/can/can.ko"), &[])?;
            insmod(&kb.join("net/can/can-raw.ko"), &[])?;
            let vcan = kb.join("drivers/net/can/vcan.ko");
            if vcan_needs_can_dev(&vcan) {
                insmod(&kb.join("drivers/net/can/dev/can-dev.ko"), &[])?;
            }
            insmod(&vcan, &["echo=1"])?;
            for iface in ifaces {
                run("ip", &["link", "add", "dev", iface, "type", "vcan"])?;
            }
        }
        Stack::Ours => {
            if let Some((i, iface)) = ifaces
                .iter()
                .enumerate()
                .find(|(i, f)| **f != format!("can{i}"))
            {
                return Err(format!(
                    "rcan_loop names its devices can0, can1, ...: device {i} cannot be {iface}"
                ));
            }
            let r = &paths.root;
            insmod(&r.join("net/can/rcan_pf.ko"), &[])?;
            insmod(&r.join("net/can/rcan_can.ko"), &[])?;
            insmod(&r.join("net/can/rcan_raw.ko"), &[])?;
            let count = format!("count={}", ifaces.len());
            let params: &[&str] = if ifaces.len() > 1 { &[&count] } else { &[] };
            insmod(&r.join("drivers/net/can/rcan_loop.ko"), params)?;
        }
    }
    for iface in ifaces {
        run("ip", &["link", "set", iface, "up"])?;
    }
    Ok(())
}

/// `ip link set IFACE ARGS...` (the FD part: `mtu 72`, `down`, `up`).
pub fn set_link(iface: &str, args: &[&str]) -> Result<(), String> {
    let mut a = vec!["link", "set", iface];
    a.extend_from_slice(args);
    run("ip", &a)
}

/// Deletes the vcan device `iface`, if vcan is loaded (rcan_loop's
/// devices go with the module).
pub fn del_link(iface: &str) {
    if loaded_modules().iter().any(|m| m == "vcan") {
        run_quiet("ip", &["link", "del", "dev", iface]);
    }
}

/// The message protocols of the DSOR part (`--part dsor`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Proto {
    /// Mainline ISO-TP: `can.ko` + `can-isotp.ko` + `vcan.ko echo=1`,
    /// default socket options.
    Isotp,
    /// The same with `frame_txtime` 0: consecutive frames in a burst.
    IsotpNoGap,
    /// rcan DSOR: `rcan_pf` + `rcan_can` + `rcan_loop` + `rcan_dsor`.
    Dsor,
    /// The same with the interface at `mtu 72`: DSOR with 64-byte CAN FD
    /// bodies (dsor.rst, "CAN FD bodies").
    DsorFd,
}

impl fmt::Display for Proto {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Proto::Isotp => "ISO-TP",
            Proto::IsotpNoGap => "ISO-TP/0",
            Proto::Dsor => "DSOR",
            Proto::DsorFd => "DSOR-FD",
        })
    }
}

/// Module files `proto` needs, relative to the kernel build directory
/// (ISO-TP) or the project tree (DSOR).
fn proto_files(proto: Proto) -> &'static [&'static str] {
    match proto {
        Proto::Isotp | Proto::IsotpNoGap => &[
            "net/can/can.ko",
            "net/can/can-isotp.ko",
            "drivers/net/can/vcan.ko",
        ],
        Proto::Dsor | Proto::DsorFd => &[
            "net/can/rcan_pf.ko",
            "net/can/rcan_can.ko",
            "drivers/net/can/rcan_loop.ko",
            "net/can/dsor/rcan_dsor.ko",
        ],
    }
}

fn proto_dir(proto: Proto, paths: &Paths) -> Result<&Path, String> {
    match proto {
        Proto::Isotp | Proto::IsotpNoGap => paths
            .kbuild
            .as_deref()
            .ok_or_else(|| "RCAN_KBUILD is not set: cannot find can-isotp.ko".to_string()),
        Proto::Dsor | Proto::DsorFd => Ok(&paths.root),
    }
}

/// The first module file of `proto` that does not exist.
pub fn missing_proto_module(proto: Proto, paths: &Paths) -> Option<PathBuf> {
    let Ok(dir) = proto_dir(proto, paths) else {
        return Some(PathBuf::from("$RCAN_KBUILD/net/can/can-isotp.ko"));
    };
    proto_files(proto)
        .iter()
        .map(|f| dir.join(f))
        .find(|f| !f.is_file())
}

/// Loads the stack of `proto` on `iface` and brings it up. Call
/// `unload_all` first. ISO-TP: can, can-isotp, (can-dev,) `vcan echo=1`,
/// `ip link add IFACE type vcan`. DSOR: rcan_pf, rcan_can, rcan_loop
/// (creates can0), link up (DSOR-FD: `mtu 72` first), then `rcan_dsor
/// ifname=IFACE` (node 0).
pub fn load_proto(proto: Proto, paths: &Paths, iface: &str) -> Result<(), String> {
    let dir = proto_dir(proto, paths)?;
    match proto {
        Proto::Isotp | Proto::IsotpNoGap => {
            insmod(&dir.join("net/can/can.ko"), &[])?;
            insmod(&dir.join("net/can/can-isotp.ko"), &[])?;
            let vcan = dir.join("drivers/net/can/vcan.ko");
            if vcan_needs_can_dev(&vcan) {
                insmod(&dir.join("drivers/net/can/dev/can-dev.ko"), &[])?;
            }
            insmod(&vcan, &["echo=1"])?;
            run("ip", &["link", "add", "dev", iface, "type", "vcan"])?;
            run("ip", &["link", "set", iface, "up"])
        }
        Proto::Dsor | Proto::DsorFd => {
            insmod(&dir.join("net/can/rcan_pf.ko"), &[])?;
            insmod(&dir.join("net/can/rcan_can.ko"), &[])?;
            insmod(&dir.join("drivers/net/can/rcan_loop.ko"), &[])?;
            if proto == Proto::DsorFd {
                run("ip", &["link", "set", iface, "mtu", "72"])?;
            }
            run("ip", &["link", "set", iface, "up"])?;
            insmod(
                &dir.join("net/can/dsor/rcan_dsor.ko"),
                &[&format!("ifname={iface}")],
            )
        }
    }
}

/// Module files of the ISO-TP part (`--part isotp`) for `stack`, under
/// the kernel build directory (mainline) or the tree (ours).
fn isotp_files(stack: Stack) -> &'static [&'static str] {
    match stack {
        Stack::Mainline => &[
            "net/can/can.ko",
            "net/can/can-raw.ko",
            "net/can/can-isotp.ko",
            "drivers/net/can/vcan.ko",
        ],
        Stack::Ours => &[
            "net/can/rcan_pf.ko",
            "net/can/rcan_can.ko",
            "net/can/rcan_raw.ko",
            "drivers/net/can/rcan_loop.ko",
            "net/can/rcan_isotp.ko",
        ],
    }
}

/// The first module file of the ISO-TP part's `stack` that does not exist.
pub fn missing_isotp_module(stack: Stack, paths: &Paths) -> Option<PathBuf> {
    let dir = match stack {
        Stack::Mainline => match &paths.kbuild {
            Some(kb) => kb.as_path(),
            None => return Some(PathBuf::from("$RCAN_KBUILD/net/can/can-isotp.ko")),
        },
        Stack::Ours => &paths.root,
    };
    isotp_files(stack)
        .iter()
        .map(|f| dir.join(f))
        .find(|f| !f.is_file())
}

/// Loads the ISO-TP part's `stack` on `iface` at MTU 72 (CAN FD, which
/// also carries classic frames) and brings it up; both ISO-TP modules get
/// `max_pdu_size=MAX_PDU`. Mainline: can, can-raw, `can-isotp
/// max_pdu_size=N`, (can-dev,) `vcan echo=1`, `ip link add IFACE type
/// vcan`. Ours: rcan_pf, rcan_can, rcan_raw, rcan_loop (creates can0),
/// `rcan_isotp max_pdu_size=N`. The CAN_RAW modules serve the bus
/// listener of the spacing measurement. Call `unload_all` first.
pub fn load_isotp(stack: Stack, paths: &Paths, iface: &str, max_pdu: u32) -> Result<(), String> {
    let param = format!("max_pdu_size={max_pdu}");
    match stack {
        Stack::Mainline => {
            let kb = paths
                .kbuild
                .as_ref()
                .ok_or("RCAN_KBUILD is not set: cannot find can-isotp.ko")?;
            insmod(&kb.join("net/can/can.ko"), &[])?;
            insmod(&kb.join("net/can/can-raw.ko"), &[])?;
            insmod(&kb.join("net/can/can-isotp.ko"), &[&param])?;
            let vcan = kb.join("drivers/net/can/vcan.ko");
            if vcan_needs_can_dev(&vcan) {
                insmod(&kb.join("drivers/net/can/dev/can-dev.ko"), &[])?;
            }
            insmod(&vcan, &["echo=1"])?;
            run("ip", &["link", "add", "dev", iface, "type", "vcan"])?;
        }
        Stack::Ours => {
            let r = &paths.root;
            insmod(&r.join("net/can/rcan_pf.ko"), &[])?;
            insmod(&r.join("net/can/rcan_can.ko"), &[])?;
            insmod(&r.join("net/can/rcan_raw.ko"), &[])?;
            insmod(&r.join("drivers/net/can/rcan_loop.ko"), &[])?;
            insmod(&r.join("net/can/rcan_isotp.ko"), &[&param])?;
        }
    }
    run("ip", &["link", "set", iface, "mtu", "72"])?;
    run("ip", &["link", "set", iface, "up"])
}

/// Whether `vcan.ko`'s `depends=` names `can-dev` (it does when vcan uses
/// the shared skb helpers of the CAN device layer).
fn vcan_needs_can_dev(vcan: &Path) -> bool {
    Command::new("modinfo")
        .args(["-F", "depends"])
        .arg(vcan)
        .output()
        .map(|o| {
            String::from_utf8_lossy(&o.stdout)
                .split(',')
                .any(|d| d.trim() == "can-dev" || d.trim() == "can_dev")
        })
        .unwrap_or(false)
}

/// Does the module file for `stack` exist? (A quick check before booting
/// into a long run; `load` reports exactly what is missing.)
pub fn missing_module(stack: Stack, paths: &Paths) -> Option<PathBuf> {
    let files: Vec<PathBuf> = match stack {
        Stack::Mainline => match &paths.kbuild {
            Some(kb) => [
                "net/can/can.ko",
                "net/can/can-raw.ko",
                "drivers/net/can/vcan.ko",
            ]
            .iter()
            .map(|f| kb.join(f))
            .collect(),
            None => return Some(PathBuf::from("$RCAN_KBUILD/net/can/can.ko")),
        },
        Stack::Ours => [
            "net/can/rcan_pf.ko",
            "net/can/rcan_can.ko",
            "net/can/rcan_raw.ko",
            "drivers/net/can/rcan_loop.ko",
        ]
        .iter()
        .map(|f| paths.root.join(f))
        .collect(),
    };
    files.into_iter().find(|f| !f.is_file())
}
