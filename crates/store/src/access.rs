//! How the store reaches a Redis server: TLS for `rediss://`,
//! `rediss+sentinel://` and `rediss+cluster://` (rustls with the `ring`
//! provider) with the CA of
//! `FUSION_REDIS_CA` and the optional client certificate of
//! `FUSION_REDIS_CERT` / `FUSION_REDIS_KEY`, and credentials from the URL's
//! user information or `FUSION_REDIS_PASSWORD`.
//!
//! Secrets never leave this module in text: `Debug` of the settings prints
//! `***` for the password, errors name the setting and never its value, and
//! a URL with a password is never echoed. A bad setting refuses to start
//! ([`StoreError::Config`]): an unreadable or empty PEM file, a certificate
//! without its key, a CA for a URL without TLS, and (checked by
//! [`probe`] against the server, when it answers at start) a TLS handshake
//! that fails or credentials that Redis rejects. A server that does not
//! answer at start is not a configuration error: the store starts degraded
//! and recovers by itself, as without TLS.

use std::{error::Error as _, path::PathBuf, time::Duration};

use redis::{
    AsyncConnectionConfig, Client, ClientTlsConfig, ConnectionAddr, ConnectionInfo, ErrorKind,
    IntoConnectionInfo, RedisError, TlsCertificates,
    cluster::{ClusterClient, ClusterClientBuilder},
};
use rustls::pki_types::{CertificateDer, PrivateKeyDer, pem::PemObject};

use super::StoreError;

/// TLS files and credentials for Redis (part of `StoreSettings`); `Debug`
/// does not print the password.
#[derive(Clone, Default)]
pub struct RedisAccessSettings {
    /// `FUSION_REDIS_CA`: PEM file of the CA that signed Redis's certificate
    /// (without it, the system's roots).
    pub ca: Option<PathBuf>,
    /// `FUSION_REDIS_CERT`: PEM client certificate chain, for Redis's
    /// `tls-auth-clients yes`.
    pub cert: Option<PathBuf>,
    /// `FUSION_REDIS_KEY`: PEM private key of `cert`.
    pub key: Option<PathBuf>,
    /// `FUSION_REDIS_PASSWORD`: overrides the URL's password.
    pub password: Option<String>,
}

impl std::fmt::Debug for RedisAccessSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RedisAccessSettings")
            .field("ca", &self.ca)
            .field("cert", &self.cert)
            .field("key", &self.key)
            .field("password", &self.password.as_ref().map(|_| "***"))
            .finish()
    }
}

pub(crate) const CA: &str = "FUSION_REDIS_CA";
pub(crate) const CERT: &str = "FUSION_REDIS_CERT";
pub(crate) const KEY: &str = "FUSION_REDIS_KEY";
pub(crate) const PASSWORD: &str = "FUSION_REDIS_PASSWORD";
pub(crate) const STORE: &str = "FUSION_SESSION_STORE";

/// What every connection of one store uses: TLS material and credentials.
#[derive(Clone)]
pub(crate) struct Access {
    tls: Option<TlsCertificates>,
    username: Option<String>,
    password: Option<String>,
}

impl Access {
    /// Reads and checks the files of `settings`; `tls` says whether the URL
    /// asks for TLS, `url_user` and `url_password` are the URL's.
    pub(crate) fn new(
        settings: &RedisAccessSettings,
        tls: bool,
        url_user: Option<String>,
        url_password: Option<String>,
    ) -> Result<Self, StoreError> {
        let tls = if tls {
            Some(certificates(settings)?)
        } else {
            for (setting, path) in [
                (CA, &settings.ca),
                (CERT, &settings.cert),
                (KEY, &settings.key),
            ] {
                if path.is_some() {
                    return Err(config(
                        setting,
                        "is set but FUSION_SESSION_STORE does not use TLS (use rediss://, \
                         rediss+sentinel:// or rediss+cluster://)"
                            .into(),
                    ));
                }
            }
            None
        };
        Ok(Self {
            tls,
            username: url_user.filter(|u| !u.is_empty()),
            password: settings
                .password
                .clone()
                .or_else(|| url_password.filter(|p| !p.is_empty())),
        })
    }

    /// A client of the data server `host:port` (database `db`), with TLS
    /// when configured and the credentials.
    pub(crate) fn client(&self, host: &str, port: u16, db: i64) -> Result<Client, StoreError> {
        let info = self.info(host, port)?;
        let mut redis = info.redis_settings().clone().set_db(db);
        if let Some(u) = &self.username {
            redis = redis.set_username(u);
        }
        if let Some(p) = &self.password {
            redis = redis.set_password(p);
        }
        self.build(info.set_redis_settings(redis))
    }

    /// A client of a Redis Cluster seeded with `nodes`: TLS when
    /// configured, the credentials, every command bounded by `timeout`.
    pub(crate) fn cluster_client(
        &self,
        nodes: &[(String, u16)],
        timeout: Duration,
    ) -> Result<ClusterClient, StoreError> {
        let infos = nodes
            .iter()
            .map(|(h, p)| self.info(h, *p))
            .collect::<Result<Vec<_>, _>>()?;
        let mut builder = ClusterClientBuilder::new(infos)
            .connection_timeout(timeout)
            .response_timeout(timeout)
            .retries(1);
        if let Some(certs) = &self.tls {
            builder = builder.certs(certs.clone());
        }
        if let Some(u) = &self.username {
            builder = builder.username(u);
        }
        if let Some(p) = &self.password {
            builder = builder.password(p);
        }
        builder
            .build()
            .map_err(|e| config(STORE, format!("cluster settings refused: {e}")))
    }

    /// A client of a sentinel: TLS when configured, no credentials (they
    /// are the data servers').
    pub(crate) fn sentinel_client(&self, host: &str, port: u16) -> Result<Client, StoreError> {
        self.build(self.info(host, port)?)
    }

    fn info(&self, host: &str, port: u16) -> Result<ConnectionInfo, StoreError> {
        let addr = if self.tls.is_some() {
            ConnectionAddr::TcpTls {
                host: host.to_string(),
                port,
                insecure: false,
                tls_params: None,
            }
        } else {
            ConnectionAddr::Tcp(host.to_string(), port)
        };
        addr.into_connection_info()
            .map_err(|e| config(STORE, format!("address {host}:{port}: {e}")))
    }

    fn build(&self, info: ConnectionInfo) -> Result<Client, StoreError> {
        match &self.tls {
            Some(certs) => Client::build_with_tls(info, certs.clone())
                .map_err(|e| config(CA, format!("TLS settings refused: {e}"))),
            None => Client::open(info).map_err(|e| config(STORE, e.to_string())),
        }
    }
}

/// The `redis://` or `rediss://` URL of one server, parsed: (host, port, db,
/// TLS, user, password). Errors never echo the URL (it may hold a password).
pub(crate) fn parse_server_url(url: &str) -> Result<ServerUrl, StoreError> {
    let info = url.into_connection_info().map_err(|e| {
        config(
            STORE,
            format!("not a Redis URL ({})", e.detail().unwrap_or("malformed")),
        )
    })?;
    let (host, port, tls) = match info.addr() {
        ConnectionAddr::Tcp(h, p) => (h.clone(), *p, false),
        ConnectionAddr::TcpTls {
            host,
            port,
            insecure,
            ..
        } => {
            if *insecure {
                return Err(config(
                    STORE,
                    "#insecure (no certificate check) is not accepted: give the CA in FUSION_REDIS_CA"
                        .into(),
                ));
            }
            (host.clone(), *port, true)
        }
        _ => {
            return Err(config(
                STORE,
                "only TCP addresses (redis://, rediss://) are supported".into(),
            ));
        }
    };
    let r = info.redis_settings();
    Ok(ServerUrl {
        host,
        port,
        db: r.db(),
        tls,
        user: r.username().map(str::to_string),
        password: r.password().map(str::to_string),
    })
}

/// A Sentinel or Cluster URL's (user, password, addresses).
pub(crate) type HostList = (Option<String>, Option<String>, Vec<(String, u16)>);

/// Parses `[USER:PASSWORD@]HOST:PORT[,HOST:PORT…]`; `what` names one address
/// in errors, which `bad` words (never echoing the user information).
pub(crate) fn parse_hosts(
    s: &str,
    what: &str,
    bad: fn(&str) -> StoreError,
) -> Result<HostList, StoreError> {
    let (userinfo, hosts) = match s.rsplit_once('@') {
        Some((u, h)) => (Some(u), h),
        None => (None, s),
    };
    let (user, password) = match userinfo {
        None => (None, None),
        Some(u) => {
            let (user, password) = u.split_once(':').unwrap_or((u, ""));
            (
                Some(percent_decode(user).ok_or_else(|| bad("the user is not percent-encoded"))?),
                Some(
                    percent_decode(password)
                        .ok_or_else(|| bad("the password is not percent-encoded"))?,
                ),
            )
        }
    };
    let mut addresses = Vec::new();
    for h in hosts.split(',') {
        let (host, port) = h
            .rsplit_once(':')
            .ok_or_else(|| bad(&format!("{what} {h:?} is not HOST:PORT")))?;
        let port: u16 = port
            .parse()
            .map_err(|_| bad(&format!("{what} {h:?} has no valid port")))?;
        if host.is_empty() || port == 0 {
            return Err(bad(&format!("{what} {h:?} is not HOST:PORT")));
        }
        addresses.push((host.to_string(), port));
    }
    Ok((user, password, addresses))
}

/// `%XX` decoding of a URL's user information; `None` for a bad escape.
fn percent_decode(s: &str) -> Option<String> {
    let mut out = Vec::with_capacity(s.len());
    let mut bytes = s.bytes();
    while let Some(b) = bytes.next() {
        if b == b'%' {
            let hex = [bytes.next()?, bytes.next()?];
            out.push(u8::from_str_radix(std::str::from_utf8(&hex).ok()?, 16).ok()?);
        } else {
            out.push(b);
        }
    }
    String::from_utf8(out).ok()
}

/// One Redis server's address and what its URL says.
pub(crate) struct ServerUrl {
    pub(crate) host: String,
    pub(crate) port: u16,
    pub(crate) db: i64,
    pub(crate) tls: bool,
    pub(crate) user: Option<String>,
    pub(crate) password: Option<String>,
}

/// Connects once to check the configuration against the server: `Err`
/// (refuse to start) for a TLS handshake that fails or rejected
/// credentials; `Ok` when it works and when the server does not answer
/// (the store then starts degraded and recovers by itself).
pub(crate) async fn probe(
    client: &Client,
    timeout: Duration,
    what: &str,
) -> Result<(), StoreError> {
    let config_ = AsyncConnectionConfig::new()
        .set_connection_timeout(Some(timeout))
        .set_response_timeout(Some(timeout));
    let attempt = async {
        let mut c = client
            .get_multiplexed_async_connection_with_config(&config_)
            .await?;
        redis::cmd("PING").query_async::<String>(&mut c).await
    };
    match tokio::time::timeout(timeout, attempt).await {
        Ok(Err(e)) => match misconfiguration(&e, what) {
            Some(err) => Err(err),
            None => Ok(()),
        },
        _ => Ok(()),
    }
}

/// The setting a connection error blames, when it is a configuration
/// error rather than an outage: a TLS failure or rejected credentials.
pub(crate) fn misconfiguration(e: &RedisError, what: &str) -> Option<StoreError> {
    if let Some(tls) = rustls_error(e) {
        let setting = match tls {
            rustls::Error::InvalidCertificate(_) => CA,
            rustls::Error::AlertReceived(_) => CERT,
            _ => CA,
        };
        return Some(config(
            setting,
            format!(
                "TLS handshake with {what} failed: {tls} (check {CA}, and {CERT}/{KEY} if the \
                 server asks for a client certificate)"
            ),
        ));
    }
    let auth = e.kind() == ErrorKind::AuthenticationFailed
        || matches!(e.code(), Some("WRONGPASS" | "NOAUTH" | "NOPERM"));
    auth.then(|| {
        config(
            PASSWORD,
            format!(
                "{what} rejected the credentials ({}; user and password come from \
                 FUSION_SESSION_STORE's URL or {PASSWORD})",
                e.code().unwrap_or("authentication failed")
            ),
        )
    })
}

/// The rustls error under a connection error, if any (the redis crate
/// keeps its cause as an `Arc<dyn Error>` around an `io::Error`).
fn rustls_error(e: &RedisError) -> Option<&rustls::Error> {
    type Shared = std::sync::Arc<dyn std::error::Error + Send + Sync>;
    let mut cur: Option<&(dyn std::error::Error + 'static)> = e.source();
    while let Some(mut err) = cur {
        if let Some(shared) = err.downcast_ref::<Shared>() {
            err = shared.as_ref();
        }
        let io_inner = err
            .downcast_ref::<std::io::Error>()
            .and_then(|io| io.get_ref())
            .map(|inner| inner as &(dyn std::error::Error + 'static));
        if let Some(tls) = io_inner.unwrap_or(err).downcast_ref::<rustls::Error>() {
            return Some(tls);
        }
        cur = err.source();
    }
    None
}

fn certificates(settings: &RedisAccessSettings) -> Result<TlsCertificates, StoreError> {
    let root_cert = match &settings.ca {
        Some(path) => {
            let pem = read(CA, path)?;
            let n = CertificateDer::pem_slice_iter(&pem)
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| config(CA, format!("{}: not PEM certificates: {e}", path.display())))?
                .len();
            if n == 0 {
                return Err(config(
                    CA,
                    format!("{}: no certificate in it", path.display()),
                ));
            }
            Some(pem)
        }
        None => None,
    };
    let client_tls = match (&settings.cert, &settings.key) {
        (None, None) => None,
        (Some(cert), Some(key)) => {
            let client_cert = read(CERT, cert)?;
            let n = CertificateDer::pem_slice_iter(&client_cert)
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| config(CERT, format!("{}: not PEM: {e}", cert.display())))?
                .len();
            if n == 0 {
                return Err(config(
                    CERT,
                    format!("{}: no certificate in it", cert.display()),
                ));
            }
            let client_key = read(KEY, key)?;
            PrivateKeyDer::from_pem_slice(&client_key)
                .map_err(|e| config(KEY, format!("{}: no PEM private key: {e}", key.display())))?;
            Some(ClientTlsConfig {
                client_cert,
                client_key,
            })
        }
        (Some(_), None) => return Err(config(KEY, format!("is needed with {CERT}"))),
        (None, Some(_)) => return Err(config(CERT, format!("is needed with {KEY}"))),
    };
    Ok(TlsCertificates {
        client_tls,
        root_cert,
    })
}

fn read(setting: &'static str, path: &std::path::Path) -> Result<Vec<u8>, StoreError> {
    std::fs::read(path).map_err(|e| config(setting, format!("{}: {e}", path.display())))
}

pub(crate) fn config(setting: &'static str, reason: String) -> StoreError {
    StoreError::Config { setting, reason }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn user_information_is_percent_decoded() {
        assert_eq!(percent_decode("p%40ss%3a").as_deref(), Some("p@ss:"));
        assert_eq!(percent_decode("%4"), None);
    }

    #[test]
    fn secrets_do_not_print() {
        let s = RedisAccessSettings {
            password: Some("hunter2".into()),
            ..Default::default()
        };
        assert!(!format!("{s:?}").contains("hunter2"));
    }

    #[test]
    fn server_urls_keep_credentials_out_of_errors() {
        let u = parse_server_url("rediss://app:hunter2@redis.example:6380/3").unwrap();
        assert_eq!(
            (u.host.as_str(), u.port, u.db, u.tls),
            ("redis.example", 6380, 3, true)
        );
        assert_eq!(u.user.as_deref(), Some("app"));
        assert_eq!(u.password.as_deref(), Some("hunter2"));
        for bad in [
            "redis://app:hunter2@",
            "rediss://app:hunter2@h:1/#insecure",
            "redis://app:hunter2@h:notaport/0",
        ] {
            let e = parse_server_url(bad).err().expect(bad).to_string();
            assert!(e.contains(STORE), "{bad}: {e}");
            assert!(!e.contains("hunter2"), "{bad}: {e}");
        }
    }

    #[test]
    fn tls_files_are_checked_and_named() {
        let dir = std::env::temp_dir().join(format!("fusion-access-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let empty = dir.join("empty.pem");
        std::fs::write(&empty, "").unwrap();
        let missing = dir.join("missing.pem");
        let cases = [
            (
                RedisAccessSettings {
                    ca: Some(missing.clone()),
                    ..Default::default()
                },
                true,
                CA,
            ),
            (
                RedisAccessSettings {
                    ca: Some(empty.clone()),
                    ..Default::default()
                },
                true,
                CA,
            ),
            (
                RedisAccessSettings {
                    cert: Some(empty.clone()),
                    ..Default::default()
                },
                true,
                KEY,
            ),
            (
                RedisAccessSettings {
                    ca: Some(empty.clone()),
                    ..Default::default()
                },
                false,
                CA,
            ),
        ];
        for (settings, tls, setting) in cases {
            match Access::new(&settings, tls, None, None) {
                Err(StoreError::Config { setting: s, .. }) => assert_eq!(s, setting),
                Err(e) => panic!("{setting}: {e}"),
                Ok(_) => panic!("{setting}: accepted"),
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
