//! A `--record` directory read back (`docs/recording.md`) through the recorder's own types
//! and readers in `eyebot_hil::record`.

use std::path::Path;

pub use eyebot_hil::record::{ByteChunk, Direction, DropRow, StateRow};

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

/// Every chunk of `bytes.tsv`.
pub fn read_chunks(dir: &Path) -> Vec<ByteChunk> {
    eyebot_hil::record::read_bytes(dir).unwrap_or_else(|e| panic!("{e}"))
}

/// Every row of `drops.tsv`: released bytes that never reached the link's endpoint.
pub fn read_drops(dir: &Path) -> Vec<DropRow> {
    eyebot_hil::record::read_drops(dir).unwrap_or_else(|e| panic!("{e}"))
}

/// Every row of `state.csv`.
pub fn read_states(dir: &Path) -> Vec<StateRow> {
    eyebot_hil::record::read_state(dir).unwrap_or_else(|e| panic!("{e}"))
}

/// Every number of a state row as its bits, in column order, for comparisons bit for bit
/// (where `==` on `f64` would take `-0.0` for `0.0`).
pub fn state_bits(r: &StateRow) -> [u64; 18] {
    [
        r.t_s,
        r.x_m,
        r.y_m,
        r.z_m,
        r.roll_rad,
        r.pitch_rad,
        r.yaw_rad,
        r.u_mps,
        r.v_mps,
        r.w_mps,
        r.p_radps,
        r.q_radps,
        r.r_radps,
        r.force_port_n,
        r.force_starboard_n,
        r.force_bow_n,
        r.force_stern_n,
        if r.contact { 1.0 } else { 0.0 },
    ]
    .map(f64::to_bits)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn chunk(sim_s: f64, link: &str, dir: Direction, data: &[u8]) -> ByteChunk {
        ByteChunk {
            sim_s,
            wall_unix_s: 0.0,
            link: link.into(),
            dir,
            data: data.to_vec(),
        }
    }

    /// Reads split differently and two lines read in either order at one instant give one
    /// transcript; a byte at another time does not.
    #[test]
    fn transcripts_ignore_read_splits_and_same_instant_line_order() {
        let a = [
            chunk(0.01, "sonar", Direction::Rx, b"@S"),
            chunk(0.01, "sensor", Direction::Rx, &[0xEB]),
            chunk(0.01, "sonar", Direction::Rx, b"1\r"),
            chunk(0.02, "sonar", Direction::Tx, b"@1"),
        ];
        let b = [
            chunk(0.01, "sensor", Direction::Rx, &[0xEB]),
            chunk(0.01, "sonar", Direction::Rx, b"@S1\r"),
            chunk(0.02, "sonar", Direction::Tx, b"@1"),
        ];
        assert_eq!(transcript(&a), transcript(&b));
        assert_eq!(transcript(&a).len(), 3, "{:?}", transcript(&a));
        let later = [
            chunk(0.01, "sensor", Direction::Rx, &[0xEB]),
            chunk(0.01, "sonar", Direction::Rx, b"@S1\r"),
            chunk(0.03, "sonar", Direction::Tx, b"@1"),
        ];
        assert_ne!(transcript(&a), transcript(&later));
        assert!(first_difference(&transcript(&a), &transcript(&later)).starts_with("chunk 2"));
    }
}
