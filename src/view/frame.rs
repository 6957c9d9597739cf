//! What the page is sent: one [`Frame`] per update, and the recent past as [`Sample`]s.

use std::collections::BTreeMap;

use serde::Serialize;

use super::wire::Readings;
use crate::daemon::status::LinkStatus;
use crate::record::StateRow;

/// How much of the past the page plots and draws as the track.
pub const HISTORY_S: f64 = 60.0;

/// One point of the plots and the track.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sample {
    pub t_s: f64,
    pub x_m: f64,
    pub y_m: f64,
    pub depth_m: f64,
    pub roll_deg: f64,
    pub pitch_deg: f64,
    /// The true heading, 0-360.
    pub heading_deg: f64,
    /// The heading the compass last reported on the wire.
    pub compass_deg: Option<f64>,
    pub surge_mps: f64,
    /// Port, starboard, bow, stern, after the motor lag.
    pub thrust_n: [f64; 4],
    pub adc: [Option<u16>; 8],
    pub contact: bool,
}

impl Sample {
    pub fn new(row: &StateRow, wire: &Readings) -> Self {
        Self {
            t_s: row.t_s,
            x_m: row.x_m,
            y_m: row.y_m,
            depth_m: row.z_m,
            roll_deg: row.roll_rad.to_degrees(),
            pitch_deg: row.pitch_rad.to_degrees(),
            heading_deg: row.yaw_rad.to_degrees().rem_euclid(360.0),
            compass_deg: wire.compass_deg,
            surge_mps: row.u_mps,
            thrust_n: [
                row.force_port_n,
                row.force_starboard_n,
                row.force_bow_n,
                row.force_stern_n,
            ],
            adc: wire.adc,
            contact: row.contact,
        }
    }
}

/// The run's clock and counters.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StatusView {
    pub sim_time_s: f64,
    pub time_mode: String,
    pub speed: f64,
    pub paused: bool,
    pub overruns: u64,
    pub links: Vec<LinkStatus>,
    /// Link chunks the view missed because it fell behind (live only).
    pub view_dropped: u64,
    /// The water current set from the page (north, east, m/s), if it was.
    pub current_mps: Option<[f64; 2]>,
}

/// Everything the page shows at one moment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Frame<'a> {
    pub sample: &'a Sample,
    pub readings: &'a Readings,
    pub status: &'a StatusView,
}

/// Per-link counts of what crossed, from the wire (a recording has no daemon counters).
pub fn wire_links(readings: &Readings) -> Vec<LinkStatus> {
    let mut links: BTreeMap<&str, LinkStatus> = BTreeMap::new();
    for (name, c) in &readings.links {
        links.insert(
            name,
            LinkStatus {
                name: name.clone(),
                bytes_rx: c.bytes_rx,
                bytes_tx: c.bytes_tx,
                frames_rx: c.messages_rx,
                frames_tx: c.messages_tx,
                errors: c.errors,
                ..LinkStatus::default()
            },
        );
    }
    links.into_values().collect()
}
