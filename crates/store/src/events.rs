//! Session events across replicas: Redis pub/sub under the store's key
//! prefix. A replica publishes each committed update of a session on the
//! session's channel (`{prefix}:ev:{tenant}:{id}`, escaped as the keys are);
//! a replica with watchers of a session subscribes to its channel. The
//! payload is opaque here (the service encodes it).
//!
//! Behind Sentinel the listener subscribes on the primary the sentinels name
//! at each (re)connection, so it follows a failover: the old primary's death
//! closes the subscription, and the next connection asks the sentinels.
//!
//! Pub/sub delivers at most once: a message published while a subscriber's
//! connection is down is lost to it. [`Feed::Resync`] says so after every
//! reconnection, and the watchers above then read the stored session again
//! (which is the truth; the events only say when to look).

use std::{collections::HashSet, sync::Arc, time::Duration};

use redis::Client;
use tokio::sync::mpsc;
use tokio_stream::StreamExt;

/// What the listener hands on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Feed {
    /// One published payload, in the order Redis delivered it.
    Message(Vec<u8>),
    /// The subscription was lost and is back: messages in between may be
    /// missing.
    Resync,
}

enum Command {
    Subscribe(String),
    Unsubscribe(String),
}

/// Subscribes and unsubscribes channels of the listener task (cheap to clone;
/// the task ends when every handle is dropped).
#[derive(Clone)]
pub struct EventListener {
    commands: mpsc::UnboundedSender<Command>,
}

impl EventListener {
    pub fn subscribe(&self, channel: String) {
        let _ = self.commands.send(Command::Subscribe(channel));
    }

    pub fn unsubscribe(&self, channel: String) {
        let _ = self.commands.send(Command::Unsubscribe(channel));
    }
}

/// How often the listener pings Redis on a quiet subscription, to find a dead
/// connection that did not close.
const PING_EVERY: Duration = Duration::from_secs(10);
const RETRY_MIN: Duration = Duration::from_millis(100);
const RETRY_MAX: Duration = Duration::from_secs(2);

/// Where the listener connects.
#[derive(Clone)]
pub(crate) enum Source {
    /// One server.
    Server(Box<Client>),
    /// The primary the sentinels name, asked at each connection.
    Sentinel(Arc<crate::sentinel::Sentinel>),
}

impl Source {
    async fn client(&self) -> Option<Client> {
        match self {
            Self::Server(c) => Some(Client::clone(c)),
            Self::Sentinel(s) => s.primary_client().await.ok(),
        }
    }
}

/// Starts the listener task on a dedicated pub/sub connection to `source`
/// (reconnecting by itself, every command bounded by `timeout`); its feed
/// holds at most `capacity` undelivered messages (then the task waits, and
/// Redis buffers, up to its `client-output-buffer-limit pubsub`, after which
/// it drops the connection: a `Resync`).
pub(crate) fn listen(
    source: Source,
    timeout: Duration,
    capacity: usize,
) -> (EventListener, mpsc::Receiver<Feed>) {
    let (commands, rx) = mpsc::unbounded_channel();
    let (feed, out) = mpsc::channel(capacity.max(1));
    tokio::spawn(run(source, timeout, rx, feed));
    (EventListener { commands }, out)
}

async fn run(
    source: Source,
    timeout: Duration,
    mut commands: mpsc::UnboundedReceiver<Command>,
    feed: mpsc::Sender<Feed>,
) {
    let mut channels: HashSet<String> = HashSet::new();
    let mut connected_before = false;
    let mut delay = RETRY_MIN;
    loop {
        match connected(&source, timeout, &channels).await {
            Ok((mut sink, mut stream)) => {
                delay = RETRY_MIN;
                if connected_before && feed.send(Feed::Resync).await.is_err() {
                    return;
                }
                connected_before = true;
                let mut ping = tokio::time::interval(PING_EVERY);
                ping.tick().await;
                loop {
                    tokio::select! {
                        command = commands.recv() => {
                            let ok = match command {
                                None => return,
                                Some(Command::Subscribe(c)) => {
                                    let ok = bounded(timeout, sink.subscribe(&c)).await;
                                    channels.insert(c);
                                    ok
                                }
                                Some(Command::Unsubscribe(c)) => {
                                    channels.remove(&c);
                                    bounded(timeout, sink.unsubscribe(&c)).await
                                }
                            };
                            if !ok {
                                break;
                            }
                        }
                        message = stream.next() => match message {
                            None => break,
                            Some(m) => {
                                let payload = m.get_payload_bytes().to_vec();
                                if feed.send(Feed::Message(payload)).await.is_err() {
                                    return;
                                }
                            }
                        },
                        _ = ping.tick() => {
                            if !bounded(timeout, sink.ping::<String>()).await {
                                break;
                            }
                        }
                    }
                }
            }
            Err(()) => {
                // Commands that arrived while down still change the set.
                while let Ok(command) = commands.try_recv() {
                    match command {
                        Command::Subscribe(c) => {
                            channels.insert(c);
                        }
                        Command::Unsubscribe(c) => {
                            channels.remove(&c);
                        }
                    }
                }
                if commands.is_closed() {
                    return;
                }
            }
        }
        tokio::time::sleep(delay).await;
        delay = (delay * 2).min(RETRY_MAX);
    }
}

async fn connected(
    source: &Source,
    timeout: Duration,
    channels: &HashSet<String>,
) -> Result<(redis::aio::PubSubSink, redis::aio::PubSubStream), ()> {
    let client = source.client().await.ok_or(())?;
    let pubsub = match tokio::time::timeout(timeout, client.get_async_pubsub()).await {
        Ok(Ok(p)) => p,
        _ => return Err(()),
    };
    let (mut sink, stream) = pubsub.split();
    for c in channels {
        if !bounded(timeout, sink.subscribe(c)).await {
            return Err(());
        }
    }
    Ok((sink, stream))
}

async fn bounded<T>(
    timeout: Duration,
    f: impl std::future::Future<Output = redis::RedisResult<T>>,
) -> bool {
    matches!(tokio::time::timeout(timeout, f).await, Ok(Ok(_)))
}
