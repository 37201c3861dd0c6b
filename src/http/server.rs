//! The accept loop. `axum::serve` bounds neither how long a connection may sit without sending a
//! request nor how many may be open, so one client's idle or half-sent sockets could hold every
//! descriptor. Here hyper serves each connection (HTTP/1.1 and HTTP/2) under two deadlines — its
//! first request's headers within `header_timeout` of opening, each later one within
//! `idle_timeout` of the last response — and at most `max_connections` are open: when that many
//! are, the one idle longest is closed to make room, so a new client gets in at once.
//!
//! The deadlines are kept here rather than by hyper's `header_read_timeout`: that one does not
//! cover the bytes the protocol sniff reads first (a socket that sends nothing, or half an
//! HTTP/2 preface) nor HTTP/2, and it would close an idle keep-alive connection on the header
//! deadline instead of the idle one.

use super::Config;
use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use http_body_util::BodyExt;
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
        let service = hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
            let busy = Busy::start(tx.clone());
            let mut req = req.map(Body::new);
            // What `into_make_service_with_connect_info` would add: per-client limits read it.
            req.extensions_mut().insert(ConnectInfo(addr));
            let app = app.clone();
            async move {
                let resp = app.oneshot(req).await.unwrap_or_else(|e: Infallible| match e {});
                // The request counts as in flight until its body has been sent (or dropped).
                Ok::<_, Infallible>(resp.map(|b| {
                    Body::new(b.map_frame(move |f| {
                        let _ = &busy;
                        f
                    }))
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
            () = deadline(rx, self.deadlines) => tracing::debug!(%addr, "connection closed: no request within its deadline"),
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

/// Completes when the connection has gone without a request for longer than it may: the header
/// deadline before its first request, the idle one after; never while a request is in flight.
async fn deadline(mut rx: watch::Receiver<Activity>, d: Deadlines) {
    loop {
        let a = *rx.borrow_and_update();
        if a.in_flight > 0 {
            if rx.changed().await.is_err() {
                return std::future::pending().await;
            }
            continue;
        }
        let limit = if a.served { d.idle } else { d.header };
        tokio::select! {
            () = tokio::time::sleep_until(a.idle_since + limit) => return,
            r = rx.changed() => if r.is_err() {
                return std::future::pending().await;
            },
        }
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
