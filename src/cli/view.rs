//! `eyebot-hil view RECORD_DIR`: the live view's page over a recording.

use std::io::Write as _;
use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Args;
use tokio::sync::watch;

use super::CliError;

/// Serve a page that shows a recording (`run --record DIR`) with a time slider: the pool
/// and vehicle, the sonar, plots, link counters and decoded messages at the slider's time.
///
/// Prints `view: URL` (the URL carries the access token) and serves until SIGINT/SIGTERM.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// The recording's directory.
    pub record_dir: PathBuf,
    /// Where to serve (default 127.0.0.1, a port the system picks).
    #[arg(long, value_name = "ADDR:PORT", default_value = crate::view::DEFAULT_ADDR)]
    pub addr: SocketAddr,
    /// Allow an address other than loopback.
    #[arg(long)]
    pub public: bool,
}

pub fn main(args: ViewArgs) -> Result<(), CliError> {
    let runtime = super::runtime()?;
    runtime.block_on(async move {
        let bound = crate::view::bind(args.addr, args.public).await?;
        let (stop_tx, stop_rx) = watch::channel(false);
        tokio::spawn(async move {
            let interrupt = tokio::signal::ctrl_c();
            let mut term =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()).ok();
            let terminate = async {
                match term.as_mut() {
                    Some(t) => {
                        t.recv().await;
                    }
                    None => std::future::pending().await,
                }
            };
            tokio::select! {
                _ = interrupt => {}
                _ = terminate => {}
            }
            let _ = stop_tx.send(true);
        });
        let url = bound.url().to_string();
        let serving = crate::view::serve_recording(bound, &args.record_dir, stop_rx, move || {
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "view: {url}");
            let _ = out.flush();
        });
        serving.await?;
        Ok(())
    })
}
