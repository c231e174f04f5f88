// SPDX-License-Identifier: GPL-2.0
//! Where a run's time goes: per test, the guest seconds it took and how
//! many of the guest's CPU seconds were busy meanwhile (from the `cpu`
//! line of `/proc/stat`: user, nice, system, irq, softirq and steal, over
//! every vCPU); at the end of the run, the slowest tests and the whole
//! run's busy share. A test whose CPU seconds are far below its seconds
//! times the number of vCPUs was mostly waiting (on a timeout, a timer, a
//! sleep, another process). Printed, never checked: the figures depend on
//! the host's speed and load (build.rst).

use std::fs;
use std::time::Instant;

/// The guest's CPU counters at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CpuTimes {
    /// Busy seconds summed over every CPU since boot.
    pub busy: f64,
    /// All seconds (busy, idle, iowait) summed over every CPU since boot.
    pub total: f64,
}

impl CpuTimes {
    /// Parses the aggregate `cpu` line of `/proc/stat`, whose fields are
    /// in clock ticks of `hz` a second. None if the line is missing or
    /// malformed.
    pub fn parse(stat: &str, hz: f64) -> Option<Self> {
        let line = stat.lines().find(|l| l.starts_with("cpu "))?;
        let v: Vec<f64> = line
            .split_whitespace()
            .skip(1)
            .map(|f| f.parse::<f64>().ok())
            .collect::<Option<_>>()?;
        // user nice system idle iowait irq softirq steal [guest guest_nice]:
        // guest time is already counted in user and nice.
        let field = |i: usize| v.get(i).copied().unwrap_or(0.0);
        if v.len() < 4 {
            return None;
        }
        let busy = field(0) + field(1) + field(2) + field(5) + field(6) + field(7);
        let idle = field(3) + field(4);
        Some(Self {
            busy: busy / hz,
            total: (busy + idle) / hz,
        })
    }

    /// The counters now (zero if `/proc/stat` cannot be read: the figures
    /// are then zero, and nothing else changes).
    pub fn now() -> Self {
        // SAFETY: sysconf takes a constant and has no preconditions.
        // USER_HZ is 100 on x86, the fallback if it fails.
        let hz = match unsafe { libc::sysconf(libc::_SC_CLK_TCK) } {
            n if n > 0 => n as f64,
            _ => 100.0,
        };
        fs::read_to_string("/proc/stat")
            .ok()
            .and_then(|s| Self::parse(&s, hz))
            .unwrap_or_default()
    }
}

/// One finished test's figures.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// The test's name.
    pub name: &'static str,
    /// Guest seconds from its start to its cleanup's end.
    pub secs: f64,
    /// Busy CPU seconds over every vCPU meanwhile.
    pub cpu: f64,
}

/// A test being timed.
pub struct Timer {
    start: Instant,
    cpu: CpuTimes,
}

impl Timer {
    /// Starts timing.
    pub fn start() -> Self {
        Self {
            start: Instant::now(),
            cpu: CpuTimes::now(),
        }
    }

    /// Ends timing the test `name`.
    pub fn stop(&self, name: &'static str) -> Sample {
        let cpu = CpuTimes::now();
        Sample {
            name,
            secs: self.start.elapsed().as_secs_f64(),
            cpu: (cpu.busy - self.cpu.busy).max(0.0),
        }
    }
}

/// The whole run's figures.
#[derive(Default)]
pub struct Report {
    samples: Vec<Sample>,
}

impl Report {
    /// Adds a finished test.
    pub fn add(&mut self, s: Sample) {
        self.samples.push(s);
    }

    /// The report's lines (TAP comments): the `n` slowest tests, slowest
    /// first, then the run's total, with `ncpu` vCPUs.
    pub fn lines(&self, n: usize, ncpu: usize) -> Vec<String> {
        let mut by_time: Vec<&Sample> = self.samples.iter().collect();
        by_time.sort_by(|a, b| b.secs.total_cmp(&a.secs).then(a.name.cmp(b.name)));
        let ncpu = ncpu.max(1) as f64;
        let share = |cpu: f64, secs: f64| {
            if secs > 0.0 {
                100.0 * cpu / (secs * ncpu)
            } else {
                0.0
            }
        };
        let mut out = vec![format!(
            "# the {} slowest tests (guest seconds; busy CPU seconds over {} vCPUs, \
             and their share of the test's CPU time):",
            n.min(by_time.len()),
            ncpu
        )];
        for s in by_time.iter().take(n) {
            out.push(format!(
                "#   {:>7.1} s  cpu {:>7.1} s {:>3.0} %  {}",
                s.secs,
                s.cpu,
                share(s.cpu, s.secs),
                s.name
            ));
        }
        let secs: f64 = self.samples.iter().map(|s| s.secs).sum();
        let cpu: f64 = self.samples.iter().map(|s| s.cpu).sum();
        out.push(format!(
            "# {} tests in {:.1} s, CPUs busy {:.1} s of {:.1} s ({:.0} %; the rest is waiting)",
            self.samples.len(),
            secs,
            cpu,
            secs * ncpu,
            share(cpu, secs)
        ));
        out
    }
}

/// The number of CPUs the guest has online (at least 1): the `cpuN`
/// lines of `/proc/stat`, which count every online CPU whatever the
/// calling thread's affinity (a test may pin its thread to one CPU, which
/// `available_parallelism` would report).
pub fn online_cpus() -> usize {
    let stat = fs::read_to_string("/proc/stat").unwrap_or_default();
    count_cpus(&stat).max(1)
}

/// The number of `cpuN` lines in a `/proc/stat` text.
fn count_cpus(stat: &str) -> usize {
    stat.lines()
        .filter(|l| {
            // "cpuN ...", not the aggregate "cpu  ...".
            l.strip_prefix("cpu")
                .and_then(|r| r.split(' ').next())
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    const STAT: &str = "cpu  100 20 30 400 50 6 4 0 0 0\n\
                        cpu0 50 10 15 200 25 3 2 0 0 0\n\
                        intr 1 2 3\n";

    #[test]
    fn parses_the_aggregate_line() {
        let t = CpuTimes::parse(STAT, 100.0).unwrap();
        assert!((t.busy - 1.6).abs() < 1e-9, "{t:?}");
        assert!((t.total - 6.1).abs() < 1e-9, "{t:?}");
        assert_eq!(CpuTimes::parse("cpu0 1 2 3 4\n", 100.0), None);
        assert_eq!(CpuTimes::parse("cpu  1 x 3 4\n", 100.0), None);
    }

    #[test]
    fn counts_cpu_lines() {
        assert_eq!(count_cpus(STAT), 1);
        assert_eq!(
            count_cpus("cpu  1 2 3 4\ncpu0 1 2 3 4\ncpu1 1 2 3 4\nctxt 5\n"),
            2
        );
    }

    #[test]
    fn slowest_first_and_totals() {
        let mut r = Report::default();
        for (name, secs, cpu) in [("a", 1.0, 0.5), ("b", 4.0, 4.0), ("c", 2.0, 0.0)] {
            r.add(Sample { name, secs, cpu });
        }
        let l = r.lines(2, 2);
        assert_eq!(l.len(), 4, "{l:#?}");
        assert!(l[1].ends_with(" b") && l[1].contains(" 50 %"), "{}", l[1]);
        assert!(l[2].ends_with(" c") && l[2].contains("   0 %"), "{}", l[2]);
        assert!(
            l[3].starts_with("# 3 tests in 7.0 s, CPUs busy 4.5 s of 14.0 s (32 %"),
            "{}",
            l[3]
        );
    }
}
