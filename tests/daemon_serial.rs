//! The real-serial code path, through a `socat` pty pair standing in for a USB serial adapter:
//! the daemon opens one end as `endpoint = "serial"` (termios applied), the client uses the
//! other; then socat is killed and restarted (the adapter vanishes and comes back) and the
//! daemon reopens the device with back-off.

use std::os::fd::AsRawFd;
use std::path::PathBuf;
use std::time::Duration;

use eyebot_test_support::clients::expect_hello;
use eyebot_test_support::config::config_text;
use eyebot_test_support::daemon::link_status;
use eyebot_test_support::process::socat_pair;
use eyebot_test_support::{Daemon, RunningDaemon};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

#[tokio::test]
async fn a_socat_linked_pair_exercises_the_serial_path_and_survives_the_device_vanishing() {
    let options = Daemon::options(BIN, "socat").realtime();
    let a: PathBuf = options.dir().join("ttyA");
    let b: PathBuf = options.dir().join("ttyB");
    let socat = socat_pair(&a, &b);
    let text = config_text(&[("path = \"sensor\"", &format!("path = \"{}\"", a.display()))]);
    // The sensor link's endpoint is the second `endpoint = "pty"`.
    let at = text.match_indices("endpoint = \"pty\"").nth(1).unwrap().0;
    let text = format!(
        "{}endpoint = \"serial\"{}",
        &text[..at],
        &text[at + "endpoint = \"pty\"".len()..]
    );
    let config = options.dir().write("serial.toml", text);
    let daemon = options
        .args(&["--config", config.to_str().expect("a UTF-8 path")])
        .start();
    assert!(
        daemon
            .links
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
    let _socat = socat_pair(&a, &b);
    let s = daemon.wait_status(Duration::from_secs(15), "a reconnect", |s| {
        link_status(s, "sensor").reconnects > 0
    });
    assert!(link_status(&s, "sensor").reconnects >= 1);
    expect_hello(&b, "HELLO across the socat pair").await;
}
