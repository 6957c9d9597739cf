use super::*;
use crate::physics::hdt_command;

const MAKO_TABLE: [f64; 11] = [
    255.0, 206.6, 183.6, 160.7, 137.7, 114.8, 91.8, 68.9, 45.9, 23.0, 0.0,
];

/// Percent -> duty -> percent -> duty gives the same duty for every command the EyeBot
/// can send (the converted commands drive the re-simulation to the same PWM).
#[test]
fn duty_to_percent_inverts_the_hdt_table() {
    for p10 in -1000..=1000 {
        let p = f64::from(p10) / 10.0;
        let c = hdt_command(&MAKO_TABLE, p);
        let dir = match c.direction {
            crate::physics::Direction::Forward => WireDirection::Forward,
            crate::physics::Direction::Reverse => WireDirection::Reverse,
        };
        let back = percent_from_duty(&MAKO_TABLE, c.duty, dir);
        let again = hdt_command(&MAKO_TABLE, back);
        assert_eq!(again.duty, c.duty, "{p} % -> duty {} -> {back} %", c.duty);
    }
    assert_eq!(
        percent_from_duty(&MAKO_TABLE, 0, WireDirection::Forward),
        100.0
    );
    assert_eq!(
        percent_from_duty(&MAKO_TABLE, 255, WireDirection::Reverse),
        -0.0
    );
}

/// A recording made by an earlier version (format 1: the configuration as comments in
/// `meta.toml`) converts, with the model files its configuration named.
#[test]
fn a_format_1_recording_converts() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("pty-tests/fixtures/recording-format-1");
    let conv = convert(&dir, &ConvertOptions::default()).unwrap();
    let names: Vec<&str> = conv
        .measurement
        .channels
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    assert!(names.contains(&"compass_deg"), "{names:?}");
    assert!(names.contains(&"depth_adc"), "{names:?}");
}

#[test]
fn paddle_speed_counts_rising_edges_per_window() {
    let sensors = SensorsConfig::load(&crate::config::Embedded, "sensors/mako-2008.toml").unwrap();
    let lsb = AdcBoard::new(&sensors.adc, 0).lsb_v();
    let high = sensors.velocity.high_v.min(sensors.adc.reference_v) / lsb;
    // 4 pulses per second sampled every 10 ms for 3 s.
    let codes: Vec<(f64, f64)> = (0..300)
        .map(|k| {
            let t = f64::from(k) * 0.01;
            (t, if (t * 4.0).fract() < 0.5 { high } else { 0.0 })
        })
        .collect();
    let v = paddle_speed(&codes, &sensors).unwrap();
    let step = sensors.velocity.firmware_scale
        / (sensors.velocity.pulses_per_metre * sensors.velocity.window_s);
    assert!(v.len() >= 2, "{v:?}");
    for (_, s) in &v[1..] {
        assert!((s - 4.0 * step).abs() < 1e-9, "{v:?}");
    }
}

mod recording {
    use super::*;
    use bytes::BytesMut;
    use firmware_protocol::sensor_link::{
        AdcChannel, AdcValue, CompassMode, CompassOutput, Frame, Message, Thruster, ThrusterCommand,
    };
    use firmware_protocol::{
        Dbt, EchoReport, HeadingFormat, HeadingWord, Sentence, Talker, Transducer,
    };

    fn frame(m: Message) -> Vec<u8> {
        let mut b = BytesMut::new();
        Frame::new(1, m).encode(&mut b);
        b.to_vec()
    }

    fn sentence(s: Sentence) -> Vec<u8> {
        let mut b = BytesMut::new();
        s.encode(&mut b).unwrap();
        b.to_vec()
    }

    fn row(sim: f64, link: &str, dir: &str, bytes: &[u8]) -> String {
        format!(
            "{sim:.9}\t0.000000\t{link}\t{dir}\t{}\n",
            hex::encode(bytes)
        )
    }

    fn wire(percent: f64) -> ThrusterCommand {
        let c = crate::physics::hdt_command(&MAKO_TABLE, percent);
        ThrusterCommand {
            duty: c.duty,
            direction: match c.direction {
                crate::physics::Direction::Forward => WireDirection::Forward,
                crate::physics::Direction::Reverse => WireDirection::Reverse,
            },
        }
    }

    fn write(dir: &Path, bytes: &str) {
        std::fs::create_dir_all(dir).unwrap();
        let meta = record::Meta::new(1, "lockstep", 1.0, "test");
        std::fs::write(dir.join("meta.toml"), toml::to_string(&meta).unwrap()).unwrap();
        std::fs::write(
            dir.join("config.toml"),
            "vehicle = \"vehicles/mako.toml\"\nworld = \"worlds/pool.toml\"\n\
                 sensors = \"sensors/mako-2008.toml\"\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("bytes.tsv"),
            format!("{}\n{bytes}", record::BYTES_HEADER),
        )
        .unwrap();
        std::fs::write(
                dir.join("state.csv"),
                format!(
                    "{}\n0,1,2,0.3,0,0,0.5,0.1,0,0,0,0,0,0,0,0,0,0\n3,1.3,2,0.3,0,0,0.5,0.1,0,0,0,0,0,0,0,0,0,0\n",
                    record::STATE_HEADER
                ),
            )
            .unwrap();
    }

    /// Thrusters and readings inside TIME_STEP and STEP (PROTOCOL.md 2.9): thrusters at the
    /// request's time; value i of a STEP is the request's reading i at the reply's tick;
    /// only values the EyeBot used count (the next TIME_STEP's `used`, or all of them when
    /// another request follows), and a last reply nobody answered counts for nothing.
    #[test]
    fn time_step_thrusters_and_step_values_convert() {
        use firmware_protocol::sensor_link::{Reading, Readings, StepValues};
        let scratch = crate::scratch::dir("gap-convert-step");
        let dir = scratch.path().join("rec");
        let seq_frame = |seq: u8, m: Message| {
            let mut b = BytesMut::new();
            Frame::new(seq, m).encode(&mut b);
            b.to_vec()
        };
        let time_step = |seq: u8, used: u8, thrusters, codes: &[Reading]| {
            seq_frame(
                seq,
                Message::TimeStep {
                    used,
                    stop_on_sonar: false,
                    ticks: 10,
                    thrusters,
                    readings: Readings::new(codes.iter().copied()).unwrap(),
                },
            )
        };
        let step = |seq: u8, ticks: u32, values: &[u16]| {
            seq_frame(
                seq,
                Message::Step {
                    ticks,
                    sonar_bytes: 0,
                    values: StepValues::new(values.iter().copied()).unwrap(),
                },
            )
        };
        let adc = |c: u8| Reading::Adc(AdcChannel::new(c).unwrap());
        let north = HeadingWord::encode(90, HeadingFormat::Binary).unwrap().0;
        let mut bytes = String::new();
        bytes += &row(
            0.0,
            "sensor",
            "rx",
            &frame(Message::Hello { client_version: 1 }),
        );
        let ahead = Some([wire(50.0), wire(50.0), wire(0.0), wire(0.0)]);
        bytes += &row(
            1.0,
            "sensor",
            "rx",
            &time_step(2, 0, ahead, &[adc(0), Reading::Compass, adc(2)]),
        );
        bytes += &row(1.1, "sensor", "tx", &step(2, 110, &[200, north, 512]));
        // Depth and compass used, channel 2 taken back; then the same request again (a
        // retry, answered from the bridge's store).
        let next = time_step(3, 2, None, &[adc(0), adc(2)]);
        bytes += &row(1.1, "sensor", "rx", &next);
        bytes += &row(1.1, "sensor", "rx", &next);
        bytes += &row(1.2, "sensor", "tx", &step(3, 120, &[210, 520]));
        bytes += &row(1.2, "sensor", "tx", &step(3, 120, &[210, 520]));
        // Another request: every value of the last STEP was used.
        bytes += &row(
            1.2,
            "sensor",
            "rx",
            &seq_frame(
                4,
                Message::ThrusterSet {
                    thruster: Thruster::Stern,
                    command: wire(-30.0),
                },
            ),
        );
        bytes += &row(1.2, "sensor", "rx", &time_step(5, 0, None, &[adc(0)]));
        bytes += &row(1.3, "sensor", "tx", &step(5, 130, &[220]));
        let back = Some([wire(-20.0), wire(-20.0), wire(0.0), wire(-30.0)]);
        bytes += &row(1.3, "sensor", "rx", &time_step(6, 1, back, &[adc(0)]));
        // The recording ends before the EyeBot says whether it used this one.
        bytes += &row(1.4, "sensor", "tx", &step(6, 140, &[230]));
        write(&dir, &bytes);
        let c = convert(&dir, &ConvertOptions::default()).unwrap();
        let m = &c.measurement;
        let ch = |n: &str| m.channel(n).map(|c| c.samples.clone()).unwrap_or_default();
        assert_eq!(
            ch("depth_adc"),
            vec![(1.1, 200.0), (1.2, 210.0), (1.3, 220.0)]
        );
        assert_eq!(ch("compass_deg"), vec![(1.1, 90.0)]);
        assert_eq!(ch("accel_x_adc"), vec![(1.2, 520.0)], "512 was taken back");
        let times: Vec<f64> = m.commands.iter().map(|c| c.t_s).collect();
        assert_eq!(times, vec![0.0, 1.0, 1.2, 1.3], "{:?}", m.commands);
        let near = |a: f64, b: f64| (a - b).abs() < 0.5;
        let [p, s, b, st] = m.commands[1].percent;
        assert!(near(p, 50.0) && near(s, 50.0) && b == 0.0 && st == 0.0);
        assert!(near(m.commands[2].percent[3], -30.0), "{:?}", m.commands);
        let [p, s, _, st] = m.commands[3].percent;
        assert!(near(p, -20.0) && near(s, -20.0) && near(st, -30.0));
        assert!(
            c.notices
                .iter()
                .any(|n| n.starts_with("2 values of STEP replies left out")),
            "{:?}",
            c.notices
        );
    }

    /// Every decoded path of a hand-made recording: HELLO, COMPASS_MODE (BCD), both thruster
    /// frames, ADC values by the analog table, a compass word split across two chunks, an
    /// echo report and an unattributable DBT.
    #[test]
    fn a_hand_made_recording_converts_channel_by_channel() {
        let scratch = crate::scratch::dir("gap-convert");
        let dir = scratch.path().join("rec");
        let heading = frame(Message::CompassHeading {
            word: HeadingWord::encode(124, HeadingFormat::Bcd).unwrap(),
        });
        let mut bytes = String::new();
        bytes += &row(
            0.0,
            "sensor",
            "rx",
            &frame(Message::Hello { client_version: 1 }),
        );
        bytes += &row(
            0.5,
            "sensor",
            "rx",
            &frame(Message::CompassMode {
                mode: CompassMode::Poll,
                output: CompassOutput::Bcd,
            }),
        );
        bytes += &row(
            1.0,
            "sensor",
            "rx",
            &frame(Message::ThrusterSetAll {
                commands: [wire(50.0), wire(50.0), wire(0.0), wire(0.0)],
            }),
        );
        bytes += &row(
            1.2,
            "sensor",
            "tx",
            &frame(Message::CompassHeading {
                word: HeadingWord::encode(123, HeadingFormat::Bcd).unwrap(),
            }),
        );
        let adc = |c: u8, v: u16| {
            frame(Message::AdcValue {
                channel: AdcChannel::new(c).unwrap(),
                value: AdcValue::new(v).unwrap(),
            })
        };
        bytes += &row(1.3, "sensor", "tx", &[adc(0, 200), adc(2, 512)].concat());
        let t2 = Transducer::new(2).unwrap();
        bytes += &row(
            1.4,
            "sonar",
            "tx",
            &[
                sentence(Sentence::Dbt(
                    Dbt::from_depth_m(Talker::new("SD").unwrap(), 3.2).unwrap(),
                )),
                sentence(Sentence::Echo(EchoReport::new(t2, Some(3.2), 87).unwrap())),
            ]
            .concat(),
        );
        bytes += &row(1.5, "sensor", "tx", &heading[..4]);
        bytes += &row(1.6, "sensor", "tx", &heading[4..]);
        bytes += &row(
            2.0,
            "sensor",
            "rx",
            &frame(Message::ThrusterSet {
                thruster: Thruster::Stern,
                command: wire(-30.0),
            }),
        );
        write(&dir, &bytes);
        let c = convert(&dir, &ConvertOptions::default()).unwrap();
        let m = &c.measurement;
        let ch = |n: &str| m.channel(n).map(|c| c.samples.clone()).unwrap_or_default();
        assert_eq!(ch("compass_deg"), vec![(1.2, 123.0), (1.6, 124.0)]);
        assert_eq!(ch("depth_adc"), vec![(1.3, 200.0)]);
        assert_eq!(ch("accel_x_adc"), vec![(1.3, 512.0)]);
        assert_eq!(ch("sonar2_m"), vec![(1.4, 3.2)]);
        assert!(m.channel("x_m").is_none(), "no camera track unless asked");
        assert_eq!(m.commands.len(), 3, "{:?}", m.commands);
        assert_eq!(m.commands[0].percent, [0.0; 4]);
        assert_eq!(m.commands[1].t_s, 1.0);
        assert!(
            (m.commands[1].percent[0] - 50.0).abs() < 0.5,
            "{:?}",
            m.commands
        );
        assert_eq!(m.commands[2].t_s, 2.0);
        assert!(
            (m.commands[2].percent[3] + 30.0).abs() < 0.5,
            "{:?}",
            m.commands
        );
        assert!((m.experiment.initial.heading_deg - 0.5f64.to_degrees()).abs() < 1e-9);
        assert_eq!(m.experiment.initial.z_m, Some(0.3));
        assert_eq!(m.experiment.duration_s, 3.0);
        assert!(
            c.notices
                .iter()
                .any(|n| n.starts_with("1 sonar depth sentences")),
            "{:?}",
            c.notices
        );

        // With a camera track: ground truth plus noise, never exactly ground truth.
        let opts = ConvertOptions {
            camera_std_m: Some(0.01),
            seed: 3,
            ..Default::default()
        };
        let c = convert(&dir, &opts).unwrap();
        let x = c.measurement.channel("x_m").unwrap();
        assert!(
            x.samples.iter().all(|(_, v)| *v != 1.0 && *v != 1.3),
            "{:?}",
            x.samples
        );
        assert_eq!(c.measurement.experiment.camera_position_std_m, 0.01);

        // A malformed line is an error naming the file and the line, not a panic.
        write(&dir, &format!("{bytes}0.5\tbad\n"));
        let err = convert(&dir, &ConvertOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("bytes.tsv line 11: 2 fields, expected 5"),
            "{err}"
        );
    }
    /// A program that reads the compass faster than it converts gets its last conversion
    /// again: each run of equal readings is one measurement, at its first read.
    #[test]
    fn repeated_compass_readings_are_one_conversion_at_its_first_read() {
        let scratch = crate::scratch::dir("gap-convert");
        let dir = scratch.path().join("rec");
        let heading = |deg: u16| {
            frame(Message::CompassHeading {
                word: HeadingWord::encode(deg, HeadingFormat::Binary).unwrap(),
            })
        };
        let mut bytes = row(
            0.0,
            "sensor",
            "rx",
            &frame(Message::Hello { client_version: 1 }),
        );
        for (t, deg) in [
            (1.2, 123),
            (1.21, 123),
            (1.22, 123),
            (1.6, 125),
            (1.61, 125),
            (2.0, 123),
        ] {
            bytes += &row(t, "sensor", "tx", &heading(deg));
        }
        write(&dir, &bytes);
        let c = convert(&dir, &ConvertOptions::default()).unwrap();
        let compass = c.measurement.channel("compass_deg").unwrap();
        assert_eq!(
            compass.samples,
            vec![(1.2, 123.0), (1.6, 125.0), (2.0, 123.0)]
        );
        assert!(
            c.notices
                .iter()
                .any(|n| n.starts_with("3 compass readings repeated")),
            "{:?}",
            c.notices
        );
    }
}
