//! The scene live over Foxglove's WebSocket protocol (`strata match --foxglove`,
//! `strata robot --foxglove`, `docs/foxglove.md`): the Foxglove app connects to a running game
//! and gets the channels a log has — `scene/field`, `scene/objects`, `scene/tf`,
//! `scene/events` with the same JSON Schemas — computed by the same [`SceneFeed`] the log's
//! writer uses.
//!
//! The server is the official Foxglove SDK's (`foxglove` crate, its `WebSocketServer` on its
//! own tokio threads): the protocol and the decoding of what clients send are theirs. A
//! [`SceneTap`] on the run's host hands the packages the scene follows to a worker thread
//! through a bounded queue (dropping and counting what does not fit, as a log that must not
//! wait does), and the worker computes the scene and publishes it.

mod channels;
mod tap;

use std::net::{SocketAddr, ToSocketAddrs};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use ::foxglove::WebSocketServerHandle;
use ::foxglove::websocket::Capability;
use anyhow::{Context as _, Result, bail};
use crossbeam_channel::{Receiver, Sender};

use crate::logging::RunConfig;
use crate::matches::{Match, robot_name};
use crate::pacing::Pacer;
use crate::scene::SceneConfig;
use crate::scene::feed::{SceneFeed, SceneTopics};
use channels::{SceneChannels, Subscribed};
pub use tap::SceneTap;
use tap::Work;

/// Where `--foxglove` serves when given no address (Foxglove's own default port).
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// Packages waiting for the worker: about a simulated second of a 7 vs 7 match's ground
/// truth, world states and decisions, so that a slow moment of the worker drops nothing.
const QUEUE: usize = 1024;

/// `HOST:PORT` (port 0: any free port), as `--foxglove` takes it.
pub fn parse_addr(text: &str) -> Result<SocketAddr> {
    let mut addrs = text.to_socket_addrs().with_context(|| {
        format!(
            "--foxglove `{text}`: expected HOST:PORT, e.g. {DEFAULT_ADDR} (port 0: any free port)"
        )
    })?;
    match addrs.next() {
        Some(addr) => Ok(addr),
        None => bail!("--foxglove `{text}`: the host names no address"),
    }
}

/// A Foxglove WebSocket server of a run's scene, and the worker thread that computes it.
/// [`SceneServer::finish`] (or dropping it) publishes what is queued and closes the server.
pub struct SceneServer {
    addr: SocketAddr,
    topics: SceneTopics,
    work: Sender<Work>,
    dropped: Arc<AtomicU64>,
    subscribed: Arc<Subscribed>,
    worker: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for SceneServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneServer").field("addr", &self.addr).finish_non_exhaustive()
    }
}

impl SceneServer {
    /// Serves the scene of `robots` (module prefixes: `home/3`, `t10/3`), drawn with `config`,
    /// on `addr`. Feed it with [`SceneServer::tap`].
    pub fn start(
        addr: SocketAddr,
        config: SceneConfig,
        robots: impl IntoIterator<Item = String>,
    ) -> Result<SceneServer> {
        let channels = SceneChannels::new()?;
        let subscribed = Arc::new(Subscribed::default());
        let server = channels
            .context()
            .websocket_server()
            .name("strata")
            .bind(addr.ip().to_string(), addr.port())
            // The run's clock is Foxglove's: a lockstep match runs faster or slower than the
            // wall clock, and its messages carry its own time.
            .capabilities([Capability::Time])
            .listener(channels.listener(Arc::clone(&subscribed)))
            .start_blocking()
            .with_context(|| format!("serving Foxglove's WebSocket protocol on {addr}"))?;
        let addr = SocketAddr::new(addr.ip(), server.port());
        let feed = SceneFeed::new(config, robots);
        let topics = feed.topics().clone();
        let (work, queue) = crossbeam_channel::bounded(QUEUE);
        let worker = Worker { feed, channels, server: Some(server) };
        let worker = std::thread::Builder::new()
            .name("strata-foxglove".to_owned())
            .spawn(move || worker.run(&queue))
            .context("starting the Foxglove server's worker thread")?;
        Ok(SceneServer {
            addr,
            topics,
            work,
            dropped: Arc::default(),
            subscribed,
            worker: Some(worker),
        })
    }

    /// Serves the scene of `game` (all its robots and the ground truth) on `addr`, fed by a
    /// tap on it; a lockstep match is paced to `speed` times real time when given. Call
    /// before the match is played.
    pub fn attach(game: &mut Match, addr: SocketAddr, speed: Option<f64>) -> Result<SceneServer> {
        let config = RunConfig::of(game).scene();
        let robots: Vec<String> = game.robots.iter().map(|(id, _)| robot_name(*id)).collect();
        let server = SceneServer::start(addr, config, robots)?;
        let pacer = if game.config.realtime { None } else { speed.and_then(Pacer::new) };
        game.add_tap(Arc::new(server.tap(pacer)));
        Ok(server)
    }

    /// A tap that feeds this server, pacing its host's ground truth with `pacer`.
    pub fn tap(&self, pacer: Option<Pacer>) -> SceneTap {
        SceneTap::new(self.topics.clone(), self.work.clone(), Arc::clone(&self.dropped), pacer)
    }

    /// The address served (with the port chosen when asked for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// `ws://...`, for the Foxglove app's *Open connection*.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// Waits up to `limit` until a client subscribed to a channel; true if one did.
    pub fn wait_for_subscriber(&self, limit: Duration) -> bool {
        self.subscribed.wait(limit)
    }

    /// Packages dropped so far because the worker had fallen behind.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Publishes what is queued, closes the channels and stops the server. Called again (or
    /// on drop), does nothing.
    pub fn finish(&mut self) {
        let Some(worker) = self.worker.take() else { return };
        // Blocks only until the worker has room, which it makes as it publishes.
        let _ = self.work.send(Work::Stop);
        if worker.join().is_err() {
            tracing::warn!("the Foxglove server's worker thread panicked");
        }
    }
}

impl Drop for SceneServer {
    fn drop(&mut self) {
        self.finish();
    }
}

/// The worker thread's state: the scene and where it goes.
struct Worker {
    feed: SceneFeed,
    channels: SceneChannels,
    server: Option<WebSocketServerHandle>,
}

impl Worker {
    fn run(mut self, queue: &Receiver<Work>) {
        // Ends at `Stop`, or when every sender is gone (the server and its taps dropped).
        loop {
            let (source, time, package) = match queue.recv() {
                Ok(Work::Package { source, time, package }) => (source, time, package),
                Ok(Work::Layer { source, time }) => {
                    self.feed.layer_output(source, time);
                    continue;
                }
                Ok(Work::Stop) | Err(_) => break,
            };
            let out = self.feed.package(source, time, package.as_ref());
            if out.objects.is_some()
                && let Some(server) = &self.server
            {
                server.broadcast_time(time.as_nanos());
            }
            self.channels.publish(&out, time);
        }
        self.channels.close();
        if let Some(server) = self.server.take() {
            // Closes the clients' connections and waits for the server's tasks to end.
            server.stop().wait_blocking();
        }
    }
}
