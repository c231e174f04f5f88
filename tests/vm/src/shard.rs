// SPDX-License-Identifier: GPL-2.0
//! `--shard I/N`: the suite split over N runs in N VMs booted side by side
//! (`run-tests.sh`). Each VM has its own kernel, modules and emulated
//! cards, so the shards cannot disturb each other; what they share is the
//! host's two cores, which one VM leaves mostly idle (it waits on
//! timeouts, timers and program starts: the `cpu` figures of the test
//! lines).
//!
//! The split is balanced by each test's recorded seconds (`weights.txt`
//! beside `Cargo.toml`, one line per test: name, release seconds, debug
//! seconds, from a whole run's test lines by
//! `tools/testing/rcan/test-weights.sh`): longest first, each to the shard
//! with the fewest seconds so far (ties: the lower shard). A test not in
//! the table weighs the table's median. Each shard then runs its tests in
//! the suite's order, and the split depends only on the table and the
//! test list: the same tests land in the same shard on every run.

use std::collections::HashMap;

/// The recorded seconds of the tests, per kernel variant.
const WEIGHTS: &str = include_str!("../weights.txt");

/// One shard of N: `index` in `1..=count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// The whole suite in one run.
    pub const WHOLE: Shard = Shard { index: 1, count: 1 };

    /// Parses `I/N` (1 <= I <= N).
    pub fn parse(s: &str) -> Result<Self, String> {
        let bad = || format!("bad --shard {s:?} (I/N with 1 <= I <= N)");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (i.parse().map_err(|_| bad())?, n.parse().map_err(|_| bad())?);
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }

    /// The positions (in `names`' order) of this shard's tests, balanced
    /// by `weights` (seconds by name; unknown names weigh the median). The
    /// last shard starts with `last_busy` seconds of other work (the
    /// debug kernel's fuzzer runs in its boot): every shard must be given
    /// the same value, or two shards could take one test.
    pub fn select(
        self,
        names: &[&str],
        weights: &HashMap<String, f64>,
        last_busy: f64,
    ) -> Vec<usize> {
        let median = median(weights.values().copied());
        let w = |n: &str| weights.get(n).copied().unwrap_or(median);
        let mut order: Vec<usize> = (0..names.len()).collect();
        // Longest first; equal weights in suite order (a stable sort).
        order.sort_by(|&a, &b| w(names[b]).total_cmp(&w(names[a])));
        let mut load = vec![0.0f64; self.count];
        load[self.count - 1] = last_busy;
        let mut mine = Vec::new();
        for pos in order {
            let (shard, _) = load
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1).then(a.0.cmp(&b.0)))
                .expect("count >= 1");
            load[shard] += w(names[pos]);
            if shard + 1 == self.index {
                mine.push(pos);
            }
        }
        mine.sort_unstable();
        mine
    }
}

/// The recorded seconds of every test on the release (`debug` false) or
/// debug kernel, from `weights.txt`.
pub fn weights(debug: bool) -> HashMap<String, f64> {
    parse_weights(WEIGHTS, debug)
}

/// Parses a weights table: `name release debug` per line, `#` comments.
/// Malformed lines are skipped (a wrong weight only unbalances a split).
fn parse_weights(text: &str, debug: bool) -> HashMap<String, f64> {
    text.lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            let secs = f.get(if debug { 2 } else { 1 })?.parse().ok()?;
            Some((f.first()?.to_string(), secs))
        })
        .collect()
}

/// The median of `v` (1.0 for none).
fn median(v: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = v.collect();
    if v.is_empty() {
        return 1.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(pairs: &[(&str, f64)]) -> HashMap<String, f64> {
        pairs.iter().map(|&(n, s)| (n.to_string(), s)).collect()
    }

    #[test]
    fn every_test_in_exactly_one_shard() {
        let names: Vec<String> = (0..37).map(|i| format!("t{i}")).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        let w = table(&[("t3", 40.0), ("t10", 30.0), ("t11", 0.1), ("t20", 5.0)]);
        for count in 1..5 {
            let mut seen = vec![0; names.len()];
            for index in 1..=count {
                let mine = Shard { index, count }.select(&names, &w, 0.0);
                assert!(mine.windows(2).all(|p| p[0] < p[1]), "suite order");
                mine.iter().for_each(|&p| seen[p] += 1);
            }
            assert!(seen.iter().all(|&n| n == 1), "{count} shards: {seen:?}");
        }
    }

    #[test]
    fn balanced_by_weight() {
        let names = ["a", "b", "c", "d", "e"];
        let w = table(&[("a", 10.0), ("b", 6.0), ("c", 5.0), ("d", 4.0), ("e", 1.0)]);
        // Longest first: a -> 1, b -> 2, c -> 2 (6 < 10), d -> 1 (10 < 11),
        // e -> 2 (11 < 14): 14 and 12 seconds.
        assert_eq!(Shard { index: 1, count: 2 }.select(&names, &w, 0.0), [0, 3]);
        assert_eq!(
            Shard { index: 2, count: 2 }.select(&names, &w, 0.0),
            [1, 2, 4]
        );
    }

    #[test]
    fn last_shard_busy_takes_less() {
        let names = ["a", "b", "c", "d", "e"];
        let w = table(&[("a", 10.0), ("b", 6.0), ("c", 5.0), ("d", 4.0), ("e", 1.0)]);
        // Shard 2 starts at 9 s: a to 1 (10), b to 2 (15), c to 1 (15),
        // d to 1 (the tie goes to the first: 19), e to 2 (16). Without
        // the 9 s, shard 2 would have b, c and e.
        assert_eq!(
            Shard { index: 1, count: 2 }.select(&names, &w, 9.0),
            [0, 2, 3]
        );
        assert_eq!(Shard { index: 2, count: 2 }.select(&names, &w, 9.0), [1, 4]);
    }

    #[test]
    fn unknown_tests_weigh_the_median() {
        let w = table(&[("a", 1.0), ("b", 2.0), ("c", 100.0)]);
        assert_eq!(median(w.values().copied()), 2.0);
        let names = ["c", "x", "y"];
        // c alone in shard 1, the two unknown ones (2 s each) in shard 2.
        assert_eq!(Shard { index: 1, count: 2 }.select(&names, &w, 0.0), [0]);
    }

    #[test]
    fn parses_the_table_and_shards() {
        let w = parse_weights("# name release debug\nab 1.5 7\nbroken\ncd x 2\n", true);
        assert_eq!(w, table(&[("ab", 7.0), ("cd", 2.0)]));
        assert_eq!(parse_weights("ab 1.5 7\n", false), table(&[("ab", 1.5)]));
        assert_eq!(Shard::parse("2/3"), Ok(Shard { index: 2, count: 3 }));
        for bad in ["0/2", "3/2", "2", "a/b", "1/0"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_committed_table_parses() {
        for debug in [false, true] {
            assert!(!weights(debug).is_empty());
        }
    }
}
