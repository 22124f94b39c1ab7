//! The Foxglove live view as a part of the node (`--foxglove [ADDR:]PORT`, docs/foxglove.md): a
//! Foxglove WebSocket server (the `foxglove` crate, the SDK Foxglove ships) with one channel per
//! topic the node publishes, each with its `ros2msg` schema (`ros::ros2msg`) and the very CDR
//! bytes the node writes to DDS; /clock's time as the server's time, so Foxglove's timeline is the
//! simulated one; /diagnostics; and each line as a scene (`super::scene`).
//!
//! Never in the line's way: the node's thread only serialises a message and offers it to a
//! bounded queue (a full queue drops it, counted on /diagnostics as `dropped_queue_full`); a
//! thread of its own hands the queue to the server, which keeps a bounded queue per viewer and
//! drops a slow viewer's oldest messages (the crate's rule). The server runs on its own tokio
//! threads, so nothing here blocks the node's single task. A viewer that subscribes gets the
//! channel's latest message at once, so one connecting mid-episode (or to an idle lock-step
//! line) sees where the line is. Client messages the server refuses (malformed, unknown channel,
//! unsupported request) are answered by it with an error status and counted here
//! (`client_messages_refused`, from the crate's own log records: `log::refused_client_messages`).
//! The node's parameters are readable (the Parameters capability), read-only as over ROS; each
//! line's `reset` is a service (the Services capability) that the node's own task carries out,
//! as it does a ROS request, and answers with the same ResetLine response.

use std::cell::RefCell;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use foxglove::messages::SceneUpdate;
use foxglove::websocket::service::{Request, Responder, Service, ServiceSchema};
use foxglove::websocket::{
    AnyClient, Capability, ChannelView, Client, GetParametersResponder, Parameter, ParameterHandler, ServerListener,
    SetParametersResponder,
};
use foxglove::{
    ChannelBuilder, Context, Encode, PartialMetadata, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};
use futures::channel::mpsc::{unbounded, UnboundedReceiver, UnboundedSender};
use serde::Serialize;

use super::log::{outbox_full_reports, refused_client_messages};
use super::parameters::ParameterValues;
use super::scene;
use crate::ros::messages::{DiagnosticStatus, KeyValue, ResetLineRequest, ResetLineResponse};
use crate::ros::protocol::HostedLine;
use crate::ros::ros2msg;

/// Messages waiting between the node's thread and the server (a few ticks of every topic of a
/// 64-line node); beyond it they are dropped and counted.
const QUEUE: usize = 4096;

/// How long the node, leaving, waits for its viewers to close their connections.
const STOP_WAIT: std::time::Duration = std::time::Duration::from_secs(1);

/// Messages the server buffers per viewer before it drops the viewer's oldest.
const VIEWER_BACKLOG: usize = 1024;

/// What the node's thread hands to the server's side.
enum Outgoing {
    /// A message for a channel, stamped with the simulated time (ns) it describes.
    Message(Arc<RawChannel>, Vec<u8>, u64),
    /// The server's time (from /clock).
    Time(u64),
}

/// Counters the node's thread and the forwarding thread share.
#[derive(Default)]
struct Counts {
    sent: AtomicU64,
    dropped: AtomicU64,
}

/// Each channel's latest message, for a viewer that subscribes later.
type Latest = Arc<Mutex<HashMap<u64, (Vec<u8>, u64)>>>;

/// The running live view.
pub(super) struct LiveView {
    address: SocketAddr,
    context: Arc<Context>,
    /// Shared with the forwarding thread (which sets the server's time); stopped on drop.
    handle: Option<Arc<WebSocketServerHandle>>,
    /// By topic name.
    channels: RefCell<HashMap<String, Arc<RawChannel>>>,
    latest: Latest,
    queue: Option<SyncSender<Outgoing>>,
    counts: Arc<Counts>,
    forwarder: Option<JoinHandle<()>>,
}

/// Sends a channel's latest message to a viewer that just subscribed to it.
struct Listener {
    context: Arc<Context>,
    latest: Latest,
}

impl ServerListener for Listener {
    /// (Sent under the lock: see [`LiveView::send`]; the send only queues it for the viewer.)
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        let latest = self.latest.lock().unwrap_or_else(|p| p.into_inner());
        let raw = self.context.get_channel_by_topic(channel.topic());
        if let (Some((bytes, time)), Some(raw)) = (latest.get(&u64::from(channel.id())), raw) {
            raw.log_with_meta_to_sink(bytes, PartialMetadata::with_log_time(*time), client.sink_id());
        }
    }
}

/// The node's parameters for viewers (Foxglove's Parameters panel): their current values, read
/// where the node's own parameter services read them (an evolution schedule moves some). They
/// are fixed for the run, so a set request applies nothing (the viewer keeps the values it got).
struct Parameters {
    values: ParameterValues,
}

impl Parameters {
    fn current(&self, names: &[String]) -> Vec<Parameter> {
        let values = self.values.lock().unwrap_or_else(|p| p.into_inner());
        values
            .iter()
            .filter(|(name, _)| names.is_empty() || names.iter().any(|n| n == name))
            .filter_map(|(name, value)| {
                use ros2_client::ParameterValue as V;
                Some(match value {
                    V::Boolean(b) => Parameter::bool(*name, *b),
                    V::Integer(i) => Parameter::integer(*name, *i),
                    V::Double(d) => Parameter::float64(*name, *d),
                    V::String(t) => Parameter::string(*name, t.as_str()),
                    _ => return None, // the node declares none of the other types
                })
            })
            .collect()
    }
}

impl ParameterHandler for Parameters {
    fn get(&self, _client: AnyClient, names: Vec<String>, _id: Option<String>, responder: GetParametersResponder) {
        responder.respond(self.current(&names));
    }

    fn set(&self, _client: AnyClient, _params: Vec<Parameter>, _id: Option<String>, responder: SetParametersResponder) {
        responder.respond(Vec::new());
    }
}

/// A viewer's call of a line's `reset` service, for the node's task to carry out and answer.
pub(super) struct ResetCall {
    pub(super) line: usize,
    pub(super) seed: Option<u64>,
    responder: Responder,
}

impl ResetCall {
    /// Answers the call with the line's ResetLine response, in CDR as over ROS.
    pub(super) fn answer(self, response: &ResetLineResponse) {
        self.responder.respond_ok(cdr(response));
    }
}

/// The requests of the viewers' reset calls, as the node waits on them.
pub(super) type ResetCalls = UnboundedReceiver<ResetCall>;

/// The `reset` service of line `index`, named as its ROS service.
fn reset_service(name: &str, index: usize, calls: UnboundedSender<ResetCall>) -> Option<Service> {
    let part = |t: &str| Some(Schema::new(t, "ros2msg", ros2msg::schema(t)?.into_bytes()));
    let schema = ServiceSchema::new("sorting_line_interfaces/srv/ResetLine")
        .with_request("cdr", part("sorting_line_interfaces/srv/ResetLine_Request")?)
        .with_response("cdr", part("sorting_line_interfaces/srv/ResetLine_Response")?);
    Some(Service::builder(name, schema).handler(ResetHandler { index, calls }))
}

/// Decodes a call (a malformed one is answered with an error at once) and hands it to the node.
struct ResetHandler {
    index: usize,
    calls: UnboundedSender<ResetCall>,
}

impl foxglove::websocket::service::Handler for ResetHandler {
    fn call(&self, request: Request, responder: Responder) {
        let payload = request.payload();
        let decoded = (payload.len() >= 4 && request.encoding() == "cdr")
            .then(|| rustdds::RepresentationIdentifier::from_bytes(&payload[..2]).ok())
            .flatten()
            .and_then(|rep| {
                rustdds::serialization::deserialize_from_cdr_with_rep_id::<ResetLineRequest>(&payload[4..], rep).ok()
            });
        let Some((request, _)) = decoded else {
            responder.respond_err("not a ResetLine request in CDR".to_string());
            return;
        };
        let call = ResetCall { line: self.index, seed: request.has_seed.then_some(request.seed), responder };
        if let Err(e) = self.calls.unbounded_send(call) {
            e.into_inner().responder.respond_err("the node is shutting down".to_string());
        }
    }
}

/// The CDR bytes DDS carries for `message`: the encapsulation header (CDR little-endian) and
/// the body, as ros2-client's publisher writes them.
pub(super) fn cdr<M: Serialize>(message: &M) -> Vec<u8> {
    let mut bytes = rustdds::RepresentationIdentifier::CDR_LE.to_bytes().to_vec();
    bytes.extend([0, 0]);
    if let Err(e) =
        rustdds::serialization::to_writer_with_rep_id(&mut bytes, message, rustdds::RepresentationIdentifier::CDR_LE)
    {
        // Our plain mirror types always serialise; say so loudly if one ever does not.
        super::log::log("ERROR", format!("live view: cannot serialise a message: {e:?}"));
    }
    bytes
}

/// The simulated time a message describes, in ns: every message the node publishes opens with a
/// builtin_interfaces/Time (its header's stamp, or /clock's clock), the 8 bytes after the
/// encapsulation header (int32 sec, uint32 nanosec, little-endian).
fn stamp_ns(cdr: &[u8]) -> u64 {
    let word = |at: usize| cdr.get(at..at + 4).map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    u64::from(word(4)) * 1_000_000_000 + u64::from(word(8))
}

impl LiveView {
    /// Starts the server on `address`; fails, naming the address, if it cannot listen there (a
    /// port in use, an address that is not this host's).
    /// `lines`: each hosted line's `reset` service name.
    pub(super) fn start(
        address: SocketAddr,
        name: &str,
        parameters: ParameterValues,
        lines: &[String],
    ) -> Result<(Self, ResetCalls), String> {
        let context = Context::new();
        let latest: Latest = Arc::default();
        let listener = Arc::new(Listener { context: Arc::clone(&context), latest: Arc::clone(&latest) });
        let host = match address {
            SocketAddr::V4(a) => a.ip().to_string(),
            SocketAddr::V6(a) => format!("[{}]", a.ip()),
        };
        let (calls, reset_calls) = unbounded();
        let services = lines.iter().enumerate().filter_map(|(k, name)| reset_service(name, k, calls.clone()));
        let handle = WebSocketServer::new()
            .name(name)
            .context(&context)
            .bind(host, address.port())
            .capabilities([Capability::Time])
            .supported_encodings(["cdr"])
            .message_backlog_size(VIEWER_BACKLOG)
            .listener(listener)
            .parameter_handler(Arc::new(Parameters { values: parameters }))
            .services(services)
            .start_blocking()
            .map_err(|e| {
                format!(
                    "parameter foxglove = {address}: cannot listen there ({e}): allowed {}",
                    crate::ros::params::FOXGLOVE_ALLOWED
                )
            })?;
        let bound = SocketAddr::new(address.ip(), handle.port());
        let handle = Arc::new(handle);
        let (queue, outgoing) = sync_channel(QUEUE);
        let counts = Arc::new(Counts::default());
        let forwarder = {
            let (counts, server) = (Arc::clone(&counts), Arc::clone(&handle));
            std::thread::Builder::new()
                .name("foxglove-forward".into())
                .spawn(move || forward(&outgoing, &counts, &server))
                .map_err(|e| format!("live view: cannot start its thread: {e}"))?
        };
        let live = LiveView {
            address: bound,
            context,
            handle: Some(handle),
            channels: RefCell::default(),
            latest,
            queue: Some(queue),
            counts,
            forwarder: Some(forwarder),
        };
        Ok((live, reset_calls))
    }

    /// Where it listens (the port the system chose, for port 0).
    pub(super) fn address(&self) -> SocketAddr {
        self.address
    }

    /// The channel of `topic` (created, and advertised, the first time, with the schema and
    /// message encoding `describe` gives).
    fn channel(
        &self,
        topic: &str,
        describe: impl FnOnce() -> Option<(Schema, &'static str)>,
    ) -> Option<Arc<RawChannel>> {
        if let Some(channel) = self.channels.borrow().get(topic) {
            return Some(Arc::clone(channel));
        }
        let (schema, encoding) = describe()?;
        let built =
            ChannelBuilder::new(topic).context(&self.context).message_encoding(encoding).schema(schema).build_raw();
        match built {
            Ok(channel) => {
                self.channels.borrow_mut().insert(topic.to_string(), Arc::clone(&channel));
                Some(channel)
            }
            Err(e) => {
                super::log::log("WARN", format!("live view: cannot create channel {topic}: {e}"));
                None
            }
        }
    }

    /// Offers `message` (of ROS type `ros_type`) on `topic`: its CDR becomes the channel's latest
    /// and goes to the server if a viewer subscribed. Never blocks.
    pub(super) fn offer<M: Serialize>(&self, topic: &str, ros_type: &str, message: &M) {
        let describe = || Some((Schema::new(ros_type, "ros2msg", ros2msg::schema(ros_type)?.into_bytes()), "cdr"));
        let Some(channel) = self.channel(topic, describe) else { return };
        let bytes = cdr(message);
        let time = stamp_ns(&bytes);
        if ros_type == "rosgraph_msgs/msg/Clock" {
            self.enqueue(Outgoing::Time(time));
        }
        self.send(channel, bytes, time);
    }

    /// Offers the scene of line `index` (in `namespace`) at its current tick on `topic` (a
    /// `foxglove.SceneUpdate`, protobuf, as the Foxglove SDK encodes it).
    pub(super) fn offer_scene(&self, topic: &str, host: &HostedLine, index: usize, namespace: &str) {
        let describe = || Some((SceneUpdate::get_schema()?, "protobuf"));
        let Some(channel) = self.channel(topic, describe) else { return };
        let mut bytes = Vec::new();
        if let Err(e) = scene::scene(host, index, namespace).encode(&mut bytes) {
            super::log::log("ERROR", format!("live view: cannot encode the scene: {e}"));
            return;
        }
        self.send(channel, bytes, u64::try_from(host.stamp().nanos()).unwrap_or_default());
    }

    /// `bytes` become the channel's latest and go to the server if a viewer subscribed.
    ///
    /// Under the lock of the latest messages, which a new subscription's `on_subscribe` takes
    /// too: the server registers a subscription before it calls that, so a message is either
    /// the latest it then sends or finds the subscriber registered and is queued for it (a
    /// viewer subscribing while a message is offered may get it twice, never not at all).
    fn send(&self, channel: Arc<RawChannel>, bytes: Vec<u8>, time: u64) {
        let id = u64::from(channel.id());
        let mut latest = self.latest.lock().unwrap_or_else(|p| p.into_inner());
        if channel.has_sinks() {
            latest.insert(id, (bytes.clone(), time));
            self.enqueue(Outgoing::Message(channel, bytes, time));
        } else {
            latest.insert(id, (bytes, time));
        }
    }

    fn enqueue(&self, item: Outgoing) {
        let Some(queue) = &self.queue else { return };
        match queue.try_send(item) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.counts.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// The live view's status on /diagnostics.
    pub(super) fn status(&self) -> DiagnosticStatus {
        let viewers = self.handle.as_ref().map_or(0, |h| h.client_count());
        let dropped = self.counts.dropped.load(Ordering::Relaxed);
        let kv = |key: &str, value: String| KeyValue { key: key.to_string(), value };
        DiagnosticStatus {
            level: u8::from(dropped > 0),
            name: "sorting_line: foxglove".to_string(),
            message: format!("ws://{}, {viewers} viewer(s)", self.address),
            hardware_id: String::new(),
            values: vec![
                kv("address", format!("ws://{}", self.address)),
                kv("viewers", viewers.to_string()),
                kv("channels", self.channels.borrow().len().to_string()),
                kv("messages_sent", self.counts.sent.load(Ordering::Relaxed).to_string()),
                kv("dropped_queue_full", dropped.to_string()),
                kv("client_messages_refused", refused_client_messages().to_string()),
                kv("viewer_outbox_full_reports", outbox_full_reports().to_string()),
            ],
        }
    }
}

impl Drop for LiveView {
    /// The queue closes (the forwarding thread ends after what it holds), then the server stops.
    fn drop(&mut self) {
        self.queue = None;
        if let Some(forwarder) = self.forwarder.take() {
            let _ = forwarder.join();
        }
        if let Some(handle) = self.handle.take().and_then(Arc::into_inner) {
            // Viewers get the server's goodbye; one that has stopped reading would hold a full
            // wait for as long as its connection lives, so the node leaves without it after
            // STOP_WAIT (its task ends with the process).
            let shutdown = handle.stop();
            let (done, finished) = std::sync::mpsc::channel();
            let waiter = std::thread::Builder::new().name("foxglove-stop".into()).spawn(move || {
                shutdown.wait_blocking();
                let _ = done.send(());
            });
            if waiter.is_ok() && finished.recv_timeout(STOP_WAIT).is_err() {
                super::log::log("WARN", "live view: a viewer did not take the goodbye in time; leaving without it");
            }
        }
    }
}

/// The forwarding thread: hands each message to the server (which queues it per subscribed
/// viewer, never waiting for one) until the node's side closes the queue.
fn forward(outgoing: &Receiver<Outgoing>, counts: &Counts, server: &WebSocketServerHandle) {
    while let Ok(item) = outgoing.recv() {
        match item {
            Outgoing::Message(channel, bytes, t) => {
                channel.log_with_meta(&bytes, PartialMetadata::with_log_time(t));
                counts.sent.fetch_add(1, Ordering::Relaxed);
            }
            Outgoing::Time(t) => server.broadcast_time(t),
        }
    }
}
