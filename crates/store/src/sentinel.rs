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

use std::{
    sync::{
        Mutex,
        atomic::{AtomicU64, Ordering},
    },
    time::Duration,
};

use redis::{
    Client, Value,
    aio::{ConnectionManager, ConnectionManagerConfig},
};

use super::StoreError;

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

fn bad(url: &str, why: &str) -> StoreError {
    // The URL may hold a password: only its shape is named.
    let _ = url;
    StoreError::Unavailable {
        reason: format!(
            "invalid FUSION_SESSION_STORE Sentinel URL (redis+sentinel://HOST:PORT[,HOST:PORT…]/MASTER_NAME[/DB]): {why}"
        ),
    }
}

/// Parses `redis+sentinel://HOST:PORT[,HOST:PORT…]/MASTER_NAME[/DB]`.
pub fn parse(url: &str) -> Result<SentinelUrl, StoreError> {
    if url.starts_with(TLS_SCHEME) {
        return Err(bad(
            url,
            "rediss+sentinel:// (TLS) is not supported by this build yet",
        ));
    }
    let rest = url
        .strip_prefix(SCHEME)
        .ok_or_else(|| bad(url, "it must start with redis+sentinel://"))?;
    let (hosts, path) = rest
        .split_once('/')
        .ok_or_else(|| bad(url, "no /MASTER_NAME after the sentinels"))?;
    if hosts.contains('@') {
        return Err(bad(
            url,
            "credentials in a Sentinel URL are not supported yet",
        ));
    }
    let mut sentinels = Vec::new();
    for h in hosts.split(',') {
        let (host, port) = h
            .rsplit_once(':')
            .ok_or_else(|| bad(url, &format!("sentinel {h:?} is not HOST:PORT")))?;
        let port: u16 = port
            .parse()
            .map_err(|_| bad(url, &format!("sentinel {h:?} has no valid port")))?;
        if host.is_empty() || port == 0 {
            return Err(bad(url, &format!("sentinel {h:?} is not HOST:PORT")));
        }
        sentinels.push((host.to_string(), port));
    }
    let mut parts = path.split('/');
    let master = parts.next().unwrap_or_default();
    if master.is_empty() {
        return Err(bad(url, "the master name is empty"));
    }
    let db = match parts.next() {
        None | Some("") => 0,
        Some(d) => d
            .parse()
            .map_err(|_| bad(url, &format!("database {d:?} is not a number")))?,
    };
    if parts.next().is_some() {
        return Err(bad(url, "too many path segments"));
    }
    Ok(SentinelUrl {
        sentinels,
        master: master.to_string(),
        db,
    })
}

/// The primary found through the sentinels, rediscovered after any failure.
pub struct Sentinel {
    url: SentinelUrl,
    timeout: Duration,
    current: Mutex<Option<(ConnectionManager, String)>>,
    last_primary: Mutex<Option<String>>,
    failovers: AtomicU64,
    rediscoveries: AtomicU64,
}

impl Sentinel {
    pub fn new(url: SentinelUrl, timeout: Duration) -> Self {
        Self {
            url,
            timeout,
            current: Mutex::new(None),
            last_primary: Mutex::new(None),
            failovers: AtomicU64::new(0),
            rediscoveries: AtomicU64::new(0),
        }
    }

    /// The primary's connection, asking the sentinels when there is none.
    pub async fn conn(&self) -> Result<ConnectionManager, StoreError> {
        if let Some((c, _)) = lock(&self.current).as_ref() {
            return Ok(c.clone());
        }
        let addr = self.discover().await?;
        let client = Client::open(format!("redis://{addr}/{}", self.url.db))
            .map_err(|e| unavailable(format!("primary {addr}: {e}")))?;
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

    /// Forgets the primary: the next command asks the sentinels again.
    pub fn invalidate(&self) {
        if lock(&self.current).take().is_some() {
            self.rediscoveries.fetch_add(1, Ordering::Relaxed);
        }
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

    async fn discover(&self) -> Result<String, StoreError> {
        let mut problems = Vec::new();
        for (host, port) in &self.url.sentinels {
            match self.ask(host, *port).await {
                Ok(addr) => return Ok(addr),
                Err(why) => problems.push(format!("sentinel {host}:{port}: {why}")),
            }
        }
        Err(unavailable(format!(
            "no primary for master {:?} from FUSION_SESSION_STORE's sentinels: {}",
            self.url.master,
            problems.join("; ")
        )))
    }

    async fn ask(&self, host: &str, port: u16) -> Result<String, String> {
        let client = Client::open(format!("redis://{host}:{port}/")).map_err(|e| e.to_string())?;
        let answer = tokio::time::timeout(self.timeout, async {
            let mut c = client.get_multiplexed_async_connection().await?;
            redis::cmd("SENTINEL")
                .arg("get-master-addr-by-name")
                .arg(&self.url.master)
                .query_async::<Option<(String, String)>>(&mut c)
                .await
        })
        .await
        .map_err(|_| "no answer in time".to_string())?
        .map_err(|e| e.to_string())?;
        let Some((ip, p)) = answer else {
            return Err(format!("unknown master name {:?}", self.url.master));
        };
        let addr = format!("{ip}:{p}");
        let client = Client::open(format!("redis://{addr}/")).map_err(|e| e.to_string())?;
        let role = tokio::time::timeout(self.timeout, async {
            let mut c = client.get_multiplexed_async_connection().await?;
            redis::cmd("ROLE").query_async::<Vec<Value>>(&mut c).await
        })
        .await
        .map_err(|_| format!("primary {addr} did not answer ROLE in time"))?
        .map_err(|e| format!("primary {addr}: {e}"))?;
        let role: Option<String> = role
            .into_iter()
            .next()
            .and_then(|v| redis::from_redis_value(v).ok());
        if role.as_deref() == Some("master") {
            Ok(addr)
        } else {
            Err(format!("{addr} is not a master (ROLE {role:?})"))
        }
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
            "redis+sentinel://u:secret@h:1/m",
        ] {
            let e = parse(url).unwrap_err().to_string();
            assert!(e.contains("FUSION_SESSION_STORE"), "{url}: {e}");
            assert!(!e.contains("secret"), "{url}: {e}");
        }
    }
}
