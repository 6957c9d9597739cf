use std::process::ExitCode;

use clap::Parser;
use eyebot_hil::cli::{Cli, LogFormat};
use tracing_subscriber::EnvFilter;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter =
        EnvFilter::try_from_env("EYEBOT_HIL_LOG").unwrap_or_else(|_| EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    match cli.log_format {
        LogFormat::Text => builder.init(),
        LogFormat::Json => builder.json().init(),
    }
    match eyebot_hil::cli::main(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eyebot_hil::cli::output::write_err(format_args!("eyebot-hil: {err}\n"));
            ExitCode::FAILURE
        }
    }
}
