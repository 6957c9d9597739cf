//! A `--record` directory read back (`docs/recording.md`): `bytes.tsv`, `state.csv` and
//! `drops.tsv`.

use std::path::Path;

use eyebot_hil::record::{BYTES_HEADER, ByteChunk, DROPS_HEADER, Direction, parse_chunk};

/// A recording read back: every byte chunk and every ground-truth row.
#[derive(Debug)]
pub struct Recording {
    pub chunks: Vec<ByteChunk>,
    pub states: Vec<StateRow>,
}

impl Recording {
    pub fn read(dir: &Path) -> Self {
        Self {
            chunks: read_chunks(dir),
            states: read_states(dir),
        }
    }

    /// Every byte recorded on `link` in direction `dir`, concatenated in order.
    pub fn stream(&self, link: &str, dir: Direction) -> Vec<u8> {
        stream(&self.chunks, link, dir)
    }

    /// The transcript of the byte chunks, see [`transcript`].
    pub fn transcript(&self) -> Vec<TranscriptChunk> {
        transcript(&self.chunks)
    }
}

fn read_text(dir: &Path, name: &str) -> String {
    let path = dir.join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()))
}

/// Every chunk of `bytes.tsv`.
pub fn read_chunks(dir: &Path) -> Vec<ByteChunk> {
    let text = read_text(dir, "bytes.tsv");
    let mut lines = text.lines().enumerate();
    assert_eq!(
        lines.next().map(|l| l.1),
        Some(BYTES_HEADER),
        "bytes.tsv header"
    );
    lines
        .map(|(i, l)| parse_chunk(l, i + 1).unwrap_or_else(|e| panic!("{e}")))
        .collect()
}

/// One row of `drops.tsv`: released bytes that never reached the link's endpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct DropRow {
    pub sim_s: f64,
    pub link: String,
    pub reason: String,
    pub data: Vec<u8>,
}

/// Every row of `drops.tsv`.
pub fn read_drops(dir: &Path) -> Vec<DropRow> {
    let text = read_text(dir, "drops.tsv");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(DROPS_HEADER), "drops.tsv header");
    lines
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 5, "drops.tsv row {l:?}");
            DropRow {
                sim_s: f[0].parse().expect("drops.tsv sim_s"),
                link: f[2].to_string(),
                reason: f[3].to_string(),
                data: hex::decode(f[4]).expect("drops.tsv hex"),
            }
        })
        .collect()
}

/// One row of `state.csv`: the ground truth at `t_s`. `values` holds every column in file
/// order, for comparisons bit for bit.
#[derive(Debug, Clone, PartialEq)]
pub struct StateRow {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub roll_rad: f64,
    pub pitch_rad: f64,
    pub yaw_rad: f64,
    pub contact: bool,
    pub values: Vec<f64>,
}

/// Every row of `state.csv`.
pub fn read_states(dir: &Path) -> Vec<StateRow> {
    let text = read_text(dir, "state.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("state.csv header").split(',').collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("state.csv has no column {name}: {header:?}"))
    };
    let [t, x, y, z, roll, pitch, yaw, contact] = [
        "t_s",
        "x_m",
        "y_m",
        "z_m",
        "roll_rad",
        "pitch_rad",
        "yaw_rad",
        "contact",
    ]
    .map(column);
    lines
        .filter(|l| !l.is_empty())
        .map(|l| {
            let values: Vec<f64> = l
                .split(',')
                .map(|v| {
                    v.parse()
                        .unwrap_or_else(|_| panic!("state.csv value {v:?} in {l:?}"))
                })
                .collect();
            assert_eq!(values.len(), header.len(), "state.csv row {l:?}");
            StateRow {
                t_s: values[t],
                x_m: values[x],
                y_m: values[y],
                z_m: values[z],
                roll_rad: values[roll],
                pitch_rad: values[pitch],
                yaw_rad: values[yaw],
                contact: values[contact] != 0.0,
                values,
            }
        })
        .collect()
}

/// Every byte recorded on `link` in direction `dir`, concatenated in order.
pub fn stream(chunks: &[ByteChunk], link: &str, dir: Direction) -> Vec<u8> {
    chunks
        .iter()
        .filter(|c| c.link == link && c.dir == dir)
        .flat_map(|c| c.data.iter().copied())
        .collect()
}

/// One entry of a [`transcript`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TranscriptChunk {
    /// Simulated time, to the nanosecond.
    pub sim_s: String,
    pub link: String,
    pub dir: Direction,
    pub hex: String,
}

/// The chunks without wall times, link by link (in name order), with adjacent chunks of the
/// same simulated time and direction joined. Two things are not part of the behaviour and
/// are normalised away: how the OS splits a write into reads (a select written byte by byte
/// may be read as one chunk or four), and the order in which the bridge reads two different
/// lines at the same simulated instant.
pub fn transcript(chunks: &[ByteChunk]) -> Vec<TranscriptChunk> {
    let mut links: Vec<&str> = chunks.iter().map(|c| c.link.as_str()).collect();
    links.sort_unstable();
    links.dedup();
    let mut out: Vec<TranscriptChunk> = Vec::new();
    for c in links
        .iter()
        .flat_map(|l| chunks.iter().filter(move |c| c.link == *l))
    {
        let sim_s = format!("{:.9}", c.sim_s);
        match out.last_mut() {
            Some(last) if last.sim_s == sim_s && last.link == c.link && last.dir == c.dir => {
                last.hex.push_str(&hex::encode(&c.data))
            }
            _ => out.push(TranscriptChunk {
                sim_s,
                link: c.link.clone(),
                dir: c.dir,
                hex: hex::encode(&c.data),
            }),
        }
    }
    out
}

/// Where two transcripts first differ, for a failure message.
pub fn first_difference(a: &[TranscriptChunk], b: &[TranscriptChunk]) -> String {
    match a.iter().zip(b).position(|(x, y)| x != y) {
        Some(i) => format!("chunk {i}: {:?} vs {:?}", a[i], b[i]),
        None => format!("lengths {} vs {}", a.len(), b.len()),
    }
}
