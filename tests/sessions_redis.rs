//! Streaming sessions shared by two real service instances on one Redis:
//! alternating and concurrent pushes, a batch retried on the other instance,
//! idle expiry, a Redis outage and recovery (on a redis-server of its own),
//! tenant isolation over gRPC, a gRPC stream dropped mid-way and continued
//! over REST on the other instance, and a Sentinel deployment whose primary
//! is SIGKILLed while both instances push (its own processes on free ports). Every final state is compared with the
//! same batches pushed to a single instance on the memory store (which equals
//! the batch endpoint's decisions).
//!
//! The tests use Redis on 127.0.0.1:6379, each under a key prefix of its own
//! shared by its two instances; they fail loudly when Redis is not running (or,
//! for the outage test, when `redis-server` is not on PATH), unless
//! `FUSION_SKIP_REDIS_TESTS=1` is set.

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use radar_fusion::{
    config::Settings,
    proto::{self as pb, session_service_client::SessionServiceClient},
};
use serde_json::{Value, json};
use tonic::transport::Channel;

#[path = "api/helpers.rs"]
#[allow(dead_code)] // the API suite's harness; this suite uses part of it
mod helpers;

use helpers::TestApp as App;

#[path = "common/sessions.rs"]
mod data;

use data::{open_stream, pb_report, scenario};
use test_support::{
    cluster as cluster_nodes, procs,
    redis::{RedisServer, redis_is_up, redis_server_available, redis_url, unique},
    sentinel,
};

/// Reports per pushed batch.
const CHUNK: usize = 8;

// ---------------------------------------------------------------- harness

/// Session calls on a running instance (the API suite's `TestApp`).
trait SessionCalls {
    async fn get(&self, path: &str) -> reqwest::Response;
    /// Creates a session over REST and returns its id.
    async fn create(&self, config: &Value) -> String;
    async fn push(&self, id: &str, body: &Value) -> Value;
    async fn state(&self, id: &str) -> Value;
    async fn sessions(&self) -> SessionServiceClient<Channel>;
    async fn delete(&self, id: &str);
}

impl SessionCalls for App {
    async fn get(&self, path: &str) -> reqwest::Response {
        self.client
            .get(self.url(path))
            .send()
            .await
            .expect("request sent")
    }

    async fn create(&self, config: &Value) -> String {
        let response = self.post_json("/v1/sessions", config).await;
        assert_eq!(response.status(), 201);
        let body: Value = response.json().await.unwrap();
        body["id"].as_str().expect("id").to_string()
    }

    async fn push(&self, id: &str, body: &Value) -> Value {
        self.post_ok(&format!("/v1/sessions/{id}/batches"), body)
            .await
    }

    async fn state(&self, id: &str) -> Value {
        self.get_ok(&format!("/v1/sessions/{id}")).await
    }

    async fn sessions(&self) -> SessionServiceClient<Channel> {
        SessionServiceClient::new(self.channel().await)
    }

    async fn delete(&self, id: &str) {
        let response = self
            .client
            .delete(self.url(&format!("/v1/sessions/{id}")))
            .send()
            .await
            .unwrap();
        assert_eq!(response.status(), 204);
    }
}

async fn spawn_app(configure: impl FnOnce(&mut Settings)) -> App {
    let app = helpers::spawn_app_with(|s| {
        // Short grace: a test's leftover connections must not hold it up.
        s.shutdown_grace_s = 1.0;
        configure(s);
    })
    .await;
    assert!(app.state.is_ready(), "the instance did not start");
    app
}

/// Two instances on one Redis under one fresh key prefix.
async fn two_instances(url: &str, configure: impl Fn(&mut Settings)) -> (App, App) {
    let prefix = unique("radar-fusion-test:sessions-redis:");
    let settings = |s: &mut Settings| {
        s.session_store = url.to_string();
        s.session_key_prefix = prefix.clone();
        configure(s);
    };
    let a = spawn_app(settings).await;
    let b = spawn_app(settings).await;
    (a, b)
}

// ---------------------------------------------------------------- scenario

fn session_config(batch: &Value) -> Value {
    let mut c = data::session_config(batch);
    c["idle_expiry_s"] = json!(120.0);
    c
}

/// The batch request bodies: sequences 1..=n of `CHUNK` reports, then n + 1, a flush.
fn batch_bodies(reports: &[Value]) -> Vec<Value> {
    let mut bodies: Vec<Value> = reports
        .chunks(CHUNK)
        .enumerate()
        .map(|(i, chunk)| json!({"sequence": i + 1, "reports": chunk}))
        .collect();
    bodies.push(json!({"sequence": bodies.len() + 1, "flush": true}));
    bodies
}

/// The parts of a session's state that the batches determine (not its id or
/// creation time); `version` included: one per applied batch, plus one.
fn outcome(state: &Value) -> Value {
    let mut out = serde_json::Map::new();
    for field in [
        "version",
        "last_sequence",
        "batches",
        "instants_processed",
        "last_instant_t",
        "pending_reports",
        "reports_accepted",
        "reports_late",
        "nodes",
        "pairs",
        "system_tracks",
    ] {
        assert!(state.get(field).is_some(), "state without {field}: {state}");
        out.insert(field.to_string(), state[field].clone());
    }
    Value::Object(out)
}

/// The reference: every batch pushed in order to one instance on the memory
/// store; checked against the batch endpoint's decisions.
async fn single_instance_outcome() -> Value {
    let app = spawn_app(|_| {}).await;
    let (batch, reports) = scenario();
    let id = app.create(&session_config(&batch)).await;
    for body in batch_bodies(&reports) {
        let u = app.push(&id, &body).await;
        assert_eq!(u["duplicate"], false);
    }
    let state = app.state(&id).await;
    let expected = app.post_ok("/v1/correlation/tracks", &batch).await;
    assert_eq!(state["pairs"], expected["pairs"]);
    assert_eq!(state["system_tracks"], expected["system_tracks"]);
    let decided = expected["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["decision"] == "correlated")
        .count();
    assert!(decided >= 5, "a scenario worth checking: {expected}");
    let n = batch_bodies(&reports).len() as u64;
    assert_eq!(state["batches"], n);
    assert_eq!(state["version"], n + 1);
    app.stop().await.expect("server stops");
    outcome(&state)
}

fn assert_same_outcome(state: &Value, reference: &Value) {
    let got = outcome(state);
    if &got != reference {
        for (field, want) in reference.as_object().unwrap() {
            assert_eq!(
                &got[field], want,
                "field {field} differs from the single-instance run"
            );
        }
    }
}

/// A gRPC push request of one REST batch body.
fn pb_batch(id: &str, body: &Value) -> pb::PushBatchRequest {
    pb::PushBatchRequest {
        session_id: id.to_string(),
        sequence: body["sequence"].as_u64(),
        reports: body["reports"]
            .as_array()
            .map(|r| r.iter().map(pb_report).collect())
            .unwrap_or_default(),
        flush: body["flush"].as_bool().unwrap_or(false),
        plots: Vec::new(),
        asterix: None,
        cooperative: Vec::new(),
        nmea: None,
    }
}

/// The scenario's session configuration over gRPC.
fn pb_open() -> pb::CreateSessionRequest {
    pb::CreateSessionRequest {
        idle_expiry_s: Some(120.0),
        ..data::pb_open()
    }
}

// ---------------------------------------------------------------- tests

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batches_alternating_between_instances_give_the_single_instance_result() {
    if !redis_is_up() {
        return;
    }
    alternating_pushes_give_the_single_instance_result(&redis_url()).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn on_a_redis_cluster_too() {
    let Some(cluster) = cluster_nodes::Cluster::start("the service on Redis Cluster") else {
        return;
    };
    alternating_pushes_give_the_single_instance_result(&cluster.url()).await;
    // Health says ok and names no host; the store follows the seeds.
    let app = spawn_app(|s| s.session_store = cluster.url()).await;
    let seeds = cluster.url().replace("redis+cluster://", "");
    assert_eq!(store_health(&app).await, (200, json!(false)));
    assert_eq!(primary(&app), json!(seeds));
    app.stop().await.expect("server stops");
}

/// Two instances on the store at `url` push one session alternately: the
/// single instance's outcome, and the session deleted at the end.
async fn alternating_pushes_give_the_single_instance_result(url: &str) {
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(url, |_| {}).await;
    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let bodies = batch_bodies(&reports);
    for (i, body) in bodies.iter().enumerate() {
        let to = if i % 2 == 0 { &a } else { &b };
        let u = to.push(&id, body).await;
        assert_eq!(u["duplicate"], false, "batch {}", i + 1);
        assert_eq!(u["version"], i as u64 + 2, "batch {}", i + 1);
    }
    let (on_a, on_b) = (a.state(&id).await, b.state(&id).await);
    assert_eq!(on_a, on_b, "both instances see one session");
    assert_same_outcome(&on_a, &reference);
    b.delete(&id).await;
    assert_eq!(a.get(&format!("/v1/sessions/{id}")).await.status(), 404);
}

/// The value of an unlabelled counter in a Prometheus text page, if present.
fn counter(page: &str, name: &str) -> Option<f64> {
    page.lines()
        .filter(|l| !l.starts_with('#'))
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_pushers_on_two_instances_apply_every_batch_exactly_once() {
    if !redis_is_up() {
        return;
    }
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(&redis_url(), |_| {}).await;
    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let bodies = Arc::new(batch_bodies(&reports));
    let conflicts_before = counter(
        &a.get("/metrics").await.text().await.unwrap(),
        "fusion_session_cas_conflicts_total",
    )
    .unwrap_or(0.0);

    let start = Arc::new(tokio::sync::Barrier::new(2));
    let pusher = |app: &App| {
        let (url, client) = (
            app.url(&format!("/v1/sessions/{id}/batches")),
            app.client.clone(),
        );
        let (bodies, start) = (Arc::clone(&bodies), Arc::clone(&start));
        tokio::spawn(async move {
            start.wait().await;
            // (applied, duplicates, refusals: 409 or 503)
            let (mut applied, mut duplicates, mut refused) = (0u64, 0u64, Vec::new());
            for body in bodies.iter() {
                let mut attempts = 0;
                loop {
                    attempts += 1;
                    assert!(
                        attempts <= 200,
                        "batch {} never went through",
                        body["sequence"]
                    );
                    let r = client.post(&url).json(body).send().await.unwrap();
                    let status = r.status().as_u16();
                    if status == 200 {
                        let u: Value = r.json().await.unwrap();
                        assert_eq!(u["sequence"], body["sequence"]);
                        if u["duplicate"] == true {
                            duplicates += 1;
                        } else {
                            applied += 1;
                        }
                        break;
                    }
                    let text = r.text().await.unwrap();
                    assert!(
                        status == 409 || status == 503,
                        "batch {}: {status} {text}",
                        body["sequence"]
                    );
                    refused.push(status);
                    tokio::time::sleep(Duration::from_millis(5)).await;
                }
            }
            (applied, duplicates, refused)
        })
    };
    let (ta, tb) = (pusher(&a), pusher(&b));
    let (ra, rb) = (ta.await.unwrap(), tb.await.unwrap());
    let n = bodies.len() as u64;
    eprintln!("concurrent pushers: A {ra:?}, B {rb:?} (applied, duplicate, refused)");
    assert_eq!(ra.0 + ra.1, n);
    assert_eq!(rb.0 + rb.1, n);
    assert_eq!(
        ra.0 + rb.0,
        n,
        "every batch applied exactly once: A {ra:?}, B {rb:?}"
    );
    // Each client pushes in order, so the session is never behind by more
    // than the batch pushed: a gap (409) cannot happen.
    assert!(
        !ra.2.contains(&409) && !rb.2.contains(&409),
        "A {ra:?}, B {rb:?}"
    );

    let state = b.state(&id).await;
    assert_eq!(state["batches"], n, "the flush batch counts too");
    assert_eq!(state["last_sequence"], n);
    assert_same_outcome(&state, &reference);
    assert_eq!(a.state(&id).await, state);

    let page = a.get("/metrics").await.text().await.unwrap();
    let conflicts = counter(&page, "fusion_session_cas_conflicts_total").unwrap_or(0.0);
    // The counter is process-wide (other tests run beside this one), and
    // whether the two pushers collide depends on scheduling: only report it.
    eprintln!("fusion_session_cas_conflicts_total: {conflicts_before} before, {conflicts} after");
    assert!(conflicts >= conflicts_before);
    a.delete(&id).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_batch_retried_on_the_other_instance_is_acknowledged_not_applied() {
    if !redis_is_up() {
        return;
    }
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(&redis_url(), |_| {}).await;
    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let bodies = batch_bodies(&reports);
    let k = 5;
    let mut original = Value::Null;
    for body in &bodies[..k] {
        original = a.push(&id, body).await;
    }
    assert!(!original["changes"].as_array().unwrap().is_empty());
    let before = a.state(&id).await;
    assert_eq!(before["batches"], k as u64);
    // The client timed out on A and retries batch k on B: the answer it
    // missed is replayed, marked duplicate, and nothing is applied.
    let again = b.push(&id, &bodies[k - 1]).await;
    assert_eq!(again["duplicate"], true, "{again}");
    assert_eq!(again["version"], before["version"]);
    for field in [
        "sequence",
        "instants",
        "pending_reports",
        "changes",
        "pairs",
        "system_tracks",
        "retired",
    ] {
        assert_eq!(again[field], original[field], "{field}");
    }
    // An older batch gets an empty acknowledgement.
    let older = b.push(&id, &bodies[k - 2]).await;
    assert_eq!(older["duplicate"], true, "{older}");
    assert_eq!(older["version"], before["version"]);
    assert_eq!(older["changes"], json!([]));
    // And the same over gRPC on B.
    let again = b
        .sessions()
        .await
        .push_batch(pb_batch(&id, &bodies[k - 1]))
        .await
        .unwrap()
        .into_inner();
    assert!(again.duplicate);
    assert_eq!(Some(again.version), before["version"].as_u64());
    assert_eq!(
        again.changes.len(),
        original["changes"].as_array().unwrap().len()
    );
    assert_eq!(
        again.system_tracks.len(),
        original["system_tracks"].as_array().unwrap().len()
    );
    let after = b.state(&id).await;
    assert_eq!(after, before, "a duplicate changes nothing");
    // The rest on B, from k + 1: the single-instance result.
    for body in &bodies[k..] {
        let u = b.push(&id, body).await;
        assert_eq!(u["duplicate"], false);
    }
    assert_same_outcome(&a.state(&id).await, &reference);
    a.delete(&id).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idle_session_expires_on_both_instances_and_pushes_keep_it_alive() {
    if !redis_is_up() {
        return;
    }
    const IDLE: f64 = 1.5;
    let (a, b) = two_instances(&redis_url(), |_| {}).await;
    let (batch, reports) = scenario();
    let mut config = session_config(&batch);
    config["idle_expiry_s"] = json!(IDLE);
    let id = a.create(&config).await;
    let path = format!("/v1/sessions/{id}");
    let bodies = batch_bodies(&reports);

    // Pushes at 0.8 s intervals keep it alive well past 1.5 s.
    for body in &bodies[..3] {
        tokio::time::sleep(Duration::from_secs_f64(IDLE * 0.5)).await;
        let u = b.push(&id, body).await;
        assert_eq!(u["duplicate"], false);
    }
    let last_push = Instant::now();
    let state = a.state(&id).await;
    assert_eq!(state["batches"], 3);
    assert_eq!(state["idle_expiry_s"], IDLE);
    let list = b.get_ok("/v1/sessions").await;
    assert_eq!(list["sessions"][0]["id"], id.as_str());

    // Then no batch: reads do not keep it alive; it is gone on both instances.
    tokio::time::sleep(Duration::from_secs_f64(IDLE * 0.5)).await;
    assert_eq!(b.get(&path).await.status(), 200);
    let wait = Duration::from_secs_f64(IDLE + 0.7).saturating_sub(last_push.elapsed());
    tokio::time::sleep(wait).await;
    for app in [&a, &b] {
        assert_eq!(app.get(&path).await.status(), 404);
        let list = app.get_ok("/v1/sessions").await;
        assert_eq!(list["sessions"], json!([]));
    }
    let late = b.post_json(&format!("{path}/batches"), &bodies[3]).await;
    assert_eq!(late.status(), 404);
    let err = a
        .sessions()
        .await
        .push_batch(pb_batch(&id, &bodies[3]))
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::NotFound);
}

// ---------------------------------------------------------------- Redis outage

/// Polls `/healthz/store` until it answers `status`; panics after `limit`.
async fn wait_readyz(app: &App, status: u16, limit: Duration) {
    let start = Instant::now();
    loop {
        let got = app.get("/healthz/store").await.status().as_u16();
        if got == status {
            return;
        }
        assert!(
            start.elapsed() < limit,
            "/healthz/store still {got}, not {status}, after {limit:?}"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// A private, persistent redis-server on a free port, or `None` (with a loud
/// warning) when `redis-server` is not on PATH and `FUSION_SKIP_REDIS_TESTS=1`.
fn private_redis() -> Option<RedisServer> {
    redis_server_available().then(RedisServer::persistent)
}

/// How long a failing call may take: generous against a 0.5 s store timeout.
const FAST: Duration = Duration::from_secs(3);

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_redis_outage_fails_fast_and_the_session_continues_after_recovery() {
    let Some(mut redis) = private_redis() else {
        return;
    };
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(&redis.url(), |s| s.store_timeout_s = 0.5).await;
    wait_readyz(&a, 200, Duration::from_secs(5)).await;
    wait_readyz(&b, 200, Duration::from_secs(5)).await;

    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let bodies = batch_bodies(&reports);
    let k = 7;
    for (i, body) in bodies[..k].iter().enumerate() {
        let to = if i % 2 == 0 { &a } else { &b };
        to.push(&id, body).await;
    }
    let before = b.state(&id).await;
    assert_eq!(before["last_sequence"], k as u64);

    redis.kill();

    // REST: 503 with Retry-After and a problem body, quickly, on both instances.
    for app in [&a, &b] {
        let start = Instant::now();
        let r = app
            .post_json(&format!("/v1/sessions/{id}/batches"), &bodies[k])
            .await;
        let took = start.elapsed();
        assert!(took < FAST, "push took {took:?}");
        assert_eq!(r.status(), 503);
        assert_eq!(r.headers()["retry-after"], "1");
        assert_eq!(r.headers()["content-type"], "application/problem+json");
        let problem: Value = r.json().await.unwrap();
        assert_eq!(problem["status"], 503);
        assert!(
            problem["type"]
                .as_str()
                .unwrap()
                .starts_with("urn:radar-fusion:problem:"),
            "{problem}"
        );
        assert!(problem["detail"].is_string(), "{problem}");
        let start = Instant::now();
        let r = app.get(&format!("/v1/sessions/{id}")).await;
        assert_eq!(r.status(), 503);
        assert!(start.elapsed() < FAST);
    }
    // Creating, listing and deleting fail the same way.
    let start = Instant::now();
    let r = a.post_json("/v1/sessions", &session_config(&batch)).await;
    assert_eq!(r.status(), 503);
    assert_eq!(r.headers()["retry-after"], "1");
    assert_eq!(b.get("/v1/sessions").await.status(), 503);
    let r = b
        .client
        .delete(b.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 503);
    assert!(start.elapsed() < FAST * 3, "took {:?}", start.elapsed());
    // gRPC: UNAVAILABLE, quickly.
    let mut grpc = b.sessions().await;
    let start = Instant::now();
    let err = grpc
        .push_batch(pb_batch(&id, &bodies[k]))
        .await
        .unwrap_err();
    assert!(
        start.elapsed() < FAST,
        "gRPC push took {:?}",
        start.elapsed()
    );
    assert_eq!(err.code(), tonic::Code::Unavailable, "{err:?}");
    // While Redis is away the replicas stay in rotation (the stateless
    // endpoints work) and report the store degraded.
    for app in [&a, &b] {
        let start = Instant::now();
        let r = app.get("/readyz").await;
        assert!(start.elapsed() < FAST);
        assert_eq!(r.status(), 200);
        let body: Value = r.json().await.unwrap();
        assert_eq!(body["store"], "degraded");
        assert_eq!(app.get("/healthz/store").await.status(), 503);
    }

    // Redis comes back with its append-only file: both instances recover by
    // themselves and the session is where it was, with no half-applied batch.
    redis.restart();
    wait_readyz(&a, 200, Duration::from_secs(10)).await;
    wait_readyz(&b, 200, Duration::from_secs(10)).await;
    assert_eq!(a.state(&id).await, before);
    assert_eq!(b.state(&id).await, before);
    // The client retries the failed batch, then carries on, on both instances.
    let retried = grpc
        .push_batch(pb_batch(&id, &bodies[k]))
        .await
        .expect("gRPC works again on the same channel")
        .into_inner();
    assert!(!retried.duplicate, "the failed batch had not been applied");
    for (i, body) in bodies.iter().enumerate().skip(k + 1) {
        let to = if i % 2 == 0 { &a } else { &b };
        let u = to.push(&id, body).await;
        assert_eq!(u["duplicate"], false);
    }
    assert_same_outcome(&a.state(&id).await, &reference);
    b.delete(&id).await;
    a.stop().await.expect("server stops");
    b.stop().await.expect("server stops");
}

// ---------------------------------------------------------------- gRPC

fn with_key<T>(message: T, header: &'static str, value: &str) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    request
        .metadata_mut()
        .insert(header, value.parse().expect("ASCII metadata"));
    request
}

/// Tenant acme's key as `x-api-key` metadata.
fn acme<T>(message: T) -> tonic::Request<T> {
    with_key(message, "x-api-key", "key-of-acme-1")
}

/// Tenant globex's key as `authorization: Bearer` metadata.
fn globex<T>(message: T) -> tonic::Request<T> {
    with_key(message, "authorization", "Bearer key-of-globex")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenants_cannot_reach_each_others_sessions_over_grpc() {
    if !redis_is_up() {
        return;
    }
    let (a, b) = two_instances(&redis_url(), |s| {
        s.api_keys = Some("key-of-acme-1=acme,key-of-globex=globex".into());
    })
    .await;
    let (_, reports) = scenario();
    let bodies = batch_bodies(&reports);

    let mut on_a = a.sessions().await;
    let created = on_a
        .create_session(acme(pb_open()))
        .await
        .unwrap()
        .into_inner();
    let id = created.id.clone();
    assert_eq!(created.version, 1);

    let mut on_b = b.sessions().await;
    let get = || pb::GetSessionRequest {
        session_id: id.clone(),
    };
    let err = on_b.get_session(globex(get())).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::NotFound, "{err:?}");
    let err = on_b
        .push_batch(globex(pb_batch(&id, &bodies[0])))
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::NotFound, "{err:?}");
    let err = on_b
        .delete_session(globex(pb::DeleteSessionRequest {
            session_id: id.clone(),
        }))
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::NotFound, "{err:?}");
    let listed = on_b
        .list_sessions(globex(pb::ListSessionsRequest {}))
        .await
        .unwrap()
        .into_inner();
    assert!(listed.sessions.is_empty(), "{listed:?}");
    // A stream attached by the other tenant is refused too.
    let (tx, rx) = tokio::sync::mpsc::channel(1);
    tx.send(pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Attach(id.clone())),
    })
    .await
    .unwrap();
    let outcome = match on_b
        .stream(globex(tokio_stream::wrappers::ReceiverStream::new(rx)))
        .await
    {
        Ok(response) => response.into_inner().message().await.map(|_| ()),
        Err(status) => Err(status),
    };
    assert_eq!(
        outcome.unwrap_err().code(),
        tonic::Code::NotFound,
        "attach by another tenant"
    );
    // No key at all: UNAUTHENTICATED, on either instance.
    for client in [&mut on_a, &mut on_b] {
        let err = client.get_session(get()).await.unwrap_err();
        assert_eq!(err.code(), tonic::Code::Unauthenticated);
        let err = client
            .list_sessions(pb::ListSessionsRequest {})
            .await
            .unwrap_err();
        assert_eq!(err.code(), tonic::Code::Unauthenticated);
    }
    // Over REST too, the other tenant gets 404.
    let r = b
        .client
        .get(b.url(&format!("/v1/sessions/{id}")))
        .bearer_auth("key-of-globex")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);

    // The owner reaches it through either instance, and nothing changed.
    let pushed = on_b
        .push_batch(acme(pb_batch(&id, &bodies[0])))
        .await
        .unwrap()
        .into_inner();
    assert!(!pushed.duplicate);
    assert_eq!(pushed.version, 2);
    let state = on_a.get_session(acme(get())).await.unwrap().into_inner();
    assert_eq!((state.batches, state.version), (1, 2));
    let listed = on_b
        .list_sessions(acme(pb::ListSessionsRequest {}))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(listed.sessions.len(), 1);
    assert_eq!(listed.sessions[0].id, id);
    on_b.delete_session(acme(pb::DeleteSessionRequest {
        session_id: id.clone(),
    }))
    .await
    .unwrap();
    let err = on_a.get_session(acme(get())).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::NotFound);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_grpc_stream_dropped_on_one_instance_continues_over_rest_on_the_other() {
    if !redis_is_up() {
        return;
    }
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(&redis_url(), |_| {}).await;
    let (_, reports) = scenario();
    let bodies = batch_bodies(&reports);
    let half = bodies.len() / 2;

    let mut client = a.sessions().await;
    let (tx, mut updates) =
        open_stream(&mut client, pb::stream_request::Kind::Open(pb_open())).await;
    let opened = updates.message().await.unwrap().expect("opened");
    let id = opened.session_id.clone();
    assert_eq!(opened.version, 1);
    for body in &bodies[..half] {
        tx.send(pb::StreamRequest {
            kind: Some(pb::stream_request::Kind::Batch(pb_batch("", body))),
        })
        .await
        .unwrap();
        let u = updates.message().await.unwrap().expect("update");
        assert_eq!(u.sequence, body["sequence"].as_u64());
        assert!(!u.duplicate);
    }
    // The client disconnects mid-stream.
    drop(tx);
    drop(updates);
    drop(client);

    // Instance B sees the session as the stream left it.
    let state = b.state(&id).await;
    assert_eq!(state["batches"], half as u64);
    assert_eq!(state["last_sequence"], half as u64);
    assert_eq!(state["version"], half as u64 + 1);
    // A stream attached on B learns where to go on from.
    let mut on_b = b.sessions().await;
    let (tx, mut attached) =
        open_stream(&mut on_b, pb::stream_request::Kind::Attach(id.clone())).await;
    let ack = attached.message().await.unwrap().expect("attached");
    assert_eq!(ack.session_id, id);
    assert_eq!(ack.sequence, Some(half as u64));
    drop(tx);
    drop(attached);

    // The rest over REST on B, retrying the last streamed batch first.
    let again = b.push(&id, &bodies[half - 1]).await;
    assert_eq!(again["duplicate"], true);
    for body in &bodies[half..] {
        let u = b.push(&id, body).await;
        assert_eq!(u["duplicate"], false);
    }
    assert_same_outcome(&a.state(&id).await, &reference);
    b.delete(&id).await;
}

/// Sends a signal to the redis-server child (`STOP` or `CONT`).
/// A Redis that stops answering (SIGSTOP) rather than going away: requests
/// still fail fast, bounded by the store timeout, and recover when it resumes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_hung_redis_fails_fast_and_the_session_continues_after_it_resumes() {
    let Some(redis) = private_redis() else {
        return;
    };
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(&redis.url(), |s| s.store_timeout_s = 0.5).await;
    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let bodies = batch_bodies(&reports);
    let k = 5;
    for body in &bodies[..k] {
        b.push(&id, body).await;
    }
    let before = a.state(&id).await;

    redis.signal("STOP");
    for app in [&a, &b] {
        let start = Instant::now();
        let r = app
            .post_json(&format!("/v1/sessions/{id}/batches"), &bodies[k])
            .await;
        assert!(start.elapsed() < FAST, "push took {:?}", start.elapsed());
        assert_eq!(r.status(), 503);
        assert_eq!(r.headers()["retry-after"], "1");
        let start = Instant::now();
        assert_eq!(app.get("/healthz/store").await.status(), 503);
        assert!(
            start.elapsed() < FAST,
            "store health took {:?}",
            start.elapsed()
        );
        assert_eq!(app.get("/readyz").await.status(), 200);
    }
    redis.signal("CONT");

    wait_readyz(&a, 200, Duration::from_secs(10)).await;
    wait_readyz(&b, 200, Duration::from_secs(10)).await;
    // The 503s said the outcome was unknown, and it was: B had written the
    // session last, so it sent its compare-and-set without a read, and the
    // hung Redis applied it when it resumed; A's, from a stale copy, lost
    // the race. Batch k is applied exactly once either way, and its retry
    // with the same sequence number is recognised.
    let after = b.state(&id).await;
    assert!(
        after == before || after["last_sequence"] == k + 1,
        "batch {} applied more than once: {after}",
        k + 1
    );
    let retry = a.push(&id, &bodies[k]).await;
    assert_eq!(retry["duplicate"], after["last_sequence"] == k + 1);
    for (i, body) in bodies.iter().enumerate().skip(k + 1) {
        let to = if i % 2 == 0 { &a } else { &b };
        let u = to.push(&id, body).await;
        assert_eq!(u["duplicate"], false);
    }
    assert_same_outcome(&a.state(&id).await, &reference);
    a.delete(&id).await;
}

/// The same without sequence numbers: a batch answered 503 while Redis hung
/// may have been written when it resumed; retried unchanged, it is known by
/// its fingerprint and not applied twice. Every batch of the run is pushed
/// once more too: nothing is applied twice, and the final state is the
/// single-instance run's.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unsequenced_batch_retried_after_a_503_is_not_applied_twice() {
    let Some(redis) = private_redis() else {
        return;
    };
    let reference = single_instance_outcome().await;
    let (a, b) = two_instances(&redis.url(), |s| s.store_timeout_s = 0.5).await;
    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    // The bodies without their sequence numbers.
    let bodies: Vec<Value> = batch_bodies(&reports)
        .into_iter()
        .map(|mut body| {
            body.as_object_mut().unwrap().remove("sequence");
            body
        })
        .collect();
    let k = 5;
    for body in &bodies[..k] {
        b.push(&id, body).await;
    }
    redis.signal("STOP");
    let r = b
        .post_json(&format!("/v1/sessions/{id}/batches"), &bodies[k])
        .await;
    assert_eq!(r.status(), 503);
    redis.signal("CONT");
    wait_readyz(&b, 200, Duration::from_secs(10)).await;
    // The client retries batch k unchanged, then every batch again.
    let retry = a.push(&id, &bodies[k]).await;
    let state = a.state(&id).await;
    let applied = state["batches"].as_u64().unwrap();
    assert_eq!(applied, k as u64 + 1, "{retry}");
    for (i, body) in bodies.iter().enumerate().skip(k + 1) {
        let to = if i % 2 == 0 { &a } else { &b };
        to.push(&id, body).await;
    }
    for body in &bodies[..bodies.len() - 1] {
        let again = a.push(&id, body).await;
        assert_eq!(again["duplicate"], true, "{again}");
    }
    let end = a.state(&id).await;
    assert_eq!(end["batches"], bodies.len() as u64);
    for field in [
        "pairs",
        "system_tracks",
        "instants_processed",
        "reports_accepted",
    ] {
        assert_eq!(end[field], reference[field], "{field}");
    }
    a.delete(&id).await;
}

/// A stream batch that outlives the request timeout (its Redis hung, the
/// store timeout longer than the request's) answers DEADLINE_EXCEEDED inside
/// the stream, which stays open; once Redis resumes, the same batch retried
/// with its sequence number is applied exactly once in all (the hung write
/// may have landed: then the retry is acknowledged as a duplicate), and the
/// stream goes on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_batch_past_the_request_timeout_answers_deadline_exceeded_and_the_stream_goes_on()
{
    let Some(redis) = private_redis() else {
        return;
    };
    let (a, _b) = two_instances(&redis.url(), |s| {
        s.store_timeout_s = 5.0;
        s.request_timeout_s = 0.3;
    })
    .await;
    let (batch, reports) = scenario();
    let bodies = batch_bodies(&reports);
    let id = a.create(&session_config(&batch)).await;
    let mut client = a.sessions().await;
    let (tx, mut updates) =
        open_stream(&mut client, pb::stream_request::Kind::Attach(id.clone())).await;
    let send = |body: &Value| pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Batch(pb_batch("", body))),
    };
    updates.message().await.unwrap().expect("attached");
    tx.send(send(&bodies[0])).await.unwrap();
    let first = updates.message().await.unwrap().expect("update");
    assert!(first.error.is_none());

    redis.signal("STOP");
    tx.send(send(&bodies[1])).await.unwrap();
    let timed_out = updates
        .message()
        .await
        .unwrap()
        .expect("answered, not ended");
    let error = timed_out.error.expect("timed out");
    assert_eq!(error.code_name, "DEADLINE_EXCEEDED");
    assert!(error.message.contains("same sequence number"), "{error:?}");
    redis.signal("CONT");
    wait_readyz(&a, 200, Duration::from_secs(10)).await;

    tx.send(send(&bodies[1])).await.unwrap();
    let retried = updates.message().await.unwrap().expect("update");
    assert!(retried.error.is_none(), "{retried:?}");
    tx.send(send(&bodies[2])).await.unwrap();
    let next = updates.message().await.unwrap().expect("update");
    assert!(next.error.is_none() && !next.duplicate, "{next:?}");
    let state = a.state(&id).await;
    assert_eq!(
        (state["batches"].as_u64(), state["version"].as_u64()),
        (Some(3), Some(4))
    );
}

/// Reads the next SSE event (name, id, data) of a streaming response,
/// heartbeat comments skipped.
async fn next_sse(response: &mut reqwest::Response, buf: &mut String) -> (String, u64, Value) {
    loop {
        if let Some(i) = buf.find("\n\n") {
            let block: String = buf.drain(..i + 2).collect();
            let (mut event, mut id, mut data) = (String::new(), 0, String::new());
            for line in block.lines() {
                if let Some(v) = line.strip_prefix("event:") {
                    event = v.trim().into();
                } else if let Some(v) = line.strip_prefix("id:") {
                    id = v.trim().parse().unwrap();
                } else if let Some(v) = line.strip_prefix("data:") {
                    data.push_str(v.trim_start());
                }
            }
            if !data.is_empty() {
                return (event, id, serde_json::from_str(&data).unwrap());
            }
            continue;
        }
        let chunk = tokio::time::timeout(Duration::from_secs(20), response.chunk())
            .await
            .expect("an event within 20 s")
            .unwrap()
            .expect("the stream is open");
        buf.push_str(&String::from_utf8_lossy(&chunk).replace("\r\n", "\n"));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_watcher_on_one_instance_sees_every_update_pushed_on_either_in_order() {
    if !redis_is_up() {
        return;
    }
    let (a, b) = two_instances(&redis_url(), |_| {}).await;
    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let mut watch = b
        .client
        .get(b.url(&format!("/v1/sessions/{id}/events")))
        .send()
        .await
        .unwrap();
    assert_eq!(watch.status(), 200);
    let mut buf = String::new();
    let (event, version, _) = next_sse(&mut watch, &mut buf).await;
    assert_eq!((event.as_str(), version), ("snapshot", 1));
    let bodies = batch_bodies(&reports);
    let mut answers = Vec::new();
    for (i, body) in bodies.iter().enumerate() {
        let to = if i % 2 == 0 { &a } else { &b };
        answers.push(to.push(&id, body).await);
    }
    // Every update, as its push answered it, in version order; a gap is
    // filled by a snapshot (pub/sub may lose a message), never skipped.
    let last = bodies.len() as u64 + 1;
    let mut seen = 1;
    while seen < last {
        let (event, version, data) = next_sse(&mut watch, &mut buf).await;
        assert!(version > seen, "{event} {version} after {seen}");
        match event.as_str() {
            "update" => {
                assert_eq!(version, seen + 1, "updates in version order");
                assert_eq!(data, answers[(version - 2) as usize]);
            }
            "snapshot" => assert_eq!(data["version"], version),
            other => panic!("unexpected {other} event: {data}"),
        }
        seen = version;
    }
    a.delete(&id).await;
    let (event, _, data) = next_sse(&mut watch, &mut buf).await;
    assert_eq!(
        (event.as_str(), &data["reason"]),
        ("end", &json!("deleted"))
    );
}

// ---------------------------------------------------------------- Sentinel

/// The store's part of `/healthz/store`: (status code, failing over). It
/// names no host (the probes need no key).
async fn store_health(app: &App) -> (u16, Value) {
    let r = app.get("/healthz/store").await;
    let code = r.status().as_u16();
    let body: Value = r.json().await.unwrap();
    assert!(body.get("primary").is_none(), "a host named: {body}");
    (code, body["failing_over"].clone())
}

/// The server the instance's store uses (its `host:port`, the seeds of a
/// Cluster), as the store reports it inside the process: no route shows it.
fn primary(app: &App) -> Value {
    json!(app.state.store().topology().and_then(|t| t.primary))
}

/// The value of an unlabelled sample in `/metrics`.
async fn metric(app: &App, name: &str) -> Option<f64> {
    counter(&app.get("/metrics").await.text().await.unwrap(), name)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sentinel_failover_under_pushes_from_two_instances_applies_every_batch_once() {
    let Some(deployment) = sentinel::Topology::start("the service on Sentinel") else {
        return;
    };
    let (url, primary_port) = (deployment.url(), deployment.primary_port);
    let mut topology = Some(deployment);
    let reference = single_instance_outcome().await;
    // Every write waits for a replica (`WAIT 1`): without it, a batch
    // acknowledged just before the kill can be lost with the primary. With
    // two replicas, the promoted one has every acknowledged write (the
    // sentinels promote the one furthest ahead) and the other replicates it.
    let (a, b) = two_instances(&url, |s| {
        s.store_timeout_s = 0.5;
        s.redis_wait_replicas = 1;
    })
    .await;
    let first = json!(format!("127.0.0.1:{primary_port}"));
    for app in [&a, &b] {
        wait_readyz(app, 200, Duration::from_secs(10)).await;
        assert_eq!(store_health(app).await, (200, json!(false)));
        assert_eq!(primary(app), first);
        let ready: Value = app.get("/readyz").await.json().await.unwrap();
        assert_eq!(
            ready,
            json!({"status": "ready", "store": "ok", "failing_over": false})
        );
    }

    let (batch, reports) = scenario();
    let id = a.create(&session_config(&batch)).await;
    let bodies = batch_bodies(&reports);
    let k = 4;
    assert!(
        bodies.len() > k + 4,
        "batches after the kill: {}",
        bodies.len()
    );
    let (mut refused, mut duplicates) = (0u32, 0u32);
    let (mut killed, mut recovered) = (None, None);
    let (tx, rx) = std::sync::mpsc::channel();
    let mut kill = None;
    for (i, body) in bodies.iter().enumerate() {
        if i == k {
            // Pushes go on while the primary dies: it is SIGKILLed from
            // another thread a moment after this batch is sent.
            let (mut deployment, tx) = (topology.take().unwrap(), tx.clone());
            kill = Some(std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(5));
                deployment.kill_primary();
                tx.send(Instant::now()).unwrap();
                deployment
            }));
        }
        let deadline = Instant::now() + Duration::from_secs(90);
        let mut to = if i % 2 == 0 { &a } else { &b };
        loop {
            let r = to
                .post_json(&format!("/v1/sessions/{id}/batches"), body)
                .await;
            killed = killed.or_else(|| rx.try_recv().ok());
            match r.status().as_u16() {
                200 => {
                    let u: Value = r.json().await.unwrap();
                    duplicates += u32::from(u["duplicate"] == true);
                    if refused > 0 && recovered.is_none() {
                        recovered = killed.map(|k: Instant| k.elapsed());
                    }
                    break;
                }
                503 | 504 => {
                    refused += 1;
                    assert!(
                        Instant::now() < deadline,
                        "no primary again within 90 s (a sentinel in TILT mode waits 30 s)"
                    );
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    // Retry unchanged, same sequence, on the other instance.
                    to = if std::ptr::eq(to, &a) { &b } else { &a };
                }
                other => panic!("batch {i}: {other}: {}", r.text().await.unwrap()),
            }
        }
    }
    let topology = kill.expect("killed").join().unwrap();
    assert!(refused > 0, "the kill was seen by the pushes");
    assert_same_outcome(&a.state(&id).await, &reference);
    assert_same_outcome(&b.state(&id).await, &reference);

    let second = json!(topology.current_primary());
    assert_ne!(second, first);
    for app in [&a, &b] {
        assert_eq!(store_health(app).await, (200, json!(false)));
        assert_eq!(primary(app), second);
        let ready: Value = app.get("/readyz").await.json().await.unwrap();
        assert!(ready.get("primary").is_none(), "a host named: {ready}");
        assert_eq!(
            metric(app, "session_store_failovers_total").await,
            Some(1.0)
        );
        assert!(metric(app, "session_store_redirections_total").await >= Some(1.0));
        assert_eq!(metric(app, "session_store_failing_over").await, Some(0.0));
    }
    procs::loud(&format!(
        "sentinel failover (service): SIGKILL -> first accepted batch {:?}, {refused} answers \
         503/504, {duplicates} retried batches acknowledged as duplicates, {} batches",
        recovered,
        bodies.len()
    ));
    a.stop().await.expect("server stops");
    b.stop().await.expect("server stops");
}
