//! A real S3-compatible server for the tests, and a fault-injecting proxy in front of it.
//!
//! # The server: moto
//!
//! [moto](https://github.com/getmoto/moto)'s standalone server (`python3 -m moto.server`), run
//! on the loopback address. Chosen because it is pure Python and installs from PyPI with pip
//! alone (no binary download, no container, no account), starts in about a second, keeps
//! buckets in memory (nothing to clean up), and speaks the S3 REST protocol over plain HTTP
//! the way `object_store`'s S3 client uses it: path-style buckets, SigV4 requests (accepted
//! without checking by default, so dummy credentials do), `ListObjectsV2`, ETags on GET, HEAD
//! and PUT, and the conditional requests the conflict detection relies on: `If-Match` and
//! `If-None-Match: *` on PUT (answering 412 Precondition Failed), `If-Match` on GET.
//! MinIO would do as well but is a Go binary fetched from outside the package registries.
//!
//! `.ci/run` installs it into a virtual environment at `target/s3-venv` (`pip install
//! 'moto[s3]' flask flask-cors`: the S3 service and the server's web framework, not every
//! AWS service of `moto[server]`). The tests use, in order, `$TERRAIN_S3_PYTHON`, that
//! environment's python, or `python3` from the PATH. When the server cannot be started the
//! tests **fail** if `TERRAIN_REQUIRE_S3=1` (set by `cargo xtask ci`), and otherwise print why
//! and skip.
//!
//! # The proxy
//!
//! [`FaultProxy`] listens on its own loopback port and relays each HTTP/1.1 request to moto
//! on a fresh connection (`Connection: close` upstream, so a response ends where the upstream
//! connection does), keeping the client's connection alive. Before relaying it checks the
//! request against its [`Rule`]s (method, a substring of the path, which matching requests
//! count: the first `skip` pass, then every `every`-th, at most `times`): the first rule that
//! fires decides the request's [`Fault`]: a delay, a stall longer than the client's timeout, a
//! 5xx answer of its own (`503 SlowDown`, `500 InternalError`, moto never sees the request), a
//! connection dropped before the request is relayed, or one dropped after moto applied it
//! (the answer is lost).

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// The environment variable that turns "no S3 server" from a skip into a failure.
pub const REQUIRE_S3: &str = "TERRAIN_REQUIRE_S3";

/// A running moto server, shared by the tests of one test binary.
#[derive(Debug)]
pub struct Moto {
    /// Its loopback address.
    pub addr: SocketAddr,
    /// Its log (moto's stdout and stderr).
    pub log: PathBuf,
    // Held open for the life of the test process: moto exits when it reads EOF here, so the
    // server dies with the tests however they end.
    _stdin: Mutex<ChildStdin>,
    _child: Mutex<Child>,
}

// Runs moto's server and exits as soon as stdin closes (the test process ended).
const LAUNCHER: &str = r#"
import os, sys, threading
def watch():
    try:
        sys.stdin.read()
    finally:
        os._exit(0)
threading.Thread(target=watch, daemon=True).start()
from moto.server import main
main(["-H", "127.0.0.1", "-p", sys.argv[1]])
"#;

fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("TERRAIN_S3_PYTHON") {
        return PathBuf::from(p);
    }
    let venv = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/s3-venv/bin/python");
    if venv.exists() {
        return venv;
    }
    PathBuf::from("python3")
}

fn free_port() -> std::io::Result<u16> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

fn start_moto() -> Result<Moto, String> {
    let py = python();
    let port = free_port().map_err(|e| format!("no free port: {e}"))?;
    let log = std::env::temp_dir().join(format!("terrain-cache-moto-{}.log", std::process::id()));
    let out = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()))?;
    let err = out.try_clone().map_err(|e| e.to_string())?;
    let mut child = Command::new(&py)
        .args(["-c", LAUNCHER, &port.to_string()])
        .stdin(Stdio::piped())
        .stdout(out)
        .stderr(err)
        .spawn()
        .map_err(|e| format!("cannot run {}: {e}", py.display()))?;
    let stdin = child.stdin.take().ok_or("no stdin")?;
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            let lines: Vec<&str> = text.lines().collect();
            let tail = lines[lines.len().saturating_sub(3)..].join(" | ");
            return Err(format!(
                "{} -m moto.server exited with {status} (is moto installed? `pip install 'moto[s3]' flask flask-cors`): {tail}",
                py.display()
            ));
        }
        if let Ok(resp) = raw_request(addr, "GET", "/", b"")
            && resp.starts_with("HTTP/1.")
        {
            break;
        }
        if start.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            return Err(format!("moto did not answer on {addr} within 30 s"));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(Moto {
        addr,
        log,
        _stdin: Mutex::new(stdin),
        _child: Mutex::new(child),
    })
}

/// The shared moto server, started on first use; `None` (after printing why) when it cannot be
/// started and `TERRAIN_REQUIRE_S3` is not `1`, a panic when it is.
pub fn moto() -> Option<&'static Moto> {
    static MOTO: OnceLock<Result<Moto, String>> = OnceLock::new();
    match MOTO.get_or_init(start_moto) {
        Ok(m) => Some(m),
        Err(why) => {
            if std::env::var(REQUIRE_S3).is_ok_and(|v| v == "1") {
                panic!("{REQUIRE_S3}=1 but the S3 test server could not be started: {why}");
            }
            eprintln!("skipping: no S3 test server ({why}); set {REQUIRE_S3}=1 to fail instead");
            None
        }
    }
}

/// One HTTP/1.1 request on a fresh connection; the whole answer as text.
pub fn raw_request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    body: &[u8],
) -> std::io::Result<String> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    s.write_all(body)?;
    let mut out = Vec::new();
    s.read_to_end(&mut out)?;
    Ok(String::from_utf8_lossy(&out).into_owned())
}

impl Moto {
    /// Creates `bucket` (path-style `PUT /bucket`).
    pub fn create_bucket(&self, bucket: &str) {
        let resp = raw_request(self.addr, "PUT", &format!("/{bucket}"), b"").unwrap();
        assert!(
            resp.starts_with("HTTP/1.1 200") || resp.starts_with("HTTP/1.0 200"),
            "{resp}"
        );
    }

    /// `http://127.0.0.1:port`.
    pub fn endpoint(&self) -> String {
        format!("http://{}", self.addr)
    }
}

/// What the proxy does to a request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// Waits this long, then relays it.
    Delay(Duration),
    /// Reads the request and answers nothing for this long (longer than the client's request
    /// timeout), then closes the connection; moto never sees it.
    Stall(Duration),
    /// Answers this status itself (503 with S3's `SlowDown` body, other codes with
    /// `InternalError`); moto never sees it.
    Status(u16),
    /// Closes the connection without relaying the request.
    DropBefore,
    /// Relays the request, reads moto's answer, and closes the connection instead of passing
    /// the answer on: the request took effect, the client cannot know.
    DropAfter,
}

/// When a fault applies. Requests that match `method` and `path_contains` are counted per
/// rule; the first `skip` of them pass, then every `every`-th one (the first included) gets
/// the fault, at most `times` times.
#[derive(Debug, Clone)]
pub struct Rule {
    /// `GET`, `PUT`, `HEAD`, `DELETE`, or any.
    pub method: Option<&'static str>,
    /// A substring of the request path (`/bucket/key?query`), or any.
    pub path_contains: Option<String>,
    /// Matching requests that pass before the rule fires.
    pub skip: u64,
    /// Fires on every `every`-th matching request after `skip` (1: all).
    pub every: u64,
    /// Most times it fires.
    pub times: u64,
    /// The fault.
    pub fault: Fault,
    matched: u64,
    fired: u64,
}

impl Rule {
    /// A rule that fires on every request (narrow it with the builder methods).
    pub fn new(fault: Fault) -> Self {
        Self {
            method: None,
            path_contains: None,
            skip: 0,
            every: 1,
            times: u64::MAX,
            fault,
            matched: 0,
            fired: 0,
        }
    }
    pub fn method(mut self, m: &'static str) -> Self {
        self.method = Some(m);
        self
    }
    pub fn path(mut self, p: impl Into<String>) -> Self {
        self.path_contains = Some(p.into());
        self
    }
    pub fn skip(mut self, n: u64) -> Self {
        self.skip = n;
        self
    }
    pub fn every(mut self, n: u64) -> Self {
        self.every = n.max(1);
        self
    }
    pub fn times(mut self, n: u64) -> Self {
        self.times = n;
        self
    }

    fn check(&mut self, method: &str, path: &str) -> Option<Fault> {
        if self.method.is_some_and(|m| m != method)
            || self
                .path_contains
                .as_deref()
                .is_some_and(|p| !path.contains(p))
        {
            return None;
        }
        self.matched += 1;
        if self.matched <= self.skip
            || !(self.matched - self.skip - 1).is_multiple_of(self.every)
            || self.fired >= self.times
        {
            return None;
        }
        self.fired += 1;
        Some(self.fault)
    }
}

/// Counts of what the proxy saw and did.
#[derive(Debug, Default)]
pub struct ProxyStats {
    pub requests: AtomicU64,
    pub relayed: AtomicU64,
    pub delayed: AtomicU64,
    pub stalled: AtomicU64,
    pub status: AtomicU64,
    pub dropped_before: AtomicU64,
    pub dropped_after: AtomicU64,
}

impl ProxyStats {
    /// Faults injected in all.
    pub fn faults(&self) -> u64 {
        [
            &self.delayed,
            &self.stalled,
            &self.status,
            &self.dropped_before,
            &self.dropped_after,
        ]
        .iter()
        .map(|c| c.load(Ordering::Relaxed))
        .sum()
    }

    pub fn get(c: &AtomicU64) -> u64 {
        c.load(Ordering::Relaxed)
    }
}

/// A fault-injecting HTTP proxy on loopback in front of `upstream` (see the module docs).
#[derive(Debug)]
pub struct FaultProxy {
    pub addr: SocketAddr,
    pub stats: Arc<ProxyStats>,
    rules: Arc<Mutex<Vec<Rule>>>,
    stop: Arc<AtomicBool>,
}

impl FaultProxy {
    pub fn start(upstream: SocketAddr) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let stats = Arc::new(ProxyStats::default());
        let rules: Arc<Mutex<Vec<Rule>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let (st, ru, sp) = (stats.clone(), rules.clone(), stop.clone());
        std::thread::spawn(move || {
            for conn in listener.incoming() {
                if sp.load(Ordering::Relaxed) {
                    return;
                }
                let Ok(conn) = conn else { continue };
                let (st, ru) = (st.clone(), ru.clone());
                std::thread::spawn(move || {
                    let _ = serve(conn, upstream, &st, &ru);
                });
            }
        });
        Self {
            addr,
            stats,
            rules,
            stop,
        }
    }

    /// `http://127.0.0.1:port`.
    pub fn endpoint(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// Replaces the rules (their counters start from zero).
    pub fn set_rules(&self, rules: Vec<Rule>) {
        *self.rules.lock().unwrap() = rules;
    }

    /// How often each rule fired so far, in order.
    pub fn fired(&self) -> Vec<u64> {
        self.rules.lock().unwrap().iter().map(|r| r.fired).collect()
    }
}

impl Drop for FaultProxy {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Wake the accept loop so it sees the flag.
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_millis(200));
    }
}

/// A request as read from the client: method, path, head lines (without the request line),
/// body.
struct Request {
    method: String,
    path: String,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

fn header<'h>(headers: &'h [(String, String)], name: &str) -> Option<&'h str> {
    headers
        .iter()
        .find(|(k, _)| k.eq_ignore_ascii_case(name))
        .map(|(_, v)| v.as_str())
}

/// A request or status line and the header fields after it.
type Head = (String, Vec<(String, String)>);

fn read_head(r: &mut impl BufRead) -> std::io::Result<Option<Head>> {
    let mut first = String::new();
    if r.read_line(&mut first)? == 0 {
        return Ok(None);
    }
    let mut headers = Vec::new();
    loop {
        let mut line = String::new();
        if r.read_line(&mut line)? == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        let line = line.trim_end();
        if line.is_empty() {
            break;
        }
        if let Some((k, v)) = line.split_once(':') {
            headers.push((k.trim().to_owned(), v.trim().to_owned()));
        }
    }
    Ok(Some((first.trim_end().to_owned(), headers)))
}

fn read_body(r: &mut impl BufRead, headers: &[(String, String)]) -> std::io::Result<Vec<u8>> {
    let mut body = Vec::new();
    if header(headers, "transfer-encoding").is_some_and(|v| v.eq_ignore_ascii_case("chunked")) {
        loop {
            let mut line = String::new();
            r.read_line(&mut line)?;
            let size = usize::from_str_radix(line.trim().split(';').next().unwrap_or("0"), 16)
                .map_err(|_| std::io::Error::other("bad chunk size"))?;
            if size == 0 {
                // Trailers until an empty line.
                loop {
                    let mut t = String::new();
                    if r.read_line(&mut t)? == 0 || t.trim().is_empty() {
                        break;
                    }
                }
                break;
            }
            let start = body.len();
            body.resize(start + size, 0);
            r.read_exact(&mut body[start..])?;
            let mut crlf = [0u8; 2];
            r.read_exact(&mut crlf)?;
        }
    } else if let Some(n) = header(headers, "content-length").and_then(|v| v.parse::<usize>().ok())
    {
        body.resize(n, 0);
        r.read_exact(&mut body)?;
    }
    Ok(body)
}

fn read_request(r: &mut impl BufRead) -> std::io::Result<Option<Request>> {
    let Some((first, headers)) = read_head(r)? else {
        return Ok(None);
    };
    let mut parts = first.split_whitespace();
    let method = parts.next().unwrap_or_default().to_owned();
    let path = parts.next().unwrap_or_default().to_owned();
    let body = read_body(r, &headers)?;
    Ok(Some(Request {
        method,
        path,
        headers,
        body,
    }))
}

fn status_answer(code: u16) -> Vec<u8> {
    let (reason, s3code) = match code {
        503 => ("Slow Down", "SlowDown"),
        500 => ("Internal Server Error", "InternalError"),
        _ => ("Error", "InternalError"),
    };
    let body = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<Error><Code>{s3code}</Code><Message>injected by the test proxy</Message></Error>"
    );
    format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: application/xml\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// Relays `req` to `upstream` on a fresh connection; moto's whole answer, and whether its
/// framing lets the client connection stay open (with `Connection: close` taken out).
fn relay(req: &Request, upstream: SocketAddr) -> std::io::Result<(Vec<u8>, bool)> {
    let mut up = TcpStream::connect_timeout(&upstream, Duration::from_secs(5))?;
    up.set_read_timeout(Some(Duration::from_secs(30)))?;
    let mut head = format!("{} {} HTTP/1.1\r\n", req.method, req.path);
    for (k, v) in &req.headers {
        if k.eq_ignore_ascii_case("connection") || k.eq_ignore_ascii_case("transfer-encoding") {
            continue;
        }
        if k.eq_ignore_ascii_case("content-length") {
            continue;
        }
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    // The body was de-chunked: send it with its length.
    if !req.body.is_empty() || matches!(req.method.as_str(), "PUT" | "POST") {
        head.push_str(&format!("Content-Length: {}\r\n", req.body.len()));
    }
    head.push_str("Connection: close\r\n\r\n");
    up.write_all(head.as_bytes())?;
    up.write_all(&req.body)?;
    let mut raw = Vec::new();
    up.read_to_end(&mut raw)?;
    // Take `Connection: close` out when the answer says where it ends, so the client may
    // reuse its connection to the proxy.
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| std::io::Error::other("no end of head from upstream"))?;
    let head_text = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head_text.split("\r\n");
    let status_line = lines.next().unwrap_or_default().to_owned();
    let status: u16 = status_line
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let headers: Vec<(String, String)> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_owned(), v.trim().to_owned()))
        .collect();
    let framed = req.method == "HEAD"
        || status == 204
        || status == 304
        || header(&headers, "content-length").is_some()
        || header(&headers, "transfer-encoding").is_some();
    if !framed {
        return Ok((raw, false));
    }
    let mut out = format!("{status_line}\r\n");
    for (k, v) in &headers {
        if !k.eq_ignore_ascii_case("connection") {
            out.push_str(&format!("{k}: {v}\r\n"));
        }
    }
    out.push_str("\r\n");
    let mut out = out.into_bytes();
    out.extend_from_slice(&raw[split + 4..]);
    Ok((out, true))
}

fn serve(
    client: TcpStream,
    upstream: SocketAddr,
    stats: &ProxyStats,
    rules: &Mutex<Vec<Rule>>,
) -> std::io::Result<()> {
    client.set_read_timeout(Some(Duration::from_secs(60)))?;
    let mut reader = BufReader::new(client.try_clone()?);
    let mut writer = client;
    loop {
        let Some(req) = read_request(&mut reader)? else {
            return Ok(());
        };
        stats.requests.fetch_add(1, Ordering::Relaxed);
        let fault = rules
            .lock()
            .unwrap()
            .iter_mut()
            .find_map(|r| r.check(&req.method, &req.path));
        match fault {
            None => {}
            Some(Fault::Delay(d)) => {
                stats.delayed.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(d);
            }
            Some(Fault::Stall(d)) => {
                stats.stalled.fetch_add(1, Ordering::Relaxed);
                std::thread::sleep(d);
                let _ = writer.shutdown(Shutdown::Both);
                return Ok(());
            }
            Some(Fault::Status(code)) => {
                stats.status.fetch_add(1, Ordering::Relaxed);
                writer.write_all(&status_answer(code))?;
                continue;
            }
            Some(Fault::DropBefore) => {
                stats.dropped_before.fetch_add(1, Ordering::Relaxed);
                let _ = writer.shutdown(Shutdown::Both);
                return Ok(());
            }
            Some(Fault::DropAfter) => {
                stats.dropped_after.fetch_add(1, Ordering::Relaxed);
                let _ = relay(&req, upstream)?;
                let _ = writer.shutdown(Shutdown::Both);
                return Ok(());
            }
        }
        let (answer, keep) = relay(&req, upstream)?;
        stats.relayed.fetch_add(1, Ordering::Relaxed);
        writer.write_all(&answer)?;
        if !keep {
            let _ = writer.shutdown(Shutdown::Both);
            return Ok(());
        }
    }
}
