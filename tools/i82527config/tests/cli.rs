// SPDX-License-Identifier: GPL-2.0
//! The command line as a user meets it (see `rcan-cli-check`).

#[test]
fn help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_i82527config"),
        "i82527config",
        env!("CARGO_PKG_VERSION"),
        &[
            &[],
            &["nosuch0", "answer", "12", "123#00"],
            &["nosuch0", "answer", "1", "800#"],
            &["nosuch0", "withdraw"],
        ],
    );
}
