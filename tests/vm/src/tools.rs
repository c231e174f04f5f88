// SPDX-License-Identifier: GPL-2.0
//! Running programs nobody here wrote (can-utils, tcpdump) from the host's
//! root filesystem: start them in the background, know when they are
//! listening, collect their output, and never wait on them forever.

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use crate::check::{wait_for, OrFail};
use crate::ctx::tool;

/// How long a tool may take to start listening or to finish: generous,
/// a software-emulated VM loads the binaries over 9p.
pub const TOOL_LIMIT: Duration = Duration::from_secs(60);

/// How long a python3 script of a test may take, start-up and imports
/// included: a hang bound, not a speed limit. python3 reads some 300
/// modules over 9p; importing python-can took 20-36 s on the release
/// kernel, 76 s alone on the debug kernel, and on the debug kernel of a
/// loaded 2-core host more than 300 s (2026-11-30, twice in a row).
/// The tests that start python3 on the debug kernel have a watchdog to
/// match (`cases::LONG_RUNNING`).
pub fn python_limit() -> Duration {
    if crate::ctx::debug_kernel() {
        TOOL_LIMIT * 15
    } else {
        TOOL_LIMIT * 2
    }
}

/// System calls a receiving program blocks in once its socket is set up
/// (x86_64 numbers): read, poll, select, recvfrom, recvmsg, epoll_wait,
/// pselect6, ppoll, epoll_pwait, recvmmsg, epoll_pwait2.
const WAITING_SYSCALLS: [u32; 11] = [0, 7, 23, 45, 47, 232, 270, 271, 281, 299, 441];

/// A finished program's exit status and output.
pub struct Output {
    /// Exit status.
    pub status: ExitStatus,
    /// Everything written to stdout.
    pub stdout: String,
    /// Everything written to stderr.
    pub stderr: String,
}

/// A program running in the background; killed when dropped.
pub struct Bg {
    cmd: String,
    child: Child,
    /// Its stdin, held open (a pipe nobody writes to) when started with
    /// [`spawn_stdin_open`]; dropping it is EOF for the program.
    stdin: Option<ChildStdin>,
    stdout: Arc<Mutex<Vec<u8>>>,
    stderr: Arc<Mutex<Vec<u8>>>,
    readers: Vec<JoinHandle<()>>,
}

/// Copies a pipe into a shared buffer until EOF.
fn collect(mut pipe: impl Read + Send + 'static, buf: Arc<Mutex<Vec<u8>>>) -> JoinHandle<()> {
    thread::spawn(move || {
        let mut chunk = [0u8; 4096];
        while let Ok(n) = pipe.read(&mut chunk) {
            if n == 0 {
                break;
            }
            buf.lock()
                .unwrap_or_else(|e| e.into_inner())
                .extend_from_slice(&chunk[..n]);
        }
    })
}

/// Starts `name args...` in `dir` (default: the current directory) with
/// stdin from /dev/null and stdout, stderr collected.
pub fn spawn(name: &str, args: &[&str], dir: Option<&Path>) -> Result<Bg, String> {
    spawn_with(name, args, dir, false)
}

/// [`spawn`] with stdin a pipe held open until [`Bg::close_stdin`]: for
/// programs that quit at EOF on stdin (`isotpsniffer` watches it for a
/// key press).
pub fn spawn_stdin_open(name: &str, args: &[&str]) -> Result<Bg, String> {
    spawn_with(name, args, None, true)
}

fn spawn_with(
    name: &str,
    args: &[&str],
    dir: Option<&Path>,
    hold_stdin: bool,
) -> Result<Bg, String> {
    let cmd = format!("{name} {}", args.join(" "));
    let mut c = Command::new(tool(name));
    c.args(args)
        .stdin(if hold_stdin {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(d) = dir {
        c.current_dir(d);
    }
    let mut child = c.spawn().or_fail(&cmd)?;
    let stdin = child.stdin.take();
    let stdout = Arc::new(Mutex::new(Vec::new()));
    let stderr = Arc::new(Mutex::new(Vec::new()));
    let readers = vec![
        collect(child.stdout.take().expect("piped"), Arc::clone(&stdout)),
        collect(child.stderr.take().expect("piped"), Arc::clone(&stderr)),
    ];
    Ok(Bg {
        cmd,
        child,
        stdin,
        stdout,
        stderr,
        readers,
    })
}

/// Starts one of this tree's own programs (built beside the test binary,
/// in target/release) like [`spawn`].
pub fn spawn_own(name: &str, args: &[&str], dir: Option<&Path>) -> Result<Bg, String> {
    let bin = std::env::current_exe()
        .or_fail("current_exe")?
        .with_file_name(name);
    let bin = bin.to_str().ok_or("non-UTF-8 path")?.to_string();
    spawn(&bin, args, dir)
}

/// Runs `name args...` to completion (at most [`TOOL_LIMIT`]) and fails
/// unless it exits with status 0.
pub fn run_ok(name: &str, args: &[&str]) -> Result<Output, String> {
    let out = spawn(name, args, None)?.finish(TOOL_LIMIT)?;
    if !out.status.success() {
        return Err(format!(
            "{name} {}: {}: {}",
            args.join(" "),
            out.status,
            out.stderr.trim()
        ));
    }
    Ok(out)
}

impl Bg {
    fn text(buf: &Arc<Mutex<Vec<u8>>>) -> String {
        String::from_utf8_lossy(&buf.lock().unwrap_or_else(|e| e.into_inner())).into_owned()
    }

    /// Sends it signal `sig` (a name kill(1) knows: TERM, KILL, STOP,
    /// CONT) with kill(1).
    pub fn signal(&self, sig: &str) -> Result<(), String> {
        run_ok("kill", &["-s", sig, &self.child.id().to_string()]).map(drop)
    }

    /// Closes its stdin (EOF) if [`spawn_stdin_open`] held it open.
    pub fn close_stdin(&mut self) {
        self.stdin = None;
    }

    /// Waits until its stdout holds `n` lines (or more).
    pub fn wait_lines(&mut self, n: usize) -> Result<(), String> {
        let what = format!("{} to print {n} lines", self.cmd);
        wait_for(TOOL_LIMIT, &what, || {
            if self.stdout_now().lines().count() >= n {
                return Ok(Some(()));
            }
            self.check_alive()?;
            Ok(None)
        })
    }

    /// What the program wrote to stdout so far.
    pub fn stdout_now(&self) -> String {
        Self::text(&self.stdout)
    }

    /// What the program wrote to stderr so far.
    pub fn stderr_now(&self) -> String {
        Self::text(&self.stderr)
    }

    /// Whether the program has exited (it is reaped then; [`Bg::finish`]
    /// still returns its status and output).
    pub fn exited(&mut self) -> bool {
        !matches!(self.child.try_wait(), Ok(None))
    }

    /// Fails if the program has already exited, with its output.
    fn check_alive(&mut self) -> Result<(), String> {
        if let Some(st) = self.child.try_wait().or_fail(&self.cmd)? {
            return Err(format!(
                "{} exited early ({st}): stdout {:?}, stderr {:?}",
                self.cmd,
                Self::text(&self.stdout).trim(),
                Self::text(&self.stderr).trim()
            ));
        }
        Ok(())
    }

    /// Waits until the program is blocked in a receiving system call
    /// (/proc/PID/syscall): its sockets are set up then, and every frame
    /// sent afterwards reaches it.
    pub fn wait_listening(&mut self) -> Result<(), String> {
        let path = PathBuf::from(format!("/proc/{}/syscall", self.child.id()));
        let what = format!("{} to wait for frames", self.cmd);
        wait_for(TOOL_LIMIT, &what, || {
            self.check_alive()?;
            let s = fs::read_to_string(&path).or_fail(path.display())?;
            let nr = s
                .split_whitespace()
                .next()
                .and_then(|n| n.parse::<u32>().ok());
            Ok(nr.filter(|n| WAITING_SYSCALLS.contains(n)).map(drop))
        })
    }

    /// Its one socket, shared (a duplicate of its descriptor,
    /// [`crate::sys::fd_of_process`]): for setting or reading that
    /// socket's options from the test, e.g. the receive buffer of an
    /// observer whose queue must not decide a result. Fails unless it has
    /// exactly one socket open.
    pub fn socket(&self) -> Result<std::os::fd::OwnedFd, String> {
        let dir = PathBuf::from(format!("/proc/{}/fd", self.child.id()));
        let mut socks = Vec::new();
        for e in fs::read_dir(&dir).or_fail(dir.display())? {
            let e = e.or_fail(dir.display())?;
            let to = fs::read_link(e.path()).or_fail(e.path().display())?;
            if to.to_string_lossy().starts_with("socket:") {
                socks.push(e.file_name().to_string_lossy().into_owned());
            }
        }
        let [fd] = &socks[..] else {
            return Err(format!("{}: sockets {socks:?}, want one", self.cmd));
        };
        let n = fd
            .parse()
            .map_err(|e| format!("{}: fd {fd}: {e}", self.cmd))?;
        crate::sys::fd_of_process(self.child.id(), n)
            .or_fail(format!("pidfd_getfd of {}'s fd {n}", self.cmd))
    }

    /// Waits until stderr contains `text`.
    pub fn wait_stderr(&mut self, text: &str) -> Result<(), String> {
        let what = format!("{} to print {text:?}", self.cmd);
        wait_for(TOOL_LIMIT, &what, || {
            if self.stderr_now().contains(text) {
                return Ok(Some(()));
            }
            self.check_alive()?;
            Ok(None)
        })
    }

    /// What the program is doing, for a failure message: its scheduler
    /// state, the CPU seconds it has used and the system call it sleeps
    /// in, from `/proc/PID/stat` and `/proc/PID/syscall`. A slow program
    /// reads `R` (running) with CPU seconds near the wall-clock ones; one
    /// that waits forever reads `S` in the same system call.
    pub fn activity(&self) -> String {
        let pid = self.child.id();
        format!("pid {pid}: {}", task_activity(&format!("/proc/{pid}")))
    }

    /// Waits up to `limit` for the program to exit on its own; kills it and
    /// fails (with its output and [`Bg::activity`]) if it does not.
    pub fn finish(mut self, limit: Duration) -> Result<Output, String> {
        let waited = wait_for(limit, &format!("{} to exit", self.cmd), || {
            self.child.try_wait().or_fail(&self.cmd)
        });
        let status = match waited {
            Ok(st) => st,
            Err(e) => {
                let e = format!("{e} ({})", self.activity());
                let _ = self.child.kill();
                let _ = self.child.wait();
                self.join_readers();
                return Err(format!(
                    "{e}; stdout {:?}, stderr {:?}",
                    Self::text(&self.stdout).trim(),
                    Self::text(&self.stderr).trim()
                ));
            }
        };
        self.join_readers();
        Ok(Output {
            status,
            stdout: Self::text(&self.stdout),
            stderr: Self::text(&self.stderr),
        })
    }

    fn join_readers(&mut self) {
        for r in self.readers.drain(..) {
            let _ = r.join();
        }
    }
}

impl Drop for Bg {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The `stat` fields of the task at `dir` (`/proc/PID` or
/// `/proc/PID/task/TID`) after its parenthesised name (the state is the
/// first), and its name; `None` if it is gone.
fn task_stat(dir: &str) -> Option<(String, Vec<String>)> {
    let stat = fs::read_to_string(format!("{dir}/stat")).ok()?;
    let (head, rest) = stat.rsplit_once(')')?;
    let comm = head.split_once('(').map_or("?", |(_, c)| c).to_string();
    Some((comm, rest.split_whitespace().map(str::to_string).collect()))
}

/// What the task at `dir` (`/proc/PID` or `/proc/PID/task/TID`) is
/// doing: its scheduler state, the CPU seconds it has used and the
/// system call it sleeps in (`stat`, `syscall`). One that waits forever
/// reads `S` or `D` in the same system call; a slow one `R` with CPU
/// seconds near the wall-clock ones.
pub fn task_activity(dir: &str) -> String {
    let Some((_, f)) = task_stat(dir) else {
        return "no /proc entry".into();
    };
    // utime and stime: the 12th and 13th fields after the name (clock
    // ticks, 100 Hz).
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    let cpu = (ticks(11) + ticks(12)) as f64 / 100.0;
    let sc = fs::read_to_string(format!("{dir}/syscall")).unwrap_or_default();
    format!(
        "state {}, {cpu:.1} CPU s, syscall {}",
        f.first().map_or("?", String::as_str),
        sc.split_whitespace().next().unwrap_or("?")
    )
}

/// Where in the kernel the task at `dir` waits: its wait channel
/// (`wchan`) and the innermost frames of its kernel stack (`stack`, root
/// only, where the kernel keeps stack traces), offsets cut.
fn task_kernel_place(dir: &str) -> String {
    let wchan = fs::read_to_string(format!("{dir}/wchan")).unwrap_or_default();
    let stack = fs::read_to_string(format!("{dir}/stack")).unwrap_or_default();
    let frames: Vec<&str> = stack
        .lines()
        .filter_map(|l| l.split_whitespace().nth(1))
        .map(|f| f.split_once('+').map_or(f, |(name, _)| name))
        .take(8)
        .collect();
    let wchan = match wchan.trim() {
        "" | "0" => "-",
        w => w,
    };
    if frames.is_empty() {
        format!("wchan {wchan}")
    } else {
        format!("wchan {wchan}, kernel stack {}", frames.join(" < "))
    }
}

/// What every thread of this process, and every process it started (and
/// theirs), is doing: one line each with its [`task_activity`] and its
/// place in the kernel. The VM runner's watchdog prints it for a test
/// that hangs, so that the report names the call and the kernel
/// function it waits in, not only the test.
pub fn hang_report() -> Vec<String> {
    let me = std::process::id();
    let mut lines = Vec::new();
    let mut pids = vec![me];
    let mut i = 0;
    // Descendants, breadth first (a tool's shell and what it runs).
    while let Some(&pid) = pids.get(i) {
        i += 1;
        let Ok(dir) = fs::read_dir("/proc") else { break };
        for e in dir.flatten() {
            let Some(child) = e.file_name().to_str().and_then(|n| n.parse::<u32>().ok()) else {
                continue;
            };
            // The parent's pid: the 2nd field after the name.
            let parent = task_stat(&format!("/proc/{child}"))
                .and_then(|(_, f)| f.get(1).and_then(|p| p.parse::<u32>().ok()));
            if parent == Some(pid) && !pids.contains(&child) {
                pids.push(child);
            }
        }
    }
    for pid in pids {
        let Ok(tasks) = fs::read_dir(format!("/proc/{pid}/task")) else {
            continue;
        };
        let mut tids: Vec<u32> = tasks
            .flatten()
            .filter_map(|e| e.file_name().to_str().and_then(|n| n.parse().ok()))
            .collect();
        tids.sort();
        for tid in tids {
            let dir = format!("/proc/{pid}/task/{tid}");
            let comm = task_stat(&dir).map_or_else(|| "?".into(), |(c, _)| c);
            lines.push(format!(
                "pid {pid} tid {tid} ({comm}): {}, {}",
                task_activity(&dir),
                task_kernel_place(&dir)
            ));
        }
    }
    lines
}

/// A scratch directory in the guest's writable /tmp, removed when dropped.
pub struct TempDir(PathBuf);

impl TempDir {
    /// Creates `/tmp/rcan-vmtest-TAG-PID`, empty.
    pub fn new(tag: &str) -> Result<Self, String> {
        let p = std::env::temp_dir().join(format!("rcan-vmtest-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&p);
        fs::create_dir_all(&p).or_fail(p.display())?;
        Ok(Self(p))
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A program that waits reads `S` in its system call; one that
    /// computes reads `R` with CPU seconds. The failure message of a bound
    /// that runs out tells the two apart by this.
    #[test]
    fn activity_tells_waiting_from_running() {
        let sleeper = spawn("sleep", &["30"], None).expect("sleep");
        let waiting = wait_for(TOOL_LIMIT, "sleep to block", || {
            let a = sleeper.activity();
            Ok(a.contains("state S, ").then_some(a))
        })
        .expect("sleep never blocked");
        // clock_nanosleep, x86_64 system call 230.
        assert!(waiting.ends_with("syscall 230"), "{waiting}");
        let spinner = spawn("sh", &["-c", "while :; do :; done"], None).expect("sh");
        let running = wait_for(TOOL_LIMIT, "sh to use CPU time", || {
            let a = spinner.activity();
            Ok((a.contains("state R, ") && !a.contains(" 0.0 CPU s")).then_some(a))
        })
        .expect("the busy loop never ran");
        assert!(running.ends_with("syscall running"), "{running}");
    }

    /// The hang report names every thread of the process and the programs
    /// it started, each with the system call it waits in: a thread blocked
    /// on a channel waits in futex, a child `sleep` in clock_nanosleep.
    #[test]
    fn hang_report_names_threads_and_children() {
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let waiter = std::thread::Builder::new()
            .name("hang-waiter".into())
            .spawn(move || rx.recv())
            .expect("thread");
        let sleeper = spawn("sleep", &["30"], None).expect("sleep");
        let report = wait_for(TOOL_LIMIT, "the thread and sleep to block", || {
            let r = hang_report();
            let blocked = |what: &str, nr: &str| {
                r.iter().any(|l| l.contains(what) && l.contains("state S") && l.contains(&format!("syscall {nr},")))
            };
            // futex is x86_64 system call 202, clock_nanosleep 230.
            Ok((blocked("(hang-waiter)", "202") && blocked("(sleep)", "230")).then_some(r))
        })
        .expect("no report line for the blocked thread and child");
        assert!(
            report.iter().any(|l| l.contains(&format!("pid {}", sleeper.child.id()))),
            "{report:?}"
        );
        drop(tx);
        let _ = waiter.join();
    }
}
