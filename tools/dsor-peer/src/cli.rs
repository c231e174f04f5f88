// SPDX-License-Identifier: GPL-2.0
//! The command line of `dsor-peer` (Documentation/networking/rcan/dsor-peer.rst),
//! apart from the program so that `rcan-mangen` builds its man page and
//! shell completions from the same definition. Options may come in any
//! order, before or after MODE; which options a mode needs is checked by
//! [`Cli::args`], with clap's usage error (exit 2) when one is missing.

use crate::node::Config;
use crate::wire::{parse_ipv4, Kind, FD_LONG_LENS};
use clap::error::ErrorKind;
use clap::{CommandFactory, Parser, ValueEnum};

/// A DSOR node in user space over a CAN_RAW socket, written from the DSOR
/// wire specification alone (Documentation/networking/rcan/dsor-wire.rst),
/// to test rcan's DSOR against an independent implementation.
///
/// Numbers are decimal or 0x hexadecimal. recv and echo exit 0 once K
/// messages arrived, 1 after --timeout-s; send exits 0 if every message
/// succeeded, 1 otherwise; 2 is a usage error, 3 a socket error.
#[derive(Parser, Debug)]
#[command(name = "dsor-peer", version, about, long_about)]
pub struct Cli {
    /// What the node does.
    #[arg(value_enum)]
    pub mode: ModeName,
    /// The CAN interface.
    #[arg(long = "if", value_name = "IFACE")]
    pub ifname: String,
    /// Own node number, 0 to 0x7f.
    #[arg(long, value_name = "N", value_parser = num_max::<0x7f>)]
    pub node: u64,
    /// T_ack: time to wait for an ack before retransmitting [default: 100].
    #[arg(long, value_name = "MS", value_parser = num)]
    pub ack_timeout_ms: Option<u64>,
    /// N_retx: retransmissions before a send fails, up to 1000 [default: 10].
    #[arg(long, value_name = "N", value_parser = num_max::<1000>)]
    pub retx: Option<u64>,
    /// T_reasm: how long a partial message is kept [default: 2000].
    #[arg(long, value_name = "MS", value_parser = num)]
    pub reasm_ms: Option<u64>,
    /// Drop that percentage (0 to 100, may be fractional) of the frames
    /// this node sends, chosen by a generator seeded with --seed.
    #[arg(long, value_name = "PERCENT", value_parser = percent)]
    pub drop: Option<f64>,
    /// Seed of the --drop generator.
    #[arg(long, value_name = "S", value_parser = num, default_value = "0")]
    pub seed: u64,
    /// After the mode's work, keep answering this long [default: 0, or
    /// 3000 with --drop].
    #[arg(long, value_name = "MS", value_parser = num)]
    pub linger_ms: Option<u64>,
    /// Longest message accepted; longer ones are answered TOO_LONG
    /// [default: 65535].
    #[arg(long, value_name = "L", value_parser = num_max::<65535>)]
    pub max_len: Option<u64>,
    /// Concurrent reassemblies per source node; more are answered
    /// NO_MEMORY [default: 16].
    #[arg(long, value_name = "N", value_parser = num)]
    pub max_per_peer: Option<u64>,
    /// Buffered bytes in all; more are answered NO_MEMORY [default: 1048560].
    #[arg(long, value_name = "B", value_parser = num)]
    pub max_bytes: Option<u64>,
    /// Log every frame received, sent and dropped on stderr as ID#DATA
    /// (ID##DATA for CAN FD frames).
    #[arg(long)]
    pub verbose: bool,
    /// Be a classic node even on an interface in CAN FD mode (MTU 72): no
    /// FD header offered, FD frames not read (no CAN_RAW_FD_FRAMES).
    #[arg(long)]
    pub classic: bool,
    /// On an interface in CAN FD mode: the largest body size offered and
    /// accepted, 12, 16, 20, 24, 32, 48 or 64 [default: 64].
    #[arg(long, value_name = "B", value_parser = fd_body, conflicts_with = "classic")]
    pub fd_body: Option<u8>,
    /// Messages to receive (recv, echo) or send (send) [send's default: 1].
    #[arg(long, value_name = "K", value_parser = num)]
    pub count: Option<u64>,
    /// recv, echo: give up after this many seconds.
    #[arg(long, value_name = "S", value_parser = num, default_value = "30")]
    pub timeout_s: u64,
    /// recv: answer every header REFUSED.
    #[arg(long, help_heading = "recv")]
    pub refuse: bool,
    /// recv: the application keeps at most N messages and never reads
    /// them; later complete messages are refused NO_MEMORY.
    #[arg(long, value_name = "N", value_parser = num, help_heading = "recv")]
    pub app_queue: Option<u64>,
    /// recv: the application goes away after F new body frames.
    #[arg(long, value_name = "F", value_parser = num, help_heading = "recv",
          conflicts_with = "close_after_ms")]
    pub close_after_frames: Option<u64>,
    /// recv: the application goes away MS after the first accepted header.
    #[arg(long, value_name = "MS", value_parser = num, help_heading = "recv")]
    pub close_after_ms: Option<u64>,
    /// send: the destination node, 0 to 0x7f.
    #[arg(long, value_name = "NODE", value_parser = num_max::<0x7f>, help_heading = "send")]
    pub to: Option<u64>,
    /// send: the priority, 0 to 0xff.
    #[arg(long, value_name = "P", value_parser = num_max::<0xff>, help_heading = "send")]
    pub prio: Option<u64>,
    /// send: segmented messages with this message id.
    #[arg(long, value_name = "ID", value_parser = num_max::<0xffff_ffff>, help_heading = "send",
          group = "kind")]
    pub segm: Option<u64>,
    /// send: port messages between these sub-ports.
    #[arg(long, value_name = "DPORT:SPORT", value_parser = port, help_heading = "send",
          group = "kind")]
    pub port: Option<(u8, u8)>,
    /// send: UDP messages to this port of this IPv4 address.
    #[arg(long, value_name = "DPORT:A.B.C.D", value_parser = udp, help_heading = "send",
          group = "kind")]
    pub udp: Option<(u16, u32)>,
    /// send: bytes per message.
    #[arg(long, value_name = "L", value_parser = num, help_heading = "send")]
    pub len: Option<u64>,
    /// send: byte i of message j is (i*31 + j*7 + SEED) & 0xff.
    #[arg(long, value_name = "SEED", value_parser = num, default_value = "0",
          help_heading = "send")]
    pub pattern: u64,
    /// send: messages in flight at once, on different channels, 1 to 16.
    #[arg(long, value_name = "W", value_parser = num_max::<16>, default_value = "1",
          help_heading = "send")]
    pub window: u64,
}

/// The three modes.
#[derive(Clone, Copy, PartialEq, Eq, Debug, ValueEnum)]
pub enum ModeName {
    /// Receive --count messages.
    Recv,
    /// Send --count messages of --len bytes to node --to.
    Send,
    /// Receive --count messages and send each back to its source.
    Echo,
}

/// What the node does, checked.
#[derive(Clone, Copy, PartialEq, Debug)]
pub enum Mode {
    /// Receive.
    Recv,
    /// Send.
    Send {
        /// Destination node.
        to: u8,
        /// Priority.
        prio: u8,
        /// Kind and address of the messages.
        kind: Kind,
        /// Bytes per message.
        len: usize,
        /// Pattern seed.
        seed: u64,
        /// Messages in flight.
        window: usize,
    },
    /// Echo.
    Echo,
}

/// The whole configuration of a run.
#[derive(Clone, Debug)]
pub struct Args {
    /// The CAN interface.
    pub ifname: String,
    /// The protocol configuration.
    pub cfg: Config,
    /// Percentage of sent frames dropped.
    pub drop_pct: f64,
    /// Seed of the drop generator.
    pub seed: u64,
    /// Linger after the work.
    pub linger_ms: Option<u64>,
    /// Log frames.
    pub verbose: bool,
    /// A classic node whatever the interface's MTU.
    pub classic: bool,
    /// Messages to receive or send.
    pub count: u64,
    /// Give up after this long.
    pub timeout_s: u64,
    /// The mode.
    pub mode: Mode,
}

/// A number, decimal or 0x hexadecimal.
pub fn num(s: &str) -> Result<u64, String> {
    match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u64::from_str_radix(h, 16),
        None => s.parse(),
    }
    .map_err(|_| format!("not a number: {s}"))
}

/// A number up to `MAX`.
pub fn num_max<const MAX: u64>(s: &str) -> Result<u64, String> {
    num(s).and_then(|v| {
        if v > MAX {
            Err(format!("{s} above {MAX:#x}"))
        } else {
            Ok(v)
        }
    })
}

fn percent(s: &str) -> Result<f64, String> {
    s.parse()
        .ok()
        .filter(|p| (0.0..=100.0).contains(p))
        .ok_or_else(|| "wants 0..100".to_string())
}

fn fd_body(s: &str) -> Result<u8, String> {
    let b = num_max::<64>(s)? as usize;
    if FD_LONG_LENS.contains(&b) {
        Ok(b as u8)
    } else {
        Err("wants 12, 16, 20, 24, 32, 48 or 64".to_string())
    }
}

fn port(s: &str) -> Result<(u8, u8), String> {
    let (d, p) = s.split_once(':').ok_or("wants DPORT:SPORT")?;
    Ok((num_max::<0xff>(d)? as u8, num_max::<0xff>(p)? as u8))
}

fn udp(s: &str) -> Result<(u16, u32), String> {
    let (p, a) = s.split_once(':').ok_or("wants DPORT:A.B.C.D")?;
    let a = parse_ipv4(a).ok_or("bad IPv4 address")?;
    Ok((num_max::<0xffff>(p)? as u16, a))
}

fn missing(what: &str) -> clap::Error {
    Cli::command().error(
        ErrorKind::MissingRequiredArgument,
        format!("{what} is required"),
    )
}

impl Cli {
    /// The checked configuration, or clap's usage error for what the mode
    /// lacks.
    pub fn args(&self) -> Result<Args, clap::Error> {
        let mut cfg = Config::new(self.node as u8);
        if let Some(v) = self.ack_timeout_ms {
            cfg.t_ack = v.max(1);
        }
        if let Some(v) = self.retx {
            cfg.n_retx = v as u32;
        }
        if let Some(v) = self.reasm_ms {
            cfg.t_reasm = v;
        }
        if let Some(v) = self.max_len {
            cfg.max_len = v as u16;
        }
        if let Some(v) = self.max_per_peer {
            cfg.max_per_peer = v as usize;
        }
        if let Some(v) = self.max_bytes {
            cfg.max_bytes_total = v as usize;
        }
        cfg.refuse = self.refuse;
        cfg.app_queue = self.app_queue.map(|v| v as usize);
        cfg.close_after_frames = self.close_after_frames;
        cfg.close_after_ms = self.close_after_ms;
        // cfg.fd is the interface's mode, decided when the socket opens.
        if let Some(b) = self.fd_body {
            cfg.fd_b_max = b;
        }
        let mode = match self.mode {
            ModeName::Recv => Mode::Recv,
            ModeName::Echo => Mode::Echo,
            ModeName::Send => Mode::Send {
                to: self.to.ok_or_else(|| missing("--to"))? as u8,
                prio: self.prio.ok_or_else(|| missing("--prio"))? as u8,
                kind: match (self.segm, self.port, self.udp) {
                    (Some(id), None, None) => Kind::Segm { id: id as u32 },
                    (None, Some((dport, sport)), None) => Kind::Port { dport, sport },
                    (None, None, Some((dport, daddr))) => Kind::Udp { dport, daddr },
                    _ => return Err(missing("one of --segm, --port, --udp")),
                },
                len: self.len.ok_or_else(|| missing("--len"))? as usize,
                seed: self.pattern,
                window: self.window.max(1) as usize,
            },
        };
        let count = match (self.count, self.mode) {
            (Some(k), _) => k,
            (None, ModeName::Send) => 1,
            (None, _) => return Err(missing("--count")),
        };
        Ok(Args {
            ifname: self.ifname.clone(),
            cfg,
            drop_pct: self.drop.unwrap_or(0.0),
            seed: self.seed,
            linger_ms: self.linger_ms,
            verbose: self.verbose,
            classic: self.classic,
            count,
            timeout_s: self.timeout_s,
            mode,
        })
    }
}

/// The command definition, for man pages and completions.
pub fn command() -> clap::Command {
    Cli::command()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &str) -> Result<Args, String> {
        Cli::try_parse_from(a.split_whitespace())
            .and_then(|c| c.args())
            .map_err(|e| e.to_string())
    }

    #[test]
    fn modes_and_checks() {
        command().debug_assert();
        let a = args("dsor-peer --if can0 --node 5 --ack-timeout-ms 0 recv --count 3").unwrap();
        assert_eq!(
            (a.cfg.node, a.cfg.t_ack, a.count, a.mode),
            (5, 1, 3, Mode::Recv)
        );
        // Options after and before the mode.
        let a = args("dsor-peer send --to 0 --if can0 --prio 0x80 --port 1:2 --len 9 --node 5")
            .unwrap();
        assert_eq!(
            a.mode,
            Mode::Send {
                to: 0,
                prio: 0x80,
                kind: Kind::Port { dport: 1, sport: 2 },
                len: 9,
                seed: 0,
                window: 1
            }
        );
        assert_eq!(a.count, 1);
        for bad in [
            "dsor-peer --if can0 --node 0x80 recv --count 1",
            "dsor-peer --if can0 --node 5 recv",
            "dsor-peer --if can0 --node 5 send --to 0 --prio 0 --len 1",
            "dsor-peer --if can0 --node 5 send --to 0 --prio 0 --len 1 --segm 1 --port 1:2",
            "dsor-peer --if can0 --node 5 send --to 0 --prio 0 --len 1 --udp 1:1.2.3",
            "dsor-peer --if can0 --node 5 --drop 101 echo --count 1",
            "dsor-peer --if can0 --node 5 --window 17 send --to 0 --prio 0 --len 1 --segm 1",
            "dsor-peer --if can0 recv --count 1",
        ] {
            assert!(args(bad).is_err(), "{bad}");
        }
    }
}
