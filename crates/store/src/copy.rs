//! Moving sessions between Redis key layouts: from a single Redis or
//! Sentinel (keys `{prefix}:{tenant}:…`) to a Redis Cluster (the tenant as a
//! hash tag, `{prefix}:{{tenant}}:…`), or back. Every field (version,
//! token, kind, snapshot and log) and the remaining idle TTL are kept; a session the target holds already is
//! left as it is, so a copy can be run again. The source is read with
//! `SCAN` on one server, so it cannot be a Cluster; sessions written to the
//! source while it runs may be missed (run it again once the replicas point
//! at the target).

use redis::Script;

use super::{
    StoreError, access,
    redis::{EXTEND_INDEX, NOW_MS, RedisStore, unescape},
};

/// What [`copy`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Copied {
    /// Sessions written to the target.
    pub sessions: usize,
    /// Sessions the target held already (left as they are).
    pub skipped: usize,
}

/// KEYS: session, index. ARGV: escaped id, (unused), ttl ms, then the
/// hash's fields and values. Returns 1 written, 0 present already.
const RESTORE: &str = r"
if redis.call('EXISTS', KEYS[1]) == 1 then return 0 end
redis.call('HSET', KEYS[1], unpack(ARGV, 4))
redis.call('PEXPIRE', KEYS[1], ARGV[3])
redis.call('ZADD', KEYS[2], now + tonumber(ARGV[3]), ARGV[1])
";

/// Copies every live session of `from` into `to` (see the module's
/// documentation).
pub async fn copy(from: &RedisStore, to: &RedisStore) -> Result<Copied, StoreError> {
    if from.is_cluster() {
        return Err(access::config(
            "--from",
            "the source of a copy must be one Redis or a Sentinel deployment, not a Cluster".into(),
        ));
    }
    let restore = Script::new(&format!("{NOW_MS}{RESTORE}{EXTEND_INDEX}return 1"));
    let mut copied = Copied {
        sessions: 0,
        skipped: 0,
    };
    for index in from.index_keys().await? {
        let Some(tenant) = from.tenant_of_index(&index) else {
            continue;
        };
        for raw in from.raw_sessions(&index, &tenant).await? {
            let id = unescape(&raw.escaped_id).ok_or_else(|| StoreError::Corrupt {
                reason: format!("bad index member {:?}", raw.escaped_id),
            })?;
            let written = to
                .run_script(&restore, &tenant, &id, |call| {
                    call.arg(&raw.escaped_id).arg("").arg(raw.ttl_ms);
                    for (field, value) in &raw.fields {
                        call.arg(field).arg(value.as_slice());
                    }
                })
                .await?;
            if written == 1 {
                copied.sessions += 1;
            } else {
                copied.skipped += 1;
            }
        }
    }
    Ok(copied)
}
