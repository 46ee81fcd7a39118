//! TLS on both ports (issue 34): rustls with the `ring` provider, the
//! certificate and key from `FUSION_TLS_CERT`/`FUSION_TLS_KEY`, optional
//! client-certificate verification (`FUSION_TLS_CLIENT_CA`,
//! `FUSION_TLS_CLIENT_AUTH`) and client certificates standing for tenants
//! (`FUSION_TLS_CLIENT_TENANTS`, [`tenants`]).
//!
//! [`Tls`] holds the loaded configuration of both ports behind a lock that
//! the accept loop (`serve`) reads once per connection, so a reload is seen
//! by the next handshake while connections already open keep theirs.
//! Reloads: the files are read again every `FUSION_TLS_RELOAD_S` (10 s) and
//! at once on SIGHUP ([`Tls::spawn_watcher`]); a change that does not load
//! (a missing or unreadable file, a key that does not match, a bad CA or
//! mapping) keeps the configuration in use, is logged at ERROR naming the
//! file, and counted in `tls_reloads_total{outcome="failed"}`.
//!
//! ALPN: `h2` and `http/1.1` on the REST port, `h2` on the gRPC port. A
//! handshake that fails is counted in
//! `tls_handshake_failures_total{server,reason}` with a reason from
//! [`FAILURE_REASONS`]; nothing about keys is ever logged (rustls errors
//! carry none, and the PEM parser's messages about the key file are not
//! repeated).
//!
//! The provider is `ring`: its build needs a C compiler only, as
//! `aws-lc-rs` (non-FIPS) does nowadays, but it compiles far less C and is
//! what tonic and rcgen default to; `aws-lc-rs` would add FIPS builds (which
//! need cmake and Go) and the post-quantum X25519MLKEM768 key exchange,
//! which rustls offers with it only.

pub mod tenants;
pub mod x509;

use std::{
    hash::{DefaultHasher, Hash, Hasher},
    io,
    path::{Path, PathBuf},
    sync::{Arc, Mutex, RwLock},
    time::Duration,
};

use rustls::{
    ClientConfig, RootCertStore, ServerConfig, ServerConnection,
    crypto::CryptoProvider,
    pki_types::{
        CertificateDer, CertificateRevocationListDer, PrivateKeyDer, ServerName, pem::PemObject,
    },
    server::{WebPkiClientVerifier, danger::ClientCertVerifier},
    sign::{CertifiedKey, SingleCertAndKey},
};
use tokio_rustls::TlsAcceptor;

use crate::{
    auth::CertTenant,
    config::{ClientAuth, Settings},
};
use tenants::{ClientTenants, Identified};

/// Every `reason` label of `tls_handshake_failures_total`.
pub const FAILURE_REASONS: &[&str] = &[
    "not_tls",
    "timeout",
    "closed",
    "no_client_cert",
    "bad_client_cert",
    "alert",
    "protocol",
    "other",
];

/// The ALPN protocols of each port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Port {
    /// REST and gRPC: `h2`, `http/1.1`.
    Http,
    /// gRPC only: `h2`.
    Grpc,
}

/// The TLS configuration of both ports, reloadable.
pub struct Tls {
    files: Files,
    current: RwLock<Arc<Loaded>>,
    /// The files' fingerprint at the last reload attempt, and whether it
    /// loaded: a poll does not retry (nor log again) a failed version.
    last_attempt: Mutex<u64>,
    reload_every: Option<Duration>,
}

/// What one connection's handshake uses: its port's acceptor and the tenant
/// mapping of the same load.
#[derive(Clone)]
pub struct Acceptor {
    pub tls: TlsAcceptor,
    pub tenants: Arc<ClientTenants>,
}

/// One port's TLS, handed to `serve::serve`.
#[derive(Clone)]
pub struct TlsPort {
    tls: Arc<Tls>,
    port: Port,
}

impl TlsPort {
    pub fn new(tls: Arc<Tls>, port: Port) -> Self {
        Self { tls, port }
    }

    /// The current configuration, for one new connection.
    pub fn acceptor(&self) -> Acceptor {
        let loaded = self.tls.loaded();
        Acceptor {
            tls: match self.port {
                Port::Http => loaded.http.clone(),
                Port::Grpc => loaded.grpc.clone(),
            },
            tenants: loaded.tenants.clone(),
        }
    }
}

/// The outcome of [`Tls::reload`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reload {
    /// The files are those in use (or a version that failed already).
    Unchanged,
    /// New files loaded: new connections use them.
    Loaded,
    /// The files changed but do not load; the message names the file.
    Failed(String),
}

impl Tls {
    /// Loads the TLS files named by the settings, or `None` without
    /// `--tls-cert`. Errors name the option and the file.
    pub fn from_settings(settings: &Settings) -> Result<Option<Arc<Self>>, String> {
        let (Some(cert), Some(key)) = (&settings.tls_cert, &settings.tls_key) else {
            return Ok(None);
        };
        let files = Files {
            cert: cert.clone(),
            key: key.clone(),
            client_ca: settings.tls_client_ca.clone(),
            client_auth: settings.tls_client_auth.unwrap_or(ClientAuth::Required),
            tenants: settings.tls_client_tenants.clone(),
            crl: settings.tls_crl.clone(),
        };
        let contents = files.read()?;
        let loaded = files.load(&contents)?;
        record_not_after(loaded.not_after);
        let reload_every =
            (settings.tls_reload_s > 0.0).then(|| Duration::from_secs_f64(settings.tls_reload_s));
        Ok(Some(Arc::new(Self {
            last_attempt: Mutex::new(contents.fingerprint()),
            current: RwLock::new(Arc::new(loaded)),
            files,
            reload_every,
        })))
    }

    /// One line for the start-up log: what is verified and mapped.
    pub fn describe(&self) -> String {
        let loaded = self.loaded();
        let clients = match (&self.files.client_ca, self.files.client_auth) {
            (None, _) => "no client certificates".to_string(),
            (Some(_), ClientAuth::Required) => "client certificates required".to_string(),
            (Some(_), ClientAuth::Optional) => "client certificates optional".to_string(),
        };
        let clients = match &self.files.crl {
            Some(path) => format!("{clients}, revocation lists {}", path.display()),
            None => clients,
        };
        let tenants = if loaded.tenants.is_empty() {
            String::new()
        } else {
            format!(
                ", {} certificate name(s) mapped to tenants",
                loaded.tenants.len()
            )
        };
        format!(
            "TLS on both ports ({}), {clients}{tenants}",
            self.files.cert.display()
        )
    }

    /// Reads the files again and, when they changed, loads them for new
    /// connections (`force`: also retry a version that failed before, as on
    /// SIGHUP). Blocking (file reads): call it off the async workers.
    pub fn reload(&self, force: bool) -> Reload {
        let outcome = self.try_reload(force);
        match &outcome {
            Reload::Unchanged => {
                if force {
                    tracing::info!("TLS reload: the files are those in use");
                }
            }
            Reload::Loaded => {
                metrics::counter!("tls_reloads_total", "outcome" => "loaded").increment(1);
                tracing::info!(cert = %self.files.cert.display(), "TLS reload: new certificate loaded for new connections");
            }
            Reload::Failed(error) => {
                metrics::counter!("tls_reloads_total", "outcome" => "failed").increment(1);
                tracing::error!(%error, "TLS reload failed: the certificate in use is kept");
            }
        }
        outcome
    }

    fn try_reload(&self, force: bool) -> Reload {
        let contents = match self.files.read() {
            Ok(contents) => contents,
            Err(error) => {
                // A file that cannot be read is a version of its own: say
                // so once, not at every poll.
                let mut h = DefaultHasher::new();
                error.hash(&mut h);
                return self.attempted(h.finish(), force, || Err(error));
            }
        };
        let fingerprint = contents.fingerprint();
        self.attempted(fingerprint, force, || {
            let loaded = self.files.load(&contents)?;
            record_not_after(loaded.not_after);
            *self.current.write().unwrap_or_else(|e| e.into_inner()) = Arc::new(loaded);
            Ok(())
        })
    }

    fn attempted(
        &self,
        fingerprint: u64,
        force: bool,
        load: impl FnOnce() -> Result<(), String>,
    ) -> Reload {
        let mut last = self.last_attempt.lock().unwrap_or_else(|e| e.into_inner());
        let in_use = self.loaded().fingerprint == fingerprint;
        if in_use || (*last == fingerprint && !force) {
            *last = fingerprint;
            return Reload::Unchanged;
        }
        *last = fingerprint;
        match load() {
            Ok(()) => Reload::Loaded,
            Err(e) => Reload::Failed(e),
        }
    }

    /// Reloads every `FUSION_TLS_RELOAD_S` and on SIGHUP, until aborted.
    /// The SIGHUP handler is in place when this returns (from then on the
    /// signal no longer ends the process).
    pub fn spawn_watcher(self: &Arc<Self>) -> tokio::task::JoinHandle<()> {
        let tls = self.clone();
        #[cfg(unix)]
        let mut hangup = match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup())
        {
            Ok(s) => Some(s),
            Err(e) => {
                tracing::warn!(error = %e, "cannot listen for SIGHUP: TLS files reload by polling only");
                None
            }
        };
        tokio::spawn(async move {
            loop {
                let every = tls.reload_every;
                let poll = async move {
                    match every {
                        Some(d) => tokio::time::sleep(d).await,
                        None => std::future::pending().await,
                    }
                };
                #[cfg(unix)]
                let signalled = async {
                    match hangup.as_mut() {
                        Some(s) => s.recv().await,
                        None => std::future::pending().await,
                    }
                };
                #[cfg(not(unix))]
                let signalled = std::future::pending::<Option<()>>();
                let force = tokio::select! {
                    () = poll => false,
                    Some(()) = signalled => true,
                };
                let tls = tls.clone();
                let _ = tokio::task::spawn_blocking(move || tls.reload(force)).await;
            }
        })
    }

    fn loaded(&self) -> Arc<Loaded> {
        self.current
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}

/// The tenant a handshake's verified client certificate stands for, if any
/// (an ambiguous one stands for none and is logged).
pub fn cert_tenant(tenants: &ClientTenants, conn: &ServerConnection) -> Option<CertTenant> {
    if tenants.is_empty() {
        return None;
    }
    let der = conn.peer_certificates()?.first()?;
    let names = x509::names(der).unwrap_or_default();
    match tenants.identify(&names) {
        Identified::Tenant(tenant) => Some(CertTenant(tenant)),
        Identified::Unmapped => None,
        Identified::Ambiguous(found) => {
            let found: Vec<&str> = found.iter().map(|t| t.as_str()).collect();
            tracing::warn!(
                tenants = ?found,
                "a client certificate's names map to several tenants (FUSION_TLS_CLIENT_TENANTS): it stands for none"
            );
            None
        }
    }
}

/// The `reason` label of a failed handshake (one of [`FAILURE_REASONS`]).
pub fn failure_reason(error: &io::Error) -> &'static str {
    use rustls::Error as E;
    if let Some(tls) = error
        .get_ref()
        .and_then(|e| e.downcast_ref::<rustls::Error>())
    {
        return match tls {
            E::NoCertificatesPresented => "no_client_cert",
            E::InvalidCertificate(_) | E::InvalidCertRevocationList(_) => "bad_client_cert",
            E::AlertReceived(_) => "alert",
            E::InappropriateMessage { .. }
            | E::InappropriateHandshakeMessage { .. }
            | E::InvalidMessage(_)
            | E::PeerIncompatible(_)
            | E::PeerMisbehaved(_)
            | E::NoApplicationProtocol
            | E::PeerSentOversizedRecord
            | E::DecryptError
            | E::UnsupportedNameType
            | E::InvalidEncryptedClientHello(_) => "protocol",
            _ => "other",
        };
    }
    match error.kind() {
        io::ErrorKind::UnexpectedEof
        | io::ErrorKind::ConnectionReset
        | io::ErrorKind::ConnectionAborted
        | io::ErrorKind::BrokenPipe => "closed",
        _ => "other",
    }
}

/// A client configuration trusting the PEM CAs in `ca` (with a client
/// certificate when given), for the `healthcheck` command and the load
/// example. Errors name the file.
pub fn client_config(
    ca: &Path,
    client: Option<(&Path, &Path)>,
    alpn: &[&[u8]],
) -> Result<ClientConfig, String> {
    let provider = provider();
    let roots = root_store(&read_file(ca, "the CA file")?, ca, "the CA file")?;
    let builder = ClientConfig::builder_with_provider(provider.clone())
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS client configuration: {e}"))?
        .with_root_certificates(roots);
    let mut config = match client {
        None => builder.with_no_client_auth(),
        Some((cert, key)) => {
            let chain = cert_chain(
                &read_file(cert, "the client certificate")?,
                cert,
                "the client certificate",
            )?;
            let key_der = private_key(&read_file(key, "the client key")?, key, "the client key")?;
            builder.with_client_auth_cert(chain, key_der).map_err(|e| {
                format!(
                    "the client key {} does not fit its certificate {}: {e}",
                    key.display(),
                    cert.display()
                )
            })?
        }
    };
    config.alpn_protocols = alpn.iter().map(|p| p.to_vec()).collect();
    Ok(config)
}

/// The server name a client verifies: a DNS name or an IP address.
pub fn server_name(name: &str) -> Result<ServerName<'static>, String> {
    ServerName::try_from(name.to_string())
        .map_err(|_| format!("{name:?} is not a DNS name or an IP address"))
}

/// The files named by the settings.
struct Files {
    cert: PathBuf,
    key: PathBuf,
    client_ca: Option<PathBuf>,
    client_auth: ClientAuth,
    tenants: Option<PathBuf>,
    crl: Option<PathBuf>,
}

/// The bytes of the files, read together.
#[derive(Hash)]
struct Contents {
    cert: Vec<u8>,
    key: Vec<u8>,
    client_ca: Option<Vec<u8>>,
    tenants: Option<Vec<u8>>,
    crl: Option<Vec<u8>>,
}

impl Contents {
    fn fingerprint(&self) -> u64 {
        let mut h = DefaultHasher::new();
        self.hash(&mut h);
        h.finish()
    }
}

/// A loaded configuration: both ports' acceptors and the tenant mapping.
struct Loaded {
    http: TlsAcceptor,
    grpc: TlsAcceptor,
    tenants: Arc<ClientTenants>,
    fingerprint: u64,
    not_after: Option<i64>,
}

const CERT: &str = "--tls-cert (FUSION_TLS_CERT)";
const KEY: &str = "--tls-key (FUSION_TLS_KEY)";
const CLIENT_CA: &str = "--tls-client-ca (FUSION_TLS_CLIENT_CA)";
const TENANTS: &str = "--tls-client-tenants (FUSION_TLS_CLIENT_TENANTS)";
const CRL: &str = "--tls-crl (FUSION_TLS_CRL)";

impl Files {
    fn read(&self) -> Result<Contents, String> {
        Ok(Contents {
            cert: read_file(&self.cert, CERT)?,
            key: read_file(&self.key, KEY)?,
            client_ca: self
                .client_ca
                .as_deref()
                .map(|p| read_file(p, CLIENT_CA))
                .transpose()?,
            tenants: self
                .tenants
                .as_deref()
                .map(|p| read_file(p, TENANTS))
                .transpose()?,
            crl: self.crl.as_deref().map(|p| read_file(p, CRL)).transpose()?,
        })
    }

    fn load(&self, contents: &Contents) -> Result<Loaded, String> {
        let provider = provider();
        let chain = cert_chain(&contents.cert, &self.cert, CERT)?;
        let not_after = x509::not_after_unix(&chain[0]).ok_or_else(|| {
            format!(
                "{CERT}: {}: the first certificate is not an X.509 certificate",
                self.cert.display()
            )
        })?;
        let key = private_key(&contents.key, &self.key, KEY)?;
        let signing_key = provider
            .key_provider
            .load_private_key(key)
            .map_err(|e| format!("{KEY}: {}: unusable private key ({e})", self.key.display()))?;
        let certified = CertifiedKey::new(chain, signing_key);
        match certified.keys_match() {
            Ok(()) | Err(rustls::Error::InconsistentKeys(rustls::InconsistentKeys::Unknown)) => {}
            Err(rustls::Error::InconsistentKeys(_)) => {
                return Err(format!(
                    "{KEY}: the key in {} does not match the certificate in {}",
                    self.key.display(),
                    self.cert.display()
                ));
            }
            Err(e) => {
                return Err(format!(
                    "{CERT}: {}: unusable certificate ({e})",
                    self.cert.display()
                ));
            }
        }
        let not_after = Some(not_after);
        let resolver = Arc::new(SingleCertAndKey::from(certified));
        let verifier: Option<Arc<dyn ClientCertVerifier>> =
            match (&self.client_ca, &contents.client_ca) {
                (Some(path), Some(bytes)) => {
                    let roots = root_store(bytes, path, CLIENT_CA)?;
                    let builder = WebPkiClientVerifier::builder_with_provider(
                        Arc::new(roots),
                        provider.clone(),
                    );
                    let builder = match self.client_auth {
                        ClientAuth::Required => builder,
                        ClientAuth::Optional => builder.allow_unauthenticated(),
                    };
                    let builder = match (&self.crl, &contents.crl) {
                        (Some(crl_path), Some(crl)) => {
                            builder.with_crls(revocation_lists(crl, crl_path)?)
                        }
                        _ => builder,
                    };
                    Some(builder.build().map_err(|e| match (e, &self.crl) {
                        (rustls::server::VerifierBuilderError::InvalidCrl(e), Some(crl)) => {
                            format!("{CRL}: {}: not a usable CRL ({e:?})", crl.display())
                        }
                        (e, _) => format!("{CLIENT_CA}: {}: {e}", path.display()),
                    })?)
                }
                _ => None,
            };
        let tenants = match (&self.tenants, &contents.tenants) {
            (Some(path), Some(bytes)) => {
                let origin = format!("{TENANTS} {}", path.display());
                let text =
                    std::str::from_utf8(bytes).map_err(|_| format!("{origin}: not UTF-8 text"))?;
                ClientTenants::parse(text, &origin)?
            }
            _ => ClientTenants::default(),
        };
        let port = |alpn: &[&[u8]]| -> Result<TlsAcceptor, String> {
            let builder = ServerConfig::builder_with_provider(provider.clone())
                .with_safe_default_protocol_versions()
                .map_err(|e| format!("TLS configuration: {e}"))?;
            let builder = match &verifier {
                Some(v) => builder.with_client_cert_verifier(v.clone()),
                None => builder.with_no_client_auth(),
            };
            let mut config = builder.with_cert_resolver(resolver.clone());
            config.alpn_protocols = alpn.iter().map(|p| p.to_vec()).collect();
            Ok(TlsAcceptor::from(Arc::new(config)))
        };
        Ok(Loaded {
            http: port(&[b"h2", b"http/1.1"])?,
            grpc: port(&[b"h2"])?,
            tenants: Arc::new(tenants),
            fingerprint: contents.fingerprint(),
            not_after,
        })
    }
}

fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

fn read_file(path: &Path, option: &str) -> Result<Vec<u8>, String> {
    std::fs::read(path).map_err(|e| format!("{option}: cannot read {}: {e}", path.display()))
}

fn cert_chain(
    pem: &[u8],
    path: &Path,
    option: &str,
) -> Result<Vec<CertificateDer<'static>>, String> {
    let chain = CertificateDer::pem_slice_iter(pem)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| {
            format!(
                "{option}: {}: not a PEM certificate file ({e})",
                path.display()
            )
        })?;
    if chain.is_empty() {
        return Err(format!(
            "{option}: {}: no `BEGIN CERTIFICATE` block found",
            path.display()
        ));
    }
    Ok(chain)
}

/// The first private key of a PEM file. The parser's error is not repeated:
/// it may quote a line of the key file.
fn private_key(pem: &[u8], path: &Path, option: &str) -> Result<PrivateKeyDer<'static>, String> {
    PrivateKeyDer::from_pem_slice(pem).map_err(|_| {
        format!(
            "{option}: {}: no PEM private key found (`BEGIN PRIVATE KEY`, `BEGIN RSA PRIVATE KEY` or `BEGIN EC PRIVATE KEY`)",
            path.display()
        )
    })
}

fn root_store(pem: &[u8], path: &Path, option: &str) -> Result<RootCertStore, String> {
    let mut roots = RootCertStore::empty();
    for cert in cert_chain(pem, path, option)? {
        roots.add(cert).map_err(|e| {
            format!(
                "{option}: {}: not a usable CA certificate ({e})",
                path.display()
            )
        })?;
    }
    Ok(roots)
}

/// The revocation lists of a `--tls-crl` file: every `X509 CRL` block of a
/// PEM file, or the file itself as one DER list.
fn revocation_lists(
    bytes: &[u8],
    path: &Path,
) -> Result<Vec<CertificateRevocationListDer<'static>>, String> {
    let pem = bytes.trim_ascii_start().starts_with(b"-----BEGIN");
    let crls = if pem {
        CertificateRevocationListDer::pem_slice_iter(bytes)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| format!("{CRL}: {}: not a PEM CRL file ({e})", path.display()))?
    } else {
        vec![CertificateRevocationListDer::from(bytes.to_vec())]
    };
    if crls.is_empty() {
        return Err(format!(
            "{CRL}: {}: no `BEGIN X509 CRL` block found",
            path.display()
        ));
    }
    Ok(crls)
}

fn record_not_after(not_after: Option<i64>) {
    if let Some(t) = not_after {
        // Seconds since the epoch, exact in an f64 for any real date.
        #[allow(clippy::cast_precision_loss)]
        metrics::gauge!("tls_certificate_not_after_seconds").set(t as f64);
    }
}

#[cfg(test)]
mod tests;
