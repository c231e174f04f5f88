// SPDX-License-Identifier: GPL-2.0
//! The command line as a user meets it (see `rcan-cli-check`).

#[test]
fn help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_dsor-peer"),
        "dsor-peer",
        env!("CARGO_PKG_VERSION"),
        &[
            &[],
            &["--if", "nosuch0", "--node", "5", "recv"],
            &["--if", "nosuch0", "--node", "5", "fly", "--count", "1"],
            &[
                "--if", "nosuch0", "--node", "5", "send", "--to", "1", "--prio", "0",
            ],
        ],
    );
}
