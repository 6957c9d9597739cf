use std::io::Write;

use super::*;

fn from_bytes(data: Vec<u8>) -> Source {
    Source::from_reader(
        Path::new("mem.log"),
        Box::new(io::Cursor::new(data)),
        "sonar",
        CommentMode::Report,
    )
    .unwrap()
}

fn drain(s: &mut Source) -> Vec<Event> {
    let mut out = Vec::new();
    while let Some(e) = s.next_event().unwrap() {
        out.push(e);
    }
    out
}

/// Format detection holds at most [`DETECT_MAX_LOOKAHEAD`] lines, whatever precedes the
/// first data lines: blank lines are counted, not held; comments stop being held at the cap.
#[test]
fn blank_and_comment_bombs_do_not_fill_the_lookahead() {
    let mut data = b"\n".repeat(200_000);
    data.extend(b"  \r\n".repeat(1000));
    let mut s = from_bytes(data.clone());
    assert!(s.lookahead.is_empty(), "blank lines are not held");
    assert_eq!(s.blank_lines, 201_000);
    let ev = drain(&mut s);
    assert!(ev.is_empty());

    let mut data = b"# note\n".repeat(50_000);
    data.extend_from_slice(b"1.0 $A*41\r\n");
    let mut s = from_bytes(data);
    assert_eq!(s.lookahead.len(), DETECT_MAX_LOOKAHEAD);
    let ev = drain(&mut s);
    assert_eq!(s.comment_lines, 50_000);
    assert_eq!(s.physical_lines(), 50_001);
    // Detection saw no data line; the form is decided on what it had (none).
    assert!(matches!(ev.last(), Some(Event::Line(l)) if l.bytes == b"1.0 $A*41"));
}

/// A CR alone ends a line (old Mac-style logs); CR LF stays one ending; a CR at the end of
/// a read buffer is paired with the LF at the start of the next.
#[test]
fn cr_only_line_endings_split_lines() {
    let mut s = from_bytes(b"$A*41\r$B*42\r\r\n$C*43\r".to_vec());
    let got: Vec<(Vec<u8>, Terminator)> = drain(&mut s)
        .into_iter()
        .filter_map(|e| match e {
            Event::Line(l) => Some((l.bytes, l.terminator)),
            _ => None,
        })
        .collect();
    assert_eq!(
        got,
        vec![
            (b"$A*41".to_vec(), Terminator::Cr),
            (b"$B*42".to_vec(), Terminator::Cr),
            (b"$C*43".to_vec(), Terminator::Cr),
        ]
    );
    assert_eq!(s.blank_lines, 1, "the CR LF after $B's CR is an empty line");
    // CR and LF in separate reads.
    let data = [&b"$A*41\r"[..], &b"\n$B*42\r\n"[..]].concat();
    let mut r = io::BufReader::with_capacity(6, &data[..]);
    let mut buf = Vec::new();
    assert_eq!(
        read_capped(&mut r, &mut buf, 100).unwrap(),
        Some((5, Terminator::CrLf))
    );
    assert_eq!(
        read_capped(&mut r, &mut buf, 100).unwrap(),
        Some((5, Terminator::CrLf))
    );
    assert_eq!(read_capped(&mut r, &mut buf, 100).unwrap(), None);
}

/// A truncated gzip yields every line before the cut, then an `input cut short` problem at
/// the line being read, and no error: the replay goes on to its summary.
#[test]
fn a_truncated_gzip_reports_where_it_ended() {
    let text: String = (0..2000).map(|i| format!("$GPXXX,{i}*00\r\n")).collect();
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(text.as_bytes()).unwrap();
    let mut gz = enc.finish().unwrap();
    gz.truncate(gz.len() / 2);
    let mut s = from_bytes(gz);
    assert!(s.is_gzip());
    let ev = drain(&mut s);
    assert!(s.cut_short);
    let lines = ev.iter().filter(|e| matches!(e, Event::Line(_))).count() as u64;
    assert!(lines > 100 && lines < 2000, "{lines}");
    match ev.last() {
        Some(Event::Problem(p)) => {
            assert!(matches!(p.kind, ProblemKind::ReadFailed { .. }), "{p}");
            assert_eq!(p.action, Action::InputEnded);
            assert!(p.loc.line > lines, "{} after {lines} lines", p.loc);
            assert!(p.to_string().starts_with("mem.log:"), "{p}");
        }
        other => panic!("{other:?}"),
    }
}

/// ISO 8601 times centuries apart differ by more than i64 nanoseconds hold.
#[test]
fn times_far_apart_do_not_overflow() {
    let mut s =
        from_bytes(b"2262-04-11T00:00:00Z $A*41\r\n1677-09-22T00:00:00Z $A*41\r\n".to_vec());
    let ev = drain(&mut s);
    let back = ev
        .iter()
        .find_map(|e| match e {
            Event::Problem(Problem {
                kind: ProblemKind::TimeWentBack { by_s },
                ..
            }) => Some(*by_s),
            _ => None,
        })
        .expect("time went back");
    let years = back / (365.25 * 86400.0);
    assert!((584.0..585.0).contains(&years), "{back} s = {years} years");
}

/// Every physical line lands in exactly one counter or event.
#[test]
fn every_line_is_accounted_for_once() {
    let data =
        b"#Serial: 9600 8N1\n# c\n\n1.0 $A*41\r\nbad $A*41\r\n2.0 $B*42\r\n\n#x\nxx\n3 $C".to_vec();
    let mut s = from_bytes(data);
    let ev = drain(&mut s);
    let lines = ev.iter().filter(|e| matches!(e, Event::Line(_))).count() as u64;
    assert_eq!(s.unplaceable_lines, 2, "`bad` and `xx` have no timestamp");
    assert_eq!(s.comment_lines, 2);
    assert_eq!(s.serial_lines, 1);
    assert_eq!(s.blank_lines, 2);
    assert_eq!(lines, 3);
    assert_eq!(
        s.physical_lines(),
        lines + s.unplaceable_lines + s.comment_lines + s.serial_lines + s.blank_lines
    );
}

/// A FIFO is opened without waiting for its writer and read once; a read waiting for a
/// writer that never comes ends on the shutdown flag.
#[test]
fn a_fifo_without_writer_gives_way_to_shutdown() {
    let tmp = crate::scratch::dir("fifo");
    let fifo = tmp.path().join("log.fifo");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let stop = Shutdown::new();
    let (tx, rx) = std::sync::mpsc::channel();
    let (path, s2) = (fifo.clone(), stop.clone());
    std::thread::spawn(move || {
        let r = Source::open_until(&path, 0, "sonar", CommentMode::Report, Arc::default(), &s2);
        let _ = tx.send(r.map(|_| ()).map_err(|e| e.to_string()));
    });
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert!(rx.try_recv().is_err(), "still waiting for the writer");
    stop.trigger();
    let r = rx
        .recv_timeout(std::time::Duration::from_secs(2))
        .expect("open gave way to the shutdown flag");
    let err = r.unwrap_err();
    assert!(
        err.contains("log.fifo") && err.contains("shutdown"),
        "{err}"
    );
}
