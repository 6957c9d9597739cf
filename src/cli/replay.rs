//! `eyebot-hil replay LOG... [options]`: arguments, output set-up and the terminal report.
//! The replay itself is [`crate::replay`]; formats and rules are in `docs/replay.md`.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::cli::output::{err, errln, out, readyln};
use crate::replay::{
    ByteSink, CommentMode, LineOrigin, Loc, NullSink, Observer, Options, Pacing, Policy, Port,
    Problem, Replay, ReplayError, Sent, Shutdown, Sink,
};
use crate::transport::LineSettings;
use crate::transport::pty::{PtyError, PtyMaster};
use crate::transport::serial::{self, SerialError};

/// `--pacing` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PacingArg {
    /// By the logs' timestamps when every log has them, else `baud`.
    Auto,
    /// By the logs' timestamps.
    Timestamps,
    /// A fixed sentence rate (`--rate`).
    Rate,
    /// Back to back at the line's baud rate.
    Baud,
    /// As fast as the consumer reads (blocking writes are the back-pressure).
    Fast,
}

/// Replay captured NMEA logs onto a pty, a serial device or stdout.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// Logs: NMEA text (optionally with a seconds or ISO 8601 timestamp prefix per line),
    /// `--record` directories or their bytes.tsv; any may be gzip-compressed. Several logs
    /// are merged by time.
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// How sentences are paced.
    #[arg(long, value_enum, default_value_t = PacingArg::Auto)]
    pub pacing: PacingArg,
    /// Sentences per second for `--pacing rate` (implies it when given alone).
    #[arg(long, value_name = "HZ")]
    pub rate: Option<f64>,
    /// Speed factor on the schedule (2 = twice as fast), from 0.001 to 1000; bytes keep
    /// their wire time (for "as fast as the line takes it", use `--pacing fast`).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Start this many seconds of log time after the first sentence.
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0)]
    pub start: f64,
    /// Stop after this many seconds of log time from the first sentence.
    #[arg(long, value_name = "SECONDS")]
    pub end: Option<f64>,
    /// Start again from the beginning when the logs end, until interrupted.
    #[arg(long = "loop")]
    pub looping: bool,
    /// Line settings, e.g. "4800 8N1" (default: the first `#Serial:` comment, else 4800 8N1).
    #[arg(long, value_name = "SETTINGS")]
    pub line: Option<LineSettings>,
    /// What to do with lines that fail checks: send unchanged, drop, or repair.
    #[arg(long, value_enum, default_value_t = Policy::Pass)]
    pub policy: Policy,
    /// What to do with `#` comments other than `#Serial:`.
    #[arg(long, value_enum, default_value_t = CommentMode::Report)]
    pub comments: CommentMode,
    /// Which recorded link to replay from `--record` output (its `tx` bytes).
    #[arg(long, default_value = "sonar")]
    pub link: String,
    /// Output: a new pty with a symlink at PATH (the default output, at run/replay).
    #[arg(long, value_name = "PATH", conflicts_with_all = ["serial", "stdout"])]
    pub pty: Option<PathBuf>,
    /// Output: a real serial device, opened with the line settings.
    #[arg(long, value_name = "DEVICE", conflicts_with = "stdout")]
    pub serial: Option<PathBuf>,
    /// Output: standard output.
    #[arg(long)]
    pub stdout: bool,
    /// Output: the sonar multiplexer inside a running `eyebot-hil run` whose run directory is
    /// RUN_DIR (default `run`): the sentences replace the simulated sonar, and the EyeBot
    /// reads them through the normal select/ack protocol (docs/replay.md).
    #[arg(long, value_name = "RUN_DIR", num_args = 0..=1, default_missing_value = "run", conflicts_with_all = ["pty", "serial", "stdout"])]
    pub into_sonar: Option<PathBuf>,
    /// Read, check and schedule everything, send nothing, no waiting.
    #[arg(long)]
    pub dry_run: bool,
    /// Print sentence counts by type, time span, gaps and checksum failures at the end.
    #[arg(long)]
    pub stats: bool,
    /// Gaps between sentences longer than this are counted by `--stats`.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    pub gap: f64,
    /// List every problem (default: the first 50 of each kind; all are counted).
    #[arg(long)]
    pub all_problems: bool,
    /// SCHED_FIFO priority of the pacing thread for timed pacing (0 = do not ask). Without
    /// it, a loaded machine can wake the replay a scheduler tick (4 ms) late.
    #[arg(long, value_name = "1-99", default_value_t = 10, value_parser = clap::value_parser!(i32).range(0..=99))]
    pub rt_priority: i32,
    /// Hold a CPU latency QoS request (/dev/cpu_dma_latency) of this many µs while pacing, as
    /// cyclictest does, so idle CPUs poll rather than halt; 0 asks for the shortest wake-up.
    /// Costs power; needs root. Off by default.
    #[arg(long, value_name = "MICROSECONDS")]
    pub cpu_latency_us: Option<u32>,
}

/// Why `replay` failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayCliError {
    #[error(transparent)]
    Replay(#[from] ReplayError),
    #[error("replay output: {0}")]
    Pty(#[from] PtyError),
    #[error("replay output: {0}")]
    Serial(#[from] SerialError),
    #[error(
        "--into-sonar: cannot reach the daemon's sonar feed {path}: {source} (is `eyebot-hil run` running with that run directory?)"
    )]
    IntoSonar {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("--pacing rate needs --rate HZ")]
    RateMissing,
    #[error("cannot start the runtime for the output: {0}")]
    Runtime(#[source] std::io::Error),
    #[error("{0} input(s) cut short by a read error; the summary above counts what was read")]
    CutShort(u64),
}

impl ReplayArgs {
    /// The library options these arguments describe.
    pub fn options(&self) -> Result<Options, ReplayCliError> {
        let pacing = match (self.pacing, self.rate) {
            (PacingArg::Auto, None) => None,
            (PacingArg::Auto | PacingArg::Rate, Some(per_s)) => Some(Pacing::Rate { per_s }),
            (PacingArg::Rate, None) => return Err(ReplayCliError::RateMissing),
            (PacingArg::Timestamps, _) => Some(Pacing::Timestamps),
            (PacingArg::Baud, _) => Some(Pacing::Baud),
            (PacingArg::Fast, _) => Some(Pacing::Fast),
        };
        let mut opts = Options::new(self.logs.clone());
        opts.pacing = pacing;
        opts.policy = self.policy;
        opts.speed = self.speed;
        opts.start_s = self.start;
        opts.end_s = self.end;
        opts.looping = self.looping && !self.dry_run;
        opts.line = self.line;
        opts.link = self.link.clone();
        opts.comments = self.comments;
        opts.gap_threshold_s = self.gap;
        opts.list_all_problems = self.all_problems;
        opts.realtime_priority = (self.rt_priority > 0).then_some(self.rt_priority);
        opts.cpu_latency_us = self.cpu_latency_us;
        Ok(opts)
    }
}

/// The terminal report: problems and comments on stderr, a progress bar on a TTY.
struct Terminal {
    bar: Option<ProgressBar>,
}

impl Terminal {
    fn line(&self, text: &str) {
        match &self.bar {
            Some(bar) => bar.println(text),
            None => errln!("{text}"),
        }
    }
}

impl Observer for Terminal {
    fn problem(&mut self, problem: &Problem) {
        self.line(&format!("replay: {problem}"));
    }
    fn comment(&mut self, loc: &Loc, text: &str) {
        self.line(&format!("replay: {loc}: comment: {text}"));
    }
    fn sent(&mut self, _loc: &Loc, _bytes: &[u8], _sent: &Sent) {}
    fn progress(&mut self, read_bytes: u64, sentences: u64) {
        if let Some(bar) = &self.bar {
            if read_bytes < bar.position() {
                bar.reset(); // a new --loop pass
            }
            bar.set_position(read_bytes);
            bar.set_message(format!("{sentences} sentences"));
        }
    }
    fn note(&mut self, text: &str) {
        self.line(&format!("replay: {text}"));
    }
}

/// Runs `eyebot-hil replay`.
pub fn main(args: ReplayArgs) -> Result<(), ReplayCliError> {
    let opts = args.options()?;
    // The pty and serial types register with a tokio reactor; the replay itself runs on this
    // thread with blocking writes and high-resolution sleeps. A second thread waits for
    // SIGINT/SIGTERM and raises the shutdown flag, so symlinks are removed on the way out and
    // a read of a pipe or FIFO (opened below, read once) ends.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(ReplayCliError::Runtime)?;
    let handle = runtime.handle().clone();
    let stop = Shutdown::new();
    let signal_stop = stop.clone();
    std::thread::Builder::new()
        .name("replay-signals".into())
        .spawn(move || runtime.block_on(wait_for_signal(signal_stop)))
        .map_err(ReplayCliError::Runtime)?;
    let _enter = handle.enter();
    let replay = Replay::open_until(opts, &stop)?;
    let line = replay.line_settings();
    let origin_note = match replay.line_origin() {
        LineOrigin::CommandLine => "--line".to_string(),
        LineOrigin::SerialComment(loc) => format!("#Serial: at {loc}"),
        LineOrigin::Default => "default".to_string(),
    };
    for input in replay.inputs() {
        errln!(
            "replay: {}: {}{}",
            input.path.display(),
            input.format,
            if input.gzip { ", gzip" } else { "" }
        );
    }
    errln!(
        "replay: line {line} ({origin_note}); pacing {}; speed {}; policy {:?}",
        if args.dry_run {
            "none (dry run)".to_string()
        } else {
            replay.pacing().to_string()
        },
        args.speed,
        args.policy
    );

    let mut sink: Box<dyn Sink> = if args.dry_run {
        Box::new(NullSink)
    } else if args.stdout {
        Box::new(ByteSink::new(Port::Stdout(std::io::stdout()), &line))
    } else if let Some(run_dir) = &args.into_sonar {
        let path = run_dir.join(crate::daemon::feed::FEED_SOCKET);
        let stream = std::os::unix::net::UnixStream::connect(&path).map_err(|source| {
            ReplayCliError::IntoSonar {
                path: path.clone(),
                source,
            }
        })?;
        readyln!(
            "replay into the sonar multiplexer of the daemon at {}",
            run_dir.display()
        );
        Box::new(ByteSink::new(Port::Writer(Box::new(stream)), &line))
    } else if let Some(device) = &args.serial {
        let port = serial::open(device, &line)?;
        readyln!("replay {} ({line})", device.display());
        Box::new(ByteSink::new(Port::Serial(port), &line))
    } else {
        let link = args
            .pty
            .clone()
            .unwrap_or_else(|| PathBuf::from("run/replay"));
        let pty = PtyMaster::open(Some(&link))?;
        readyln!(
            "replay {} -> {}",
            pty.client_path().display(),
            pty.slave_path().display()
        );
        Box::new(ByteSink::new(Port::Pty(pty), &line))
    };

    let stderr_tty = std::io::stderr().is_terminal();
    let bar = (stderr_tty && !args.dry_run).then(|| {
        let bar = ProgressBar::with_draw_target(
            Some(replay.total_input_bytes()),
            ProgressDrawTarget::stderr_with_hz(4),
        );
        if let Ok(style) = ProgressStyle::with_template(
            "{elapsed_precise} [{wide_bar}] {bytes}/{total_bytes} {bytes_per_sec} ETA {eta} {msg}",
        ) {
            bar.set_style(style);
        }
        bar.enable_steady_tick(Duration::from_millis(250));
        bar
    });
    let mut terminal = Terminal { bar };
    let started = Instant::now();
    let result = replay.run(sink.as_mut(), &mut terminal, &stop);
    if let Some(bar) = &terminal.bar {
        bar.finish_and_clear();
    }
    // A reader of standard output that stops early (`| head`) ends the replay quietly, as
    // it ends any Unix tool.
    if args.stdout
        && let Err(crate::replay::ReplayError::Sink(crate::replay::SinkError::Io {
            source, ..
        })) = &result
        && source.kind() == std::io::ErrorKind::BrokenPipe
    {
        return Ok(());
    }
    let summary = result?;
    if stop.is_triggered() {
        errln!(
            "replay: stopped by signal after {:.3} s",
            started.elapsed().as_secs_f64()
        );
    }
    err!("{summary}");
    if args.stats {
        // With sentences on stdout, the statistics go to stderr.
        if args.stdout && !args.dry_run {
            err!("{}", summary.stats_text());
        } else {
            out!("{}", summary.stats_text());
        }
    }
    drop(sink); // removes the pty symlink
    if summary.inputs_cut_short > 0 {
        return Err(ReplayCliError::CutShort(summary.inputs_cut_short));
    }
    Ok(())
}

async fn wait_for_signal(stop: Shutdown) {
    use tokio::signal::unix::{SignalKind, signal};
    let (Ok(mut int), Ok(mut term)) = (
        signal(SignalKind::interrupt()),
        signal(SignalKind::terminate()),
    ) else {
        tracing::warn!("cannot install signal handlers; Ctrl-C will not clean up");
        return;
    };
    tokio::select! {
        _ = int.recv() => {}
        _ = term.recv() => {}
    }
    stop.trigger();
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;
    use crate::cli::{Cli, Command};

    fn parse(args: &[&str]) -> ReplayArgs {
        let cli = Cli::try_parse_from(["eyebot-hil", "replay"].iter().chain(args)).unwrap();
        match cli.command {
            Command::Replay(a) => a,
            #[allow(unreachable_patterns)]
            _ => panic!("not replay"),
        }
    }

    #[test]
    fn options_follow_the_arguments() {
        let a = parse(&[
            "a.log", "b.log.gz", "--rate", "5", "--speed", "2", "--policy", "fix", "--line",
            "9600 8N1", "--loop", "--start", "1.5", "--end", "3",
        ]);
        let o = a.options().unwrap();
        assert_eq!(o.inputs.len(), 2);
        assert_eq!(o.pacing, Some(Pacing::Rate { per_s: 5.0 }));
        assert_eq!(o.speed, 2.0);
        assert_eq!(o.policy, Policy::Fix);
        assert_eq!(o.line, Some(LineSettings::n81(9600)));
        assert!(o.looping);
        assert_eq!((o.start_s, o.end_s), (1.5, Some(3.0)));
        assert_eq!(parse(&["a.log"]).options().unwrap().pacing, None);
        assert!(matches!(
            parse(&["a.log", "--pacing", "rate"]).options(),
            Err(ReplayCliError::RateMissing)
        ));
        assert!(
            Cli::try_parse_from(["eyebot-hil", "replay", "a", "--stdout", "--pty", "x"]).is_err()
        );
        assert!(Cli::try_parse_from(["eyebot-hil", "replay", "a", "--line", "4801 8N1"]).is_err());
    }
}
