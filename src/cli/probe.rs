//! `eyebot-hil probe`: a small EyeBot-side client for people and scripts.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, Subcommand, ValueEnum};
use firmware_protocol::sensor_link::{
    AdcChannel, CompassMode, CompassOutput, Direction, Message, ThrusterCommand,
};
use firmware_protocol::{HeadingFormat, Transducer};

use super::CliError;
use crate::cli::output::outln;
use crate::probe::{SensorClient, SonarClient, SonarItem};
use crate::transport::LineSettings;

/// Talk to a running bridge as an EyeBot would.
#[derive(Debug, Args)]
pub struct ProbeArgs {
    /// The link to open: the sensor link for adc/compass/thrusters/advance/time/hello/counters,
    /// the sonar link for `sonar`.
    #[arg(long)]
    pub link: PathBuf,
    /// Line settings, e.g. "115200 8N1" (default: 115200 8N1, or 4800 8N1 for `sonar`).
    #[arg(long)]
    pub line: Option<LineSettings>,
    #[command(subcommand)]
    pub action: ProbeAction,
}

/// Compass output format.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum CompassFormat {
    Binary,
    Bcd,
    Raw,
}

#[derive(Debug, Subcommand)]
pub enum ProbeAction {
    /// Say hello: print the bridge's protocol version, capabilities and tick.
    Hello,
    /// Print the bridge's link counters.
    Counters,
    /// Read ADC channel 0-7 (prints the 10-bit code and its voltage).
    Adc {
        channel: u8,
        /// Read this many times, one line each.
        #[arg(long, default_value_t = 1)]
        count: u32,
    },
    /// Read the compass heading.
    Compass {
        #[arg(long, value_enum, default_value_t = CompassFormat::Binary)]
        format: CompassFormat,
    },
    /// Select a sonar transducer (1-4) and print what the multiplexer sends.
    Sonar {
        transducer: u8,
        /// Stop after this many sentences.
        #[arg(long, default_value_t = 3)]
        count: u32,
        /// Give up after this many seconds.
        #[arg(long, default_value_t = 10.0)]
        timeout_s: f64,
    },
    /// Set the thrusters in signed percent (-100..100), port starboard bow stern.
    Thrusters {
        #[arg(allow_negative_numbers = true)]
        port: i32,
        #[arg(allow_negative_numbers = true)]
        starboard: i32,
        #[arg(allow_negative_numbers = true)]
        bow: i32,
        #[arg(allow_negative_numbers = true)]
        stern: i32,
    },
    /// Lockstep: advance simulated time by N ticks and print the new time.
    Advance { ticks: u32 },
    /// Print the simulated time.
    Time,
}

/// Signed percent to the motor driver's inverted PWM duty and direction, linearly (the
/// vehicle's HDT table, applied by the bridge's physics, balances the motors).
pub fn percent_to_command(percent: i32) -> Result<ThrusterCommand, CliError> {
    if !(-100..=100).contains(&percent) {
        return Err(CliError::Usage(format!(
            "thrust {percent} % is outside -100..100"
        )));
    }
    let on = f64::from(percent.unsigned_abs()) / 100.0;
    Ok(ThrusterCommand {
        duty: (255.0 * (1.0 - on)).round() as u8,
        direction: if percent < 0 {
            Direction::Reverse
        } else {
            Direction::Forward
        },
    })
}

pub fn main(args: ProbeArgs) -> Result<(), CliError> {
    super::runtime()?.block_on(run(args))
}

async fn run(args: ProbeArgs) -> Result<(), CliError> {
    if let ProbeAction::Sonar {
        transducer,
        count,
        timeout_s,
    } = args.action
    {
        let line = args.line.unwrap_or(LineSettings::n81(4800));
        return sonar(&args.link, &line, transducer, count, timeout_s).await;
    }
    let line = args.line.unwrap_or(LineSettings::n81(115_200));
    let mut client = SensorClient::open(&args.link, &line)?;
    match args.action {
        ProbeAction::Hello => {
            let reply = client
                .request(
                    "HELLO",
                    Message::Hello { client_version: 1 },
                    Duration::ZERO,
                )
                .await?;
            let Message::HelloReply {
                protocol_version,
                capabilities,
                tick_us,
                max_payload,
            } = reply
            else {
                return Err(unexpected("HELLO", reply));
            };
            outln!(
                "protocol {protocol_version} capabilities {capabilities:#06x} tick {tick_us} us max payload {max_payload}"
            );
        }
        ProbeAction::Counters => {
            let reply = client
                .request("COUNTERS_GET", Message::CountersGet, Duration::ZERO)
                .await?;
            let Message::Counters(c) = reply else {
                return Err(unexpected("COUNTERS_GET", reply));
            };
            outln!(
                "rx_frames {} rx_crc_errors {} rx_framing_errors {} rx_skipped_bytes {} rx_rejected {} tx_frames {} tx_naks {}",
                c.rx_frames,
                c.rx_crc_errors,
                c.rx_framing_errors,
                c.rx_skipped_bytes,
                c.rx_rejected,
                c.tx_frames,
                c.tx_naks
            );
        }
        ProbeAction::Adc { channel, count } => {
            let channel = AdcChannel::new(channel).map_err(|e| CliError::Usage(e.to_string()))?;
            for _ in 0..count {
                let reply = client
                    .request("ADC_READ", Message::AdcRead { channel }, Duration::ZERO)
                    .await?;
                let Message::AdcValue { value, .. } = reply else {
                    return Err(unexpected("ADC_READ", reply));
                };
                outln!(
                    "adc {} = {} ({:.3} V)",
                    channel.get(),
                    value.get(),
                    f64::from(value.get()) * 5.0 / 1024.0
                );
            }
        }
        ProbeAction::Compass { format } => {
            let output = match format {
                CompassFormat::Binary => CompassOutput::Binary,
                CompassFormat::Bcd => CompassOutput::Bcd,
                CompassFormat::Raw => CompassOutput::Raw,
            };
            client
                .request(
                    "COMPASS_MODE",
                    Message::CompassMode {
                        mode: CompassMode::Poll,
                        output,
                    },
                    Duration::ZERO,
                )
                .await?;
            match client
                .request("COMPASS_READ", Message::CompassRead, Duration::ZERO)
                .await?
            {
                Message::CompassHeading { word } => {
                    let fmt = if matches!(format, CompassFormat::Bcd) {
                        HeadingFormat::Bcd
                    } else {
                        HeadingFormat::Binary
                    };
                    match word.decode(fmt) {
                        Ok(deg) => outln!("heading {deg} deg (word {:#06x})", word.0),
                        Err(e) => outln!("bad heading word: {e}"),
                    }
                }
                Message::CompassRaw { x, y } => outln!("raw x {x} y {y}"),
                other => return Err(unexpected("COMPASS_READ", other)),
            }
        }
        ProbeAction::Thrusters {
            port,
            starboard,
            bow,
            stern,
        } => {
            let commands = [
                percent_to_command(port)?,
                percent_to_command(starboard)?,
                percent_to_command(bow)?,
                percent_to_command(stern)?,
            ];
            client
                .request(
                    "THRUSTER_SET_ALL",
                    Message::ThrusterSetAll { commands },
                    Duration::ZERO,
                )
                .await?;
            outln!("thrusters set");
        }
        ProbeAction::Advance { ticks } => {
            // Allow the bridge time to simulate: generously 1 ms per tick.
            let extra = Duration::from_millis(u64::from(ticks));
            let reply = client
                .request("TIME_ADVANCE", Message::TimeAdvance { ticks }, extra)
                .await?;
            print_time("TIME_ADVANCE", reply)?;
        }
        ProbeAction::Time => {
            let reply = client
                .request("TIME_GET", Message::TimeGet, Duration::ZERO)
                .await?;
            print_time("TIME_GET", reply)?;
        }
        ProbeAction::Sonar { .. } => unreachable!("handled above"),
    }
    Ok(())
}

/// Prints a TIME reply to `request` as ticks and seconds.
fn print_time(request: &'static str, reply: Message) -> Result<(), CliError> {
    let Message::Time { ticks, tick_us } = reply else {
        return Err(unexpected(request, reply));
    };
    outln!(
        "time {ticks} ticks ({:.3} s)",
        f64::from(ticks) * f64::from(tick_us) * 1e-6
    );
    Ok(())
}

/// A reply of the wrong kind: a bridge this client does not understand.
fn unexpected(request: &'static str, reply: Message) -> CliError {
    CliError::UnexpectedReply {
        request,
        reply: format!("{reply:?}"),
    }
}

/// Selects `transducer` and prints what the multiplexer sends, up to `count` sentences.
async fn sonar(
    link: &std::path::Path,
    line: &LineSettings,
    transducer: u8,
    count: u32,
    timeout_s: f64,
) -> Result<(), CliError> {
    let mut sonar = SonarClient::open(link, line)?;
    let t = Transducer::new(transducer).map_err(|e| CliError::Usage(e.to_string()))?;
    sonar.select(t).await?;
    let deadline = tokio::time::Instant::now() + Duration::from_secs_f64(timeout_s.max(0.0));
    let mut sentences = 0;
    let mut acked = false;
    while sentences < count {
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        match sonar.next(left).await? {
            None if sentences == 0 => {
                return Err(CliError::Usage(format!(
                    "timed out after {timeout_s} s: {}: {}",
                    if acked {
                        "the ack came but no sentence"
                    } else {
                        "no ack"
                    },
                    why_no_echo(link, acked).await
                )));
            }
            None if acked => {
                return Err(CliError::Usage(format!(
                    "timed out after {timeout_s} s with {sentences} of {count} sentences: the \
                     multiplexer sends a sentence only for a ping with a valid echo (about one \
                     a second at best; fewer when the beam meets the wall obliquely, thesis \
                     4.4); wait longer with --timeout-s"
                )));
            }
            None => return Err(CliError::Usage(format!("timed out after {timeout_s} s"))),
            Some(SonarItem::Ack(t)) => {
                acked = true;
                outln!("ack transducer {t}");
            }
            Some(SonarItem::Nak) => outln!("nak"),
            Some(SonarItem::Sentence { raw, .. }) => {
                outln!("{raw}");
                sentences += 1;
            }
            Some(SonarItem::Error(e)) => outln!("error: {e}"),
        }
    }
    Ok(())
}

/// Why a selected transducer may send nothing, from the daemon's status (next to the link in
/// its run directory): lockstep time that nobody advances, no acknowledgement (not the sonar
/// link), or no wall within the sonar's range, with the distances to the default pool's walls.
async fn why_no_echo(link: &std::path::Path, acked: bool) -> String {
    let socket = link
        .parent()
        .unwrap_or(std::path::Path::new("."))
        .join("status.sock");
    let Ok(s) = crate::daemon::status::query(&socket, Duration::from_secs(2)).await else {
        return format!(
            "a sentence comes only when the transducer hears an echo (no daemon status at {} \
             to say more)",
            socket.display()
        );
    };
    if s.time_mode == "lockstep" {
        return "the daemon runs in lockstep: simulated time moves only when a client \
                advances it (e.g. `probe --link run/sensor advance 200` from another shell)"
            .to_string();
    }
    if !acked {
        return format!(
            "the multiplexer did not acknowledge the select: is {} the daemon's sonar link?",
            link.display()
        );
    }
    let p = &s.pose;
    let walls = crate::physics::load_world(&crate::config::Embedded, "worlds/pool.toml")
        .map(|w| {
            format!(
                "in the default {} x {} m pool the walls are {:.1} m west, {:.1} m east, {:.1} m \
                 south and {:.1} m north of its centre; ",
                w.pool_m.x,
                w.pool_m.y,
                p.y_m,
                w.pool_m.y - p.y_m,
                p.x_m,
                w.pool_m.x - p.x_m
            )
        })
        .unwrap_or_default();
    format!(
        "no echo within the sonar's range (4.4 m with configs/sensors/mako-2008.toml, thesis \
         table 4.7). The vehicle is at north {:.2} m, east {:.2} m, heading {:.0} deg; {walls}\
         start it near a wall with `run --start west_wall` or `--start wall_following` \
         (docs/eyebot.md, \"Course starts\")",
        p.x_m, p.y_m, p.heading_deg
    )
}
