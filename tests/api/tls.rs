//! TLS and mutual TLS on both ports (issue 34), through the real servers
//! with certificates made here by rcgen: REST and gRPC over TLS, ALPN,
//! client certificates required, refused and mapped to tenants, plaintext
//! and slow handshakes cut, a certificate reloaded while a connection
//! stays open, the `healthcheck` command over TLS and files that stop the
//! start.
//!
//! The waits below are bounds on an outcome (the server closes, a reload
//! is seen), never measurements of speed.

use std::{net::SocketAddr, path::PathBuf, sync::Arc, time::Duration};

use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::rt::{TokioExecutor, TokioIo};
use radar_fusion::{
    config::{ClientAuth, Settings},
    proto::{
        self as pb, correlation_service_client::CorrelationServiceClient,
        session_service_client::SessionServiceClient,
    },
};
use rcgen::{
    BasicConstraints, CertificateParams, CertificateRevocationListParams, DnType,
    ExtendedKeyUsagePurpose, IsCa, Issuer, KeyIdMethod, KeyPair, KeyUsagePurpose, RevocationReason,
    RevokedCertParams, SanType, SerialNumber, date_time_ymd,
};
use rustls::{
    ClientConfig, RootCertStore,
    pki_types::{CertificateDer, PrivateKeyDer, ServerName, pem::PemObject},
};
use serde_json::{Value, json};
use tokio::{
    io::{AsyncReadExt, AsyncWriteExt},
    net::TcpStream,
};
use tokio_rustls::{TlsConnector, client::TlsStream};
use tonic::transport::{Channel, Endpoint};

use crate::helpers::{TestApp, spawn_app_with};

const EVALUATE: &str = "/v1/correlation/rules/evaluate";
const BOUND: Duration = Duration::from_secs(10);

// ---------------------------------------------------------------------------
// Certificates

/// A test CA and the files made with it, in a scratch directory.
struct Pki {
    issuer: Issuer<'static, KeyPair>,
    ca_pem: String,
    dir: PathBuf,
}

/// A certificate and its key, PEM.
struct Pair {
    cert: String,
    key: String,
}

impl Pki {
    fn new(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!(
            "radar-fusion-tls-test-{name}-{}-{}",
            std::process::id(),
            rand::random::<u32>()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        params
            .distinguished_name
            .push(DnType::CommonName, format!("Radar Fusion test CA {name}"));
        let key = KeyPair::generate().unwrap();
        let ca = params.self_signed(&key).unwrap();
        Self {
            ca_pem: ca.pem(),
            issuer: Issuer::new(params, key),
            dir,
        }
    }

    /// A server certificate for `localhost` and 127.0.0.1.
    fn server(&self) -> Pair {
        let mut params =
            CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
        params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth];
        self.sign(params)
    }

    /// A client certificate with this common name and URI names.
    fn client(&self, cn: &str, uris: &[&str]) -> Pair {
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.distinguished_name.push(DnType::CommonName, cn);
        for uri in uris {
            params
                .subject_alt_names
                .push(SanType::URI((*uri).try_into().unwrap()));
        }
        params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ClientAuth];
        self.sign(params)
    }

    /// A client certificate with this common name and serial number.
    fn client_numbered(&self, cn: &str, serial: u64) -> Pair {
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.distinguished_name.push(DnType::CommonName, cn);
        params.serial_number = Some(SerialNumber::from(serial));
        params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ClientAuth];
        self.sign(params)
    }

    /// A revocation list of this CA revoking the certificates of `serials`,
    /// DER.
    fn crl(&self, serials: &[u64]) -> Vec<u8> {
        CertificateRevocationListParams {
            this_update: date_time_ymd(2025, 1, 1),
            next_update: date_time_ymd(2100, 1, 1),
            crl_number: SerialNumber::from(serials.len() as u64 + 1),
            issuing_distribution_point: None,
            revoked_certs: serials
                .iter()
                .map(|&s| RevokedCertParams {
                    serial_number: SerialNumber::from(s),
                    revocation_time: date_time_ymd(2025, 6, 1),
                    reason_code: Some(RevocationReason::KeyCompromise),
                    invalidity_date: None,
                })
                .collect(),
            key_identifier_method: KeyIdMethod::Sha256,
        }
        .signed_by(&self.issuer)
        .unwrap()
        .der()
        .to_vec()
    }

    fn sign(&self, params: CertificateParams) -> Pair {
        let key = KeyPair::generate().unwrap();
        let cert = params.signed_by(&key, &self.issuer).unwrap();
        Pair {
            cert: cert.pem(),
            key: key.serialize_pem(),
        }
    }

    fn write(&self, name: &str, contents: &str) -> PathBuf {
        let path = self.dir.join(name);
        std::fs::write(&path, contents).unwrap();
        path
    }

    /// Replaces a file at once (write then rename), as operators should.
    fn replace(&self, name: &str, contents: &str) {
        let tmp = self.write(&format!("{name}.tmp"), contents);
        std::fs::rename(tmp, self.dir.join(name)).unwrap();
    }

    /// Settings serving `pair` (certificate and key in one file, so that a
    /// replacement is one rename).
    fn serve(&self, settings: &mut Settings, pair: &Pair) {
        let both = self.write("server.pem", &format!("{}{}", pair.cert, pair.key));
        settings.tls_cert = Some(both.clone());
        settings.tls_key = Some(both);
    }

    /// ... and verifying clients against this CA.
    fn verify_clients(&self, settings: &mut Settings, auth: Option<ClientAuth>) {
        settings.tls_client_ca = Some(self.write("client-ca.pem", &self.ca_pem));
        settings.tls_client_auth = auth;
    }
}

impl Drop for Pki {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

// ---------------------------------------------------------------------------
// Clients

/// A client configuration trusting `ca_pem`, with a client certificate when
/// given, offering `alpn`.
fn client_config(ca_pem: &str, client: Option<&Pair>, alpn: &[&[u8]]) -> Arc<ClientConfig> {
    let mut roots = RootCertStore::empty();
    for cert in CertificateDer::pem_slice_iter(ca_pem.as_bytes()) {
        roots.add(cert.unwrap()).unwrap();
    }
    let builder =
        ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
            .with_safe_default_protocol_versions()
            .unwrap()
            .with_root_certificates(roots);
    let mut config = match client {
        None => builder.with_no_client_auth(),
        Some(pair) => {
            let chain = CertificateDer::pem_slice_iter(pair.cert.as_bytes())
                .collect::<Result<Vec<_>, _>>()
                .unwrap();
            let key = PrivateKeyDer::from_pem_slice(pair.key.as_bytes()).unwrap();
            builder.with_client_auth_cert(chain, key).unwrap()
        }
    };
    config.alpn_protocols = alpn.iter().map(|p| p.to_vec()).collect();
    Arc::new(config)
}

async fn tls_connect(
    addr: SocketAddr,
    config: Arc<ClientConfig>,
) -> std::io::Result<TlsStream<TcpStream>> {
    let tcp = TcpStream::connect(addr).await?;
    TlsConnector::from(config)
        .connect(ServerName::try_from("localhost").unwrap(), tcp)
        .await
}

/// The negotiated ALPN protocol of a client connection.
fn alpn(stream: &TlsStream<TcpStream>) -> Option<Vec<u8>> {
    stream.get_ref().1.alpn_protocol().map(<[u8]>::to_vec)
}

/// An HTTP request sender over one TLS connection, HTTP/1.1 or HTTP/2 as
/// negotiated by ALPN.
enum Sender {
    H1(hyper::client::conn::http1::SendRequest<Full<Bytes>>),
    H2(hyper::client::conn::http2::SendRequest<Full<Bytes>>),
}

impl Sender {
    async fn over(stream: TlsStream<TcpStream>) -> hyper::Result<Self> {
        let h2 = alpn(&stream).as_deref() == Some(b"h2");
        let io = TokioIo::new(stream);
        if h2 {
            let (sender, conn) =
                hyper::client::conn::http2::handshake(TokioExecutor::new(), io).await?;
            tokio::spawn(conn);
            Ok(Self::H2(sender))
        } else {
            let (sender, conn) = hyper::client::conn::http1::handshake(io).await?;
            tokio::spawn(conn);
            Ok(Self::H1(sender))
        }
    }

    /// Sends a request (a JSON body when given); the status and JSON body.
    async fn send(
        &mut self,
        method: &str,
        path: &str,
        body: Option<&Value>,
        bearer: Option<&str>,
    ) -> hyper::Result<(u16, Value)> {
        let mut req = hyper::Request::builder()
            .method(method)
            .uri(format!("https://localhost{path}"));
        if let Self::H1(_) = self {
            req = req.header("host", "localhost");
        }
        if let Some(key) = bearer {
            req = req.header("authorization", format!("Bearer {key}"));
        }
        let bytes = match body {
            Some(v) => {
                req = req.header("content-type", "application/json");
                Bytes::from(v.to_string())
            }
            None => Bytes::new(),
        };
        let req = req.body(Full::new(bytes)).unwrap();
        let response = match self {
            Self::H1(s) => {
                s.ready().await?;
                s.send_request(req).await?
            }
            Self::H2(s) => {
                s.ready().await?;
                s.send_request(req).await?
            }
        };
        let status = response.status().as_u16();
        let bytes = response.into_body().collect().await?.to_bytes();
        let json = serde_json::from_slice(&bytes).unwrap_or(Value::Null);
        Ok((status, json))
    }
}

/// A request on a new TLS connection with `config`.
async fn request(
    addr: SocketAddr,
    config: Arc<ClientConfig>,
    method: &str,
    path: &str,
    body: Option<&Value>,
    bearer: Option<&str>,
) -> Result<(u16, Value), String> {
    let stream = tls_connect(addr, config).await.map_err(|e| e.to_string())?;
    let mut sender = Sender::over(stream).await.map_err(|e| e.to_string())?;
    sender
        .send(method, path, body, bearer)
        .await
        .map_err(|e| e.to_string())
}

fn evaluate_body() -> Value {
    json!({"alpha": 0.05, "rules": [{"l": 3, "r": 4}]})
}

/// A gRPC channel over TLS with `config` (which must offer `h2`).
async fn grpc_channel(
    addr: SocketAddr,
    config: Arc<ClientConfig>,
) -> Result<Channel, tonic::transport::Error> {
    let connector = TlsConnector::from(config);
    Endpoint::from_static("http://localhost")
        .connect_with_connector(tower::service_fn(move |_: hyper::Uri| {
            let connector = connector.clone();
            async move {
                let tcp = TcpStream::connect(addr).await?;
                let tls = connector
                    .connect(ServerName::try_from("localhost").unwrap(), tcp)
                    .await?;
                Ok::<_, std::io::Error>(TokioIo::new(tls))
            }
        }))
        .await
}

fn evaluate_request() -> pb::EvaluateRulesRequest {
    pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![pb::LrRule {
            l: Some(3),
            r: Some(4),
        }],
    }
}

/// The value of a counter line of `/metrics` (0 when absent), read over TLS.
async fn counter(app: &TestApp, config: &Arc<ClientConfig>, series: &str) -> f64 {
    let stream = tls_connect(app.http_addr, config.clone()).await.unwrap();
    let mut sender = Sender::over(stream).await.unwrap();
    let req = hyper::Request::get("https://localhost/metrics")
        .header("host", "localhost")
        .body(Full::new(Bytes::new()))
        .unwrap();
    let text = match &mut sender {
        Sender::H1(s) => s.send_request(req).await.unwrap(),
        Sender::H2(s) => s.send_request(req).await.unwrap(),
    }
    .into_body()
    .collect()
    .await
    .unwrap()
    .to_bytes();
    let text = String::from_utf8_lossy(&text);
    text.lines()
        .find_map(|l| l.strip_prefix(series).and_then(|v| v.trim().parse().ok()))
        .unwrap_or(0.0)
}

/// Reads until the server closes; panics when it does not within [`BOUND`].
async fn read_until_closed(stream: &mut TcpStream, what: &str) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    let read = async {
        loop {
            match stream.read(&mut buf).await {
                Ok(0) | Err(_) => break,
                Ok(n) => out.extend_from_slice(&buf[..n]),
            }
        }
    };
    if tokio::time::timeout(BOUND, read).await.is_err() {
        panic!("{what}: the server kept the connection open");
    }
    out
}

// ---------------------------------------------------------------------------
// Tests

#[tokio::test]
async fn rest_and_grpc_are_served_over_tls_on_both_ports_with_alpn() {
    let pki = Pki::new("serve");
    let server = pki.server();
    let app = spawn_app_with(|s| pki.serve(s, &server)).await;

    // REST port: HTTP/1.1 and HTTP/2, each chosen by ALPN.
    for (offer, expected) in [
        (&[&b"http/1.1"[..]][..], &b"http/1.1"[..]),
        (&[b"h2"], b"h2"),
        (&[b"h2", b"http/1.1"], b"h2"),
    ] {
        let stream = tls_connect(app.http_addr, client_config(&pki.ca_pem, None, offer))
            .await
            .unwrap();
        assert_eq!(
            alpn(&stream).as_deref(),
            Some(expected),
            "offered {offer:?}"
        );
        let mut sender = Sender::over(stream).await.unwrap();
        let (status, body) = sender
            .send("POST", EVALUATE, Some(&evaluate_body()), None)
            .await
            .unwrap();
        assert_eq!(status, 200, "{body}");
        assert!(body["evaluations"].is_array(), "{body}");
    }
    // gRPC on both ports.
    let h2 = client_config(&pki.ca_pem, None, &[b"h2"]);
    for addr in [app.http_addr, app.grpc_addr] {
        let channel = grpc_channel(addr, h2.clone()).await.unwrap();
        let answer = CorrelationServiceClient::new(channel)
            .evaluate_rules(evaluate_request())
            .await
            .unwrap()
            .into_inner();
        assert_eq!(answer.evaluations.len(), 1, "{addr}");
    }
    // The gRPC port offers h2 only: a client that speaks only HTTP/1.1 is refused.
    let before = counter(
        &app,
        &h2,
        r#"tls_handshake_failures_total{server="grpc",reason="protocol"}"#,
    )
    .await;
    let refused = tls_connect(
        app.grpc_addr,
        client_config(&pki.ca_pem, None, &[b"http/1.1"]),
    )
    .await;
    assert!(refused.is_err(), "an HTTP/1.1-only client on the gRPC port");
    let after = counter(
        &app,
        &h2,
        r#"tls_handshake_failures_total{server="grpc",reason="protocol"}"#,
    )
    .await;
    assert!(after > before, "{before} -> {after}");
    // A client that does not trust the server's CA gives up the handshake.
    let other = Pki::new("stranger");
    assert!(
        tls_connect(app.http_addr, client_config(&other.ca_pem, None, &[b"h2"]))
            .await
            .is_err()
    );
    // Handshakes are counted.
    assert!(
        counter(
            &app,
            &h2,
            r#"tls_handshakes_total{server="grpc",kind="full"}"#
        )
        .await
            >= 1.0
    );
    assert!(
        counter(&app, &h2, r#"tls_certificate_not_after_seconds"#).await > 1.7e9,
        "the certificate's end of validity is exported"
    );
}

#[tokio::test]
async fn plaintext_to_a_tls_port_is_closed_at_once() {
    let pki = Pki::new("plaintext");
    let server = pki.server();
    // A header-read timeout far beyond the bound: closing in time is not the timeout's doing.
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        s.header_read_timeout_s = 600.0;
    })
    .await;
    let config = client_config(&pki.ca_pem, None, &[b"http/1.1"]);
    let series = |server: &str| {
        format!(r#"tls_handshake_failures_total{{server="{server}",reason="not_tls"}}"#)
    };
    let before_http = counter(&app, &config, &series("http")).await;
    let before_grpc = counter(&app, &config, &series("grpc")).await;
    for (addr, hello) in [
        (
            app.http_addr,
            &b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"[..],
        ),
        (app.http_addr, b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"),
        (app.grpc_addr, b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"),
    ] {
        let mut stream = TcpStream::connect(addr).await.unwrap();
        stream.write_all(hello).await.unwrap();
        let got = read_until_closed(&mut stream, "plaintext on a TLS port").await;
        assert!(got.is_empty(), "nothing is answered in plaintext: {got:?}");
    }
    assert!(counter(&app, &config, &series("http")).await >= before_http + 2.0);
    assert!(counter(&app, &config, &series("grpc")).await > before_grpc);
}

#[tokio::test]
async fn a_slow_handshake_is_cut_by_the_header_read_timeout() {
    let pki = Pki::new("slow");
    let server = pki.server();
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        s.header_read_timeout_s = 0.3;
    })
    .await;
    let config = client_config(&pki.ca_pem, None, &[b"http/1.1"]);
    let series = r#"tls_handshake_failures_total{server="http",reason="timeout"}"#;
    let before = counter(&app, &config, series).await;
    // The header of a TLS handshake record, and then nothing.
    let mut stream = TcpStream::connect(app.http_addr).await.unwrap();
    stream
        .write_all(&[0x16, 0x03, 0x01, 0x01, 0x00])
        .await
        .unwrap();
    read_until_closed(&mut stream, "a handshake that never finishes").await;
    assert!(counter(&app, &config, series).await > before);
    // A finished handshake, then no request: closed too.
    let mut tls = tls_connect(app.http_addr, config.clone()).await.unwrap();
    let mut buf = Vec::new();
    let closed = tokio::time::timeout(BOUND, tls.read_to_end(&mut buf)).await;
    assert!(
        closed.is_ok(),
        "a TLS connection that never begins a request is closed"
    );
    // Others are still served.
    let (status, _) = request(app.http_addr, config, "GET", "/healthz", None, None)
        .await
        .unwrap();
    assert_eq!(status, 200);
}

#[tokio::test]
async fn mutual_tls_required_refuses_missing_and_untrusted_certificates() {
    let pki = Pki::new("mtls");
    let server = pki.server();
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        pki.verify_clients(s, None); // `required` is the default
    })
    .await;
    let trusted = pki.client("ingest-1", &[]);
    let ok = client_config(&pki.ca_pem, Some(&trusted), &[b"http/1.1"]);
    let series = |reason: &str| {
        format!(r#"tls_handshake_failures_total{{server="http",reason="{reason}"}}"#)
    };
    let (no_cert_before, bad_cert_before) = (
        counter(&app, &ok, &series("no_client_cert")).await,
        counter(&app, &ok, &series("bad_client_cert")).await,
    );
    // No certificate: in TLS 1.3 the client learns of the refusal on its
    // first read, so the request fails.
    let none = client_config(&pki.ca_pem, None, &[b"http/1.1"]);
    let refused = request(
        app.http_addr,
        none,
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        None,
    )
    .await;
    assert!(
        refused.is_err(),
        "served without a client certificate: {refused:?}"
    );
    // A certificate of another CA.
    let stranger = Pki::new("mtls-stranger").client("ingest-1", &[]);
    let untrusted = client_config(&pki.ca_pem, Some(&stranger), &[b"http/1.1"]);
    let refused = request(
        app.http_addr,
        untrusted,
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        None,
    )
    .await;
    assert!(
        refused.is_err(),
        "served with an untrusted certificate: {refused:?}"
    );
    // On the gRPC port as well.
    let none_h2 = client_config(&pki.ca_pem, None, &[b"h2"]);
    let call = match grpc_channel(app.grpc_addr, none_h2).await {
        Ok(channel) => CorrelationServiceClient::new(channel)
            .evaluate_rules(evaluate_request())
            .await
            .map(|_| ()),
        Err(e) => Err(tonic::Status::unavailable(e.to_string())),
    };
    assert!(call.is_err(), "gRPC served without a client certificate");
    // A trusted certificate is served (no API keys: tenant `default`).
    let (status, body) = request(
        app.http_addr,
        ok.clone(),
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        None,
    )
    .await
    .unwrap();
    assert_eq!(status, 200, "{body}");
    let ok_h2 = client_config(&pki.ca_pem, Some(&trusted), &[b"h2"]);
    let channel = grpc_channel(app.grpc_addr, ok_h2).await.unwrap();
    CorrelationServiceClient::new(channel)
        .evaluate_rules(evaluate_request())
        .await
        .unwrap();
    assert!(counter(&app, &ok, &series("no_client_cert")).await > no_cert_before);
    assert!(counter(&app, &ok, &series("bad_client_cert")).await > bad_cert_before);
}

/// The session configuration of `tests/common/sessions.rs`.
fn session_config() -> Value {
    json!({
        "state_layout": ["x", "vx", "y", "vy"],
        "method": {"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}},
        "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0},
        "nodes": ["a", "b"],
        "history_instants": 64,
    })
}

#[tokio::test]
async fn a_client_certificate_stands_for_its_tenant_and_sessions_stay_apart() {
    let pki = Pki::new("tenants");
    let server = pki.server();
    let tenants = pki.write(
        "tenants",
        "# certificate names -> tenants\n\
         uri:spiffe://radar.test/ingest/acme=acme\n\
         cn:globex-batch=globex\n",
    );
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        pki.verify_clients(s, Some(ClientAuth::Required));
        s.tls_client_tenants = Some(tenants.clone());
        s.api_keys = Some("key-of-acme=acme,key-of-globex=globex".into());
    })
    .await;
    let acme = client_config(
        &pki.ca_pem,
        Some(&pki.client("acme-ingest-7", &["spiffe://radar.test/ingest/acme"])),
        &[b"h2", b"http/1.1"],
    );
    let globex = client_config(
        &pki.ca_pem,
        Some(&pki.client("globex-batch", &[])),
        &[b"h2", b"http/1.1"],
    );
    let unmapped = client_config(
        &pki.ca_pem,
        Some(&pki.client("someone-else", &[])),
        &[b"h2", b"http/1.1"],
    );

    // acme's certificate alone creates a session (no key).
    let (status, created) = request(
        app.http_addr,
        acme.clone(),
        "POST",
        "/v1/sessions",
        Some(&session_config()),
        None,
    )
    .await
    .unwrap();
    assert_eq!(status, 201, "{created}");
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}");
    let (status, _) = request(app.http_addr, acme.clone(), "GET", &path, None, None)
        .await
        .unwrap();
    assert_eq!(status, 200, "acme sees its session");
    // globex, by its certificate or by its key, does not.
    let (status, _) = request(app.http_addr, globex.clone(), "GET", &path, None, None)
        .await
        .unwrap();
    assert_eq!(status, 404);
    let (status, list) = request(
        app.http_addr,
        globex.clone(),
        "GET",
        "/v1/sessions",
        None,
        None,
    )
    .await
    .unwrap();
    assert_eq!((status, &list["sessions"]), (200, &json!([])));
    // acme's certificate with acme's key agrees; with globex's key it is refused.
    let (status, _) = request(
        app.http_addr,
        acme.clone(),
        "GET",
        &path,
        None,
        Some("key-of-acme"),
    )
    .await
    .unwrap();
    assert_eq!(status, 200);
    let (status, problem) = request(
        app.http_addr,
        acme.clone(),
        "GET",
        &path,
        None,
        Some("key-of-globex"),
    )
    .await
    .unwrap();
    assert_eq!(status, 403, "{problem}");
    assert_eq!(problem["type"], "urn:radar-fusion:problem:forbidden");
    // A trusted certificate that maps to no tenant needs a key, as without TLS.
    let (status, _) = request(app.http_addr, unmapped.clone(), "GET", &path, None, None)
        .await
        .unwrap();
    assert_eq!(status, 401);
    let (status, _) = request(
        app.http_addr,
        unmapped.clone(),
        "GET",
        &path,
        None,
        Some("key-of-acme"),
    )
    .await
    .unwrap();
    assert_eq!(status, 200);

    // gRPC on both ports: the same tenants.
    let h2 = |config: &Arc<ClientConfig>| {
        let mut c = (**config).clone();
        c.alpn_protocols = vec![b"h2".to_vec()];
        Arc::new(c)
    };
    for addr in [app.grpc_addr, app.http_addr] {
        let mut as_acme = SessionServiceClient::new(grpc_channel(addr, h2(&acme)).await.unwrap());
        let listed = as_acme
            .list_sessions(pb::ListSessionsRequest::default())
            .await
            .unwrap()
            .into_inner();
        assert_eq!(listed.sessions.len(), 1, "{addr}: acme lists its session");
        let mut as_globex =
            SessionServiceClient::new(grpc_channel(addr, h2(&globex)).await.unwrap());
        let listed = as_globex
            .list_sessions(pb::ListSessionsRequest::default())
            .await
            .unwrap()
            .into_inner();
        assert!(listed.sessions.is_empty(), "{addr}: globex lists none");
        let gone = as_globex
            .get_session(pb::GetSessionRequest {
                session_id: id.clone(),
            })
            .await
            .unwrap_err();
        assert_eq!(gone.code(), tonic::Code::NotFound);
        // A key of the other tenant beside the certificate.
        let mut call = tonic::Request::new(pb::ListSessionsRequest::default());
        call.metadata_mut()
            .insert("x-api-key", "key-of-acme".parse().unwrap());
        let denied = as_globex.list_sessions(call).await.unwrap_err();
        assert_eq!(denied.code(), tonic::Code::PermissionDenied, "{addr}");
        let mut as_unmapped =
            SessionServiceClient::new(grpc_channel(addr, h2(&unmapped)).await.unwrap());
        let anonymous = as_unmapped
            .list_sessions(pb::ListSessionsRequest::default())
            .await
            .unwrap_err();
        assert_eq!(anonymous.code(), tonic::Code::Unauthenticated);
    }
}

#[tokio::test]
async fn optional_client_certificates_let_key_holders_in() {
    let pki = Pki::new("optional");
    let server = pki.server();
    let tenants = pki.write("tenants", "cn:acme-batch=acme\n");
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        pki.verify_clients(s, Some(ClientAuth::Optional));
        s.tls_client_tenants = Some(tenants.clone());
        s.api_keys = Some("key-of-globex=globex".into());
    })
    .await;
    let bare = client_config(&pki.ca_pem, None, &[b"http/1.1"]);
    let (status, _) = request(
        app.http_addr,
        bare.clone(),
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        None,
    )
    .await
    .unwrap();
    assert_eq!(status, 401, "no certificate and no key");
    let (status, _) = request(
        app.http_addr,
        bare,
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        Some("key-of-globex"),
    )
    .await
    .unwrap();
    assert_eq!(status, 200, "no certificate, a key");
    let acme = client_config(
        &pki.ca_pem,
        Some(&pki.client("acme-batch", &[])),
        &[b"http/1.1"],
    );
    let (status, _) = request(
        app.http_addr,
        acme,
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        None,
    )
    .await
    .unwrap();
    assert_eq!(status, 200, "a mapped certificate, no key");
    // A certificate that is sent must be trusted, even when optional.
    let stranger = Pki::new("optional-stranger").client("acme-batch", &[]);
    let untrusted = client_config(&pki.ca_pem, Some(&stranger), &[b"http/1.1"]);
    assert!(
        request(
            app.http_addr,
            untrusted,
            "POST",
            EVALUATE,
            Some(&evaluate_body()),
            Some("key-of-globex")
        )
        .await
        .is_err()
    );
}

#[tokio::test]
async fn a_reloaded_certificate_serves_new_connections_while_open_ones_continue() {
    let first = Pki::new("reload-1");
    let second = Pki::new("reload-2");
    let server = first.server();
    let app = spawn_app_with(|s| {
        first.serve(s, &server);
        s.tls_reload_s = 0.05;
    })
    .await;
    let old_ca = client_config(&first.ca_pem, None, &[b"http/1.1"]);
    let new_ca = client_config(&second.ca_pem, None, &[b"http/1.1"]);
    let stream = tls_connect(app.http_addr, old_ca.clone()).await.unwrap();
    let mut open = Sender::over(stream).await.unwrap();
    let (status, _) = open.send("GET", "/healthz", None, None).await.unwrap();
    assert_eq!(status, 200);
    assert!(
        tls_connect(app.http_addr, new_ca.clone()).await.is_err(),
        "not the new CA's yet"
    );

    // A certificate of another CA replaces the file (certificate and key in one
    // file, replaced by one rename); new connections see it after a poll.
    let replacement = second.server();
    first.replace(
        "server.pem",
        &format!("{}{}", replacement.cert, replacement.key),
    );
    let mut seen = None;
    for _ in 0..200 {
        if let Ok(stream) = tls_connect(app.http_addr, new_ca.clone()).await {
            seen = Some(stream);
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    let stream = seen.expect("the reloaded certificate is served within the bound");
    let served = stream.get_ref().1.peer_certificates().unwrap()[0].clone();
    let expected = CertificateDer::pem_slice_iter(replacement.cert.as_bytes())
        .next()
        .unwrap()
        .unwrap();
    assert_eq!(served, expected);
    let mut fresh = Sender::over(stream).await.unwrap();
    assert_eq!(
        fresh.send("GET", "/healthz", None, None).await.unwrap().0,
        200
    );
    assert!(
        tls_connect(app.http_addr, old_ca.clone()).await.is_err(),
        "the old certificate is gone"
    );
    // The connection opened before the reload still serves.
    let (status, body) = open
        .send("POST", EVALUATE, Some(&evaluate_body()), None)
        .await
        .unwrap();
    assert_eq!(status, 200, "{body}");

    // A broken replacement keeps the certificate in use and is counted.
    let failed = r#"tls_reloads_total{outcome="failed"}"#;
    let before = counter(&app, &new_ca, failed).await;
    first.replace(
        "server.pem",
        "-----BEGIN CERTIFICATE-----\nbroken\n-----END CERTIFICATE-----\n",
    );
    let mut counted = false;
    for _ in 0..200 {
        if counter(&app, &new_ca, failed).await > before {
            counted = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    assert!(counted, "the failed reload is counted");
    let (status, _) = request(app.http_addr, new_ca, "GET", "/healthz", None, None)
        .await
        .unwrap();
    assert_eq!(status, 200, "still served with the last good certificate");
}

/// Runs the binary's `healthcheck` with `args`; whether it succeeded, and stderr.
async fn healthcheck(args: Vec<String>) -> (bool, String) {
    tokio::task::spawn_blocking(move || {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_radar-fusion"))
            .arg("healthcheck")
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    })
    .await
    .unwrap()
}

#[tokio::test]
async fn the_healthcheck_command_probes_a_tls_port() {
    let pki = Pki::new("healthcheck");
    let server = pki.server();
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        pki.verify_clients(s, None);
    })
    .await;
    let addr = app.http_addr.to_string();
    let ca = pki.write("ca.pem", &pki.ca_pem).display().to_string();
    let probe = pki.client("healthcheck", &[]);
    let cert = pki.write("probe.pem", &probe.cert).display().to_string();
    let key = pki.write("probe-key.pem", &probe.key).display().to_string();
    let args = |extra: &[&str]| -> Vec<String> {
        ["--addr", &addr]
            .iter()
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    let (ok, err) = healthcheck(args(&[
        "--tls-ca",
        &ca,
        "--tls-client-cert",
        &cert,
        "--tls-client-key",
        &key,
    ]))
    .await;
    assert!(ok, "{err}");
    // Without the client certificate mutual TLS refuses it; in plaintext it gets nothing.
    let (ok, err) = healthcheck(args(&["--tls-ca", &ca])).await;
    assert!(
        !ok && err.contains(&format!("https://{addr}/healthz")),
        "{err}"
    );
    let (ok, err) = healthcheck(args(&[])).await;
    assert!(
        !ok && err.contains(&format!("http://{addr}/healthz")),
        "{err}"
    );
    // The certificate must hold the name checked.
    let (ok, err) = healthcheck(args(&[
        "--tls-ca",
        &ca,
        "--tls-client-cert",
        &cert,
        "--tls-client-key",
        &key,
        "--tls-server-name",
        "fusion.example",
    ]))
    .await;
    assert!(!ok, "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[tokio::test]
async fn bad_tls_files_stop_the_start_naming_the_file() {
    let pki = Pki::new("refuse");
    let server = pki.server();
    let other = pki.server();
    let cert = pki.write("cert.pem", &server.cert);
    let other_key = pki.write("other-key.pem", &other.key);
    let missing = pki.dir.join("missing.pem");
    for (cert, key, named) in [
        (missing.clone(), other_key.clone(), "missing.pem"),
        (cert.clone(), missing.clone(), "missing.pem"),
        (cert.clone(), other_key.clone(), "other-key.pem"),
    ] {
        let mut settings = Settings::for_tests();
        settings.tls_cert = Some(cert.clone());
        settings.tls_key = Some(key.clone());
        let error = match radar_fusion::app::Application::build(settings).await {
            Ok(_) => panic!("started with {cert:?} and {key:?}"),
            Err(e) => format!("{e:#}"),
        };
        assert!(error.contains(named), "{error}");
        assert!(error.contains("--tls-"), "{error}");
    }
    // The binary says so and exits, without a panic.
    let out = tokio::task::spawn_blocking(move || {
        std::process::Command::new(env!("CARGO_BIN_EXE_radar-fusion"))
            .args([
                "serve",
                "--http-addr",
                "127.0.0.1:0",
                "--grpc-addr",
                "127.0.0.1:0",
            ])
            .env("FUSION_TLS_CERT", &cert)
            .env("FUSION_TLS_KEY", &other_key)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("other-key.pem") && stderr.contains("does not match"),
        "{stderr}"
    );
    assert!(
        !stderr.contains("panicked") && !stderr.contains("PRIVATE KEY"),
        "{stderr}"
    );
}

/// PEM text of a DER revocation list.
fn crl_pem(der: &[u8]) -> String {
    use base64::Engine as _;
    let b64 = base64::engine::general_purpose::STANDARD.encode(der);
    let lines: Vec<&str> = b64
        .as_bytes()
        .chunks(64)
        .map(|c| std::str::from_utf8(c).unwrap())
        .collect();
    format!(
        "-----BEGIN X509 CRL-----\n{}\n-----END X509 CRL-----\n",
        lines.join("\n")
    )
}

/// Issue 53: certificate revocation lists and a maximum connection age. A
/// client keeps a connection open while its certificate is revoked: the
/// reloaded CRL refuses its new connections at once, and the open one is
/// closed at its age limit, so the revoked certificate stops acting.
#[tokio::test]
async fn a_revoked_client_certificate_is_refused_and_its_open_connection_ends_at_its_age() {
    let pki = Pki::new("crl");
    let server = pki.server();
    let crl = pki.write("crl.pem", &crl_pem(&pki.crl(&[])));
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        pki.verify_clients(s, None);
        s.tls_crl = Some(crl.clone());
        s.tls_reload_s = 0.1;
        s.max_connection_age_s = 1.0;
    })
    .await;
    let acme = pki.client_numbered("acme-ingest", 7);
    let globex = pki.client_numbered("globex-ingest", 8);
    let acme_h2 = client_config(&pki.ca_pem, Some(&acme), &[b"h2"]);
    let globex_h2 = client_config(&pki.ca_pem, Some(&globex), &[b"h2"]);
    let stream = tls_connect(app.http_addr, acme_h2.clone()).await.unwrap();
    let mut open = Sender::over(stream).await.unwrap();
    let (status, _) = open
        .send("POST", EVALUATE, Some(&evaluate_body()), None)
        .await
        .unwrap();
    assert_eq!(status, 200);

    // Certificate 7 revoked: new connections with it are refused once the
    // list is read again (every 0.1 s here), 8 is still served.
    pki.replace("crl.pem", &crl_pem(&pki.crl(&[7])));
    let deadline = tokio::time::Instant::now() + BOUND;
    loop {
        let r = request(
            app.http_addr,
            acme_h2.clone(),
            "POST",
            EVALUATE,
            Some(&evaluate_body()),
            None,
        )
        .await;
        if r.is_err() {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the revoked certificate was still served"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let (status, _) = request(
        app.http_addr,
        globex_h2.clone(),
        "POST",
        EVALUATE,
        Some(&evaluate_body()),
        None,
    )
    .await
    .unwrap();
    assert_eq!(status, 200);

    // The connection opened before the revocation is closed at its age
    // (1 s): before, it served its client for as long as it kept it open.
    let deadline = tokio::time::Instant::now() + BOUND;
    loop {
        if open
            .send("POST", EVALUATE, Some(&evaluate_body()), None)
            .await
            .is_err()
        {
            break;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "the connection of the revoked certificate stayed open"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let globex_h1 = client_config(&pki.ca_pem, Some(&globex), &[b"http/1.1"]);
    let aged = counter(
        &app,
        &globex_h1,
        r#"connections_aged_out_total{server="http",how="graceful"}"#,
    )
    .await;
    assert!(aged >= 1.0, "{aged}");
}

#[tokio::test]
async fn a_der_revocation_list_is_read_and_a_bad_one_stops_the_start_naming_it() {
    let pki = Pki::new("crl-der");
    let server = pki.server();
    let der = pki.crl(&[7]);
    let path = pki.dir.join("crl.der");
    std::fs::write(&path, &der).unwrap();
    let app = spawn_app_with(|s| {
        pki.serve(s, &server);
        pki.verify_clients(s, None);
        s.tls_crl = Some(path.clone());
    })
    .await;
    let revoked = client_config(&pki.ca_pem, Some(&pki.client_numbered("a", 7)), &[b"h2"]);
    let kept = client_config(&pki.ca_pem, Some(&pki.client_numbered("b", 8)), &[b"h2"]);
    let body = evaluate_body();
    let refused = request(app.http_addr, revoked, "POST", EVALUATE, Some(&body), None).await;
    assert!(
        refused.is_err(),
        "served a revoked certificate: {refused:?}"
    );
    let (status, _) = request(app.http_addr, kept, "POST", EVALUATE, Some(&body), None)
        .await
        .unwrap();
    assert_eq!(status, 200);

    // A file that is no CRL stops the start, naming the option and file.
    let mut settings = Settings::for_tests();
    pki.serve(&mut settings, &server);
    pki.verify_clients(&mut settings, None);
    settings.tls_crl = Some(pki.write("not-a-crl.der", "not a revocation list"));
    let Err(e) = radar_fusion::tls::Tls::from_settings(&settings) else {
        panic!("a bad CRL file loaded");
    };
    assert!(
        e.contains("FUSION_TLS_CRL") && e.contains("not-a-crl.der"),
        "{e}"
    );
}
