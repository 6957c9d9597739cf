use bytes::BytesMut;
use proptest::prelude::*;

use super::*;
use crate::error::FrameError;
use crate::nmea::{Dbt, Talker, Transducer};
use crate::sensor_link::ErrorCode;

fn bytes_of(seq: u8, message: Message) -> Vec<u8> {
    let mut b = BytesMut::new();
    Frame::new(seq, message).encode(&mut b);
    b.to_vec()
}

fn time(ticks: u32) -> Message {
    Message::Time {
        ticks,
        tick_us: 10_000,
    }
}

fn push(x: i16) -> Message {
    Message::CompassRawPush { x, y: -x }
}

fn dbt() -> Vec<u8> {
    let mut b = BytesMut::new();
    Sentence::Dbt(Dbt::empty(Talker::SOUNDER))
        .encode(&mut b)
        .expect("an empty DBT encodes");
    b.to_vec()
}

/// Feeds `bytes` one at a time, polling `take_reply(seq)` after each, as a slow line would.
fn reply_byte_by_byte(client: &mut EyeBotClient, seq: u8, bytes: &[u8]) -> Option<Message> {
    let mut reply = None;
    for &b in bytes {
        client.receive(&[b]);
        while let Some(r) = client.take_reply(seq) {
            if let Ok(message) = r {
                assert!(reply.is_none(), "one reply to {seq}");
                reply = Some(message);
            }
        }
    }
    reply
}

#[test]
fn requests_take_consecutive_seqs_from_the_first_and_wrap() {
    let mut client = EyeBotClient::with_first_seq(0xFE);
    let mut wire = BytesMut::new();
    let seqs: Vec<u8> = (0..3)
        .map(|_| client.encode_request(Message::TimeGet, &mut wire))
        .collect();
    assert_eq!(seqs, [0xFE, 0xFF, 0x00]);
    let sent: Vec<u8> = seqs
        .iter()
        .flat_map(|&seq| bytes_of(seq, Message::TimeGet))
        .collect();
    assert_eq!(&wire[..], &sent[..], "the frames, in order");
    assert_eq!(EyeBotClient::new().next_seq(), 0);
}

#[test]
fn a_request_with_a_given_seq_moves_the_counter_past_it() {
    let mut client = EyeBotClient::new();
    let mut wire = BytesMut::new();
    client.encode_request_as(0x41, Message::CountersGet, &mut wire);
    assert_eq!(&wire[..], &bytes_of(0x41, Message::CountersGet)[..]);
    assert_eq!(client.encode_request(Message::TimeGet, &mut wire), 0x42);
}

#[test]
fn pushes_before_a_reply_are_queued_in_order_and_the_reply_matched_by_seq() {
    let mut client = EyeBotClient::new();
    let seq = client.encode_request(Message::TimeGet, &mut BytesMut::new());
    let line = [
        bytes_of(7, push(1)),
        bytes_of(8, push(2)),
        bytes_of(seq, time(5)),
        bytes_of(9, push(3)),
    ]
    .concat();
    assert_eq!(reply_byte_by_byte(&mut client, seq, &line), Some(time(5)));
    let pushes: Vec<Frame> = std::iter::from_fn(|| client.take_push())
        .map(|p| p.expect("no wire error"))
        .collect();
    assert_eq!(
        pushes,
        [
            Frame::new(7, push(1)),
            Frame::new(8, push(2)),
            Frame::new(9, push(3))
        ]
    );
    assert_eq!((client.errors(), client.stale_replies()), (0, 0));
}

/// A retried request is answered twice (the bridge resends its stored reply); the second
/// answer, arriving while the next request waits, is not taken for that request's reply.
#[test]
fn a_late_reply_to_a_retried_request_is_skipped_by_the_next_request() {
    let mut client = EyeBotClient::with_first_seq(0x10);
    let first = client.encode_request(Message::TimeGet, &mut BytesMut::new());
    client.receive(&bytes_of(first, time(1)));
    assert_eq!(client.take_reply(first), Some(Ok(time(1))));
    let second = client.encode_request(Message::TimeGet, &mut BytesMut::new());
    client.receive(&bytes_of(first, time(1)));
    assert_eq!(
        client.take_reply(second),
        None,
        "the late answer is not the reply"
    );
    client.receive(&bytes_of(second, time(2)));
    assert_eq!(client.take_reply(second), Some(Ok(time(2))));
    assert_eq!(client.stale_replies(), 1);
}

#[test]
fn a_nak_is_the_reply_to_its_seq() {
    let mut client = EyeBotClient::new();
    let nak = Message::Nak {
        rejected_type: 0x41,
        code: ErrorCode::BadState,
        detail: 0,
    };
    client.receive(&bytes_of(3, nak));
    assert_eq!(client.take_reply(3), Some(Ok(nak)));
}

#[test]
fn nmea_and_sonar_items_on_a_shared_line_are_skipped_while_waiting_and_yielded_in_order() {
    let mut select = BytesMut::new();
    let t2 = Transducer::new(2).expect("transducer 2");
    SonarCommand::Ack(t2).encode(&mut select);
    let line = [dbt(), select.to_vec(), bytes_of(4, time(9))].concat();

    let mut waiting = EyeBotClient::new();
    waiting.receive(&line);
    assert_eq!(waiting.take_reply(4), Some(Ok(time(9))));
    assert_eq!(waiting.take_push(), None);

    let mut reading = EyeBotClient::new();
    reading.receive(&line);
    let items: Vec<Incoming> = std::iter::from_fn(|| reading.next_incoming()).collect();
    assert_eq!(
        items,
        [
            Incoming::Nmea(Sentence::Dbt(Dbt::empty(Talker::SOUNDER))),
            Incoming::Sonar(SonarCommand::Ack(t2)),
            Incoming::Reply(Frame::new(4, time(9))),
        ]
    );
}

#[test]
fn an_item_comes_with_the_bytes_it_was_decoded_from() {
    let mut client = EyeBotClient::new();
    let sentence = dbt();
    client.receive(&[sentence.clone(), bytes_of(1, push(4))].concat());
    let (item, bytes) = client.next_incoming_with_bytes().expect("the sentence");
    assert!(matches!(item, Incoming::Nmea(_)), "{item:?}");
    assert_eq!(&bytes[..], &sentence[..]);
    let (item, bytes) = client.next_incoming_with_bytes().expect("the push");
    assert_eq!(item, Incoming::Push(Frame::new(1, push(4))));
    assert_eq!(&bytes[..], &bytes_of(1, push(4))[..]);
    assert_eq!(client.next_incoming_with_bytes(), None);
}

#[test]
fn wire_errors_are_counted_returned_and_decoding_goes_on() {
    let mut client = EyeBotClient::new();
    let mut bad = bytes_of(2, time(1));
    let last = bad.len() - 1;
    bad[last] ^= 0xFF;
    let first = bytes_of(1, time(0));
    client.receive(&[&first[..], &b"zz"[..], &bad, &bytes_of(2, time(3))].concat());
    let mut errors = Vec::new();
    let reply = loop {
        match client.take_reply(2) {
            Some(Ok(message)) => break message,
            Some(Err(error)) => errors.push(error),
            None => panic!("the good frame is found after the bad ones"),
        }
    };
    assert_eq!(reply, time(3));
    assert!(
        matches!(errors[0], LinkError::Skipped { count: 2 }),
        "{errors:?}"
    );
    assert!(
        errors
            .iter()
            .any(|e| matches!(e, LinkError::Frame(FrameError::ChecksumMismatch { .. }))),
        "{errors:?}"
    );
    assert_eq!(client.errors(), errors.len() as u64);
    assert_eq!(client.joined_tail(), 0);
}

/// A client that opens a line in the middle of a message (a sonar line sends sentences all
/// the time) first reads that message's tail: it is counted apart, not as a wire error, and
/// the same bytes after the first whole item are one.
#[test]
fn the_tail_of_a_message_joined_mid_way_is_no_wire_error() {
    let sentence = dbt();
    let tail = &sentence[sentence.len() - 6..];
    let mut client = EyeBotClient::new();
    client.receive(&[tail, &sentence[..], tail].concat());
    let (item, _) = client.next_incoming_with_bytes().expect("the sentence");
    assert!(matches!(item, Incoming::Nmea(_)), "{item:?}");
    assert_eq!(
        (client.joined_tail(), client.errors()),
        (4, 0),
        "CR LF are not counted"
    );
    let mut more = client.clone();
    assert_eq!(
        more.next_incoming_with_bytes(),
        None,
        "a tail still waits for its end"
    );
    client.receive(&sentence);
    assert!(matches!(
        client.next_incoming(),
        Some(Incoming::Error(LinkError::Skipped { count: 4 }))
    ));
    assert!(matches!(client.next_incoming(), Some(Incoming::Nmea(_))));
    assert_eq!((client.joined_tail(), client.errors()), (4, 1));
}

#[test]
fn a_reply_while_waiting_for_a_push_is_stale() {
    let mut client = EyeBotClient::new();
    client.receive(&[bytes_of(1, time(1)), dbt(), bytes_of(5, push(6))].concat());
    assert_eq!(client.take_push(), Some(Ok(Frame::new(5, push(6)))));
    assert_eq!(client.stale_replies(), 1);
}

/// What the bridge may send while a request waits, as the test builds it.
#[derive(Debug, Clone)]
enum Sent {
    Push(i16),
    Stale(u8),
    Nmea,
}

proptest! {
    /// Whatever comes before the reply, in whatever chunks: the reply is the frame with the
    /// request's seq, every push is kept in order, every other reply counted as stale.
    #[test]
    fn the_reply_is_found_among_pushes_stale_replies_and_sentences_at_any_chunking(
        first_seq in any::<u8>(),
        before in prop::collection::vec(
            prop_oneof![
                any::<i16>().prop_map(Sent::Push),
                any::<u8>().prop_map(Sent::Stale),
                Just(Sent::Nmea),
            ],
            0..12,
        ),
        ticks in any::<u32>(),
        chunk in 1usize..40,
    ) {
        let mut client = EyeBotClient::with_first_seq(first_seq);
        let seq = client.encode_request(Message::TimeGet, &mut BytesMut::new());
        let mut line = Vec::new();
        let mut pushes = Vec::new();
        let mut stale = 0;
        for (i, sent) in before.iter().enumerate() {
            match *sent {
                Sent::Push(x) => {
                    let frame = Frame::new(i as u8, push(x));
                    line.extend(bytes_of(frame.seq, frame.message));
                    pushes.push(frame);
                }
                Sent::Stale(other) if other != seq => {
                    line.extend(bytes_of(other, time(0)));
                    stale += 1;
                }
                Sent::Stale(_) => {}
                Sent::Nmea => line.extend(dbt()),
            }
        }
        line.extend(bytes_of(seq, time(ticks)));
        let mut reply = None;
        for piece in line.chunks(chunk) {
            client.receive(piece);
            if let Some(r) = client.take_reply(seq) {
                prop_assert!(reply.is_none());
                reply = Some(r);
            }
        }
        prop_assert_eq!(reply, Some(Ok(time(ticks))));
        let got: Vec<Frame> = std::iter::from_fn(|| client.take_push())
            .map(|p| p.expect("no wire error"))
            .collect();
        prop_assert_eq!(got, pushes);
        prop_assert_eq!((client.stale_replies(), client.errors()), (stale, 0));
    }
}
