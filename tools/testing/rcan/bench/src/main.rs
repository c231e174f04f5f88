// SPDX-License-Identifier: GPL-2.0
//! rcan-bench: rcan's CAN_RAW receive path against mainline SocketCAN.
//!
//! Run as root inside the test VM (`make bench`, or
//! `tools/testing/rcan/bench.sh`). In each of `--rounds` rounds it loads
//! every selected stack in turn (the order alternates between rounds),
//! brings `can0` up, runs three workloads with the same code (mainline
//! CAN_RAW ABI only) and removes the stack again:
//!
//! - (a) throughput: frames/s from one sender socket to one receiver
//!   socket, at most `--window` frames in flight, losses counted;
//! - (b) fan-out: cost per frame with 1, 100 and 1,000 receivers, each
//!   bound to its own exact 11-bit id, frames sent round-robin over the ids;
//! - (c) latency: send-to-receive p50/p99/max, one frame in flight.
//!
//! Each workload is warmed up, then measured `--reps` times per round. The
//! summary shows medians over all runs, the ratios ours/mainline and their
//! range round by round, and the targets met or missed. A missed target is
//! never an error: the exit status is non-zero only if a stack could not be
//! set up or a workload could not run. See
//! `Documentation/networking/rcan/benchmarks.rst`.
//!
//! A second part (`--part table`, see `table.rs`) measures what many
//! sockets cost on both stacks: bind and close of 1,000 and 10,000
//! sockets, the cost of a frame nobody wants with that many filters, 1,000
//! against 1 receivers, two senders on two CPUs, memory per socket.
//!
//! A third part (`--part dsor`, see `dsor.rs`) measures messages instead
//! of frames: rcan's DSOR protocol against mainline ISO-TP, goodput and
//! kernel CPU time per KiB. `--part raw,table,dsor` (the default) runs all
//! three in that order.
//!
//! A fourth part, only on request (`--part bcm`, see `bcm.rs`), measures
//! kernel CPU time per cyclic frame of CAN_BCM (1,000 jobs at 10 ms):
//! rcan_bcm against mainline's can-bcm.ko.

mod bcm;
mod can;
mod dsor;
mod report;
mod stack;
mod table;
mod workload;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use report::{Fanout, Latency, StackResult, Throughput};
use stack::{Paths, Proto, Stack};
use workload::median;

const USAGE: &str = "\
usage: rcan-bench [options]
  --part LIST           parts to run, comma-separated: raw (CAN_RAW, mainline vs
                        ours), table (many sockets, mainline vs ours), dsor (DSOR
                        vs mainline ISO-TP), bcm (CAN_BCM cyclic jobs, mainline
                        vs ours; not in the default) (default raw,table,dsor)
  --stack S             raw and table parts: mainline, ours or both (default both)
  --only LIST           workloads to run, comma-separated: a|throughput, b|fanout,
                        c|latency (default all)
  --iface NAME          CAN interface (default can0)
  --no-load             measure the stack already set up on --iface (one --stack
                        only, used as its label); load and unload nothing
  --ours-dir DIR        where our modules are: DIR/net/can/rcan_*.ko,
                        DIR/drivers/net/can/rcan_loop.ko (default: RCAN_ROOT;
                        a relative DIR is taken from the current directory,
                        the project root in the VM)
  --cpu N|any           run the workloads on CPU N (default 0), or anywhere
  --rx-cpu N            throughput: the receiver thread on CPU N (default: --cpu)
  --rounds N            rounds (default 5): each loads, measures and unloads every
                        selected stack in turn; mainline first in odd rounds,
                        ours first in even ones
  --reps N              measured runs per figure and round (default 2); the
                        summary gives the median over all rounds' runs
  --warmup N            frames per warm-up run (default 2000)
  --throughput-frames N frames per throughput run (default 100000)
  --window N            throughput: frames in flight at most (default 256)
  --fanout-frames N     frames per fan-out run (default 50000)
  --fanout-receivers L  receiver counts, comma-separated (default 1,100,1000)
  --batch N             fan-out: frames sent before reading them back (default 64)
  --latency-frames N    frames per latency run (default 100000)
  --proto LIST          dsor part: protocols, comma-separated: isotp (ISO-TP,
                        default options), isotp0 (ISO-TP, frame_txtime 0), dsor
                        (default isotp,isotp0,dsor)
  --msg-sizes L         dsor part: message sizes in bytes (default 1024,4096)
  --msg-secs S          dsor part: seconds per measured run at least (default 2)
  --msg-min N           dsor part: messages per measured run at least (default 20)
  --msg-warmup N        dsor part: messages per warm-up run (default 5)
  --bcm-jobs N          bcm part: cyclic jobs (default 1000)
  --bcm-ival-ms N       bcm part: interval of each job in ms (default 10)
  --bcm-secs S          bcm part: seconds per measured run (default 3)
  --table-rounds N      table part: rounds (default 3)
  --table-sockets L     table part: socket counts (default 1000,10000)
  --table-kinds L       table part: filter kinds, comma-separated: exact (one
                        exact id each), same (all one id), masked (id:7F0),
                        masks (many distinct masks) (default all four)
  --table-masks M       table part: distinct masks of kind masks (1-255, default 64)
  --table-frames N      table part: unwanted frames per run (default 6400)
  --table-secs S        table part: seconds per two-sender run (default 2)
  --table-unwanted-id X table part: can_id (hex, flags included) of the frame
                        nobody should want (default 555); another id may be
                        wanted by some kinds, which the run then reports
  --table-only LIST     table part: workloads, comma-separated: sockets (bind,
                        close, unwanted frame, memory), fanout (1000 : 1
                        receivers), pair (two senders) (default all)
  --iface2 NAME         table part: the second device (default can1)
  --quick               a tenth of the frames, one run each (smoke test)
  --summary FILE        also write the summary to FILE
                        (default $RCAN_OUT/bench-summary.txt if RCAN_OUT is set)
Environment: RCAN_KBUILD (test kernel build directory: mainline modules),
RCAN_ROOT (project tree with our modules; default the current directory).";

/// Command line settings.
#[derive(Debug, PartialEq)]
struct Config {
    run_raw: bool,
    run_table: bool,
    run_dsor: bool,
    run_bcm: bool,
    bcm_jobs: u32,
    bcm_ival_ms: u64,
    bcm_secs: f64,
    table: table::Config,
    protos: Vec<Proto>,
    msg_sizes: Vec<usize>,
    msg_secs: f64,
    msg_min: u64,
    msg_warmup: u64,
    stacks: Vec<Stack>,
    iface: String,
    load: bool,
    run_a: bool,
    run_b: bool,
    run_c: bool,
    cpu: Option<usize>,
    rx_cpu: Option<usize>,
    rounds: usize,
    reps: usize,
    warmup: u64,
    tp_frames: u64,
    window: u64,
    fan_frames: u64,
    fan_counts: Vec<usize>,
    batch: u64,
    lat_frames: u64,
    summary: Option<PathBuf>,
    paths: Paths,
}

fn parse_num<T: std::str::FromStr>(opt: &str, v: Option<String>) -> Result<T, String> {
    let v = v.ok_or(format!("{opt} wants a value"))?;
    v.replace('_', "")
        .parse()
        .map_err(|_| format!("{opt}: bad number '{v}'"))
}

/// What the defaults take from the process: `RCAN_OUT` (the summary's
/// directory), `RCAN_ROOT` (else the current directory) and `RCAN_KBUILD`;
/// empty variables count as unset.
struct Env {
    out: Option<PathBuf>,
    root: PathBuf,
    kbuild: Option<PathBuf>,
}

impl Env {
    fn from_process() -> Env {
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

fn parse_args(args: impl IntoIterator<Item = String>, env: Env) -> Result<Config, String> {
    let mut c = Config {
        run_raw: true,
        run_table: true,
        run_dsor: true,
        run_bcm: false,
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
    let mut quick = false;
    let mut args = args.into_iter();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--part" => {
                let v = args.next().ok_or("--part wants a list")?;
                (c.run_raw, c.run_table, c.run_dsor, c.run_bcm) = (false, false, false, false);
                for w in v.split(',') {
                    match w.trim() {
                        "raw" => c.run_raw = true,
                        "table" => c.run_table = true,
                        "dsor" => c.run_dsor = true,
                        "bcm" => c.run_bcm = true,
                        other => return Err(format!("--part: unknown part '{other}'")),
                    }
                }
            }
            "--bcm-jobs" => {
                c.bcm_jobs = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .filter(|&n| (1..=0x600).contains(&n))
                    .ok_or("--bcm-jobs wants 1..1536")?;
            }
            "--bcm-ival-ms" => {
                c.bcm_ival_ms = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .filter(|&n| n > 0)
                    .ok_or("--bcm-ival-ms wants a positive number")?;
            }
            "--bcm-secs" => {
                c.bcm_secs = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .filter(|&n: &f64| n > 0.0)
                    .ok_or("--bcm-secs wants a positive number")?;
            }
            "--proto" => {
                let v = args.next().ok_or("--proto wants a list")?;
                c.protos.clear();
                for w in v.split(',') {
                    let p = match w.trim() {
                        "isotp" => Proto::Isotp,
                        "isotp0" => Proto::IsotpNoGap,
                        "dsor" => Proto::Dsor,
                        other => return Err(format!("--proto: unknown protocol '{other}'")),
                    };
                    if !c.protos.contains(&p) {
                        c.protos.push(p);
                    }
                }
            }
            "--msg-sizes" => {
                let v = args.next().ok_or("--msg-sizes wants a list")?;
                c.msg_sizes = v
                    .split(',')
                    .map(|n| parse_num(&a, Some(n.trim().to_string())))
                    .collect::<Result<_, _>>()?;
            }
            "--msg-secs" => c.msg_secs = parse_num(&a, args.next())?,
            "--msg-min" => c.msg_min = parse_num(&a, args.next())?,
            "--msg-warmup" => c.msg_warmup = parse_num(&a, args.next())?,
            "--table-rounds" => c.table.rounds = parse_num(&a, args.next())?,
            "--table-sockets" => {
                let v = args.next().ok_or("--table-sockets wants a list")?;
                c.table.counts = v
                    .split(',')
                    .map(|n| parse_num(&a, Some(n.trim().to_string())))
                    .collect::<Result<_, _>>()?;
                if c.table.counts.contains(&0) {
                    return Err("--table-sockets: counts must be at least 1".into());
                }
            }
            "--table-kinds" => {
                let v = args.next().ok_or("--table-kinds wants a list")?;
                c.table.kinds.clear();
                for w in v.split(',') {
                    let k = table::Kind::parse(w.trim())
                        .ok_or_else(|| format!("--table-kinds: unknown kind '{}'", w.trim()))?;
                    if !c.table.kinds.contains(&k) {
                        c.table.kinds.push(k);
                    }
                }
            }
            "--table-masks" => {
                c.table.masks = parse_num(&a, args.next())?;
                if !(1..=255).contains(&c.table.masks) {
                    return Err("--table-masks wants 1 to 255".into());
                }
            }
            "--table-frames" => c.table.frames = parse_num(&a, args.next())?,
            "--table-unwanted-id" => {
                let v = args.next().ok_or("--table-unwanted-id wants a can_id")?;
                let hex = v.trim_start_matches("0x").trim_start_matches("0X");
                c.table.unwanted_id = u32::from_str_radix(hex, 16)
                    .map_err(|_| format!("--table-unwanted-id: bad hex can_id '{v}'"))?;
                if c.table.unwanted_id & 0x1fff_ffff == table::SENTINEL_ID {
                    return Err("--table-unwanted-id: that is the sentinel's id".into());
                }
            }
            "--table-secs" => c.table.secs = parse_num(&a, args.next())?,
            "--table-only" => {
                let v = args.next().ok_or("--table-only wants a list")?;
                (c.table.sockets, c.table.fan, c.table.pair) = (false, false, false);
                for w in v.split(',') {
                    match w.trim() {
                        "sockets" => c.table.sockets = true,
                        "fanout" => c.table.fan = true,
                        "pair" => c.table.pair = true,
                        other => return Err(format!("--table-only: unknown workload '{other}'")),
                    }
                }
            }
            "--iface2" => c.table.iface2 = args.next().ok_or("--iface2 wants a name")?,
            "--stack" => {
                c.stacks = match args.next().as_deref() {
                    Some("mainline") => vec![Stack::Mainline],
                    Some("ours") => vec![Stack::Ours],
                    Some("both") => vec![Stack::Mainline, Stack::Ours],
                    other => {
                        return Err(format!(
                            "--stack: want mainline, ours or both, got {other:?}"
                        ))
                    }
                }
            }
            "--only" => {
                let v = args.next().ok_or("--only wants a list")?;
                (c.run_a, c.run_b, c.run_c) = (false, false, false);
                for w in v.split(',') {
                    match w.trim() {
                        "a" | "throughput" => c.run_a = true,
                        "b" | "fanout" | "fan-out" => c.run_b = true,
                        "c" | "latency" => c.run_c = true,
                        other => return Err(format!("--only: unknown workload '{other}'")),
                    }
                }
            }
            "--iface" => c.iface = args.next().ok_or("--iface wants a name")?,
            "--no-load" => c.load = false,
            "--ours-dir" => {
                c.paths.root = PathBuf::from(args.next().ok_or("--ours-dir wants a directory")?)
            }
            "--cpu" => {
                c.cpu = match args.next().as_deref() {
                    Some("any") => None,
                    v => Some(parse_num(&a, v.map(str::to_string))?),
                }
            }
            "--rx-cpu" => c.rx_cpu = Some(parse_num(&a, args.next())?),
            "--rounds" => c.rounds = parse_num(&a, args.next())?,
            "--reps" => c.reps = parse_num(&a, args.next())?,
            "--warmup" => c.warmup = parse_num(&a, args.next())?,
            "--throughput-frames" => c.tp_frames = parse_num(&a, args.next())?,
            "--window" => c.window = parse_num(&a, args.next())?,
            "--fanout-frames" => c.fan_frames = parse_num(&a, args.next())?,
            "--fanout-receivers" => {
                let v = args.next().ok_or("--fanout-receivers wants a list")?;
                c.fan_counts = v
                    .split(',')
                    .map(|n| parse_num(&a, Some(n.trim().to_string())))
                    .collect::<Result<_, _>>()?;
            }
            "--batch" => c.batch = parse_num(&a, args.next())?,
            "--latency-frames" => c.lat_frames = parse_num(&a, args.next())?,
            "--quick" => quick = true,
            "--summary" => {
                c.summary = Some(PathBuf::from(args.next().ok_or("--summary wants a file")?))
            }
            "-h" | "--help" => {
                println!("{USAGE}");
                std::process::exit(0);
            }
            other => return Err(format!("unknown argument '{other}'")),
        }
    }
    if quick {
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
        return Err("--msg-sizes: sizes from 8 to 8300 bytes".into());
    }
    if c.rounds == 0 || c.reps == 0 || c.window == 0 || c.batch == 0 || c.fan_counts.contains(&0) {
        return Err(
            "--rounds, --reps, --window, --batch and receiver counts must be positive".into(),
        );
    }
    if c.window > u64::from(u32::MAX) || c.tp_frames > u64::from(u32::MAX) {
        return Err("frame counts must fit in 32 bits".into());
    }
    if !c.load && c.run_raw && c.stacks.len() != 1 {
        return Err("--no-load measures one stack: say which with --stack".into());
    }
    if !c.load && c.run_dsor && c.protos.len() != 1 {
        return Err("--no-load measures one protocol: say which with --proto".into());
    }
    c.fan_counts.sort_unstable();
    c.fan_counts.dedup();
    if c.fan_counts
        .last()
        .is_some_and(|&n| n > 0x7ff - workload::FANOUT_BASE_ID as usize)
    {
        return Err("too many fan-out receivers for distinct 11-bit ids".into());
    }
    Ok(c)
}

fn median_u64(v: Vec<u64>) -> u64 {
    median(v.into_iter().map(|x| x as f64).collect()).round() as u64
}

/// Percentiles of one latency run, in ns.
#[derive(Clone, Copy, Debug)]
struct LatencyStats {
    p50: u64,
    p99: u64,
    max: u64,
    lost: u64,
    odd: u64,
}

/// Raw runs of one stack over all rounds (each tagged with its round),
/// and what stopped working.
#[derive(Default)]
struct Samples {
    tp: Vec<(usize, workload::ThroughputRun)>,
    fan: Vec<(usize, usize, workload::FanoutRun)>,
    lat: Vec<(usize, LatencyStats)>,
    errors: Vec<String>,
    /// Setup failed: skip the stack in later rounds.
    broken: bool,
    /// Workloads that failed: skipped in later rounds.
    tp_off: bool,
    fan_off: Vec<usize>,
    lat_off: bool,
}

impl Samples {
    /// Medians over the runs of `round`, or of all rounds.
    fn result(&self, stack: Stack, round: Option<usize>) -> StackResult {
        let want = |r: usize| round.is_none_or(|k| k == r);
        let tp: Vec<_> = self
            .tp
            .iter()
            .filter(|(r, _)| want(*r))
            .map(|(_, t)| t)
            .collect();
        let throughput = (!tp.is_empty()).then(|| Throughput {
            fps: median(tp.iter().map(|r| r.fps_fast).collect()),
            fps_run: median(tp.iter().map(|r| r.fps).collect()),
            lost: tp.iter().map(|r| r.counts.lost).sum(),
            odd: tp.iter().map(|r| r.counts.odd).sum(),
            runs: tp.len(),
        });
        let fan: Vec<_> = self.fan.iter().filter(|(r, _, _)| want(*r)).collect();
        let mut counts: Vec<usize> = fan.iter().map(|(_, n, _)| *n).collect();
        counts.sort_unstable();
        counts.dedup();
        let fanout = counts
            .into_iter()
            .map(|n| {
                let runs: Vec<_> = fan
                    .iter()
                    .filter(|(_, k, _)| *k == n)
                    .map(|(_, _, f)| f)
                    .collect();
                Fanout {
                    receivers: n,
                    ns_per_frame: median(runs.iter().map(|r| r.ns_fast).collect()),
                    ns_run: median(runs.iter().map(|r| r.ns_per_frame).collect()),
                    setup_ms: median(runs.iter().map(|r| r.setup.as_secs_f64() * 1e3).collect()),
                    lost: runs.iter().map(|r| r.counts.lost).sum(),
                    odd: runs.iter().map(|r| r.counts.odd).sum(),
                    runs: runs.len(),
                }
            })
            .collect();
        let lat: Vec<_> = self
            .lat
            .iter()
            .filter(|(r, _)| want(*r))
            .map(|(_, l)| l)
            .collect();
        let latency = (!lat.is_empty()).then(|| Latency {
            p50: median_u64(lat.iter().map(|l| l.p50).collect()),
            p99: median_u64(lat.iter().map(|l| l.p99).collect()),
            max: lat.iter().map(|l| l.max).max().unwrap_or(0),
            lost: lat.iter().map(|l| l.lost).sum(),
            odd: lat.iter().map(|l| l.odd).sum(),
            runs: lat.len(),
        });
        StackResult {
            stack,
            errors: if round.is_none() {
                self.errors.clone()
            } else {
                Vec::new()
            },
            throughput,
            fanout,
            latency,
        }
    }
}

/// Workload (a) on `ifindex`: warm-up, then `reps` runs.
fn bench_throughput(
    c: &Config,
    tag: &str,
    ifindex: i32,
    round: usize,
    s: &mut Samples,
) -> Result<(), String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let rx = workload::receiver(ifindex, workload::TP_ID)
        .map_err(|e| format!("receiver socket: {e}"))?;
    let w = workload::throughput(&tx, &rx, c.warmup, c.window, c.rx_cpu)
        .map_err(|e| format!("warm-up: {e}"))?;
    println!(
        "{tag} (a) warm-up: {} frames, {:.0} frames/s",
        w.counts.received, w.fps
    );
    for i in 1..=c.reps {
        let r = workload::throughput(&tx, &rx, c.tp_frames, c.window, c.rx_cpu)
            .map_err(|e| format!("run {i}: {e}"))?;
        println!(
            "{tag} (a) run {i}/{}: {} sent, {} received in {:.3} s = {:.0} frames/s, undisturbed {:.0}; \
             lost {}, odd {}, send retries {}, stalls {}",
            c.reps,
            r.counts.sent,
            r.counts.received,
            r.elapsed.as_secs_f64(),
            r.fps,
            r.fps_fast,
            r.counts.lost,
            r.counts.odd,
            r.counts.send_retries,
            r.counts.stalls
        );
        s.tp.push((round, r));
    }
    Ok(())
}

/// Workload (b), one run with `n` receivers on `ifindex`: open the sockets,
/// warm up, measure, close them.
fn bench_fanout(
    c: &Config,
    tag: &str,
    ifindex: i32,
    n: usize,
    run: &str,
) -> Result<workload::FanoutRun, String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let t0 = Instant::now();
    let rxs = (0..n)
        .map(|i| workload::receiver(ifindex, workload::FANOUT_BASE_ID + i as u32))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("receiver sockets: {e}"))?;
    let setup = t0.elapsed();
    let w = workload::fanout(&tx, &rxs, c.warmup, c.batch).map_err(|e| format!("warm-up: {e}"))?;
    let mut r = workload::fanout(&tx, &rxs, c.fan_frames, c.batch)
        .map_err(|e| format!("run {run}: {e}"))?;
    println!(
        "{tag} (b) {n} receiver(s), run {run}: {} sent, {} received in {:.3} s = {:.0} ns/frame, undisturbed {:.0}; \
         lost {}, odd {}, send retries {}, stalls {} (sockets set up in {:.3} s, warm-up {:.0} ns/frame)",
        r.counts.sent,
        r.counts.received,
        r.elapsed.as_secs_f64(),
        r.ns_per_frame,
        r.ns_fast,
        r.counts.lost,
        r.counts.odd,
        r.counts.send_retries,
        r.counts.stalls,
        setup.as_secs_f64(),
        w.ns_per_frame
    );
    r.setup = setup;
    Ok(r)
}

/// Workload (c) on `ifindex`: warm-up, then `reps` runs of `lat_frames`.
fn bench_latency(
    c: &Config,
    tag: &str,
    ifindex: i32,
    round: usize,
    s: &mut Samples,
) -> Result<(), String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let rx = workload::receiver(ifindex, workload::LAT_ID)
        .map_err(|e| format!("receiver socket: {e}"))?;
    let w = workload::latency(&tx, &rx, c.warmup).map_err(|e| format!("warm-up: {e}"))?;
    println!(
        "{tag} (c) warm-up: p50 {:.1} us",
        w.percentile(50.0) as f64 / 1e3
    );
    for i in 1..=c.reps {
        let r = workload::latency(&tx, &rx, c.lat_frames).map_err(|e| format!("run {i}: {e}"))?;
        let us = |p: f64| r.percentile(p) as f64 / 1e3;
        println!(
            "{tag} (c) run {i}/{}: {} frames: p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, \
             p99.9 {:.1} us, max {:.1} us; lost {}, odd {}, stalls {}",
            c.reps,
            r.counts.received,
            us(50.0),
            us(90.0),
            us(99.0),
            us(99.9),
            us(100.0),
            r.counts.lost,
            r.counts.odd,
            r.counts.stalls
        );
        s.lat.push((
            round,
            LatencyStats {
                p50: r.percentile(50.0),
                p99: r.percentile(99.0),
                max: r.percentile(100.0),
                lost: r.counts.lost,
                odd: r.counts.odd,
            },
        ));
    }
    Ok(())
}

/// One round on one stack: load it (unless `--no-load`), run the selected
/// workloads, remove it again. Failures are recorded in `s` and switch the
/// failing part off for later rounds.
fn bench_round(c: &Config, stack: Stack, round: usize, s: &mut Samples) {
    let tag = if c.rounds > 1 {
        format!("[{stack} {round}/{}]", c.rounds)
    } else {
        format!("[{stack}]")
    };
    let fail = |s: &mut Samples, what: String| {
        println!("{tag} FAILED: {what}");
        s.errors.push(format!("round {round}: {what}"));
    };
    println!("=== {stack} stack, round {round}/{}", c.rounds);
    if c.load {
        if let Some(f) = stack::missing_module(stack, &c.paths) {
            fail(s, format!("module not available: {}", f.display()));
            s.broken = true;
            return;
        }
        if let Err(e) =
            stack::unload_all(&c.iface).and_then(|()| stack::load(stack, &c.paths, &c.iface))
        {
            fail(s, format!("setup: {e}"));
            s.broken = true;
            let _ = stack::unload_all(&c.iface);
            return;
        }
    }
    let started = Instant::now();
    match can::ifindex(&c.iface) {
        Err(e) => {
            fail(s, format!("{}: {e}", c.iface));
            s.broken = true;
        }
        Ok(ifindex) => {
            if c.run_a && !s.tp_off {
                if let Err(e) = bench_throughput(c, &tag, ifindex, round, s) {
                    fail(s, format!("(a) throughput: {e}"));
                    s.tp_off = true;
                }
            }
            if c.run_b {
                // Receiver counts interleaved run by run, so that slow
                // drifts of the host's load hit all of them alike.
                for i in 1..=c.reps {
                    for &n in &c.fan_counts {
                        if s.fan_off.contains(&n) {
                            continue;
                        }
                        match bench_fanout(c, &tag, ifindex, n, &format!("{i}/{}", c.reps)) {
                            Ok(r) => s.fan.push((round, n, r)),
                            Err(e) => {
                                fail(s, format!("(b) {n} receivers: {e}"));
                                s.fan_off.push(n);
                            }
                        }
                    }
                }
            }
            if c.run_c && !s.lat_off {
                if let Err(e) = bench_latency(c, &tag, ifindex, round, s) {
                    fail(s, format!("(c) latency: {e}"));
                    s.lat_off = true;
                }
            }
        }
    }
    println!(
        "{tag} workloads took {:.1} s",
        started.elapsed().as_secs_f64()
    );
    if c.load {
        if let Err(e) = stack::unload_all(&c.iface) {
            fail(s, format!("unload: {e}"));
            s.broken = true;
        }
    }
}

/// Prints the medians of one stack so far.
fn print_medians(r: &StackResult) {
    let tag = format!("[{}]", r.stack);
    if let Some(t) = r.throughput {
        println!(
            "{tag} (a) throughput: median {:.0} frames/s undisturbed, {:.0} whole runs, over {} runs; lost {}",
            t.fps, t.fps_run, t.runs, t.lost
        );
    }
    for f in &r.fanout {
        println!(
            "{tag} (b) {} receiver(s): median {:.0} ns/frame undisturbed, {:.0} whole runs, over {} runs; lost {}",
            f.receivers, f.ns_per_frame, f.ns_run, f.runs, f.lost
        );
    }
    if let Some((n, x)) = r.fanout_ratio() {
        println!("{tag} (b) cost per frame, {n} receivers : 1 receiver = {x:.2}");
    }
    if let Some(l) = r.latency {
        println!(
            "{tag} (c) latency: median p50 {:.1} us, median p99 {:.1} us, max {:.1} us over {} runs; lost {}",
            l.p50 as f64 / 1e3,
            l.p99 as f64 / 1e3,
            l.max as f64 / 1e3,
            l.runs,
            l.lost
        );
    }
}

fn cpu_name(cpu: Option<usize>) -> String {
    cpu.map_or_else(|| "any CPU".to_string(), |n| format!("CPU {n}"))
}

/// Kernel, CPUs and settings, for the summary's header.
fn header(c: &Config) -> String {
    let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
    let cpuinfo = read("/proc/cpuinfo");
    let model = cpuinfo
        .lines()
        .find_map(|l| {
            l.strip_prefix("model name")
                .and_then(|r| r.split_once(':'))
                .map(|x| x.1.trim())
        })
        .unwrap_or("?");
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let hv = if cpuinfo.contains(" hypervisor") {
        ", virtualised"
    } else {
        ""
    };
    format!(
        "kernel {} on {cpus} CPU(s) ({model}{hv})\n\
         workloads on {}; {} round(s) x {} run(s) per figure and stack; medians over all runs\n\
         (a) {} frames/run, window {}, receiver thread on {}\n\
         (b) {} frames/run round-robin over the receivers' ids, batch {}\n\
         (c) {} frames/run, one in flight\n\
         undisturbed: from the fastest tenth of the {}-frame chunks (a) or {}-frame batches (b) of a run; \
         whole runs: all frames / all time",
        read("/proc/sys/kernel/osrelease").trim(),
        cpu_name(c.cpu),
        c.rounds,
        c.reps,
        c.tp_frames,
        c.window,
        cpu_name(c.rx_cpu.or(c.cpu)),
        c.fan_frames,
        c.batch,
        c.lat_frames,
        workload::CHUNK,
        c.batch
    )
}

fn main() -> ExitCode {
    let c = match parse_args(std::env::args().skip(1), Env::from_process()) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("rcan-bench: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let hdr = header(&c);
    // The kernel and CPU line, for the other parts' summaries.
    let hdr1 = hdr.lines().next().unwrap_or_default().to_string();
    println!("rcan-bench: {hdr}");
    let mut want = 0u64;
    if c.run_raw && c.run_b {
        want = *c.fan_counts.iter().max().unwrap_or(&1) as u64 + 64;
    }
    if c.run_table {
        let most = c.table.counts.iter().copied().max().unwrap_or(0).max(1000);
        want = want.max(most as u64 + 64);
    }
    if want > 0 {
        match can::raise_nofile(want) {
            Ok(n) => println!("rcan-bench: RLIMIT_NOFILE {n}"),
            Err(e) => println!("rcan-bench: cannot raise RLIMIT_NOFILE to {want}: {e}"),
        }
    }
    if let Some(cpu) = c.cpu {
        // Threads inherit this, so every workload runs on that CPU.
        if let Err(e) = can::pin_current_thread(cpu) {
            eprintln!("rcan-bench: cannot pin to CPU {cpu}: {e}");
            return ExitCode::from(2);
        }
    }
    let t0 = Instant::now();
    let mut samples: Vec<(Stack, Samples)> = c
        .stacks
        .iter()
        .map(|&st| (st, Samples::default()))
        .collect();
    let results = |samples: &[(Stack, Samples)], round: Option<usize>| -> Vec<StackResult> {
        samples.iter().map(|(st, s)| s.result(*st, round)).collect()
    };
    let summary = |samples: &[(Stack, Samples)]| {
        let per_round: Vec<_> = (1..=c.rounds).map(|k| results(samples, Some(k))).collect();
        report::summary(&results(samples, None), &per_round, &hdr)
    };
    let raw_rounds = if c.run_raw { c.rounds } else { 0 };
    for round in 1..=raw_rounds {
        // Odd rounds in the given order, even rounds reversed (mainline,
        // ours, ours, mainline, ...): neither stack always goes first.
        let mut order: Vec<usize> = (0..samples.len()).collect();
        if round % 2 == 0 {
            order.reverse();
        }
        for i in order {
            let (stack, s) = &mut samples[i];
            if !s.broken {
                bench_round(&c, *stack, round, s);
            }
        }
        // Written after each round: a later crash keeps the earlier figures.
        if let Some(p) = &c.summary {
            if let Err(e) = std::fs::write(p, summary(&samples)) {
                eprintln!("rcan-bench: {}: {e}", p.display());
            }
        }
    }
    let all = results(&samples, None);
    let mut failed = all.iter().any(|r| !r.errors.is_empty());
    let raw_text = if c.run_raw {
        println!();
        all.iter().for_each(print_medians);
        println!();
        let t = summary(&samples);
        print!("{t}");
        t + "\n"
    } else {
        String::new()
    };
    let table_text = if c.run_table {
        let write = |s: &table::Samples| {
            if let Some(p) = &c.summary {
                let text = raw_text.clone() + &table::summary(&c.table, s, &hdr1);
                if let Err(e) = std::fs::write(p, text) {
                    eprintln!("rcan-bench: {}: {e}", p.display());
                }
            }
        };
        let ts = table::bench(&c.table, &c.stacks, &c.paths, &write);
        println!();
        let t = table::summary(&c.table, &ts, &hdr1);
        print!("{t}");
        failed |= !ts.errors.is_empty();
        raw_text.clone() + &t + "\n"
    } else {
        raw_text.clone()
    };
    if c.run_dsor {
        let dc = dsor::Config {
            protos: c.protos.clone(),
            sizes: c.msg_sizes.clone(),
            rounds: c.rounds,
            secs: c.msg_secs,
            min_msgs: c.msg_min,
            warmup: c.msg_warmup,
            iface: c.iface.clone(),
            load: c.load,
            cpu: c.cpu,
        };
        let dhdr = hdr1.clone();
        let write = |s: &dsor::Samples| {
            if let Some(p) = &c.summary {
                let text = table_text.clone() + &dsor::summary(&dc, s, &dhdr);
                if let Err(e) = std::fs::write(p, text) {
                    eprintln!("rcan-bench: {}: {e}", p.display());
                }
            }
        };
        let ds = dsor::bench(&dc, &c.paths, &write);
        println!();
        print!("{}", dsor::summary(&dc, &ds, &dhdr));
        failed |= !ds.errors.is_empty();
    }
    if c.run_bcm {
        let bc = bcm::Config {
            rounds: c.rounds,
            jobs: c.bcm_jobs,
            ival_ms: c.bcm_ival_ms,
            secs: c.bcm_secs,
            iface: c.iface.clone(),
            stacks: c.stacks.clone(),
        };
        let (runs, errors) = bcm::bench(&bc, &c.paths);
        let text = bcm::summary(&bc, &runs);
        print!("{text}");
        if let Some(p) = &c.summary {
            let old = std::fs::read_to_string(p).unwrap_or_default();
            if let Err(e) = std::fs::write(p, old + &text) {
                eprintln!("rcan-bench: {}: {e}", p.display());
            }
        }
        failed |= !errors.is_empty();
    }
    println!("rcan-bench: done in {:.0} s", t0.elapsed().as_secs_f64());
    if let Some(p) = &c.summary {
        println!("rcan-bench: summary saved in {}", p.display());
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use table::Kind;

    /// The environment of every test: as `bench.sh` sets it up in the VM.
    fn env() -> Env {
        Env {
            out: Some(PathBuf::from("/out")),
            root: PathBuf::from("/rcan"),
            kbuild: Some(PathBuf::from("/kbuild")),
        }
    }

    fn parse(args: &[&str]) -> Result<Config, String> {
        parse_args(args.iter().map(|a| a.to_string()), env())
    }

    /// What `rcan-bench` with no options runs, written out in full.
    fn defaults() -> Config {
        Config {
            run_raw: true,
            run_table: true,
            run_dsor: true,
            run_bcm: false,
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
        assert_eq!(parse_args(Vec::new(), no_out), Ok(e));
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
    }

    /// Values the parser refuses, each with everything else valid.
    #[test]
    fn refused() {
        for args in [
            &["--part", "nosuch"][..],
            &["--part", ""],
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
            &["--rx-cpu", "any"],
            &["--cpu", "first"],
            &["--bogus"],
            &["can0"],
        ] {
            assert!(parse(args).is_err(), "{args:?} accepted");
        }
    }
}
