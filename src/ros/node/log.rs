//! How the node writes its log lines (as rcl formats them, on stderr) and the values in them:
//! topics, clients, stamps; and where its libraries' `log` records go: the DDS stack's to
//! env_logger when RUST_LOG asks (RUST_LOG=rustdds=debug), and the Foxglove server's refusals of
//! client messages counted for /diagnostics.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::ros::messages::Time;
use crate::ros::names::NODE_NAME;
use crate::ros::protocol::Client;

pub(super) fn log(level: &str, message: impl AsRef<str>) {
    eprintln!("[{level}] [{NODE_NAME}]: {}", message.as_ref());
}

/// A topic of the line in `namespace`, for messages.
pub(super) fn show_topic(namespace: &str, relative: &str) -> String {
    format!("{}/{relative}", namespace.trim_end_matches('/'))
}

pub(super) fn show_client(client: Option<Client>) -> String {
    client.map_or_else(|| "none".to_string(), |c| c.iter().map(|b| format!("{b:02x}")).collect())
}

pub(super) fn show_stamp(t: Time) -> String {
    format!("{}.{:09}", t.sec, t.nanosec)
}

/// Client messages the Foxglove server answered with an error or warning status.
static REFUSED: AtomicU64 = AtomicU64::new(0);

/// Times the Foxglove server reported a viewer's outbox full (it then drops that viewer's
/// oldest messages; it reports at most once per 30 s and does not count the drops).
static OUTBOX_FULL: AtomicU64 = AtomicU64::new(0);

#[cfg_attr(not(feature = "foxglove"), allow(dead_code))]
pub(super) fn refused_client_messages() -> u64 {
    REFUSED.load(Ordering::Relaxed)
}

#[cfg_attr(not(feature = "foxglove"), allow(dead_code))]
pub(super) fn outbox_full_reports() -> u64 {
    OUTBOX_FULL.load(Ordering::Relaxed)
}

/// Every `log` record of the process: counted if it is the Foxglove server answering a client
/// with an error or warning (the crate logs each such answer, at debug level, and offers no
/// counter of its own), then passed to env_logger if RUST_LOG set one up.
struct Records {
    inner: Option<env_logger::Logger>,
}

/// What a record of the Foxglove server says that we count.
enum Counted {
    /// Its answer to a client message it refused: `Sending error to client ...` or `Sending
    /// warning to client ...` (foxglove 0.30, src/websocket/connected_client.rs).
    Refusal,
    /// `outbox for client ... full` (src/websocket/connected_client/send_lossy.rs).
    OutboxFull,
}

fn counted(record: &log::Record) -> Option<Counted> {
    if !record.target().starts_with("foxglove::websocket") {
        return None;
    }
    let text = record.args().to_string();
    if text.starts_with("Sending error to client") || text.starts_with("Sending warning to client") {
        Some(Counted::Refusal)
    } else if text.starts_with("outbox for client") {
        Some(Counted::OutboxFull)
    } else {
        None
    }
}

impl log::Log for Records {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.target().starts_with("foxglove") || self.inner.as_ref().is_some_and(|l| l.enabled(metadata))
    }

    fn log(&self, record: &log::Record) {
        match counted(record) {
            Some(Counted::Refusal) => REFUSED.fetch_add(1, Ordering::Relaxed),
            Some(Counted::OutboxFull) => OUTBOX_FULL.fetch_add(1, Ordering::Relaxed),
            None => 0,
        };
        if let Some(inner) = self.inner.as_ref().filter(|l| l.matches(record)) {
            inner.log(record);
        }
    }

    fn flush(&self) {
        if let Some(inner) = &self.inner {
            inner.flush();
        }
    }
}

/// Sets up where the process's `log` records go: env_logger when RUST_LOG is set (without it
/// env_logger would still print rustdds' error lines, some of them routine), and with the live
/// view on the Foxglove server's debug records too, for the count of refused client messages.
pub(super) fn install_records(live_view: bool) {
    let inner = std::env::var_os("RUST_LOG")
        .is_some()
        .then(|| env_logger::Builder::from_default_env().format_timestamp_micros().build());
    let mut max = inner.as_ref().map_or(log::LevelFilter::Off, env_logger::Logger::filter);
    if live_view {
        max = max.max(log::LevelFilter::Debug);
    } else if inner.is_none() {
        return;
    }
    if log::set_boxed_logger(Box::new(Records { inner })).is_ok() {
        log::set_max_level(max);
    }
}
