use std::io::Write;

use std::sync::atomic::Ordering;

use super::*;

fn events(path: &Path) -> (Format, Vec<Event>) {
    let mut s = Source::open(
        path,
        0,
        "sonar",
        CommentMode::Report,
        Arc::new(AtomicU64::new(0)),
    )
    .unwrap();
    let mut out = Vec::new();
    while let Some(e) = s.next_event().unwrap() {
        out.push(e);
    }
    (s.format(), out)
}

fn lines(events: &[Event]) -> Vec<(Option<i64>, Vec<u8>, Terminator)> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Line(l) => Some((l.time_ns, l.bytes.clone(), l.terminator)),
            _ => None,
        })
        .collect()
}

#[test]
fn seconds_iso_and_plain_forms_are_told_apart() {
    assert_eq!(classify(b"$SDDBT,1*00"), Some(TimestampForm::None));
    assert_eq!(
        classify(b"12.250 $SDDBT,1*00"),
        Some(TimestampForm::Seconds)
    );
    assert_eq!(
        classify(b"1714564800\t$SDDBT"),
        Some(TimestampForm::Seconds)
    );
    assert_eq!(
        classify(b"2024-05-01T12:00:00.250Z $SDDBT"),
        Some(TimestampForm::Iso8601)
    );
    assert_eq!(
        classify(b"2024-05-01T12:00:00+02:00  $SDDBT"),
        Some(TimestampForm::Iso8601)
    );
    assert_eq!(
        classify(b"2024-05-01T12:00:00.5 $SDDBT"),
        Some(TimestampForm::Iso8601)
    );
    // Junk does not vote; a prefix without a following sentence is not a timestamp.
    assert_eq!(classify(b"\x00\x01garbage"), None);
    assert_eq!(classify(b"12.5 hello"), None);
    assert_eq!(classify(b"1.2.3 $SDDBT"), None);
    assert_eq!(classify(b"-5 $SDDBT"), None);
}

#[test]
fn iso_times_become_unix_nanoseconds() {
    assert_eq!(parse_iso8601("1970-01-01T00:00:01.5Z"), Some(1_500_000_000));
    assert_eq!(parse_iso8601("1970-01-01T01:00:00+01:00"), Some(0));
    assert_eq!(parse_iso8601("1970-01-01T00:00:02"), Some(2_000_000_000));
    assert_eq!(parse_iso8601("1970-01-01"), None);
    assert_eq!(parse_seconds("0.001"), Some(1_000_000));
}

#[test]
fn majority_of_first_lines_decides_and_ties_are_errors() {
    let p = Path::new("log");
    let s = TimestampForm::Seconds;
    let n = TimestampForm::None;
    assert_eq!(decide_form(p, &[(1, s), (2, n), (3, s)]).unwrap(), s);
    assert_eq!(decide_form(p, &[]).unwrap(), n);
    let err = decide_form(p, &[(4, s), (9, n)]).unwrap_err();
    assert!(err.to_string().contains("lines 9 and 4"), "{err}");
}

#[test]
fn timestamped_log_with_comments_lf_and_junk() {
    let tmp = crate::scratch::dir("timed");
    let dir = tmp.path();
    let path = dir.join("a.log");
    std::fs::write(
        &path,
        b"#Serial: 9600 8N1\n# a note\n0.5 $SDDBT,1*00\r\n\n1.25\t$SDDBT,2*00\nnot-a-time $SDDBT,3*00\n\x01\x02junk\n2 $SDDBT,4*00",
    )
    .unwrap();
    let (format, ev) = events(&path);
    assert_eq!(
        format,
        Format::Nmea {
            timestamps: TimestampForm::Seconds
        }
    );
    assert!(
        matches!(&ev[0], Event::Serial { settings, loc } if settings.baud == 9600 && loc.line == 1)
    );
    assert!(matches!(&ev[1], Event::Comment { text, .. } if text == "# a note"));
    let l = lines(&ev);
    assert_eq!(
        l,
        vec![
            (Some(500_000_000), b"$SDDBT,1*00".to_vec(), Terminator::CrLf),
            (Some(1_250_000_000), b"$SDDBT,2*00".to_vec(), Terminator::Lf),
            (
                Some(2_000_000_000),
                b"$SDDBT,4*00".to_vec(),
                Terminator::Eof
            ),
        ]
    );
    let bad: Vec<u64> = ev
        .iter()
        .filter_map(|e| match e {
            Event::Problem(p) => Some(p.loc.line),
            _ => None,
        })
        .collect();
    assert_eq!(bad, vec![6, 7], "the untimed line and the junk line");
}

#[test]
fn gzip_is_detected_by_magic_not_extension() {
    let tmp = crate::scratch::dir("gzip");
    let dir = tmp.path();
    let plain = b"$SDDBT,1*00\r\n$SDDBT,2*00\r\n";
    let path = dir.join("log.txt"); // no .gz extension
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(plain).unwrap();
    std::fs::write(&path, enc.finish().unwrap()).unwrap();
    let count = Arc::new(AtomicU64::new(0));
    let mut s = Source::open(&path, 0, "sonar", CommentMode::Report, count.clone()).unwrap();
    assert!(s.is_gzip());
    let mut got = Vec::new();
    while let Some(Event::Line(l)) = s.next_event().unwrap() {
        got.push(l.bytes);
    }
    assert_eq!(got, vec![b"$SDDBT,1*00".to_vec(), b"$SDDBT,2*00".to_vec()]);
    assert_eq!(
        count.load(Ordering::Relaxed),
        std::fs::metadata(&path).unwrap().len(),
        "progress counts compressed bytes read from disk"
    );
    // A .gz name on a plain file is read as plain text.
    let fake = dir.join("plain.gz");
    std::fs::write(&fake, plain).unwrap();
    let (_, ev) = events(&fake);
    assert_eq!(lines(&ev).len(), 2);
}

#[test]
fn recorded_sentences_are_reassembled_across_chunks() {
    let tmp = crate::scratch::dir("record");
    let dir = tmp.path();
    let rec = dir.join("run1");
    std::fs::create_dir_all(&rec).unwrap();
    let sentence = b"$SDDBT,6.6,f,2.0,M,1.1,F*3A\r\n";
    let mut tsv = format!("{BYTES_HEADER}\n");
    // Split the first sentence over three chunks, interleave other traffic.
    let parts: [&[u8]; 3] = [&sentence[..5], &sentence[5..20], &sentence[20..]];
    tsv += &format!("1.000000000\t0\tsonar\ttx\t{}\n", hex::encode(parts[0]));
    tsv += &format!("1.001000000\t0\tsonar\trx\t{}\n", hex::encode(b"@S1\r"));
    tsv += &format!("1.002000000\t0\tsensor\ttx\t{}\n", hex::encode([0xEB, 1]));
    tsv += &format!("1.003000000\t0\tsonar\ttx\t{}\n", hex::encode(parts[1]));
    tsv += &format!(
        "1.004000000\t0\tsonar\ttx\t{}{}\n",
        hex::encode(parts[2]),
        hex::encode(b"@A1\r\n$SD")
    );
    tsv += "garbage line\n";
    tsv += &format!("2.5\t0\tsonar\ttx\t{}\n", hex::encode(&sentence[3..]));
    std::fs::write(rec.join("bytes.tsv"), tsv).unwrap();
    let mut s = Source::open(
        &rec,
        0,
        "sonar",
        CommentMode::Report,
        Arc::new(AtomicU64::new(0)),
    )
    .unwrap();
    assert_eq!(s.format(), Format::Recording);
    let mut ev = Vec::new();
    while let Some(e) = s.next_event().unwrap() {
        ev.push(e);
    }
    let l = lines(&ev);
    assert_eq!(l.len(), 2);
    assert_eq!(l[0].0, Some(1_000_000_000), "time of the first byte");
    assert_eq!(l[0].1, &sentence[..sentence.len() - 2]);
    assert_eq!(l[0].2, Terminator::CrLf);
    assert_eq!(l[1].1, &sentence[..sentence.len() - 2], "split at $SD");
    assert_eq!(l[1].0, Some(1_004_000_000));
    assert_eq!(s.link_messages_skipped, 1, "the @A1 ack");
    assert!(ev.iter().any(
        |e| matches!(e, Event::Problem(p) if p.loc.line == 7 && matches!(p.kind, ProblemKind::BadRecordLine { .. }))
    ));
}

#[test]
fn a_line_without_line_feeds_is_cut_at_the_cap() {
    let tmp = crate::scratch::dir("cap");
    let dir = tmp.path();
    let path = dir.join("junk.log");
    let mut data = vec![0xFFu8; 3 * MAX_PHYSICAL_LINE];
    data.extend_from_slice(b"\n$SDDBT,1*00\r\n");
    std::fs::write(&path, data).unwrap();
    let (_, ev) = events(&path);
    match &ev[0] {
        Event::Line(l) => {
            assert_eq!(l.bytes.len(), MAX_PHYSICAL_LINE);
            assert_eq!(l.overflow, Some(3 * MAX_PHYSICAL_LINE));
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(&ev[1], Event::Line(l) if l.bytes == b"$SDDBT,1*00" && l.loc.line == 2));
}
