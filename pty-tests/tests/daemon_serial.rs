//! The real-serial code path, through a `socat` pty pair standing in for a USB serial adapter:
//! the daemon opens one end as `endpoint = "serial"` (termios applied), the client uses the
//! other; then socat is killed and restarted (the adapter vanishes and comes back) and the
//! daemon reopens the device with back-off.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use pty_tests::daemon::{
    DaemonProcess, TestDir, expect_hello, link_status, poll_until, require_tool,
};
use std::os::fd::AsRawFd;

/// `socat pty,raw,echo=0,link=A pty,raw,echo=0,link=B`, killed in `Drop`.
struct Socat {
    child: Child,
}

impl Socat {
    fn start(a: &Path, b: &Path) -> Self {
        let socat = require_tool("socat", "the real-serial test (Debian package `socat`)");
        let child = Command::new(socat)
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start socat");
        poll_until(Duration::from_secs(10), "socat's pty links", || {
            (a.exists() && b.exists()).then_some(())
        });
        Self { child }
    }

    fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Socat {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[tokio::test]
async fn a_socat_linked_pair_exercises_the_serial_path_and_survives_the_device_vanishing() {
    let dir = TestDir::new("socat");
    let a: PathBuf = dir.join("ttyA");
    let b: PathBuf = dir.join("ttyB");
    let socat = Socat::start(&a, &b);
    let config = dir.write_config(
        "serial.toml",
        &[("path = \"sensor\"", &format!("path = \"{}\"", a.display()))],
    );
    let text = std::fs::read_to_string(&config).unwrap();
    // The sensor link's endpoint is the second `endpoint = "pty"`.
    let at = text.match_indices("endpoint = \"pty\"").nth(1).unwrap().0;
    let text = format!(
        "{}endpoint = \"serial\"{}",
        &text[..at],
        &text[at + "endpoint = \"pty\"".len()..]
    );
    std::fs::write(&config, text).unwrap();
    let daemon = DaemonProcess::start(
        dir,
        &[
            "--config",
            config.to_str().unwrap(),
            "--time-mode",
            "realtime",
        ],
    );
    assert!(
        daemon
            .links
            .lines
            .iter()
            .any(|(name, path)| name == "sensor" && path.contains("115200")),
        "{:?}",
        daemon.links
    );

    // termios reached the device: socat made it 38400 baud; the daemon set 115200 8N1.
    // serialport sets the speed through termios2 (BOTHER), so read it back the same way.
    let device = std::fs::File::open(&a).unwrap();
    // SAFETY: TCGETS2 fills a termios2 struct for a tty descriptor we hold open.
    let mut t2: libc::termios2 = unsafe { std::mem::zeroed() };
    let r = unsafe { libc::ioctl(device.as_raw_fd(), libc::TCGETS2 as _, &mut t2) };
    assert_eq!(r, 0, "TCGETS2 on {}", a.display());
    assert_eq!((t2.c_ospeed, t2.c_ispeed), (115_200, 115_200), "baud");
    assert_eq!(t2.c_cflag & libc::CSIZE, libc::CS8, "8 data bits");
    assert_eq!(t2.c_cflag & libc::CSTOPB, 0, "1 stop bit");
    assert_eq!(t2.c_cflag & libc::PARENB, 0, "no parity");
    drop(device);

    expect_hello(&b, "HELLO across the socat pair").await;
    assert_eq!(link_status(&daemon.status(), "sensor").reconnects, 0);

    // The adapter vanishes...
    socat.kill();
    daemon.wait_status(Duration::from_secs(10), "the lost device noticed", |s| {
        link_status(s, "sensor").errors > 0 || !a.exists()
    });
    // ...and comes back under the same name (socat killed with SIGKILL leaves its links).
    let _ = std::fs::remove_file(&a);
    let _ = std::fs::remove_file(&b);
    // Same names, new devices.
    let _socat = Socat::start(&a, &b);
    let s = daemon.wait_status(Duration::from_secs(15), "a reconnect", |s| {
        link_status(s, "sensor").reconnects > 0
    });
    assert!(link_status(&s, "sensor").reconnects >= 1);
    expect_hello(&b, "HELLO across the socat pair").await;
}
