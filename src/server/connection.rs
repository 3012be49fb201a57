//! The server's connections: accepted under a cap, each served by hyper's
//! HTTP/1 with limits on how long a client may take (to send its request,
//! to read its answer) and how large a request head may be, and all
//! closed within a grace period at shutdown. `axum::serve` sets none of
//! these: a client that stopped sending or reading held its connection,
//! and a shutdown, for ever.

use super::{shutdown_signal, AppState};
use axum::Router;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// The most connections served at once; past it, new ones wait in the
/// listen queue until one closes (a client opening connections without
/// end would otherwise run the process out of file descriptors).
const MAX_CONNECTIONS: usize = 512;

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
/// kept-alive connection) and, whenever an answer is being written, to
/// take some of it ([`StalledWrites`]).
pub(super) async fn serve(listener: TcpListener, app: Router, state: &AppState) {
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    let limit = state.options.client_timeout;
    let signal = shutdown_signal();
    tokio::pin!(signal);
    loop {
        let (stream, slot) = tokio::select! {
            accepted = accept(&listener, &slots) => accepted,
            _ = &mut signal => break,
        };
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        let mut http = hyper::server::conn::http1::Builder::new();
        http.timer(hyper_util::rt::TokioTimer::new())
            .header_read_timeout(limit)
            .max_header_size(MAX_HEAD_BYTES)
            // A client that shuts its side after its request (`nc -N`, some
            // HTTP/1.0 tools) still gets the answer.
            .half_close(true);
        let io = hyper_util::rt::TokioIo::new(StalledWrites::new(stream, limit));
        let connection = graceful.watch(http.serve_connection(io, service));
        tokio::spawn(async move {
            // A client that went away or sent garbage: nothing to report.
            let _ = connection.await;
            drop(slot);
        });
    }
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
    }
}

/// The next connection, once fewer than [`MAX_CONNECTIONS`] are open, with
/// its slot. Accept errors (out of file descriptors, a connection reset
/// before it was accepted) are waited out, as `axum::serve` does.
async fn accept(
    listener: &TcpListener,
    slots: &Arc<Semaphore>,
) -> (TcpStream, OwnedSemaphorePermit) {
    let slot = slots
        .clone()
        .acquire_owned()
        .await
        .expect("the connection semaphore is never closed");
    loop {
        match listener.accept().await {
            Ok((stream, _)) => {
                // Frames and events are small writes that should leave at once.
                stream.set_nodelay(true).ok();
                return (stream, slot);
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
}

/// A connection whose writes fail once none of them has made progress for
/// `limit`: a client that stopped reading (its socket buffers full) let
/// go, where it held its connection slot, and the answer's bytes, for as
/// long as it liked. A stream waiting for its next frame writes nothing
/// and is not timed.
struct StalledWrites {
    stream: TcpStream,
    limit: Duration,
    /// Armed when a write finds the socket full; cleared by any progress.
    stalled: Option<Pin<Box<tokio::time::Sleep>>>,
}

impl StalledWrites {
    fn new(stream: TcpStream, limit: Duration) -> Self {
        StalledWrites {
            stream,
            limit,
            stalled: None,
        }
    }

    /// `poll` made progress (or failed): the stall, if any, is over.
    /// Pending: the stall goes on, and fails once it has lasted `limit`.
    fn timed<T>(&mut self, cx: &mut Context<'_>, poll: Poll<io::Result<T>>) -> Poll<io::Result<T>> {
        if poll.is_ready() {
            self.stalled = None;
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

impl AsyncRead for StalledWrites {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for StalledWrites {
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
