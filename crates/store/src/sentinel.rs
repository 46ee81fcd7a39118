//! Redis Sentinel: `redis+sentinel://HOST:PORT[,HOST:PORT…]/MASTER_NAME[/DB]`.
//!
//! The store asks the sentinels in turn for the primary of `MASTER_NAME`
//! (`SENTINEL get-master-addr-by-name`), checks that the address answers
//! `ROLE` as a master, and then talks to it. Any failed command (a
//! connection error, a time-out, a `READONLY` reply from a demoted primary)
//! drops the current primary, so the next command asks the sentinels again:
//! a failover is followed within one command. A command that failed is
//! reported `Unavailable` (the service answers 503/504 "retry with the same
//! sequence"), never as not executed, since it may have run.
//!
//! The store also listens to the sentinels' `+switch-master` (one sentinel
//! at a time, the next one when it goes away): a primary change announced
//! there drops the current primary at once, so the next command goes to the
//! new one without first failing on the old (a manual `SENTINEL FAILOVER`,
//! or a primary that is demoted but still answers reads).
//!
//! `rediss+sentinel://` talks TLS to the sentinels and the primary alike
//! (one CA and client certificate, [`crate::access`]). Credentials
//! (`redis+sentinel://USER:PASSWORD@…` or `FUSION_REDIS_PASSWORD`) are the
//! data servers'; the sentinels are asked without them.

use std::{
    sync::{
        Arc, Mutex, Weak,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::Duration,
};

use redis::{
    Client, Value,
    aio::{ConnectionManager, ConnectionManagerConfig, MultiplexedConnection},
};

use tokio_stream::StreamExt;

use super::{StoreError, access};

pub(crate) const SCHEME: &str = "redis+sentinel://";
pub(crate) const TLS_SCHEME: &str = "rediss+sentinel://";

/// A parsed Sentinel URL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SentinelUrl {
    pub sentinels: Vec<(String, u16)>,
    pub master: String,
    pub db: u32,
}

/// Whether `url` names a Sentinel deployment.
pub fn is_sentinel_url(url: &str) -> bool {
    url.starts_with(SCHEME) || url.starts_with(TLS_SCHEME)
}

fn bad(why: &str) -> StoreError {
    // The URL may hold a password: only its shape is named.
    access::config(
        access::STORE,
        format!(
            "invalid Sentinel URL (redis+sentinel://[USER:PASSWORD@]HOST:PORT[,HOST:PORT…]/MASTER_NAME[/DB]): {why}"
        ),
    )
}

/// Parses `redis[s]+sentinel://[USER:PASSWORD@]HOST:PORT[,HOST:PORT…]/MASTER_NAME[/DB]`
/// and reads the TLS files and credentials it needs.
pub(crate) fn parse(
    url: &str,
    settings: &access::RedisAccessSettings,
) -> Result<(SentinelUrl, access::Access), StoreError> {
    let (rest, tls) = match (url.strip_prefix(SCHEME), url.strip_prefix(TLS_SCHEME)) {
        (Some(rest), _) => (rest, false),
        (None, Some(rest)) => (rest, true),
        (None, None) => {
            return Err(bad(
                "it must start with redis+sentinel:// or rediss+sentinel://",
            ));
        }
    };
    let (hosts, path) = rest
        .split_once('/')
        .ok_or_else(|| bad("no /MASTER_NAME after the sentinels"))?;
    let (user, password, sentinels) = access::parse_hosts(hosts, "sentinel", bad)?;
    let mut parts = path.split('/');
    let master = parts.next().unwrap_or_default();
    if master.is_empty() {
        return Err(bad("the master name is empty"));
    }
    let db = match parts.next() {
        None | Some("") => 0,
        Some(d) => d
            .parse()
            .map_err(|_| bad(&format!("database {d:?} is not a number")))?,
    };
    if parts.next().is_some() {
        return Err(bad("too many path segments"));
    }
    let access = access::Access::new(settings, tls, user, password)?;
    Ok((
        SentinelUrl {
            sentinels,
            master: master.to_string(),
            db,
        },
        access,
    ))
}

/// The primary found through the sentinels, rediscovered after any failure.
pub struct Sentinel {
    url: SentinelUrl,
    access: access::Access,
    timeout: Duration,
    current: Mutex<Option<(ConnectionManager, String)>>,
    last_primary: Mutex<Option<String>>,
    failovers: AtomicU64,
    rediscoveries: AtomicU64,
    /// Set when the primary is dropped after a failure, cleared by the next
    /// command that succeeds.
    failing_over: AtomicBool,
}

impl Sentinel {
    pub(crate) fn new(url: SentinelUrl, access: access::Access, timeout: Duration) -> Self {
        Self {
            url,
            access,
            timeout,
            current: Mutex::new(None),
            last_primary: Mutex::new(None),
            failovers: AtomicU64::new(0),
            rediscoveries: AtomicU64::new(0),
            failing_over: AtomicBool::new(false),
        }
    }

    /// The primary's connection, asking the sentinels when there is none.
    pub async fn conn(&self) -> Result<ConnectionManager, StoreError> {
        if let Some((c, _)) = lock(&self.current).as_ref() {
            return Ok(c.clone());
        }
        let (host, port) = self.discover().await?;
        let addr = format!("{host}:{port}");
        let client = self.access.client(&host, port, i64::from(self.url.db))?;
        let config = ConnectionManagerConfig::new()
            .set_connection_timeout(Some(self.timeout))
            .set_response_timeout(Some(self.timeout))
            .set_number_of_retries(0);
        let conn = ConnectionManager::new_lazy_with_config(client, config)
            .map_err(|e| unavailable(format!("primary {addr}: {e}")))?;
        {
            let mut last = lock(&self.last_primary);
            if last.as_ref().is_some_and(|p| p != &addr) {
                self.failovers.fetch_add(1, Ordering::Relaxed);
            }
            *last = Some(addr.clone());
        }
        *lock(&self.current) = Some((conn.clone(), addr));
        Ok(conn)
    }

    /// A client of the primary the sentinels name now (asked afresh), for a
    /// connection of its own such as the event listener's.
    pub(crate) async fn primary_client(&self) -> Result<Client, StoreError> {
        let (host, port) = self.discover().await?;
        self.access.client(&host, port, i64::from(self.url.db))
    }

    /// Starts following the sentinels' `+switch-master` announcements; the
    /// task ends when the store is dropped.
    pub(crate) fn follow_switches(self: &Arc<Self>) {
        tokio::spawn(follow_switches(Arc::downgrade(self)));
    }

    /// A `+switch-master` announcement: `MASTER OLD_IP OLD_PORT NEW_IP NEW_PORT`.
    fn switched(&self, announcement: &str) {
        let parts: Vec<&str> = announcement.split_whitespace().collect();
        if let [master, _, _, ip, port] = parts[..]
            && master == self.url.master
            && self.primary().is_some_and(|p| p != format!("{ip}:{port}"))
        {
            self.invalidate();
        }
    }

    /// Forgets the primary: the next command asks the sentinels again.
    pub fn invalidate(&self) {
        if lock(&self.current).take().is_some() {
            self.rediscoveries.fetch_add(1, Ordering::Relaxed);
            self.failing_over.store(true, Ordering::Relaxed);
        }
    }

    /// A command succeeded on the primary: any failover is over.
    pub fn confirm(&self) {
        self.failing_over.store(false, Ordering::Relaxed);
    }

    /// Whether the primary was lost and no command has succeeded since.
    pub fn failing_over(&self) -> bool {
        self.failing_over.load(Ordering::Relaxed)
    }

    /// The primary in use (`host:port`), if any.
    pub fn primary(&self) -> Option<String> {
        lock(&self.current).as_ref().map(|(_, a)| a.clone())
    }

    /// Primary changes seen (a failover followed).
    pub fn failovers(&self) -> u64 {
        self.failovers.load(Ordering::Relaxed)
    }

    /// Times the primary was dropped after a failure and asked for again.
    pub fn rediscoveries(&self) -> u64 {
        self.rediscoveries.load(Ordering::Relaxed)
    }

    /// At start: asks the sentinels once and refuses a configuration error
    /// (a failed TLS handshake, credentials the primary rejects). No answer
    /// at all is not one: the store starts degraded and asks again later.
    pub(crate) async fn check(&self) -> Result<(), StoreError> {
        match self.discover().await {
            Err(e @ StoreError::Config { .. }) => Err(e),
            _ => Ok(()),
        }
    }

    async fn discover(&self) -> Result<(String, u16), StoreError> {
        let mut problems = Vec::new();
        for (host, port) in &self.url.sentinels {
            match self.ask(host, *port).await {
                Ok(addr) => return Ok(addr),
                Err(Asked::Config(e)) => return Err(e),
                Err(Asked::Failed(why)) => problems.push(format!("sentinel {host}:{port}: {why}")),
            }
        }
        Err(unavailable(format!(
            "no primary for master {:?} from FUSION_SESSION_STORE's sentinels: {}",
            self.url.master,
            problems.join("; ")
        )))
    }

    async fn ask(&self, host: &str, port: u16) -> Result<(String, u16), Asked> {
        let client = self.access.sentinel_client(host, port)?;
        let what = format!("sentinel {host}:{port}");
        let answer = self
            .query(&client, &what, |mut c| async move {
                redis::cmd("SENTINEL")
                    .arg("get-master-addr-by-name")
                    .arg(&self.url.master)
                    .query_async::<Option<(String, u16)>>(&mut c)
                    .await
            })
            .await?;
        let Some((ip, p)) = answer else {
            return Err(Asked::Failed(format!(
                "unknown master name {:?}",
                self.url.master
            )));
        };
        let client = self.access.client(&ip, p, 0)?;
        let what = format!("primary {ip}:{p}");
        let role = self
            .query(&client, &what, |mut c| async move {
                redis::cmd("ROLE").query_async::<Vec<Value>>(&mut c).await
            })
            .await?;
        let role: Option<String> = role
            .into_iter()
            .next()
            .and_then(|v| redis::from_redis_value(v).ok());
        if role.as_deref() == Some("master") {
            Ok((ip, p))
        } else {
            Err(Asked::Failed(format!(
                "{what} is not a master (ROLE {role:?})"
            )))
        }
    }

    /// One command on a fresh connection, within the timeout.
    async fn query<T, F, Fut>(&self, client: &Client, what: &str, command: F) -> Result<T, Asked>
    where
        F: FnOnce(MultiplexedConnection) -> Fut,
        Fut: std::future::Future<Output = redis::RedisResult<T>>,
    {
        let attempt = async {
            let c = client.get_multiplexed_async_connection().await?;
            command(c).await
        };
        match tokio::time::timeout(self.timeout, attempt).await {
            Err(_) => Err(Asked::Failed(format!("{what}: no answer in time"))),
            Ok(Ok(v)) => Ok(v),
            Ok(Err(e)) => Err(match access::misconfiguration(&e, what) {
                Some(config) => Asked::Config(config),
                None => Asked::Failed(format!("{what}: {e}")),
            }),
        }
    }
}

/// Why one sentinel gave no primary.
enum Asked {
    /// A setting is wrong: stop asking.
    Config(StoreError),
    /// Try the next sentinel.
    Failed(String),
}

impl From<StoreError> for Asked {
    fn from(e: StoreError) -> Self {
        Self::Config(e)
    }
}

/// How long a quiet `+switch-master` subscription waits before checking
/// that the store still exists; the pause before the next sentinel.
const SWITCH_IDLE: Duration = Duration::from_secs(5);
const SWITCH_RETRY: Duration = Duration::from_millis(500);

/// Subscribes to `+switch-master` on each sentinel in turn while the store
/// lives.
async fn follow_switches(sentinel: Weak<Sentinel>) {
    for turn in 0usize.. {
        let Some(s) = sentinel.upgrade() else { return };
        let (host, port) = s.url.sentinels[turn % s.url.sentinels.len()].clone();
        let (client, timeout) = (s.access.sentinel_client(&host, port), s.timeout);
        drop(s);
        let subscribed = match client {
            Ok(client) => tokio::time::timeout(timeout, async {
                let mut pubsub = client.get_async_pubsub().await?;
                pubsub.subscribe("+switch-master").await?;
                Ok::<_, redis::RedisError>(pubsub)
            })
            .await
            .ok()
            .and_then(Result::ok),
            Err(_) => None,
        };
        if let Some(mut pubsub) = subscribed {
            let mut messages = pubsub.on_message();
            loop {
                match tokio::time::timeout(SWITCH_IDLE, messages.next()).await {
                    Ok(Some(m)) => match sentinel.upgrade() {
                        Some(s) => s.switched(&String::from_utf8_lossy(m.get_payload_bytes())),
                        None => return,
                    },
                    Ok(None) => break,
                    Err(_) if sentinel.strong_count() == 0 => return,
                    Err(_) => {}
                }
            }
        }
        tokio::time::sleep(SWITCH_RETRY).await;
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn unavailable(reason: String) -> StoreError {
    StoreError::Unavailable { reason }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(url: &str) -> Result<SentinelUrl, StoreError> {
        super::parse(url, &access::RedisAccessSettings::default()).map(|(u, _)| u)
    }

    #[test]
    fn parses_sentinel_urls() {
        let u = parse("redis+sentinel://127.0.0.1:26450,localhost:26451/mymaster/2").unwrap();
        assert_eq!(
            u.sentinels,
            vec![("127.0.0.1".into(), 26450), ("localhost".into(), 26451)]
        );
        assert_eq!(u.master, "mymaster");
        assert_eq!(u.db, 2);
        assert_eq!(parse("redis+sentinel://h:1/m").unwrap().db, 0);
        let u = parse("redis+sentinel://app:p%40ss@h:1,g:2/m").unwrap();
        assert_eq!(u.sentinels.len(), 2);
        assert!(parse("rediss+sentinel://h:1/m").is_ok());
    }

    #[test]
    fn bad_sentinel_urls_name_the_setting() {
        for url in [
            "redis+sentinel://h:1",
            "redis+sentinel://h/m",
            "redis+sentinel://h:x/m",
            "redis+sentinel://h:1/",
            "redis+sentinel://h:1/m/x",
            "redis+sentinel://h:1/m/0/z",
            "redis+sentinel://u:secret@h/m",
            "redis+sentinel://u:secret%zz@h:1/m",
        ] {
            let e = parse(url).unwrap_err().to_string();
            assert!(e.contains("FUSION_SESSION_STORE"), "{url}: {e}");
            assert!(!e.contains("secret"), "{url}: {e}");
        }
    }
}
