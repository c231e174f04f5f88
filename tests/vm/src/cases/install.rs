// SPDX-License-Identifier: GPL-2.0
//! Installed like any kernel driver (issue 21): `make install` into the
//! VM's own `/lib/modules/$(uname -r)` and `/etc/modprobe.d`, then, with
//! nothing loaded, a plain `socket()` loads the stack and `modprobe` by a
//! card's PCI modalias loads its driver; `make uninstall` leaves nothing.
//!
//! The guest sees the host's root read-only, and the host has no
//! `/lib/modules` at all, so the test first gives the guest a writable
//! one: `/lib` (a symlink `usr/lib` on the guest's tmpfs root) becomes, for
//! the test, a tmpfs directory of symlinks into `/usr/lib` plus a real
//! `modules/`, which gets the test kernel's own modules (mainline CAN
//! among them, so that rcan.conf has something to win against) the way
//! the kernel's `modules_install` lays them out; a tmpfs is mounted on
//! `/etc/modprobe.d`. And the kernel's `request_module` runs
//! `/sbin/modprobe` in the root of the VM's init (its initramfs, where the
//! test command's root is `/newroot`), not in the chroot the test runs in:
//! for the test, `/proc/sys/kernel/modprobe` names a two-line script in
//! the initramfs that runs the real root's modprobe there, as a normal
//! system's kernel would. All of it is undone afterwards, also when the
//! test fails.

use std::fs;
use std::os::unix::fs::{symlink, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::test_table;
use crate::check::{ensure, wait_for, OrFail, TestResult, SETTLE};
use crate::ctx::Ctx;
use crate::sys;
use crate::tools::{spawn, Output};
use crate::Test;

pub const TESTS: &[Test] = test_table![install_autoload];

/// How long `make install` / `make uninstall` may take before the test
/// calls it hung (a kernel Makefile under TCG: 45-96 s on a quiet host,
/// 2-5 times that when the host is loaded; the bound is not a speed
/// requirement).
const MAKE_LIMIT: Duration = Duration::from_secs(600);

/// Where `make install` puts the tools (PREFIX): the guest's /usr/local is
/// the host's, read-only.
const PREFIX: &str = "/tmp/rcan-prefix";

/// Runs `bash -c script`; fails unless it exits 0.
fn sh(script: &str, limit: Duration) -> Result<Output, String> {
    let out = spawn("bash", &["-c", script], None)?.finish(limit)?;
    if !out.status.success() {
        return Err(format!(
            "`{script}`: {}: {} {}",
            out.status,
            out.stdout.trim(),
            out.stderr.trim()
        ));
    }
    Ok(out)
}

/// The names in /proc/modules.
fn loaded() -> Result<Vec<String>, String> {
    let s = fs::read_to_string("/proc/modules").or_fail("/proc/modules")?;
    Ok(s.lines()
        .filter_map(|l| l.split(' ').next().map(String::from))
        .collect())
}

/// Whether `m` is a CAN module of either stack: ours start with `rcan_`;
/// mainline's are `can`, `can_*`, `vcan`, `kvaser_pci`, `plx_pci`,
/// `sja1000`.
fn is_can_module(m: &str) -> bool {
    m.starts_with("rcan_")
        || m == "can"
        || m.starts_with("can_")
        || ["vcan", "kvaser_pci", "plx_pci", "sja1000"].contains(&m)
}

/// Unloads every loaded CAN module of both stacks (rmmod by system call,
/// which works without /lib/modules; a module still in use by another is
/// retried after that one is gone) and checks none is left.
fn unload_everything() -> TestResult {
    let mut left = Vec::new();
    wait_for(SETTLE, "every CAN module unloaded", || {
        left = loaded()?.into_iter().filter(|m| is_can_module(m)).collect();
        for m in &left {
            let _ = sys::delete_module(m);
        }
        Ok(left.is_empty().then_some(()))
    })
    .map_err(|e| format!("{e}: modules still loaded: {left:?}"))
}

/// The writable `/lib/modules` and `/etc/modprobe.d`; undone on drop.
struct Scratch {
    lib_swapped: bool,
    modprobe_d: bool,
    /// The kernel's modprobe path before the test.
    umh_modprobe: Option<String>,
}

/// The hand-over script, as the kernel sees it (the initramfs root) and
/// as this process reaches it (through init's root).
const UMH_SCRIPT: &str = "/rcan-modprobe";
const UMH_SCRIPT_HERE: &str = "/proc/1/root/rcan-modprobe";
const UMH_SYSCTL: &str = "/proc/sys/kernel/modprobe";

impl Scratch {
    /// Replaces the `/lib -> usr/lib` symlink by a directory of symlinks
    /// into `/usr/lib` with a real (tmpfs) `modules/`. Plain file system
    /// calls from this process, no program started between removing the
    /// link and completing the directory (programs need /lib to start).
    fn new() -> Result<Self, String> {
        let mut s = Scratch {
            lib_swapped: false,
            modprobe_d: false,
            umh_modprobe: None,
        };
        let lib = Path::new("/lib");
        let link = fs::read_link(lib).or_fail("readlink /lib (the guest's /lib is a symlink)")?;
        ensure!(
            link == Path::new("usr/lib"),
            "/lib -> {} (expected usr/lib)",
            link.display()
        );
        ensure!(
            !Path::new("/usr/lib/modules").exists(),
            "/usr/lib/modules exists on the host: this test expects none"
        );
        let entries: Vec<PathBuf> = fs::read_dir("/usr/lib")
            .or_fail("/usr/lib")?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        fs::remove_file(lib).or_fail("rm /lib")?;
        s.lib_swapped = true;
        fs::create_dir(lib).or_fail("mkdir /lib")?;
        for e in &entries {
            let name = e.file_name().expect("entries of a directory have names");
            symlink(e, lib.join(name)).or_fail(format!("ln -s {}", e.display()))?;
        }
        fs::create_dir(lib.join("modules")).or_fail("mkdir /lib/modules")?;
        sh("mount -t tmpfs tmpfs /lib/modules", MAKE_LIMIT)?;
        sh("mount -t tmpfs tmpfs /etc/modprobe.d", MAKE_LIMIT)?;
        s.modprobe_d = true;
        ensure!(
            Path::new("/proc/1/root/newroot").is_dir(),
            "init's root has no /newroot (tools/testing/rcan/vm/init changed?)"
        );
        fs::write(
            UMH_SCRIPT_HERE,
            "#!/bin/sh\nexec chroot /newroot /sbin/modprobe \"$@\"\n",
        )
        .or_fail(UMH_SCRIPT_HERE)?;
        fs::set_permissions(UMH_SCRIPT_HERE, fs::Permissions::from_mode(0o755))
            .or_fail(UMH_SCRIPT_HERE)?;
        let old = fs::read_to_string(UMH_SYSCTL).or_fail(UMH_SYSCTL)?;
        s.umh_modprobe = Some(old.trim().to_string());
        fs::write(UMH_SYSCTL, UMH_SCRIPT).or_fail(UMH_SYSCTL)?;
        Ok(s)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Some(old) = self.umh_modprobe.take() {
            let _ = fs::write(UMH_SYSCTL, old);
        }
        let _ = fs::remove_file(UMH_SCRIPT_HERE);
        if self.modprobe_d {
            let _ = sh("umount /etc/modprobe.d", MAKE_LIMIT);
        }
        if self.lib_swapped {
            let _ = sh("umount /lib/modules", MAKE_LIMIT);
            // Back to the symlink, again without starting a program
            // while /lib is missing.
            let lib = Path::new("/lib");
            if let Ok(entries) = fs::read_dir(lib) {
                for e in entries.flatten() {
                    let p = e.path();
                    let _ = if p.is_symlink() {
                        fs::remove_file(&p)
                    } else {
                        fs::remove_dir_all(&p)
                    };
                }
            }
            let _ = fs::remove_dir(lib);
            let _ = symlink("usr/lib", lib);
        }
    }
}

/// Copies the test kernel's own modules into `/lib/modules/KVER/kernel/`
/// as its `modules_install` would (with its modules.order and
/// modules.builtin*), so depmod and modprobe see a complete kernel.
fn install_kernel_modules(kbuild: &Path, kver: &str) -> TestResult {
    let dst = Path::new("/lib/modules").join(kver);
    fs::create_dir_all(dst.join("kernel")).or_fail("mkdir /lib/modules/KVER/kernel")?;
    let order = fs::read_to_string(kbuild.join("modules.order")).or_fail("modules.order")?;
    let mut installed = String::new();
    for o in order.lines().filter(|l| !l.is_empty()) {
        let ko = format!("{}.ko", o.trim_end_matches(".o"));
        let to = dst.join("kernel").join(&ko);
        fs::create_dir_all(to.parent().expect("has a parent")).or_fail(to.display())?;
        fs::copy(kbuild.join(&ko), &to).or_fail(format!("cp {ko}"))?;
        installed.push_str(&format!("kernel/{ko}\n"));
    }
    fs::write(dst.join("modules.order"), installed).or_fail("modules.order")?;
    for f in ["modules.builtin", "modules.builtin.modinfo"] {
        fs::copy(kbuild.join(f), dst.join(f)).or_fail(f)?;
    }
    Ok(())
}

/// Every file below `dir`, sorted (empty if `dir` is missing).
fn files_below(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        let Ok(rd) = fs::read_dir(&d) else { continue };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() && !p.is_symlink() {
                out.push(format!("{}/", p.display()));
                todo.push(p);
            } else {
                out.push(p.display().to_string());
            }
        }
    }
    out.sort();
    out
}

/// `make install`, then: socket() autoloads rcan_pf and the protocol's
/// module for CAN_RAW, CANPROTO_CAN and CANPROTO_DSOR, never mainline's
/// can.ko (rcan.conf); `modprobe` of each emulated card's PCI modalias
/// loads our front-end (not mainline's kvaser_pci) and can0 appears;
/// `modinfo` shows the pci: aliases; `make uninstall` removes every file
/// it installed and depmod forgets our aliases.
fn install_autoload(ctx: &mut Ctx) -> TestResult {
    let kbuild = ctx
        .kbuild()
        .ok_or("needs the kernel build directory (RCAN_KBUILD or --kbuild)")?
        .to_path_buf();
    let root = ctx.root().to_path_buf();
    let kver = fs::read_to_string("/proc/sys/kernel/osrelease").or_fail("osrelease")?;
    let kver = kver.trim();
    // Where the test's time goes, one note line at the end (the test took
    // 30 to 43 s in fresh-clone runs, with the host's load).
    let mut laps: Vec<String> = Vec::new();
    let mut t = Instant::now();
    let mut lap = |what: &str| {
        laps.push(format!("{what} {:.1} s", t.elapsed().as_secs_f64()));
        t = Instant::now();
    };
    unload_everything()?;

    let _scratch = Scratch::new()?;
    install_kernel_modules(&kbuild, kver)?;
    let before_lib = files_below(Path::new("/lib/modules"));
    lap("scratch and kernel modules");

    // What the user types (as root, after `make`).
    let out = sh(
        &format!(
            "make -C {} install KDIR={} PREFIX={PREFIX}",
            root.display(),
            kbuild.display()
        ),
        MAKE_LIMIT,
    )?;
    lap("make install");
    ctx.note(out.stdout.lines().last().unwrap_or(""));
    let conf = fs::read_to_string("/etc/modprobe.d/rcan.conf").or_fail("rcan.conf")?;
    ensure!(
        conf.lines().any(|l| l.trim() == "alias net-pf-29 rcan_pf"),
        "rcan.conf has no 'alias net-pf-29 rcan_pf'"
    );
    let modinfo = sh("modinfo rcan_kvaser_pci", MAKE_LIMIT)?.stdout;
    ensure!(
        modinfo
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>()
                == ["alias:", "pci:v000010E8d00008406sv*sd*bc*sc*i*"]),
        "modinfo rcan_kvaser_pci shows no pci:v000010E8d00008406 alias: {modinfo}"
    );

    lap("modinfo");
    // Autoload by socket, from nothing loaded.
    // The test's own socket() (python3's took 4 s a start on the debug
    // kernel): the kernel's request_module is the same whoever calls.
    for (ty, proto, module) in [
        ("SOCK_RAW", 1, "rcan_raw"),
        ("SOCK_DGRAM", 2, "rcan_bcm"),
        ("SOCK_DGRAM", 6, "rcan_isotp"),
        ("SOCK_DGRAM", 7, "rcan_j1939"),
        ("SOCK_RAW", 16, "rcan_can"),
        ("SOCK_DGRAM", 17, "rcan_dsor"),
    ] {
        unload_everything()?;
        let sock_type = if ty == "SOCK_RAW" {
            libc::SOCK_RAW
        } else {
            libc::SOCK_DGRAM
        };
        drop(
            sys::socket(29, sock_type, proto)
                .map_err(|e| format!("socket(29, {ty}, {proto}): {e}"))?,
        );
        let mods = loaded()?;
        ensure!(
            mods.iter().any(|m| m == "rcan_pf") && mods.iter().any(|m| m == module),
            "after socket(29, {ty}, {proto}): rcan_pf and {module} not both loaded: {mods:?}"
        );
        ensure!(
            !mods.iter().any(|m| m == "can" || m.starts_with("can_")),
            "after socket(29, {ty}, {proto}): mainline modules loaded: {mods:?}"
        );
    }

    lap("autoload by socket");
    // Autoload by device: what udev does for each PCI device.
    unload_everything()?;
    let cards = sh(
        "grep -l -e 0x10e8 -e 0x13fe /sys/bus/pci/devices/*/vendor | xargs -n1 dirname",
        MAKE_LIMIT,
    )?
    .stdout;
    let cards: Vec<&str> = cards.lines().collect();
    ensure!(
        !cards.is_empty(),
        "no emulated Kvaser or Advantech card (RCAN_QEMU_CAN)"
    );
    for c in &cards {
        sh(&format!("modprobe $(cat {c}/modalias)"), MAKE_LIMIT)?;
    }
    let mods = loaded()?;
    ensure!(
        mods.iter().any(|m| m == "rcan_kvaser_pci"),
        "modprobe by modalias did not load rcan_kvaser_pci: {mods:?}"
    );
    ensure!(
        !mods.iter().any(|m| m == "kvaser_pci" || m == "can"),
        "mainline modules loaded by modalias: {mods:?}"
    );
    // Bound to our driver (mainline's would have bound them otherwise)
    // and registered: can0 appears.
    let bound: Vec<String> = fs::read_dir("/sys/bus/pci/drivers/rcan_kvaser_pci")
        .or_fail("/sys/bus/pci/drivers/rcan_kvaser_pci")?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("0000:"))
        .collect();
    ensure!(!bound.is_empty(), "no card bound to rcan_kvaser_pci");
    ensure!(
        Path::new("/sys/class/net/can0").exists(),
        "no can0 after modprobe by modalias"
    );
    unload_everything()?;
    lap("autoload by modalias");

    // Uninstall leaves what was there before, and nothing in PREFIX or
    // /etc/modprobe.d.
    sh(
        &format!("make -C {} uninstall PREFIX={PREFIX}", root.display()),
        MAKE_LIMIT,
    )?;
    let left_prefix = files_below(Path::new(PREFIX));
    ensure!(left_prefix.is_empty(), "left in {PREFIX}: {left_prefix:?}");
    let left_conf = files_below(Path::new("/etc/modprobe.d"));
    ensure!(
        left_conf.is_empty(),
        "left in /etc/modprobe.d: {left_conf:?}"
    );
    let after_lib: Vec<String> = files_below(Path::new("/lib/modules"))
        .into_iter()
        .filter(|p| !before_lib.contains(p))
        .filter(|p| {
            !Path::new(p)
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("modules."))
        })
        .collect();
    ensure!(after_lib.is_empty(), "left in /lib/modules: {after_lib:?}");
    let aliases = fs::read_to_string(format!("/lib/modules/{kver}/modules.alias"))
        .or_fail("modules.alias")?;
    ensure!(
        !aliases.contains("rcan"),
        "modules.alias still names rcan modules after uninstall"
    );
    lap("make uninstall");
    ctx.note(format!("time: {}", laps.join(", ")));
    Ok(())
}
