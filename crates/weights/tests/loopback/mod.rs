//! A loopback HTTP/1.1 server standing in for the hub, Dropbox, Google Drive and static mirrors
//! in the fetch tests: it serves files with ranges (206 and `Content-Range`) or without (a
//! server that ignores `Range`), with extra headers (`ETag`, `Content-Disposition`), pages,
//! redirects with extra headers (the hub's `x-repo-commit`, `x-linked-etag`); it can break the
//! connection of the next full download after some bytes, or fall silent there; and it records
//! every request. [`Server::silent`] accepts connections and never answers. The command line's
//! tests include it too.

#![allow(dead_code)]

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::sync::{Arc, Mutex};

/// What a path answers.
#[derive(Clone)]
pub enum Route {
    /// The bytes, with these headers, honouring ranges or not.
    File { body: Arc<Vec<u8>>, headers: Vec<(String, String)>, ranges: bool },
    /// A 302 to another path of this server, with these headers.
    Redirect { to: String, headers: Vec<(String, String)> },
}

/// One request the server received.
#[derive(Clone, Debug)]
pub struct Request {
    /// The path.
    pub path: String,
    /// Its `Range` header.
    pub range: Option<String>,
}

#[derive(Default)]
struct State {
    routes: HashMap<String, Route>,
    requests: Vec<Request>,
    /// Paths whose next body is cut after this many bytes.
    cut: HashMap<String, usize>,
    /// Paths whose next body stops after this many bytes, the connection left open.
    stall: HashMap<String, usize>,
}

/// The server; it runs until the test process ends.
pub struct Server {
    base: String,
    state: Arc<Mutex<State>>,
}

impl Server {
    /// Starts a server on a free loopback port.
    pub fn start() -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let base = format!("http://{}", listener.local_addr().unwrap());
        let state = Arc::new(Mutex::new(State::default()));
        let shared = state.clone();
        let base_for_threads = base.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let (state, base) = (shared.clone(), base_for_threads.clone());
                std::thread::spawn(move || serve(stream, &state, &base));
            }
        });
        Self { base, state }
    }

    /// A server that accepts connections and never answers (a captive portal, a filtering
    /// proxy): it reads nothing and writes nothing, holding each connection until the client
    /// gives up.
    pub fn silent() -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let base = format!("http://{}", listener.local_addr().unwrap());
        let state = Arc::new(Mutex::new(State::default()));
        let shared = state.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                shared.lock().unwrap().requests.push(Request { path: String::new(), range: None });
                std::thread::spawn(move || hold(stream));
            }
        });
        Self { base, state }
    }

    /// `http://127.0.0.1:PORT`.
    pub fn base(&self) -> &str {
        &self.base
    }

    /// Serves `body` at `path`, with ranges.
    pub fn file(&self, path: &str, body: Vec<u8>) {
        self.file_with(path, body, &[], true);
    }

    /// Serves `body` at `path` with `headers`, honouring ranges with `ranges` (else every
    /// request gets the whole file with 200, as `python3 -m http.server` answers).
    pub fn file_with(&self, path: &str, body: Vec<u8>, headers: &[(&str, &str)], ranges: bool) {
        let headers = headers.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        self.state.lock().unwrap().routes.insert(path.into(), Route::File { body: Arc::new(body), headers, ranges });
    }

    /// Serves the HTML `page` at `path`.
    pub fn page(&self, path: &str, page: &str) {
        self.file_with(path, page.as_bytes().to_vec(), &[("Content-Type", "text/html; charset=utf-8")], false);
    }

    /// Redirects `path` to `to` with `headers`.
    pub fn redirect(&self, path: &str, to: &str, headers: &[(&str, &str)]) {
        let headers = headers.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        self.state.lock().unwrap().routes.insert(path.into(), Route::Redirect { to: to.into(), headers });
    }

    /// Breaks the connection of the next response at `path` with a body of more than `bytes`
    /// bytes, after `bytes` bytes.
    pub fn cut_next(&self, path: &str, bytes: usize) {
        self.state.lock().unwrap().cut.insert(path.into(), bytes);
    }

    /// Stops the next response at `path` with a body of more than `bytes` bytes after `bytes`
    /// bytes, the connection left open and silent.
    pub fn stall_next(&self, path: &str, bytes: usize) {
        self.state.lock().unwrap().stall.insert(path.into(), bytes);
    }

    /// The requests so far.
    pub fn requests(&self) -> Vec<Request> {
        self.state.lock().unwrap().requests.clone()
    }
}

fn serve(mut stream: TcpStream, state: &Mutex<State>, base: &str) {
    let mut reader = BufReader::new(stream.try_clone().unwrap());
    let mut line = String::new();
    if reader.read_line(&mut line).is_err() {
        return;
    }
    let path = line.split_whitespace().nth(1).unwrap_or("/").to_string();
    let mut range = None;
    loop {
        let mut header = String::new();
        if reader.read_line(&mut header).unwrap_or(0) == 0 || header.trim().is_empty() {
            break;
        }
        if let Some((name, value)) = header.split_once(':')
            && name.trim().eq_ignore_ascii_case("range")
        {
            range = Some(value.trim().to_string());
        }
    }
    let route = {
        let mut s = state.lock().unwrap();
        s.requests.push(Request { path: path.clone(), range: range.clone() });
        s.routes.get(&path).or_else(|| s.routes.get(path.split('?').next().unwrap_or_default())).cloned()
    };
    let _ = match route {
        None => write!(stream, "HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"),
        Some(Route::Redirect { to, headers }) => {
            let extra: String = headers.iter().map(|(k, v)| format!("{k}: {v}\r\n")).collect();
            write!(
                stream,
                "HTTP/1.1 302 Found\r\nLocation: {base}{to}\r\n{extra}Content-Length: 0\r\nConnection: close\r\n\r\n"
            )
        }
        Some(Route::File { body, headers, ranges }) => {
            let total = body.len();
            let asked = range.as_deref().and_then(|r| r.strip_prefix("bytes=")).filter(|_| ranges);
            let (status, start, end) = match asked {
                Some(r) => {
                    let (a, b) = r.split_once('-').unwrap_or((r, ""));
                    let start: usize = a.parse().unwrap_or(0);
                    let end = b.parse::<usize>().map(|e| e + 1).unwrap_or(total).min(total);
                    if start >= total {
                        let _ = write!(
                            stream,
                            "HTTP/1.1 416 Range Not Satisfiable\r\nContent-Range: bytes */{total}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
                        );
                        return;
                    }
                    ("206 Partial Content", start, end)
                }
                None => ("200 OK", 0, total),
            };
            let content_range = if asked.is_some() {
                format!("Content-Range: bytes {start}-{}/{total}\r\n", end - 1)
            } else {
                String::new()
            };
            let accept = if ranges { "Accept-Ranges: bytes\r\n" } else { "" };
            let extra: String = headers.iter().map(|(k, v)| format!("{k}: {v}\r\n")).collect();
            let head = format!(
                "HTTP/1.1 {status}\r\nContent-Length: {}\r\n{content_range}{accept}{extra}Connection: close\r\n\r\n",
                end - start
            );
            let (cut, stall) = {
                let mut s = state.lock().unwrap();
                let take = |map: &mut HashMap<String, usize>| match map.get(&path).copied() {
                    Some(after) if end - start > after => map.remove(&path),
                    _ => None,
                };
                let cut = take(&mut s.cut);
                (cut, take(&mut s.stall))
            };
            let send_end = cut.or(stall).map(|after| start + after).unwrap_or(end);
            let sent = stream.write_all(head.as_bytes()).and_then(|_| stream.write_all(&body[start..send_end]));
            if stall.is_some() {
                let _ = stream.flush();
                hold(stream);
                return;
            }
            sent
        }
    };
    let _ = stream.flush();
    let _ = stream.shutdown(Shutdown::Both);
}

/// Keeps `stream` open without a word until the client closes it.
fn hold(mut stream: TcpStream) {
    let mut sink = [0u8; 1024];
    while matches!(stream.read(&mut sink), Ok(n) if n > 0) {}
}
