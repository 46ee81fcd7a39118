//! Redis Cluster: `redis+cluster://[USER:PASSWORD@]HOST:PORT[,HOST:PORT…]`
//! (`rediss+cluster://` for TLS, with [`crate::access`]).
//!
//! The nodes given are seeds: the client learns the slot map from them and
//! follows `MOVED` and `ASK` redirections itself (a resharding included),
//! reconnecting to nodes that come back. Keys carry a hash tag per tenant
//! (`{prefix}:{tenant}:…`, see [`crate::redis`]), so a tenant's sessions and
//! index share a slot and every Lua script of the store stays single-slot;
//! tenants spread over the primaries. The connection is made at the first
//! command (a cluster down at start leaves the store degraded, as a single
//! Redis does); a failed handshake, rejected credentials or a cluster that
//! answers but does not cover every slot refuse to start.

use std::time::Duration;

use redis::{aio::ConnectionLike, cluster::ClusterClient, cluster_async::ClusterConnection};
use tokio::sync::Mutex;

use super::{StoreError, access};

pub(crate) const SCHEME: &str = "redis+cluster://";
pub(crate) const TLS_SCHEME: &str = "rediss+cluster://";

/// Whether `url` names a Redis Cluster.
pub fn is_cluster_url(url: &str) -> bool {
    url.starts_with(SCHEME) || url.starts_with(TLS_SCHEME)
}

fn bad(why: &str) -> StoreError {
    access::config(
        access::STORE,
        format!(
            "invalid Cluster URL (redis+cluster://[USER:PASSWORD@]HOST:PORT[,HOST:PORT…]): {why}"
        ),
    )
}

/// Parses `redis[s]+cluster://[USER:PASSWORD@]HOST:PORT[,HOST:PORT…][/]`
/// and reads the TLS files and credentials it needs.
fn parse(
    url: &str,
    settings: &access::RedisAccessSettings,
) -> Result<(Vec<(String, u16)>, access::Access), StoreError> {
    let (rest, tls) = match (url.strip_prefix(SCHEME), url.strip_prefix(TLS_SCHEME)) {
        (Some(rest), _) => (rest, false),
        (None, Some(rest)) => (rest, true),
        (None, None) => {
            return Err(bad(
                "it must start with redis+cluster:// or rediss+cluster://",
            ));
        }
    };
    let hosts = rest.strip_suffix('/').unwrap_or(rest);
    if hosts.contains('/') {
        return Err(bad("a cluster has no database number (only database 0)"));
    }
    let (user, password, nodes) = access::parse_hosts(hosts, "node", bad)?;
    let access = access::Access::new(settings, tls, user, password)?;
    Ok((nodes, access))
}

/// A Redis Cluster, connected at the first command.
pub(crate) struct Cluster {
    client: ClusterClient,
    conn: Mutex<Option<ClusterConnection>>,
    /// The seed nodes, `host:port`, for health.
    pub(crate) seeds: String,
    /// The first seed, for the event listener (PUBLISH reaches every node).
    pub(crate) first: (String, u16),
    pub(crate) access: access::Access,
    timeout: Duration,
}

impl Cluster {
    /// Parses the URL, reads the TLS files, and checks the cluster once if
    /// it answers (see the module's documentation).
    pub(crate) async fn connect(
        url: &str,
        settings: &access::RedisAccessSettings,
        timeout: Duration,
    ) -> Result<Self, StoreError> {
        let (nodes, access) = parse(url, settings)?;
        let client = access.cluster_client(&nodes, timeout)?;
        let cluster = Self {
            client,
            conn: Mutex::new(None),
            seeds: nodes
                .iter()
                .map(|(h, p)| format!("{h}:{p}"))
                .collect::<Vec<_>>()
                .join(","),
            first: nodes[0].clone(),
            access,
            timeout,
        };
        cluster.check().await?;
        Ok(cluster)
    }

    /// The cluster's connection, made now if there is none.
    pub(crate) async fn conn(&self) -> Result<ClusterConnection, StoreError> {
        let mut slot = self.conn.lock().await;
        if let Some(c) = slot.as_ref() {
            return Ok(c.clone());
        }
        let c = match tokio::time::timeout(self.timeout * 2, self.client.get_async_connection())
            .await
        {
            Ok(Ok(c)) => c,
            Ok(Err(e)) => {
                return Err(access::misconfiguration(&e, "Redis Cluster").unwrap_or(
                    StoreError::Unavailable {
                        reason: format!("Redis Cluster {}: {e}", self.seeds),
                    },
                ));
            }
            Err(_) => {
                return Err(StoreError::Unavailable {
                    reason: format!("Redis Cluster {} did not answer in time", self.seeds),
                });
            }
        };
        *slot = Some(c.clone());
        Ok(c)
    }

    /// At start: a configuration error, or a cluster that answers without
    /// covering every slot, refuses to start; no answer does not.
    async fn check(&self) -> Result<(), StoreError> {
        let mut conn = match self.conn().await {
            Ok(c) => c,
            Err(e @ StoreError::Config { .. }) => return Err(e),
            Err(_) => return Ok(()),
        };
        let info = tokio::time::timeout(
            self.timeout,
            conn.req_packed_command(redis::cmd("CLUSTER").arg("INFO")),
        )
        .await;
        let Ok(Ok(info)) = info else { return Ok(()) };
        let info: String = redis::from_redis_value(info).unwrap_or_default();
        if info.lines().any(|l| l.trim() == "cluster_state:ok") {
            Ok(())
        } else {
            Err(access::config(
                access::STORE,
                format!(
                    "Redis Cluster {} answers but is not in state ok (are all 16384 slots \
                     covered?)",
                    self.seeds
                ),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cluster_urls_parse_and_bad_ones_name_the_setting() {
        let settings = access::RedisAccessSettings::default();
        let (nodes, _) = parse(
            "redis+cluster://app:p%40ss@10.0.0.1:7000,h2:7001/",
            &settings,
        )
        .unwrap();
        assert_eq!(
            nodes,
            [("10.0.0.1".to_string(), 7000), ("h2".to_string(), 7001)]
        );
        for url in [
            "redis+cluster://u:secret@h",
            "redis+cluster://u:secret@h:1/0",
            "redis+cluster://u:secret@h:x",
            "redis+cluster://u:secret%zz@h:1",
        ] {
            let e = parse(url, &settings).err().expect(url).to_string();
            assert!(e.contains("FUSION_SESSION_STORE"), "{url}: {e}");
            assert!(!e.contains("secret"), "{url}: {e}");
        }
    }
}
