// SPDX-License-Identifier: GPL-2.0
//! The test cases, grouped by topic. Each file exports a `TESTS` table.

mod errors;
mod filter;
mod lifecycle;
mod loopdrv;
mod modules;
mod recv;
mod socket;

use crate::ctx::{dev, Ctx};
use crate::Test;

/// `test_table![a, b]`: a table of [`Test`]s named after their functions.
macro_rules! test_table {
    ($($f:ident),* $(,)?) => {
        &[$(crate::Test { name: stringify!($f), run: $f }),*]
    };
}
pub(crate) use test_table;

/// Every test, in running order.
pub fn all() -> impl Iterator<Item = &'static Test> {
    [
        modules::TESTS,
        socket::TESTS,
        recv::TESTS,
        filter::TESTS,
        errors::TESTS,
        loopdrv::TESTS,
        lifecycle::TESTS,
    ]
    .into_iter()
    .flatten()
}

/// Loads the stack with one loopback device (up); returns can0's ifindex.
fn stack1(ctx: &mut Ctx) -> Result<u32, String> {
    ctx.load_stack(&[])?;
    ctx.ifindex(&dev(0))
}

/// Loads the stack with two loopback devices (up); returns their ifindexes.
fn stack2(ctx: &mut Ctx) -> Result<(u32, u32), String> {
    ctx.load_stack(&["count=2"])?;
    Ok((ctx.ifindex(&dev(0))?, ctx.ifindex(&dev(1))?))
}

#[cfg(test)]
mod tests {
    #[test]
    fn names_are_unique() {
        let mut names: Vec<_> = super::all().map(|t| t.name).collect();
        let n = names.len();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), n);
    }
}
