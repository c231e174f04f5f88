// SPDX-License-Identifier: GPL-2.0
//! [`Ctx`]: what a test needs from its environment — loading and unloading
//! the rcan modules (or, for the CAN_RAW tests, mainline SocketCAN's),
//! interface state, sysfs counters, the kernel log, and sockets with sane
//! timeouts.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::thread;
use std::time::{Duration, Instant};

use rcan_uapi::ArbSocket;

use crate::check::{OrFail, RX_TIMEOUT};
use crate::sys;

/// Which CAN stack the suite runs against.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Stack {
    /// The rcan modules: every test.
    Ours,
    /// Mainline SocketCAN (`can.ko`, `can-raw.ko`, `vcan.ko` of the test
    /// kernel): only the tests marked portable, which shows that they
    /// encode mainline behaviour.
    Mainline,
}

impl Stack {
    /// Parses `ours` or `mainline`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "ours" => Ok(Stack::Ours),
            "mainline" => Ok(Stack::Mainline),
            _ => Err(format!("unknown stack {s:?} (ours or mainline)")),
        }
    }

    /// The name [`Stack::parse`] takes.
    pub fn name(self) -> &'static str {
        match self {
            Stack::Ours => "ours",
            Stack::Mainline => "mainline",
        }
    }
}

/// What a test uses of the machine, declared in its table
/// (`test_table![own; stack: shared]` in `cases`). The runner shares what
/// it may: loading the stack costs more than most tests on the debug
/// kernel (some 3 s of KASAN-checked module loading and unloading under
/// TCG, against 0.2-0.4 s of test).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Uses {
    /// Modules of its own: the runner unloads everything before and after
    /// it. Every test whose subject is loading, unloading, module
    /// parameters or a driver, and every test that leaves something behind
    /// on purpose.
    Own,
    /// The loaded stack: [`Module::SHARED`] (rcan_pf, rcan_can, rcan_raw,
    /// rcan_bcm, rcan_isotp, rcan_j1939, and rcan_loop with no parameter but `count=N`), loaded
    /// through [`Ctx::load_stack`], [`Ctx::can_ifaces`], [`Ctx::bcm_ifaces`]
    /// or [`Ctx::insmod`]. On our stack the runner keeps those modules
    /// loaded from one such test to the next, when the test left them as
    /// it found them ([`Ctx::end`]); a different `count=` reloads rcan_loop
    /// only. Such a test may not unload anything nor load anything else:
    /// [`Ctx`] refuses, so the declaration is checked, not trusted. On
    /// mainline every test is run as [`Uses::Own`].
    Stack,
}

/// One of the rcan kernel modules.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Module {
    /// Protocol family PF_CAN (`net/can/rcan_pf.ko`).
    Pf,
    /// CANPROTO_CAN (`net/can/rcan_can.ko`).
    Can,
    /// SocketCAN-compatible CAN_RAW (`net/can/rcan_raw.ko`).
    Raw,
    /// SocketCAN-compatible CAN_BCM (`net/can/rcan_bcm.ko`).
    Bcm,
    /// SocketCAN-compatible CAN_ISOTP (`net/can/rcan_isotp.ko`).
    Isotp,
    /// SocketCAN-compatible CAN_J1939 (`net/can/rcan_j1939.ko`).
    J1939,
    /// Loopback driver (`drivers/net/can/rcan_loop.ko`).
    Loop,
    /// DSOR time service (`net/can/dsor/rcan_time.ko`).
    Time,
    /// Redundant DSOR time service (`net/can/dsor/rcan_rtime.ko`).
    Rtime,
    /// DSOR protocol and canip0 (`net/can/dsor/rcan_dsor.ko`).
    Dsor,
    /// The CAN device layer, link kind "can" (`drivers/net/can/dev/rcan_dev.ko`):
    /// the SJA1000 front-ends need it ([`Ctx::insmod`] loads it first).
    Dev,
    /// SJA1000 front-end for Kvaser PCIcan cards.
    Kvaser,
    /// SJA1000 front-end for Advantech PCM-3680I / MIOe-3680 cards.
    Advantech,
    /// SJA1000 front-end for memory-mapped ISA cards.
    Isa,
    /// SJA1000 front-end for PEAK PCAN-PCI cards.
    Pcan,
    /// SJA1000 front-end for TS-CAN1 PC/104 boards.
    Tscan1,
    /// Simulated Intel 82527 cards on a simulated bus.
    I82527Sim,
    /// Intel 82527 front-end for memory-mapped ISA cards.
    I82527Isa,
    /// Simulated SJA1000 cards on a simulated bus, with fault injection.
    Sja1000Sim,
    /// CTU CAN FD driver for the CTU CAN FD PCI card (QEMU `ctucan_pci`).
    CtuCanFdPci,
    /// Simulated CTU CAN FD cores on a simulated bus, with fault injection.
    CtuCanFdSim,
}

impl Module {
    /// Load order; unload in reverse.
    pub const ALL: [Module; 21] = [
        Module::Pf,
        Module::Can,
        Module::Raw,
        Module::Bcm,
        Module::Isotp,
        Module::J1939,
        Module::Loop,
        Module::Time,
        Module::Rtime,
        Module::Dsor,
        Module::Dev,
        Module::Kvaser,
        Module::Advantech,
        Module::Isa,
        Module::Pcan,
        Module::Tscan1,
        Module::I82527Sim,
        Module::I82527Isa,
        Module::Sja1000Sim,
        Module::CtuCanFdPci,
        Module::CtuCanFdSim,
    ];

    /// The modules a [`Uses::Stack`] test may load, in load order.
    pub const SHARED: [Module; 7] = [
        Module::Pf,
        Module::Can,
        Module::Raw,
        Module::Bcm,
        Module::Isotp,
        Module::J1939,
        Module::Loop,
    ];

    /// Name as shown by `/proc/modules` and taken by `rmmod`.
    pub fn name(self) -> &'static str {
        match self {
            Module::Pf => "rcan_pf",
            Module::Can => "rcan_can",
            Module::Raw => "rcan_raw",
            Module::Bcm => "rcan_bcm",
            Module::Isotp => "rcan_isotp",
            Module::J1939 => "rcan_j1939",
            Module::Loop => "rcan_loop",
            Module::Time => "rcan_time",
            Module::Rtime => "rcan_rtime",
            Module::Dsor => "rcan_dsor",
            Module::Dev => "rcan_dev",
            Module::Kvaser => "rcan_kvaser_pci",
            Module::Advantech => "rcan_advantech_pci",
            Module::Isa => "rcan_sja1000_isa",
            Module::Pcan => "rcan_pcan_pci",
            Module::Tscan1 => "rcan_tscan1",
            Module::I82527Sim => "rcan_i82527_sim",
            Module::I82527Isa => "rcan_i82527_isa",
            Module::Sja1000Sim => "rcan_sja1000_sim",
            Module::CtuCanFdPci => "rcan_ctucanfd_pci",
            Module::CtuCanFdSim => "rcan_ctucanfd_sim",
        }
    }

    /// Path of the `.ko` relative to the repository root.
    pub fn rel_path(self) -> &'static str {
        match self {
            Module::Pf => "net/can/rcan_pf.ko",
            Module::Can => "net/can/rcan_can.ko",
            Module::Raw => "net/can/rcan_raw.ko",
            Module::Bcm => "net/can/rcan_bcm.ko",
            Module::Isotp => "net/can/rcan_isotp.ko",
            Module::J1939 => "net/can/rcan_j1939.ko",
            Module::Loop => "drivers/net/can/rcan_loop.ko",
            Module::Time => "net/can/dsor/rcan_time.ko",
            Module::Rtime => "net/can/dsor/rcan_rtime.ko",
            Module::Dsor => "net/can/dsor/rcan_dsor.ko",
            Module::Dev => "drivers/net/can/dev/rcan_dev.ko",
            Module::Kvaser => "drivers/net/can/sja1000/rcan_kvaser_pci.ko",
            Module::Advantech => "drivers/net/can/sja1000/rcan_advantech_pci.ko",
            Module::Isa => "drivers/net/can/sja1000/rcan_sja1000_isa.ko",
            Module::Pcan => "drivers/net/can/sja1000/rcan_pcan_pci.ko",
            Module::Tscan1 => "drivers/net/can/sja1000/rcan_tscan1.ko",
            Module::I82527Sim => "drivers/net/can/i82527/rcan_i82527_sim.ko",
            Module::I82527Isa => "drivers/net/can/i82527/rcan_i82527_isa.ko",
            Module::Sja1000Sim => "drivers/net/can/sja1000/rcan_sja1000_sim.ko",
            Module::CtuCanFdPci => "drivers/net/can/ctucanfd/rcan_ctucanfd_pci.ko",
            Module::CtuCanFdSim => "drivers/net/can/ctucanfd/rcan_ctucanfd_sim.ko",
        }
    }
}

/// One of the mainline SocketCAN modules the test kernel builds.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Mainline {
    /// PF_CAN core (`net/can/can.ko`).
    Can,
    /// CAN_RAW (`net/can/can-raw.ko`).
    Raw,
    /// CAN device infrastructure (`drivers/net/can/dev/can-dev.ko`): vcan
    /// needs its `can_dropped_invalid_skb`.
    Dev,
    /// Virtual CAN driver (`drivers/net/can/vcan.ko`).
    Vcan,
    /// Broadcast manager (`net/can/can-bcm.ko`): not in [`Mainline::ALL`],
    /// loaded only by [`Ctx::bcm_ifaces`].
    Bcm,
    /// ISO-TP (`net/can/can-isotp.ko`): not in [`Mainline::ALL`], loaded
    /// only by [`Ctx::isotp_ifaces`].
    Isotp,
    /// SAE J1939 (`net/can/j1939/can-j1939.ko`): not in
    /// [`Mainline::ALL`], loaded only by [`Ctx::j1939_ifaces`].
    J1939,
    /// SJA1000 core (`drivers/net/can/sja1000/sja1000.ko`): not in
    /// [`Mainline::ALL`], loaded only by [`Ctx::sja1000_cards`].
    Sja1000,
    /// Kvaser PCIcan front-end (`drivers/net/can/sja1000/kvaser_pci.ko`),
    /// likewise.
    KvaserPci,
    /// CTU CAN FD core (`drivers/net/can/ctucanfd/ctucanfd.ko`): not in
    /// [`Mainline::ALL`], loaded only by [`Ctx::ctucan_cards`].
    CtuCanFd,
    /// Its PCI front-end (`ctucanfd_pci.ko`), likewise.
    CtuCanFdPci,
}

impl Mainline {
    /// Load order (insmod resolves no dependencies); unload in reverse.
    pub const ALL: [Mainline; 4] = [Mainline::Can, Mainline::Raw, Mainline::Dev, Mainline::Vcan];

    /// Name as shown by `/proc/modules` (dashes become underscores).
    pub fn name(self) -> &'static str {
        match self {
            Mainline::Can => "can",
            Mainline::Raw => "can_raw",
            Mainline::Dev => "can_dev",
            Mainline::Vcan => "vcan",
            Mainline::Bcm => "can_bcm",
            Mainline::Isotp => "can_isotp",
            Mainline::J1939 => "can_j1939",
            Mainline::Sja1000 => "sja1000",
            Mainline::KvaserPci => "kvaser_pci",
            Mainline::CtuCanFd => "ctucanfd",
            Mainline::CtuCanFdPci => "ctucanfd_pci",
        }
    }

    /// Path of the `.ko` relative to the kernel build directory.
    pub fn rel_path(self) -> &'static str {
        match self {
            Mainline::Can => "net/can/can.ko",
            Mainline::Raw => "net/can/can-raw.ko",
            Mainline::Dev => "drivers/net/can/dev/can-dev.ko",
            Mainline::Vcan => "drivers/net/can/vcan.ko",
            Mainline::Bcm => "net/can/can-bcm.ko",
            Mainline::Isotp => "net/can/can-isotp.ko",
            Mainline::J1939 => "net/can/j1939/can-j1939.ko",
            Mainline::Sja1000 => "drivers/net/can/sja1000/sja1000.ko",
            Mainline::KvaserPci => "drivers/net/can/sja1000/kvaser_pci.ko",
            Mainline::CtuCanFd => "drivers/net/can/ctucanfd/ctucanfd.ko",
            Mainline::CtuCanFdPci => "drivers/net/can/ctucanfd/ctucanfd_pci.ko",
        }
    }
}

/// The test-only module `rcan_exittest` (`tools/testing/rcan/exitmod`,
/// which `make modules` builds in a Kbuild run of its own and `make
/// install` never installs): it forgets one registration of each kind the
/// glue's module exit sweeps (issue 39). Not a [`Module`]: only
/// `teardown_exit_sweeps` loads it ([`Ctx::insmod_exittest`]), and
/// [`Ctx::unload_all`] unloads it first.
pub const EXITTEST: &str = "rcan_exittest";
/// Its `.ko`, relative to the repository root.
pub const EXITTEST_KO: &str = "tools/testing/rcan/exitmod/rcan_exittest.ko";

/// The test-only module `rcan_abiskew` (built beside [`EXITTEST`]):
/// `rcan_exittest` built for another ABI version; only
/// `module_abi_mismatch` tries to load it ([`Ctx::insmod_abiskew`]).
pub const ABISKEW: &str = "rcan_abiskew";
/// Its `.ko`, relative to the repository root.
pub const ABISKEW_KO: &str = "tools/testing/rcan/exitmod/rcan_abiskew.ko";

/// The test-only module `rcan_iomemkeep` (built beside [`EXITTEST`]): a
/// PCI driver, bound by `driver_override` only, that keeps its register
/// window and its enable past `remove` and uses the window at exit
/// (issue 39, "A mapping past its binding"); only
/// `sja1000_kvaser_iomem_revoked` loads it ([`Ctx::insmod_iomemkeep`]),
/// and [`Ctx::unload_all`] unloads it.
pub const IOMEMKEEP: &str = "rcan_iomemkeep";
/// Its `.ko`, relative to the repository root.
pub const IOMEMKEEP_KO: &str = "tools/testing/rcan/exitmod/rcan_iomemkeep.ko";

/// Test context: where the modules are and the state of the loaded stack.
pub struct Ctx {
    root: PathBuf,
    stack: Stack,
    /// Kernel build directory holding the mainline modules.
    kbuild: Option<PathBuf>,
    /// Number of canN devices of the loaded rcan_loop (0: not loaded).
    ndev: usize,
    /// vcan interfaces created by [`Ctx::can_ifaces`] on mainline.
    vcans: Vec<String>,
    /// What the running test declared ([`Ctx::begin`]).
    uses: Uses,
    /// The canN devices and rcan_loop's parameters as [`Ctx::load_stack`]
    /// left them after loading rcan_loop ([`loop_state`]): what a
    /// [`Uses::Stack`] test must leave for the next one. None while
    /// rcan_loop is not loaded, or was loaded otherwise.
    loop_state: Option<String>,
    /// [`Uses::Stack`] tests run so far, and how many of them found the
    /// shared stack loaded ([`Ctx::shared_runs`]).
    stack_tests: usize,
    kept: usize,
    /// The last [`Ctx::end`] failed: modules may be left loaded or in use.
    dirty: bool,
}

impl Ctx {
    /// A context for the rcan modules under `root`, running against
    /// `stack`; `kbuild` is the kernel build directory (mainline only).
    pub fn new(root: PathBuf, stack: Stack, kbuild: Option<PathBuf>) -> Self {
        Self {
            root,
            stack,
            kbuild,
            ndev: 0,
            vcans: Vec::new(),
            uses: Uses::Own,
            loop_state: None,
            stack_tests: 0,
            kept: 0,
            dirty: false,
        }
    }

    /// The repository root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The stack under test.
    pub fn stack(&self) -> Stack {
        self.stack
    }

    /// The kernel build directory with the mainline modules, if given.
    pub fn kbuild(&self) -> Option<&Path> {
        self.kbuild.as_deref()
    }

    /// Absolute path of mainline module `m` (None: no kernel build
    /// directory given).
    pub fn mainline_ko(&self, m: Mainline) -> Option<PathBuf> {
        self.kbuild.as_ref().map(|k| k.join(m.rel_path()))
    }

    /// Whether `net/can/rcan_raw.ko` has been built. While it has not, the
    /// stack loads without it and only the CAN_RAW tests fail.
    pub fn have_raw(&self) -> bool {
        self.ko(Module::Raw).is_file()
    }

    /// Absolute path of module `m`.
    pub fn ko(&self, m: Module) -> PathBuf {
        self.root.join(m.rel_path())
    }

    /// `insmod` module `m` with `params`. A hardware driver (SJA1000,
    /// 82527, CTU CAN FD) needs `rcan_dev` (the "can" link kind its
    /// devices use): it is loaded first if it is not, as modprobe would.
    ///
    /// In a [`Uses::Stack`] test, a module of [`Module::SHARED`] that is
    /// loaded already (kept from an earlier test) is left as it is, except
    /// rcan_loop with another `count=`, which is reloaded; any other module
    /// or parameter is refused.
    pub fn insmod(&mut self, m: Module, params: &[&str]) -> Result<(), String> {
        if self.uses == Uses::Stack {
            let count_only = params.iter().all(|p| p.starts_with("count="));
            if !Module::SHARED.contains(&m)
                || !(params.is_empty() || m == Module::Loop && count_only)
            {
                return Err(format!(
                    "insmod {} {}: a test declared Uses::Stack loads only the shared stack \
                     (declare it Uses::Own)",
                    m.name(),
                    params.join(" ")
                ));
            }
            if self.is_loaded(m) {
                if m != Module::Loop || self.ndev == loop_count(params) {
                    return Ok(());
                }
                rmmod_retrying(m.name())?;
                self.ndev = 0;
                self.loop_state = None;
            }
        }
        let needs_dev = [
            Module::Kvaser,
            Module::Advantech,
            Module::Isa,
            Module::Pcan,
            Module::Tscan1,
            Module::Sja1000Sim,
            Module::I82527Sim,
            Module::I82527Isa,
            Module::CtuCanFdPci,
            Module::CtuCanFdSim,
        ];
        if needs_dev.contains(&m) && !self.is_loaded(Module::Dev) {
            self.insmod(Module::Dev, &[])?;
        }
        let ko = self.ko(m);
        sys::finit_module(&ko, params)
            .map_err(|e| format!("insmod {} {}: {e}", ko.display(), params.join(" ")))
            .map_err(|e| {
                if m == Module::Pf && module_listed("can") {
                    format!("{e} (mainline can.ko is loaded and owns PF_CAN: rmmod it)")
                } else {
                    e
                }
            })?;
        if m == Module::Loop {
            self.ndev = loop_count(params);
        }
        Ok(())
    }

    /// `insmod` the test-only module [`EXITTEST`] (after rcan_pf).
    pub fn insmod_exittest(&mut self) -> Result<(), String> {
        self.own("insmod", EXITTEST)?;
        let ko = self.root.join(EXITTEST_KO);
        sys::finit_module(&ko, &[]).map_err(|e| format!("insmod {}: {e}", ko.display()))
    }

    /// Tries to `insmod` the test-only module [`ABISKEW`] (after
    /// rcan_pf): the loader's error, as the caller expects one.
    pub fn insmod_abiskew(&mut self) -> Result<std::io::Result<()>, String> {
        self.own("insmod", ABISKEW)?;
        Ok(sys::finit_module(&self.root.join(ABISKEW_KO), &[]))
    }

    /// `insmod` the test-only module [`IOMEMKEEP`].
    pub fn insmod_iomemkeep(&mut self) -> Result<(), String> {
        self.own("insmod", IOMEMKEEP)?;
        let ko = self.root.join(IOMEMKEEP_KO);
        sys::finit_module(&ko, &[]).map_err(|e| format!("insmod {}: {e}", ko.display()))
    }

    /// `rmmod` the test-only module [`IOMEMKEEP`] (no retries).
    pub fn rmmod_iomemkeep(&mut self) -> Result<(), String> {
        self.own("rmmod", IOMEMKEEP)?;
        rmmod(IOMEMKEEP)
    }

    /// `rmmod` the test-only module [`EXITTEST`] (no retries).
    pub fn rmmod_exittest(&mut self) -> Result<(), String> {
        self.own("rmmod", EXITTEST)?;
        rmmod(EXITTEST)
    }

    /// `rmmod` module `m` (no retries).
    pub fn rmmod(&mut self, m: Module) -> Result<(), String> {
        self.own("rmmod", m.name())?;
        rmmod(m.name())?;
        if m == Module::Loop {
            self.ndev = 0;
            self.loop_state = None;
        }
        Ok(())
    }

    /// Refuses `what` in a [`Uses::Stack`] test: it unloads part of the
    /// shared stack.
    fn own(&self, what: &str, arg: &str) -> Result<(), String> {
        match self.uses {
            Uses::Own => Ok(()),
            Uses::Stack => Err(format!(
                "{what} {arg}: a test declared Uses::Stack may not unload the shared stack \
                 (declare it Uses::Own)"
            )),
        }
    }

    /// Before a test that declared `uses`: on mainline, or for a
    /// [`Uses::Own`] test, unloads whatever is loaded (an earlier test's
    /// leftovers: its error). A [`Uses::Stack`] test on our stack finds
    /// the shared stack as the last such test left it, or nothing.
    pub fn begin(&mut self, uses: Uses) -> Result<(), String> {
        self.uses = Uses::Own;
        let dirty = std::mem::take(&mut self.dirty);
        if uses == Uses::Own || self.stack == Stack::Mainline || !sharing() || dirty {
            return self.unload_all();
        }
        self.uses = Uses::Stack;
        self.stack_tests += 1;
        if self.is_loaded(Module::Pf) {
            self.kept += 1;
        }
        Ok(())
    }

    /// How many [`Uses::Stack`] tests ran, and how many of them found the
    /// shared stack kept loaded by the test before.
    pub fn shared_runs(&self) -> (usize, usize) {
        (self.stack_tests, self.kept)
    }

    /// After a test (`passed` or not): unloads everything, except after a
    /// passed [`Uses::Stack`] test that left the shared stack as it found
    /// it, which keeps it for the next. Fails (the test's fault) if the
    /// test left a module in use: a socket it did not close, a thread or
    /// program still holding one, past a 10 s grace for late releases.
    /// State a test may change on purpose (a link down, an MTU, a loaded
    /// module outside the shared set) is not a failure: the stack is then
    /// reloaded for the next test.
    pub fn end(&mut self, passed: bool) -> Result<(), String> {
        let r = self.end_test(passed);
        // What is left after a failed clean-up is the next test's
        // "leftover": it unloads first, whatever it declared.
        self.dirty = r.is_err();
        r
    }

    fn end_test(&mut self, passed: bool) -> Result<(), String> {
        let shared = std::mem::replace(&mut self.uses, Uses::Own) == Uses::Stack;
        if !(shared && passed) {
            return self.unload_all();
        }
        let idle = wait_idle(&Module::SHARED);
        if let Err(e) = idle {
            return Err(match self.unload_all() {
                Ok(()) => e,
                Err(u) => format!("{e}; {u}"),
            });
        }
        let only_shared = Module::ALL
            .into_iter()
            .all(|m| Module::SHARED.contains(&m) || !self.is_loaded(m));
        let as_found = self.loop_state.is_some() && self.loop_state == loop_state(self.ndev);
        if only_shared && as_found {
            Ok(())
        } else {
            self.unload_all()
        }
    }

    /// Whether module `m` is loaded (listed in `/proc/modules`).
    pub fn is_loaded(&self, m: Module) -> bool {
        module_listed(m.name())
    }

    /// Loads rcan_pf, rcan_can, rcan_raw (if built, see
    /// [`Ctx::have_raw`]) and rcan_loop (with `loop_params`, e.g.
    /// `["count=2"]`) and sets every canN device up.
    pub fn load_stack(&mut self, loop_params: &[&str]) -> Result<(), String> {
        self.insmod(Module::Pf, &[])?;
        self.insmod(Module::Can, &[])?;
        if self.have_raw() {
            self.insmod(Module::Raw, &[])?;
        }
        let fresh = !self.is_loaded(Module::Loop) || self.ndev != loop_count(loop_params);
        self.insmod(Module::Loop, loop_params)?;
        self.links_up()?;
        if fresh {
            self.loop_state = loop_state(self.ndev);
        }
        Ok(())
    }

    /// Loads the stack under test with CAN_RAW and `n` interfaces can0..,
    /// all up, that reflect frames sent with loopback into their receive
    /// path; returns their ifindexes. Ours: [`Ctx::load_stack`] with
    /// `count=n`. Mainline: can, can-raw, can-dev, `vcan echo=1` and
    /// `ip link add canI type vcan`, MTU 16 (classic CAN).
    pub fn can_ifaces(&mut self, n: usize) -> Result<Vec<u32>, String> {
        match self.stack {
            Stack::Ours => {
                if !self.have_raw() {
                    return Err(format!("{} not built", Module::Raw.rel_path()));
                }
                self.load_stack(&[&format!("count={n}")])?;
            }
            Stack::Mainline => {
                for m in Mainline::ALL {
                    let ko = self
                        .mainline_ko(m)
                        .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
                    // vcan: echo in the driver, like rcan_loop (IFF_ECHO).
                    let params: &[&str] = if m == Mainline::Vcan {
                        &["echo=1"]
                    } else {
                        &[]
                    };
                    sys::finit_module(&ko, params)
                        .map_err(|e| format!("insmod {}: {e}", ko.display()))?;
                }
                for i in 0..n {
                    let name = dev(i);
                    run(
                        "ip",
                        &["link", "add", "dev", &name, "type", "vcan"].map(String::from),
                    )?;
                    self.vcans.push(name.clone());
                    // vcan starts with the CAN FD MTU (72); ours are classic
                    // CAN interfaces (16), so make mainline's the same.
                    run("ip", &["link", "set", &name, "mtu", "16"].map(String::from))?;
                    self.link_up(&name)?;
                }
            }
        }
        (0..n).map(|i| self.ifindex(&dev(i))).collect()
    }

    /// Loads the SJA1000 driver of the stack under test for QEMU's Kvaser
    /// cards (can0, can1: the VM runs with `RCAN_QEMU_CAN`), with no bit
    /// timing set and the interfaces down, for the `ip ... type can`
    /// tests. Ours: rcan_pf, rcan_dev, rcan_kvaser_pci. Mainline: can-dev,
    /// sja1000, kvaser_pci (no PF_CAN needed for `ip`).
    pub fn sja1000_cards(&mut self) -> Result<(), String> {
        match self.stack {
            Stack::Ours => {
                self.insmod(Module::Pf, &[])?;
                self.insmod(Module::Dev, &[])?;
                self.insmod(Module::Kvaser, &[])?;
            }
            Stack::Mainline => {
                for m in [Mainline::Dev, Mainline::Sja1000, Mainline::KvaserPci] {
                    let ko = self
                        .mainline_ko(m)
                        .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
                    sys::finit_module(&ko, &[])
                        .map_err(|e| format!("insmod {}: {e}", ko.display()))?;
                }
            }
        }
        if !Path::new("/sys/class/net/can1").exists() {
            return Err(
                "fewer than two Kvaser channels (is the VM booted with RCAN_QEMU_CAN?)".into(),
            );
        }
        Ok(())
    }

    /// Loads the stack under test with CAN_RAW and its CTU CAN FD driver
    /// for QEMU's two `ctucan_pci` cores (can0, can1: the VM runs with
    /// `RCAN_QEMU_CAN`), no bit timing set, the interfaces down and
    /// classic (MTU 16). Ours: rcan_pf, rcan_can, rcan_raw,
    /// rcan_ctucanfd_pci. Mainline: can, can-raw, can-dev, ctucanfd,
    /// ctucanfd_pci.
    pub fn ctucan_cards(&mut self) -> Result<(), String> {
        match self.stack {
            Stack::Ours => {
                self.insmod(Module::Pf, &[])?;
                self.insmod(Module::Can, &[])?;
                self.insmod(Module::Raw, &[])?;
                self.insmod(Module::CtuCanFdPci, &[])?;
            }
            Stack::Mainline => {
                for m in [
                    Mainline::Can,
                    Mainline::Raw,
                    Mainline::Dev,
                    Mainline::CtuCanFd,
                    Mainline::CtuCanFdPci,
                ] {
                    let ko = self
                        .mainline_ko(m)
                        .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
                    sys::finit_module(&ko, &[])
                        .map_err(|e| format!("insmod {}: {e}", ko.display()))?;
                }
            }
        }
        if !Path::new("/sys/class/net/can1").exists() {
            return Err(
                "fewer than two CTU CAN FD cores (is the VM booted with QEMU's ctucan_pci, RCAN_QEMU_CAN?)"
                    .into(),
            );
        }
        Ok(())
    }

    /// [`Ctx::can_ifaces`] plus the CAN_BCM protocol. Mainline: can-bcm.ko.
    /// Ours: rcan_bcm.
    pub fn bcm_ifaces(&mut self, n: usize) -> Result<Vec<u32>, String> {
        if self.stack == Stack::Ours {
            let ifaces = self.can_ifaces(n)?;
            self.insmod(Module::Bcm, &[])?;
            return Ok(ifaces);
        }
        let ifaces = self.can_ifaces(n)?;
        let ko = self
            .mainline_ko(Mainline::Bcm)
            .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
        sys::finit_module(&ko, &[]).map_err(|e| format!("insmod {}: {e}", ko.display()))?;
        Ok(ifaces)
    }

    /// [`Ctx::can_ifaces`] plus the CAN_J1939 protocol. Mainline:
    /// can-j1939.ko. Ours: rcan_j1939.
    pub fn j1939_ifaces(&mut self, n: usize) -> Result<Vec<u32>, String> {
        let ifaces = self.can_ifaces(n)?;
        if self.stack == Stack::Ours {
            self.insmod(Module::J1939, &[])?;
            return Ok(ifaces);
        }
        let ko = self
            .mainline_ko(Mainline::J1939)
            .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
        sys::finit_module(&ko, &[]).map_err(|e| format!("insmod {}: {e}", ko.display()))?;
        Ok(ifaces)
    }

    /// [`Ctx::can_ifaces`] plus the CAN_ISOTP protocol. Mainline:
    /// can-isotp.ko. Ours: rcan_isotp.
    pub fn isotp_ifaces(&mut self, n: usize) -> Result<Vec<u32>, String> {
        self.isotp_ifaces_with(n, &[])
    }

    /// [`Ctx::isotp_ifaces`] with the ISO-TP module loaded with `params`
    /// (both stacks' modules take `max_pdu_size=`): a [`Uses::Own`] test.
    pub fn isotp_ifaces_with(&mut self, n: usize, params: &[&str]) -> Result<Vec<u32>, String> {
        let ifaces = self.can_ifaces(n)?;
        if self.stack == Stack::Ours {
            self.insmod(Module::Isotp, params)?;
            return Ok(ifaces);
        }
        let ko = self
            .mainline_ko(Mainline::Isotp)
            .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
        sys::finit_module(&ko, params)
            .map_err(|e| format!("insmod {} {}: {e}", ko.display(), params.join(" ")))?;
        Ok(ifaces)
    }

    /// Loads the ISO-TP module that [`Ctx::isotp_ifaces_with`] loaded
    /// again, with `params` (its sockets must be closed): a [`Uses::Own`]
    /// test.
    pub fn reload_isotp_with(&mut self, params: &[&str]) -> Result<(), String> {
        self.own("reload", "the ISO-TP module")?;
        if self.stack == Stack::Ours {
            // Retrying: a socket's release may end a little after close.
            rmmod_retrying(Module::Isotp.name())?;
            return self.insmod(Module::Isotp, params);
        }
        rmmod_retrying(Mainline::Isotp.name())?;
        let ko = self
            .mainline_ko(Mainline::Isotp)
            .ok_or("no kernel build directory (RCAN_KBUILD or --kbuild)")?;
        sys::finit_module(&ko, params)
            .map_err(|e| format!("insmod {} {}: {e}", ko.display(), params.join(" ")))
    }

    /// Unregisters the interfaces [`Ctx::can_ifaces`] made, under any
    /// sockets bound to them. Ours: rmmod rcan_loop. Mainline:
    /// `ip link del` each vcan.
    pub fn remove_can_ifaces(&mut self) -> Result<(), String> {
        self.own("remove", "the canN interfaces")?;
        match self.stack {
            Stack::Ours => self.rmmod(Module::Loop),
            Stack::Mainline => std::mem::take(&mut self.vcans)
                .iter()
                .try_for_each(|name| run("ip", &["link", "del", "dev", name].map(String::from))),
        }
    }

    /// Sets every canN device of the loaded rcan_loop up.
    pub fn links_up(&self) -> Result<(), String> {
        (0..self.ndev).try_for_each(|i| self.link_up(&dev(i)))
    }

    /// Unloads whatever of the stack is loaded, in reverse load order.
    /// A module that is not loaded is skipped; one that will not unload is
    /// retried for up to 3 s (sockets may be released a little late).
    /// Mainline modules and the vcan interfaces made for a test go the same
    /// way (`ip link del`, then rmmod).
    pub fn unload_all(&mut self) -> Result<(), String> {
        self.own("unload", "every module")?;
        let mut errors = Vec::new();
        // It uses rcan_pf: first.
        if let Err(e) = rmmod_retrying(EXITTEST) {
            errors.push(e);
        }
        if let Err(e) = rmmod_retrying(IOMEMKEEP) {
            errors.push(e);
        }
        for m in Module::ALL.into_iter().rev() {
            if let Err(e) = rmmod_retrying(m.name()) {
                errors.push(e);
            }
        }
        for name in std::mem::take(&mut self.vcans) {
            if Path::new("/sys/class/net").join(&name).exists() {
                if let Err(e) = run("ip", &["link", "del", "dev", &name].map(String::from)) {
                    errors.push(e);
                }
            }
        }
        for m in [
            Mainline::Bcm,
            Mainline::Isotp,
            Mainline::J1939,
            Mainline::KvaserPci,
            Mainline::Sja1000,
            Mainline::CtuCanFdPci,
            Mainline::CtuCanFd,
        ]
        .into_iter()
        .chain(Mainline::ALL.into_iter().rev())
        {
            if let Err(e) = rmmod_retrying(m.name()) {
                errors.push(e);
            }
        }
        self.ndev = 0;
        self.loop_state = None;
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors.join("; "))
        }
    }

    /// Number of canN devices of the loaded rcan_loop.
    pub fn ndev(&self) -> usize {
        self.ndev
    }

    /// `ip link set DEV up` (by ioctl, see [`sys::set_link_up`]).
    pub fn link_up(&self, dev: &str) -> Result<(), String> {
        sys::set_link_up(dev, true).map_err(|e| format!("ip link set {dev} up: {e}"))
    }

    /// `ip link set DEV down` (by ioctl).
    pub fn link_down(&self, dev: &str) -> Result<(), String> {
        sys::set_link_up(dev, false).map_err(|e| format!("ip link set {dev} down: {e}"))
    }

    /// Interface index of `dev`.
    pub fn ifindex(&self, dev: &str) -> Result<u32, String> {
        rcan_uapi::ifindex(dev).or_fail(format_args!("if_nametoindex({dev})"))
    }

    /// A counter from `/sys/class/net/DEV/statistics/`.
    pub fn stat(&self, dev: &str, counter: &str) -> Result<u64, String> {
        let p = format!("/sys/class/net/{dev}/statistics/{counter}");
        let s = fs::read_to_string(&p).or_fail(&p)?;
        s.trim()
            .parse()
            .map_err(|e| format!("{p}: {e}: {:?}", s.trim()))
    }

    /// A cursor on the kernel log positioned at its current end.
    pub fn kmsg(&self) -> Result<Kmsg, String> {
        Kmsg::at_end()
    }

    /// A new, unbound CANPROTO_CAN socket with [`RX_TIMEOUT`].
    pub fn socket(&self) -> Result<ArbSocket, String> {
        let s = ArbSocket::new().or_fail("socket(PF_CAN, SOCK_RAW, CANPROTO_CAN)")?;
        s.set_rcvtimeo(RX_TIMEOUT).or_fail("SO_RCVTIMEO")?;
        Ok(s)
    }

    /// A socket bound to filter (`arb`, `mask`) on `ifindex`.
    pub fn bound(&self, arb: u32, mask: u32, ifindex: u32) -> Result<ArbSocket, String> {
        let s = self.socket()?;
        s.bind(arb, mask, ifindex).or_fail(format_args!(
            "bind(arb {arb:#010x}, mask {mask:#010x}, ifindex {ifindex})"
        ))?;
        Ok(s)
    }

    /// Prints an informational line (TAP comment) into the test output.
    pub fn note(&self, msg: impl AsRef<str>) {
        println!("# {}", msg.as_ref());
    }
}

/// Unloads module `name` if it is loaded, retrying for up to 3 s: sockets
/// may be released a little after close.
fn rmmod_retrying(name: &str) -> Result<(), String> {
    let start = Instant::now();
    while module_listed(name) {
        match rmmod(name) {
            Ok(()) => break,
            Err(e) if start.elapsed() > Duration::from_secs(3) => return Err(e),
            Err(_) => thread::sleep(Duration::from_millis(50)),
        }
    }
    Ok(())
}

/// Whether [`Uses::Stack`] tests share the loaded stack: unless
/// `RCAN_VMTEST_SHARE=0`, which runs every test on modules of its own (to
/// tell a test that depends on another's leftovers, and to measure what
/// sharing saves).
fn sharing() -> bool {
    std::env::var("RCAN_VMTEST_SHARE").map_or(true, |v| v != "0")
}

/// Waits (10 s at most) until none of the loaded `modules` is held by more
/// than the modules that use it (`/proc/modules`: the use count against
/// the "used by" list): no socket, device or program of a test holds one.
fn wait_idle(modules: &[Module]) -> Result<(), String> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let held: Vec<String> = fs::read_to_string("/proc/modules")
            .or_fail("/proc/modules")?
            .lines()
            .filter_map(|l| {
                let f: Vec<&str> = l.split(' ').collect();
                let (name, count, users) = (f.first()?, f.get(2)?, f.get(3)?);
                if !modules.iter().any(|m| m.name() == *name) {
                    return None;
                }
                let count: usize = count.parse().ok()?;
                let users = users
                    .split(',')
                    .filter(|u| !u.is_empty() && *u != "-")
                    .count();
                (count > users).then(|| format!("{name} (use count {count}, {users} module(s))"))
            })
            .collect();
        if held.is_empty() {
            return Ok(());
        }
        if Instant::now() > deadline {
            return Err(format!(
                "left in use after 10 s: {} (a socket, device or program of the test still holds it)",
                held.join(", ")
            ));
        }
        thread::sleep(Duration::from_millis(20));
    }
}

/// What a [`Uses::Stack`] test must leave of rcan_loop as it found it: for
/// each of its `n` devices (and no more), the flags, MTU and queue length,
/// and the module's parameters. None if a device is missing.
fn loop_state(n: usize) -> Option<String> {
    let mut s = String::new();
    for i in 0..n {
        let d = Path::new("/sys/class/net").join(dev(i));
        for attr in ["flags", "mtu", "tx_queue_len"] {
            s += fs::read_to_string(d.join(attr)).ok()?.trim();
            s.push(' ');
        }
    }
    if Path::new("/sys/class/net").join(dev(n)).exists() {
        return None;
    }
    if let Ok(dir) = fs::read_dir("/sys/module/rcan_loop/parameters") {
        let mut params: Vec<_> = dir.flatten().map(|e| e.path()).collect();
        params.sort();
        for p in params {
            s += &fs::read_to_string(&p).unwrap_or_default();
        }
    }
    Some(s)
}

/// `rmmod NAME` (by syscall, see [`sys::delete_module`]).
fn rmmod(name: &str) -> Result<(), String> {
    sys::delete_module(name).map_err(|e| format!("rmmod {name}: {e}"))
}

/// Whether a module called `name` is listed in `/proc/modules`.
fn module_listed(name: &str) -> bool {
    fs::read_to_string("/proc/modules")
        .map(|s| s.lines().any(|l| l.split(' ').next() == Some(name)))
        .unwrap_or(false)
}

/// Whether the suite runs on the debug kernel (KASAN, lockdep, kmemleak;
/// under TCG some ten to a hundred times slower per frame than the release
/// kernel), as `RCAN_KERNEL=debug` tells (vm-run.sh passes it into the VM).
pub fn debug_kernel() -> bool {
    std::env::var("RCAN_KERNEL").is_ok_and(|k| k == "debug")
}

/// A test's workload size: the environment variable `env` if it is set to
/// a number, else `release` on the release kernel and `debug` on the debug
/// kernel.
pub fn sized(env: &str, release: u32, debug: u32) -> u32 {
    std::env::var(env)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if debug_kernel() { debug } else { release })
}

/// Name of the `i`-th loopback device.
pub fn dev(i: usize) -> String {
    format!("can{i}")
}

/// The `count=` parameter of rcan_loop (default 1).
fn loop_count(params: &[&str]) -> usize {
    params
        .iter()
        .find_map(|p| p.strip_prefix("count="))
        .and_then(|v| v.parse().ok())
        .unwrap_or(1)
}

/// Where the system tools live inside the VM.
pub fn tool(name: &str) -> PathBuf {
    ["/sbin", "/usr/sbin", "/bin", "/usr/bin"]
        .iter()
        .map(|d| Path::new(d).join(name))
        .find(|p| p.exists())
        .unwrap_or_else(|| PathBuf::from(name))
}

/// Runs a system tool; fails with its exit status and stderr.
fn run(name: &str, args: &[String]) -> Result<(), String> {
    let cmd = format!("{name} {}", args.join(" "));
    let out = Command::new(tool(name))
        .args(args)
        .output()
        .map_err(|e| format!("{cmd}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        let err = String::from_utf8_lossy(&out.stderr);
        Err(format!(
            "{cmd}: {}: {}",
            out.status,
            err.trim().replace('\n', " / ")
        ))
    }
}

/// A reader of kernel log records written after it was created.
pub enum Kmsg {
    /// `/dev/kmsg`, non-blocking, positioned at the end.
    Dev(File),
    /// Fallback: `dmesg` output, skipping the first `n` lines.
    Dmesg(usize),
}

impl Kmsg {
    fn at_end() -> Result<Self, String> {
        let opened = OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open("/dev/kmsg");
        match opened {
            Ok(mut f) => {
                f.seek(SeekFrom::End(0)).or_fail("seek /dev/kmsg")?;
                Ok(Kmsg::Dev(f))
            }
            Err(_) => Ok(Kmsg::Dmesg(dmesg_lines()?.len())),
        }
    }

    /// The messages logged since the cursor was created or last read.
    pub fn read_new(&mut self) -> Result<Vec<String>, String> {
        match self {
            Kmsg::Dev(f) => {
                let mut out = Vec::new();
                let mut buf = vec![0u8; 8192];
                loop {
                    match f.read(&mut buf) {
                        Ok(0) => break,
                        // "prio,seq,usec,flags;message\n continuation..."
                        Ok(n) => {
                            let rec = String::from_utf8_lossy(&buf[..n]);
                            let msg = rec.split_once(';').map_or(&*rec, |(_, m)| m);
                            out.push(msg.lines().next().unwrap_or("").to_string());
                        }
                        Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                        // Records were overwritten before we read them.
                        Err(e) if e.raw_os_error() == Some(libc::EPIPE) => continue,
                        Err(e) => return Err(format!("read /dev/kmsg: {e}")),
                    }
                }
                Ok(out)
            }
            Kmsg::Dmesg(skip) => {
                let lines = dmesg_lines()?;
                let new = lines.get(*skip..).unwrap_or_default().to_vec();
                *skip = lines.len();
                Ok(new)
            }
        }
    }
}

fn dmesg_lines() -> Result<Vec<String>, String> {
    let out = Command::new(tool("dmesg"))
        .output()
        .map_err(|e| format!("dmesg: {e}"))?;
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(String::from)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn count_param() {
        assert_eq!(loop_count(&[]), 1);
        assert_eq!(loop_count(&["verbose=1", "count=4"]), 4);
    }

    #[test]
    fn module_paths() {
        let c = Ctx::new(PathBuf::from("/r"), Stack::Ours, Some(PathBuf::from("/k")));
        assert_eq!(
            c.ko(Module::Loop),
            Path::new("/r/drivers/net/can/rcan_loop.ko")
        );
        assert_eq!(c.ko(Module::Raw), Path::new("/r/net/can/rcan_raw.ko"));
        assert_eq!(
            Module::ALL.map(Module::name),
            [
                "rcan_pf",
                "rcan_can",
                "rcan_raw",
                "rcan_bcm",
                "rcan_isotp",
                "rcan_j1939",
                "rcan_loop",
                "rcan_time",
                "rcan_rtime",
                "rcan_dsor",
                "rcan_dev",
                "rcan_kvaser_pci",
                "rcan_advantech_pci",
                "rcan_sja1000_isa",
                "rcan_pcan_pci",
                "rcan_tscan1",
                "rcan_i82527_sim",
                "rcan_i82527_isa",
                "rcan_sja1000_sim",
                "rcan_ctucanfd_pci",
                "rcan_ctucanfd_sim"
            ]
        );
        assert_eq!(
            c.mainline_ko(Mainline::Raw).as_deref(),
            Some(Path::new("/k/net/can/can-raw.ko"))
        );
    }

    #[test]
    fn stack_names() {
        for s in [Stack::Ours, Stack::Mainline] {
            assert_eq!(Stack::parse(s.name()), Ok(s));
        }
        assert!(Stack::parse("vcan").is_err());
    }
}

/// The PCI ids (vendor, device) of the CAN cards the VM carries
/// (`RCAN_QEMU_CAN`): Kvaser PCIcan, Advantech PCM-3680 and MIOe-3680,
/// CTU CAN FD.
const CAN_CARD_IDS: [(u32, u32); 4] = [
    (0x10e8, 0x8406),
    (0x13fe, 0xc002),
    (0x13fe, 0xc302),
    (0x1760, 0xff00),
];

/// Enables every PCI CAN card once, as `echo 1 >
/// /sys/bus/pci/devices/ADDR/enable` does, and leaves it enabled for the
/// whole run. `pci_enable_device()` counts its callers: the first one
/// routes the card's interrupt, which on QEMU's q35 means evaluating the
/// ACPI `_PRT` method of the root bus (hundreds of ACPI objects allocated
/// and freed), and the last `pci_disable_device()` undoes it. On the debug
/// kernel, where KASAN and kmemleak record a stack trace for every
/// allocation, that was most of each driver load and unload (build.rst).
/// Held here, a driver's probe and remove still make both calls, and
/// they only count. Called once when rcan-vmtest starts; a VM without the
/// cards is left alone. Returns how many cards it enabled.
pub fn hold_can_cards_enabled() -> Result<usize, String> {
    let cards = pci_devices(&CAN_CARD_IDS)?;
    for addr in &cards {
        let f = format!("/sys/bus/pci/devices/{addr}/enable");
        fs::write(&f, "1").map_err(|e| format!("echo 1 > {f}: {e}"))?;
    }
    Ok(cards.len())
}

/// The PCI addresses (as in `/sys/bus/pci/devices`) of the devices whose
/// (vendor, device) ids are in `ids`, in PCI order.
pub fn pci_devices(ids: &[(u32, u32)]) -> Result<Vec<String>, String> {
    let dir = "/sys/bus/pci/devices";
    let hex = |p: &Path, f: &str| {
        let s = fs::read_to_string(p.join(f)).unwrap_or_default();
        u32::from_str_radix(s.trim().trim_start_matches("0x"), 16).ok()
    };
    let mut found = Vec::new();
    for e in fs::read_dir(dir).or_fail(dir)? {
        let p = e.or_fail(dir)?.path();
        let (Some(v), Some(d)) = (hex(&p, "vendor"), hex(&p, "device")) else {
            continue;
        };
        if ids.contains(&(v, d)) {
            if let Some(n) = p.file_name().and_then(|n| n.to_str()) {
                found.push(n.to_string());
            }
        }
    }
    found.sort();
    Ok(found)
}
