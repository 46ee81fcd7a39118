//! The Redis session store, shared by every replica of the service.
//!
//! Keys (tenant and id escaped by [`escape`], so `:` in them cannot make two
//! names collide):
//! - `{prefix}:{tenant}:s:{id}` — a hash, `v` the version in decimal, `d` the
//!   data, `k` the session's kind (absent in sessions written before kinds
//!   existed: `correlation`), expiring after the session's TTL (PEXPIRE);
//! - `{prefix}:{tenant}:idx` — a sorted set of the tenant's escaped ids scored
//!   by their expiry time in Unix milliseconds (Redis's clock), for counting
//!   and listing live sessions; expired members are removed before use.
//!
//! On a Redis Cluster (`redis+cluster://`) the tenant is a hash tag:
//! `{prefix}:{{tenant}}:s:{id}` and `{prefix}:{{tenant}}:idx`, so a tenant's
//! keys share one slot and tenants spread over the primaries.
//!
//! `create`, `compare_and_set`, `delete` and `list` are Lua scripts, so each
//! is atomic. The list script reads the session keys it finds in the index,
//! which are in the index's slot (the tenant's hash tag) on a Cluster.
//! Every command is bounded by the configured timeout and fails with
//! `Unavailable`; the connections reconnect by themselves when Redis comes
//! back.

use std::{future::Future, sync::Arc, time::Duration};

use redis::{
    Client, Cmd, Pipeline, RedisError, RedisFuture, Script, Value,
    aio::{ConnectionLike, ConnectionManager, ConnectionManagerConfig},
    cluster_async::ClusterConnection,
};

use super::{
    CasOutcome, Compacted, Expected, SessionMeta, StoreError, StoreSettings, Stored, Write, access,
    ttl_ms,
};

pub struct RedisStore {
    /// For the event listener's own pub/sub connection (a single server).
    client: Option<Client>,
    conn: Option<ConnectionManager>,
    /// Set for a `redis+sentinel://` URL: the primary is found through it.
    sentinel: Option<Arc<super::sentinel::Sentinel>>,
    /// A single server's `host:port` (no credentials), for health.
    server: String,
    /// Set for a `redis+cluster://` URL; keys then carry the tenant as a
    /// hash tag.
    cluster: Option<Arc<super::cluster::Cluster>>,
    prefix: String,
    /// Replicas that must acknowledge each write (`WAIT`), 0 for none.
    wait_replicas: usize,
    max_sessions_per_tenant: usize,
    timeout: Duration,
    create: Script,
    write: Script,
    compact: Script,
    delete: Script,
    list: Script,
}

/// Redis's clock in Unix milliseconds, as a Lua expression's prelude.
pub(crate) const NOW_MS: &str = r"
local t = redis.call('TIME')
local now = tonumber(t[1]) * 1000 + math.floor(tonumber(t[2]) / 1000)
";

/// Keeps the index alive at least as long as the session just written.
pub(crate) const EXTEND_INDEX: &str = r"
if redis.call('PTTL', KEYS[2]) < tonumber(ARGV[3]) then
  redis.call('PEXPIRE', KEYS[2], ARGV[3])
end
";

/// KEYS: session, index. ARGV: escaped id, data, ttl ms, limit, kind.
/// Returns 1 created, -1 exists, -2 too many sessions.
const CREATE: &str = r"
redis.call('ZREMRANGEBYSCORE', KEYS[2], '-inf', now)
if redis.call('EXISTS', KEYS[1]) == 1 then return -1 end
if redis.call('ZCARD', KEYS[2]) >= tonumber(ARGV[4]) then return -2 end
redis.call('HSET', KEYS[1], 'v', '1', 'd', ARGV[2], 'k', ARGV[5])
redis.call('PEXPIRE', KEYS[1], ARGV[3])
redis.call('ZADD', KEYS[2], now + tonumber(ARGV[3]), ARGV[1])
";

/// KEYS: session, index. ARGV: escaped id, payload, ttl ms, expected
/// version, new version, expected token ('' for any), new token, mode
/// ('s' a snapshot, 'a' a log entry). Returns {0, ''} missing, {1, new}
/// stored, {2, current} conflict.
///
/// A session is a hash: `v` its version, `t` the token of the write that
/// made it (absent: 0), `k` its kind, `d` a snapshot, `b` the snapshot's
/// version (absent: `v`, no log), `e<n>` the log entry that made
/// version n, for n in b+1..=v, and `w<n>` the token of the write that
/// appended it (for [`COMPACT`]). A snapshot deletes the entries.
const WRITE: &str = r"
local f = redis.call('HMGET', KEYS[1], 'v', 't', 'b')
local v = f[1]
if not v then return {0, ''} end
if v ~= ARGV[4] then return {2, v} end
if ARGV[6] ~= '' and (f[2] or '0') ~= ARGV[6] then return {2, v} end
if ARGV[8] == 's' then
  for n = tonumber(f[3] or v) + 1, tonumber(v) do
    redis.call('HDEL', KEYS[1], 'e' .. n, 'w' .. n)
  end
  redis.call('HSET', KEYS[1], 'v', ARGV[5], 'd', ARGV[2], 't', ARGV[7], 'b', ARGV[5])
else
  if not f[3] then redis.call('HSET', KEYS[1], 'b', v) end
  redis.call('HSET', KEYS[1], 'v', ARGV[5], 'e' .. ARGV[5], ARGV[2], 't', ARGV[7],
    'w' .. ARGV[5], ARGV[7])
end
redis.call('PEXPIRE', KEYS[1], ARGV[3])
redis.call('ZADD', KEYS[2], now + tonumber(ARGV[3]), ARGV[1])
";

/// KEYS: session. ARGV: the snapshot's version, the token of the write
/// that made it, the snapshot. Returns 0 missing, 1 stored, 2 stale (the
/// log does not hold that version made by that token). The snapshot
/// replaces `d` and the entries up to its version; `v`, `t`, the later
/// entries and the TTL stay.
const COMPACT: &str = r"
local f = redis.call('HMGET', KEYS[1], 'v', 'b')
if not f[1] then return 0 end
local v = tonumber(f[1])
local b = tonumber(f[2] or f[1])
local at = tonumber(ARGV[1])
if at <= b or at > v then return 2 end
if redis.call('HGET', KEYS[1], 'w' .. ARGV[1]) ~= ARGV[2] then return 2 end
for n = b + 1, at do
  redis.call('HDEL', KEYS[1], 'e' .. n, 'w' .. n)
end
redis.call('HSET', KEYS[1], 'd', ARGV[3], 'b', ARGV[1])
return 1
";

/// KEYS: session, index. ARGV: escaped id. Returns the number of keys deleted.
const DELETE: &str = r"
local n = redis.call('DEL', KEYS[1])
redis.call('ZREM', KEYS[2], ARGV[1])
return n
";

/// KEYS: index. ARGV: the session key prefix `{prefix}:{tenant}:s:`.
/// Returns {escaped id, version, bytes (snapshot and log), pttl, kind} per
/// live session.
const LIST: &str = r"
redis.call('ZREMRANGEBYSCORE', KEYS[1], '-inf', now)
local out = {}
for _, m in ipairs(redis.call('ZRANGE', KEYS[1], 0, -1)) do
  local k = ARGV[1] .. m
  local f = redis.call('HMGET', k, 'v', 'k', 'b')
  local v = f[1]
  if v then
    local bytes = redis.call('HSTRLEN', k, 'd')
    for n = tonumber(f[3] or v) + 1, tonumber(v) do
      bytes = bytes + redis.call('HSTRLEN', k, 'e' .. n)
    end
    table.insert(out, {m, v, bytes, redis.call('PTTL', k), f[2] or 'correlation'})
  else
    redis.call('ZREM', KEYS[1], m)
  end
end
return out
";

impl RedisStore {
    /// A store over a lazily connected, self-reconnecting connection: this
    /// fails when a setting is wrong (the URL, TLS files, or a TLS handshake
    /// or credentials that a Redis answering at start rejects), never
    /// because Redis is down.
    pub async fn connect(settings: &StoreSettings) -> Result<Self, StoreError> {
        if super::sentinel::is_sentinel_url(&settings.url) {
            let (url, access) = super::sentinel::parse(&settings.url, &settings.redis)?;
            let sentinel = super::sentinel::Sentinel::new(url, access, settings.timeout);
            sentinel.check().await?;
            let sentinel = Arc::new(sentinel);
            sentinel.follow_switches();
            return Ok(Self::with_conn(settings, None, Some(sentinel)));
        }
        if super::cluster::is_cluster_url(&settings.url) {
            if settings.wait_replicas > 0 {
                return Err(access::config(
                    "FUSION_REDIS_WAIT_REPLICAS",
                    "is for one Redis or Sentinel; a Cluster's writes are not waited for".into(),
                ));
            }
            let cluster =
                super::cluster::Cluster::connect(&settings.url, &settings.redis, settings.timeout)
                    .await?;
            let mut store = Self::with_conn(settings, None, None);
            store.cluster = Some(Arc::new(cluster));
            return Ok(store);
        }
        let url = access::parse_server_url(&settings.url)?;
        let access = access::Access::new(&settings.redis, url.tls, url.user, url.password)?;
        let client = access.client(&url.host, url.port, url.db)?;
        access::probe(
            &client,
            settings.timeout,
            &format!("Redis {}:{}", url.host, url.port),
        )
        .await?;
        // One quick retry, then fail: the next command starts a new attempt, so
        // a Redis that comes back is found again within one command or two.
        let config = ConnectionManagerConfig::new()
            .set_connection_timeout(Some(settings.timeout))
            .set_response_timeout(Some(settings.timeout))
            .set_number_of_retries(1)
            .set_min_delay(Duration::from_millis(50))
            .set_max_delay(Duration::from_millis(200));
        let conn =
            ConnectionManager::new_lazy_with_config(client.clone(), config).map_err(unavailable)?;
        let mut store = Self::with_conn(settings, Some(conn), None);
        store.client = Some(client);
        store.server = format!("{}:{}", url.host, url.port);
        Ok(store)
    }

    fn with_conn(
        settings: &StoreSettings,
        conn: Option<ConnectionManager>,
        sentinel: Option<Arc<super::sentinel::Sentinel>>,
    ) -> Self {
        Self {
            client: None,
            conn,
            sentinel,
            server: String::new(),
            cluster: None,
            prefix: settings.key_prefix.clone(),
            wait_replicas: settings.wait_replicas,
            max_sessions_per_tenant: settings.max_sessions_per_tenant,
            timeout: settings.timeout,
            create: Script::new(&format!("{NOW_MS}{CREATE}{EXTEND_INDEX}return 1")),
            write: Script::new(&format!(
                "{NOW_MS}{WRITE}{EXTEND_INDEX}return {{1, ARGV[5]}}"
            )),
            compact: Script::new(COMPACT),
            delete: Script::new(DELETE),
            list: Script::new(&format!("{NOW_MS}{LIST}")),
        }
    }

    /// The connection to use: the single server's, or the primary's that
    /// the sentinels name.
    async fn connection(&self) -> Result<Conn, StoreError> {
        match (&self.conn, &self.sentinel, &self.cluster) {
            (Some(c), _, _) => Ok(Conn::Single(c.clone())),
            (None, Some(s), _) => s.conn().await.map(Conn::Single),
            (None, None, Some(c)) => c.conn().await.map(Conn::Cluster),
            (None, None, None) => Err(StoreError::Unavailable {
                reason: "no Redis connection configured".into(),
            }),
        }
    }

    /// The server in use and, behind Sentinel, the failover state.
    /// On a Cluster, `primary` is its seed nodes.
    pub fn topology(&self) -> crate::Topology {
        if let Some(c) = &self.cluster {
            return crate::Topology {
                primary: Some(c.seeds.clone()),
                failing_over: false,
                failovers: 0,
                redirections: 0,
            };
        }
        match &self.sentinel {
            Some(s) => crate::Topology {
                primary: s.primary(),
                failing_over: s.failing_over(),
                failovers: s.failovers(),
                redirections: s.rediscoveries(),
            },
            None => crate::Topology {
                primary: Some(self.server.clone()),
                failing_over: false,
                failovers: 0,
                redirections: 0,
            },
        }
    }

    pub async fn create(
        &self,
        tenant: &str,
        id: &str,
        kind: &str,
        data: Vec<u8>,
        ttl: Duration,
    ) -> Result<u64, StoreError> {
        let mut conn = self.connection().await?;
        let mut call = self.create.key(self.session_key(tenant, id));
        call.key(self.index_key(tenant))
            .arg(escape(id))
            .arg(data)
            .arg(ttl_ms(ttl))
            .arg(self.max_sessions_per_tenant)
            .arg(kind);
        match self.bounded(call.invoke_async::<i64>(&mut conn)).await? {
            1 => self.replicated(&mut conn).await.map(|()| 1),
            -1 => Err(StoreError::AlreadyExists),
            -2 => Err(StoreError::TooManySessions {
                limit: self.max_sessions_per_tenant,
            }),
            other => Err(corrupt(format!("create script answered {other}"))),
        }
    }

    pub async fn get(&self, tenant: &str, id: &str) -> Result<Option<Stored>, StoreError> {
        let mut conn = self.connection().await?;
        let key = self.session_key(tenant, id);
        let fields: Vec<(String, Vec<u8>)> = self
            .bounded(redis::cmd("HGETALL").arg(&key).query_async(&mut conn))
            .await?;
        if fields.is_empty() {
            return Ok(None);
        }
        stored_of(&key, fields).map(Some)
    }

    pub async fn write(
        &self,
        tenant: &str,
        id: &str,
        expected: Expected,
        token: u64,
        write: Write,
        ttl: Duration,
    ) -> Result<CasOutcome, StoreError> {
        let Some(new_version) = expected.version.checked_add(1) else {
            return Err(corrupt("version overflow".into()));
        };
        let mut conn = self.connection().await?;
        let mut call = self.write.key(self.session_key(tenant, id));
        let (mode, payload) = match write {
            Write::Snapshot(d) => ("s", d),
            Write::Append(e) => ("a", e),
        };
        call.key(self.index_key(tenant))
            .arg(escape(id))
            .arg(payload)
            .arg(ttl_ms(ttl))
            .arg(expected.version.to_string())
            .arg(new_version.to_string())
            .arg(expected.token.map_or_else(String::new, |t| t.to_string()))
            .arg(token.to_string())
            .arg(mode);
        let (status, version): (i64, String) = self.bounded(call.invoke_async(&mut conn)).await?;
        match status {
            0 => Ok(CasOutcome::Missing),
            1 => {
                self.replicated(&mut conn).await?;
                Ok(CasOutcome::Stored {
                    version: parse_version(&version)?,
                })
            }
            2 => Ok(CasOutcome::Conflict {
                current: parse_version(&version)?,
            }),
            other => Err(corrupt(format!("write script answered {other}"))),
        }
    }

    /// See [`crate::SessionStore::compact`]; waits for the replicas as a
    /// write does.
    pub async fn compact(
        &self,
        tenant: &str,
        id: &str,
        at: u64,
        token: u64,
        data: Vec<u8>,
    ) -> Result<Compacted, StoreError> {
        let mut conn = self.connection().await?;
        let mut call = self.compact.key(self.session_key(tenant, id));
        call.arg(at.to_string()).arg(token.to_string()).arg(data);
        match self.bounded(call.invoke_async::<i64>(&mut conn)).await? {
            0 => Ok(Compacted::Missing),
            1 => self.replicated(&mut conn).await.map(|()| Compacted::Stored),
            2 => Ok(Compacted::Stale),
            other => Err(corrupt(format!("compact script answered {other}"))),
        }
    }

    /// Restarts the session's TTL (a write, replicated after every earlier
    /// one) and, with `wait_replicas`, waits until the replicas hold it,
    /// so every earlier write of the session with it.
    pub async fn touch_replicated(
        &self,
        tenant: &str,
        id: &str,
        ttl: Duration,
    ) -> Result<(), StoreError> {
        if self.wait_replicas == 0 {
            return Ok(());
        }
        let mut conn = self.connection().await?;
        let _: i64 = self
            .bounded(
                redis::cmd("PEXPIRE")
                    .arg(self.session_key(tenant, id))
                    .arg(ttl_ms(ttl))
                    .query_async(&mut conn),
            )
            .await?;
        self.replicated(&mut conn).await
    }

    pub async fn delete(&self, tenant: &str, id: &str) -> Result<bool, StoreError> {
        let mut conn = self.connection().await?;
        let mut call = self.delete.key(self.session_key(tenant, id));
        call.key(self.index_key(tenant)).arg(escape(id));
        let deleted: i64 = self.bounded(call.invoke_async(&mut conn)).await?;
        self.replicated(&mut conn).await?;
        Ok(deleted > 0)
    }

    pub async fn list(&self, tenant: &str) -> Result<Vec<SessionMeta>, StoreError> {
        let mut conn = self.connection().await?;
        let mut call = self.list.key(self.index_key(tenant));
        call.arg(self.session_key(tenant, ""));
        let rows: Vec<(String, String, i64, i64, String)> =
            self.bounded(call.invoke_async(&mut conn)).await?;
        let mut sessions = rows
            .into_iter()
            .map(|(id, version, bytes, pttl, kind)| {
                Ok(SessionMeta {
                    id: unescape(&id).ok_or_else(|| corrupt(format!("bad index member {id:?}")))?,
                    version: parse_version(&version)?,
                    kind,
                    bytes: usize::try_from(bytes).unwrap_or(0),
                    ttl_remaining: Duration::from_millis(u64::try_from(pttl).unwrap_or(0)),
                })
            })
            .collect::<Result<Vec<_>, StoreError>>()?;
        sessions.sort_by(|a, b| a.id.cmp(&b.id));
        Ok(sessions)
    }

    pub async fn version(&self, tenant: &str, id: &str) -> Result<Option<u64>, StoreError> {
        let mut conn = self.connection().await?;
        let v: Option<String> = self
            .bounded(
                redis::cmd("HGET")
                    .arg(self.session_key(tenant, id))
                    .arg("v")
                    .query_async(&mut conn),
            )
            .await?;
        v.map(|v| parse_version(&v)).transpose()
    }

    /// With `wait_replicas`, waits until that many replicas hold the
    /// writes made so far on `conn` (`WAIT`, for half the timeout); fewer
    /// is `Unavailable`: the write is done on the primary but could be lost
    /// with it, so the caller answers "may or may not have been applied;
    /// retry with the same sequence", which is right either way.
    async fn replicated(&self, conn: &mut Conn) -> Result<(), StoreError> {
        if self.wait_replicas == 0 {
            return Ok(());
        }
        let wait_ms = (self.timeout.as_millis() / 2).max(1) as u64;
        let acked: usize = self
            .bounded(
                redis::cmd("WAIT")
                    .arg(self.wait_replicas)
                    .arg(wait_ms)
                    .query_async(conn),
            )
            .await?;
        if acked >= self.wait_replicas {
            Ok(())
        } else {
            Err(StoreError::Unavailable {
                reason: format!(
                    "the write reached {acked} of the {} replicas it waits for within {wait_ms} ms",
                    self.wait_replicas
                ),
            })
        }
    }

    /// `PUBLISH` on the session's event channel.
    pub async fn publish(&self, tenant: &str, id: &str, payload: &[u8]) -> Result<(), StoreError> {
        let mut conn = self.connection().await?;
        let _: i64 = self
            .bounded(
                redis::cmd("PUBLISH")
                    .arg(self.channel(tenant, id))
                    .arg(payload)
                    .query_async(&mut conn),
            )
            .await?;
        Ok(())
    }

    /// Starts this replica's event listener (see [`crate::events`]); behind
    /// Sentinel it follows the primary.
    pub fn listen(
        &self,
        capacity: usize,
    ) -> Option<(
        crate::events::EventListener,
        tokio::sync::mpsc::Receiver<crate::events::Feed>,
    )> {
        let source = match (&self.client, &self.sentinel, &self.cluster) {
            (Some(c), _, _) => crate::events::Source::Server(Box::new(c.clone())),
            (None, Some(s), _) => crate::events::Source::Sentinel(s.clone()),
            // PUBLISH on a Cluster reaches every node: listen on the first seed.
            (None, None, Some(c)) => {
                let (host, port) = &c.first;
                crate::events::Source::Server(Box::new(c.access.client(host, *port, 0).ok()?))
            }
            (None, None, None) => return None,
        };
        Some(crate::events::listen(source, self.timeout, capacity))
    }

    /// `{prefix}:ev:{tenant}:{id}`, escaped as the keys are.
    pub fn channel(&self, tenant: &str, id: &str) -> String {
        format!("{}:ev:{}:{}", self.prefix, escape(tenant), escape(id))
    }

    pub async fn ping(&self) -> Result<(), StoreError> {
        let mut conn = self.connection().await?;
        let _: String = self
            .bounded(redis::cmd("PING").query_async(&mut conn))
            .await?;
        Ok(())
    }

    fn session_key(&self, tenant: &str, id: &str) -> String {
        format!("{}:s:{}", self.tenant_part(tenant), escape(id))
    }

    fn index_key(&self, tenant: &str) -> String {
        format!("{}:idx", self.tenant_part(tenant))
    }

    pub(crate) fn is_cluster(&self) -> bool {
        self.cluster.is_some()
    }

    /// Every tenant's index key (`SCAN`; one server, not a Cluster).
    pub(crate) async fn index_keys(&self) -> Result<Vec<String>, StoreError> {
        let mut conn = self.connection().await?;
        let pattern = format!("{}:*:idx", self.prefix);
        let (mut cursor, mut keys) = (0u64, Vec::new());
        loop {
            let (next, batch): (u64, Vec<String>) = self
                .bounded(
                    redis::cmd("SCAN")
                        .arg(cursor)
                        .arg("MATCH")
                        .arg(&pattern)
                        .arg("COUNT")
                        .arg(1000)
                        .query_async(&mut conn),
                )
                .await?;
            keys.extend(batch);
            if next == 0 {
                return Ok(keys);
            }
            cursor = next;
        }
    }

    /// The tenant an index key of this store's layout belongs to.
    pub(crate) fn tenant_of_index(&self, index: &str) -> Option<String> {
        let escaped = index
            .strip_prefix(&format!("{}:", self.prefix))?
            .strip_suffix(":idx")?;
        let escaped = if self.is_cluster() {
            escaped.strip_prefix('{')?.strip_suffix('}')?
        } else {
            escaped
        };
        unescape(escaped)
    }

    /// The live sessions in one index, as stored.
    pub(crate) async fn raw_sessions(
        &self,
        index: &str,
        tenant: &str,
    ) -> Result<Vec<RawSession>, StoreError> {
        let mut conn = self.connection().await?;
        let ids: Vec<String> = self
            .bounded(
                redis::cmd("ZRANGE")
                    .arg(index)
                    .arg(0)
                    .arg(-1)
                    .query_async(&mut conn),
            )
            .await?;
        let mut out = Vec::new();
        for id in ids {
            let key = format!("{}:s:{id}", self.tenant_part(tenant));
            let (fields, pttl): (Vec<(String, Vec<u8>)>, i64) = self
                .bounded(
                    redis::pipe()
                        .cmd("HGETALL")
                        .arg(&key)
                        .cmd("PTTL")
                        .arg(&key)
                        .query_async(&mut conn),
                )
                .await?;
            if fields.iter().any(|(f, _)| f == "v") && pttl > 0 {
                out.push(RawSession {
                    escaped_id: id,
                    fields,
                    ttl_ms: pttl,
                });
            }
        }
        Ok(out)
    }

    /// Runs a script on a session's key and its tenant's index, with the
    /// arguments `args` adds; its integer answer.
    pub(crate) async fn run_script(
        &self,
        script: &Script,
        tenant: &str,
        id: &str,
        args: impl FnOnce(&mut redis::ScriptInvocation<'_>),
    ) -> Result<i64, StoreError> {
        let mut conn = self.connection().await?;
        let mut call = script.key(self.session_key(tenant, id));
        call.key(self.index_key(tenant));
        args(&mut call);
        self.bounded(call.invoke_async(&mut conn)).await
    }

    /// `{prefix}:{tenant}`, or on a Cluster `{prefix}:{{tenant}}` (the hash
    /// tag: the first `{…}` of every key of the tenant is the same, since it
    /// lies in this common beginning).
    fn tenant_part(&self, tenant: &str) -> String {
        if self.cluster.is_some() {
            format!("{}:{{{}}}", self.prefix, escape(tenant))
        } else {
            format!("{}:{}", self.prefix, escape(tenant))
        }
    }

    /// Runs one command within the timeout; errors and timeouts are `Unavailable`
    /// except a key of the wrong type, which is `Corrupt`.
    async fn bounded<T>(
        &self,
        command: impl Future<Output = Result<T, RedisError>>,
    ) -> Result<T, StoreError> {
        let result = self.bounded_inner(command).await;
        if let Some(s) = &self.sentinel {
            match &result {
                // A connection error, a time-out or READONLY: ask the
                // sentinels again before the next command.
                Err(StoreError::Unavailable { .. }) => s.invalidate(),
                Err(_) => {}
                Ok(_) => s.confirm(),
            }
        }
        result
    }

    async fn bounded_inner<T>(
        &self,
        command: impl Future<Output = Result<T, RedisError>>,
    ) -> Result<T, StoreError> {
        match tokio::time::timeout(self.timeout, command).await {
            Ok(Ok(value)) => Ok(value),
            Ok(Err(e)) if e.code() == Some("WRONGTYPE") => Err(corrupt(e.to_string())),
            Ok(Err(e)) => Err(unavailable(e)),
            Err(_) => Err(StoreError::Unavailable {
                reason: format!(
                    "Redis did not answer within {} ms",
                    self.timeout.as_millis()
                ),
            }),
        }
    }
}

/// A session's fields as stored (for a copy between key layouts).
pub(crate) struct RawSession {
    pub(crate) escaped_id: String,
    /// Every field of the session's hash (version, kind, snapshot, log).
    pub(crate) fields: Vec<(String, Vec<u8>)>,
    pub(crate) ttl_ms: i64,
}

/// The connection of a single server (or Sentinel's primary) or of a Cluster.
#[derive(Clone)]
enum Conn {
    Single(ConnectionManager),
    Cluster(ClusterConnection),
}

impl ConnectionLike for Conn {
    fn req_packed_command<'a>(&'a mut self, cmd: &'a Cmd) -> RedisFuture<'a, Value> {
        match self {
            Self::Single(c) => c.req_packed_command(cmd),
            Self::Cluster(c) => c.req_packed_command(cmd),
        }
    }

    fn req_packed_commands<'a>(
        &'a mut self,
        pipeline: &'a Pipeline,
        offset: usize,
        count: usize,
    ) -> RedisFuture<'a, Vec<Value>> {
        match self {
            Self::Single(c) => c.req_packed_commands(pipeline, offset, count),
            Self::Cluster(c) => c.req_packed_commands(pipeline, offset, count),
        }
    }

    fn get_db(&self) -> i64 {
        match self {
            Self::Single(c) => c.get_db(),
            Self::Cluster(c) => c.get_db(),
        }
    }
}

/// Escapes `%` and `:` (`%25`, `%3A`), so that escaped tenants and ids never
/// contain the key separator and distinct names give distinct keys.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '%' => out.push_str("%25"),
            ':' => out.push_str("%3A"),
            c => out.push(c),
        }
    }
    out
}

/// The inverse of [`escape`]; `None` for a string `escape` cannot produce.
pub fn unescape(s: &str) -> Option<String> {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find('%') {
        out.push_str(&rest[..i]);
        let code = rest.get(i + 1..i + 3)?;
        out.push(match code {
            "25" => '%',
            "3A" => ':',
            _ => return None,
        });
        rest = &rest[i + 3..];
    }
    if rest.contains(':') {
        return None;
    }
    out.push_str(rest);
    Some(out)
}

/// A session hash's fields as a [`Stored`] (see [`WRITE`] for the layout).
fn stored_of(key: &str, fields: Vec<(String, Vec<u8>)>) -> Result<Stored, StoreError> {
    let text = |v: &[u8]| String::from_utf8_lossy(v).into_owned();
    let (mut version, mut token, mut base, mut data) = (None, 0, None, None);
    let mut entries = std::collections::BTreeMap::new();
    for (name, value) in fields {
        match name.as_str() {
            "v" => version = Some(parse_version(&text(&value))?),
            "t" => {
                token = text(&value)
                    .parse()
                    .map_err(|_| corrupt(format!("{key} has a bad token")))?
            }
            "b" => base = Some(parse_version(&text(&value))?),
            "d" => data = Some(value),
            "k" => {}
            w if w.len() > 1
                && w.starts_with('w')
                && w[1..].bytes().all(|b| b.is_ascii_digit()) => {}
            e => {
                let n = e
                    .strip_prefix('e')
                    .and_then(|n| n.parse::<u64>().ok())
                    .ok_or_else(|| corrupt(format!("{key} has an unknown field {e:?}")))?;
                entries.insert(n, value);
            }
        }
    }
    let (Some(version), Some(data)) = (version, data) else {
        return Err(corrupt(format!("{key} lacks field v or d")));
    };
    let base = base.unwrap_or(version);
    let expected: Vec<u64> = (base.saturating_add(1)..=version).collect();
    if base > version || entries.keys().copied().ne(expected.iter().copied()) {
        return Err(corrupt(format!(
            "{key}: the log after the snapshot at version {base} does not hold exactly the \
             entries up to version {version}"
        )));
    }
    Ok(Stored {
        version,
        token,
        data,
        log: entries.into_values().collect(),
    })
}

fn parse_version(v: &str) -> Result<u64, StoreError> {
    v.parse()
        .map_err(|_| corrupt(format!("version {v:?} is not a number")))
}

fn corrupt(reason: String) -> StoreError {
    StoreError::Corrupt { reason }
}

fn unavailable(e: RedisError) -> StoreError {
    StoreError::Unavailable {
        reason: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escaping_is_injective_and_reversible() {
        let names = ["a", "a:b", "a%3Ab", "a%b", "%", ":", "", "x:s:y", "ü:%25"];
        let escaped: Vec<String> = names.iter().map(|n| escape(n)).collect();
        for (n, e) in names.iter().zip(&escaped) {
            assert!(!e.contains(':'), "{e}");
            assert_eq!(unescape(e).as_deref(), Some(*n));
        }
        let mut unique = escaped.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), names.len());
        assert_eq!(escape("a:b%"), "a%3Ab%25");
        assert_eq!(unescape("%zz"), None);
        assert_eq!(unescape("a:b"), None);
    }
}
