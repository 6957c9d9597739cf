use super::*;

/// What a `--record` directory holds before the run.
#[derive(Debug, Clone)]
enum Before {
    Missing,
    Empty,
    /// Some of a recording's files, with contents.
    Recording(Vec<(&'static str, Vec<u8>)>),
    /// Anything else: files (hidden ones too), a directory, a symlink.
    Other(Vec<(String, u8)>),
}

fn before() -> impl proptest::strategy::Strategy<Value = Before> {
    use proptest::prelude::*;
    let recording_file = prop::sample::select(vec![
        format::META_FILE,
        format::CONFIG_FILE,
        format::BYTES_FILE,
        format::DROPS_FILE,
        format::STATE_FILE,
        format::EVENTS_FILE,
        "bytes.tsv.gz",
    ]);
    prop_oneof![
        Just(Before::Missing),
        Just(Before::Empty),
        prop::collection::vec(
            (recording_file, prop::collection::vec(any::<u8>(), 0..64)),
            1..6
        )
        .prop_map(Before::Recording),
        prop::collection::vec(("[.]?[a-z]{1,8}", 0u8..3), 1..4).prop_map(Before::Other),
    ]
}

/// Every entry under `dir` with its contents (a symlink by its target), sorted.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let meta = std::fs::symlink_metadata(&path).unwrap();
        if meta.file_type().is_symlink() {
            let target = std::fs::read_link(&path).unwrap();
            out.push((path, target.into_os_string().into_encoded_bytes()));
        } else if meta.is_dir() {
            out.push((path.clone(), b"<dir>".to_vec()));
            out.extend(snapshot(&path));
        } else {
            out.push((path.clone(), std::fs::read(&path).unwrap()));
        }
    }
    out.sort();
    out
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// A recording starts in a missing or empty directory; a directory holding a
    /// recording, or anything else, is refused by name and left as it was. (A second
    /// `run --record DIR` replaced a recording of 1,260 chunks with an empty one.)
    #[test]
    fn a_recording_never_writes_over_what_a_directory_holds(before in before()) {
        let tmp = crate::scratch::dir("rec-over");
        let dir = tmp.path().join("rec");
        match &before {
            Before::Missing => {}
            Before::Empty => std::fs::create_dir(&dir).unwrap(),
            Before::Recording(files) => {
                std::fs::create_dir(&dir).unwrap();
                for (name, data) in files {
                    std::fs::write(dir.join(name), data).unwrap();
                }
            }
            Before::Other(entries) => {
                std::fs::create_dir(&dir).unwrap();
                for (name, kind) in entries {
                    let path = dir.join(name);
                    if std::fs::symlink_metadata(&path).is_ok() {
                        continue;
                    }
                    match kind {
                        0 => std::fs::write(&path, name.as_bytes()).unwrap(),
                        1 => std::fs::create_dir_all(path.join("inner")).unwrap(),
                        _ => std::os::unix::fs::symlink(tmp.path(), &path).unwrap(),
                    }
                }
            }
        }
        let was = if dir.exists() { snapshot(&dir) } else { Vec::new() };
        let meta = Meta::new(1, "lockstep", 1.0, "test");
        match Recorder::start(&dir, &meta, "") {
            Ok(rec) => {
                proptest::prop_assert!(was.is_empty(), "started over {was:?}");
                rec.finish().unwrap();
            }
            Err(e) => {
                proptest::prop_assert!(!was.is_empty(), "{e}");
                proptest::prop_assert!(matches!(e, RecordError::NotEmpty { .. }), "{e}");
                proptest::prop_assert!(e.to_string().contains(&dir.display().to_string()), "{e}");
                proptest::prop_assert_eq!(snapshot(&dir), was);
            }
        }
    }
}

fn state_row(t_s: f64, contact: bool) -> StateRow {
    StateRow {
        t_s,
        x_m: 1.0 / 3.0,
        y_m: -2.5,
        z_m: 1e-7,
        roll_rad: 0.1,
        pitch_rad: -0.2,
        yaw_rad: std::f64::consts::PI,
        u_mps: 0.3,
        v_mps: 0.0,
        w_mps: -0.0,
        p_radps: 1e300,
        q_radps: 0.5,
        r_radps: 0.25,
        force_port_n: 3.0,
        force_starboard_n: -3.0,
        force_bow_n: 0.125,
        force_stern_n: 7.0,
        contact,
    }
}

/// Everything handed to the recorder reads back through the public readers, bit for bit:
/// meta, the configuration verbatim, every byte value, drops and state rows.
#[test]
fn a_recording_reads_back_exactly() {
    let tmp = crate::scratch::dir("rec");
    let dir = tmp.path();
    let meta = Meta::new(7, "lockstep", 1.0, "<embedded>/default.toml");
    let config = "# a comment survives\nvehicle = \"vehicles/mako.toml\"\n";
    let rec = Recorder::start(dir, &meta, config).unwrap();
    let all: Vec<u8> = (0..=255u8).collect();
    rec.bytes(0.25, "sensor", Direction::Rx, &all);
    rec.bytes(1.5, "sonar", Direction::Tx, b"$SDDBT,,f,2.0,M,,F*00\r\n");
    let rows = [state_row(0.0, false), state_row(0.02, true)];
    for row in rows {
        rec.state(row);
    }
    rec.handle()
        .dropped(1.75, "sensor", DropReason::NotRead, &[0xEB, 0x90]);
    rec.event(1.8, "pose", "x_m=2 y_m=3 depth_m=1 heading_deg=90");
    let stats = rec.finish().unwrap();
    assert_eq!(
        stats,
        Stats {
            chunks: 2,
            bytes: 256 + 23,
            states: 2,
            drops: 1,
            dropped_bytes: 2,
            stalls: 0,
            events: 1,
        }
    );
    let events = read_events(dir).unwrap();
    assert_eq!(events.len(), 1);
    assert_eq!(
        (
            events[0].sim_s,
            events[0].event.as_str(),
            events[0].detail.as_str()
        ),
        (1.8, "pose", "x_m=2 y_m=3 depth_m=1 heading_deg=90")
    );
    assert_eq!(read_meta(dir).unwrap(), meta);
    assert_eq!(read_config(dir).unwrap(), config);
    let chunks = read_bytes(dir).unwrap();
    assert_eq!(chunks.len(), 2);
    assert_eq!(chunks[0].data, all);
    assert_eq!(chunks[0].dir, Direction::Rx);
    assert_eq!(chunks[0].sim_s, 0.25);
    assert_eq!(chunks[1].link, "sonar");
    assert_eq!(chunks[1].dir, Direction::Tx);
    assert_eq!(chunks[1].data, b"$SDDBT,,f,2.0,M,,F*00\r\n");
    let drops = read_drops(dir).unwrap();
    assert_eq!(drops.len(), 1);
    assert_eq!(
        (drops[0].sim_s, drops[0].link.as_str(), drops[0].reason),
        (1.75, "sensor", DropReason::NotRead)
    );
    assert_eq!(drops[0].data, [0xEB, 0x90]);
    let states = read_state(dir).unwrap();
    assert_eq!(states.len(), 2);
    for (got, want) in states.iter().zip(&rows) {
        // Bit for bit, including the sign of -0.0.
        let bits = |r: &StateRow| format!("{r:?}");
        assert_eq!(bits(got), bits(want));
    }
    // The documented text layout: 9 decimals of simulated time, lower-case hex.
    let text = std::fs::read_to_string(dir.join("drops.tsv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(DROPS_HEADER));
    let fields: Vec<&str> = lines.next().unwrap().split('\t').collect();
    assert_eq!(fields[0], "1.750000000");
    assert_eq!(fields[2..], ["sensor", "not-read", "eb90"]);
}

/// The header constants are the serde field names, so a renamed field cannot leave the
/// documented header behind.
#[test]
fn the_headers_are_the_field_names_of_the_row_types() {
    fn header_of(row: &impl serde::Serialize, delimiter: u8) -> String {
        let mut w = csv::WriterBuilder::new()
            .delimiter(delimiter)
            .from_writer(Vec::new());
        w.serialize(row).unwrap();
        let text = String::from_utf8(w.into_inner().unwrap()).unwrap();
        text.lines().next().unwrap().to_string()
    }
    let chunk = ByteChunk {
        sim_s: 0.0,
        wall_unix_s: 0.0,
        link: "sonar".into(),
        dir: Direction::Tx,
        data: vec![1],
    };
    let drop = DropRow {
        sim_s: 0.0,
        wall_unix_s: 0.0,
        link: "sonar".into(),
        reason: DropReason::Shutdown,
        data: vec![1],
    };
    assert_eq!(header_of(&chunk, b'\t'), BYTES_HEADER);
    assert_eq!(header_of(&drop, b'\t'), DROPS_HEADER);
    assert_eq!(header_of(&state_row(0.0, false), b','), STATE_HEADER);
}

/// A recording made before `config.toml` existed (format 1: the configuration as `#`
/// comments in `meta.toml`), written by that version's binary, still reads: meta,
/// configuration, model files, bytes and state.
#[test]
fn a_format_1_recording_still_reads() {
    let dir = &Path::new(env!("CARGO_MANIFEST_DIR")).join("pty-tests/fixtures/recording-format-1");
    let meta = read_meta(dir).unwrap();
    assert_eq!(meta.format, format::FORMAT_COMMENTED_CONFIG);
    assert_eq!(meta.time_mode, "lockstep");
    let config = read_config(dir).unwrap();
    // the default configuration of the binary that made it (configs/default.toml then)
    let then = std::fs::read_to_string(dir.join("default-then.toml")).unwrap();
    assert_eq!(
        config, then,
        "the commented copy is the configuration verbatim"
    );
    assert_eq!(
        read_model_files(dir).unwrap(),
        ModelFiles {
            vehicle: "vehicles/mako.toml".into(),
            world: "worlds/pool.toml".into(),
            sensors: "sensors/mako-2008.toml".into(),
        }
    );
    let chunks = read_bytes(dir).unwrap();
    assert!(chunks.iter().any(|c| c.dir == Direction::Rx));
    assert!(chunks.iter().any(|c| c.dir == Direction::Tx));
    assert!(!read_state(dir).unwrap().is_empty());
    assert!(read_drops(dir).unwrap().is_empty());
}

/// A `meta.toml` of neither format names the file and says it may be older.
#[test]
fn an_unreadable_meta_says_it_may_be_from_an_older_version() {
    let tmp = crate::scratch::dir("rec-oldmeta");
    let dir = tmp.path();
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("meta.toml"), "seed = 1\n").unwrap();
    let e = read_meta(dir).unwrap_err().to_string();
    assert!(e.contains("meta.toml"), "{e}");
    assert!(e.contains("recorded by an older version"), "{e}");
    let newer = "format = 99\nversion = \"9.0.0\"\nseed = 1\ntime_mode = \"lockstep\"\n\
                     speed = 1.0\nconfig = \"x\"\n";
    std::fs::write(dir.join("meta.toml"), newer).unwrap();
    let e = read_meta(dir).unwrap_err().to_string();
    assert!(e.contains("newer version"), "{e}");
}

/// Table errors name the file, the line and the column or header that was expected.
#[test]
fn a_bad_table_names_file_line_and_what_was_expected() {
    let tmp = crate::scratch::dir("rec-bad");
    let dir = tmp.path();
    std::fs::create_dir_all(dir).unwrap();
    // `simulate`'s earlier columns (degrees, thrust_*) are not state rows.
    std::fs::write(
        dir.join("state.csv"),
        "t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,0,0,0,0\n",
    )
    .unwrap();
    let e = read_state(dir).unwrap_err().to_string();
    assert!(e.contains("state.csv line 1: expected the header"), "{e}");
    let good = format!("{STATE_HEADER}\n{}\n", "0,".repeat(17) + "0");
    let bad_cell = good.clone() + &"0,".repeat(17) + "2\n";
    std::fs::write(dir.join("state.csv"), &bad_cell).unwrap();
    let e = read_state(dir).unwrap_err().to_string();
    assert!(e.contains("state.csv line 3"), "{e}");
    assert!(e.contains("column `contact`"), "{e}");
    std::fs::write(
        dir.join("bytes.tsv"),
        format!("{BYTES_HEADER}\n1.0\t2.0\tsonar\tup\t00\n"),
    )
    .unwrap();
    let e = read_bytes(dir).unwrap_err().to_string();
    assert!(e.contains("bytes.tsv line 2: unknown variant `up`"), "{e}");
    std::fs::write(
        dir.join("state.csv"),
        format!("{good}NaN{}\n", ",0".repeat(17)),
    )
    .unwrap();
    let e = read_state(dir).unwrap_err().to_string();
    assert!(
        e.contains("state.csv line 3: column `t_s`: expected a finite"),
        "{e}"
    );
}

/// A disk that stops taking data (here a FIFO nobody reads) makes the caller wait once
/// the queue is full, instead of growing memory or dropping: every chunk arrives once the
/// reader catches up, and the waits are counted.
#[test]
fn a_stalled_disk_blocks_the_caller_and_loses_nothing() {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let tmp = crate::scratch::dir("rec-fifo");
    let dir = tmp.path();
    let fifo = dir.join("bytes.tsv");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let mut reader = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(nix::libc::O_NONBLOCK)
        .open(&fifo)
        .unwrap();
    // The FIFO stands in for a stalled disk, so the directory is not empty.
    let rec = Recorder::start_in(dir, &Meta::new(1, "lockstep", 1.0, "test"), "").unwrap();
    let chunk = vec![0x5A_u8; 1024];
    let total = 3 * QUEUE_MESSAGES;
    let (done_tx, done_rx) = mpsc::channel();
    let writer = std::thread::spawn(move || {
        for i in 0..total {
            rec.bytes(i as f64, "sensor", Direction::Rx, &chunk);
        }
        let _ = done_tx.send(rec.stalls());
        rec.finish().unwrap()
    });
    // Nobody reads: the pipe (64 KiB) and the queue fill, then the caller waits.
    assert!(
        done_rx.recv_timeout(Duration::from_millis(500)).is_err(),
        "the caller must wait for a stalled recorder"
    );
    let mut got = Vec::new();
    let mut buf = vec![0u8; 1 << 16];
    let stalls = loop {
        match reader.read(&mut buf) {
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                if let Ok(stalls) = done_rx.try_recv() {
                    break stalls;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => panic!("{e}"),
        }
    };
    assert!(stalls > 0, "the waits are counted");
    // Drain the rest until the writer closes its end.
    let finishing = std::thread::spawn(move || writer.join().unwrap());
    loop {
        match reader.read(&mut buf) {
            Ok(0) if finishing.is_finished() => break,
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(1))
            }
            Err(e) => panic!("{e}"),
        }
    }
    let stats = finishing.join().unwrap();
    assert_eq!(stats.chunks, total as u64);
    assert!(stats.stalls > 0);
    let text = String::from_utf8(got).unwrap();
    assert_eq!(text.lines().count(), total + 1, "header + every chunk");
}

#[test]
fn malformed_lines_name_the_line_and_the_problem() {
    let reason = |text| parse_chunk(text, 1).unwrap_err().reason;
    assert_eq!(
        parse_chunk("1.0\t2.0\tsonar\tup\t00", 7).unwrap_err().line,
        7
    );
    assert!(reason("1.0\t2.0\tsonar\tup\t00").contains("expected `rx` or `tx`"));
    assert!(reason("1.0\t2.0\tsonar\ttx\t0").contains("bad hex"));
    assert!(reason("1.0\t2.0\tsonar\ttx\tzz").contains("bad hex"));
    assert!(reason("x\t2.0\tsonar\ttx\t00").contains("column `sim_s`"));
    assert!(reason("1.0").contains("missing"));
}
