//! A real browser for the view's tests: Debian's `chromium`, headless, driven over the
//! DevTools protocol (a WebSocket, JSON commands), and a plain HTTP/1.1 client for requests a
//! browser would not send (no token, a foreign `Host`).
//!
//! The browser gets a fresh profile and its own temporary directory inside the test's
//! [`TempDir`], so it leaves nothing behind; it is killed and reaped in `Drop`.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine as _;
use serde_json::{Value, json};
use tungstenite::stream::MaybeTlsStream;

use crate::tools::require_tool;
use crate::wait::wait_for;

/// How long the browser may take to start and load a page on a loaded machine.
pub const BROWSER_TIMEOUT: Duration = Duration::from_secs(30);

/// Headless chromium with a DevTools connection to its one page.
pub struct Browser {
    child: Child,
    ws: tungstenite::WebSocket<MaybeTlsStream<TcpStream>>,
    next_id: u64,
    profile: PathBuf,
}

impl Browser {
    /// Starts chromium on `url` with its profile in `dir/NAME` (removed with the test's
    /// directory) and connects to the page.
    pub fn open(dir: &Path, name: &str, url: &str) -> Self {
        let chromium = require_tool("chromium", "chromium");
        let profile = dir.join(name);
        std::fs::create_dir_all(profile.join("tmp")).expect("browser profile directory");
        let log = std::fs::File::create(profile.join("chromium.log")).expect("chromium.log");
        let child = Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--disable-dev-shm-usage",
                "--window-size=1400,1250",
                "--remote-debugging-address=127.0.0.1",
                "--remote-debugging-port=0",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg(url)
            .env("TMPDIR", profile.join("tmp"))
            .env("HOME", &profile)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| panic!("spawn chromium: {e}"));
        // Chromium writes the port it chose into the profile.
        let port_file = profile.join("DevToolsActivePort");
        let port: u16 = wait_for("chromium's DevToolsActivePort", BROWSER_TIMEOUT, || {
            std::fs::read_to_string(&port_file)
                .ok()
                .and_then(|t| t.lines().next().and_then(|l| l.trim().parse().ok()))
        });
        let devtools = SocketAddr::from(([127, 0, 0, 1], port));
        let page = wait_for("chromium's page target", BROWSER_TIMEOUT, || {
            let (status, body) = http(devtools, "GET", "/json/list", &[], "").ok()?;
            if status != 200 {
                return None;
            }
            let targets: Value = serde_json::from_str(&body).ok()?;
            targets.as_array()?.iter().find_map(|t| {
                (t["type"] == "page")
                    .then(|| t["webSocketDebuggerUrl"].as_str().map(str::to_string))
                    .flatten()
            })
        });
        let (ws, _) = tungstenite::connect(page.as_str())
            .unwrap_or_else(|e| panic!("connect to chromium's page at {page}: {e}"));
        if let MaybeTlsStream::Plain(stream) = ws.get_ref() {
            stream
                .set_read_timeout(Some(BROWSER_TIMEOUT))
                .expect("read timeout");
        }
        Self {
            child,
            ws,
            next_id: 1,
            profile,
        }
    }

    /// Sends a DevTools command and returns its `result`.
    pub fn command(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        let message = json!({"id": id, "method": method, "params": params});
        self.ws
            .send(tungstenite::Message::text(message.to_string()))
            .unwrap_or_else(|e| panic!("DevTools {method}: {e}"));
        loop {
            let reply = self
                .ws
                .read()
                .unwrap_or_else(|e| panic!("DevTools {method}: no answer: {e}"));
            let tungstenite::Message::Text(text) = reply else {
                continue;
            };
            let value: Value = serde_json::from_str(text.as_str()).expect("DevTools sends JSON");
            if value["id"] == id {
                if let Some(error) = value.get("error") {
                    panic!("DevTools {method}: {error}");
                }
                return value["result"].clone();
            }
        }
    }

    /// Evaluates a JavaScript expression in the page (awaiting a promise) and returns its
    /// value; a thrown exception is a panic naming the expression.
    pub fn eval(&mut self, expression: &str) -> Value {
        let result = self.command(
            "Runtime.evaluate",
            json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
        );
        if let Some(e) = result.get("exceptionDetails") {
            panic!("page threw evaluating `{expression}`: {e}");
        }
        result["result"]["value"].clone()
    }

    /// Evaluates `expression` until `pred` accepts its value, or panics after `timeout`
    /// naming `what` and the last value.
    pub fn wait_eval(
        &mut self,
        what: &str,
        timeout: Duration,
        expression: &str,
        pred: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + timeout;
        loop {
            let value = self.eval(expression);
            if pred(&value) {
                return value;
            }
            assert!(
                Instant::now() < deadline,
                "the page did not show {what} within {timeout:?}: `{expression}` is {value}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// A PNG of the page as it is drawn now.
    pub fn screenshot(&mut self) -> Vec<u8> {
        let result = self.command("Page.captureScreenshot", json!({"format": "png"}));
        let data = result["data"].as_str().expect("screenshot data");
        base64::engine::general_purpose::STANDARD
            .decode(data)
            .expect("screenshot is base64")
    }

    /// Chromium's own log (stderr), for a failure message.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.profile.join("chromium.log")).unwrap_or_default()
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One HTTP/1.1 request to `addr` with `headers` (a `Host` of `addr` unless given) and
/// `body`; returns the status code and the body. The connection is closed after it.
pub fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> std::io::Result<(u16, String)> {
    let mut stream = TcpStream::connect_timeout(&addr, Duration::from_secs(5))?;
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut request = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        request.push_str(&format!("Host: {addr}\r\n"));
    }
    for (k, v) in headers {
        request.push_str(&format!("{k}: {v}\r\n"));
    }
    request.push_str(&format!("Content-Length: {}\r\n\r\n{body}", body.len()));
    stream.write_all(request.as_bytes())?;
    // Read the head, then `Content-Length` bytes (a server may keep the connection open).
    let mut response = Vec::new();
    let mut buf = [0u8; 8192];
    let head_end = loop {
        if let Some(at) = response.windows(4).position(|w| w == b"\r\n\r\n") {
            break at + 4;
        }
        let n = stream.read(&mut buf)?;
        if n == 0 {
            return Err(std::io::Error::other(
                "the connection closed before a response",
            ));
        }
        response.extend_from_slice(&buf[..n]);
    };
    let head = String::from_utf8_lossy(&response[..head_end]).into_owned();
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| std::io::Error::other(format!("not an HTTP response: {head:?}")))?;
    let length = head.lines().find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.eq_ignore_ascii_case("content-length")
            .then(|| v.trim().parse::<usize>().ok())
            .flatten()
    });
    match length {
        Some(length) => {
            while response.len() < head_end + length {
                let n = stream.read(&mut buf)?;
                if n == 0 {
                    break;
                }
                response.extend_from_slice(&buf[..n]);
            }
        }
        None => {
            stream.read_to_end(&mut response)?;
        }
    }
    let body = String::from_utf8_lossy(&response[head_end..]).into_owned();
    Ok((status, body))
}

/// The address and token of a view URL (`http://ADDR/?token=TOKEN`).
pub fn split_view_url(url: &str) -> (SocketAddr, String) {
    let rest = url.strip_prefix("http://").expect("an http:// URL");
    let (addr, query) = rest.split_once("/?token=").expect("a URL with ?token=");
    (addr.parse().expect("an ADDR:PORT"), query.to_string())
}

/// A request for the event stream on a socket with a 4 KiB receive buffer that is never
/// read.
pub fn stalled_stream(addr: SocketAddr, token: &str) -> std::net::TcpStream {
    use std::io::Write;
    use std::os::fd::AsFd;
    let socket = nix::sys::socket::socket(
        nix::sys::socket::AddressFamily::Inet,
        nix::sys::socket::SockType::Stream,
        nix::sys::socket::SockFlag::empty(),
        None,
    )
    .expect("socket");
    nix::sys::socket::setsockopt(&socket.as_fd(), nix::sys::socket::sockopt::RcvBuf, &4096)
        .expect("SO_RCVBUF");
    let SocketAddr::V4(v4) = addr else {
        panic!("a loopback IPv4 view address: {addr}")
    };
    nix::sys::socket::connect(
        std::os::fd::AsRawFd::as_raw_fd(&socket),
        &nix::sys::socket::SockaddrIn::from(v4),
    )
    .expect("connect");
    let mut stream = std::net::TcpStream::from(socket);
    write!(
        stream,
        "GET /api/stream?token={token} HTTP/1.1\r\nHost: {addr}\r\n\r\n"
    )
    .expect("send the request");
    stream
}
