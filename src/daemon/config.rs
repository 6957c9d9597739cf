//! The daemon's own settings (`configs/default.toml`): run, links and devices.
//!
//! Model files (vehicle, world, sensors) are referenced by name and loaded by their layers.
//! Raw structs mirror the TOML with `deny_unknown_fields`; [`DaemonConfig::resolve`] checks
//! them and points at the offending key's line.

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;

use firmware_protocol::Talker;

use super::clock::TimeMode;
use crate::config::{ConfigError, Document};
use crate::devices::multiplexer::{DepthSentence, InvalidEcho, MultiplexerSettings};
use crate::transport::{FlowControl, LineSettings};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDaemon {
    vehicle: String,
    world: String,
    sensors: String,
    run: RawRun,
    start: RawStart,
    links: RawLinks,
    devices: RawDevices,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRun {
    seed: u64,
    time_mode: String,
    speed: f64,
    max_lag_ms: f64,
    run_dir: String,
    state_record_hz: f64,
    #[serde(default = "default_release_quantum_ms")]
    release_quantum_ms: f64,
    #[serde(default)]
    cpu_latency_us: Option<i64>,
    #[serde(default)]
    rt_priority: Option<i64>,
}

fn default_release_quantum_ms() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStart {
    position_m: [f64; 3],
    heading_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLinks {
    sonar: RawLink,
    sensor: RawLink,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLink {
    endpoint: String,
    #[serde(default)]
    path: Option<String>,
    #[serde(default)]
    line: Option<String>,
    #[serde(default)]
    flow_control: FlowControl,
    #[serde(default = "default_tx_queue")]
    tx_queue_bytes: usize,
}

fn default_tx_queue() -> usize {
    4096
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevices {
    multiplexer: RawMultiplexer,
    compass: RawCompassDevice,
    motor_driver: RawMotorDriver,
    lockstep: RawLockstep,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMultiplexer {
    sentence: String,
    talker: String,
    dpt_offset_m: f64,
    invalid_echo: String,
    proprietary: bool,
    #[serde(default)]
    replay: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCompassDevice {
    continuous_period_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotorDriver {
    watchdog_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLockstep {
    tick_s: f64,
}

/// Where a link's bytes go.
#[derive(Debug, Clone, PartialEq)]
pub enum Endpoint {
    /// A pty pair created in-process; the symlink at `link` (relative paths inside the run
    /// directory) points at the slave.
    Pty { link: PathBuf },
    /// A real serial device.
    Serial { device: PathBuf },
    /// A TCP listener on loopback, one client at a time.
    Tcp { addr: std::net::SocketAddr },
    /// This link rides on the sonar link's line; a receiver tells the two apart by the first
    /// byte (see PROTOCOL.md).
    SharedWithSonar,
}

/// One link's resolved settings.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    pub endpoint: Endpoint,
    pub line: LineSettings,
    pub tx_queue_bytes: usize,
}

/// Where the vehicle starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Start {
    /// Centre of mass, NED (m).
    pub position_m: nalgebra::Vector3<f64>,
    /// Compass heading (deg, clockwise from north).
    pub heading_deg: f64,
}

/// The daemon's resolved settings.
#[derive(Debug, Clone, PartialEq)]
pub struct DaemonConfig {
    /// Model files, by name inside the same config source.
    pub vehicle: String,
    pub world: String,
    pub sensors: String,
    pub seed: u64,
    pub time_mode: TimeMode,
    pub max_lag: Duration,
    /// Longest a byte that completed its wire time waits for its hand-over to the port
    /// (`transport::pacer`): bytes leave in bursts of at most this long.
    pub release_quantum: Duration,
    /// In realtime mode, hold a CPU latency QoS request of this many µs
    /// ([`crate::transport::CpuLatencyRequest`]); `None` = do not ask.
    pub cpu_latency_us: Option<u32>,
    /// In realtime mode, run the bridge's thread under `SCHED_FIFO` at this priority (1-99,
    /// [`crate::transport::set_realtime_priority`]); `None` = the default scheduler.
    pub rt_priority: Option<i32>,
    pub run_dir: PathBuf,
    pub state_record_hz: f64,
    pub start: Start,
    /// The line of `start.position_m` (`None`: the key's default), for an error found once
    /// the world is loaded.
    pub start_line: Option<usize>,
    /// The configuration's name in errors: its path, or `<embedded>/default.toml`.
    pub origin: String,
    pub sonar: LinkConfig,
    pub sensor: LinkConfig,
    /// Zero the thrusters after this long without a thruster frame; `None` = off.
    pub watchdog: Option<Duration>,
    /// Length of one lockstep tick (MK4 `OSGetCount` tick: 1/100 s).
    pub tick: Duration,
    /// The PICAXE master's sentence settings.
    pub multiplexer: MultiplexerSettings,
    /// Period of the compass's continuous mode.
    pub compass_period: Duration,
    /// A captured NMEA log forwarded in place of the simulated sonar (`devices.multiplexer
    /// .replay`); relative paths are relative to the configuration file's directory.
    pub sonar_replay: Option<PathBuf>,
}

/// The realtime speed factors allowed, in `run.speed` and `--speed`.
pub const SPEED_RANGE: std::ops::RangeInclusive<f64> = 0.1..=1000.0;

/// A time mode by name, as `run.time_mode` and `--time-mode` give it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TimeModeName {
    /// Follow the wall clock (times --speed): for a real EyeBot.
    Realtime,
    /// Advance only on the client's time frames: deterministic, as fast as the client.
    Lockstep,
}

/// Values given in place of the configuration's `[run]` keys (`eyebot-hil run`'s options),
/// applied and checked by [`DaemonConfig::resolve_with`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overrides {
    pub seed: Option<u64>,
    pub time_mode: Option<TimeModeName>,
    pub speed: Option<f64>,
    pub run_dir: Option<PathBuf>,
}

impl DaemonConfig {
    /// Parses and checks a daemon config document.
    pub fn resolve(doc: &Document<'_>) -> Result<Self, ConfigError> {
        Self::resolve_with(doc, &Overrides::default(), None)
    }

    /// Parses and checks a daemon config document, then applies and checks `overrides`.
    /// `base_dir` is the configuration file's directory: a relative file path inside the
    /// configuration (the sonar replay log) is taken relative to it. `None` (an embedded
    /// configuration) leaves such paths relative to the working directory.
    pub fn resolve_with(
        doc: &Document<'_>,
        overrides: &Overrides,
        base_dir: Option<&std::path::Path>,
    ) -> Result<Self, ConfigError> {
        let raw: RawDaemon = doc.parse()?;
        let speed = resolve_speed(doc, &raw.run, overrides)?;
        let time_mode = resolve_time_mode(doc, &raw.run, overrides, speed)?;
        let max_lag_ms =
            doc.check_range("run.max_lag_ms", raw.run.max_lag_ms, 1.0, 10_000.0, "ms")?;
        let release_quantum_ms = doc.check_range(
            "run.release_quantum_ms",
            raw.run.release_quantum_ms,
            0.0,
            10.0,
            "ms",
        )?;
        let cpu_latency_us = resolve_cpu_latency_us(doc, raw.run.cpu_latency_us)?;
        let rt_priority = resolve_rt_priority(doc, raw.run.rt_priority)?;
        // (key, value, min, max, unit); the first out of range is reported.
        let [state_record_hz, watchdog_s, tick_s] = [
            (
                "run.state_record_hz",
                raw.run.state_record_hz,
                0.1,
                1000.0,
                "Hz",
            ),
            (
                "devices.motor_driver.watchdog_s",
                raw.devices.motor_driver.watchdog_s,
                0.0,
                3600.0,
                "s",
            ),
            (
                "devices.lockstep.tick_s",
                raw.devices.lockstep.tick_s,
                1e-4,
                1.0,
                "s",
            ),
        ]
        .map(|(key, value, min, max, unit)| doc.check_range(key, value, min, max, unit));
        let (state_record_hz, watchdog_s, tick_s) = (state_record_hz?, watchdog_s?, tick_s?);
        if raw.run.run_dir.is_empty() {
            return Err(doc.invalid("run.run_dir", "must not be empty"));
        }
        let m = &raw.devices.multiplexer;
        let multiplexer = resolve_multiplexer(doc, m)?;
        let compass_period_s = doc.check_range(
            "devices.compass.continuous_period_s",
            raw.devices.compass.continuous_period_s,
            0.01,
            10.0,
            "s",
        )?;
        let start = resolve_start(doc, &raw.start)?;
        let sonar = resolve_link(doc, "sonar", raw.links.sonar, false)?;
        let sensor = resolve_link(doc, "sensor", raw.links.sensor, true)?;
        check_links_distinct(doc, &sonar, &sensor)?;
        Ok(Self {
            vehicle: raw.vehicle,
            world: raw.world,
            sensors: raw.sensors,
            seed: overrides.seed.unwrap_or(raw.run.seed),
            time_mode,
            max_lag: Duration::from_secs_f64(max_lag_ms / 1000.0),
            release_quantum: Duration::from_secs_f64(release_quantum_ms / 1000.0),
            cpu_latency_us,
            rt_priority,
            run_dir: overrides
                .run_dir
                .clone()
                .unwrap_or_else(|| PathBuf::from(raw.run.run_dir)),
            state_record_hz,
            start,
            start_line: doc.line_of("start.position_m"),
            origin: doc.origin().to_string(),
            sonar,
            sensor,
            watchdog: (watchdog_s > 0.0).then(|| Duration::from_secs_f64(watchdog_s)),
            tick: Duration::from_secs_f64(tick_s),
            multiplexer,
            compass_period: Duration::from_secs_f64(compass_period_s),
            sonar_replay: m
                .replay
                .as_ref()
                .filter(|p| !p.is_empty())
                .map(|p| match base_dir {
                    Some(dir) => dir.join(p),
                    None => PathBuf::from(p),
                }),
        })
    }
}

/// The realtime speed factor: `run.speed`, checked, unless `--speed` overrides it (checked
/// against the same range, after the file's value).
fn resolve_speed(
    doc: &Document<'_>,
    run: &RawRun,
    overrides: &Overrides,
) -> Result<f64, ConfigError> {
    let file_speed = doc.check_range(
        "run.speed",
        run.speed,
        *SPEED_RANGE.start(),
        *SPEED_RANGE.end(),
        "x real time",
    )?;
    match overrides.speed {
        Some(speed) if !(speed.is_finite() && SPEED_RANGE.contains(&speed)) => {
            Err(ConfigError::Override {
                option: "--speed".into(),
                key: "run.speed".into(),
                message: format!(
                    "{speed:?} is outside the allowed range {}..={} x real time",
                    SPEED_RANGE.start(),
                    SPEED_RANGE.end()
                ),
            })
        }
        Some(speed) => Ok(speed),
        None => Ok(file_speed),
    }
}

/// The time mode: `run.time_mode` (which must name one even when `--time-mode` overrides
/// it), realtime at `speed`.
fn resolve_time_mode(
    doc: &Document<'_>,
    run: &RawRun,
    overrides: &Overrides,
    speed: f64,
) -> Result<TimeMode, ConfigError> {
    let file_mode = match run.time_mode.as_str() {
        "realtime" => TimeModeName::Realtime,
        "lockstep" => TimeModeName::Lockstep,
        other => {
            return Err(doc.invalid(
                "run.time_mode",
                format!("`{other}` is not a time mode; expected `realtime` or `lockstep`"),
            ));
        }
    };
    Ok(match overrides.time_mode.unwrap_or(file_mode) {
        TimeModeName::Realtime => TimeMode::Realtime { speed },
        TimeModeName::Lockstep => TimeMode::Lockstep,
    })
}

/// Checks the optional `run.cpu_latency_us`: 0 to 1000000 µs.
fn resolve_cpu_latency_us(
    doc: &Document<'_>,
    raw: Option<i64>,
) -> Result<Option<u32>, ConfigError> {
    Ok(match raw {
        None => None,
        Some(us) => Some(
            u32::try_from(us)
                .ok()
                .filter(|us| *us <= 1_000_000)
                .ok_or_else(|| {
                    doc.invalid(
                        "run.cpu_latency_us",
                        format!("{us} is out of range; expected 0 to 1000000 µs"),
                    )
                })?,
        ),
    })
}

/// Checks the optional `run.rt_priority`: a `SCHED_FIFO` priority, 1 to 99.
fn resolve_rt_priority(doc: &Document<'_>, raw: Option<i64>) -> Result<Option<i32>, ConfigError> {
    Ok(match raw {
        None => None,
        Some(p) => Some(
            i32::try_from(p)
                .ok()
                .filter(|p| (1..=99).contains(p))
                .ok_or_else(|| {
                    doc.invalid(
                        "run.rt_priority",
                        format!("{p} is out of range; expected a SCHED_FIFO priority 1 to 99"),
                    )
                })?,
        ),
    })
}

/// Resolves the PICAXE master's sentence settings (`devices.multiplexer`): the depth
/// sentence (with its offset for DPT), the talker and the invalid-echo policy.
fn resolve_multiplexer(
    doc: &Document<'_>,
    m: &RawMultiplexer,
) -> Result<MultiplexerSettings, ConfigError> {
    let sentence = match m.sentence.as_str() {
        "DBT" => DepthSentence::Dbt,
        "DPT" => DepthSentence::Dpt {
            offset_m: doc.check_range(
                "devices.multiplexer.dpt_offset_m",
                m.dpt_offset_m,
                -99.0,
                99.0,
                "m",
            )?,
        },
        other => {
            return Err(doc.invalid(
                "devices.multiplexer.sentence",
                format!("`{other}` is not a depth sentence; expected `DBT` or `DPT`"),
            ));
        }
    };
    let talker = Talker::new(&m.talker)
        .map_err(|e| doc.invalid("devices.multiplexer.talker", e.to_string()))?;
    let invalid_echo = match m.invalid_echo.as_str() {
        "omit" => InvalidEcho::Omit,
        "empty" => InvalidEcho::EmptyFields,
        other => {
            return Err(doc.invalid(
                "devices.multiplexer.invalid_echo",
                format!("`{other}` is not a policy; expected `omit` or `empty`"),
            ));
        }
    };
    Ok(MultiplexerSettings {
        sentence,
        talker,
        invalid_echo,
        proprietary: m.proprietary,
    })
}

/// Checks the `[start]` table: each axis of the position, then the heading. Whether the
/// position lies inside the pool is checked once the world is loaded.
fn resolve_start(doc: &Document<'_>, raw: &RawStart) -> Result<Start, ConfigError> {
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        doc.check_range(
            "start.position_m",
            raw.position_m[i],
            -1000.0,
            1000.0,
            &format!("m ({axis})"),
        )?;
    }
    let heading_deg =
        doc.check_range("start.heading_deg", raw.heading_deg, -360.0, 360.0, "deg")?;
    Ok(Start {
        position_m: nalgebra::Vector3::from(raw.position_m),
        heading_deg,
    })
}

/// Refuses two links on one path: the second would replace the first's symlink or device,
/// leaving that link unreachable. (`shared` is the one way for them to share a line.)
fn check_links_distinct(
    doc: &Document<'_>,
    sonar: &LinkConfig,
    sensor: &LinkConfig,
) -> Result<(), ConfigError> {
    let same = match (&sonar.endpoint, &sensor.endpoint) {
        (Endpoint::Pty { link: a }, Endpoint::Pty { link: b }) => a == b,
        (Endpoint::Serial { device: a }, Endpoint::Serial { device: b }) => a == b,
        (Endpoint::Tcp { addr: a }, Endpoint::Tcp { addr: b }) => a == b,
        _ => false,
    };
    if same {
        return Err(doc.invalid(
            "links.sensor.path",
            "is the same as `links.sonar.path`; two links cannot share a path (use `endpoint = \"shared\"` for one line carrying both)",
        ));
    }
    Ok(())
}

/// Whether `link`, joined to a directory, names a path inside it: a relative path of plain
/// names (`.` allowed), without `..` or a root.
pub fn stays_inside(link: &std::path::Path) -> bool {
    use std::path::Component;
    link.components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
        && link.components().any(|c| matches!(c, Component::Normal(_)))
}

fn resolve_link(
    doc: &Document<'_>,
    name: &str,
    raw: RawLink,
    may_share: bool,
) -> Result<LinkConfig, ConfigError> {
    let key = |k: &str| format!("links.{name}.{k}");
    let path = |what: &str| {
        raw.path.clone().filter(|p| !p.is_empty()).ok_or_else(|| {
            doc.invalid(
                &key("path"),
                format!("a `{}` endpoint needs `path` ({what})", raw.endpoint),
            )
        })
    };
    let endpoint = match raw.endpoint.as_str() {
        "pty" => {
            let link = PathBuf::from(path("the symlink to create, relative to run.run_dir")?);
            if !stays_inside(&link) {
                return Err(doc.invalid(
                    &key("path"),
                    format!(
                        "`{}` leaves the run directory; a pty link is a name inside `run.run_dir` (no `..`, not absolute), where the daemon checks who owns the directory",
                        link.display()
                    ),
                ));
            }
            Endpoint::Pty { link }
        }
        "serial" => Endpoint::Serial {
            device: PathBuf::from(path("the device, e.g. /dev/ttyUSB0")?),
        },
        "tcp" => {
            let text = path("a loopback address, e.g. 127.0.0.1:7001")?;
            let addr: std::net::SocketAddr = text.parse().map_err(|_| {
                doc.invalid(
                    &key("path"),
                    format!("`{text}` is not an address like 127.0.0.1:7001"),
                )
            })?;
            if !addr.ip().is_loopback() {
                return Err(doc.invalid(
                    &key("path"),
                    format!(
                        "{addr} is not a loopback address; the bridge only listens on loopback"
                    ),
                ));
            }
            Endpoint::Tcp { addr }
        }
        "shared" if may_share => Endpoint::SharedWithSonar,
        other => {
            let allowed = if may_share {
                "`pty`, `serial`, `tcp` or `shared`"
            } else {
                "`pty`, `serial` or `tcp`"
            };
            return Err(doc.invalid(
                &key("endpoint"),
                format!("`{other}` is not an endpoint; expected {allowed}"),
            ));
        }
    };
    let line = match (&endpoint, raw.line) {
        (Endpoint::SharedWithSonar, Some(_)) => {
            return Err(doc.invalid(
                &key("line"),
                "a shared link uses the sonar link's line settings; remove `line`",
            ));
        }
        (Endpoint::SharedWithSonar, None) => LineSettings::n81(4800),
        (_, Some(text)) => {
            let mut line: LineSettings =
                text.parse()
                    .map_err(|e: crate::transport::line::LineSettingsError| {
                        doc.invalid(&key("line"), e.to_string())
                    })?;
            line.flow_control = raw.flow_control;
            line
        }
        (_, None) => {
            return Err(doc.invalid(
                &key("line"),
                "missing: give the line settings, e.g. \"4800 8N1\"",
            ));
        }
    };
    if !(64..=1 << 20).contains(&raw.tx_queue_bytes) {
        return Err(doc.invalid(
            &key("tx_queue_bytes"),
            format!("{} is outside 64..=1048576 bytes", raw.tx_queue_bytes),
        ));
    }
    Ok(LinkConfig {
        endpoint,
        line,
        tx_queue_bytes: raw.tx_queue_bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ConfigSource, DEFAULT_CONFIG, Embedded};

    #[test]
    fn the_embedded_default_resolves() {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap();
        let doc = Document::new(Embedded.describe(DEFAULT_CONFIG), &text);
        let config = DaemonConfig::resolve(&doc).unwrap();
        assert_eq!(config.sonar.line, LineSettings::n81(4800));
        assert_eq!(config.sensor.line, LineSettings::n81(115_200));
        assert_eq!(config.tick, Duration::from_millis(10));
    }

    fn with(replacements: &[(&str, &str)]) -> Result<DaemonConfig, ConfigError> {
        let mut text = Embedded.read(DEFAULT_CONFIG).unwrap().into_owned();
        for (replace, by) in replacements {
            assert!(text.contains(replace), "default.toml lost `{replace}`");
            text = text.replacen(replace, by, 1);
        }
        DaemonConfig::resolve(&Document::new("test.toml", &text))
    }

    #[test]
    fn bad_values_are_named_with_their_line() {
        let err = with(&[("time_mode = \"realtime\"", "time_mode = \"fast\"")]).unwrap_err();
        assert!(
            matches!(&err, ConfigError::Invalid { key, line: Some(_), .. } if key == "run.time_mode"),
            "{err}"
        );
        let err = with(&[("speed = 1.0", "speed = 0.01")]).unwrap_err();
        assert!(err.to_string().contains("run.speed"), "{err}");
        let err = with(&[("line = \"4800 8N1\"", "line = \"4800 8Q1\"")]).unwrap_err();
        assert!(err.to_string().contains("links.sonar.line"), "{err}");
    }

    #[test]
    fn scheduler_requests_are_range_checked() {
        let at = |value: &str| {
            with(&[(
                "release_quantum_ms = 1.0",
                &format!("release_quantum_ms = 1.0\nrt_priority = {value}\ncpu_latency_us = 0"),
            )])
        };
        let ok = at("10").unwrap();
        assert_eq!((ok.rt_priority, ok.cpu_latency_us), (Some(10), Some(0)));
        assert_eq!(with(&[]).unwrap().rt_priority, None, "off unless set");
        for bad in ["0", "100", "-1"] {
            let err = at(bad).unwrap_err();
            assert!(
                err.to_string().contains("run.rt_priority") && err.to_string().contains("1 to 99"),
                "{err}"
            );
        }
    }

    fn with_overrides(
        overrides: &Overrides,
        base: Option<&str>,
    ) -> Result<DaemonConfig, ConfigError> {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap().into_owned();
        let text = text.replacen(
            "[devices.multiplexer]",
            "[devices.multiplexer]\nreplay = \"logs/a.nmea\"",
            1,
        );
        DaemonConfig::resolve_with(
            &Document::new("test.toml", &text),
            overrides,
            base.map(std::path::Path::new),
        )
    }

    /// Command-line values replace the file's, are checked against the same range, and a
    /// relative log path in the file is taken relative to the file.
    #[test]
    fn overrides_are_applied_and_checked_in_one_place() {
        let plain = with_overrides(&Overrides::default(), Some("/etc/hil")).unwrap();
        assert_eq!(
            plain.sonar_replay,
            Some(PathBuf::from("/etc/hil/logs/a.nmea"))
        );
        let embedded = with_overrides(&Overrides::default(), None).unwrap();
        assert_eq!(embedded.sonar_replay, Some(PathBuf::from("logs/a.nmea")));
        let given = Overrides {
            seed: Some(99),
            time_mode: Some(TimeModeName::Realtime),
            speed: Some(10.0),
            run_dir: Some(PathBuf::from("/tmp/x")),
        };
        let config = with_overrides(&given, None).unwrap();
        assert_eq!(config.seed, 99);
        assert_eq!(config.time_mode, TimeMode::Realtime { speed: 10.0 });
        assert_eq!(config.run_dir, PathBuf::from("/tmp/x"));
        let lockstep = Overrides {
            time_mode: Some(TimeModeName::Lockstep),
            ..Overrides::default()
        };
        assert_eq!(
            with_overrides(&lockstep, None).unwrap().time_mode,
            TimeMode::Lockstep
        );
        for bad in [0.05, 1000.5, f64::NAN, 1e-300] {
            let over = Overrides {
                speed: Some(bad),
                ..Overrides::default()
            };
            let err = with_overrides(&over, None).unwrap_err().to_string();
            assert!(
                err.starts_with("--speed") && err.contains("0.1..=1000"),
                "{err}"
            );
            assert!(err.len() < 160, "a value written in full: {err}");
        }
    }

    #[test]
    fn tcp_endpoints_must_be_loopback() {
        let tcp = |addr: &'static str| {
            [
                ("endpoint = \"pty\"", "endpoint = \"tcp\""),
                ("path = \"sonar\"", addr),
            ]
        };
        let err = with(&tcp("path = \"10.0.0.1:7001\"")).unwrap_err();
        assert!(err.to_string().contains("loopback"), "{err}");
        let ok = with(&tcp("path = \"127.0.0.1:7001\"")).unwrap();
        assert!(matches!(ok.sonar.endpoint, Endpoint::Tcp { .. }));
    }

    /// A pty path that leaves the run directory is refused, naming the key, its line and the
    /// rule (`../../../escaped-sonar` was accepted).
    #[test]
    fn a_pty_path_outside_the_run_directory_is_refused() {
        for bad in [
            "../../../escaped-sonar",
            "/tmp/sonar",
            "a/../../sonar",
            ".",
            "..",
        ] {
            let by = format!("path = \"{bad}\"");
            let err = with(&[("path = \"sonar\"", by.as_str())]).unwrap_err();
            assert!(
                matches!(&err, ConfigError::Invalid { key, line: Some(_), .. } if key == "links.sonar.path"),
                "{bad}: {err}"
            );
            assert!(
                err.to_string().contains("leaves the run directory"),
                "{bad}: {err}"
            );
        }
        for good in ["sonar", "./sonar", "links/sonar"] {
            let by = format!("path = \"{good}\"");
            let config = with(&[("path = \"sonar\"", by.as_str())]).unwrap();
            assert!(
                matches!(config.sonar.endpoint, Endpoint::Pty { .. }),
                "{good}"
            );
        }
    }

    /// Two links on one path would leave one unreachable (the second symlink replaces the
    /// first); the error names the key and its line.
    #[test]
    fn two_links_cannot_share_a_path() {
        let err = with(&[("path = \"sensor\"", "path = \"sonar\"")]).unwrap_err();
        assert!(
            matches!(&err, ConfigError::Invalid { key, line: Some(_), .. } if key == "links.sensor.path"),
            "{err}"
        );
        assert!(err.to_string().contains("links.sonar.path"), "{err}");
        let tcp = with(&[
            ("endpoint = \"pty\"", "endpoint = \"tcp\""),
            ("path = \"sonar\"", "path = \"127.0.0.1:7001\""),
            ("endpoint = \"pty\"", "endpoint = \"tcp\""),
            ("path = \"sensor\"", "path = \"127.0.0.1:7001\""),
        ]);
        assert!(tcp.is_err(), "one loopback port for both links");
    }
}
