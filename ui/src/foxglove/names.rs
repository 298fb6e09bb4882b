//! The live view's front door: Foxglove's WebSocket protocol goes by two names. Clients of
//! Foxglove's `@foxglove/ws-protocol` library (and Lichtblick before 1.22) offer only
//! `foxglove.websocket.v1`; the `foxglove` crate's server accepts only the names it gives the same
//! protocol, `foxglove.sdk.v1` (and `foxglove.sdk.v1.1`), and answers HTTP 400 to the others.
//!
//! So seabus listens itself and hands each connection to the crate's server on a loopback port: a
//! handshake offering `foxglove.websocket.v1` and no `foxglove.sdk.*` name goes in as
//! `foxglove.sdk.v1`, and the answer comes back naming `foxglove.websocket.v1`, the name that
//! client chose; any other handshake goes in as it is. Past the handshake the bytes are copied
//! both ways untouched. A request head is read within [`HEAD_TIME`] and at most [`HEAD_MAX`]
//! bytes, and at most [`CONNECTIONS`] connections are open at once; beyond, a connection is
//! closed at once. What goes wrong is counted by kind.

use seabus_medium::tally::Tally;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio::task::JoinHandle;

/// The name of the protocol Foxglove's client library offers.
pub const OLD_NAME: &str = "foxglove.websocket.v1";
/// The name the `foxglove` crate's server gives the same protocol.
pub const SDK_NAME: &str = "foxglove.sdk.v1";
/// The longest request or answer head read.
pub const HEAD_MAX: usize = 16 * 1024;
/// How long a client has to send its request head.
pub const HEAD_TIME: Duration = Duration::from_secs(10);
/// Connections open at once, at most.
pub const CONNECTIONS: usize = 256;

/// The front door: its listener's task, stopped when dropped.
pub struct Front {
    addr: SocketAddr,
    task: JoinHandle<()>,
}

impl Drop for Front {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl Front {
    /// Listens on `listen` and hands every connection to the server on `inner`; `faults` counts
    /// what went wrong (`handshake`, `server unreachable`, `too many connections`).
    pub async fn start(
        listen: SocketAddr,
        inner: SocketAddr,
        faults: Arc<Tally>,
    ) -> std::io::Result<Front> {
        let listener = TcpListener::bind(listen).await?;
        let addr = listener.local_addr()?;
        let room = Arc::new(Semaphore::new(CONNECTIONS));
        let task = tokio::spawn(async move {
            loop {
                let Ok((client, _)) = listener.accept().await else {
                    // out of descriptors or the like: try again shortly, never spin
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                };
                let Ok(permit) = room.clone().try_acquire_owned() else {
                    faults.record(
                        "foxglove",
                        "too many connections",
                        format_args!("{CONNECTIONS} connections are open: one more refused"),
                    );
                    continue;
                };
                let faults = faults.clone();
                tokio::spawn(async move {
                    let _permit = permit;
                    if let Err((kind, why)) = pass(client, inner).await {
                        faults.record("foxglove", kind, format_args!("a client: {why}"));
                    }
                });
            }
        });
        Ok(Front { addr, task })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

/// What went wrong with one connection: its kind (counted) and what.
type Fault = (&'static str, String);

/// Hands one connection to the server, renaming the protocol in its handshake when it must.
async fn pass(mut client: TcpStream, inner: SocketAddr) -> Result<(), Fault> {
    client.set_nodelay(true).ok();
    let head = tokio::time::timeout(HEAD_TIME, read_head(&mut client))
        .await
        .map_err(|_| ("handshake", format!("no request head within {HEAD_TIME:?}")))?
        .map_err(|e| ("handshake", e))?;
    let (request, rest) = head;
    let (request, renamed) = rename_offer(&request);
    let mut server = TcpStream::connect(inner)
        .await
        .map_err(|e| ("server unreachable", e.to_string()))?;
    server.set_nodelay(true).ok();
    let io = |e: std::io::Error| ("broken connection", e.to_string());
    server.write_all(&request).await.map_err(io)?;
    server.write_all(&rest).await.map_err(io)?;
    if renamed {
        let (answer, rest) = read_head(&mut server)
            .await
            .map_err(|e| ("handshake", format!("the server's answer: {e}")))?;
        client
            .write_all(&rename_answer(&answer))
            .await
            .map_err(io)?;
        client.write_all(&rest).await.map_err(io)?;
    }
    // a connection closed by either side is the end of it, not a fault
    let _ = tokio::io::copy_bidirectional(&mut client, &mut server).await;
    Ok(())
}

/// Reads an HTTP head (up to and with its empty line): the head, and what came after it.
async fn read_head<S: AsyncRead + AsyncWrite + Unpin>(
    s: &mut S,
) -> Result<(Vec<u8>, Vec<u8>), String> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        let n = s.read(&mut chunk).await.map_err(|e| e.to_string())?;
        if n == 0 {
            return Err(format!(
                "closed after {} bytes, before the head ended",
                buf.len()
            ));
        }
        let from = buf.len().saturating_sub(3);
        buf.extend_from_slice(&chunk[..n]);
        if let Some(i) = find(&buf[from..], b"\r\n\r\n") {
            let end = from + i + 4;
            let rest = buf.split_off(end);
            return Ok((buf, rest));
        }
        if buf.len() > HEAD_MAX {
            return Err(format!("a head longer than {HEAD_MAX} bytes"));
        }
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Whether a head line is the `Sec-WebSocket-Protocol` header; its value when it is.
fn protocol_header(line: &str) -> Option<&str> {
    let (name, value) = line.split_once(':')?;
    name.trim()
        .eq_ignore_ascii_case("sec-websocket-protocol")
        .then_some(value)
}

/// The request head as the server takes it: when it offers [`OLD_NAME`] and no
/// `foxglove.sdk.*` name, its protocol headers offer [`SDK_NAME`] instead (and `true`).
fn rename_offer(head: &[u8]) -> (Vec<u8>, bool) {
    let Ok(text) = std::str::from_utf8(head) else {
        return (head.to_vec(), false);
    };
    let offered: Vec<&str> = text
        .split("\r\n")
        .filter_map(protocol_header)
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let sdk = offered.iter().any(|n| n.starts_with("foxglove.sdk."));
    if sdk || !offered.contains(&OLD_NAME) {
        return (head.to_vec(), false);
    }
    let mut out = String::with_capacity(text.len());
    let mut named = false;
    for line in text.split_inclusive("\r\n") {
        if protocol_header(line.trim_end()).is_some() {
            if !named {
                out.push_str("Sec-WebSocket-Protocol: ");
                out.push_str(SDK_NAME);
                out.push_str("\r\n");
                named = true;
            }
        } else {
            out.push_str(line);
        }
    }
    (out.into_bytes(), true)
}

/// The server's answer as the client takes it: its protocol header names [`OLD_NAME`].
fn rename_answer(head: &[u8]) -> Vec<u8> {
    let Ok(text) = std::str::from_utf8(head) else {
        return head.to_vec();
    };
    let mut out = String::with_capacity(text.len());
    for line in text.split_inclusive("\r\n") {
        match protocol_header(line.trim_end()) {
            Some(v) if v.trim() == SDK_NAME => {
                out.push_str("Sec-WebSocket-Protocol: ");
                out.push_str(OLD_NAME);
                out.push_str("\r\n");
            }
            _ => out.push_str(line),
        }
    }
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    const OLD: &str = "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\nUpgrade: websocket\r\n\r\n";

    #[test]
    fn only_a_handshake_offering_the_old_name_alone_is_renamed() {
        let (head, renamed) = rename_offer(OLD.as_bytes());
        assert!(renamed);
        assert_eq!(
            String::from_utf8(head).unwrap(),
            "GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\nUpgrade: websocket\r\n\r\n"
        );
        // two headers, any case: one offer of the SDK's name
        let two = "GET / HTTP/1.1\r\nsec-websocket-protocol: x.y\r\nSEC-WEBSOCKET-PROTOCOL:  foxglove.websocket.v1\r\n\r\n";
        let (head, renamed) = rename_offer(two.as_bytes());
        assert!(renamed);
        assert_eq!(
            String::from_utf8(head).unwrap(),
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
        );
        for same in [
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.websocket.v1, foxglove.sdk.v1\r\n\r\n",
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1.1\r\n\r\n",
            "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: other\r\n\r\n",
            "GET / HTTP/1.1\r\nHost: x\r\n\r\n",
        ] {
            assert_eq!(
                rename_offer(same.as_bytes()),
                (same.as_bytes().to_vec(), false)
            );
        }
    }

    #[test]
    fn the_answer_names_what_the_client_offered() {
        let answer = "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\nConnection: Upgrade\r\n\r\n";
        assert_eq!(
            String::from_utf8(rename_answer(answer.as_bytes())).unwrap(),
            "HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: foxglove.websocket.v1\r\nConnection: Upgrade\r\n\r\n"
        );
    }

    #[tokio::test]
    async fn a_head_too_long_or_cut_short_is_refused_with_why() {
        let (mut a, mut b) = tokio::io::duplex(1 << 20);
        a.write_all(&vec![b'x'; HEAD_MAX + 4096]).await.unwrap();
        let e = read_head(&mut b).await.unwrap_err();
        assert_eq!(e, format!("a head longer than {HEAD_MAX} bytes"));
        let (mut a, mut b) = tokio::io::duplex(1 << 10);
        a.write_all(b"GET / HTTP/1.1\r\n").await.unwrap();
        drop(a);
        let e = read_head(&mut b).await.unwrap_err();
        assert_eq!(e, "closed after 16 bytes, before the head ended");
        let (mut a, mut b) = tokio::io::duplex(1 << 10);
        a.write_all(b"GET / HTTP/1.1\r\n\r\nAB").await.unwrap();
        let (head, rest) = read_head(&mut b).await.unwrap();
        assert_eq!((head.len(), rest), (18, b"AB".to_vec()));
    }
}
