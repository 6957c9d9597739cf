//! EyeBot-side clients of a running daemon's links.

use std::path::Path;
use std::time::Duration;

use eyebot_hil::probe::{RetryPolicy, SensorClient, SonarClient};
use firmware_protocol::sensor_link::Message;

/// Opens a pty or serial device with `line` (`"115200 8N1"`) as the EyeBot side does
/// (termios applied). Must be called inside a tokio runtime.
pub fn open_line(path: &Path, line: &str) -> tokio_serial::SerialStream {
    let settings: eyebot_hil::transport::LineSettings = line.parse().expect("line settings");
    eyebot_hil::transport::serial::open(path, &settings)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()))
}

/// A sensor-link client with one attempt and a long timeout: in lockstep a retry would
/// change the transcript, and a loaded machine may be slow.
pub fn sensor_client(path: &Path) -> SensorClient {
    let mut client = SensorClient::open(path, &"115200 8N1".parse().expect("line"))
        .unwrap_or_else(|e| panic!("open the sensor link {}: {e}", path.display()));
    client.set_policy(RetryPolicy {
        timeout: Duration::from_secs(10),
        retries: 0,
    });
    client
}

/// A sonar-link client at 4800 8N1.
pub fn sonar_client(path: &Path) -> SonarClient {
    SonarClient::open(path, &"4800 8N1".parse().expect("line"))
        .unwrap_or_else(|e| panic!("open the sonar link {}: {e}", path.display()))
}

/// Sends HELLO on the sensor link at `path` and checks the reply; `context` says what the
/// answer shows (in the panic message).
pub async fn expect_hello(path: &Path, context: &str) {
    let mut client = sensor_client(path);
    let reply = client
        .request(
            "hello",
            Message::Hello { client_version: 1 },
            Duration::ZERO,
        )
        .await
        .unwrap_or_else(|e| panic!("{context}: {e}"));
    assert!(
        matches!(reply, Message::HelloReply { .. }),
        "{context}: {reply:?}"
    );
}

/// Opens a link as a raw file (blocking), as a plain C program would.
pub fn open_raw(path: &Path) -> std::fs::File {
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(path)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()))
}

/// The EyeBot side of a lockstep run, driven from a synchronous test: a sensor-link client on
/// its own runtime, counting the ticks it advanced.
pub struct LockstepDriver {
    rt: tokio::runtime::Runtime,
    sensor: SensorClient,
    label: &'static str,
    /// Ticks of 10 ms advanced so far.
    pub ticks: u64,
}

impl LockstepDriver {
    /// Opens the daemon's sensor link and says HELLO; `label` names the test in errors.
    pub fn new(daemon: &crate::Daemon, label: &'static str) -> Self {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        let sensor = rt.block_on(async { sensor_client(&daemon.link("sensor")) });
        let mut d = Self {
            rt,
            sensor,
            label,
            ticks: 0,
        };
        d.ask(Message::Hello { client_version: 1 });
        d
    }

    /// One request and its reply.
    pub fn ask(&mut self, message: Message) -> Message {
        self.rt
            .block_on(self.sensor.request(self.label, message, Duration::ZERO))
            .expect("the bridge answers")
    }

    /// Advances simulated time by `ticks` of 10 ms.
    pub fn advance(&mut self, ticks: u32) {
        let reply = self.ask(Message::TimeAdvance { ticks });
        assert!(matches!(reply, Message::Time { .. }), "{reply:?}");
        self.ticks += u64::from(ticks);
    }

    /// Port and starboard thrusters on, the ADC streaming every channel, the sonar's
    /// transducer 1 selected: messages of every kind on both links. The sonar client is
    /// returned so that the link stays open.
    pub fn busy(&mut self, daemon: &crate::Daemon) -> SonarClient {
        use firmware_protocol::sensor_link::{Direction, ThrusterCommand};
        let on = ThrusterCommand {
            duty: 0x60,
            direction: Direction::Forward,
        };
        self.ask(Message::ThrusterSetAll {
            commands: [on, on, ThrusterCommand::OFF, ThrusterCommand::OFF],
        });
        self.ask(Message::AdcStream {
            channels: 0xFF,
            period_ms: 100,
        });
        let mut sonar = self
            .rt
            .block_on(async { sonar_client(&daemon.link("sonar")) });
        self.rt
            .block_on(sonar.select(firmware_protocol::Transducer::new(1).expect("transducer 1")))
            .expect("select");
        sonar
    }
}
