// SPDX-License-Identifier: GPL-2.0
//! # rcan-vmtest: the rcan VM test suite
//!
//! Exercises the thesis CAN socket API (`CANPROTO_CAN`, section 5.2), the
//! SocketCAN-compatible `CAN_RAW` protocol (through the `socketcan` crate,
//! can-utils and tcpdump) and the `rcan_loop` driver against the real kernel
//! modules. It loads and unloads modules, so it runs as root inside the test
//! VM, never on the host:
//!
//! ```text
//! cargo build -p rcan-vmtests
//! tools/testing/rcan/vm-run.sh -- target/debug/rcan-vmtest            # all tests
//! tools/testing/rcan/vm-run.sh -- target/debug/rcan-vmtest filter_    # names containing "filter_"
//! target/debug/rcan-vmtest --list                                     # just the names
//! RCAN_KBUILD=$(tools/testing/rcan/build-kernel.sh) tools/testing/rcan/vm-run.sh -- \
//!     target/debug/rcan-vmtest --stack mainline                       # CAN_RAW tests on mainline
//! ```
//!
//! Usage: `rcan-vmtest [--root DIR] [--stack ours|mainline] [--kbuild DIR]
//! [--timeout SECS] [--shard I/N] [--last-shard-busy SECS] [--list] [FILTER]`
//!
//! - `--root DIR`: repository root holding the built `.ko` files (default:
//!   `$RCAN_ROOT`, else the current directory).
//! - `--stack STACK` (default `$RCAN_VMTEST_STACK`, else `ours`): `ours`
//!   runs every test against the rcan modules; `mainline` runs only the
//!   portable tests (CAN_RAW, can-utils, tcpdump, CAN_BCM, `ip ... type
//!   can` on the Kvaser cards, the daemons) against mainline SocketCAN
//!   (`can.ko`, `can-raw.ko`, `can-bcm.ko`, `can-dev.ko`, `vcan.ko
//!   echo=1`), to show that they encode mainline behaviour. The other
//!   tests are skipped there, not counted.
//! - `--kbuild DIR`: kernel build directory with the mainline modules
//!   (default: `$RCAN_KBUILD`); needed for `--stack mainline`.
//! - `--timeout SECS`: per-test watchdog (default 180, or 360 on the debug
//!   kernel, `RCAN_KERNEL=debug`). A test that takes longer is reported as
//!   hung and the run ends there.
//!   `cases::LONG_RUNNING` gives a few tests a longer one.
//! - `--shard I/N`: run only the I-th of N parts of the selected tests,
//!   balanced by their recorded seconds (`shard`): N runs, in N VMs booted
//!   side by side, share the suite (`run-tests.sh` does this; each VM has
//!   its own kernel, so the shards cannot disturb each other's modules or
//!   devices).
//! - `--last-shard-busy SECS`: the last shard's VM does SECS of other
//!   work too (run-tests.sh runs the fuzzer after it on the debug kernel):
//!   it gets that much less of the suite. Every shard must get the same.
//! - `FILTER`: run only the tests whose name contains it, or one of its
//!   comma-separated parts (`raw_bind,mixed_`).
//!
//! Output, one line per test with the seconds it took and the busy CPU
//! seconds of all vCPUs meanwhile (guest time, for finding the slow tests
//! and telling waiting from work, never checked), then the 15 slowest
//! tests and the run's busy share (`timing`), then one summary line; exit
//! status 1 if any test failed:
//!
//! ```text
//! # informational note
//! ok - roundtrip_std_sendto # 0.4 s, cpu 0.3 s
//! not ok - filter_exact_ext: expected STD 6AF ... got ... # 0.6 s, cpu 0.2 s
//! # the 15 slowest tests (...):
//! #      12.1 s  cpu     3.0 s  12 %  sja1000_burst
//! # 46 tests in 80.2 s, CPUs busy 40.1 s of 160.4 s (25 %; the rest is waiting)
//! 45 passed, 1 failed
//! ```
//!
//! Every test loads the modules it needs (`Ctx::load_stack`,
//! `Ctx::can_ifaces`). After a test declared `Uses::Own` the runner
//! unloads everything, also after a failure or panic; after one declared
//! `Uses::Stack` (its set-up is the shared stack: rcan_pf, rcan_can,
//! rcan_raw, rcan_bcm, rcan_loop `count=N`) it keeps those modules for the
//! next such test if no module is left in use and rcan_loop's devices are
//! as they were (`Ctx::end`), else unloads them too; the run ends with an
//! unload. So tests are independent. Receives use a 2 s
//! (thesis API) or 10 s (CAN_RAW) `SO_RCVTIMEO`; "nothing arrives" is
//! checked with `MSG_DONTWAIT` after a 200 ms pause, in CAN_RAW tests also
//! by a marker frame sent last. No test asserts on wall-clock time, except
//! the time-service tests (`time_*`, `rtime_*`, whose subject is timing):
//! they assert generous bounds and print what they measure.
//!
//! While `net/can/rcan_raw.ko` is not built, `--stack ours` loads the stack
//! without it and only the tests that need CAN_RAW fail.

mod canraw;
mod cases;
mod check;
mod ctx;
mod shard;
mod sys;
mod timing;
mod tools;

use std::panic::{self, AssertUnwindSafe};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use check::TestResult;
pub use ctx::Uses;
use ctx::{Ctx, Mainline, Module, Stack};
use shard::Shard;

/// A named test case.
pub struct Test {
    /// Unique name, used by FILTER.
    pub name: &'static str,
    /// The test body; modules are unloaded by the runner afterwards.
    pub run: fn(&mut Ctx) -> TestResult,
    /// Whether the test also runs against mainline SocketCAN: it uses only
    /// the mainline API (CAN_RAW, can-utils, packet sockets) and sets up its
    /// interfaces with `Ctx::can_ifaces`.
    pub portable: bool,
    /// What it uses of the machine: modules of its own, or the stack the
    /// runner keeps loaded between such tests.
    pub uses: Uses,
}

impl Test {
    /// Whether the test runs against `stack`.
    pub fn runs_on(&self, stack: Stack) -> bool {
        match stack {
            Stack::Ours => true,
            Stack::Mainline => self.portable,
        }
    }
}

const USAGE: &str = "usage: rcan-vmtest [--root DIR] [--stack ours|mainline] [--kbuild DIR] \
                     [--timeout SECS] [--shard I/N] [--last-shard-busy SECS] [--list] [FILTER]";

struct Options {
    root: Option<PathBuf>,
    stack: Stack,
    kbuild: Option<PathBuf>,
    filter: Option<String>,
    list: bool,
    timeout: Duration,
    shard: Shard,
    last_busy: f64,
}

fn parse_args() -> Result<Options, String> {
    let stack = match std::env::var("RCAN_VMTEST_STACK") {
        Ok(s) if !s.is_empty() => {
            Stack::parse(&s).map_err(|e| format!("RCAN_VMTEST_STACK: {e}"))?
        }
        _ => Stack::Ours,
    };
    let mut o = Options {
        root: std::env::var_os("RCAN_ROOT").map(PathBuf::from),
        stack,
        kbuild: std::env::var_os("RCAN_KBUILD")
            .filter(|k| !k.is_empty())
            .map(PathBuf::from),
        filter: None,
        list: false,
        timeout: Duration::from_secs(if ctx::debug_kernel() { 360 } else { 180 }),
        shard: Shard::WHOLE,
        last_busy: 0.0,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--root" => o.root = Some(args.next().ok_or("--root needs a directory")?.into()),
            "--stack" => o.stack = Stack::parse(&args.next().ok_or("--stack needs a name")?)?,
            "--kbuild" => o.kbuild = Some(args.next().ok_or("--kbuild needs a directory")?.into()),
            "--timeout" => {
                let s = args.next().ok_or("--timeout needs seconds")?;
                let secs = s.parse().map_err(|_| format!("bad --timeout {s:?}"))?;
                o.timeout = Duration::from_secs(secs);
            }
            "--list" => o.list = true,
            "--shard" => o.shard = Shard::parse(&args.next().ok_or("--shard needs I/N")?)?,
            "--last-shard-busy" => {
                let s = args.next().ok_or("--last-shard-busy needs seconds")?;
                o.last_busy = s
                    .parse()
                    .map_err(|_| format!("bad --last-shard-busy {s:?}"))?;
            }
            "-h" | "--help" => return Err(USAGE.into()),
            f if !f.starts_with('-') && o.filter.is_none() => o.filter = Some(f.to_string()),
            other => return Err(format!("unexpected argument {other:?}")),
        }
    }
    Ok(o)
}

/// Progress shared with the watchdog thread.
#[derive(Default)]
struct Progress {
    current: Option<(&'static str, Instant)>,
    passed: usize,
    failed: usize,
}

/// The run's progress, for [`heartbeat`].
static PROGRESS: std::sync::OnceLock<Arc<Mutex<Progress>>> = std::sync::OnceLock::new();

/// Restarts the watchdog's clock for the running test: a test made of
/// many bounded steps (one module's load/unload cycles, say) calls it
/// after each, so the watchdog bounds each step rather than their sum.
pub fn heartbeat() {
    if let Some(p) = PROGRESS.get() {
        let mut p = p.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((name, _)) = p.current {
            p.current = Some((name, Instant::now()));
        }
    }
}

/// Ends the run if a test exceeds `limit` (e.g. a kernel hang in rmmod or
/// recv), reporting that test as failed. Modules stay loaded then, but the
/// VM is about to be discarded anyway.
fn spawn_watchdog(progress: Arc<Mutex<Progress>>, limit: Duration) {
    thread::spawn(move || loop {
        thread::sleep(Duration::from_secs(1));
        let p = progress.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((name, start)) = p.current {
            let limit = cases::LONG_RUNNING
                .iter()
                .find(|(n, _)| *n == name)
                .map_or(limit, |&(_, secs)| limit.max(Duration::from_secs(secs)));
            if start.elapsed() > limit {
                // Where it hangs: every thread's system call and kernel
                // place, and the kernel's list of blocked tasks (sysrq w,
                // on the console).
                for l in tools::hang_report() {
                    println!("# hung: {l}");
                }
                let _ = std::fs::write("/proc/sysrq-trigger", "w");
                println!("not ok - {name}: hung, no result after {limit:?}");
                println!("{} passed, {} failed", p.passed, p.failed + 1);
                // A thread asleep in the kernel keeps the process from
                // ever exiting: in the VM, tell its init to go on without
                // us (tools/testing/rcan/vm/init).
                if std::env::var_os("RCAN_GUEST").is_some() {
                    let _ = std::io::Write::flush(&mut std::io::stdout());
                    sys::sigusr1_to_init();
                }
                std::process::exit(1);
            }
        }
    });
}

/// Runs one test between two full unloads, catching panics. A test that
/// leaves the runner's thread pinned to fewer CPUs than it found fails,
/// and the affinity is put back: every later test, and every thread and
/// program it starts, would inherit it (two SJA1000 tests did that once,
/// and a BCM test late in the run took minutes instead of seconds).
fn run_one(ctx: &mut Ctx, t: &Test) -> TestResult {
    ctx.begin(t.uses)
        .map_err(|e| format!("leftover modules from an earlier test: {e}"))?;
    let cpus = sys::affinity().map_err(|e| format!("sched_getaffinity: {e}"))?;
    let r = panic::catch_unwind(AssertUnwindSafe(|| (t.run)(ctx))).unwrap_or_else(|p| {
        let msg = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "unknown payload".into());
        Err(format!("panicked: {msg}"))
    });
    let mut cleanup = ctx.end(r.is_ok());
    match sys::affinity() {
        Ok(now) if now == cpus => {}
        now => {
            let put_back = sys::set_affinity(&cpus);
            let left = format!(
                "left the runner's thread on CPUs {now:?}, was {cpus:?} (put back: {put_back:?})"
            );
            cleanup = Err(match cleanup {
                Ok(()) => left,
                Err(c) => format!("{c}; {left}"),
            });
        }
    }
    match (r, cleanup) {
        (Ok(()), Ok(())) => Ok(()),
        (Ok(()), Err(c)) => Err(format!("cleanup: {c}")),
        (Err(e), Ok(())) => Err(e),
        (Err(e), Err(c)) => Err(format!("{e}; cleanup: {c}")),
    }
}

/// Checks that the modules the selected stack needs exist. rcan_raw is
/// exempt: the suite stays usable while it is being written.
fn check_modules(ctx: &Ctx) -> Result<(), String> {
    match ctx.stack() {
        Stack::Ours => {
            for m in Module::ALL.into_iter().filter(|&m| m != Module::Raw) {
                if !ctx.ko(m).is_file() {
                    return Err(format!(
                        "{} not found (build the modules; set RCAN_ROOT or --root)",
                        ctx.ko(m).display()
                    ));
                }
            }
        }
        Stack::Mainline => {
            for m in Mainline::ALL {
                let ko = ctx.mainline_ko(m).ok_or(
                    "--stack mainline needs the kernel build directory (RCAN_KBUILD or --kbuild)",
                )?;
                if !ko.is_file() {
                    return Err(format!(
                        "{} not found (a test kernel with CONFIG_CAN_RAW=m, CONFIG_CAN_VCAN=m)",
                        ko.display()
                    ));
                }
            }
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    let opts = match parse_args() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("rcan-vmtest: {e}");
            return ExitCode::from(2);
        }
    };
    let (tests, skipped): (Vec<&Test>, Vec<&Test>) = cases::all()
        .filter(|t| {
            opts.filter
                .as_deref()
                .is_none_or(|f| f.split(',').any(|part| t.name.contains(part)))
        })
        .partition(|t| t.runs_on(opts.stack));
    // Tests too slow for the debug kernel's per-test watchdog: listed,
    // with the reason, and not run there.
    let (tests, too_slow): (Vec<&Test>, Vec<&Test>) = tests
        .into_iter()
        .partition(|t| !(ctx::debug_kernel() && cases::RELEASE_ONLY.contains(&t.name)));
    let names: Vec<&str> = tests.iter().map(|t| t.name).collect();
    let mine = opts
        .shard
        .select(&names, &shard::weights(ctx::debug_kernel()), opts.last_busy);
    let tests: Vec<&Test> = mine.into_iter().map(|pos| tests[pos]).collect();
    // Said once, by the first shard.
    for t in too_slow.iter().filter(|_| opts.shard.index == 1) {
        println!(
            "# {}: release kernel only (past the debug kernel's per-test watchdog under TCG)",
            t.name
        );
    }
    if opts.list {
        tests.iter().for_each(|t| println!("{}", t.name));
        return ExitCode::SUCCESS;
    }

    let root = opts
        .root
        .unwrap_or_else(|| std::env::current_dir().unwrap_or_default());
    let mut ctx = Ctx::new(root, opts.stack, opts.kbuild);
    if let Err(e) = check_modules(&ctx) {
        eprintln!("rcan-vmtest: {e}");
        return ExitCode::from(2);
    }
    // The second ctucan_pci card is the wire-peer test's alone.
    if let Err(e) = cases::park_spare_ctucan_cards() {
        eprintln!("rcan-vmtest: {e}");
        return ExitCode::from(2);
    }
    // Each driver load would otherwise route the cards' interrupts anew.
    if let Err(e) = ctx::hold_can_cards_enabled() {
        eprintln!("rcan-vmtest: {e}");
        return ExitCode::from(2);
    }
    // run_one turns a panic into a test failure; the hook only logs it as
    // a comment line, with its location.
    panic::set_hook(Box::new(|info| eprintln!("# panic: {info}")));

    let progress = Arc::new(Mutex::new(Progress::default()));
    spawn_watchdog(Arc::clone(&progress), opts.timeout);
    let _ = PROGRESS.set(Arc::clone(&progress));
    let lock = || progress.lock().unwrap_or_else(|e| e.into_inner());

    match ctx.stack() {
        Stack::Ours => println!(
            "# rcan-vmtest: {} tests against our stack, modules from {}",
            tests.len(),
            ctx.root().display(),
        ),
        Stack::Mainline => println!(
            "# rcan-vmtest: {} tests against mainline SocketCAN, modules from {}; \
             {} tests skipped (they need the rcan stack)",
            tests.len(),
            ctx.kbuild()
                .map(|k| k.display().to_string())
                .unwrap_or_default(),
            skipped.len()
        ),
    }
    if ctx.stack() == Stack::Ours && !ctx.have_raw() {
        ctx.note(format!(
            "{} not built: the stack loads without it and the CAN_RAW tests fail",
            ctx.ko(Module::Raw).display()
        ));
    }
    let mut report = timing::Report::default();
    for t in tests {
        let timer = timing::Timer::start();
        lock().current = Some((t.name, Instant::now()));
        let r = run_one(&mut ctx, t);
        let mut p = lock();
        p.current = None;
        let sample = timer.stop(t.name);
        let (secs, cpu) = (sample.secs, sample.cpu);
        report.add(sample);
        match r {
            Ok(()) => {
                p.passed += 1;
                println!("ok - {} # {secs:.1} s, cpu {cpu:.1} s", t.name);
            }
            Err(e) => {
                p.failed += 1;
                println!(
                    "not ok - {}: {} # {secs:.1} s, cpu {cpu:.1} s",
                    t.name,
                    e.replace('\n', "; ")
                );
            }
        }
    }
    // The stack the last Uses::Stack test may have left loaded: a module
    // that will not unload (a receive registration or socket leaked and
    // not seen by the use counts) fails the run.
    if let Err(e) = ctx.unload_all() {
        lock().failed += 1;
        println!("not ok - (end of run): the modules kept loaded do not unload: {e}");
    }
    let p = lock();
    let (stack_tests, kept) = ctx.shared_runs();
    if stack_tests > 0 {
        println!(
            "# {stack_tests} tests declared Uses::Stack, {kept} of them ran on the stack kept loaded by the test before"
        );
    }
    report
        .lines(15, timing::online_cpus())
        .iter()
        .for_each(|l| println!("{l}"));
    println!("{} passed, {} failed", p.passed, p.failed);
    if p.failed > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
