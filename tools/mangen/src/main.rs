// SPDX-License-Identifier: GPL-2.0
//! `rcan-mangen DIR`: writes `DIR/man1/TOOL.1` and the bash, zsh and fish
//! completions (`DIR/completions/{bash,zsh,fish}/`) of every rcan tool,
//! from the same clap definitions the tools parse their arguments with,
//! so pages and completions cannot drift from the programs. `make man`
//! runs it into `target/man`.

use clap::Parser;
use clap_complete::Shell;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Write the man pages and shell completions of the rcan tools.
#[derive(Parser, Debug)]
#[command(name = "rcan-mangen", version, about)]
struct Cli {
    /// Output directory (created if missing).
    dir: PathBuf,
}

/// Every tool's command definition.
fn commands() -> Vec<clap::Command> {
    vec![
        sja1000config::command(),
        i82527config::command(),
        dsor_peer::cli::command(),
        rcan_samples::canarb_demo_command(),
        rcan_daemons::cli::zlog_command(),
        rcan_daemons::cli::tcp_command(),
        rcan_daemons::cli::power_command(),
        rcan_daemons::cli::logd_command(),
    ]
}

fn write(dir: &Path, mut cmd: clap::Command) -> std::io::Result<()> {
    let name = cmd.get_name().to_string();
    let man = dir.join("man1");
    fs::create_dir_all(&man)?;
    let mut page = Vec::new();
    clap_mangen::Man::new(cmd.clone()).render(&mut page)?;
    fs::write(man.join(format!("{name}.1")), page)?;
    for shell in [Shell::Bash, Shell::Zsh, Shell::Fish] {
        let out = dir.join("completions").join(shell.to_string());
        fs::create_dir_all(&out)?;
        clap_complete::generate_to(shell, &mut cmd, &name, &out)?;
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    for cmd in commands() {
        let name = cmd.get_name().to_string();
        if let Err(e) = write(&cli.dir, cmd) {
            eprintln!("rcan-mangen: {name}: {}: {e}", cli.dir.display());
            return ExitCode::FAILURE;
        }
        println!("rcan-mangen: {name}");
    }
    ExitCode::SUCCESS
}
