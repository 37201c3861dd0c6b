//! The accept loop. `axum::serve` bounds neither how long a connection may sit without sending a
//! request nor how many may be open, so one client's idle or half-sent sockets could hold every
//! descriptor. Here hyper serves each connection (HTTP/1.1 and HTTP/2) under two deadlines — its
//! first request's headers within `header_timeout` of opening, each later one within
//! `idle_timeout` of the last response — and at most `max_connections` are open: when that many
//! are, the one idle longest is closed to make room, so a new client gets in at once.
//!
//! A response is written under a third deadline, `write_timeout`: a body that has handed hyper a
//! frame and is not asked for the next one within it is waiting on a client that reads nothing,
//! and its connection is closed, so that what the response holds (a file, a post's thread, its
//! buffers) is freed. A body slow to make its next frame (a post computing) is not waiting on the
//! client and is not cut.
//!
//! The deadlines are kept here rather than by hyper's `header_read_timeout`: that one does not
//! cover the bytes the protocol sniff reads first (a socket that sends nothing, or half an
//! HTTP/2 preface) nor HTTP/2, and it would close an idle keep-alive connection on the header
//! deadline instead of the idle one.

use super::Config;
use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioExecutor, TokioIo};
use hyper_util::server::conn::auto::Builder;
use hyper_util::server::graceful::GracefulShutdown;
use std::collections::HashMap;
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, OwnedSemaphorePermit, Semaphore, watch};
use tokio::time::Instant;
use tower::ServiceExt;

/// Serves `app` on `listener` until `shutdown` completes, then stops accepting, lets requests in
/// flight finish and returns once every connection has closed.
pub async fn run(listener: TcpListener, app: Router, cfg: &Config, shutdown: impl Future<Output = ()>) {
    let slots = Arc::new(Semaphore::new(cfg.max_connections.max(1)));
    let open = Arc::new(Mutex::new(Registry::default()));
    let graceful = GracefulShutdown::new();
    let builder = Builder::new(TokioExecutor::new());
    let deadlines = Deadlines {
        header: cfg.header_timeout,
        idle: cfg.idle_timeout,
        write: cfg.write_timeout,
    };
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let (stream, addr) = tokio::select! {
            r = listener.accept() => match r {
                Ok(c) => c,
                Err(e) => {
                    accept_failed(e, &open).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let permit = match slots.clone().try_acquire_owned() {
            Ok(p) => p,
            Err(_) => {
                lock(&open).evict_idlest();
                tokio::select! {
                    p = slots.clone().acquire_owned() => p.expect("the semaphore is never closed"),
                    () = &mut shutdown => break,
                }
            }
        };
        let conn = Conn {
            app: app.clone(),
            addr,
            deadlines,
            permit,
            open: open.clone(),
        };
        tokio::spawn(conn.serve(stream, builder.clone(), graceful.watcher()));
    }
    drop(listener);
    graceful.shutdown().await;
}

#[derive(Clone, Copy)]
struct Deadlines {
    header: Duration,
    idle: Duration,
    /// Zero: none.
    write: Duration,
}

/// What a connection is doing: its deadline, and whether it may be closed to make room.
#[derive(Clone, Copy)]
struct Activity {
    /// Requests whose response has not been sent to its end.
    in_flight: usize,
    /// When it last had none in flight (or opened).
    idle_since: Instant,
    /// Whether any request came: then the idle deadline applies, else the header one.
    served: bool,
}

/// The open connections, for choosing the one to close when every slot is taken.
#[derive(Default)]
struct Registry {
    next: u64,
    open: HashMap<u64, (watch::Receiver<Activity>, Arc<Notify>)>,
}

impl Registry {
    fn add(&mut self, activity: watch::Receiver<Activity>, close: Arc<Notify>) -> u64 {
        self.next += 1;
        self.open.insert(self.next, (activity, close));
        self.next
    }

    /// Closes the connection idle longest (never one with a request in flight); it leaves the
    /// registry now, so that the next call picks another.
    fn evict_idlest(&mut self) {
        let idlest = self
            .open
            .iter()
            .filter_map(|(id, (a, _))| {
                let a = *a.borrow();
                (a.in_flight == 0).then_some((a.idle_since, *id))
            })
            .min();
        if let Some((_, close)) = idlest.and_then(|(_, id)| self.open.remove(&id)) {
            close.notify_one();
        }
    }
}

fn lock(r: &Mutex<Registry>) -> std::sync::MutexGuard<'_, Registry> {
    r.lock().unwrap_or_else(|p| p.into_inner())
}

/// Accepting failed: a connection reset before it was taken needs nothing; out of descriptors
/// (another part of the process holds more than budgeted), an idle connection gives one back.
async fn accept_failed(e: std::io::Error, open: &Mutex<Registry>) {
    use std::io::ErrorKind::*;
    if matches!(
        e.kind(),
        ConnectionAborted | ConnectionReset | ConnectionRefused | Interrupted
    ) {
        return;
    }
    tracing::warn!(error = %e, "accept failed: closing the idlest connection, retrying");
    lock(open).evict_idlest();
    tokio::time::sleep(Duration::from_millis(100)).await;
}

/// One accepted connection, with what it needs to serve itself.
struct Conn {
    app: Router,
    addr: SocketAddr,
    deadlines: Deadlines,
    /// Its slot among `max_connections`, given back when it closes.
    permit: OwnedSemaphorePermit,
    open: Arc<Mutex<Registry>>,
}

impl Conn {
    async fn serve(self, stream: TcpStream, builder: Builder<TokioExecutor>, watcher: hyper_util::server::graceful::Watcher) {
        let (tx, rx) = watch::channel(Activity {
            in_flight: 0,
            idle_since: Instant::now(),
            served: false,
        });
        let tx = Arc::new(tx);
        let close = Arc::new(Notify::new());
        let id = lock(&self.open).add(rx.clone(), close.clone());
        let (app, addr) = (self.app, self.addr);
        let waits = Arc::new(Waits::default());
        let bodies = waits.clone();
        let service = hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
            let busy = Busy::start(tx.clone());
            let waiting = bodies.add();
            let mut req = req.map(Body::new);
            // What `into_make_service_with_connect_info` would add: per-client limits read it.
            req.extensions_mut().insert(ConnectInfo(addr));
            let app = app.clone();
            async move {
                let resp = app.oneshot(req).await.unwrap_or_else(|e: Infallible| match e {});
                // The request counts as in flight until its body has been sent (or dropped).
                Ok::<_, Infallible>(resp.map(|b| {
                    Body::new(Watched {
                        inner: b,
                        waiting,
                        _busy: busy,
                    })
                }))
            }
        });
        let conn = watcher.watch(builder.serve_connection(TokioIo::new(stream), service));
        tokio::select! {
            r = conn => {
                if let Err(e) = r {
                    tracing::debug!(%addr, error = %e, "connection ended with an error");
                }
            }
            why = deadline(rx, self.deadlines, &waits) => tracing::debug!(%addr, "connection closed: {why}"),
            () = close.notified() => tracing::debug!(%addr, "idle connection closed to make room"),
        }
        lock(&self.open).open.remove(&id);
        drop(self.permit);
    }
}

/// A request in flight on its connection, from its headers until its response has been sent.
struct Busy(Arc<watch::Sender<Activity>>);

impl Busy {
    fn start(tx: Arc<watch::Sender<Activity>>) -> Self {
        tx.send_modify(|a| {
            a.in_flight += 1;
            a.served = true;
        });
        Busy(tx)
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.send_modify(|a| {
            a.in_flight -= 1;
            if a.in_flight == 0 {
                a.idle_since = Instant::now();
            }
        });
    }
}

/// Completes when the connection has gone without a request for longer than it may (the header
/// deadline before its first request, the idle one after), or when a response in flight has
/// waited on its client for longer than the write deadline; with what happened.
async fn deadline(mut rx: watch::Receiver<Activity>, d: Deadlines, waits: &Waits) -> &'static str {
    // How often a response in flight is looked at: a stalled one is cut within a quarter of
    // the deadline after it.
    let tick = (d.write / 4).clamp(Duration::from_millis(50), Duration::from_secs(1));
    loop {
        let a = *rx.borrow_and_update();
        if a.in_flight > 0 {
            if d.write.is_zero() {
                if rx.changed().await.is_err() {
                    return std::future::pending().await;
                }
                continue;
            }
            tokio::select! {
                r = rx.changed() => if r.is_err() {
                    return std::future::pending().await;
                },
                () = tokio::time::sleep(tick) => if waits.longest() > d.write {
                    return "a response waited on its client longer than --write-timeout";
                },
            }
            continue;
        }
        let limit = if a.served { d.idle } else { d.header };
        tokio::select! {
            () = tokio::time::sleep_until(a.idle_since + limit) => return "no request within its deadline",
            r = rx.changed() => if r.is_err() {
                return std::future::pending().await;
            },
        }
    }
}

/// The responses of one connection in flight, each with when it began to wait on the client.
#[derive(Default)]
struct Waits {
    bodies: Mutex<Vec<std::sync::Weak<Waiting>>>,
}

/// When a body handed over its last frame and has not been asked for the next (ms since
/// `since`; `u64::MAX`: it is not waiting on the client).
struct Waiting {
    since: std::time::Instant,
    at: std::sync::atomic::AtomicU64,
}

impl Waiting {
    fn mark(&self, waiting: bool) {
        let at = if waiting {
            u64::try_from(self.since.elapsed().as_millis()).unwrap_or(u64::MAX - 1)
        } else {
            u64::MAX
        };
        self.at.store(at, std::sync::atomic::Ordering::Relaxed);
    }
}

impl Waits {
    fn add(&self) -> Arc<Waiting> {
        let w = Arc::new(Waiting {
            since: std::time::Instant::now(),
            at: std::sync::atomic::AtomicU64::new(u64::MAX),
        });
        let mut bodies = self.bodies.lock().unwrap_or_else(|p| p.into_inner());
        bodies.retain(|b| b.strong_count() > 0);
        bodies.push(Arc::downgrade(&w));
        w
    }

    /// The longest any response in flight has waited on its client.
    fn longest(&self) -> Duration {
        let bodies = self.bodies.lock().unwrap_or_else(|p| p.into_inner());
        bodies
            .iter()
            .filter_map(std::sync::Weak::upgrade)
            .filter_map(|w| {
                let at = w.at.load(std::sync::atomic::Ordering::Relaxed);
                (at != u64::MAX).then(|| w.since.elapsed().saturating_sub(Duration::from_millis(at)))
            })
            .max()
            .unwrap_or_default()
    }
}

/// A response body that tells its connection when it waits on the client: from the frame it
/// handed over until hyper asks for the next one (hyper asks only once it has room to write).
/// It holds its request's [`Busy`] until it is dropped, sent to its end or not.
struct Watched {
    inner: Body,
    waiting: Arc<Waiting>,
    _busy: Busy,
}

impl hyper::body::Body for Watched {
    type Data = bytes::Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Result<hyper::body::Frame<Self::Data>, Self::Error>>> {
        self.waiting.mark(false);
        let r = std::pin::Pin::new(&mut self.inner).poll_frame(cx);
        if matches!(r, std::task::Poll::Ready(Some(Ok(_)))) {
            self.waiting.mark(true);
        }
        r
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> hyper::body::SizeHint {
        self.inner.size_hint()
    }
}

/// Connections that fit the process's descriptors: the soft limit is raised to the hard one
/// first (a default of 1024 is common and low for a server); each connection may hold its
/// socket and an upload's spool file, and `RESERVED` stay for the store, jobs and the listener.
pub fn connection_budget(want: usize) -> usize {
    const RESERVED: u64 = 128;
    #[cfg(unix)]
    {
        use rustix::process::{Resource, getrlimit, setrlimit};
        let mut lim = getrlimit(Resource::Nofile);
        if lim.current != lim.maximum {
            let raised = rustix::process::Rlimit {
                current: lim.maximum,
                maximum: lim.maximum,
            };
            if setrlimit(Resource::Nofile, raised).is_ok() {
                lim = raised;
            }
        }
        if let Some(n) = lim.current {
            let fit = (n.saturating_sub(RESERVED) / 2).max(1);
            return want.min(usize::try_from(fit).unwrap_or(usize::MAX));
        }
    }
    want
}
