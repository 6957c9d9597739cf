use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = eyebot_hil::cli::Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("EYEBOT_HIL_LOG")
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    match eyebot_hil::cli::main(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("eyebot-hil: {err:#}");
            ExitCode::FAILURE
        }
    }
}
