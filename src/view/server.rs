//! The HTTP side: the embedded page, the event stream, the recording's frames and the
//! controls, behind the token, `Host` and `Origin` checks.
//!
//! Routes (every one needs `?token=`):
//! - `GET /` the page;
//! - `GET /api/info` the scene and what is being viewed;
//! - `GET /api/stream` (live) Server-Sent Events: one `history` event, then a `frame` event
//!   per update;
//! - `GET /api/at?t=SECONDS` (recording) the frame, the last minute and the last messages at
//!   that time;
//! - `POST /api/control` (live, with controls) a JSON [`Control`].

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::{Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::Deserialize;
use tokio::sync::{mpsc, oneshot, watch};

use super::live::LiveShared;
use super::recording::RecordingView;
use super::scene::Scene;
use super::wire::LinkMessage;
use crate::daemon::observer::{Control, ControlRequest};

/// The page, embedded: plain HTML, CSS and JavaScript, nothing fetched from elsewhere.
pub const PAGE: &str = include_str!("page.html");

/// How long a control waits for the simulation loop to apply it.
const CONTROL_TIMEOUT: Duration = Duration::from_secs(2);

/// What the server shows.
#[derive(Clone)]
pub enum Source {
    Live {
        shared: LiveShared,
        /// `None`: the page has no controls.
        controls: Option<mpsc::Sender<ControlRequest>>,
    },
    Recording(Arc<RecordingView>),
}

/// Who may talk to the server.
#[derive(Debug, Clone)]
pub struct Guard {
    token: String,
    /// `Host` values accepted (lower case); `None` accepts any (`--view-public`).
    hosts: Option<Vec<String>>,
}

impl Guard {
    /// A fresh random token; on a loopback address only loopback names are accepted as
    /// `Host`.
    pub fn new(addr: SocketAddr, public: bool) -> Result<Self, getrandom::Error> {
        let mut raw = [0u8; 24];
        getrandom::fill(&mut raw)?;
        let port = addr.port();
        let hosts = (!public).then(|| {
            vec![
                format!("127.0.0.1:{port}"),
                format!("localhost:{port}"),
                format!("[::1]:{port}"),
                addr.to_string().to_ascii_lowercase(),
            ]
        });
        Ok(Self {
            token: hex::encode(raw),
            hosts,
        })
    }

    pub fn token(&self) -> &str {
        &self.token
    }

    /// `Ok` or why the request is refused.
    pub fn check(
        &self,
        method: &Method,
        headers: &HeaderMap,
        query: Option<&str>,
    ) -> Result<(), &'static str> {
        let host = headers
            .get(header::HOST)
            .and_then(|h| h.to_str().ok())
            .map(str::to_ascii_lowercase)
            .ok_or("no Host header")?;
        if let Some(hosts) = &self.hosts
            && !hosts.contains(&host)
        {
            return Err("Host is not this server's loopback address (DNS rebinding?)");
        }
        let token = query
            .unwrap_or_default()
            .split('&')
            .find_map(|pair| pair.strip_prefix("token="))
            .ok_or("no token: open the URL the bridge printed")?;
        if !constant_time_eq(token.as_bytes(), self.token.as_bytes()) {
            return Err("wrong token: open the URL the bridge printed");
        }
        if let Some(origin) = headers.get(header::ORIGIN) {
            let same = origin
                .to_str()
                .is_ok_and(|o| o.eq_ignore_ascii_case(&format!("http://{host}")));
            if !same {
                return Err("cross-origin request");
            }
        }
        let cross_site = headers
            .get("sec-fetch-site")
            .is_some_and(|v| v.as_bytes().eq_ignore_ascii_case(b"cross-site"));
        if cross_site && method != Method::GET {
            return Err("cross-site request");
        }
        Ok(())
    }
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[derive(Clone)]
struct AppState {
    source: Source,
    scene: Arc<Scene>,
    stop: watch::Receiver<bool>,
}

async fn guard(State(guard): State<Arc<Guard>>, request: Request, next: Next) -> Response {
    if let Err(reason) = guard.check(request.method(), request.headers(), request.uri().query()) {
        tracing::debug!(reason, uri = %request.uri().path(), "view request refused");
        return (StatusCode::FORBIDDEN, format!("{reason}\n")).into_response();
    }
    let mut response = next.run(request).await;
    let h = response.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    // The token is in the URL: never send it on as a referrer.
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; connect-src 'self'; img-src 'self' data:",
        ),
    );
    response
}

/// The router for `source`, guarded by `guard`. Event streams end when `stop` turns true.
pub fn router(source: Source, scene: Scene, guard: Guard, stop: watch::Receiver<bool>) -> Router {
    let state = AppState {
        source,
        scene: Arc::new(scene),
        stop,
    };
    Router::new()
        .route("/", get(page))
        .route("/api/info", get(info))
        .route("/api/stream", get(stream))
        .route("/api/at", get(at))
        .route("/api/control", post(control))
        .with_state(state)
        .layer(middleware::from_fn_with_state(Arc::new(guard), guard_layer))
}

async fn guard_layer(state: State<Arc<Guard>>, request: Request, next: Next) -> Response {
    guard(state, request, next).await
}

async fn page() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE)
}

async fn info(State(app): State<AppState>) -> Response {
    let (mode, controls, duration) = match &app.source {
        Source::Live { controls, .. } => ("live", controls.is_some(), None),
        Source::Recording(r) => ("recording", false, Some(r.span_s())),
    };
    let meta = match &app.source {
        Source::Recording(r) => Some(r.describe()),
        Source::Live { .. } => None,
    };
    axum::Json(serde_json::json!({
        "mode": mode,
        "controls": controls,
        "span_s": duration,
        "recording": meta,
        "scene": &*app.scene,
    }))
    .into_response()
}

/// The new messages of `all` (those after `seq`), as JSON.
fn new_messages(all: &[LinkMessage], after: Option<u64>) -> String {
    let fresh: Vec<&LinkMessage> = all
        .iter()
        .filter(|m| after.is_none_or(|a| m.seq > a))
        .collect();
    serde_json::to_string(&fresh).unwrap_or_else(|_| "[]".into())
}

async fn stream(State(app): State<AppState>) -> Response {
    let Source::Live { shared, .. } = &app.source else {
        return (StatusCode::NOT_FOUND, "a recording has no live stream\n").into_response();
    };
    let mut latest = shared.latest.clone();
    let history = {
        let now = latest.borrow_and_update();
        format!(
            "{{\"samples\":{},\"messages\":{}}}",
            serde_json::to_string(&shared.history()).unwrap_or_else(|_| "[]".into()),
            new_messages(&now.messages, None)
        )
    };
    let first_seq = latest.borrow().messages.last().map(|m| m.seq);
    struct Client {
        latest: watch::Receiver<super::live::Published>,
        stop: watch::Receiver<bool>,
        history: Option<String>,
        last_seq: Option<u64>,
        /// The page counts as watching (the link bytes are decoded) while its stream lives.
        _watching: crate::daemon::observer::WatchGuard,
    }
    let client = Client {
        _watching: shared.watchers.guard(),
        latest,
        stop: app.stop.clone(),
        history: Some(history),
        last_seq: first_seq,
    };
    // Latest-wins: the stream is polled only as fast as the client reads; frames published
    // meanwhile replace each other in the watch, so a slow page skips frames and holds one.
    let events = futures_util::stream::unfold(client, |mut c| async move {
        if let Some(history) = c.history.take() {
            let event = Event::default().event("history").data(history);
            return Some((Ok::<_, std::convert::Infallible>(event), c));
        }
        tokio::select! {
            changed = c.latest.changed() => changed.ok()?,
            _ = c.stop.wait_for(|s| *s) => return None,
        }
        let data = {
            let p = c.latest.borrow_and_update();
            let messages = new_messages(&p.messages, c.last_seq);
            if let Some(last) = p.messages.last() {
                c.last_seq = Some(last.seq);
            }
            format!("{{\"frame\":{},\"messages\":{messages}}}", p.frame_json)
        };
        Some((Ok(Event::default().event("frame").data(data)), c))
    });
    Sse::new(events)
        .keep_alive(KeepAlive::default())
        .into_response()
}

#[derive(Deserialize)]
struct AtQuery {
    t: f64,
}

async fn at(
    State(app): State<AppState>,
    query: Result<Query<AtQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let Source::Recording(recording) = &app.source else {
        return (StatusCode::NOT_FOUND, "a live run has no time slider\n").into_response();
    };
    let Some(Query(AtQuery { t })) = query.ok().filter(|q| q.t.is_finite()) else {
        return (StatusCode::BAD_REQUEST, "expected ?t=SECONDS (a number)\n").into_response();
    };
    (
        [(header::CONTENT_TYPE, "application/json")],
        recording.at(t),
    )
        .into_response()
}

async fn control(State(app): State<AppState>, body: axum::body::Bytes) -> Response {
    let Source::Live {
        controls: Some(controls),
        ..
    } = &app.source
    else {
        return (StatusCode::FORBIDDEN, "this view has no controls\n").into_response();
    };
    let control: Control = match serde_json::from_slice(&body) {
        Ok(c) => c,
        Err(e) => {
            return (
                StatusCode::BAD_REQUEST,
                format!("expected a control as JSON ({{\"action\": \"pause\"}}, ...): {e}\n"),
            )
                .into_response();
        }
    };
    let (reply, answer) = oneshot::channel();
    if controls
        .try_send(ControlRequest { control, reply })
        .is_err()
    {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            "the bridge is busy with earlier controls\n",
        )
            .into_response();
    }
    match tokio::time::timeout(CONTROL_TIMEOUT, answer).await {
        Ok(Ok(Ok(done))) => (StatusCode::OK, format!("{done}\n")).into_response(),
        Ok(Ok(Err(reason))) => (StatusCode::BAD_REQUEST, format!("{reason}\n")).into_response(),
        _ => (
            StatusCode::SERVICE_UNAVAILABLE,
            "the bridge did not take the control (stopping?)\n",
        )
            .into_response(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(pairs: &[(&'static str, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.insert(*k, HeaderValue::from_str(v).unwrap());
        }
        h
    }

    /// The token is required and compared whole; on loopback only loopback names are taken
    /// as `Host`; a foreign `Origin` is refused on any request, `Sec-Fetch-Site: cross-site`
    /// on anything but GET; `--view-public` accepts any `Host` but still wants the token.
    #[test]
    fn the_guard_wants_the_token_a_loopback_host_and_the_same_origin() {
        let addr: SocketAddr = "127.0.0.1:4321".parse().unwrap();
        let guard = Guard::new(addr, false).unwrap();
        assert_eq!(guard.token().len(), 48);
        assert_ne!(guard.token(), Guard::new(addr, false).unwrap().token());
        let query = format!("token={}", guard.token());
        let ok = |h: &[(&'static str, &str)], m: Method, q: Option<&str>| {
            guard.check(&m, &headers(h), q)
        };
        let host = [("host", "127.0.0.1:4321")];
        assert_eq!(ok(&host, Method::GET, Some(&query)), Ok(()));
        assert_eq!(
            ok(&[("host", "LOCALHOST:4321")], Method::GET, Some(&query)),
            Ok(())
        );
        assert!(ok(&host, Method::GET, None).is_err());
        assert!(ok(&host, Method::GET, Some("token=")).is_err());
        let short = &query[..query.len() - 1];
        assert!(ok(&host, Method::GET, Some(short)).is_err());
        assert!(ok(&[], Method::GET, Some(&query)).is_err(), "no Host");
        assert!(ok(&[("host", "evil.example:4321")], Method::GET, Some(&query)).is_err());
        assert!(ok(&[("host", "127.0.0.1:80")], Method::GET, Some(&query)).is_err());
        let same = [
            ("host", "127.0.0.1:4321"),
            ("origin", "http://127.0.0.1:4321"),
        ];
        assert_eq!(ok(&same, Method::POST, Some(&query)), Ok(()));
        let foreign = [
            ("host", "127.0.0.1:4321"),
            ("origin", "http://evil.example"),
        ];
        assert!(ok(&foreign, Method::GET, Some(&query)).is_err());
        assert!(ok(&foreign, Method::POST, Some(&query)).is_err());
        let cross = [("host", "127.0.0.1:4321"), ("sec-fetch-site", "cross-site")];
        assert!(ok(&cross, Method::POST, Some(&query)).is_err());
        assert_eq!(ok(&cross, Method::GET, Some(&query)), Ok(()));

        let public = Guard::new("0.0.0.0:4321".parse().unwrap(), true).unwrap();
        let query = format!("token={}", public.token());
        let h = headers(&[("host", "bridge.lab:4321")]);
        assert_eq!(public.check(&Method::GET, &h, Some(&query)), Ok(()));
        assert!(public.check(&Method::GET, &h, None).is_err());
    }
}
