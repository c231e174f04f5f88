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
SIGTERM and SIGINT flush, close the file and exit with status 0."
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

/// Serve CAN interfaces to TCP clients with the socketcand protocol (raw
/// mode): python-can's `socketcand` interface and other socketcand
/// clients connect unchanged.
#[derive(Parser, Debug)]
#[command(name = "cantcpd", version)]
#[command(
    after_help = "Protocol: the server greets with `< hi >`; the client sends \
`< open IFACE >` and `< rawmode >` (each answered `< ok >`), then `< send ID DLC B0 B1 ... >` \
to transmit; every frame on IFACE reaches the client as `< frame ID SEC.USEC DATA >`. \
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
    }
}
