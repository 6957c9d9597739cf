use std::io::{Read, Write};

use super::*;

fn pty_config() -> LinkConfig {
    LinkConfig {
        endpoint: Endpoint::Pty {
            link: "sonar".into(),
        },
        line: LineSettings::n81(4800),
        tx_queue_bytes: 4096,
    }
}

struct Running {
    to_core: mpsc::Receiver<Inbound>,
    from_core: mpsc::Sender<Outbound>,
    counters: Arc<LinkCounters>,
    stop: watch::Sender<bool>,
    task: tokio::task::JoinHandle<()>,
    client_path: PathBuf,
    /// Holds the run directory of the link's symlink; removed when the test ends.
    _dir: tempfile::TempDir,
}

async fn start(tag: &str) -> Running {
    let dir = crate::scratch::dir(&format!("link-{tag}"));
    let endpoint = OpenEndpoint::open("sonar", &pty_config(), dir.path())
        .await
        .unwrap();
    let client_path = dir.path().join("sonar");
    assert!(
        endpoint
            .describe()
            .starts_with(&client_path.display().to_string())
    );
    let (in_tx, in_rx) = mpsc::channel(16);
    let (out_tx, out_rx) = mpsc::channel(TX_CHANNEL_CHUNKS);
    let (stop, stop_rx) = watch::channel(false);
    let counters = Arc::new(LinkCounters::default());
    let cx = LineContext {
        line: 0,
        name: "sonar",
        counters: counters.clone(),
        recorder: None,
    };
    let task = tokio::spawn(run_line(cx, endpoint, in_tx, out_rx, stop_rx));
    Running {
        to_core: in_rx,
        from_core: out_tx,
        counters,
        stop,
        task,
        client_path,
        _dir: dir,
    }
}

#[tokio::test]
async fn bytes_cross_a_pty_link_both_ways() {
    let mut run = start("both").await;
    let path = run.client_path.clone();
    let mut client = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .unwrap();
    client.write_all(b"#S1\r").unwrap();
    let got = run.to_core.recv().await.unwrap();
    assert_eq!(&got.data[..], b"#S1\r");
    run.from_core
        .send(outbound(b"$SDDBT,,f,2.0,M,,F*00\r\n"))
        .await
        .unwrap();
    let mut back = [0u8; 23];
    tokio::task::spawn_blocking(move || {
        client.read_exact(&mut back).unwrap();
        back
    })
    .await
    .map(|b| assert_eq!(&b, b"$SDDBT,,f,2.0,M,,F*00\r\n"))
    .unwrap();
    run.stop.send(true).unwrap();
    run.task.await.unwrap();
    assert!(
        std::fs::symlink_metadata(&path).is_err(),
        "symlink removed at shutdown"
    );
}

/// Regression: bytes the EyeBot wrote just before shutdown were lost when the task's
/// select picked the shutdown over the pending read (and so never reached the
/// recording). The task now drains its endpoint as it stops.
#[tokio::test]
async fn bytes_written_just_before_shutdown_still_reach_the_core() {
    for round in 0..20 {
        let mut run = start(&format!("drain{round}")).await;
        let mut client = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&run.client_path)
            .unwrap();
        // The shutdown is signalled before the link task has run at all.
        client.write_all(b"#S2\r").unwrap();
        run.stop.send(true).unwrap();
        tokio::time::timeout(Duration::from_secs(1), run.task)
            .await
            .expect("link task ends")
            .unwrap();
        let got = run.to_core.try_recv().map(|i| i.data.to_vec());
        assert_eq!(got.as_deref(), Ok(&b"#S2\r"[..]), "round {round}");
    }
}

/// A client that opens the line but never reads must not wedge the daemon: the hand-over
/// channel fills (the core then drops and counts), and shutdown still ends the task.
#[tokio::test]
async fn a_client_that_never_reads_cannot_block_shutdown() {
    let run = start("noread").await;
    let _client = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&run.client_path)
        .unwrap();
    let chunk = outbound(&[b'x'; 4096]);
    let mut refused = 0;
    for _ in 0..1000 {
        if run.from_core.try_send(chunk.clone()).is_err() {
            refused += 1;
        }
        tokio::task::yield_now().await;
    }
    assert!(
        refused > 0,
        "a bounded hand-over refuses chunks once the client stops reading"
    );
    run.stop.send(true).unwrap();
    drop(run.from_core);
    tokio::time::timeout(Duration::from_secs(1), run.task)
        .await
        .expect("link task ends within 1 s of shutdown")
        .unwrap();
    // What was handed over but never taken by the client is accounted for: written
    // (into the pty's kernel buffer) or dropped at shutdown, nothing else.
    let written = run.counters.bytes_tx.load(Ordering::Relaxed);
    let dropped = run.counters.dropped_tx.load(Ordering::Relaxed);
    assert_eq!(
        written + dropped,
        (1000 - refused) * 4096,
        "written {written}, dropped {dropped}"
    );
    assert!(dropped > 0);
}

fn outbound(data: &[u8]) -> Outbound {
    Outbound {
        sim_s: 0.0,
        data: Bytes::copy_from_slice(data),
    }
}

/// Regression: the EyeBot side opening and closing its pty end was invisible (the bridge
/// keeps the slave open) and never counted in the link's reconnects.
#[tokio::test]
async fn reopening_the_pty_counts_as_a_reconnect() {
    let run = start("reopen").await;
    for _ in 0..5 {
        drop(
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&run.client_path)
                .unwrap(),
        );
    }
    let deadline = std::time::Instant::now() + Duration::from_secs(5);
    while run.counters.reconnects.load(Ordering::Relaxed) < 4
        && std::time::Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    assert_eq!(
        run.counters.reconnects.load(Ordering::Relaxed),
        4,
        "five sessions: the first a connect, four reconnects"
    );
    run.stop.send(true).unwrap();
    run.task.await.unwrap();
}

/// The forms a pty link path takes in a configuration, as components: plain names, a
/// name that is a real directory, one that is a symlink to a world-writable directory
/// outside, `.`, `..`, and optionally an absolute start in that outside directory.
fn link_path_form() -> impl proptest::strategy::Strategy<Value = (bool, Vec<&'static str>)> {
    use proptest::prelude::*;
    (
        any::<bool>(),
        prop::collection::vec(
            prop::sample::select(vec!["sonar", "new", "real", "escape", ".", ".."]),
            1..5,
        ),
    )
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// Whatever the link path's form (absolute, relative, with `..`, through a symlinked
    /// directory), the daemon makes nothing outside its checked run directory: the link
    /// lands inside it, or opening fails naming the path. (`../../../escaped-sonar` put the
    /// symlink and its owner file in a world-writable directory.)
    #[test]
    fn a_pty_link_never_lands_outside_the_run_directory((absolute, parts) in link_path_form()) {
        use std::os::unix::fs::PermissionsExt;
        let tmp = crate::scratch::dir("link-form");
        let run = tmp.path().join("a/b/run");
        let outside = tmp.path().join("outside");
        std::fs::create_dir_all(run.join("real")).unwrap();
        std::fs::create_dir(&outside).unwrap();
        std::fs::set_permissions(&outside, std::fs::Permissions::from_mode(0o777)).unwrap();
        std::os::unix::fs::symlink(&outside, run.join("escape")).unwrap();
        let mut link = if absolute { outside.clone() } else { PathBuf::new() };
        link.extend(&parts);
        let config = LinkConfig {
            endpoint: Endpoint::Pty { link: link.clone() },
            ..pty_config()
        };
        let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
        let opened = rt.block_on(OpenEndpoint::open("sonar", &config, &run));
        let outside_now: Vec<_> = std::fs::read_dir(&outside).unwrap().collect();
        proptest::prop_assert!(outside_now.is_empty(), "{} made {outside_now:?}", link.display());
        let above: Vec<_> = std::fs::read_dir(tmp.path().join("a/b")).unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        proptest::prop_assert_eq!(above, vec![std::ffi::OsString::from("run")]);
        match opened {
            Ok(endpoint) => {
                let (made, _) = endpoint.owned_link().expect("a pty link");
                let parent = made.parent().unwrap().canonicalize().unwrap();
                proptest::prop_assert!(
                    parent.starts_with(run.canonicalize().unwrap()),
                    "{} landed in {}", link.display(), parent.display()
                );
            }
            Err(e) => {
                let text = e.to_string();
                proptest::prop_assert!(text.contains(&run.join(&link).display().to_string()), "{text}");
            }
        }
    }
}
