// SPDX-License-Identifier: GPL-2.0
//! [`Ctx`]: what a test needs from its environment — loading and unloading
//! the rcan modules, interface state, sysfs counters, the kernel log, and
//! sockets with sane timeouts.

use std::fs::{self, File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::thread;
use std::time::{Duration, Instant};

use rcan_uapi::ArbSocket;

use crate::check::{OrFail, RX_TIMEOUT};

/// One of the three rcan kernel modules.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Module {
    /// Protocol family PF_CAN (`net/can/rcan_pf.ko`).
    Pf,
    /// CANPROTO_CAN (`net/can/rcan_can.ko`).
    Can,
    /// Loopback driver (`drivers/net/can/rcan_loop.ko`).
    Loop,
}

impl Module {
    /// Load order; unload in reverse.
    pub const ALL: [Module; 3] = [Module::Pf, Module::Can, Module::Loop];

    /// Name as shown by `/proc/modules` and taken by `rmmod`.
    pub fn name(self) -> &'static str {
        match self {
            Module::Pf => "rcan_pf",
            Module::Can => "rcan_can",
            Module::Loop => "rcan_loop",
        }
    }

    /// Path of the `.ko` relative to the repository root.
    pub fn rel_path(self) -> &'static str {
        match self {
            Module::Pf => "net/can/rcan_pf.ko",
            Module::Can => "net/can/rcan_can.ko",
            Module::Loop => "drivers/net/can/rcan_loop.ko",
        }
    }
}

/// Test context: repository root and the state of the loaded stack.
pub struct Ctx {
    root: PathBuf,
    /// Number of canN devices of the loaded rcan_loop (0: not loaded).
    ndev: usize,
}

impl Ctx {
    /// A context for the modules under `root`.
    pub fn new(root: PathBuf) -> Self {
        Self { root, ndev: 0 }
    }

    /// The repository root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Absolute path of module `m`.
    pub fn ko(&self, m: Module) -> PathBuf {
        self.root.join(m.rel_path())
    }

    /// `insmod` module `m` with `params`.
    pub fn insmod(&mut self, m: Module, params: &[&str]) -> Result<(), String> {
        let ko = self.ko(m);
        let mut args = vec![ko.to_string_lossy().into_owned()];
        args.extend(params.iter().map(|p| p.to_string()));
        run("insmod", &args).map_err(|e| {
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

    /// `rmmod` module `m` (no retries).
    pub fn rmmod(&mut self, m: Module) -> Result<(), String> {
        run("rmmod", &[m.name().to_string()])?;
        if m == Module::Loop {
            self.ndev = 0;
        }
        Ok(())
    }

    /// Whether module `m` is loaded (listed in `/proc/modules`).
    pub fn is_loaded(&self, m: Module) -> bool {
        module_listed(m.name())
    }

    /// Loads rcan_pf, rcan_can and rcan_loop (with `loop_params`, e.g.
    /// `["count=2"]`) and sets every canN device up.
    pub fn load_stack(&mut self, loop_params: &[&str]) -> Result<(), String> {
        self.insmod(Module::Pf, &[])?;
        self.insmod(Module::Can, &[])?;
        self.insmod(Module::Loop, loop_params)?;
        self.links_up()
    }

    /// Sets every canN device of the loaded rcan_loop up.
    pub fn links_up(&self) -> Result<(), String> {
        (0..self.ndev).try_for_each(|i| self.link_up(&dev(i)))
    }

    /// Unloads whatever of the stack is loaded, in reverse load order.
    /// A module that is not loaded is skipped; one that will not unload is
    /// retried for up to 3 s (sockets may be released a little late).
    pub fn unload_all(&mut self) -> Result<(), String> {
        let mut errors = Vec::new();
        for m in Module::ALL.into_iter().rev() {
            let start = Instant::now();
            while self.is_loaded(m) {
                match self.rmmod(m) {
                    Ok(()) => break,
                    Err(e) if start.elapsed() > Duration::from_secs(3) => {
                        errors.push(e);
                        break;
                    }
                    Err(_) => thread::sleep(Duration::from_millis(50)),
                }
            }
        }
        self.ndev = 0;
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

    /// `ip link set DEV up`.
    pub fn link_up(&self, dev: &str) -> Result<(), String> {
        run("ip", &["link", "set", dev, "up"].map(String::from))
    }

    /// `ip link set DEV down`.
    pub fn link_down(&self, dev: &str) -> Result<(), String> {
        run("ip", &["link", "set", dev, "down"].map(String::from))
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

/// Whether a module called `name` is listed in `/proc/modules`.
fn module_listed(name: &str) -> bool {
    fs::read_to_string("/proc/modules")
        .map(|s| s.lines().any(|l| l.split(' ').next() == Some(name)))
        .unwrap_or(false)
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
fn tool(name: &str) -> PathBuf {
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
        let c = Ctx::new(PathBuf::from("/r"));
        assert_eq!(
            c.ko(Module::Loop),
            Path::new("/r/drivers/net/can/rcan_loop.ko")
        );
        assert_eq!(
            Module::ALL.map(Module::name),
            ["rcan_pf", "rcan_can", "rcan_loop"]
        );
    }
}
