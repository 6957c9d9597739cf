//! The run or the recording for Foxglove: the same state rows and decoded link messages the
//! page shows, as channels of Foxglove's built-in schemas, for its WebSocket server (`run
//! --foxglove`) and its MCAP writer (`export --mcap`). One [`Channels`] builds the messages
//! for both.
//!
//! Frames: `pool` is the world frame of the simulation (NED: x north, y east, z down, metres,
//! origin at the pool's corner); `world` is the same place with z up (x east, y north), so
//! Foxglove's 3D panel shows the pool the right way up; `vehicle` is the body frame (x
//! forward, y starboard, z down).
//!
//! Channels (every message's log time is simulated time, in nanoseconds):
//! - `/scene` `foxglove.SceneUpdate`: the pool, its obstacles and the hull (locked to
//!   `vehicle`), first and then once per simulated second (and live, when a client
//!   subscribes);
//! - `/tf_static` `foxglove.FrameTransform` `world` to `pool`, with each `/scene`;
//! - `/tf` `foxglove.FrameTransform` `pool` to `vehicle`: the pose, one per state update;
//! - `/sonar` `foxglove.SceneUpdate`: each transducer's beam cone, as long as its latest echo
//!   (or, grey, as the sonar's range when it has none) with a sphere at the echo, one per
//!   state update;
//! - `/sensors` JSON: depth, attitude, the compass heading on the wire, surge speed, the ADC
//!   channels and the echoes, one per state update;
//! - `/thrusters` JSON: the four thrust forces and the duty bytes the EyeBot last sent, one
//!   per state update;
//! - `/links` `foxglove.Log`: every decoded link message, at its time.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use foxglove::messages::{
    Color, CubePrimitive, CylinderPrimitive, FrameTransform, Log, Pose, Quaternion, SceneEntity,
    SceneUpdate, SpherePrimitive, Timestamp, Vector3, log,
};
use foxglove::{Channel, ChannelBuilder, Context, RawChannel, Schema};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};
use serde::Serialize;

use super::frame::Sample;
use super::scene::{Scene, SceneObstacle};
use super::wire::{LinkMessage, Readings};
use crate::daemon::observer::Watchers;

/// The topics, in the order they are created.
pub const TOPICS: [&str; 7] = [
    "/scene",
    "/tf_static",
    "/tf",
    "/sonar",
    "/sensors",
    "/thrusters",
    "/links",
];

/// An echo older than this is drawn as "no echo" (as the page does).
const ECHO_FRESH_S: f64 = 3.0;

/// The channels of one context, and what they need to build messages.
pub struct Channels {
    scene: Channel<SceneUpdate>,
    tf_static: Channel<FrameTransform>,
    tf: Channel<FrameTransform>,
    sonar: Channel<SceneUpdate>,
    sensors: Arc<RawChannel>,
    thrusters: Arc<RawChannel>,
    links: Channel<Log>,
    layout: Scene,
    /// The simulated second of the last `/scene` (`None`: not sent yet).
    scene_second: Option<i64>,
    /// Send `/scene` with the next state update (a client has just subscribed).
    resend_scene: Arc<AtomicBool>,
}

/// `/sensors`: what the vehicle's sensors and the wire say.
#[derive(Debug, Serialize)]
struct SensorsMessage<'a> {
    t_s: f64,
    depth_m: f64,
    roll_deg: f64,
    pitch_deg: f64,
    heading_deg: f64,
    /// The heading the compass last reported on the wire.
    compass_deg: Option<f64>,
    surge_mps: f64,
    adc: &'a [Option<u16>; 8],
    /// Per transducer: the latest echo's range; `None` for "no echo" or no reading yet.
    echo_m: [Option<f64>; 4],
    contact: bool,
}

/// `/thrusters`: the forces (after the motor lag) and the commands the EyeBot sent.
#[derive(Debug, Serialize)]
struct ThrustersMessage {
    t_s: f64,
    /// Port, starboard, bow, stern.
    thrust_n: [f64; 4],
    /// The PWM duty bytes on the wire (255 is off); `None` until the EyeBot sent one.
    duty: [Option<u8>; 4],
    reverse: [Option<bool>; 4],
}

const SENSORS_SCHEMA: &str = r#"{"title":"eyebot.Sensors","type":"object","properties":{
"t_s":{"type":"number","description":"simulated time, s"},
"depth_m":{"type":"number"},"roll_deg":{"type":"number"},"pitch_deg":{"type":"number"},
"heading_deg":{"type":"number","description":"true heading, 0-360"},
"compass_deg":{"type":["number","null"],"description":"the compass heading last answered on the wire"},
"surge_mps":{"type":"number"},
"adc":{"type":"array","items":{"type":["integer","null"]},"description":"ADC channels 0-7 as last answered"},
"echo_m":{"type":"array","items":{"type":["number","null"]},"description":"transducers 1-4: latest echo range, null for no echo"},
"contact":{"type":"boolean"}}}"#;

const THRUSTERS_SCHEMA: &str = r#"{"title":"eyebot.Thrusters","type":"object","properties":{
"t_s":{"type":"number","description":"simulated time, s"},
"thrust_n":{"type":"array","items":{"type":"number"},"description":"port, starboard, bow, stern, after the motor lag"},
"duty":{"type":"array","items":{"type":["integer","null"]},"description":"PWM duty bytes the EyeBot last sent (255 is off)"},
"reverse":{"type":"array","items":{"type":["boolean","null"]}}}}"#;

/// Simulated seconds as Foxglove nanoseconds (times before 0 are 0).
pub fn nanos(t_s: f64) -> u64 {
    (t_s.max(0.0) * 1e9).round() as u64
}

fn stamp(t_s: f64) -> Option<Timestamp> {
    let ns = nanos(t_s);
    Some(Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    ))
}

fn v3(v: [f64; 3]) -> Option<Vector3> {
    Some(Vector3 {
        x: v[0],
        y: v[1],
        z: v[2],
    })
}

fn quat(q: &UnitQuaternion<f64>) -> Option<Quaternion> {
    Some(Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    })
}

fn pose(position: [f64; 3], orientation: &UnitQuaternion<f64>) -> Option<Pose> {
    Some(Pose {
        position: v3(position),
        orientation: quat(orientation),
    })
}

fn rgba(r: f64, g: f64, b: f64, a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

/// `world` (z up, x east, y north) to `pool` (NED).
pub fn world_to_pool() -> UnitQuaternion<f64> {
    let m = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// The vehicle's attitude in the pool frame (roll, pitch, yaw about NED axes).
pub fn attitude(sample: &Sample) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(
        sample.roll_deg.to_radians(),
        sample.pitch_deg.to_radians(),
        sample.heading_deg.to_radians(),
    )
}

/// A transducer's beam axis in the body frame (azimuth about z down, so + is to starboard;
/// elevation + up), as the sonar model has it.
fn beam_axis(azimuth_deg: f64, elevation_deg: f64) -> nalgebra::Vector3<f64> {
    let rot = Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), azimuth_deg.to_radians())
        * Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), elevation_deg.to_radians());
    rot * nalgebra::Vector3::x()
}

impl Channels {
    /// Creates the channels in `ctx` (before any sink is added, so every sink sees them all).
    pub fn new(ctx: &Arc<Context>, layout: Scene) -> Result<Self, foxglove::FoxgloveError> {
        let json = |topic: &str, name: &str, schema: &'static str| {
            ChannelBuilder::new(topic)
                .context(ctx)
                .message_encoding("json")
                .schema(Schema::new(name, "jsonschema", schema.as_bytes()))
                .build_raw()
        };
        Ok(Self {
            scene: ChannelBuilder::new(TOPICS[0]).context(ctx).build(),
            tf_static: ChannelBuilder::new(TOPICS[1]).context(ctx).build(),
            tf: ChannelBuilder::new(TOPICS[2]).context(ctx).build(),
            sonar: ChannelBuilder::new(TOPICS[3]).context(ctx).build(),
            sensors: json(TOPICS[4], "eyebot.Sensors", SENSORS_SCHEMA)?,
            thrusters: json(TOPICS[5], "eyebot.Thrusters", THRUSTERS_SCHEMA)?,
            links: ChannelBuilder::new(TOPICS[6]).context(ctx).build(),
            layout,
            scene_second: None,
            resend_scene: Arc::new(AtomicBool::new(false)),
        })
    }

    /// Set to have `/scene` sent again with the next state update.
    pub fn resend_scene_flag(&self) -> Arc<AtomicBool> {
        self.resend_scene.clone()
    }

    /// One decoded link message, as a log line at its time.
    pub fn message(&self, m: &LinkMessage) {
        let level = if m.kind == "Error" {
            log::Level::Error
        } else {
            log::Level::Info
        };
        let line = Log {
            timestamp: stamp(m.t_s),
            level: level as i32,
            message: m.text.clone(),
            name: format!("{} {} {}", m.link, m.dir, m.kind),
            file: String::new(),
            line: 0,
        };
        self.links.log_with_time(&line, nanos(m.t_s));
    }

    /// One state update: the pose, the sonar, the sensors and thrusters (and the scene when
    /// it is due).
    pub fn state(&mut self, sample: &Sample, readings: &Readings) {
        let t = sample.t_s;
        let ns = nanos(t);
        let second = t.floor() as i64;
        let resend = self.resend_scene.swap(false, Ordering::Relaxed);
        if resend || self.scene_second.is_none_or(|s| second > s) {
            self.scene_second = Some(second);
            self.tf_static.log_with_time(
                &FrameTransform {
                    timestamp: stamp(t),
                    parent_frame_id: "world".into(),
                    child_frame_id: "pool".into(),
                    translation: v3([0.0; 3]),
                    rotation: quat(&world_to_pool()),
                },
                ns,
            );
            if self.scene.has_sinks() {
                self.scene.log_with_time(&self.scene_update(t), ns);
            }
        }
        self.tf.log_with_time(
            &FrameTransform {
                timestamp: stamp(t),
                parent_frame_id: "pool".into(),
                child_frame_id: "vehicle".into(),
                translation: v3([sample.x_m, sample.y_m, sample.depth_m]),
                rotation: quat(&attitude(sample)),
            },
            ns,
        );
        // What no client subscribed to is not built (live, with nobody watching, that is
        // everything).
        if self.sonar.has_sinks() {
            self.sonar
                .log_with_time(&self.sonar_update(t, readings), ns);
        }
        if !self.sensors.has_sinks() && !self.thrusters.has_sinks() {
            return;
        }
        let echo_m = readings.echoes.map(|e| {
            e.filter(|e| t - e.t_s < ECHO_FRESH_S)
                .and_then(|e| e.range_m)
        });
        let sensors = SensorsMessage {
            t_s: t,
            depth_m: sample.depth_m,
            roll_deg: sample.roll_deg,
            pitch_deg: sample.pitch_deg,
            heading_deg: sample.heading_deg,
            compass_deg: sample.compass_deg,
            surge_mps: sample.surge_mps,
            adc: &sample.adc,
            echo_m,
            contact: sample.contact,
        };
        let thrusters = ThrustersMessage {
            t_s: t,
            thrust_n: sample.thrust_n,
            duty: readings.thrusters.map(|c| c.map(|c| c.duty)),
            reverse: readings.thrusters.map(|c| c.map(|c| c.reverse)),
        };
        let meta = foxglove::PartialMetadata::with_log_time(ns);
        match serde_json::to_vec(&sensors) {
            Ok(json) => self.sensors.log_with_meta(&json, meta),
            Err(e) => tracing::error!(error = %e, "cannot serialise /sensors"),
        }
        match serde_json::to_vec(&thrusters) {
            Ok(json) => self.thrusters.log_with_meta(&json, meta),
            Err(e) => tracing::error!(error = %e, "cannot serialise /thrusters"),
        }
    }

    /// The pool's walls and floor, the obstacles and the hull.
    fn scene_update(&self, t: f64) -> SceneUpdate {
        let l = &self.layout;
        let [north, east, depth] = l.pool_m;
        let level = UnitQuaternion::identity();
        let water = rgba(0.25, 0.55, 0.85, 0.12);
        let wall = rgba(0.6, 0.65, 0.7, 0.35);
        let thin = 0.02;
        let mut pool = entity(t, "pool", "pool", false);
        // The water volume, the floor and the four walls.
        pool.cubes.push(CubePrimitive {
            pose: pose([north / 2.0, east / 2.0, depth / 2.0], &level),
            size: v3([north, east, depth]),
            color: water,
        });
        for (centre, size) in [
            ([north / 2.0, east / 2.0, depth], [north, east, thin]),
            ([0.0, east / 2.0, depth / 2.0], [thin, east, depth]),
            ([north, east / 2.0, depth / 2.0], [thin, east, depth]),
            ([north / 2.0, 0.0, depth / 2.0], [north, thin, depth]),
            ([north / 2.0, east, depth / 2.0], [north, thin, depth]),
        ] {
            pool.cubes.push(CubePrimitive {
                pose: pose(centre, &level),
                size: v3(size),
                color: wall,
            });
        }
        let obstacle = rgba(0.55, 0.42, 0.3, 0.9);
        for o in &l.obstacles {
            match o {
                SceneObstacle::Box {
                    centre_m,
                    half_extents_m,
                    yaw_deg,
                } => pool.cubes.push(CubePrimitive {
                    pose: pose(
                        *centre_m,
                        &UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians()),
                    ),
                    size: v3(half_extents_m.map(|h| 2.0 * h)),
                    color: obstacle,
                }),
                SceneObstacle::Cylinder { centre_m, radius_m } => {
                    pool.cylinders.push(CylinderPrimitive {
                        pose: pose([centre_m[0], centre_m[1], depth / 2.0], &level),
                        size: v3([2.0 * radius_m, 2.0 * radius_m, depth]),
                        bottom_scale: 1.0,
                        top_scale: 1.0,
                        color: obstacle,
                    })
                }
            }
        }
        let mut hull = entity(t, "vehicle", "hull", true);
        hull.cubes.push(CubePrimitive {
            pose: pose([0.0; 3], &level),
            size: v3(l.hull_half_m.map(|h| 2.0 * h)),
            color: rgba(1.0, 0.79, 0.16, 1.0),
        });
        SceneUpdate {
            deletions: Vec::new(),
            entities: vec![pool, hull],
        }
    }

    /// Each transducer's beam as a cone from it along its axis, and its echo.
    fn sonar_update(&self, t: f64, readings: &Readings) -> SceneUpdate {
        let l = &self.layout;
        let half = (l.beam_width_deg / 2.0).to_radians();
        let entities = l
            .transducers
            .iter()
            .map(|tr| {
                let echo = usize::from(tr.id)
                    .checked_sub(1)
                    .and_then(|i| readings.echoes.get(i).copied().flatten())
                    .filter(|e| t - e.t_s < ECHO_FRESH_S);
                let range = echo.and_then(|e| e.range_m);
                let selected = readings.selected == Some(tr.id);
                let length = range.unwrap_or(l.max_range_m).max(0.05);
                let axis = beam_axis(tr.azimuth_deg, tr.elevation_deg);
                // The cylinder's z axis along the beam: its bottom face (the apex) at the
                // transducer.
                let turn = UnitQuaternion::rotation_between(&nalgebra::Vector3::z(), &axis)
                    .unwrap_or_else(|| {
                        UnitQuaternion::from_axis_angle(
                            &nalgebra::Vector3::x_axis(),
                            std::f64::consts::PI,
                        )
                    });
                let p = nalgebra::Vector3::from(tr.position_body_m);
                let mid = p + axis * (length / 2.0);
                let width = 2.0 * length * half.tan();
                let alpha = if selected { 0.45 } else { 0.2 };
                let color = match range {
                    Some(_) => rgba(1.0, 0.92, 0.23, alpha),
                    None => rgba(0.7, 0.7, 0.7, alpha / 2.0),
                };
                let mut e = entity(t, "vehicle", &format!("transducer {}", tr.id), true);
                e.cylinders.push(CylinderPrimitive {
                    pose: pose([mid.x, mid.y, mid.z], &turn),
                    size: v3([width, width, length]),
                    bottom_scale: 0.0,
                    top_scale: 1.0,
                    color,
                });
                if let Some(r) = range {
                    let at = p + axis * r;
                    e.spheres.push(SpherePrimitive {
                        pose: pose([at.x, at.y, at.z], &UnitQuaternion::identity()),
                        size: v3([0.15; 3]),
                        color: rgba(1.0, 0.35, 0.2, 1.0),
                    });
                }
                e.metadata.push(foxglove::messages::KeyValuePair {
                    key: "echo".into(),
                    value: match (echo, range) {
                        (None, _) => "no reading".into(),
                        (Some(_), None) => "no echo".into(),
                        (Some(_), Some(r)) => format!("{r:.1} m"),
                    },
                });
                e
            })
            .collect();
        SceneUpdate {
            deletions: Vec::new(),
            entities,
        }
    }
}

fn entity(t: f64, frame: &str, id: &str, frame_locked: bool) -> SceneEntity {
    SceneEntity {
        timestamp: stamp(t),
        frame_id: frame.into(),
        id: id.into(),
        frame_locked,
        ..SceneEntity::default()
    }
}

/// Counts Foxglove clients as watchers and has the scene sent again when one subscribes.
struct Listener {
    watchers: Watchers,
    resend_scene: Arc<AtomicBool>,
}

impl foxglove::websocket::ServerListener for Listener {
    fn on_client_connect(&self) {
        self.watchers.join();
    }

    fn on_client_disconnect(&self) {
        self.watchers.leave();
    }

    fn on_subscribe(
        &self,
        _client: foxglove::websocket::Client,
        channel: foxglove::websocket::ChannelView<'_>,
    ) {
        if channel.topic() == TOPICS[0] || channel.topic() == TOPICS[1] {
            self.resend_scene.store(true, Ordering::Relaxed);
        }
    }
}

/// A running Foxglove WebSocket server with its channels.
pub struct LiveFoxglove {
    pub channels: Channels,
    server: foxglove::WebSocketServerHandle,
    _context: Arc<Context>,
}

impl std::fmt::Debug for LiveFoxglove {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveFoxglove")
            .field("port", &self.server.port())
            .finish_non_exhaustive()
    }
}

/// Why Foxglove could not be served or written.
#[derive(Debug, thiserror::Error)]
pub enum FoxgloveError {
    #[error(
        "foxglove address {addr}: not a loopback address; pass --foxglove-public to publish the run to the network"
    )]
    NotLoopback { addr: std::net::SocketAddr },
    #[error("foxglove address {addr}: {source}")]
    Serve {
        addr: std::net::SocketAddr,
        #[source]
        source: foxglove::FoxgloveError,
    },
    #[error("cannot write MCAP file {}: {source}", path.display())]
    Mcap {
        path: std::path::PathBuf,
        #[source]
        source: foxglove::FoxgloveError,
    },
}

impl LiveFoxglove {
    /// Starts a Foxglove WebSocket server on `addr` (on the current tokio runtime); clients
    /// count as `watchers`.
    pub async fn start(
        addr: std::net::SocketAddr,
        public: bool,
        layout: Scene,
        watchers: Watchers,
    ) -> Result<Self, FoxgloveError> {
        if !addr.ip().is_loopback() && !public {
            return Err(FoxgloveError::NotLoopback { addr });
        }
        let context = Context::new();
        let channels = Channels::new(&context, layout)
            .map_err(|source| FoxgloveError::Serve { addr, source })?;
        let listener = Listener {
            watchers,
            resend_scene: channels.resend_scene_flag(),
        };
        let host = match addr.ip() {
            std::net::IpAddr::V6(ip) => format!("[{ip}]"),
            std::net::IpAddr::V4(ip) => ip.to_string(),
        };
        let server = context
            .websocket_server()
            .name("eyebot-hil")
            .bind(host, addr.port())
            .capabilities([foxglove::websocket::Capability::Time])
            .listener(Arc::new(listener))
            .start()
            .await
            .map_err(|source| FoxgloveError::Serve { addr, source })?;
        if public {
            tracing::warn!(
                %addr,
                "Foxglove is served beyond this machine: anyone who can reach the port can watch the run"
            );
        }
        Ok(Self {
            channels,
            server,
            _context: context,
        })
    }

    /// The address to give Foxglove (`ws://HOST:PORT`).
    pub fn url(&self, addr: std::net::SocketAddr) -> String {
        let host = match addr.ip() {
            std::net::IpAddr::V6(ip) => format!("[{ip}]"),
            std::net::IpAddr::V4(ip) => ip.to_string(),
        };
        format!("ws://{host}:{}", self.server.port())
    }

    /// Tells the clients the simulated time (they play the channels against it).
    pub fn time(&self, t_s: f64) {
        self.server.broadcast_time(nanos(t_s));
    }

    /// Stops the server (its clients are disconnected).
    pub async fn stop(self) {
        self.server.stop().wait().await;
    }
}

/// What an export wrote.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Exported {
    pub states: usize,
    pub messages: usize,
    pub scenes: usize,
}

/// Writes the recording in `dir` as MCAP to `path` (replaced if it exists): every state row
/// and every decoded link message, in time order, through the same [`Channels`] as a live
/// run.
pub fn export_mcap(
    dir: &std::path::Path,
    path: &std::path::Path,
) -> Result<Exported, super::ViewError> {
    let recording = super::recording::RecordingView::load(dir)?;
    let files = crate::record::read_model_files(dir)?;
    let layout = super::recording_scene(dir, &files)?;
    let context = Context::new();
    let mcap_error = |source| FoxgloveError::Mcap {
        path: path.to_path_buf(),
        source,
    };
    let mut channels = Channels::new(&context, layout).map_err(mcap_error)?;
    let file =
        std::fs::File::create(path).map_err(|e| mcap_error(foxglove::FoxgloveError::IoError(e)))?;
    let writer = context
        .mcap_writer()
        .create(std::io::BufWriter::new(file))
        .map_err(mcap_error)?;
    let mut done = Exported::default();
    recording.replay(|step| match step {
        super::recording::Step::Message(m) => {
            channels.message(m);
            done.messages += 1;
        }
        super::recording::Step::State(sample, readings) => {
            let before = channels.scene_second;
            channels.state(sample, readings);
            if channels.scene_second != before {
                done.scenes += 1;
            }
            done.states += 1;
        }
    });
    let mut file = writer.close().map_err(mcap_error)?;
    std::io::Write::flush(&mut file)
        .map_err(|e| mcap_error(foxglove::FoxgloveError::IoError(e)))?;
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `world` is z up with x east and y north: the pool's north axis is world y, east is
    /// world x, down is world -z.
    #[test]
    fn the_world_frame_is_the_pool_turned_z_up() {
        let q = world_to_pool();
        let n = q * nalgebra::Vector3::x();
        let e = q * nalgebra::Vector3::y();
        let d = q * nalgebra::Vector3::z();
        assert!((n - nalgebra::Vector3::y()).norm() < 1e-12, "{n}");
        assert!((e - nalgebra::Vector3::x()).norm() < 1e-12, "{e}");
        assert!((d + nalgebra::Vector3::z()).norm() < 1e-12, "{d}");
    }

    /// The beam axis of a forward transducer is body x, one at azimuth 90 is starboard, one
    /// at elevation -90 looks down (+z).
    #[test]
    fn beam_axes_follow_the_sonar_model() {
        let close = |a: nalgebra::Vector3<f64>, b: [f64; 3]| {
            (a - nalgebra::Vector3::from(b)).norm() < 1e-12
        };
        assert!(close(beam_axis(0.0, 0.0), [1.0, 0.0, 0.0]));
        assert!(close(beam_axis(90.0, 0.0), [0.0, 1.0, 0.0]));
        assert!(close(beam_axis(0.0, -90.0), [0.0, 0.0, 1.0]));
    }
}
