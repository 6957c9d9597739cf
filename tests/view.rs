//! The live view in a real browser (Debian's `chromium`, headless, over the DevTools
//! protocol) and over plain HTTP: the page follows the daemon, its controls reach the
//! simulation and the recording, the page over a recording shows what was recorded, foreign
//! requests are refused, and a client that never reads does not slow the bridge.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use eyebot_hil::daemon::status::StatusSnapshot;
use eyebot_test_support::browser::{Browser, http, split_view_url, stalled_stream};
use eyebot_test_support::clients::LockstepDriver;
use eyebot_test_support::{Daemon, RunningDaemon};
use firmware_protocol::sensor_link::Message;
use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const WAIT: Duration = Duration::from_secs(20);

/// The page's current pose and time: `[t_s, x_m, y_m, depth_m, heading_deg]`.
const PAGE_POSE: &str = "(() => { const f = window.eyebotView && eyebotView.frame; \
     return f ? [f.sample.t_s, f.sample.x_m, f.sample.y_m, f.sample.depth_m, f.sample.heading_deg] : null; })()";

fn pose_of(v: &Value) -> Option<[f64; 5]> {
    let a = v.as_array()?;
    let mut out = [0.0; 5];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x.as_f64()?;
    }
    Some(out)
}

fn status_pose(s: &StatusSnapshot) -> [f64; 5] {
    [
        s.sim_time_s,
        s.pose.x_m,
        s.pose.y_m,
        s.pose.depth_m,
        s.pose.heading_deg,
    ]
}

fn close(a: &[f64; 5], b: &[f64; 5]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
}

/// How many distinct colours the pool canvas holds (a blank canvas has one).
const POOL_COLOURS: &str = "(() => { const c = document.getElementById('pool'); \
     const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; const s = new Set(); \
     for (let i = 0; i < d.length; i += 16) s.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]); return s.size; })()";

/// Where test artefacts go: cargo's scratch directory for integration tests.
fn artefact(name: &str) -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("view");
    std::fs::create_dir_all(&dir).expect("artefact directory");
    dir.join(name)
}

/// A lockstep daemon with `--view`: the page follows `status` frame for frame; setting the
/// pose through the page moves the vehicle and the recording holds the event (a refused one
/// changes nothing and is not recorded); the run still converts and replays; a screenshot is
/// written and is not blank; then the page over the recording shows the recorded pose at
/// the slider's time.
#[test]
fn the_page_follows_the_bridge_steers_it_and_shows_the_recording() {
    let mut daemon = Daemon::options(BIN, "view-live")
        .lockstep()
        .record()
        .args(&["--view"])
        .start();
    let url = daemon
        .view_url
        .clone()
        .expect("run --view prints `view: URL`");
    let mut drive = LockstepDriver::new(&daemon, "view test");
    let sonar = drive.busy(&daemon);
    drive.advance(300);

    let mut browser = Browser::open(daemon.dir.path(), "chromium", &url);
    for step in 0..4 {
        let status = daemon.wait_status(WAIT, "time to reach the advance", |s| {
            (s.sim_time_s - drive.ticks as f64 * 0.01).abs() < 1e-6
        });
        let want = status_pose(&status);
        let shown = browser.wait_eval(
            &format!("the pose of status at {} s (step {step})", want[0]),
            WAIT,
            PAGE_POSE,
            |v| pose_of(v).is_some_and(|p| close(&p, &want)),
        );
        assert!(pose_of(&shown).is_some());
        drive.advance(25);
        drive.ask(Message::CompassRead);
    }

    // A pose outside the pool is refused with the reason, and nothing moves.
    let before = daemon.wait_status(WAIT, "time to reach the advance", |s| {
        (s.sim_time_s - drive.ticks as f64 * 0.01).abs() < 1e-6
    });
    let refused = browser
        .eval("eyebotControl({action: 'pose', x_m: 99, y_m: 5, depth_m: 1, heading_deg: 45})");
    assert_eq!(refused, 400);
    let answer = browser.eval("document.getElementById('answer').textContent");
    assert!(
        answer
            .as_str()
            .is_some_and(|a| a.contains("outside the pool")),
        "{answer}"
    );
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(daemon.status().pose, before.pose);

    let set = browser
        .eval("eyebotControl({action: 'pose', x_m: 10, y_m: 2, depth_m: 1, heading_deg: 345})");
    assert_eq!(set, 200);
    let moved = daemon.wait_status(WAIT, "the vehicle at the page's pose", |s| {
        (s.pose.x_m - 10.0).abs() < 1e-9
    });
    assert!((moved.pose.y_m - 2.0).abs() < 1e-9, "{:?}", moved.pose);
    assert!((moved.pose.depth_m - 1.0).abs() < 1e-9, "{:?}", moved.pose);
    assert!(
        (moved.pose.heading_deg - 345.0).abs() < 1e-6,
        "{:?}",
        moved.pose
    );
    let event_time = moved.sim_time_s;
    for _ in 0..24 {
        drive.advance(25);
        drive.ask(Message::CompassRead);
    }
    let status = daemon.wait_status(WAIT, "the last advance", |s| {
        (s.sim_time_s - drive.ticks as f64 * 0.01).abs() < 1e-6
    });
    let want = status_pose(&status);
    browser.wait_eval("the pose after the move", WAIT, PAGE_POSE, |v| {
        pose_of(v).is_some_and(|p| close(&p, &want))
    });
    // Let the plots and messages fill one more frame, then take the picture.
    browser.wait_eval(
        "decoded link messages",
        WAIT,
        "eyebotView.messages.length",
        |v| v.as_u64().is_some_and(|n| n > 5),
    );
    let colours = browser.eval(POOL_COLOURS).as_u64().unwrap_or(0);
    assert!(colours > 20, "the pool canvas is blank: {colours} colours");
    let png = browser.screenshot();
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    assert!(
        png.len() > 20_000,
        "a {} byte screenshot is blank",
        png.len()
    );
    let shot = artefact("live.png");
    std::fs::write(&shot, &png).expect("write the screenshot");
    eprintln!("screenshot: {}", shot.display());
    drop(browser);
    drop(sonar);
    drop(drive);
    daemon.stop();

    let record = daemon.record_dir().to_path_buf();
    let events = eyebot_hil::record::read_events(&record).expect("events.tsv reads");
    assert_eq!(events.len(), 1, "only the accepted control: {events:?}");
    assert_eq!(events[0].event, "pose");
    assert_eq!(events[0].detail, "x_m=10 y_m=2 depth_m=1 heading_deg=345");
    assert!((events[0].sim_s - event_time).abs() < 1e-6, "{events:?}");

    // The run with a change still converts and replays.
    let out = daemon.dir.join("measured");
    daemon.cli(&[
        "gap".as_ref(),
        "convert".as_ref(),
        record.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
    ]);
    assert!(out.join("experiment.toml").is_file());
    let replayed = daemon.cli(&[
        "replay".as_ref(),
        record.as_os_str(),
        "--pacing".as_ref(),
        "fast".as_ref(),
        "--stdout".as_ref(),
    ]);
    let recorded_dbt: usize = eyebot_hil::record::read_bytes(&record)
        .expect("bytes.tsv")
        .iter()
        .filter(|c| c.link == "sonar" && c.dir == eyebot_hil::record::Direction::Tx)
        .map(|c| String::from_utf8_lossy(&c.data).matches("DBT,").count())
        .sum();
    assert!(recorded_dbt > 0, "the sonar answered near the wall");
    assert_eq!(replayed.matches("DBT,").count(), recorded_dbt, "{replayed}");

    // The page over the recording, at a time after the move.
    let viewer = ViewProcess::start(&record);
    let mut browser = Browser::open(daemon.dir.path(), "chromium-rec", &viewer.url);
    browser.wait_eval(
        "the recording loaded",
        WAIT,
        "!!(window.eyebotView && eyebotView.frame)",
        |v| v == &Value::Bool(true),
    );
    let states = eyebot_hil::record::read_state(&record).expect("state.csv");
    for t in [event_time + 0.5, 1.0, event_time + 1.234] {
        let row = states
            .iter()
            .rev()
            .find(|r| r.t_s <= t)
            .expect("a row before t");
        let shown = browser.eval(&format!("eyebotView.seek({t}).then(() => {PAGE_POSE})"));
        let p = pose_of(&shown).expect("a pose");
        let want = [
            row.t_s,
            row.x_m,
            row.y_m,
            row.z_m,
            row.yaw_rad.to_degrees().rem_euclid(360.0),
        ];
        assert!(
            close(&p, &want),
            "at {t} s the page shows {p:?}, state.csv {want:?}"
        );
        let slider = browser.eval("Number(document.getElementById('slider').value)");
        assert!(
            (slider.as_f64().unwrap_or(f64::NAN) - t).abs() < 0.03,
            "{slider}"
        );
    }
    let events_text = browser.eval("document.getElementById('events').textContent");
    assert!(
        events_text.as_str().is_some_and(|t| t.contains("pose")),
        "{events_text}"
    );
    std::fs::write(artefact("recording.png"), browser.screenshot()).expect("screenshot");
}

/// `eyebot-hil view RECORD_DIR` as a child process, killed in `Drop`.
struct ViewProcess {
    child: std::process::Child,
    url: String,
}

impl ViewProcess {
    fn start(record: &std::path::Path) -> Self {
        use std::io::BufRead;
        let mut child = std::process::Command::new(BIN)
            .arg("view")
            .arg(record)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::inherit())
            .spawn()
            .expect("spawn eyebot-hil view");
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        std::io::BufReader::new(stdout)
            .read_line(&mut line)
            .expect("read the view line");
        let url = line
            .trim()
            .strip_prefix("view: ")
            .unwrap_or_else(|| panic!("expected `view: URL`, got {line:?}"))
            .to_string();
        Self { child, url }
    }
}

impl Drop for ViewProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Requests without the token, with a wrong one, with a foreign `Host` (DNS rebinding) or a
/// foreign `Origin` (a cross-site page) are refused with 403; controls are POST only; a
/// malformed or out-of-range control gets 400 with the reason and changes nothing; a lockstep
/// run refuses to pause.
#[test]
fn foreign_requests_are_refused_and_bad_controls_get_400() {
    let mut daemon = Daemon::options(BIN, "view-guard")
        .lockstep()
        .args(&["--view"])
        .start();
    let url = daemon.view_url.clone().expect("view URL");
    let (addr, token) = split_view_url(&url);
    assert!(addr.ip().is_loopback(), "{addr}");
    let get = |path: &str, headers: &[(&str, &str)]| {
        http(addr, "GET", path, headers, "").expect("an HTTP answer")
    };
    let with_token = |path: &str| format!("{path}?token={token}");
    assert_eq!(get(&with_token("/"), &[]).0, 200);
    assert!(get(&with_token("/"), &[]).1.contains("<canvas id=\"pool\""));
    for (what, path, headers) in [
        ("no token", "/".to_string(), vec![]),
        ("no token, API", "/api/info".to_string(), vec![]),
        ("a wrong token", format!("/?token={}x", &token[1..]), vec![]),
        (
            "a foreign Host",
            with_token("/"),
            vec![("Host", "attacker.example:80")],
        ),
        (
            "a foreign Host naming the port",
            with_token("/api/info"),
            vec![("Host", &*format!("evil.example:{}", addr.port()))],
        ),
        (
            "a foreign Origin",
            with_token("/api/info"),
            vec![("Origin", "http://attacker.example")],
        ),
    ] {
        let headers: Vec<(&str, &str)> = headers.iter().map(|(k, v)| (*k, &**v)).collect();
        let (status, body) = get(&path, &headers);
        assert_eq!(status, 403, "{what}: {status} {body}");
    }
    let post = |body: &str, headers: &[(&str, &str)]| {
        http(addr, "POST", &with_token("/api/control"), headers, body).expect("an HTTP answer")
    };
    let (status, body) = post(
        r#"{"action":"pose","x_m":1,"y_m":1,"depth_m":1,"heading_deg":0}"#,
        &[("Origin", "http://attacker.example")],
    );
    assert_eq!(status, 403, "a cross-site POST: {body}");
    assert_eq!(
        get(&with_token("/api/control"), &[]).0,
        405,
        "controls are POST only"
    );
    let before = daemon.status();
    for (body, reason) in [
        ("not json", "expected a control as JSON"),
        (r#"{"action":"teleport"}"#, "expected a control as JSON"),
        (
            r#"{"action":"pose","x_m":-1,"y_m":1,"depth_m":1,"heading_deg":0}"#,
            "outside the pool",
        ),
        (
            r#"{"action":"pose","x_m":1,"y_m":1,"depth_m":9,"heading_deg":0}"#,
            "outside the pool",
        ),
        (
            r#"{"action":"current","north_mps":50,"east_mps":0}"#,
            "north_mps 50",
        ),
        (r#"{"action":"speed","factor":2}"#, "lockstep"),
        (r#"{"action":"pause"}"#, "lockstep"),
    ] {
        let (status, text) = post(body, &[]);
        assert_eq!(status, 400, "{body}: {text}");
        assert!(text.contains(reason), "{body}: {text}");
    }
    let (status, text) = post(r#"{"action":"current","north_mps":0.1,"east_mps":0}"#, &[]);
    assert_eq!(status, 200, "{text}");
    std::thread::sleep(Duration::from_millis(300));
    let after = daemon.status();
    assert_eq!(
        status_pose(&after)[1..],
        status_pose(&before)[1..],
        "lockstep: nothing moved"
    );
    daemon.stop();
}

/// Clients that connect and never read (one never even sends a request, twenty ask for the
/// event stream with a 4 KiB receive window and stop reading) leave the daemon's timing and
/// memory as they were. The same daemon is measured for 2 s before and 2 s after they
/// connect: simulated time keeps its pace at speed 5 (a bridge that waited for a client would
/// stop), a page that does read keeps getting frames, and resident memory does not grow.
/// (The machine is shared, so the pace is compared with the pace before, not with the wall
/// clock; the overruns of both periods are printed.)
#[test]
fn stalled_clients_never_slow_the_bridge() {
    let mut daemon = Daemon::options(BIN, "view-stall")
        .realtime()
        .args(&["--speed", "5", "--view"])
        .start();
    let url = daemon.view_url.clone().expect("view URL");
    let (addr, token) = split_view_url(&url);
    let period = Duration::from_secs(2);
    let measure = |daemon: &Daemon| {
        let (first, start) = (daemon.status(), Instant::now());
        std::thread::sleep(period);
        let last = daemon.status();
        (
            (last.sim_time_s - first.sim_time_s) / start.elapsed().as_secs_f64(),
            last.overruns - first.overruns,
        )
    };
    let (pace_before, overruns_before) = measure(&daemon);
    let silent = std::net::TcpStream::connect(addr).expect("connect");
    let stalled: Vec<_> = (0..20).map(|_| stalled_stream(addr, &token)).collect();
    std::thread::sleep(Duration::from_millis(500));
    let rss_early = daemon.rss_kb();
    let (pace_after, overruns_after) = measure(&daemon);
    let frames = count_frames(addr, &token, period);
    let rss_late = daemon.rss_kb();
    eprintln!(
        "stalled clients: pace {pace_before:.2} -> {pace_after:.2} simulated s per s (speed 5), \
         overruns {overruns_before} -> {overruns_after}, a reading page got {frames} frames in 2 s, \
         RSS {rss_early} kB -> {rss_late} kB"
    );
    assert!(
        pace_after > 0.5 * pace_before,
        "the bridge slowed from {pace_before:.2} to {pace_after:.2} simulated s per s with stalled clients"
    );
    assert!(
        frames >= 10,
        "a reading page got {frames} frames in 2 s (20 Hz)"
    );
    assert!(
        rss_late <= rss_early + 2048,
        "resident memory grew from {rss_early} kB to {rss_late} kB with stalled clients"
    );
    drop(stalled);
    drop(silent);
    daemon.stop();
}

/// Reads the event stream for `span` and counts its frames.
fn count_frames(addr: SocketAddr, token: &str, span: Duration) -> usize {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).expect("connect");
    write!(
        stream,
        "GET /api/stream?token={token} HTTP/1.1\r\nHost: {addr}\r\n\r\n"
    )
    .expect("request");
    stream
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let deadline = Instant::now() + span;
    let mut text = Vec::new();
    let mut buf = [0u8; 65536];
    while Instant::now() < deadline {
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => text.extend_from_slice(&buf[..n]),
            Err(_) => {}
        }
    }
    let text = String::from_utf8_lossy(&text);
    text.matches("event: frame").count()
}

/// In lockstep with TIME_STEP, the C library's default, the thrusters travel inside the
/// request and the readings come back as STEP values. The live page shows both; the page over
/// the recording, `gap convert` and `export --mcap` read the same values from the recording,
/// each the ones the client was sent. (The view's decoder once knew no TIME_STEP or STEP: the
/// page showed no thruster commands and no ADC values of such a run.)
#[test]
fn a_time_step_run_shows_the_same_thrusters_and_readings_everywhere() {
    use firmware_protocol::sensor_link::{
        AdcChannel, Direction as Spin, Reading, Readings, ThrusterCommand,
    };
    use firmware_protocol::{HeadingFormat, HeadingWord};

    let mut daemon = Daemon::options(BIN, "view-step")
        .lockstep()
        .record()
        .args(&["--view"])
        .start();
    let url = daemon
        .view_url
        .clone()
        .expect("run --view prints `view: URL`");
    let mut drive = LockstepDriver::new(&daemon, "time-step view test");
    let mut browser = Browser::open(daemon.dir.path(), "chromium-step", &url);
    // The loop hands bytes over only while a page watches.
    browser.wait_eval(
        "the page connected",
        WAIT,
        "!!(window.eyebotView && eyebotView.frame)",
        |v| v == &Value::Bool(true),
    );
    let adc = |c: u8| Reading::Adc(AdcChannel::new(c).expect("channel 0..8"));
    // Depth (channel 0), accel_x (channel 2) and the compass, as `configs/sensors` wires them.
    let codes = [adc(0), adc(2), Reading::Compass];
    let step = |drive: &mut LockstepDriver, used: u8, thrusters, readings: &[Reading]| {
        let reply = drive.ask(Message::TimeStep {
            used,
            stop_on_sonar: false,
            ticks: 5,
            thrusters,
            readings: Readings::new(readings.iter().copied()).expect("at most 16 readings"),
        });
        match reply {
            Message::Step { ticks, values, .. } => (ticks, values.as_slice().to_vec()),
            other => panic!("TIME_STEP answered {other:?}"),
        }
    };
    let mut sent = Vec::new();
    let mut duty = 0;
    for k in 0..20u8 {
        duty = 0x30 + k;
        let thrusters = [
            ThrusterCommand {
                duty,
                direction: Spin::Forward,
            },
            ThrusterCommand {
                duty,
                direction: Spin::Reverse,
            },
            ThrusterCommand::OFF,
            ThrusterCommand::OFF,
        ];
        let used = if k == 0 { 0 } else { 3 };
        sent.push(step(&mut drive, used, Some(thrusters), &codes));
    }
    // The last reply's values used, then time moves on without new readings.
    step(&mut drive, 3, None, &[]);
    for _ in 0..3 {
        step(&mut drive, 0, None, &[]);
    }
    let (last_ticks, last) = sent.last().cloned().expect("twenty steps");
    let heading = |word: u16| {
        HeadingWord(word)
            .decode(HeadingFormat::Binary)
            .map(f64::from)
            .expect("a binary heading word")
    };
    let want_adc = [Some(last[0]), None, Some(last[1])];
    let want_compass = heading(last[2]);

    let shown = browser.wait_eval(
        "the thrusters and ADC values of the last TIME_STEP",
        WAIT,
        "window.eyebotView && eyebotView.frame && eyebotView.frame.readings",
        |r| {
            r["thrusters"][0]["duty"] == duty
                && r["thrusters"][1]["reverse"] == true
                && r["adc"][0] == last[0]
                && r["adc"][2] == last[1]
                && r["compass_deg"].as_f64() == Some(want_compass)
        },
    );
    // The page draws on its next animation frame, after the frame object is in: wait for the
    // text to follow, and fail naming what it shows.
    let want_cmd = format!("cmd +{duty:02x} -{duty:02x} +ff +ff");
    let want_adc_text = format!("{} - {}", last[0], last[1]);
    browser.wait_eval(
        &format!("the page's text to show `{want_cmd}` and ADC `{want_adc_text}` (readings {shown})"),
        WAIT,
        "[document.getElementById('v-thrust').textContent, document.getElementById('v-adc').textContent]",
        |t| {
            t[0].as_str().is_some_and(|t| t.contains(&want_cmd))
                && t[1].as_str().is_some_and(|t| t.starts_with(&want_adc_text))
        },
    );
    let shot = artefact("time-step.png");
    std::fs::write(&shot, browser.screenshot()).expect("write the screenshot");
    eprintln!("screenshot: {}", shot.display());
    drop(browser);
    drop(drive);
    daemon.stop();
    let record = daemon.record_dir().to_path_buf();

    // The page over the recording reads the bytes through the same `WireWatch`.
    let mut wire = eyebot_hil::view::wire::WireWatch::new();
    for c in eyebot_hil::record::read_bytes(&record).expect("bytes.tsv") {
        wire.feed(c.sim_s, &c.link, c.dir, &c.data, |_| {});
    }
    let r = wire.readings();
    assert_eq!(r.adc[..3], want_adc, "{r:?}");
    assert_eq!(r.compass_deg, Some(want_compass));
    assert_eq!(
        r.thrusters[1].map(|t| (t.duty, t.reverse)),
        Some((duty, true))
    );

    // `gap convert`: every used STEP value at its tick, every command.
    let conv = eyebot_hil::gap::convert::convert(&record, &Default::default())
        .expect("the recording converts");
    let t0 = eyebot_hil::record::read_state(&record).expect("state.csv")[0].t_s;
    let series = |name: &str| {
        conv.measurement
            .channel(name)
            .map(|c| c.samples.clone())
            .unwrap_or_default()
    };
    let at = |ticks: u32| f64::from(ticks) * 0.01 - t0;
    let close_series = |got: Vec<(f64, f64)>, want: Vec<(f64, f64)>, name: &str| {
        assert_eq!(got.len(), want.len(), "{name}: {got:?} != {want:?}");
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g.0 - w.0).abs() < 1e-9 && g.1 == w.1,
                "{name}: {got:?} != {want:?}"
            );
        }
    };
    let value = |i: usize| -> Vec<(f64, f64)> {
        sent.iter()
            .map(|(t, v)| (at(*t), f64::from(v[i])))
            .collect()
    };
    close_series(series("depth_adc"), value(0), "depth_adc");
    close_series(series("accel_x_adc"), value(1), "accel_x_adc");
    // A heading repeated is the compass's last conversion read again: kept at its first read.
    let mut compass: Vec<(f64, f64)> = sent.iter().map(|(t, v)| (at(*t), heading(v[2]))).collect();
    compass.dedup_by(|later, first| later.1 == first.1);
    close_series(series("compass_deg"), compass, "compass_deg");
    let times: Vec<f64> = conv.measurement.commands.iter().map(|c| c.t_s).collect();
    let want_times: Vec<f64> = (0..sent.len()).map(|k| at(5 * k as u32)).collect();
    assert!(
        times.len() == want_times.len()
            && times
                .iter()
                .zip(&want_times)
                .all(|(a, b)| (a - b).abs() < 1e-9),
        "one row per TIME_STEP, at its request (the first at the start): {times:?}"
    );
    assert!(
        !conv.notices.iter().any(|n| n.contains("STEP")),
        "every value was used: {:?}",
        conv.notices
    );

    // `export --mcap`: the last state row's sensors and thrusters.
    let out = daemon.dir.join("step.mcap");
    eyebot_hil::view::foxglove::export_mcap(&record, &out).expect("the export");
    let bytes = std::fs::read(&out).expect("the MCAP file");
    let (mut sensors, mut thrusters) = (Value::Null, Value::Null);
    for message in mcap::MessageStream::new(&bytes).expect("an MCAP file") {
        let message = message.expect("a readable message");
        let slot = match message.channel.topic.as_str() {
            "/sensors" => &mut sensors,
            "/thrusters" => &mut thrusters,
            _ => continue,
        };
        *slot = serde_json::from_slice(&message.data).expect("a JSON message");
    }
    assert_eq!(
        sensors["adc"][0], last[0],
        "/sensors at the end (last STEP at tick {last_ticks}): {sensors}"
    );
    assert_eq!(sensors["adc"][2], last[1], "{sensors}");
    assert_eq!(sensors["compass_deg"].as_f64(), Some(want_compass));
    assert_eq!(thrusters["duty"][0], duty, "{thrusters}");
    assert_eq!(thrusters["reverse"][1], true, "{thrusters}");
}
