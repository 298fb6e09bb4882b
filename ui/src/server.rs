//! The console's HTTP server: log-in, the embedded page, and the WebSocket at `/ws` that only a
//! logged-in session may open.
//!
//! Routes: `GET /` (the console, or a redirect to `/login`), `GET /login` and `POST /login`
//! (form fields `name`, `password`; limited by [`crate::auth::Limiter`]; a right one gets a
//! session, see [`crate::auth::Sessions`]), `GET /logout`,
//! `GET /assets/{file}` (embedded), `GET /ws`. Every connection is a [`Client`] of the [`Hub`].

use crate::assets;
use crate::auth::{COOKIE, Key, QUEUE_WAIT, Refused, Session};
use crate::hub::{Client, Hub};
use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Form, Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::get;
use futures_util::{SinkExt, StreamExt};
use seabus_medium::DataMap;
use serde_json::{Value as Json, json};
use std::collections::BTreeMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;
use std::time::Duration;

/// How often a connection gets the data that changed: at most 20 times a second.
pub const DATA_EVERY: Duration = Duration::from_millis(50);
/// How long a page may take to take a message; a connection that stops reading is closed.
pub const SEND_LIMIT: Duration = Duration::from_secs(5);
/// How often the server pings a page.
pub const PING_EVERY: Duration = Duration::from_secs(5);
/// A page silent this long (no message, no answer to pings) is gone.
pub const SILENCE_LIMIT: Duration = Duration::from_secs(20);
/// The largest message a page may send (a layout saved from the designer).
pub const MAX_MESSAGE: usize = 1 << 20;

/// What every answer of the console says of itself to the browser: only the console's own scripts,
/// styles and connections run on its pages (no inline script or style; the WebSocket only back to
/// the host the page came from, which `connect-src` names), no other site may frame them, no
/// address leaks to another site (the same origin still gets it: log-in checks the Origin), and no
/// type is guessed.
pub const SECURITY_HEADERS: [(&str, &str); 4] = [
    (
        "content-security-policy",
        "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
         frame-ancestors 'none'; base-uri 'none'; form-action 'self'; connect-src 'self'",
    ),
    ("x-frame-options", "DENY"),
    ("referrer-policy", "same-origin"),
    ("x-content-type-options", "nosniff"),
];

/// The host a request names, when it is only a host name or address and a port.
fn plain_host(headers: &HeaderMap) -> Option<&str> {
    let host = headers.get(header::HOST)?.to_str().ok()?;
    let plain = !host.is_empty()
        && host.len() <= 255
        && host
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b".-:[]".contains(&b));
    plain.then_some(host)
}

/// Adds [`SECURITY_HEADERS`] to every answer, the page's own WebSocket address in `connect-src`.
async fn secured(request: axum::extract::Request, next: axum::middleware::Next) -> Response {
    let socket = plain_host(request.headers()).map(|h| format!(" ws://{h} wss://{h}"));
    let mut r = next.run(request).await;
    for (name, value) in SECURITY_HEADERS {
        let value = match (&socket, name) {
            (Some(ws), "content-security-policy") => HeaderValue::from_str(&format!("{value}{ws}"))
                .unwrap_or(HeaderValue::from_static(value)),
            _ => HeaderValue::from_static(value),
        };
        r.headers_mut()
            .insert(header::HeaderName::from_static(name), value);
    }
    r
}

/// The console's routes.
pub fn router(hub: Arc<Hub>) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/login", get(login_page).post(login))
        .route("/logout", get(logout))
        .route("/assets/{file}", get(asset))
        .route("/ws", get(ws))
        .layer(axum::middleware::from_fn(secured))
        .with_state(hub)
}

/// Serves the console on `listener` until the task is dropped.
pub async fn serve(listener: tokio::net::TcpListener, hub: Arc<Hub>) -> std::io::Result<()> {
    axum::serve(
        listener,
        router(hub).into_make_service_with_connect_info::<SocketAddr>(),
    )
    .await
}

/// The session token in the request's cookies.
fn token(headers: &HeaderMap) -> Option<String> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|kv| kv.trim().split_once('='))
        .find(|(k, _)| *k == COOKIE)
        .map(|(_, v)| v.to_string())
}

/// The request's session and the key it is known by.
fn session(hub: &Hub, headers: &HeaderMap) -> Option<(Key, Session)> {
    let key = Key::of(&token(headers)?)?;
    let s = hub.sessions.find(&key)?;
    Some((key, s))
}

fn file(name: &str) -> Response {
    match assets::get(name) {
        Some((mime, body)) => (
            [
                (header::CONTENT_TYPE, HeaderValue::from_static(mime)),
                (header::CACHE_CONTROL, HeaderValue::from_static("no-cache")),
            ],
            body,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "not found").into_response(),
    }
}

async fn index(State(hub): State<Arc<Hub>>, headers: HeaderMap) -> Response {
    if session(&hub, &headers).is_none() {
        return Redirect::to("/login").into_response();
    }
    file("index.html")
}

async fn login_page() -> Response {
    file("login.html")
}

async fn asset(Path(name): Path<String>) -> Response {
    file(&name)
}

/// The log-in form.
#[derive(serde::Deserialize)]
struct LoginForm {
    name: String,
    password: String,
}

/// The log-in page's address with `error` for it to show.
fn login_url(error: &str) -> String {
    let q: String = error
        .bytes()
        .map(|b| match b {
            b'a'..=b'z' | b'A'..=b'Z' | b'0'..=b'9' | b'-' | b'.' | b'_' => (b as char).to_string(),
            b' ' => "+".to_string(),
            _ => format!("%{b:02X}"),
        })
        .collect();
    format!("/login?error={q}")
}

fn back_to_login(error: &str) -> Response {
    Redirect::to(&login_url(error)).into_response()
}

/// The answer to a log-in refused for too many failures: 429 for programs; a browser is sent on to
/// the log-in page, which says why.
fn limited(wait: Duration) -> Response {
    let to = login_url(&format!(
        "Too many failed log-ins: try again in {} s",
        wait.as_secs().max(1)
    ));
    let page = format!(
        "<!doctype html><meta http-equiv=\"refresh\" content=\"0; url={to}\"><title>seabus console</title>"
    );
    let mut r = (StatusCode::TOO_MANY_REQUESTS, axum::response::Html(page)).into_response();
    if let Ok(v) = HeaderValue::from_str(&wait.as_secs().max(1).to_string()) {
        r.headers_mut().insert(header::RETRY_AFTER, v);
    }
    r
}

/// Checks a log-in: it waits its turn under the limit, then for one of the few password checks
/// that run at once (each takes tens of milliseconds and ~19 MiB); the user's roles when right.
async fn check(
    hub: Arc<Hub>,
    ip: IpAddr,
    name: String,
    password: String,
) -> Result<Vec<String>, Refused> {
    let attempt = hub.limiter.attempt(ip, &name).await?;
    let Ok(Ok(_permit)) = tokio::time::timeout(QUEUE_WAIT, hub.checks.acquire()).await else {
        return Err(attempt.busy());
    };
    let verified = {
        let hub = hub.clone();
        tokio::task::spawn_blocking(move || {
            hub.users.verify(&name, &password).map(|u| u.roles.clone())
        })
        .await
    };
    match verified {
        Ok(Some(roles)) => {
            attempt.succeed();
            Ok(roles)
        }
        Ok(None) => Err(attempt.fail()),
        Err(_) => Err(attempt.busy()),
    }
}

async fn login(
    State(hub): State<Arc<Hub>>,
    ConnectInfo(addr): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    Form(form): Form<LoginForm>,
) -> Response {
    let ip = addr.ip();
    if !same_origin(&headers) {
        return (StatusCode::FORBIDDEN, "another site's page").into_response();
    }
    if !crate::users::is_name(&form.name) {
        return back_to_login("Wrong name or password");
    }
    // checked in a task of its own: a failure counts even when the client hangs up meanwhile
    let checked = tokio::spawn(check(hub.clone(), ip, form.name.clone(), form.password)).await;
    let roles = match checked {
        Ok(Ok(roles)) => roles,
        Ok(Err(Refused::Wrong)) => return back_to_login("Wrong name or password"),
        Ok(Err(Refused::Limited(wait))) => return limited(wait),
        Ok(Err(Refused::Busy)) | Err(_) => {
            let mut r = back_to_login("The console is busy: try again");
            *r.status_mut() = StatusCode::SERVICE_UNAVAILABLE;
            return r;
        }
    };
    let Some(t) = hub.sessions.start(&form.name, &roles) else {
        return (
            StatusCode::INTERNAL_SERVER_ERROR,
            "no randomness for a session",
        )
            .into_response();
    };
    tracing::info!(component = "console", address = %ip, user = %form.name, "logged in");
    let cookie = format!("{COOKIE}={t}; HttpOnly; SameSite=Strict; Path=/");
    let mut r = Redirect::to("/").into_response();
    if let Ok(v) = HeaderValue::from_str(&cookie) {
        r.headers_mut().insert(header::SET_COOKIE, v);
    }
    r
}

async fn logout(State(hub): State<Arc<Hub>>, headers: HeaderMap) -> Response {
    if let Some((key, session)) = session(&hub, &headers) {
        hub.sessions.end(&key);
        tracing::info!(component = "console", user = %session.user, "logged out");
        // control goes with its holder's log-out (for anyone else there is nothing to release)
        hub.release_everything(&session).await;
        // the log-out is in the session file before it is answered
        hub.sessions.save().await;
    }
    let mut r = Redirect::to("/login").into_response();
    r.headers_mut().insert(
        header::SET_COOKIE,
        HeaderValue::from_static("seabus_session=; Max-Age=0; Path=/"),
    );
    r
}

/// Whether a browser's `Origin` (when it sends one) is this server.
fn same_origin(headers: &HeaderMap) -> bool {
    let Some(origin) = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok()) else {
        return true;
    };
    let host = headers
        .get(header::HOST)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    origin
        .split_once("://")
        .is_some_and(|(_, rest)| rest == host)
}

async fn ws(
    State(hub): State<Arc<Hub>>,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    let Some((key, session)) = session(&hub, &headers) else {
        return (StatusCode::UNAUTHORIZED, "log in first").into_response();
    };
    if !same_origin(&headers) {
        return (StatusCode::FORBIDDEN, "another site's page").into_response();
    }
    upgrade
        .max_message_size(MAX_MESSAGE)
        .on_upgrade(move |socket| connection(hub, key, session, socket))
}

async fn connection(hub: Arc<Hub>, key: Key, session: Session, socket: WebSocket) {
    let mut client = hub.connect(session);
    let (mut sink, mut stream) = socket.split();
    let mut events = hub.events();
    let mut tick = tokio::time::interval(DATA_EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut out = vec![hub.hello(&client), hub.history()];
    let mut ping = tokio::time::interval(PING_EVERY);
    let mut heard = tokio::time::Instant::now();
    'conn: loop {
        for v in out.drain(..) {
            if !put(&mut sink, Message::Text(v.to_string().into())).await {
                break 'conn;
            }
        }
        tokio::select! {
            msg = stream.next() => {
                heard = tokio::time::Instant::now();
                match msg {
                    Some(Ok(Message::Text(t))) => out = handle(&hub, &mut client, &t).await,
                    Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                    Some(Ok(_)) => {}
                }
            }
            _ = ping.tick() => {
                // a page that answers nothing, not even pings, is gone
                if heard.elapsed() > SILENCE_LIMIT || !put(&mut sink, Message::Ping(Default::default())).await {
                    break;
                }
            }
            ev = events.recv() => match ev {
                Ok(text) => {
                    if !put(&mut sink, Message::Text(text.to_string().into())).await {
                        break;
                    }
                }
                Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => {
                    out.push(hub.lease_json());
                    out.push(hub.leases_json());
                    out.push(hub.history());
                    out.extend(hub.commands_again(&client));
                }
                Err(tokio::sync::broadcast::error::RecvError::Closed) => break,
            },
            _ = tick.tick() => {
                // logged out elsewhere: the connection ends with the session
                if hub.sessions.find(&key).is_none() {
                    break;
                }
                if let Some(data) = hub.data_for(&mut client)
                    && !put(&mut sink, Message::Text(data.into())).await
                {
                    break;
                }
            }
        }
    }
    hub.disconnect(&client).await;
}

/// Sends one message; false when the page is gone or takes longer than [`SEND_LIMIT`] (a
/// connection that stops reading must not hold its user's control or the server).
async fn put(sink: &mut futures_util::stream::SplitSink<WebSocket, Message>, msg: Message) -> bool {
    matches!(
        tokio::time::timeout(SEND_LIMIT, sink.send(msg)).await,
        Ok(Ok(()))
    )
}

fn error(message: impl std::fmt::Display) -> Json {
    json!({"type": "error", "message": message.to_string()})
}

/// Answers one message from the page.
pub async fn handle(hub: &Hub, client: &mut Client, text: &str) -> Vec<Json> {
    let Ok(msg) = serde_json::from_str::<Json>(text) else {
        return vec![error("not a JSON message")];
    };
    let s = |k: &str| msg.get(k).and_then(Json::as_str).unwrap_or("").to_string();
    let fields = || -> Result<DataMap, String> {
        match msg.get("fields") {
            None => Ok(DataMap::new()),
            Some(f) => {
                serde_json::from_value::<DataMap>(f.clone()).map_err(|e| format!("fields: {e}"))
            }
        }
    };
    match s("type").as_str() {
        "open" => {
            let vars: BTreeMap<String, String> = msg
                .get("vars")
                .and_then(Json::as_object)
                .map(|o| {
                    o.iter()
                        .filter_map(|(k, v)| {
                            let v = match v {
                                Json::String(s) => s.clone(),
                                Json::Number(n) => n.to_string(),
                                _ => return None,
                            };
                            // a value names a vehicle or such: nothing that could change the
                            // meaning of the attribute it lands in
                            crate::layout::is_name(&v).then(|| (k.clone(), v))
                        })
                        .collect()
                })
                .unwrap_or_default();
            let opened = hub.open(client, &s("layout"), &vars);
            let loaded = opened["type"] == "layout" && opened.get("layout").is_some();
            let backlog = loaded.then(|| hub.backlog(client)).flatten();
            std::iter::once(opened).chain(backlog).collect()
        }
        "lease" => {
            let take = match s("action").as_str() {
                "take" => true,
                "release" => false,
                other => return vec![error(format!("lease action `{other}`: take or release"))],
            };
            // a vehicle's own control, or (none named) the console's one control
            let vehicle = s("vehicle");
            if !vehicle.is_empty() && !crate::layout::is_name(&vehicle) {
                return vec![error(format!("`{vehicle}` is not a vehicle name"))];
            }
            // what the page showed the pilot would be kept on taking control: {COMMAND: fields}
            let keep: Result<Vec<(String, DataMap)>, String> = match msg.get("keep") {
                None | Some(Json::Null) => Ok(Vec::new()),
                Some(Json::Object(o)) if take => o
                    .iter()
                    .map(|(k, v)| {
                        serde_json::from_value::<DataMap>(v.clone())
                            .map(|f| (k.clone(), f))
                            .map_err(|e| format!("keep.{k}: {e}"))
                    })
                    .collect(),
                Some(_) => Err("keep: an object of commands and their fields, on take".into()),
            };
            let keep = match keep {
                Ok(k) => k,
                Err(e) => return vec![error(e)],
            };
            let done = if take {
                hub.take_keeping(client, &vehicle, &keep).await
            } else {
                hub.lease(&client.session, &vehicle, false).await
            };
            match done {
                Ok(()) => Vec::new(),
                Err(e) => vec![error(e), hub.vehicle_lease_json(&vehicle)],
            }
        }
        "arm" => match hub.arm(client, &s("layout"), &s("command")) {
            Ok(id) => vec![json!({"type": "armed", "command": s("command"), "arm": id})],
            Err(e) => vec![error(e)],
        },
        "send" => {
            let set = match fields() {
                Ok(f) => f,
                Err(e) => return vec![error(e)],
            };
            let confirmed = msg.get("confirmed").and_then(Json::as_u64);
            match hub
                .send(client, &s("layout"), &s("command"), &set, confirmed)
                .await
            {
                Ok(_) => Vec::new(),
                Err(e) => vec![error(e)],
            }
        }
        "drive" => {
            let set = match fields() {
                Ok(f) => f,
                Err(e) => return vec![error(e)],
            };
            match hub.drive(client, &s("layout"), &s("command"), &set).await {
                Ok(()) => Vec::new(),
                Err(e) => vec![error(e)],
            }
        }
        "release" => {
            hub.release(client, &s("layout"), &s("command")).await;
            Vec::new()
        }
        "save" => {
            let name = s("layout");
            match hub.save(&client.session, &name, &s("xml")) {
                Ok(()) => vec![
                    json!({"type": "saved", "layout": name}),
                    hub.open(client, &name, &BTreeMap::new()),
                ],
                Err(e) => {
                    vec![json!({"type": "error", "message": e.to_string(), "error": e.json()})]
                }
            }
        }
        other => vec![error(format!("unknown message type `{other}`"))],
    }
}
