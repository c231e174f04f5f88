// SPDX-License-Identifier: GPL-2.0
//! Command lines of the daemons, shared with tools/mangen (man pages and
//! completions come from these definitions).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::{CommandFactory, Parser};

/// Log every CAN frame of one or more interfaces into rotating gzip files
/// (candump -l format): the vehicle's black box.
#[derive(Parser, Debug)]
#[command(name = "canzlogd", version)]
#[command(
    after_help = "Files are DIR/PREFIX-<unix seconds>-<sequence>.log.gz, each a series of \
gzip members; `zcat FILE` gives candump -l lines, `# ` lines are canzlogd's notes (dropped \
frames, start, stop), which canplayer and log2asc skip.\n\nFlush policy: received lines are \
kept in memory for at most --flush-ms milliseconds, then written as one complete gzip member \
and fdatasync'ed: a SIGKILL, crash or power loss loses at most the last --flush-ms of traffic.\n\n\
SIGTERM and SIGINT log the frames already queued, flush, close the file and exit with status 0."
)]
pub struct ZlogCli {
    /// CAN interfaces to log (one CAN_RAW socket each).
    #[arg(required = true, value_name = "IFACE")]
    pub ifaces: Vec<String>,
    /// Directory for the log files (created if missing).
    #[arg(short, long, default_value = "/var/log/canzlogd")]
    pub dir: PathBuf,
    /// File name prefix.
    #[arg(short, long, default_value = "canzlog")]
    pub prefix: String,
    /// Most milliseconds a received frame waits in memory before it is on
    /// disk (one gzip member per flush).
    #[arg(short = 'f', long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    pub flush_ms: u64,
    /// Start a new file once the current one has this many bytes
    /// (compressed).
    #[arg(short = 's', long, default_value_t = 16 << 20)]
    pub max_size: u64,
    /// Start a new file once the current one is this many seconds old.
    #[arg(short = 'a', long, default_value_t = 3600, value_parser = clap::value_parser!(u64).range(1..))]
    pub max_age: u64,
    /// gzip compression level (0-9). 1 is the default: about 9 % larger
    /// files than 6 for three times less CPU (canzlogd.rst, Measurements).
    #[arg(short = 'l', long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=9))]
    pub level: u32,
    /// Do not fdatasync after each member (survives a crash of the
    /// daemon, not a power loss).
    #[arg(long)]
    pub no_fsync: bool,
    /// Do not log error frames (by default CAN_RAW_ERR_FILTER is
    /// CAN_ERR_MASK: all error classes).
    #[arg(long)]
    pub no_errors: bool,
    /// SO_RCVBUF of each socket in bytes (the kernel doubles it, capped by
    /// net.core.rmem_max); default: the system's.
    #[arg(long)]
    pub rcvbuf: Option<usize>,
}

/// Serve CAN interfaces to TCP clients with the socketcand protocol (BCM
/// and raw mode): python-can's `socketcand` interface and other
/// socketcand clients connect unchanged.
#[derive(Parser, Debug)]
#[command(name = "cantcpd", version)]
#[command(
    after_help = "Protocol: the server greets with `< hi >`; the client sends \
`< open IFACE >` (answered `< ok >`) and is in BCM mode (a CAN_BCM socket): \
`< send ID DLC B0 ... >` transmits once, `< add SEC USEC ID DLC B0 ... >` cyclically, \
`< update ID DLC B0 ... >` changes a job's content, `< delete ID >` ends it; \
`< subscribe SEC USEC ID >` and `< filter SEC USEC ID DLC M0 ... >` deliver frames of ID \
(every one, or those changing under the mask) as `< frame ID SEC.USEC B0 B1 ... >`; \
`< unsubscribe ID >` ends that. `< rawmode >` switches to raw mode (every frame on IFACE \
as `< frame ID SEC.USEC DATA >`, `send` as before), `< bcmmode >` back. \
Frames sent by one client reach the others like any frame on the bus.\n\nEach client has its \
own queue of --queue frames: a client that reads too slowly loses frames (counted, reported \
on stderr and as `< error dropped N >`), never stalls the bus or other clients.\n\nSIGTERM and \
SIGINT close every connection and exit with status 0."
)]
pub struct TcpCli {
    /// Address and port to listen on; loopback unless told otherwise.
    #[arg(short, long, default_value = "127.0.0.1:29536")]
    pub listen: SocketAddr,
    /// Frames queued per client before new ones are dropped for it.
    #[arg(short, long, default_value_t = 1024, value_parser = clap::value_parser!(u64).range(1..))]
    pub queue: u64,
    /// Interfaces clients may open (default: any CAN interface).
    #[arg(short, long = "allow", value_name = "IFACE")]
    pub allow: Vec<String>,
    /// SO_SNDBUF of each client connection in bytes (the kernel doubles
    /// it); with --queue it bounds what a client that stops reading can
    /// hold. Default: the system's (TCP autotuning, up to megabytes).
    #[arg(long)]
    pub sndbuf: Option<usize>,
    /// Most clients at once; more are refused.
    #[arg(short, long, default_value_t = 16)]
    pub max_clients: usize,
}

/// Wait for the CAN frame that commands an orderly shutdown, then stop
/// the programs that write the log partition, sync and unmount it.
#[derive(Parser, Debug)]
#[command(name = "powerd", version)]
#[command(
    after_help = "The shutdown frame: a data frame on IFACE with identifier --id (hex; \
extended when written with 8 digits or above 7FF) whose first bytes equal --data under \
--mask (a frame may be longer). Other frames are ignored.\n\nThe sequence, in this order, \
each step on stderr: send --signal to every process named by --pidfile (the pid in the file) \
and --name (every process whose /proc/PID/comm is NAME); wait up to --wait-ms for them to \
exit; sync(2); unmount each --umount directory (retrying while it is busy, until --wait-ms \
has passed since the signals); run --exec with /bin/sh -c. Exit status 0 if every step \
succeeded, 1 otherwise.\n\n--dry-run prints the steps it would take and does none.\n\n\
SIGTERM and SIGINT before the frame end powerd with status 0 and nothing done."
)]
pub struct PowerCli {
    /// CAN interface to listen on.
    #[arg(value_name = "IFACE")]
    pub iface: String,
    /// Identifier of the shutdown frame (hex).
    #[arg(short, long, value_parser = crate::powerd::parse_id)]
    pub id: u32,
    /// Data the frame must begin with (hex bytes, `.` separators allowed).
    #[arg(short, long, default_value = "", value_parser = hex_bytes)]
    pub data: HexBytes,
    /// Mask of --data (same length; 1 bits are compared). Default: all.
    #[arg(short, long, value_parser = hex_bytes)]
    pub mask: Option<HexBytes>,
    /// Signal the process whose pid this file holds (repeatable).
    #[arg(long, value_name = "FILE")]
    pub pidfile: Vec<std::path::PathBuf>,
    /// Signal every process of this name, as in /proc/PID/comm
    /// (repeatable).
    #[arg(long, value_name = "NAME")]
    pub name: Vec<String>,
    /// The signal to send them.
    #[arg(short, long, default_value = "SIGTERM", value_parser = parse_signal)]
    pub signal: nix::sys::signal::Signal,
    /// How long to wait for the signalled programs to exit and for a busy
    /// mount to become free, in milliseconds.
    #[arg(short, long, default_value_t = 5000)]
    pub wait_ms: u64,
    /// Do not call sync(2).
    #[arg(long)]
    pub no_sync: bool,
    /// Unmount this directory (repeatable; in the order given).
    #[arg(short, long, value_name = "DIR")]
    pub umount: Vec<std::path::PathBuf>,
    /// Finally run this command with /bin/sh -c (for example `systemctl
    /// poweroff`).
    #[arg(short, long, value_name = "COMMAND")]
    pub exec: Option<String>,
    /// Print the steps on the frame, do none of them.
    #[arg(short = 'n', long)]
    pub dry_run: bool,
}

/// Bytes given in hex on the command line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HexBytes(pub Vec<u8>);

fn hex_bytes(s: &str) -> Result<HexBytes, String> {
    crate::powerd::parse_bytes(s).map(HexBytes)
}

/// `TERM`, `SIGTERM`, `15`, ...
fn parse_signal(s: &str) -> Result<nix::sys::signal::Signal, String> {
    use nix::sys::signal::Signal;
    if let Ok(n) = s.parse::<i32>() {
        return Signal::try_from(n).map_err(|_| format!("no signal {n}"));
    }
    let name = if s.starts_with("SIG") {
        s.to_string()
    } else {
        format!("SIG{s}")
    };
    name.parse::<Signal>().map_err(|_| format!("no signal {s}"))
}

/// Log DSOR segmented messages from the given node/id pairs, one line
/// each, with timestamps.
#[derive(Parser, Debug)]
#[command(name = "logd", version)]
#[command(
    after_help = "SOURCE is NODE:ID, each decimal, 0x hexadecimal or `any` (the DSOR \
wildcards): the messages with identifier ID from node NODE (one CANPROTO_DSOR socket bound \
to each; overlapping sources log a message once per matching source).\n\nLine format: \
`(SECONDS.MICROSECONDS) NODE ID LEN DATA`: the time logd read the message, the source node \
(2 hex digits), the message identifier (8 hex digits), the length in decimal and the bytes in \
lower-case hex (`-` when empty). `# ` lines are logd's notes. Each line is appended with one \
write(2) to a file opened O_APPEND, so a crash never leaves half a line; --fsync makes each \
line durable before the next message is read.\n\nThe DSOR node and interface are the \
rcan_dsor module's (`node=`, `ifname=`).\n\nSIGTERM and SIGINT end logd with status 0."
)]
pub struct LogdCli {
    /// The sources, NODE:ID.
    #[arg(required = true, value_name = "SOURCE", value_parser = crate::logd::parse_source)]
    pub sources: Vec<(u8, u32)>,
    /// The log file (created if missing, appended to).
    #[arg(short, long, default_value = "/var/log/logd/dsor.log")]
    pub log: std::path::PathBuf,
    /// fdatasync after every line.
    #[arg(long)]
    pub fsync: bool,
    /// Longest message logged whole; longer ones are logged cut to this
    /// length with a note.
    #[arg(long, default_value_t = 65535, value_parser = clap::value_parser!(u64).range(1..=65535))]
    pub max_len: u64,
}

/// powerd's command, for tools/mangen.
pub fn power_command() -> clap::Command {
    PowerCli::command()
}

/// logd's command, for tools/mangen.
pub fn logd_command() -> clap::Command {
    LogdCli::command()
}

/// canzlogd's command, for tools/mangen.
pub fn zlog_command() -> clap::Command {
    ZlogCli::command()
}

/// cantcpd's command, for tools/mangen.
pub fn tcp_command() -> clap::Command {
    TcpCli::command()
}

#[cfg(test)]
mod tests {
    #[test]
    fn commands_are_consistent() {
        super::zlog_command().debug_assert();
        super::tcp_command().debug_assert();
        super::power_command().debug_assert();
        super::logd_command().debug_assert();
    }
}
