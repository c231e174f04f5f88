// SPDX-License-Identifier: GPL-2.0
//! The command line of `rcan-bench`: one clap definition ([`Cli`]), the
//! environment the defaults come from ([`Env`]) and the settings both
//! make ([`Config`], one per run). Values keep the syntax of the
//! hand-written parser this replaces (issue 21, item 4): comma lists with
//! blanks around items allowed, `_` in numbers, hex `can_id`s, the last of
//! a repeated option wins, a value may start with `-`.

use std::path::PathBuf;

use clap::error::{ContextKind, ContextValue, ErrorKind};
use clap::{CommandFactory, Parser};

use crate::stack::{Paths, Proto, Stack};
use crate::{isotp, table, workload};

/// Benchmark rcan against mainline SocketCAN inside the test VM (run as
/// root; `make bench` or tools/testing/rcan/bench.sh): the CAN_RAW receive
/// path (raw), many sockets (table), DSOR against ISO-TP (dsor) and, on
/// request, CAN_BCM cyclic jobs (bcm) and CAN FD frames (fd). See
/// Documentation/networking/rcan/benchmarks.rst.
#[derive(Parser, Debug)]
#[command(name = "rcan-bench", version, long_about = None, args_override_self = true)]
#[command(
    after_help = "Environment: RCAN_KBUILD (test kernel build directory: mainline modules),\nRCAN_ROOT (project tree with our modules; default the current directory),\nRCAN_OUT (directory for the summary)."
)]
pub struct Cli {
    /// Parts to run, comma-separated: raw (CAN_RAW, mainline vs ours), table (many sockets, mainline vs ours), dsor (DSOR vs mainline ISO-TP), bcm (CAN_BCM cyclic jobs, mainline vs ours; not in the default), fd (CAN FD frames at MTU 72, mainline vcan vs rcan_loop; not in the default), isotp (CAN_ISOTP, mainline can-isotp vs rcan_isotp; not in the default) (default raw,table,dsor)
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, value_parser = parts)]
    part: Option<[bool; 6]>,
    /// Raw and table parts: mainline, ours or both (default both)
    #[arg(long, value_name = "S", allow_hyphen_values = true, value_parser = stacks)]
    stack: Option<List<Stack>>,
    /// Workloads to run, comma-separated: a|throughput, b|fanout, c|latency (default all)
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, value_parser = workloads)]
    only: Option<[bool; 3]>,
    /// CAN interface (default can0)
    #[arg(long, value_name = "NAME", allow_hyphen_values = true)]
    iface: Option<String>,
    /// Measure the stack already set up on --iface (one --stack only, used as its label); load and unload nothing
    #[arg(long)]
    no_load: bool,
    /// Where our modules are: DIR/net/can/rcan_*.ko, DIR/drivers/net/can/rcan_loop.ko (default: RCAN_ROOT; a relative DIR is taken from the current directory, the project root in the VM)
    #[arg(long, value_name = "DIR", allow_hyphen_values = true)]
    ours_dir: Option<PathBuf>,
    /// Run the workloads on CPU N (default 0), or anywhere
    #[arg(long, value_name = "N|any", allow_hyphen_values = true, value_parser = cpu)]
    cpu: Option<Cpu>,
    /// Throughput: the receiver thread on CPU N (default: --cpu)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<usize>)]
    rx_cpu: Option<usize>,
    /// Rounds (default 5): each loads, measures and unloads every selected stack in turn; mainline first in odd rounds, ours first in even ones
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<usize>)]
    rounds: Option<usize>,
    /// Measured runs per figure and round (default 2); the summary gives the median over all rounds' runs
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<usize>)]
    reps: Option<usize>,
    /// Frames per warm-up run (default 2000)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    warmup: Option<u64>,
    /// Frames per throughput run (default 100000)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    throughput_frames: Option<u64>,
    /// Throughput: frames in flight at most (default 256)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    window: Option<u64>,
    /// Frames per fan-out run (default 50000)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    fanout_frames: Option<u64>,
    /// Receiver counts, comma-separated (default 1,100,1000)
    #[arg(long, value_name = "L", allow_hyphen_values = true, value_parser = nums)]
    fanout_receivers: Option<List<usize>>,
    /// Fan-out: frames sent before reading them back (default 64)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    batch: Option<u64>,
    /// Frames per latency run (default 100000)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    latency_frames: Option<u64>,
    /// DSOR part: protocols, comma-separated: isotp (ISO-TP, default options), isotp0 (ISO-TP, frame_txtime 0), dsor, dsorfd (DSOR with CAN FD bodies, rcan_loop at mtu 72; not in the default) (default isotp,isotp0,dsor)
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, value_parser = protos)]
    proto: Option<List<Proto>>,
    /// DSOR part: message sizes in bytes, 8 to 8300, comma-separated (default 1024,4096)
    #[arg(long, value_name = "L", allow_hyphen_values = true, value_parser = nums)]
    msg_sizes: Option<List<usize>>,
    /// DSOR part: seconds per measured run at least (default 2)
    #[arg(long, value_name = "S", allow_hyphen_values = true, value_parser = num::<f64>)]
    msg_secs: Option<f64>,
    /// DSOR part: messages per measured run at least (default 20)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    msg_min: Option<u64>,
    /// DSOR part: messages per warm-up run (default 5)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    msg_warmup: Option<u64>,
    /// ISO-TP part: PDU sizes in bytes, 8 to 1048576, comma-separated (default 4096,65536); both ISO-TP modules get max_pdu_size = the largest (at least 8300)
    #[arg(long, value_name = "L", allow_hyphen_values = true, value_parser = nums)]
    isotp_sizes: Option<List<usize>>,
    /// ISO-TP part: link layers, comma-separated: classic, fd (default classic,fd)
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, value_parser = links)]
    isotp_links: Option<List<isotp::Link>>,
    /// ISO-TP part: PDUs per spacing run (BS 8, STmin 1 ms) and round, 0 for none (default 2)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<usize>)]
    isotp_spacing_pdus: Option<usize>,
    /// BCM part: cyclic jobs, 1 to 1536 (default 1000)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = bcm_jobs)]
    bcm_jobs: Option<u32>,
    /// BCM part: interval of each job in ms (default 10)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = bcm_ival_ms)]
    bcm_ival_ms: Option<u64>,
    /// BCM part: seconds per measured run (default 3)
    #[arg(long, value_name = "S", allow_hyphen_values = true, value_parser = bcm_secs)]
    bcm_secs: Option<f64>,
    /// Table part: rounds (default 3)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<usize>)]
    table_rounds: Option<usize>,
    /// Table part: socket counts, comma-separated (default 1000,10000)
    #[arg(long, value_name = "L", allow_hyphen_values = true, value_parser = table_sockets)]
    table_sockets: Option<List<usize>>,
    /// Table part: filter kinds, comma-separated: exact (one exact id each), same (all one id), masked (id:7F0), masks (many distinct masks) (default all four)
    #[arg(long, value_name = "L", allow_hyphen_values = true, value_parser = kinds)]
    table_kinds: Option<List<table::Kind>>,
    /// Table part: distinct masks of kind masks (1-255, default 64)
    #[arg(long, value_name = "M", allow_hyphen_values = true, value_parser = table_masks)]
    table_masks: Option<usize>,
    /// Table part: unwanted frames per run (default 6400)
    #[arg(long, value_name = "N", allow_hyphen_values = true, value_parser = num::<u64>)]
    table_frames: Option<u64>,
    /// Table part: seconds per two-sender run (default 2)
    #[arg(long, value_name = "S", allow_hyphen_values = true, value_parser = num::<f64>)]
    table_secs: Option<f64>,
    /// Table part: can_id (hex, flags included) of the frame nobody should want (default 555); another id may be wanted by some kinds, which the run then reports
    #[arg(long, value_name = "X", allow_hyphen_values = true, value_parser = unwanted_id)]
    table_unwanted_id: Option<u32>,
    /// Table part: workloads, comma-separated: sockets (bind, close, unwanted frame, memory), fanout (1000 : 1 receivers), pair (two senders) (default all)
    #[arg(long, value_name = "LIST", allow_hyphen_values = true, value_parser = table_only)]
    table_only: Option<[bool; 3]>,
    /// Table part: the second device (default can1)
    #[arg(long, value_name = "NAME", allow_hyphen_values = true)]
    iface2: Option<String>,
    /// A tenth of the frames, one run each (smoke test)
    #[arg(long)]
    quick: bool,
    /// Also write the summary to FILE (default $RCAN_OUT/bench-summary.txt if RCAN_OUT is set)
    #[arg(long, value_name = "FILE", allow_hyphen_values = true)]
    summary: Option<PathBuf>,
}

/// The value of a comma-separated option. A newtype, not a `Vec` field:
/// clap would take that for an option given several times.
#[derive(Clone, Debug)]
pub struct List<T>(Vec<T>);

/// `--cpu`: `Cpu(None)` is `any`.
#[derive(Clone, Copy, Debug)]
pub struct Cpu(Option<usize>);

/// A number; `_` may group digits (`100_000`).
fn num<T: std::str::FromStr>(v: &str) -> Result<T, String> {
    v.replace('_', "")
        .parse()
        .map_err(|_| format!("bad number '{v}'"))
}

/// The items of a comma-separated list, blanks around them ignored.
fn items<T>(v: &str, item: impl Fn(&str) -> Result<T, String>) -> Result<Vec<T>, String> {
    v.split(',').map(|w| item(w.trim())).collect()
}

/// `items`, each item kept once, in the order first given.
fn set<T: PartialEq>(v: &str, item: impl Fn(&str) -> Result<T, String>) -> Result<List<T>, String> {
    let mut out = Vec::new();
    for x in items(v, item)? {
        if !out.contains(&x) {
            out.push(x);
        }
    }
    Ok(List(out))
}

/// `--part`: which of raw, table, dsor, bcm, fd, isotp.
fn parts(v: &str) -> Result<[bool; 6], String> {
    let mut on = [false; 6];
    for w in items(v, |w| Ok(w.to_string()))? {
        match w.as_str() {
            "raw" => on[0] = true,
            "table" => on[1] = true,
            "dsor" => on[2] = true,
            "bcm" => on[3] = true,
            "fd" => on[4] = true,
            "isotp" => on[5] = true,
            other => return Err(format!("unknown part '{other}'")),
        }
    }
    Ok(on)
}

/// `--only`: which of the workloads (a), (b), (c).
fn workloads(v: &str) -> Result<[bool; 3], String> {
    let mut on = [false; 3];
    for w in items(v, |w| Ok(w.to_string()))? {
        match w.as_str() {
            "a" | "throughput" => on[0] = true,
            "b" | "fanout" | "fan-out" => on[1] = true,
            "c" | "latency" => on[2] = true,
            other => return Err(format!("unknown workload '{other}'")),
        }
    }
    Ok(on)
}

/// `--table-only`: which of sockets, fanout, pair.
fn table_only(v: &str) -> Result<[bool; 3], String> {
    let mut on = [false; 3];
    for w in items(v, |w| Ok(w.to_string()))? {
        match w.as_str() {
            "sockets" => on[0] = true,
            "fanout" => on[1] = true,
            "pair" => on[2] = true,
            other => return Err(format!("unknown workload '{other}'")),
        }
    }
    Ok(on)
}

fn stacks(v: &str) -> Result<List<Stack>, String> {
    Ok(List(match v {
        "mainline" => vec![Stack::Mainline],
        "ours" => vec![Stack::Ours],
        "both" => vec![Stack::Mainline, Stack::Ours],
        other => return Err(format!("want mainline, ours or both, got {other:?}")),
    }))
}

fn protos(v: &str) -> Result<List<Proto>, String> {
    set(v, |w| match w {
        "isotp" => Ok(Proto::Isotp),
        "isotp0" => Ok(Proto::IsotpNoGap),
        "dsor" => Ok(Proto::Dsor),
        "dsorfd" => Ok(Proto::DsorFd),
        other => Err(format!("unknown protocol '{other}'")),
    })
}

fn links(v: &str) -> Result<List<isotp::Link>, String> {
    set(v, |w| match w {
        "classic" => Ok(isotp::Link::Classic),
        "fd" => Ok(isotp::Link::Fd),
        other => Err(format!("unknown link layer '{other}'")),
    })
}

fn kinds(v: &str) -> Result<List<table::Kind>, String> {
    set(v, |w| {
        table::Kind::parse(w).ok_or_else(|| format!("unknown kind '{w}'"))
    })
}

fn nums(v: &str) -> Result<List<usize>, String> {
    items(v, num).map(List)
}

fn table_sockets(v: &str) -> Result<List<usize>, String> {
    let counts = nums(v)?;
    if counts.0.contains(&0) {
        return Err("counts must be at least 1".into());
    }
    Ok(counts)
}

fn table_masks(v: &str) -> Result<usize, String> {
    let n = num(v)?;
    if !(1..=255).contains(&n) {
        return Err("wants 1 to 255".into());
    }
    Ok(n)
}

/// `--table-unwanted-id`: hex, `0x` optional, flags included; not the
/// sentinel's id, whatever the flags.
fn unwanted_id(v: &str) -> Result<u32, String> {
    let hex = v.trim_start_matches("0x").trim_start_matches("0X");
    let id = u32::from_str_radix(hex, 16).map_err(|_| format!("bad hex can_id '{v}'"))?;
    if id & 0x1fff_ffff == table::SENTINEL_ID {
        return Err("that is the sentinel's id".into());
    }
    Ok(id)
}

fn cpu(v: &str) -> Result<Cpu, String> {
    match v {
        "any" => Ok(Cpu(None)),
        n => num(n).map(|n| Cpu(Some(n))),
    }
}

/// `--bcm-jobs`: no `_` in this one, as before.
fn bcm_jobs(v: &str) -> Result<u32, String> {
    v.parse()
        .ok()
        .filter(|n| (1..=0x600).contains(n))
        .ok_or_else(|| "wants 1..1536".into())
}

fn bcm_ival_ms(v: &str) -> Result<u64, String> {
    v.parse()
        .ok()
        .filter(|&n| n > 0)
        .ok_or_else(|| "wants a positive number".into())
}

fn bcm_secs(v: &str) -> Result<f64, String> {
    v.parse()
        .ok()
        .filter(|&n: &f64| n > 0.0)
        .ok_or_else(|| "wants a positive number".into())
}

/// The `clap::Command` of [`Cli`].
pub fn command() -> clap::Command {
    Cli::command()
}

/// The settings of this process's command line. Exits 0 after `--help`
/// and `--version`, 2 after a usage error.
pub fn parse() -> Config {
    Cli::try_parse()
        .and_then(|cli| Config::new(cli, Env::from_process()))
        .unwrap_or_else(|e| with_usage(e).exit())
}

/// `e` with the usage line, which clap leaves off errors in values (`bad
/// number`, `a value is required`): every usage error shows it.
fn with_usage(mut e: clap::Error) -> clap::Error {
    if e.use_stderr() && e.get(ContextKind::Usage).is_none() {
        let usage = command().render_usage();
        e.insert(ContextKind::Usage, ContextValue::StyledStr(usage));
    }
    e
}

/// A usage error found after parsing, in clap's form.
fn usage_error(kind: ErrorKind, msg: &str) -> clap::Error {
    command().error(kind, msg)
}

/// What the defaults take from the process: `RCAN_OUT` (the summary's
/// directory), `RCAN_ROOT` (else the current directory) and `RCAN_KBUILD`;
/// empty variables count as unset.
pub struct Env {
    pub out: Option<PathBuf>,
    pub root: PathBuf,
    pub kbuild: Option<PathBuf>,
}

impl Env {
    pub fn from_process() -> Env {
        let env_path = |k: &str| {
            std::env::var_os(k)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        };
        Env {
            out: env_path("RCAN_OUT"),
            root: env_path("RCAN_ROOT")
                .or_else(|| std::env::current_dir().ok())
                .unwrap_or_else(|| PathBuf::from(".")),
            kbuild: env_path("RCAN_KBUILD"),
        }
    }
}

/// Command line settings.
#[derive(Debug, PartialEq)]
pub struct Config {
    pub run_raw: bool,
    pub run_table: bool,
    pub run_dsor: bool,
    pub run_bcm: bool,
    pub run_fd: bool,
    pub run_isotp: bool,
    pub isotp_sizes: Vec<usize>,
    pub isotp_links: Vec<isotp::Link>,
    pub isotp_spacing_pdus: usize,
    pub bcm_jobs: u32,
    pub bcm_ival_ms: u64,
    pub bcm_secs: f64,
    pub table: table::Config,
    pub protos: Vec<Proto>,
    pub msg_sizes: Vec<usize>,
    pub msg_secs: f64,
    pub msg_min: u64,
    pub msg_warmup: u64,
    pub stacks: Vec<Stack>,
    pub iface: String,
    pub load: bool,
    pub run_a: bool,
    pub run_b: bool,
    pub run_c: bool,
    pub cpu: Option<usize>,
    pub rx_cpu: Option<usize>,
    pub rounds: usize,
    pub reps: usize,
    pub warmup: u64,
    pub tp_frames: u64,
    pub window: u64,
    pub fan_frames: u64,
    pub fan_counts: Vec<usize>,
    pub batch: u64,
    pub lat_frames: u64,
    pub summary: Option<PathBuf>,
    pub paths: Paths,
}

impl Config {
    /// The settings of `cli` over the defaults of `env`; a usage error for
    /// combinations the options refuse together.
    pub fn new(cli: Cli, env: Env) -> Result<Config, clap::Error> {
        let mut c = Config {
            run_raw: true,
            run_table: true,
            run_dsor: true,
            run_bcm: false,
            run_fd: false,
            run_isotp: false,
            isotp_sizes: vec![4096, 65536],
            isotp_links: vec![isotp::Link::Classic, isotp::Link::Fd],
            isotp_spacing_pdus: 2,
            bcm_jobs: 1000,
            bcm_ival_ms: 10,
            bcm_secs: 3.0,
            table: table::Config {
                counts: vec![1000, 10_000],
                kinds: table::Kind::ALL.to_vec(),
                masks: 64,
                rounds: 3,
                frames: 6400,
                warmup: 640,
                batch: 64,
                fan_frames: 50_000,
                sockets: true,
                fan: true,
                secs: 2.0,
                pair: true,
                iface: "can0".into(),
                iface2: "can1".into(),
                load: true,
                unwanted_id: table::UNWANTED_ID,
            },
            protos: vec![Proto::Isotp, Proto::IsotpNoGap, Proto::Dsor],
            msg_sizes: vec![1024, 4096],
            msg_secs: 2.0,
            msg_min: 20,
            msg_warmup: 5,
            stacks: vec![Stack::Mainline, Stack::Ours],
            iface: "can0".into(),
            load: true,
            run_a: true,
            run_b: true,
            run_c: true,
            cpu: Some(0),
            rx_cpu: None,
            rounds: 5,
            reps: 2,
            warmup: 2000,
            tp_frames: 100_000,
            window: 256,
            fan_frames: 50_000,
            fan_counts: vec![1, 100, 1000],
            batch: 64,
            lat_frames: 100_000,
            summary: env.out.map(|d| d.join("bench-summary.txt")),
            paths: Paths {
                root: env.root,
                kbuild: env.kbuild,
            },
        };
        fn set<T>(field: &mut T, v: Option<T>) {
            if let Some(v) = v {
                *field = v;
            }
        }
        if let Some(p) = cli.part {
            [
                c.run_raw,
                c.run_table,
                c.run_dsor,
                c.run_bcm,
                c.run_fd,
                c.run_isotp,
            ] = p;
        }
        set(&mut c.stacks, cli.stack.map(|l| l.0));
        if let Some(w) = cli.only {
            [c.run_a, c.run_b, c.run_c] = w;
        }
        set(&mut c.iface, cli.iface);
        c.load = !cli.no_load;
        set(&mut c.paths.root, cli.ours_dir);
        set(&mut c.cpu, cli.cpu.map(|n| n.0));
        set(&mut c.rx_cpu, cli.rx_cpu.map(Some));
        set(&mut c.rounds, cli.rounds);
        set(&mut c.reps, cli.reps);
        set(&mut c.warmup, cli.warmup);
        set(&mut c.tp_frames, cli.throughput_frames);
        set(&mut c.window, cli.window);
        set(&mut c.fan_frames, cli.fanout_frames);
        set(&mut c.fan_counts, cli.fanout_receivers.map(|l| l.0));
        set(&mut c.batch, cli.batch);
        set(&mut c.lat_frames, cli.latency_frames);
        set(&mut c.protos, cli.proto.map(|l| l.0));
        set(&mut c.msg_sizes, cli.msg_sizes.map(|l| l.0));
        set(&mut c.msg_secs, cli.msg_secs);
        set(&mut c.msg_min, cli.msg_min);
        set(&mut c.msg_warmup, cli.msg_warmup);
        set(&mut c.isotp_sizes, cli.isotp_sizes.map(|l| l.0));
        set(&mut c.isotp_links, cli.isotp_links.map(|l| l.0));
        set(&mut c.isotp_spacing_pdus, cli.isotp_spacing_pdus);
        set(&mut c.bcm_jobs, cli.bcm_jobs);
        set(&mut c.bcm_ival_ms, cli.bcm_ival_ms);
        set(&mut c.bcm_secs, cli.bcm_secs);
        set(&mut c.table.rounds, cli.table_rounds);
        set(&mut c.table.counts, cli.table_sockets.map(|l| l.0));
        set(&mut c.table.kinds, cli.table_kinds.map(|l| l.0));
        set(&mut c.table.masks, cli.table_masks);
        set(&mut c.table.frames, cli.table_frames);
        set(&mut c.table.secs, cli.table_secs);
        set(&mut c.table.unwanted_id, cli.table_unwanted_id);
        if let Some(w) = cli.table_only {
            [c.table.sockets, c.table.fan, c.table.pair] = w;
        }
        set(&mut c.table.iface2, cli.iface2);
        set(&mut c.summary, cli.summary.map(Some));
        if cli.quick {
            c.rounds = 1;
            c.reps = 1;
            c.warmup = (c.warmup / 10).max(100);
            c.tp_frames = (c.tp_frames / 10).max(100);
            c.fan_frames = (c.fan_frames / 10).max(100);
            c.lat_frames = (c.lat_frames / 10).max(100);
            c.msg_secs = c.msg_secs.min(0.5);
            c.msg_min = c.msg_min.min(5);
            c.msg_warmup = c.msg_warmup.min(2);
            c.table.rounds = 1;
            c.table.frames = (c.table.frames / 10).max(c.table.batch);
            c.table.warmup = (c.table.warmup / 10).max(c.table.batch);
            c.table.secs = c.table.secs.min(0.5);
        }
        // The table part shares these with the raw part.
        c.table.iface = c.iface.clone();
        c.table.load = c.load;
        c.table.batch = c.batch.max(1);
        c.table.fan_frames = c.fan_frames;
        // ISO-TP needs more than a single frame; DSOR and ISO-TP (mainline's
        // default max_pdu_size) both take 8300 bytes.
        if c.msg_sizes.is_empty() || c.msg_sizes.iter().any(|&n| !(8..=8300).contains(&n)) {
            return Err(usage_error(
                ErrorKind::ValueValidation,
                "--msg-sizes: sizes from 8 to 8300 bytes",
            ));
        }
        // Mainline clamps max_pdu_size to 1025 KiB.
        if c.isotp_sizes.is_empty() || c.isotp_sizes.iter().any(|&n| !(8..=1 << 20).contains(&n)) {
            return Err(usage_error(
                ErrorKind::ValueValidation,
                "--isotp-sizes: sizes from 8 to 1048576 bytes",
            ));
        }
        if c.rounds == 0
            || c.reps == 0
            || c.window == 0
            || c.batch == 0
            || c.fan_counts.contains(&0)
        {
            return Err(usage_error(
                ErrorKind::ValueValidation,
                "--rounds, --reps, --window, --batch and receiver counts must be positive",
            ));
        }
        if c.window > u64::from(u32::MAX) || c.tp_frames > u64::from(u32::MAX) {
            return Err(usage_error(
                ErrorKind::ValueValidation,
                "frame counts must fit in 32 bits",
            ));
        }
        if !c.load && c.run_raw && c.stacks.len() != 1 {
            return Err(usage_error(
                ErrorKind::ArgumentConflict,
                "--no-load measures one stack: say which with --stack",
            ));
        }
        if !c.load && c.run_isotp && c.stacks.len() != 1 {
            return Err(usage_error(
                ErrorKind::ArgumentConflict,
                "--no-load measures one stack: say which with --stack",
            ));
        }
        if !c.load && c.run_dsor && c.protos.len() != 1 {
            return Err(usage_error(
                ErrorKind::ArgumentConflict,
                "--no-load measures one protocol: say which with --proto",
            ));
        }
        c.fan_counts.sort_unstable();
        c.fan_counts.dedup();
        if c.fan_counts
            .last()
            .is_some_and(|&n| n > 0x7ff - workload::FANOUT_BASE_ID as usize)
        {
            return Err(usage_error(
                ErrorKind::ValueValidation,
                "too many fan-out receivers for distinct 11-bit ids",
            ));
        }
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use table::Kind;

    #[test]
    fn clap_definition() {
        command().debug_assert();
    }

    /// The environment of every test: as `bench.sh` sets it up in the VM.
    fn env() -> Env {
        Env {
            out: Some(PathBuf::from("/out")),
            root: PathBuf::from("/rcan"),
            kbuild: Some(PathBuf::from("/kbuild")),
        }
    }

    fn parse_with(args: &[&str], env: Env) -> Result<Config, String> {
        let args = std::iter::once(&"rcan-bench").chain(args);
        Cli::try_parse_from(args)
            .and_then(|cli| Config::new(cli, env))
            .map_err(|e| with_usage(e).to_string())
    }

    fn parse(args: &[&str]) -> Result<Config, String> {
        parse_with(args, env())
    }

    /// What `rcan-bench` with no options runs, written out in full.
    fn defaults() -> Config {
        Config {
            run_raw: true,
            run_table: true,
            run_dsor: true,
            run_bcm: false,
            run_fd: false,
            run_isotp: false,
            isotp_sizes: vec![4096, 65536],
            isotp_links: vec![isotp::Link::Classic, isotp::Link::Fd],
            isotp_spacing_pdus: 2,
            bcm_jobs: 1000,
            bcm_ival_ms: 10,
            bcm_secs: 3.0,
            table: table::Config {
                counts: vec![1000, 10_000],
                kinds: vec![Kind::Exact, Kind::Same, Kind::Masked, Kind::Masks],
                masks: 64,
                rounds: 3,
                frames: 6400,
                warmup: 640,
                batch: 64,
                fan_frames: 50_000,
                sockets: true,
                fan: true,
                secs: 2.0,
                pair: true,
                iface: "can0".into(),
                iface2: "can1".into(),
                load: true,
                unwanted_id: 0x555,
            },
            protos: vec![Proto::Isotp, Proto::IsotpNoGap, Proto::Dsor],
            msg_sizes: vec![1024, 4096],
            msg_secs: 2.0,
            msg_min: 20,
            msg_warmup: 5,
            stacks: vec![Stack::Mainline, Stack::Ours],
            iface: "can0".into(),
            load: true,
            run_a: true,
            run_b: true,
            run_c: true,
            cpu: Some(0),
            rx_cpu: None,
            rounds: 5,
            reps: 2,
            warmup: 2000,
            tp_frames: 100_000,
            window: 256,
            fan_frames: 50_000,
            fan_counts: vec![1, 100, 1000],
            batch: 64,
            lat_frames: 100_000,
            summary: Some(PathBuf::from("/out/bench-summary.txt")),
            paths: Paths {
                root: PathBuf::from("/rcan"),
                kbuild: Some(PathBuf::from("/kbuild")),
            },
        }
    }

    fn parts(c: &mut Config, raw: bool, table: bool, dsor: bool, bcm: bool) {
        (c.run_raw, c.run_table, c.run_dsor, c.run_bcm) = (raw, table, dsor, bcm);
    }

    #[test]
    fn defaults_without_options() {
        assert_eq!(parse(&[]), Ok(defaults()));
        assert_eq!(parse(&["--part", "raw,table,dsor"]), Ok(defaults()));
        let mut e = defaults();
        e.summary = None;
        let no_out = Env { out: None, ..env() };
        assert_eq!(parse_with(&[], no_out), Ok(e));
    }

    /// The examples of `bench.sh` and of benchmarks.rst.
    #[test]
    fn bench_sh_option_sets() {
        let mut e = defaults();
        e.stacks = vec![Stack::Mainline];
        assert_eq!(parse(&["--stack", "mainline"]), Ok(e));

        let mut e = defaults();
        (e.rounds, e.reps, e.warmup) = (1, 1, 200);
        (e.tp_frames, e.fan_frames, e.lat_frames) = (10_000, 5000, 10_000);
        (e.msg_secs, e.msg_min, e.msg_warmup) = (0.5, 5, 2);
        (e.table.rounds, e.table.frames, e.table.warmup) = (1, 640, 64);
        (e.table.secs, e.table.fan_frames) = (0.5, 5000);
        assert_eq!(parse(&["--quick"]), Ok(e));

        for (part, raw, table, dsor, bcm) in [
            ("raw", true, false, false, false),
            ("table", false, true, false, false),
            ("dsor", false, false, true, false),
            ("bcm", false, false, false, true),
        ] {
            let mut e = defaults();
            parts(&mut e, raw, table, dsor, bcm);
            assert_eq!(parse(&["--part", part]), Ok(e), "--part {part}");
        }

        let mut e = defaults();
        parts(&mut e, false, false, true, false);
        e.rounds = 3;
        assert_eq!(parse(&["--part", "dsor", "--rounds", "3"]), Ok(e));

        // The ISO-TP part, as benchmarks.rst runs it.
        let mut e = defaults();
        parts(&mut e, false, false, false, false);
        (e.run_isotp, e.rounds) = (true, 3);
        assert_eq!(parse(&["--part", "isotp", "--rounds", "3"]), Ok(e));
        let mut e = defaults();
        parts(&mut e, false, false, false, false);
        e.run_isotp = true;
        e.isotp_sizes = vec![4096];
        e.isotp_links = vec![isotp::Link::Fd];
        e.isotp_spacing_pdus = 0;
        assert_eq!(
            parse(&[
                "--part",
                "isotp",
                "--isotp-sizes",
                "4096",
                "--isotp-links",
                "fd",
                "--isotp-spacing-pdus",
                "0"
            ]),
            Ok(e)
        );

        // The CAN FD part, as benchmarks.rst runs it.
        let mut e = defaults();
        parts(&mut e, false, false, false, false);
        (e.run_fd, e.rounds) = (true, 3);
        assert_eq!(parse(&["--part", "fd", "--rounds", "3"]), Ok(e));

        let mut e = defaults();
        parts(&mut e, true, false, false, false);
        e.rounds = 3;
        assert_eq!(parse(&["--part", "raw", "--rounds", "3"]), Ok(e));

        let mut e = defaults();
        parts(&mut e, false, true, false, false);
        e.table.rounds = 1;
        e.table.kinds = vec![Kind::Exact, Kind::Same];
        (e.table.fan, e.table.pair) = (false, false);
        e.table.unwanted_id = 0xC000_04DD;
        assert_eq!(
            parse(&[
                "--part",
                "table",
                "--table-rounds",
                "1",
                "--table-kinds",
                "exact,same",
                "--table-sockets",
                "1000,10000",
                "--table-only",
                "sockets",
                "--table-unwanted-id",
                "C00004DD",
            ]),
            Ok(e)
        );

        let mut e = defaults();
        parts(&mut e, false, true, false, false);
        e.stacks = vec![Stack::Ours];
        (e.load, e.table.load) = (false, false);
        e.table.kinds = vec![Kind::Exact];
        e.table.counts = vec![10_000];
        (e.table.fan, e.table.pair) = (false, false);
        assert_eq!(
            parse(&[
                "--part",
                "table",
                "--stack",
                "ours",
                "--no-load",
                "--table-kinds",
                "exact",
                "--table-sockets",
                "10000",
                "--table-only",
                "sockets",
            ]),
            Ok(e)
        );

        let mut e = defaults();
        parts(&mut e, true, false, false, false);
        e.stacks = vec![Stack::Ours];
        (e.load, e.table.load) = (false, false);
        (e.run_b, e.run_c) = (false, false);
        (e.rounds, e.reps) = (1, 2);
        assert_eq!(
            parse(&[
                "--part",
                "raw",
                "--stack",
                "ours",
                "--no-load",
                "--only",
                "throughput",
                "--rounds",
                "1",
                "--reps",
                "2",
            ]),
            Ok(e)
        );

        let mut e = defaults();
        parts(&mut e, false, true, false, false);
        (e.table.fan, e.table.pair) = (false, false);
        e.table.kinds = vec![Kind::Exact];
        e.table.counts = vec![10_000];
        e.table.rounds = 3;
        assert_eq!(
            parse(&[
                "--part",
                "table",
                "--table-only",
                "sockets",
                "--table-kinds",
                "exact",
                "--table-sockets",
                "10000",
                "--table-rounds",
                "3",
            ]),
            Ok(e)
        );

        let mut e = defaults();
        parts(&mut e, false, true, false, false);
        (e.table.fan, e.table.pair) = (false, false);
        e.table.counts = vec![10_000];
        e.table.rounds = 2;
        e.paths.root = PathBuf::from("/tmp/base");
        assert_eq!(
            parse(&[
                "--part",
                "table",
                "--table-only",
                "sockets",
                "--table-sockets",
                "10000",
                "--table-rounds",
                "2",
                "--ours-dir",
                "/tmp/base",
            ]),
            Ok(e)
        );

        let mut e = defaults();
        parts(&mut e, false, false, true, false);
        e.cpu = None;
        (e.load, e.table.load) = (false, false);
        e.protos = vec![Proto::Dsor];
        assert_eq!(
            parse(&[
                "--part",
                "dsor",
                "--cpu",
                "any",
                "--no-load",
                "--proto",
                "dsor"
            ]),
            Ok(e)
        );
        let mut e = defaults();
        parts(&mut e, false, false, true, false);
        e.cpu = None;
        e.protos = vec![Proto::Dsor, Proto::DsorFd];
        assert_eq!(
            parse(&["--part", "dsor", "--cpu", "any", "--proto", "dsor,dsorfd"]),
            Ok(e)
        );
    }

    /// Value syntax: lists, underscores in numbers, hex ids, the last of a
    /// repeated option, `--quick` wherever it stands.
    #[test]
    fn value_syntax() {
        let mut e = defaults();
        parts(&mut e, false, true, false, true);
        e.protos = vec![Proto::Dsor, Proto::Isotp];
        e.msg_sizes = vec![4096, 8, 4096];
        e.fan_counts = vec![1, 7, 2031];
        e.run_a = false;
        e.tp_frames = 1_000_000;
        e.rounds = 4;
        e.cpu = Some(1);
        e.rx_cpu = Some(0);
        e.iface = "vcan3".into();
        e.table.iface = "vcan3".into();
        e.table.iface2 = "vcan4".into();
        e.table.unwanted_id = 0x123;
        e.table.kinds = vec![Kind::Masks, Kind::Masked];
        e.table.masks = 255;
        e.table.secs = 1.5;
        e.table.counts = vec![5, 5];
        (e.table.sockets, e.table.fan) = (false, false);
        (e.bcm_jobs, e.bcm_ival_ms, e.bcm_secs) = (1536, 1, 0.25);
        (e.batch, e.table.batch) = (8, 8);
        e.summary = Some(PathBuf::from("s.txt"));
        assert_eq!(
            parse(&[
                "--part",
                "bcm, table",
                "--proto",
                "dsor,isotp,dsor",
                "--msg-sizes",
                "4_096, 8,4096",
                "--fanout-receivers",
                "2031,1,7,1",
                "--only",
                "b,latency,fan-out",
                "--throughput-frames",
                "1_000_000",
                "--rounds",
                "2",
                "--rounds",
                "4",
                "--cpu",
                "1",
                "--rx-cpu",
                "0",
                "--iface",
                "vcan3",
                "--iface2",
                "vcan4",
                "--table-unwanted-id",
                "0x123",
                "--table-kinds",
                "masks,masked,masks",
                "--table-masks",
                "255",
                "--table-secs",
                "1.5",
                "--table-sockets",
                "5,5",
                "--table-only",
                "pair",
                "--bcm-jobs",
                "1536",
                "--bcm-ival-ms",
                "1",
                "--bcm-secs",
                "0.25",
                "--batch",
                "8",
                "--summary",
                "s.txt",
            ]),
            Ok(e)
        );

        // --quick scales what the other options set, before or after it.
        let mut e = defaults();
        (e.rounds, e.reps, e.warmup) = (1, 1, 100);
        (e.tp_frames, e.fan_frames, e.lat_frames) = (10_000, 5000, 10_000);
        (e.msg_secs, e.msg_min, e.msg_warmup) = (0.5, 5, 2);
        (e.table.rounds, e.table.frames, e.table.warmup) = (1, 640, 64);
        (e.table.secs, e.table.fan_frames) = (0.5, 5000);
        assert_eq!(parse(&["--quick", "--warmup", "1000"]), Ok(e));

        // A value is the next argument, whatever it starts with.
        let mut e = defaults();
        (e.iface, e.table.iface) = ("-x".into(), "-x".into());
        e.summary = Some(PathBuf::from("--quick"));
        assert_eq!(parse(&["--iface", "-x", "--summary", "--quick"]), Ok(e));
    }

    /// Values the parser refuses, each with everything else valid.
    #[test]
    fn refused() {
        for args in [
            &["--part", "nosuch"][..],
            &["--part", ""],
            &["--part", "nosuch", "--part", "raw"],
            &["--table-sockets", "0", "--table-sockets", "5"],
            &["--stack", "neither"],
            &["--only", "d"],
            &["--proto", "tcp"],
            &["--table-kinds", "exact,"],
            &["--table-only", "all"],
            &["--bcm-jobs", "0"],
            &["--bcm-jobs", "1537"],
            &["--bcm-jobs", "1_000"],
            &["--bcm-ival-ms", "0"],
            &["--bcm-secs", "0"],
            &["--bcm-secs", "NaN"],
            &["--table-masks", "0"],
            &["--table-masks", "256"],
            &["--table-sockets", "1000,0"],
            &["--table-unwanted-id", "55a"],
            &["--table-unwanted-id", "8000055A"],
            &["--table-unwanted-id", "xyz"],
            &["--msg-sizes", "7"],
            &["--msg-sizes", "8301"],
            &["--isotp-sizes", "7"],
            &["--isotp-sizes", "1048577"],
            &["--isotp-links", "lin"],
            &["--no-load", "--part", "isotp"],
            &["--msg-sizes", "1024,,4096"],
            &["--rounds", "0"],
            &["--reps", "0"],
            &["--window", "0"],
            &["--batch", "0"],
            &["--fanout-receivers", "1,0"],
            &["--fanout-receivers", "2032"],
            &["--window", "4294967296"],
            &["--throughput-frames", "4294967296"],
            &["--no-load"],
            &["--no-load", "--part", "dsor", "--stack", "ours"],
            &["--rounds"],
            &["--rounds", "x"],
            &["--rounds", "-1"],
            &["--rounds", "--quick"],
            &["--rx-cpu", "any"],
            &["--cpu", "first"],
            &["--bogus"],
            &["can0"],
        ] {
            match parse(args) {
                Ok(_) => panic!("{args:?} accepted"),
                Err(e) => assert!(e.contains("Usage: rcan-bench"), "{args:?}: {e}"),
            }
        }
    }
}
