// SPDX-License-Identifier: GPL-2.0
//! The command line as a user meets it (see `rcan-cli-check`).

#[test]
fn help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_sja1000config"),
        "sja1000config",
        env!("CARGO_PKG_VERSION"),
        &[
            &[],
            &["nosuch0", "btr0"],
            &["nosuch0", "btr0", "256"],
            &["nosuch0", "speed", "1"],
        ],
    );
}
