//! TLS and credentials to Redis against a real `redis-server` started here
//! with `--tls-port` (and `--port 0`: no plaintext), certificates made by
//! rcgen, mutual TLS (`--tls-auth-clients yes`) and `--requirepass`, in a
//! scratch `--dir`. Skipped with a loud line only when redis-server is not
//! on PATH or was built without TLS.

use std::{
    path::PathBuf,
    process::{Command, Stdio},
    sync::atomic::{AtomicU32, Ordering},
    time::{Duration, Instant},
};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};
use store::{CasOutcome, SessionStore, StoreError, StoreSettings, access::RedisAccessSettings};
use test_support::procs::{Proc, free_port, loud, redis_tools};

const PASSWORD: &str = "s3cret-Pa55word-for-tls-test";

/// A CA, a server and a client certificate, written as PEM files.
struct Pki {
    dir: PathBuf,
}

fn ca(name: &str) -> (Issuer<'static, KeyPair>, String) {
    let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
    params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    params.distinguished_name.push(
        DnType::CommonName,
        format!("Radar Fusion Redis test CA {name}"),
    );
    let key = KeyPair::generate().unwrap();
    let pem = params.self_signed(&key).unwrap().pem();
    (Issuer::new(params, key), pem)
}

fn leaf(
    issuer: &Issuer<'static, KeyPair>,
    names: &[&str],
    usage: &[ExtendedKeyUsagePurpose],
) -> (String, String) {
    let mut params =
        CertificateParams::new(names.iter().map(|n| n.to_string()).collect::<Vec<_>>()).unwrap();
    params
        .distinguished_name
        .push(DnType::CommonName, "radar-fusion");
    params.extended_key_usages = usage.to_vec();
    let key = KeyPair::generate().unwrap();
    let cert = params.signed_by(&key, issuer).unwrap();
    (cert.pem(), key.serialize_pem())
}

impl Pki {
    fn new() -> Self {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "fusion-redis-tls-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let (issuer, ca_pem) = ca("right");
        let (_, other_ca_pem) = ca("wrong");
        let (server_cert, server_key) = leaf(
            &issuer,
            &["localhost", "127.0.0.1"],
            // Sentinels present it to the primary as a client, too.
            &[
                ExtendedKeyUsagePurpose::ServerAuth,
                ExtendedKeyUsagePurpose::ClientAuth,
            ],
        );
        let (client_cert, client_key) = leaf(&issuer, &[], &[ExtendedKeyUsagePurpose::ClientAuth]);
        for (name, pem) in [
            ("ca.pem", &ca_pem),
            ("other-ca.pem", &other_ca_pem),
            ("server.pem", &server_cert),
            ("server.key", &server_key),
            ("client.pem", &client_cert),
            ("client.key", &client_key),
        ] {
            std::fs::write(dir.join(name), pem).unwrap();
        }
        Self { dir }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

impl Drop for Pki {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// `redis-server` with TLS only, mutual TLS and a password; `None` (after a
/// loud SKIPPED line) when it is not installed or has no TLS.
fn tls_redis(pki: &Pki) -> Option<(Proc, u16)> {
    let port = free_port();
    let data = pki.path(&format!("data-{port}"));
    std::fs::create_dir_all(&data).unwrap();
    let mut args = tls_args(pki, port);
    args.extend(
        [
            "--tls-auth-clients",
            "yes",
            "--requirepass",
            PASSWORD,
            "--save",
            "",
            "--appendonly",
            "no",
            "--dir",
            data.to_str().unwrap(),
        ]
        .map(String::from),
    );
    spawn(&args, &data, port)
}

/// A sentinel over TLS (to clients and to the primary) watching `primary`.
fn tls_sentinel(pki: &Pki, primary: u16) -> Option<(Proc, u16)> {
    let port = free_port();
    let data = pki.path(&format!("sentinel-{port}"));
    std::fs::create_dir_all(&data).unwrap();
    let conf = data.join("sentinel.conf");
    std::fs::write(
        &conf,
        format!(
            "sentinel monitor fusion 127.0.0.1 {primary} 1\n\
             sentinel auth-pass fusion {PASSWORD}\n"
        ),
    )
    .unwrap();
    let mut args = vec![conf.to_str().unwrap().to_string(), "--sentinel".into()];
    args.extend(tls_args(pki, port));
    args.extend(
        [
            "--tls-auth-clients",
            "no",
            "--tls-replication",
            "yes",
            "--dir",
            data.to_str().unwrap(),
        ]
        .map(String::from),
    );
    spawn(&args, &data, port)
}

fn tls_args(pki: &Pki, port: u16) -> Vec<String> {
    let s = |name: &str| pki.path(name).to_str().unwrap().to_string();
    [
        "--port".into(),
        "0".into(),
        "--tls-port".into(),
        port.to_string(),
        "--bind".into(),
        "127.0.0.1".into(),
        "--tls-cert-file".into(),
        s("server.pem"),
        "--tls-key-file".into(),
        s("server.key"),
        "--tls-ca-cert-file".into(),
        s("ca.pem"),
    ]
    .to_vec()
}

fn spawn(args: &[String], data: &std::path::Path, port: u16) -> Option<(Proc, u16)> {
    redis_tools("Redis TLS tests", &["redis-server"])?;
    let log = data.join("redis.log");
    let mut server = Proc(
        Command::new("redis-server")
            .args(args)
            .args(["--logfile", log.to_str().unwrap()])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("redis-server starts"),
    );
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
            return Some((server, port));
        }
        if let Ok(Some(_)) = server.0.try_wait() {
            let mut text = std::fs::read_to_string(&log).unwrap_or_default();
            if let Some(mut err) = server.0.stderr.take() {
                let _ = std::io::Read::read_to_string(&mut err, &mut text);
            }
            if text.contains("TLS") || text.contains("tls") {
                loud(&format!(
                    "SKIPPED: redis_tls: this redis-server has no TLS ({})",
                    text.trim()
                ));
                return None;
            }
            panic!("redis-server with TLS exited: {text}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("redis-server with TLS does not listen on {port}");
}

fn settings(url: String, redis: RedisAccessSettings) -> StoreSettings {
    StoreSettings {
        url,
        redis,
        wait_replicas: 0,
        key_prefix: "tls-test".into(),
        max_sessions_per_tenant: 10,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_secs(2),
    }
}

fn access(pki: &Pki, ca: &str, password: Option<&str>) -> RedisAccessSettings {
    RedisAccessSettings {
        ca: Some(pki.path(ca)),
        cert: Some(pki.path("client.pem")),
        key: Some(pki.path("client.key")),
        password: password.map(str::to_string),
    }
}

fn assert_config(result: Result<SessionStore, StoreError>, setting: &str, secrets: &[&str]) {
    match result {
        Err(e @ StoreError::Config { .. }) => {
            let text = e.to_string();
            assert!(text.contains(setting), "{text}");
            for s in secrets {
                assert!(!text.contains(s), "the error shows a secret: {text}");
            }
        }
        Err(e) => panic!("expected a configuration error naming {setting}, got {e}"),
        Ok(_) => panic!("expected a configuration error naming {setting}, the store started"),
    }
}

#[tokio::test]
async fn the_store_talks_tls_with_the_ca_a_client_certificate_and_the_password() {
    let pki = Pki::new();
    let Some((server, port)) = tls_redis(&pki) else {
        return;
    };
    // The password as FUSION_REDIS_PASSWORD gives it (the URL has none).
    let store = SessionStore::connect(&settings(
        format!("rediss://127.0.0.1:{port}/0"),
        access(&pki, "ca.pem", Some(PASSWORD)),
    ))
    .await
    .expect("the store starts over TLS");
    let ttl = Duration::from_secs(60);
    assert_eq!(
        store
            .create("t", "s", "correlation", b"a".to_vec(), ttl)
            .await,
        Ok(1)
    );
    assert_eq!(
        store.compare_and_set("t", "s", 1, b"b".to_vec(), ttl).await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    assert_eq!(store.get("t", "s").await.unwrap().unwrap().data, b"b");
    store.ping().await.expect("ping over TLS");

    // The password in the URL works as well (user `default`, the one
    // `requirepass` sets).
    let from_url = SessionStore::connect(&settings(
        format!("rediss://default:{PASSWORD}@127.0.0.1:{port}/0"),
        access(&pki, "ca.pem", None),
    ))
    .await
    .expect("the store starts with the URL's password");
    assert_eq!(from_url.version("t", "s").await, Ok(Some(2)));
    // Health names the server, never the credentials.
    let topology = from_url.topology().unwrap();
    assert_eq!(topology.primary, Some(format!("127.0.0.1:{port}")));
    assert!(!format!("{topology:?}").contains(PASSWORD));

    // Redis gone: errors say unavailable and never show the password.
    drop(server);
    let e = store.get("t", "s").await.unwrap_err();
    assert!(matches!(e, StoreError::Unavailable { .. }), "{e}");
    assert!(!e.to_string().contains(PASSWORD), "{e}");
}

#[tokio::test]
async fn a_wrong_ca_a_wrong_password_or_no_client_certificate_refuse_to_start() {
    let pki = Pki::new();
    let Some((_server, port)) = tls_redis(&pki) else {
        return;
    };
    let url = format!("rediss://127.0.0.1:{port}/0");
    assert_config(
        SessionStore::connect(&settings(
            url.clone(),
            access(&pki, "other-ca.pem", Some(PASSWORD)),
        ))
        .await,
        "FUSION_REDIS_CA",
        &[PASSWORD],
    );
    let wrong = "not-the-Pa55word";
    assert_config(
        SessionStore::connect(&settings(url.clone(), access(&pki, "ca.pem", Some(wrong)))).await,
        "FUSION_REDIS_PASSWORD",
        &[wrong, PASSWORD],
    );
    assert_config(
        SessionStore::connect(&settings(
            format!("rediss://default:{wrong}@127.0.0.1:{port}/0"),
            access(&pki, "ca.pem", None),
        ))
        .await,
        "FUSION_REDIS_PASSWORD",
        &[wrong],
    );
    let mut no_client_cert = access(&pki, "ca.pem", Some(PASSWORD));
    (no_client_cert.cert, no_client_cert.key) = (None, None);
    assert_config(
        SessionStore::connect(&settings(url.clone(), no_client_cert)).await,
        "FUSION_REDIS_CERT",
        &[PASSWORD],
    );
    // Plaintext to a TLS-only port: the CA is meaningless without rediss://.
    assert_config(
        SessionStore::connect(&settings(
            format!("redis://127.0.0.1:{port}/0"),
            access(&pki, "ca.pem", None),
        ))
        .await,
        "FUSION_REDIS_CA",
        &[],
    );
}

#[tokio::test]
async fn a_tls_redis_that_is_down_at_start_leaves_the_store_degraded_not_refused() {
    let pki = Pki::new();
    let port = free_port();
    let store = SessionStore::connect(&settings(
        format!("rediss://127.0.0.1:{port}/0"),
        access(&pki, "ca.pem", Some(PASSWORD)),
    ))
    .await
    .expect("a Redis that is down is an outage, not a configuration error");
    let e = store.ping().await.unwrap_err();
    assert!(matches!(e, StoreError::Unavailable { .. }), "{e}");
    assert!(!e.to_string().contains(PASSWORD), "{e}");
}

#[tokio::test]
async fn rediss_sentinel_finds_the_primary_over_tls() {
    let pki = Pki::new();
    let Some((_primary, port)) = tls_redis(&pki) else {
        return;
    };
    let Some((_sentinel, sentinel)) = tls_sentinel(&pki, port) else {
        return;
    };
    let url = format!("rediss+sentinel://127.0.0.1:{sentinel}/fusion/0");
    let store = SessionStore::connect(&settings(
        url.clone(),
        access(&pki, "ca.pem", Some(PASSWORD)),
    ))
    .await
    .expect("the store starts through TLS sentinels");
    let ttl = Duration::from_secs(60);
    assert_eq!(
        store
            .create("t", "s", "correlation", b"a".to_vec(), ttl)
            .await,
        Ok(1)
    );
    assert_eq!(store.version("t", "s").await, Ok(Some(1)));
    let topology = store.topology().unwrap();
    assert_eq!(topology.primary, Some(format!("127.0.0.1:{port}")));
    // A wrong CA is refused at start, naming the setting, through the
    // sentinels as well.
    assert_config(
        SessionStore::connect(&settings(url, access(&pki, "other-ca.pem", Some(PASSWORD)))).await,
        "FUSION_REDIS_CA",
        &[PASSWORD],
    );
}
