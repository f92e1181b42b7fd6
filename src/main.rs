//! The `skillpost` binary: a thin dispatcher; see [`skillpost::cli`].
#![forbid(unsafe_code)]

fn main() -> std::process::ExitCode {
    skillpost::cli::main(std::env::args_os())
}
