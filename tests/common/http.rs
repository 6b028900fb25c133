//! A minimal HTTP/1.1 client over a plain `TcpStream`, for the studio's API
//! tests: one request per connection (`Connection: close`), the body read to
//! the end (Content-Length or chunked). Hand-written rather than a client
//! crate so that the test build's dependency features stay those of the
//! release build (a client crate's URL and Unicode stack widened `syn`'s
//! features, and `cargo build --release` after `make test` recompiled every
//! proc-macro and its dependents). Raw sockets are also what the server's
//! robustness tests need.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::time::Duration;

/// `base` is `http://HOST:PORT`; `path` starts with `/`. The status and the
/// body; panics on a broken connection (a test failure, with what was asked).
pub fn request(base: &str, method: &str, path: &str, body: Option<(&str, &[u8])>, headers: &[(&str, &str)]) -> (u16, Vec<u8>) {
    let (status, _, body) = exchange(base, method, path, body, headers);
    (status, body)
}

/// The value of header `name` in the answer to `GET path` (no other header sent).
pub fn response_header(base: &str, path: &str, name: &str) -> Option<String> {
    let (_, headers, _) = exchange(base, "GET", path, None, &[]);
    headers.into_iter().find(|(k, _)| k.eq_ignore_ascii_case(name)).map(|(_, v)| v)
}

/// [`request`], with the answer's headers.
fn exchange(base: &str, method: &str, path: &str, body: Option<(&str, &[u8])>, headers: &[(&str, &str)]) -> (u16, Vec<(String, String)>, Vec<u8>) {
    let authority = base.strip_prefix("http://").unwrap_or(base);
    let mut stream = TcpStream::connect(authority).unwrap_or_else(|e| panic!("{method} {path}: connect {authority}: {e}"));
    stream.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let mut head = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        head.push_str(&format!("Host: {authority}\r\n"));
    }
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    let payload = match body {
        Some((content_type, bytes)) => {
            head.push_str(&format!("Content-Type: {content_type}\r\nContent-Length: {}\r\n", bytes.len()));
            bytes
        }
        None => &[][..],
    };
    head.push_str("\r\n");
    stream.write_all(head.as_bytes()).and_then(|_| stream.write_all(payload)).unwrap_or_else(|e| panic!("{method} {path}: send: {e}"));
    read_response(stream).unwrap_or_else(|e| panic!("{method} {path}: {e}"))
}

fn read_response(stream: TcpStream) -> Result<(u16, Vec<(String, String)>, Vec<u8>), String> {
    let mut r = BufReader::new(stream);
    let mut line = String::new();
    r.read_line(&mut line).map_err(|e| format!("status line: {e}"))?;
    let status: u16 = line.split_whitespace().nth(1).and_then(|s| s.parse().ok()).ok_or_else(|| format!("bad status line {line:?}"))?;
    let (mut length, mut chunked, mut headers) = (None, false, Vec::new());
    loop {
        line.clear();
        r.read_line(&mut line).map_err(|e| format!("header: {e}"))?;
        let l = line.trim_end();
        if l.is_empty() {
            break;
        }
        if let Some((k, v)) = l.split_once(':') {
            let v = v.trim();
            headers.push((k.trim().to_string(), v.to_string()));
            if k.eq_ignore_ascii_case("content-length") {
                length = v.parse::<usize>().ok();
            } else if k.eq_ignore_ascii_case("transfer-encoding") && v.to_ascii_lowercase().contains("chunked") {
                chunked = true;
            }
        }
    }
    let mut body = Vec::new();
    if chunked {
        loop {
            line.clear();
            r.read_line(&mut line).map_err(|e| format!("chunk size: {e}"))?;
            let size = usize::from_str_radix(line.trim().split(';').next().unwrap_or(""), 16).map_err(|_| format!("bad chunk size {line:?}"))?;
            if size == 0 {
                break;
            }
            let start = body.len();
            body.resize(start + size, 0);
            r.read_exact(&mut body[start..]).map_err(|e| format!("chunk: {e}"))?;
            line.clear();
            r.read_line(&mut line).map_err(|e| format!("chunk end: {e}"))?;
        }
    } else if let Some(n) = length {
        body.resize(n, 0);
        r.read_exact(&mut body).map_err(|e| format!("body: {e}"))?;
    } else {
        r.read_to_end(&mut body).map_err(|e| format!("body: {e}"))?;
    }
    Ok((status, headers, body))
}
