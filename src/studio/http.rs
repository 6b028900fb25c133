//! The studio's local HTTP server: hyper's HTTP/1.1 on a tokio runtime of
//! one thread, bound to 127.0.0.1. Limits before any work: a request's head
//! within [`HEAD_TIMEOUT`] (an idle connection is closed after it too), at
//! most [`MAX_HEAD`] bytes and [`MAX_HEADERS`] fields (431), a body declared
//! over [`MAX_BODY`] refused before a byte of it is read (413), a body sent
//! within [`BODY_TIMEOUT`], at most [`MAX_CONNECTIONS`] open connections
//! (those past it are closed at once), and an accept loop that waits and goes
//! on when the process runs out of file descriptors. The routes run on the
//! runtime's blocking pool ([`HANDLERS`] threads), so a slow one holds no
//! connection's reading.
//!
//! Every request carries the session's token (the `?token=` of the printed
//! URL, then a cookie the page gets, or an `X-Studio-Token` header), a Host
//! header other than localhost or 127.0.0.1 is refused (DNS rebinding), and
//! only the routes below answer: nothing is served by path from the disk, so
//! nothing outside the run folder can be reached. A request that changes
//! something is JSON from the studio's own page ([`change_refused`]); every
//! answer carries a strict Content-Security-Policy. A bad request gets a 4xx
//! with a one-line message and changes nothing.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use http_body_util::{BodyExt, Full, Limited};
use hyper::body::Bytes;
use hyper::{HeaderMap, Method};
use serde::Serialize;

use crate::error::{Error, Result};

use super::shapes::{is_unknown, points_payload};
use super::{EditRequest, JobRequest, Studio};

/// Largest request body read (an edit or a job is a few hundred bytes).
pub const MAX_BODY: usize = 64 * 1024;
/// Largest request head (request line and header fields), bytes.
pub const MAX_HEAD: usize = 16 * 1024;
/// Most header fields in a request.
pub const MAX_HEADERS: usize = 64;
/// A request's head arrives within this, or the connection is closed (an
/// idle kept-alive connection too).
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(10);
/// A request's body arrives within this (408 otherwise).
pub const BODY_TIMEOUT: Duration = Duration::from_secs(10);
/// Open connections at most (a browser opens six); one past it is closed
/// as soon as it is accepted.
pub const MAX_CONNECTIONS: usize = 1024;
/// Threads answering requests (jobs run on the studio's worker, so these
/// stay free while one runs).
pub const HANDLERS: usize = 8;

/// How the studio is served.
pub struct ServeOptions {
    /// 0: a free port chosen by the system.
    pub port: u16,
    /// The session token (random when None).
    pub token: Option<String>,
}

/// A served studio: its address and token.
pub struct Served {
    pub port: u16,
    pub token: String,
    stop: tokio::sync::watch::Sender<bool>,
    server: std::thread::JoinHandle<()>,
}

impl Served {
    /// The page's address with the token.
    pub fn url(&self) -> String {
        format!("http://127.0.0.1:{}/?token={}", self.port, self.token)
    }

    /// Stops answering: no new connection is taken, and the requests being
    /// answered get a second to end.
    pub fn stop(self) {
        let _ = self.stop.send(true);
        let _ = self.server.join();
    }
}

/// What every connection shares.
struct Shared {
    studio: Arc<Studio>,
    token: String,
    port: u16,
}

/// Binds 127.0.0.1:`port` and answers requests for `studio` until
/// [`Served::stop`].
pub fn serve(studio: Arc<Studio>, options: ServeOptions) -> Result<Served> {
    let listener = std::net::TcpListener::bind(("127.0.0.1", options.port))
        .map_err(|e| Error::Usage(format!("cannot listen on 127.0.0.1:{}: {e}", options.port)))?;
    let port = listener.local_addr().map(|a| a.port()).unwrap_or(options.port);
    listener.set_nonblocking(true).map_err(|e| Error::Invalid(format!("studio server: {e}")))?;
    let token = match options.token {
        Some(t) => t,
        None => new_token()?,
    };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .max_blocking_threads(HANDLERS)
        .thread_name("studio-http")
        .build()
        .map_err(|e| Error::Invalid(format!("studio server: {e}")))?;
    let listener = {
        let _inside = runtime.enter();
        tokio::net::TcpListener::from_std(listener).map_err(|e| Error::Invalid(format!("studio server: {e}")))?
    };
    let shared = Arc::new(Shared { studio, token: token.clone(), port });
    let (stop, stopped) = tokio::sync::watch::channel(false);
    let server = std::thread::Builder::new()
        .name("studio-http".into())
        .spawn(move || {
            runtime.block_on(accept_loop(listener, shared, stopped));
            // Requests being answered get a second; the process is ending.
            runtime.shutdown_timeout(Duration::from_secs(1));
        })
        .map_err(|e| Error::Invalid(format!("studio server: {e}")))?;
    Ok(Served { port, token, stop, server })
}

/// Takes connections until told to stop. Accepting fails when the process
/// is out of file descriptors (EMFILE) or the system is (ENFILE): it waits
/// a little and goes on, while idle connections time out and free theirs.
async fn accept_loop(listener: tokio::net::TcpListener, shared: Arc<Shared>, mut stop: tokio::sync::watch::Receiver<bool>) {
    let open = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    loop {
        let accepted = tokio::select! {
            _ = stop.changed() => return,
            a = listener.accept() => a,
        };
        match accepted {
            Ok((stream, _)) => {
                let Ok(permit) = open.clone().try_acquire_owned() else { continue };
                let shared = shared.clone();
                tokio::spawn(async move {
                    serve_connection(stream, shared).await;
                    drop(permit);
                });
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
}

async fn serve_connection(stream: tokio::net::TcpStream, shared: Arc<Shared>) {
    let _ = stream.set_nodelay(true);
    let service = hyper::service::service_fn(move |request| {
        let shared = shared.clone();
        async move { Ok::<_, std::convert::Infallible>(handle(request, shared).await) }
    });
    let connection = hyper::server::conn::http1::Builder::new()
        .timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(HEAD_TIMEOUT)
        .max_buf_size(MAX_HEAD.max(8192))
        .max_headers(MAX_HEADERS)
        .serve_connection(hyper_util::rt::TokioIo::new(stream), service);
    let _ = connection.await;
}

/// What the routes see of a request.
struct Request {
    method: Method,
    /// Path and query.
    target: String,
    headers: HeaderMap,
}

impl Request {
    fn url(&self) -> &str {
        &self.target
    }
    fn method(&self) -> &Method {
        &self.method
    }
}

async fn handle(request: hyper::Request<hyper::body::Incoming>, shared: Arc<Shared>) -> hyper::Response<Full<Bytes>> {
    let (parts, body) = request.into_parts();
    let request = Request {
        method: parts.method,
        target: parts.uri.path_and_query().map_or_else(|| "/".to_string(), |p| p.as_str().to_string()),
        headers: parts.headers,
    };
    let reply = match refusal(&shared, &request) {
        Some(reply) => reply,
        None => match read_body(body, &request).await {
            Err(reply) => reply,
            Ok(body) => {
                let shared = shared.clone();
                // A bug answering one request fails that request (500).
                tokio::task::spawn_blocking(move || route(&shared.studio, &request, &body, &shared.token, shared.port))
                    .await
                    .unwrap_or_else(|_| Reply::error(500, "the studio failed answering this request (see its log)"))
            }
        },
    };
    response(reply)
}

/// 32 hex digits from the operating system's random source (none, no
/// studio: a guessable token would open it to any local page).
pub fn new_token() -> Result<String> {
    let mut b = [0u8; 16];
    super::os_random(&mut b).map_err(|e| Error::Invalid(format!("no random source for the studio's token (/dev/urandom): {e}")))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// An answer: status, content type, body, extra headers.
struct Reply {
    status: u16,
    content_type: &'static str,
    body: Vec<u8>,
    headers: Vec<(String, String)>,
}

impl Reply {
    fn json<T: Serialize>(value: &T) -> Reply {
        Reply { status: 200, content_type: "application/json", body: serde_json::to_vec(value).unwrap_or_default(), headers: Vec::new() }
    }
    fn bytes(content_type: &'static str, body: Vec<u8>) -> Reply {
        Reply { status: 200, content_type, body, headers: Vec::new() }
    }
    fn error(status: u16, message: &str) -> Reply {
        let body = serde_json::to_vec(&serde_json::json!({ "error": crate::error::one_line(message) })).unwrap_or_default();
        Reply { status, content_type: "application/json", body, headers: Vec::new() }
    }
}

/// The status for a library error: unknown ids 404, the rest of the user's
/// mistakes 400, a full queue or too many drafts 429, a stop 503.
fn status_of(e: &Error) -> u16 {
    match e {
        _ if is_unknown(e) => 404,
        Error::Invalid(_) | Error::Usage(_) => 400,
        Error::Stopped(_) => 503,
        Error::Busy(_) => 429,
        _ => 500,
    }
}

fn from_result(r: Result<Reply>) -> Reply {
    r.unwrap_or_else(|e| Reply::error(status_of(&e), &e.to_string()))
}

fn header<'a>(request: &'a Request, name: &str) -> Option<&'a str> {
    request.headers.get(name).and_then(|v| v.to_str().ok())
}

/// Whether the Host header names this machine's loopback (with or without
/// the port): a page of another site that rebinds its name to 127.0.0.1
/// sends its own name and is refused.
pub fn host_allowed(host: Option<&str>, port: u16) -> bool {
    let Some(host) = host else { return false };
    let (name, p) = match host.rsplit_once(':') {
        Some((n, p)) if !n.ends_with(']') || n.starts_with('[') => (n, Some(p)),
        _ => (host, None),
    };
    let port_ok = p.is_none_or(|p| p.parse::<u16>().ok() == Some(port));
    port_ok && matches!(name.to_ascii_lowercase().as_str(), "localhost" | "127.0.0.1")
}

fn cookie_name(port: u16) -> String {
    format!("shapeshifter_studio_{port}")
}

/// The token a request carries: `?token=`, the `X-Studio-Token` header, or
/// the studio's cookie.
fn token_of(request: &Request, port: u16) -> Option<String> {
    let query = request.url().split_once('?').map(|(_, q)| q).unwrap_or("");
    if let Some(t) = query.split('&').find_map(|kv| kv.strip_prefix("token=")) {
        return Some(t.to_string());
    }
    if let Some(t) = header(request, "X-Studio-Token") {
        return Some(t.to_string());
    }
    let name = cookie_name(port);
    header(request, "Cookie")?.split(';').find_map(|c| c.trim().strip_prefix(&format!("{name}=")).map(str::to_string))
}

/// Compares without stopping at the first difference.
fn same(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.bytes().zip(b.bytes()).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Why a request that changes something is refused, if it is: it must say
/// its body is JSON (a form or `text/plain` POST is what another site's page
/// can send without asking), and where it names the page it came from
/// (`Origin`, which browsers send with every POST), that page must be this
/// studio's.
fn change_refused(request: &Request, port: u16) -> Option<&'static str> {
    if *request.method() != Method::POST {
        return None;
    }
    let json = header(request, "Content-Type")
        .is_some_and(|t| t.split(';').next().is_some_and(|m| m.trim().eq_ignore_ascii_case("application/json")));
    if !json {
        return Some("a request that changes something must send its body as application/json");
    }
    let origin_ok = header(request, "Origin").is_none_or(|o| {
        o.strip_prefix("http://").is_some_and(|host| !host.contains('/') && host.contains(':') && host_allowed(Some(host), port))
    });
    (!origin_ok).then_some("a request from a page other than this studio's is refused (Origin)")
}

/// The Content-Security-Policy of every answer: scripts and styles only
/// from the studio's own files (and the page's one inline import map, by its
/// hash), data only from the studio, no plugins, forms, frames or base URL.
/// A string from a run folder that reached the page as markup still could
/// not run.
fn content_security_policy() -> &'static str {
    static POLICY: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    POLICY.get_or_init(|| {
        let scripts: String = super::assets::inline_scripts()
            .iter()
            .map(|s| {
                use base64::Engine as _;
                use sha2::Digest as _;
                format!(" 'sha256-{}'", base64::engine::general_purpose::STANDARD.encode(sha2::Sha256::digest(s.as_bytes())))
            })
            .collect();
        format!(
            "default-src 'none'; script-src 'self'{scripts}; style-src 'self'; img-src 'self' blob: data:; \
             connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
        )
    })
}

/// Why a request is refused before its body is read, if it is: not
/// addressed to this machine, without the token, a change not from the
/// studio's page, a body declared too large.
fn refusal(shared: &Shared, request: &Request) -> Option<Reply> {
    let port = shared.port;
    if !host_allowed(header(request, "Host"), port) {
        return Some(Reply::error(403, "this studio answers only requests addressed to localhost or 127.0.0.1"));
    }
    if !token_of(request, port).is_some_and(|t| same(&t, &shared.token)) {
        return Some(Reply::error(403, "missing or wrong token: open the address the studio printed (with its ?token=)"));
    }
    if let Some(why) = change_refused(request, port) {
        return Some(Reply::error(403, why));
    }
    let declared = header(request, "Content-Length").map(|n| n.trim().parse::<u64>());
    match declared {
        Some(Err(_)) => Some(Reply::error(400, "Content-Length is not a number")),
        Some(Ok(n)) if n > MAX_BODY as u64 => Some(Reply::error(413, &format!("request body over {MAX_BODY} bytes"))),
        _ => None,
    }
}

/// The body, at most [`MAX_BODY`] bytes, within [`BODY_TIMEOUT`].
async fn read_body(body: hyper::body::Incoming, request: &Request) -> std::result::Result<Vec<u8>, Reply> {
    if *request.method() == Method::GET {
        return Ok(Vec::new());
    }
    match tokio::time::timeout(BODY_TIMEOUT, Limited::new(body, MAX_BODY).collect()).await {
        Err(_) => Err(Reply::error(408, &format!("the request body did not arrive within {} s", BODY_TIMEOUT.as_secs()))),
        Ok(Err(e)) if e.is::<http_body_util::LengthLimitError>() => Err(Reply::error(413, &format!("request body over {MAX_BODY} bytes"))),
        Ok(Err(e)) => Err(Reply::error(400, &format!("cannot read the request body: {e}"))),
        Ok(Ok(collected)) => Ok(collected.to_bytes().to_vec()),
    }
}

fn response(reply: Reply) -> hyper::Response<Full<Bytes>> {
    let mut builder = hyper::Response::builder()
        .status(reply.status)
        .header("Content-Type", reply.content_type)
        .header("Cache-Control", "no-store")
        .header("X-Content-Type-Options", "nosniff")
        .header("Content-Security-Policy", content_security_policy())
        .header("Referrer-Policy", "no-referrer");
    for (k, v) in &reply.headers {
        builder = builder.header(k.as_str(), v.as_str());
    }
    builder.body(Full::new(Bytes::from(reply.body))).unwrap_or_else(|_| {
        let mut r = hyper::Response::new(Full::new(Bytes::from_static(b"{\"error\": \"the answer could not be made\"}")));
        *r.status_mut() = hyper::StatusCode::INTERNAL_SERVER_ERROR;
        r
    })
}

fn parse<T: serde::de::DeserializeOwned>(body: &[u8]) -> Result<T> {
    serde_json::from_slice(body).map_err(|e| Error::Invalid(format!("malformed request: {e}")))
}

fn route(studio: &Studio, request: &Request, body: &[u8], token: &str, port: u16) -> Reply {
    let path = request.url().split('?').next().unwrap_or("/");
    let parts: Vec<&str> = path.trim_matches('/').split('/').filter(|p| !p.is_empty()).collect();
    let get = *request.method() == Method::GET;
    let post = *request.method() == Method::POST;
    match (parts.as_slice(), get, post) {
        ([], true, _) | (["index.html"], true, _) => {
            let mut r = Reply::bytes("text/html; charset=utf-8", super::assets::page().as_bytes().to_vec());
            // The page's own requests (scripts, data) carry the token as a
            // cookie of this port, never sent to another site.
            r.headers.push(("Set-Cookie".into(), format!("{}={token}; Path=/; HttpOnly; SameSite=Strict", cookie_name(port))));
            r
        }
        (["assets", name], true, _) => match super::assets::asset(name) {
            Some((content_type, bytes)) => Reply::bytes(content_type, bytes.to_vec()),
            None => Reply::error(404, &format!("no asset '{}'", crate::error::one_line(name))),
        },
        (["api", "state"], true, _) => Reply::json(&studio.state()),
        (["api", "shapes", id, "levels", k, "points"], true, _) => from_result((|| {
            let k: usize = k.parse().map_err(|_| Error::Invalid(format!("level '{k}' is not a number")))?;
            let level = if id.starts_with('d') {
                let l = studio.draft_level(id)?;
                if l.index != k {
                    return Err(Error::Invalid(format!("{id} is an edit of level {}, not {k}", l.index)));
                }
                l
            } else {
                (*studio.gallery.level(id, k)?).clone()
            };
            Ok(Reply::bytes("application/octet-stream", points_payload(&level)))
        })()),
        (["api", "shapes", id, "preview.png"], true, _) => from_result(studio.preview(id).map(|png| Reply::bytes("image/png", (*png).clone()))),
        (["api", "shapes", id, "mesh.ply"], true, _) => from_result((|| {
            let folder = studio.gallery.with(id, |s| Ok(s.folder().map(Path::to_path_buf)))?;
            let path = folder.map(|f| f.join(crate::pipeline::layout::MESH_PLY)).filter(|p| p.is_file());
            let path = path.ok_or_else(|| Error::Invalid(format!("{id} has no mesh (a session variant is meshed when kept)")))?;
            let bytes = std::fs::read(&path).map_err(|e| Error::file(&path, e.to_string()))?;
            Ok(Reply::bytes("application/octet-stream", bytes))
        })()),
        (["api", "shapes", id, "discard"], _, true) => from_result(studio.gallery.discard(id).map(|_| Reply::json(&serde_json::json!({"discarded": id})))),
        (["api", "drafts"], _, true) => from_result((|| {
            #[derive(serde::Deserialize)]
            #[serde(deny_unknown_fields)]
            struct NewDraft {
                source: String,
                level: usize,
            }
            let r: NewDraft = parse(body)?;
            Ok(Reply::json(&studio.new_draft(&r.source, r.level)?))
        })()),
        (["api", "drafts", id, "edit"], _, true) => from_result((|| {
            let edit: EditRequest = parse(body)?;
            let (what, draft) = studio.edit(id, &edit)?;
            Ok(Reply::json(&serde_json::json!({ "did": what, "draft": draft })))
        })()),
        (["api", "drafts", id, "discard"], _, true) => from_result(studio.discard_draft(id).map(|_| Reply::json(&serde_json::json!({"discarded": id})))),
        (["api", "jobs"], _, true) => from_result((|| {
            let job: JobRequest = parse(body)?;
            let id = studio.submit(job)?;
            let mut r = Reply::json(&studio.jobs.get(&id));
            r.status = 202;
            Ok(r)
        })()),
        (["api", "jobs", id], true, _) => match studio.jobs.get(id) {
            Some(j) => Reply::json(&j),
            None => Reply::error(404, &format!("no job '{}'", crate::error::one_line(id))),
        },
        (["api", "jobs", id, "cancel"], _, true) => from_result(studio.jobs.cancel(id).map(|j| Reply::json(&j))),
        (_, false, false) => Reply::error(405, "only GET and POST are answered"),
        _ => Reply::error(404, &format!("no such page or call: {}", crate::error::one_line(path))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_loopback_names_on_our_port_are_allowed_hosts() {
        assert!(host_allowed(Some("127.0.0.1:8080"), 8080));
        assert!(host_allowed(Some("localhost:8080"), 8080));
        assert!(host_allowed(Some("LOCALHOST"), 8080));
        assert!(!host_allowed(Some("localhost:8081"), 8080));
        assert!(!host_allowed(Some("evil.example:8080"), 8080));
        assert!(!host_allowed(Some("127.0.0.1.evil.example:8080"), 8080));
        assert!(!host_allowed(Some("localhost.:8080"), 8080));
        assert!(!host_allowed(None, 8080));
    }

    #[test]
    fn the_policy_allows_the_pages_import_map_by_its_hash_and_nothing_inline_else() {
        let policy = content_security_policy();
        assert_eq!(policy.matches("'sha256-").count(), 1, "{policy}");
        assert!(policy.starts_with("default-src 'none'; script-src 'self' 'sha256-"), "{policy}");
        assert!(!policy.contains("unsafe"), "{policy}");
    }

    #[test]
    fn tokens_are_random_hex_and_compared_whole() {
        let (a, b) = (new_token().unwrap(), new_token().unwrap());
        assert_eq!(a.len(), 32);
        assert!(a.chars().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a, b);
        assert!(same(&a, &a.clone()));
        assert!(!same(&a, &b));
        assert!(!same(&a, &a[..31]));
    }
}
