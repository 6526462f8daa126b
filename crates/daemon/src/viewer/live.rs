//! The live Foxglove WebSocket server (`foxglove.websocket.v1`, negotiated as `foxglove.sdk.v1`; the SDK's
//! `WebSocketServer`) with one raw channel per viewer [`Topic`]. The
//! server's I/O runs on a tokio runtime of one worker thread
//! (`topspin-live`) owned here; messages are logged from the telemetry
//! thread, which never waits for a client: the SDK queues per client and
//! drops for a slow one.

use std::net::SocketAddr;
use std::sync::Arc;

use foxglove::{Context, PartialMetadata, RawChannel, WebSocketServer, WebSocketServerHandle};

use super::ViewerError;
use crate::channels::{TOPICS, Topic};

/// Messages a client may fall behind before the SDK drops its oldest.
pub(crate) const CLIENT_BACKLOG: usize = 1024;

/// The longest a stopping server waits for its clients' connections to close.
pub(crate) const SHUTDOWN_WAIT: std::time::Duration = std::time::Duration::from_secs(1);

/// A running live server and its channels.
pub struct LiveServer {
    addr: SocketAddr,
    channels: Vec<Arc<RawChannel>>,
    handle: Option<WebSocketServerHandle>,
    runtime: Option<tokio::runtime::Runtime>,
    _context: Arc<Context>,
}

impl std::fmt::Debug for LiveServer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveServer").field("addr", &self.addr).finish_non_exhaustive()
    }
}

impl LiveServer {
    /// Starts the server on `addr` (port 0: any free port; see
    /// [`addr`](Self::addr)); its thread pinned to `core` (the telemetry
    /// thread's) where given, so it never competes with the hot threads.
    pub fn start(addr: SocketAddr, core: Option<usize>) -> Result<LiveServer, ViewerError> {
        let err = |message: String| ViewerError::Start { addr, message };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .max_blocking_threads(1)
            .thread_name("topspin-live")
            .on_thread_start(move || {
                if let Some(id) = core {
                    let _ = core_affinity::set_for_current(core_affinity::CoreId { id });
                }
            })
            .enable_all()
            .build()
            .map_err(|e| err(e.to_string()))?;
        let context = Context::new();
        let mut channels = Vec::with_capacity(TOPICS.len());
        for t in TOPICS {
            let ch = context
                .channel_builder(t.name())
                .schema(t.schema())
                .message_encoding(t.encoding())
                .build_raw()
                .map_err(|e| err(e.to_string()))?;
            channels.push(ch);
        }
        let handle = WebSocketServer::new()
            .name(concat!("topspin ", env!("CARGO_PKG_VERSION")))
            .context(&context)
            .bind(addr.ip().to_string(), addr.port())
            .message_backlog_size(CLIENT_BACKLOG)
            .tokio_runtime(runtime.handle())
            .start_blocking()
            .map_err(|e| err(e.to_string()))?;
        let addr = SocketAddr::new(addr.ip(), handle.port());
        Ok(LiveServer { addr, channels, handle: Some(handle), runtime: Some(runtime), _context: context })
    }

    /// Where clients connect (`ws://ADDR`).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// A client subscribes to `topic`.
    pub(crate) fn wants(&self, topic: Topic) -> bool {
        self.channels[topic as usize].has_sinks()
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.handle.as_ref().map_or(0, |h| h.client_count())
    }

    /// Sends one encoded message of `topic` to its subscribers.
    pub fn send(&self, topic: Topic, data: &[u8], log_time_ns: u64) {
        self.channels[topic as usize].log_with_meta(data, PartialMetadata::with_log_time(log_time_ns));
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        let (Some(h), Some(rt)) = (self.handle.take(), self.runtime.take()) else { return };
        // Close the connections (a close frame to each client), waiting at most SHUTDOWN_WAIT.
        let stopping = h.stop();
        rt.block_on(async { tokio::time::timeout(SHUTDOWN_WAIT, stopping.wait()).await.ok() });
        rt.shutdown_background();
    }
}
