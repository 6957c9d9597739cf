//! An EyeBot-side client of the bridge, for people, scripts and tests (`eyebot-hil probe`),
//! in the spirit of gpsd's gpspipe and gpsmon.
//!
//! [`SensorClient`] speaks the sensor link as PROTOCOL.md section 2.2 tells an EyeBot to: one
//! request outstanding, a fresh sequence number per request, a 100 ms reply timeout and up to
//! three retries of the identical frame. Pushes that arrive while it waits are kept for
//! [`SensorClient::next_push`]. [`SonarClient`] selects transducers and reads sentences.

use std::collections::VecDeque;
use std::path::Path;
use std::time::Duration;

use bytes::BytesMut;
use firmware_protocol::sensor_link::{self, Message};
use firmware_protocol::sonar_link::SonarCommand;
use firmware_protocol::{Frame, LineDecoder, LineItem, Sentence, Transducer};
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

/// A sensor-link client over a serial device or pty.
pub struct SensorClient {
    port: SerialStream,
    path: String,
    seq: u8,
    decoder: LineDecoder,
    buf: BytesMut,
    pushes: VecDeque<Frame>,
    policy: RetryPolicy,
    /// Wire errors seen in what the bridge sent (should stay 0).
    pub errors: u64,
}

impl SensorClient {
    /// Opens the sensor link at `path` and flushes stale input.
    pub fn open(path: &Path, line: &LineSettings) -> Result<Self, ProbeError> {
        let port = serial::open(path, line)?;
        let _ = tokio_serial::SerialPort::clear(&port, tokio_serial::ClearBuffer::Input);
        Ok(Self {
            port,
            path: path.display().to_string(),
            // A fresh process must not repeat its predecessor's last (seq, request): the bridge
            // answers an identical request from its stored reply (PROTOCOL.md 2.2). Starting
            // from the process id makes back-to-back `probe` runs differ.
            seq: std::process::id() as u8,
            decoder: LineDecoder::new(),
            buf: BytesMut::new(),
            pushes: VecDeque::new(),
            policy: RetryPolicy::default(),
            errors: 0,
        })
    }

    pub fn set_policy(&mut self, policy: RetryPolicy) {
        self.policy = policy;
    }

    async fn read_frame(
        &mut self,
        deadline: tokio::time::Instant,
    ) -> Result<Option<Frame>, ProbeError> {
        loop {
            while let Some(item) = self.decoder.decode(&mut self.buf) {
                match item {
                    LineItem::Frame(frame) => return Ok(Some(frame)),
                    LineItem::Error(e) => {
                        self.errors += 1;
                        tracing::warn!(path = %self.path, error = %e, "bad bytes from the bridge");
                    }
                    // NMEA or sonar commands on a shared line are not ours.
                    LineItem::Nmea(_) | LineItem::Sonar(_) => {}
                }
            }
            if !read_more(&mut self.port, &mut self.buf, deadline, &self.path).await? {
                return Ok(None);
            }
        }
    }

    /// Sends `message` and waits for its reply (same seq), retrying the identical frame.
    /// `extra` lengthens the timeout (a long TIME_ADVANCE takes the bridge a while).
    pub async fn request(
        &mut self,
        what: &'static str,
        message: Message,
        extra: Duration,
    ) -> Result<Message, ProbeError> {
        self.seq = self.seq.wrapping_add(1);
        let seq = self.seq;
        let mut wire = BytesMut::new();
        Frame::new(seq, message).encode(&mut wire);
        let timeout = self.policy.timeout + extra;
        for _attempt in 0..=self.policy.retries {
            self.port
                .write_all(&wire)
                .await
                .map_err(|source| ProbeError::Io {
                    path: self.path.clone(),
                    source,
                })?;
            let deadline = tokio::time::Instant::now() + timeout;
            while let Some(frame) = self.read_frame(deadline).await? {
                if frame.message.msg_type() >= 0xC0 {
                    self.pushes.push_back(frame);
                    continue;
                }
                if frame.seq != seq {
                    continue; // a late reply to an earlier, retried request
                }
                return match frame.message {
                    Message::Nak { code, detail, .. } => Err(ProbeError::Refused {
                        path: self.path.clone(),
                        what,
                        code,
                        detail,
                    }),
                    reply => Ok(reply),
                };
            }
        }
        Err(ProbeError::NoReply {
            path: self.path.clone(),
            what,
            attempts: self.policy.retries + 1,
            timeout,
        })
    }

    /// The next push (ADC samples, compass), waiting up to `timeout`.
    pub async fn next_push(&mut self, timeout: Duration) -> Result<Option<Frame>, ProbeError> {
        if let Some(frame) = self.pushes.pop_front() {
            return Ok(Some(frame));
        }
        let deadline = tokio::time::Instant::now() + timeout;
        while let Some(frame) = self.read_frame(deadline).await? {
            if frame.message.msg_type() >= 0xC0 {
                return Ok(Some(frame));
            }
        }
        Ok(None)
    }
}

/// A sonar-link client: selects transducers and reads what the multiplexer forwards.
pub struct SonarClient {
    port: SerialStream,
    path: String,
    decoder: LineDecoder,
    buf: BytesMut,
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
        let port = serial::open(path, line)?;
        let _ = tokio_serial::SerialPort::clear(&port, tokio_serial::ClearBuffer::Input);
        Ok(Self {
            port,
            path: path.display().to_string(),
            decoder: LineDecoder::new(),
            buf: BytesMut::new(),
        })
    }

    pub async fn select(&mut self, transducer: Transducer) -> Result<(), ProbeError> {
        let mut wire = BytesMut::new();
        SonarCommand::Select(transducer).encode(&mut wire);
        self.port
            .write_all(&wire)
            .await
            .map_err(|source| ProbeError::Io {
                path: self.path.clone(),
                source,
            })
    }

    /// The next item within `timeout`, with the raw text of sentences.
    pub async fn next(&mut self, timeout: Duration) -> Result<Option<SonarItem>, ProbeError> {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            let before = self.buf.clone();
            if let Some(item) = self.decoder.decode(&mut self.buf) {
                let used = before.len() - self.buf.len();
                let raw = String::from_utf8_lossy(&before[..used])
                    .trim_end()
                    .to_string();
                return Ok(Some(match item {
                    LineItem::Sonar(SonarCommand::Ack(t)) => SonarItem::Ack(t.get()),
                    LineItem::Sonar(_) => SonarItem::Nak,
                    LineItem::Nmea(sentence) => SonarItem::Sentence { sentence, raw },
                    LineItem::Error(e) => SonarItem::Error(e.to_string()),
                    LineItem::Frame(_) => continue,
                }));
            }
            if !read_more(&mut self.port, &mut self.buf, deadline, &self.path).await? {
                return Ok(None);
            }
        }
    }
}

/// Reads what the port has into `buf` before `deadline`: `Ok(false)` when the deadline
/// passed first. Shared by both clients.
async fn read_more(
    port: &mut SerialStream,
    buf: &mut BytesMut,
    deadline: tokio::time::Instant,
    path: &str,
) -> Result<bool, ProbeError> {
    let mut chunk = [0u8; 512];
    match tokio::time::timeout_at(deadline, port.read(&mut chunk)).await {
        Err(_) => Ok(false),
        Ok(Ok(0)) => Err(ProbeError::Closed {
            path: path.to_string(),
        }),
        Ok(Ok(n)) => {
            buf.extend_from_slice(&chunk[..n]);
            Ok(true)
        }
        Ok(Err(source)) => Err(ProbeError::Io {
            path: path.to_string(),
            source,
        }),
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
