//! The server's connections: accepted under a cap, and one for each peer,
//! each served by hyper's
//! HTTP/1 with limits on how long a client may take (to send its request,
//! to read its answer, to stay on after it has gone) and how large a
//! request head may be, and all closed within a grace period at shutdown.
//! `axum::serve` sets none of these: a client that stopped sending or
//! reading held its connection, and a shutdown, for ever.

use super::{shutdown_signal, AppState};
use axum::body::{Body, Bytes};
use axum::Router;
use hyper::body::{Frame, SizeHint};
use hyper::service::Service;
use std::collections::HashMap;
use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::net::{IpAddr, Ipv6Addr, SocketAddr};
use std::pin::Pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// The most connections served at once; past it, new ones wait in the
/// listen queue until one closes (a client opening connections without
/// end would otherwise run the process out of file descriptors).
const MAX_CONNECTIONS: usize = 512;

/// The default of the most connections served at once to one peer
/// (`--connections-per-peer`; `peer_of`: an IPv4 address, or an IPv6
/// /64); past it, a new one from that peer is closed as soon as it is
/// accepted. Without it, one client that never sent a
/// request (the token is checked only on requests) could hold all of
/// the server's 512 connections, reopening them as `--client-timeout` closes them,
/// and no one else would be served. 64 is some ten times what one browser
/// opens to a server (6 at once over HTTP/1.1, the dashboard's event and
/// frame streams among them), so a few people behind one NAT, or a script
/// with a few dozen clients, are not turned away, while one address holds
/// an eighth of the server's connections at most. It does not stop a
/// client with many addresses: eight of them fill the server again. A
/// reverse proxy on the same host is one peer for all its clients: it
/// needs a larger share.
pub const MAX_CONNECTIONS_PER_PEER: usize = 64;

/// How long a shutdown waits for the requests under way to finish before
/// it closes their connections (the event and frame streams end at once;
/// this bounds a client that reads its answer slowly).
const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);

/// The largest request head (request line and headers) read: past it the
/// answer is 431. Ours are a few hundred bytes; hyper's default let 400 KB
/// through, for each of the connections.
const MAX_HEAD_BYTES: usize = 64 * 1024;

/// Serves `app` on `listener` until Ctrl-C or SIGTERM, then stops the
/// worker and closes the connections within [`SHUTDOWN_GRACE`]. Each
/// connection has [`super::ServeOptions::client_timeout`] to send a
/// request's head (hyper's header read timeout, which also closes an idle
/// kept-alive connection), whenever an answer is being written, to take
/// some of it, and after its client shut its side, to be answered
/// ([`ClientIo`]).
pub(super) async fn serve(listener: TcpListener, app: Router, state: &Arc<AppState>) {
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    let peers = Arc::new(Peers::new(state.options.connections_per_peer));
    let mut connections = tokio::task::JoinSet::new();
    let limit = state.options.client_timeout;
    let signal = shutdown_signal();
    tokio::pin!(signal);
    loop {
        let (stream, peer, slot) = tokio::select! {
            accepted = accept(&listener, &slots) => accepted,
            // Reaps the finished ones, which the set keeps until joined.
            Some(_) = connections.join_next(), if !connections.is_empty() => continue,
            _ = &mut signal => break,
        };
        let Some(peer_slot) = peers.take(peer_of(peer)) else {
            // Over its peer's share: closed unread, its slot given back.
            state.refused_connections.fetch_add(1, Ordering::Relaxed);
            drop((stream, slot));
            continue;
        };
        let answering = Arc::new(AtomicUsize::new(0));
        let service = counting_answers(&app, &answering);
        let mut http = hyper::server::conn::http1::Builder::new();
        http.timer(hyper_util::rt::TokioTimer::new())
            .header_read_timeout(limit)
            .max_header_size(MAX_HEAD_BYTES);
        let io = hyper_util::rt::TokioIo::new(ClientIo::new(stream, limit, answering));
        let connection = graceful.watch(http.serve_connection(io, service));
        let open = OpenConnection::new(state.clone(), slot, peer_slot);
        connections.spawn(async move {
            // A client that went away or sent garbage: nothing to report.
            let _ = connection.await;
            drop(open);
        });
    }
    // New clients are refused at once, not queued through the grace period
    // and then reset.
    drop(listener);
    state.shutdown.store(true, Ordering::SeqCst);
    state.abandon_frame(None);
    state.wake.notify_one();
    state.notify_all();
    if tokio::time::timeout(SHUTDOWN_GRACE, graceful.shutdown())
        .await
        .is_err()
    {
        eprintln!(
            "closing the connections still open {} s after the shutdown began",
            SHUTDOWN_GRACE.as_secs()
        );
        connections.shutdown().await;
    }
}

/// `app` as one connection's hyper service, counting in `answering` the
/// answers under way (from the request's call to the end of its answer's
/// body), which tells [`ClientIo`] whether the client's end of data came
/// while it waits for one.
fn counting_answers(
    app: &Router,
    answering: &Arc<AtomicUsize>,
) -> impl Service<
    hyper::Request<hyper::body::Incoming>,
    Response = hyper::Response<Answered>,
    Error = Infallible,
    Future = impl Future<Output = Result<hyper::Response<Answered>, Infallible>> + Send,
> + Clone {
    let app = hyper_util::service::TowerToHyperService::new(app.clone());
    let answering = answering.clone();
    hyper::service::service_fn(move |request| {
        let answer = Answer::begin(&answering);
        let call = app.call(request);
        async move {
            let response = call.await?;
            Ok(response.map(|body| Answered {
                body,
                _answer: answer,
            }))
        }
    })
}

/// One answer under way on a connection, counted until dropped: with its
/// request, or with its body once hyper has sent it.
struct Answer(Arc<AtomicUsize>);

impl Answer {
    fn begin(answering: &Arc<AtomicUsize>) -> Self {
        answering.fetch_add(1, Ordering::SeqCst);
        Answer(answering.clone())
    }
}

impl Drop for Answer {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// An answer's body, carrying its [`Answer`].
struct Answered {
    body: Body,
    _answer: Answer,
}

impl hyper::body::Body for Answered {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        Pin::new(&mut self.body).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.body.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.body.size_hint()
    }
}

/// A served connection: holds its slot of [`MAX_CONNECTIONS`] and of its
/// peer's [`MAX_CONNECTIONS_PER_PEER`], and counts in
/// [`AppState::open_connections`] (`/metrics`) until dropped.
struct OpenConnection {
    state: Arc<AppState>,
    _slot: OwnedSemaphorePermit,
    _peer_slot: PeerSlot,
}

impl OpenConnection {
    fn new(state: Arc<AppState>, slot: OwnedSemaphorePermit, peer_slot: PeerSlot) -> Self {
        state.open_connections.fetch_add(1, Ordering::Relaxed);
        OpenConnection {
            state,
            _slot: slot,
            _peer_slot: peer_slot,
        }
    }
}

impl Drop for OpenConnection {
    fn drop(&mut self) {
        self.state.open_connections.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Where a connection comes from, as [`MAX_CONNECTIONS_PER_PEER`] counts
/// them: its IPv4 address (also when it reaches an IPv6 socket, as
/// `::ffff:a.b.c.d`), or the /64 its IPv6 address lies in, as one host
/// commonly holds a whole /64 and could otherwise take a new address for
/// each connection.
fn peer_of(addr: SocketAddr) -> IpAddr {
    match addr.ip().to_canonical() {
        IpAddr::V6(v6) => {
            let prefix = u128::from(v6) & !(u128::from(u64::MAX));
            IpAddr::V6(Ipv6Addr::from(prefix))
        }
        v4 => v4,
    }
}

/// The connections open to each peer ([`peer_of`]); a peer with none is
/// not kept.
struct Peers {
    open: Mutex<HashMap<IpAddr, usize>>,
    /// Connections one peer may have open.
    limit: usize,
}

impl Peers {
    fn new(limit: usize) -> Self {
        Peers {
            open: Mutex::new(HashMap::new()),
            limit,
        }
    }

    /// A slot for one more connection of `peer`, unless it has its limit
    /// open.
    fn take(self: &Arc<Self>, peer: IpAddr) -> Option<PeerSlot> {
        let mut open = self.lock();
        let n = open.entry(peer).or_insert(0);
        if *n >= self.limit {
            return None;
        }
        *n += 1;
        Some(PeerSlot {
            peers: self.clone(),
            peer,
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<IpAddr, usize>> {
        // Counts only: a panic while holding it leaves them right.
        self.open.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// One connection of a peer, counted in [`Peers`] until dropped.
struct PeerSlot {
    peers: Arc<Peers>,
    peer: IpAddr,
}

impl Drop for PeerSlot {
    fn drop(&mut self) {
        let mut open = self.peers.lock();
        if let Some(n) = open.get_mut(&self.peer) {
            *n -= 1;
            if *n == 0 {
                open.remove(&self.peer);
            }
        }
    }
}

/// The next connection, once fewer than [`MAX_CONNECTIONS`] are open, with
/// its peer's address and its slot. Accept errors (out of file
/// descriptors, a connection reset before it was accepted) are waited
/// out, as `axum::serve` does.
async fn accept(
    listener: &TcpListener,
    slots: &Arc<Semaphore>,
) -> (TcpStream, SocketAddr, OwnedSemaphorePermit) {
    let slot = slots
        .clone()
        .acquire_owned()
        .await
        .expect("the connection semaphore is never closed");
    loop {
        match listener.accept().await {
            Ok((stream, peer)) => {
                // Frames and events are small writes that should leave at once.
                stream.set_nodelay(true).ok();
                // A client that vanished without a FIN or reset (its machine
                // or network gone) fails the reads hyper makes during a
                // silent frame stream within minutes, not never.
                let probes = socket2::TcpKeepalive::new()
                    .with_time(Duration::from_secs(60))
                    .with_interval(Duration::from_secs(10));
                socket2::SockRef::from(&stream)
                    .set_tcp_keepalive(&probes)
                    .ok();
                return (stream, peer, slot);
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
}

/// A client's connection under two limits of `limit` each.
///
/// Writes fail once none of them has made progress for `limit`: a client
/// that stopped reading (its socket buffers full) is let go, where it held
/// its connection slot, and the answer's bytes, for as long as it liked.
/// A stream waiting for its next frame writes nothing and is not timed.
///
/// The end of the client's data, when it comes while an answer is under
/// way (`answering`), is handed to hyper once the answer is done or
/// `limit` after it came, whichever is first; between answers, at once.
/// TCP cannot tell a client that shut its sending side after its request
/// (`nc -N`, some HTTP/1.0 tools), which waits for the answer, from one
/// that closed its socket, until a write meets the reset; and a frame
/// stream may write nothing for hours. hyper's `half_close(true)` served
/// the first and kept the second, with its slot, until the job's next
/// frame; its default closed both at once, before the first got an
/// answer not ready at once (`/records`). So the first gets an answer
/// that comes within `limit`, and the second is let go after `limit`.
struct ClientIo {
    stream: TcpStream,
    limit: Duration,
    /// Answers under way on this connection ([`counting_answers`]).
    answering: Arc<AtomicUsize>,
    /// Armed when a write finds the socket full; cleared by any progress.
    stalled: Option<Pin<Box<tokio::time::Sleep>>>,
    /// Armed when a read finds the end of the client's data, pushed back by
    /// every write that makes progress; when it fires, reads return that
    /// end.
    ended: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl ClientIo {
    fn new(stream: TcpStream, limit: Duration, answering: Arc<AtomicUsize>) -> Self {
        ClientIo {
            stream,
            limit,
            answering,
            stalled: None,
            ended: None,
        }
    }

    /// `poll` made progress (or failed): the stall, if any, is over.
    /// Pending: the stall goes on, and fails once it has lasted `limit`.
    fn timed<T>(&mut self, cx: &mut Context<'_>, poll: Poll<io::Result<T>>) -> Poll<io::Result<T>> {
        if poll.is_ready() {
            self.stalled = None;
            // A half-closed client taking a long answer is not cut off.
            if let Some(ended) = self.ended.as_mut() {
                ended
                    .as_mut()
                    .reset(tokio::time::Instant::now() + self.limit);
            }
            return poll;
        }
        let limit = self.limit;
        let stalled = self
            .stalled
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(limit)));
        match stalled.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the client took nothing of the answer for the client timeout",
            ))),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl AsyncRead for ClientIo {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        if self.ended.is_none() {
            let before = buf.filled().len();
            std::task::ready!(Pin::new(&mut self.stream).poll_read(cx, buf))?;
            if buf.filled().len() > before || buf.remaining() == 0 {
                return Poll::Ready(Ok(()));
            }
            self.ended = Some(Box::pin(tokio::time::sleep(self.limit)));
        }
        // Nothing read: the end of the data, now if no answer is under way
        // nor left to write (hyper drops an answer's body once the body is
        // in its buffer, and reads before it writes the rest), else once
        // the timer has fired. Once the answer is written hyper reads again
        // (its header read timeout has it, going idle, ask for a read).
        if self.answering.load(Ordering::SeqCst) == 0 && self.stalled.is_none() {
            return Poll::Ready(Ok(()));
        }
        let ended = self.ended.as_mut().expect("armed above");
        ended.as_mut().poll(cx).map(Ok)
    }
}

impl AsyncWrite for ClientIo {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let poll = Pin::new(&mut self.stream).poll_write(cx, buf);
        self.timed(cx, poll)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let poll = Pin::new(&mut self.stream).poll_write_vectored(cx, bufs);
        self.timed(cx, poll)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    /// Not timed: a socket's flush is always ready, and is no progress.
    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peer gets [`MAX_CONNECTIONS_PER_PEER`] slots and no more, another
    /// peer its own, and a slot dropped is free again (a peer with none
    /// left is forgotten).
    #[test]
    fn each_peer_has_its_share_of_the_connections() {
        let peers = Arc::new(Peers::new(MAX_CONNECTIONS_PER_PEER));
        let a: IpAddr = "192.0.2.1".parse().unwrap();
        let b: IpAddr = "192.0.2.2".parse().unwrap();
        let mut held: Vec<_> = (0..MAX_CONNECTIONS_PER_PEER)
            .map(|_| peers.take(a).expect("under the cap"))
            .collect();
        assert!(peers.take(a).is_none(), "one over the cap");
        let other = peers.take(b).expect("another peer");
        held.pop();
        let again = peers.take(a).expect("a slot was freed");
        assert!(peers.take(a).is_none());
        drop((held, again, other));
        assert!(peers.lock().is_empty(), "{:?}", peers.lock());
    }

    /// IPv4 is counted by address, also mapped into IPv6; IPv6 by /64.
    #[test]
    fn peers_are_ipv4_addresses_and_ipv6_prefixes() {
        let peer = |s: &str| peer_of(SocketAddr::new(s.parse().unwrap(), 1234));
        assert_eq!(peer("192.0.2.1"), peer("::ffff:192.0.2.1"));
        assert_ne!(peer("192.0.2.1"), peer("192.0.2.2"));
        assert_eq!(peer("2001:db8:1:2::1"), peer("2001:db8:1:2:ffff::9"));
        assert_eq!(
            peer("2001:db8:1:2::1"),
            "2001:db8:1:2::".parse::<IpAddr>().unwrap()
        );
        assert_ne!(peer("2001:db8:1:2::1"), peer("2001:db8:1:3::1"));
    }
}
