//! An EyeBot-side client of the bridge, for people, scripts and tests (`eyebot-hil probe`),
//! in the spirit of gpsd's gpspipe and gpsmon.
//!
//! Both clients are I/O shells (tokio-serial, deadlines) over the protocol crate's sans-IO
//! [`EyeBotClient`], which keeps the sequence counter, decodes, tells replies from pushes and
//! counts wire errors. [`SensorClient`] speaks the sensor link as PROTOCOL.md section 2.2 tells
//! an EyeBot to: one request outstanding, a fresh sequence number per request, a 100 ms reply
//! timeout and up to three retries of the identical frame. Pushes that arrive while it waits
//! are kept for [`SensorClient::next_push`]. [`SonarClient`] selects transducers and reads
//! sentences.

use std::path::Path;
use std::time::Duration;

use bytes::BytesMut;
use firmware_protocol::sensor_link::{self, Message};
use firmware_protocol::sonar_link::SonarCommand;
use firmware_protocol::{EyeBotClient, Frame, Incoming, LinkError, Sentence, Transducer};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::SerialStream;

use crate::transport::{LineSettings, serial};

/// Why a probe request failed.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    #[error(transparent)]
    Open(#[from] serial::SerialError),
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: no reply to {what} after {attempts} attempts of {timeout:?}")]
    NoReply {
        path: String,
        what: &'static str,
        attempts: u32,
        timeout: Duration,
    },
    #[error("{path}: the bridge refused {what}: {code:?} (detail {detail}){}", refusal_hint(what, *code))]
    Refused {
        path: String,
        what: &'static str,
        code: sensor_link::ErrorCode,
        detail: u8,
    },
    #[error("{path}: the link closed")]
    Closed { path: String },
}

/// What a refusal means for the user, where the code alone does not say it: a time request
/// in real time is answered BAD_STATE (PROTOCOL.md 2.8, 2.9).
fn refusal_hint(what: &str, code: sensor_link::ErrorCode) -> &'static str {
    match (what, code) {
        ("TIME_ADVANCE" | "TIME_STEP", sensor_link::ErrorCode::BadState) => {
            ": the daemon runs in real time; start it with `--time-mode lockstep`"
        }
        _ => "",
    }
}

/// Reply timeout and retries (PROTOCOL.md 2.2).
#[derive(Debug, Clone, Copy)]
pub struct RetryPolicy {
    pub timeout: Duration,
    pub retries: u32,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(100),
            retries: 3,
        }
    }
}

/// A sensor-link client over a serial device or pty: an I/O shell over
/// [`EyeBotClient`], which keeps the seq, decodes and queues pushes.
pub struct SensorClient {
    port: Port,
    policy: RetryPolicy,
}

impl SensorClient {
    /// Opens the sensor link at `path` and flushes stale input.
    pub fn open(path: &Path, line: &LineSettings) -> Result<Self, ProbeError> {
        // A fresh process must not repeat its predecessor's last (seq, request): the bridge
        // answers an identical request from its stored reply (PROTOCOL.md 2.2). Starting
        // after the process id makes back-to-back `probe` runs differ.
        let first_seq = (std::process::id() as u8).wrapping_add(1);
        Ok(Self {
            port: Port::open(path, line, EyeBotClient::with_first_seq(first_seq))?,
            policy: RetryPolicy::default(),
        })
    }

    pub fn set_policy(&mut self, policy: RetryPolicy) {
        self.policy = policy;
    }

    /// Wire errors seen in what the bridge sent (should stay 0).
    pub fn errors(&self) -> u64 {
        self.port.client.errors()
    }

    /// Sends `message` and waits for its reply (same seq), retrying the identical frame.
    /// `extra` lengthens the timeout (a long TIME_ADVANCE takes the bridge a while).
    pub async fn request(
        &mut self,
        what: &'static str,
        message: Message,
        extra: Duration,
    ) -> Result<Message, ProbeError> {
        let mut wire = BytesMut::new();
        let seq = self.port.client.encode_request(message, &mut wire);
        let timeout = self.policy.timeout + extra;
        for _attempt in 0..=self.policy.retries {
            self.port.write(&wire).await?;
            let deadline = tokio::time::Instant::now() + timeout;
            loop {
                match self.port.client.take_reply(seq) {
                    Some(Ok(Message::Nak { code, detail, .. })) => {
                        return Err(ProbeError::Refused {
                            path: self.port.path.clone(),
                            what,
                            code,
                            detail,
                        });
                    }
                    Some(Ok(reply)) => return Ok(reply),
                    Some(Err(error)) => self.port.warn(&error),
                    None => {
                        if !self.port.read_more(deadline).await? {
                            break;
                        }
                    }
                }
            }
        }
        Err(ProbeError::NoReply {
            path: self.port.path.clone(),
            what,
            attempts: self.policy.retries + 1,
            timeout,
        })
    }

    /// The next push (ADC samples, compass), waiting up to `timeout`.
    pub async fn next_push(&mut self, timeout: Duration) -> Result<Option<Frame>, ProbeError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            match self.port.client.take_push() {
                Some(Ok(frame)) => return Ok(Some(frame)),
                Some(Err(error)) => self.port.warn(&error),
                None => {
                    if !self.port.read_more(deadline).await? {
                        return Ok(None);
                    }
                }
            }
        }
    }
}

/// A sonar-link client: selects transducers and reads what the multiplexer forwards.
pub struct SonarClient {
    port: Port,
}

/// What the multiplexer sent.
#[derive(Debug, Clone, PartialEq)]
pub enum SonarItem {
    Ack(u8),
    Nak,
    Sentence { sentence: Sentence, raw: String },
    Error(String),
}

impl SonarClient {
    pub fn open(path: &Path, line: &LineSettings) -> Result<Self, ProbeError> {
        Ok(Self {
            port: Port::open(path, line, EyeBotClient::new())?,
        })
    }

    pub async fn select(&mut self, transducer: Transducer) -> Result<(), ProbeError> {
        let mut wire = BytesMut::new();
        SonarCommand::Select(transducer).encode(&mut wire);
        self.port.write(&wire).await
    }

    /// The next item within `timeout`, with the raw text of sentences.
    pub async fn next(&mut self, timeout: Duration) -> Result<Option<SonarItem>, ProbeError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            if let Some((item, bytes)) = self.port.client.next_incoming_with_bytes() {
                return Ok(Some(match item {
                    Incoming::Sonar(SonarCommand::Ack(t)) => SonarItem::Ack(t.get()),
                    Incoming::Sonar(_) => SonarItem::Nak,
                    Incoming::Nmea(sentence) => SonarItem::Sentence {
                        sentence,
                        raw: String::from_utf8_lossy(&bytes).trim_end().to_string(),
                    },
                    Incoming::Error(e) => SonarItem::Error(e.to_string()),
                    Incoming::Reply(_) | Incoming::Push(_) => continue,
                }));
            }
            if !self.port.read_more(deadline).await? {
                return Ok(None);
            }
        }
    }
}

/// The I/O both clients share: the open port, its path for errors, and the sans-IO client
/// that what it reads is handed to.
struct Port {
    port: SerialStream,
    path: String,
    client: EyeBotClient,
}

impl Port {
    /// Opens `path` and flushes stale input.
    fn open(path: &Path, line: &LineSettings, client: EyeBotClient) -> Result<Self, ProbeError> {
        let port = serial::open(path, line)?;
        let _ = tokio_serial::SerialPort::clear(&port, tokio_serial::ClearBuffer::Input);
        Ok(Self {
            port,
            path: path.display().to_string(),
            client,
        })
    }

    async fn write(&mut self, bytes: &[u8]) -> Result<(), ProbeError> {
        self.port
            .write_all(bytes)
            .await
            .map_err(|source| ProbeError::Io {
                path: self.path.clone(),
                source,
            })
    }

    /// Hands what the port has to the client before `deadline`: `Ok(false)` when the
    /// deadline passed first.
    async fn read_more(&mut self, deadline: tokio::time::Instant) -> Result<bool, ProbeError> {
        let mut chunk = [0u8; 512];
        match tokio::time::timeout_at(deadline, self.port.read(&mut chunk)).await {
            Err(_) => Ok(false),
            Ok(Ok(0)) => Err(ProbeError::Closed {
                path: self.path.clone(),
            }),
            Ok(Ok(n)) => {
                self.client.receive(&chunk[..n]);
                Ok(true)
            }
            Ok(Err(source)) => Err(ProbeError::Io {
                path: self.path.clone(),
                source,
            }),
        }
    }

    fn warn(&self, error: &LinkError) {
        tracing::warn!(path = %self.path, error = %error, "bad bytes from the bridge");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A time request refused with BAD_STATE says what to do: the daemon runs in real time
    /// (`probe advance` said only `BadState (detail 0)`). Other refusals keep the code alone.
    #[test]
    fn a_time_request_refused_in_real_time_says_to_start_in_lockstep() {
        let refused = |what, code| {
            ProbeError::Refused {
                path: "run/sensor".into(),
                what,
                code,
                detail: 0,
            }
            .to_string()
        };
        for what in ["TIME_ADVANCE", "TIME_STEP"] {
            let text = refused(what, sensor_link::ErrorCode::BadState);
            assert!(
                text.ends_with(
                    "the daemon runs in real time; start it with `--time-mode lockstep`"
                ),
                "{text}"
            );
        }
        let other = refused("ADC_READ", sensor_link::ErrorCode::BadState);
        assert!(other.ends_with("BadState (detail 0)"), "{other}");
    }
}
