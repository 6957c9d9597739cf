//! The live view: a page in the browser that shows the vehicle in the pool, what each sonar
//! transducer sees, the sensor readings and thruster commands as plots, the links' counters
//! and decoded messages, for a running bridge (`run --view`) and for a recording
//! (`eyebot-hil view RECORD_DIR`).
//!
//! What flows where:
//! - the daemon's loop hands its observer link bytes and the true state through a tap
//!   ([`crate::daemon::observer`]: bounded, `try_send`, latest-wins: the simulation never
//!   waits for a page); the CLI connects the view to it, the daemon knows nothing of the view;
//! - [`live`] decodes the wire ([`wire::WireWatch`]) and publishes one [`frame::Frame`] per
//!   state update (20 Hz) through a `watch`; each page's event stream reads the newest;
//! - [`recording`] decodes a recording once and answers "what was it like at time t";
//! - [`server`] serves the embedded page (`page.html`: HTML, CSS and JavaScript drawing on a
//!   canvas, no build step, nothing fetched from elsewhere) with axum on the daemon's tokio
//!   runtime, behind a random token, `Host` and `Origin` checks; controls are POST only and
//!   go back to the loop as [`ControlRequest`](crate::daemon::observer::ControlRequest)s,
//!   which the recording keeps as events.

pub mod foxglove;
pub mod frame;
pub mod live;
pub mod recording;
pub mod scene;
pub mod server;
pub mod wire;

use std::net::SocketAddr;

use tokio::sync::watch;

pub use self::scene::Scene;
use self::server::{Guard, Source};

/// Where and how to show a running bridge: the page, Foxglove, or both.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// Where to serve the page (`None`: no page).
    pub addr: Option<SocketAddr>,
    /// Allows a non-loopback page address (and any `Host`; the token still guards).
    pub public: bool,
    /// Where to serve Foxglove's WebSocket protocol (`None`: not at all).
    pub foxglove: Option<SocketAddr>,
    /// Allows a non-loopback Foxglove address.
    pub foxglove_public: bool,
    /// The pool, the hull and the transducers to draw.
    pub scene: Scene,
}

/// The default address: loopback, a port the system chooses.
pub const DEFAULT_ADDR: &str = "127.0.0.1:0";

/// Foxglove's default: loopback, the port Foxglove's "open connection" dialog proposes.
pub const FOXGLOVE_ADDR: &str = "127.0.0.1:8765";

/// Why a view could not be served.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error(
        "view address {addr}: not a loopback address; pass --view-public to serve the view (and its controls) to the network"
    )]
    NotLoopback { addr: SocketAddr },
    #[error("view address {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error("view: no random token could be drawn from the system: {0}")]
    Token(String),
    #[error(transparent)]
    Recording(#[from] crate::record::ReadError),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error(transparent)]
    Foxglove(#[from] self::foxglove::FoxgloveError),
}

/// A bound listener with its token, not serving yet.
#[derive(Debug)]
pub struct Bound {
    listener: tokio::net::TcpListener,
    guard: Guard,
    url: String,
}

/// Binds `addr` (refusing a non-loopback one unless `public`) and draws the token.
pub async fn bind(addr: SocketAddr, public: bool) -> Result<Bound, ViewError> {
    if !addr.ip().is_loopback() && !public {
        return Err(ViewError::NotLoopback { addr });
    }
    let listener = tokio::net::TcpListener::bind(addr)
        .await
        .map_err(|source| ViewError::Bind { addr, source })?;
    let local = listener
        .local_addr()
        .map_err(|source| ViewError::Bind { addr, source })?;
    let guard = Guard::new(local, public).map_err(|e| ViewError::Token(e.to_string()))?;
    if public {
        tracing::warn!(
            addr = %local,
            "the view is served beyond this machine: anyone with the URL can watch and steer the run"
        );
    }
    let url = format!("http://{local}/?token={}", guard.token());
    Ok(Bound {
        listener,
        guard,
        url,
    })
}

impl Bound {
    /// The URL to open (it carries the token).
    pub fn url(&self) -> &str {
        &self.url
    }

    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.listener.local_addr().ok()
    }

    /// Serves `source` until `stop` turns true (open event streams end then too).
    pub async fn serve(self, source: Source, scene: Scene, stop: watch::Receiver<bool>) {
        let app = server::router(source, scene, self.guard, stop.clone());
        let mut stop = stop;
        let served = axum::serve(self.listener, app)
            .with_graceful_shutdown(async move {
                let _ = stop.wait_for(|s| *s).await;
            })
            .await;
        if let Err(e) = served {
            tracing::error!(error = %e, "the view server stopped");
        }
    }
}

/// A service to run beside the links: given the daemon's stop signal, the future to spawn.
pub type LiveService = Box<
    dyn FnOnce(watch::Receiver<bool>) -> std::pin::Pin<Box<dyn Future<Output = ()> + Send>> + Send,
>;

/// A live view, started: the service to spawn beside the links, and where to look.
pub struct Started {
    pub service: LiveService,
    /// The page's URL (it carries the token).
    pub page_url: Option<String>,
    /// Foxglove's address (`ws://HOST:PORT`).
    pub foxglove_url: Option<String>,
}

/// Binds the page and starts the Foxglove server as `options` ask; returns the service that
/// decodes the daemon's `observation` and serves both (given the daemon's status updates
/// and, when spawned, its stop signal).
pub async fn start_live(
    options: ViewOptions,
    observation: crate::daemon::observer::Observation,
    status: watch::Receiver<crate::daemon::status::StatusSnapshot>,
) -> Result<Started, ViewError> {
    let crate::daemon::observer::Observation {
        tap: tap_rx,
        controls: controls_tx,
    } = observation;
    let bound = match options.addr {
        Some(addr) => Some(bind(addr, options.public).await?),
        None => None,
    };
    let fox = match options.foxglove {
        Some(addr) => Some((
            addr,
            self::foxglove::LiveFoxglove::start(
                addr,
                options.foxglove_public,
                options.scene.clone(),
                tap_rx.watchers.clone(),
            )
            .await?,
        )),
        None => None,
    };
    let page_url = bound.as_ref().map(|b| b.url().to_string());
    let foxglove_url = fox.as_ref().map(|(addr, f)| f.url(*addr));
    let fox = fox.map(|(_, f)| f);
    let scene = options.scene;
    let service = move |stop: watch::Receiver<bool>| {
        let (shared, live) = live::service(tap_rx, status, fox, stop.clone());
        let source = Source::Live {
            shared,
            controls: Some(controls_tx),
        };
        let fut: std::pin::Pin<Box<dyn Future<Output = ()> + Send>> = Box::pin(async move {
            match bound {
                Some(bound) => {
                    tokio::join!(live, bound.serve(source, scene, stop));
                }
                None => live.await,
            }
        });
        fut
    };
    Ok(Started {
        service: Box::new(service),
        page_url,
        foxglove_url,
    })
}

/// Serves the view of the recording in `dir` until `stop` turns true; `on_ready` runs once
/// the recording is read and the page can be opened.
pub async fn serve_recording(
    bound: Bound,
    dir: &std::path::Path,
    stop: watch::Receiver<bool>,
    on_ready: impl FnOnce(),
) -> Result<(), ViewError> {
    let recording = recording::RecordingView::load(dir)?;
    let files = crate::record::read_model_files(dir)?;
    let scene = recording_scene(dir, &files)?;
    on_ready();
    bound
        .serve(
            Source::Recording(std::sync::Arc::new(recording)),
            scene,
            stop,
        )
        .await;
    Ok(())
}

/// The scene of a recording: its model files from beside it, else the embedded ones (as
/// `gap convert` finds them).
fn recording_scene(
    dir: &std::path::Path,
    files: &crate::record::ModelFiles,
) -> Result<Scene, ViewError> {
    let pick = |name: &str| -> Box<dyn crate::config::ConfigSource> {
        if dir.join(name).is_file() {
            Box::new(crate::config::Directory::new(dir))
        } else {
            Box::new(crate::config::Embedded)
        }
    };
    let vehicle = crate::physics::load_vehicle(pick(&files.vehicle).as_ref(), &files.vehicle)?;
    let world = crate::physics::load_world(pick(&files.world).as_ref(), &files.world)?;
    let sensors =
        crate::sensors::SensorsConfig::load(pick(&files.sensors).as_ref(), &files.sensors)?;
    Ok(Scene::new(&vehicle, &world, &sensors))
}
