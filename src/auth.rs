//! API keys and tenants, shared by both adapters. Keys come from
//! `--api-keys` and/or `--api-keys-file` as `key=tenant` pairs; a request
//! presents one as `Authorization: Bearer <key>` (REST and gRPC) or
//! `x-api-key: <key>` (gRPC metadata) and acts as that key's [`Tenant`]. With
//! no key configured the service is open and every request acts as tenant
//! [`DEFAULT_TENANT`]. The adapters put the `Tenant` into the request
//! extensions; keys themselves are never logged nor echoed in errors.
//!
//! Over mutual TLS a verified client certificate may stand for a tenant
//! (`FUSION_TLS_CLIENT_TENANTS`): the accept loop puts a [`CertTenant`] into
//! every request of that connection, and [`ApiKeys::authenticate_request`]
//! decides between it and a key (the precedence is documented there and in
//! docs/operations.md, "TLS").

use std::fmt;

use crate::config::Settings;

/// The tenant of every request when no API key is configured.
pub const DEFAULT_TENANT: &str = "default";

/// Shortest accepted API key, in bytes.
pub const MIN_KEY_LEN: usize = 8;

/// Longest tenant name.
pub const MAX_TENANT_LEN: usize = 64;

/// The tenant a request acts for: inserted into the request extensions by the
/// REST and gRPC authentication layers (`Extension<Tenant>` in axum handlers,
/// `request.extensions().get::<Tenant>()` in tonic services).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Tenant(pub String);

impl Tenant {
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for Tenant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// The tenant a connection's verified client certificate stands for: put
/// into the extensions of every request on that connection by `serve`
/// (mutual TLS with `FUSION_TLS_CLIENT_TENANTS`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertTenant(pub Tenant);

/// Why a request was not authenticated (the messages name no key).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AuthError {
    #[error("an API key is required: send `Authorization: Bearer <key>`")]
    Missing,
    #[error("malformed credentials: expected `Authorization: Bearer <key>`")]
    Malformed,
    #[error("the API key is not valid")]
    UnknownKey,
    /// A valid key of another tenant than the client certificate's
    /// (403 / PERMISSION_DENIED, not 401: both credentials are genuine).
    #[error("the API key belongs to another tenant than the client certificate")]
    TenantMismatch,
}

/// The configured API keys, each mapped to its tenant. Empty means open.
#[derive(Clone, Default)]
pub struct ApiKeys {
    keys: Vec<(Vec<u8>, Tenant)>,
    /// `--metrics-key`: the one key `/metrics` takes, when given.
    metrics: Option<Vec<u8>>,
}

impl fmt::Debug for ApiKeys {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ApiKeys")
            .field("keys", &self.keys.len())
            .field("tenants", &self.tenant_count())
            .field("metrics_key", &self.metrics.is_some())
            .finish()
    }
}

impl ApiKeys {
    /// Keys from `--api-keys` and `--api-keys-file` (either, both or neither).
    /// Errors name the flag (and the entry or line) and never the key.
    ///
    /// Open mode (no authentication) only when neither option is given: a
    /// key option that yields no key (an empty or comment-only file, an
    /// empty mounted secret, `FUSION_API_KEYS=''` or `','`) is an error,
    /// never a silently open service.
    pub fn from_settings(settings: &Settings) -> Result<Self, String> {
        let mut entries = Vec::new();
        if let Some(list) = &settings.api_keys {
            entries.extend(parse_list(list.expose())?);
        }
        if let Some(path) = &settings.api_keys_file {
            let text = std::fs::read_to_string(path)
                .map_err(|e| format!("--api-keys-file: cannot read {}: {e}", path.display()))?;
            entries.extend(parse_file(&text)?);
        }
        let given: Vec<&str> = [
            settings
                .api_keys
                .as_ref()
                .map(|_| "--api-keys (FUSION_API_KEYS)"),
            settings
                .api_keys_file
                .as_ref()
                .map(|_| "--api-keys-file (FUSION_API_KEYS_FILE)"),
        ]
        .into_iter()
        .flatten()
        .collect();
        if entries.is_empty() && !given.is_empty() {
            return Err(format!(
                "{} given but no API key found in it: refusing to start without \
                 authentication; remove the option to run open, or give `key=tenant` entries",
                given.join(" and ")
            ));
        }
        let mut keys = Self::from_entries(entries)?;
        if let Some(key) = &settings.metrics_key {
            let key = key.expose().trim();
            check_key(key, "--metrics-key (FUSION_METRICS_KEY)")?;
            keys.metrics = Some(key.as_bytes().to_vec());
        }
        Ok(keys)
    }

    /// Whether a request may read `/metrics`, which names every tenant's
    /// sessions and radars: with `--metrics-key`, its `Authorization:
    /// Bearer <key>` must be that key; otherwise whatever authenticates an
    /// API request (any tenant's key, a client certificate that stands for
    /// a tenant, anything in open mode; [`Self::authenticate_request`]).
    pub fn authorize_metrics(
        &self,
        cert: Option<&CertTenant>,
        authorization: Option<&str>,
    ) -> Result<(), AuthError> {
        let Some(metrics_key) = &self.metrics else {
            return self
                .authenticate_request(cert, authorization, None)
                .map(|_| ());
        };
        let key = bearer(authorization.ok_or(AuthError::Missing)?)?;
        if constant_time_eq(metrics_key, key.as_bytes()) {
            Ok(())
        } else {
            Err(AuthError::UnknownKey)
        }
    }

    /// True when no key is configured: every request is tenant `default`.
    pub fn is_open(&self) -> bool {
        self.keys.is_empty()
    }

    /// Number of distinct tenants the keys map to.
    pub fn tenant_count(&self) -> usize {
        let mut tenants: Vec<&str> = self.keys.iter().map(|(_, t)| t.as_str()).collect();
        tenants.sort_unstable();
        tenants.dedup();
        tenants.len()
    }

    /// The tenant of an `Authorization` header value (`Bearer <key>`; the
    /// scheme is case-insensitive). Open mode accepts anything as `default`.
    pub fn authenticate(&self, authorization: Option<&str>) -> Result<Tenant, AuthError> {
        if self.is_open() {
            return Ok(default_tenant());
        }
        let key = bearer(authorization.ok_or(AuthError::Missing)?)?;
        self.authenticate_key(Some(key))
    }

    /// The tenant of a request from its credentials: the connection's
    /// client certificate (`cert`, when it maps to a tenant), the
    /// `Authorization` header and, for gRPC, the `x-api-key` metadata (used
    /// only when there is no `authorization`). Precedence:
    ///
    /// - no certificate tenant: the key alone, as [`Self::authenticate`];
    /// - a certificate tenant and no key: that tenant (the certificate
    ///   stands for a key);
    /// - both: the key must be valid (else 401 as without a certificate) and
    ///   belong to the certificate's tenant (else [`AuthError::TenantMismatch`]);
    ///   in open mode (no keys configured) a key is ignored.
    pub fn authenticate_request(
        &self,
        cert: Option<&CertTenant>,
        authorization: Option<&str>,
        api_key: Option<&str>,
    ) -> Result<Tenant, AuthError> {
        let by_key = || match (authorization, api_key) {
            (None, Some(key)) => self.authenticate_key(Some(key.trim())),
            (authorization, _) => self.authenticate(authorization),
        };
        let Some(CertTenant(cert_tenant)) = cert else {
            return by_key();
        };
        if self.is_open() || (authorization.is_none() && api_key.is_none()) {
            return Ok(cert_tenant.clone());
        }
        let key_tenant = by_key()?;
        if key_tenant == *cert_tenant {
            Ok(key_tenant)
        } else {
            Err(AuthError::TenantMismatch)
        }
    }

    /// The tenant of a bare key (the gRPC `x-api-key` metadata).
    pub fn authenticate_key(&self, key: Option<&str>) -> Result<Tenant, AuthError> {
        if self.is_open() {
            return Ok(default_tenant());
        }
        let key = key.ok_or(AuthError::Missing)?;
        if key.is_empty() {
            return Err(AuthError::Malformed);
        }
        self.lookup(key.as_bytes()).ok_or(AuthError::UnknownKey)
    }

    /// Compares `key` with every configured key in constant time per key and
    /// without stopping at a match, so timing tells nothing about which key,
    /// or which prefix of one, matched.
    fn lookup(&self, key: &[u8]) -> Option<Tenant> {
        let mut found = None;
        for (candidate, tenant) in &self.keys {
            if constant_time_eq(candidate, key) {
                found = Some(tenant);
            }
        }
        found.cloned()
    }

    fn from_entries(entries: Vec<Entry>) -> Result<Self, String> {
        let mut keys: Vec<(Vec<u8>, Tenant)> = Vec::with_capacity(entries.len());
        let mut origins: Vec<String> = Vec::with_capacity(entries.len());
        for entry in entries {
            if let Some(i) = keys
                .iter()
                .position(|(k, _)| constant_time_eq(k, entry.key.as_bytes()))
            {
                return Err(format!(
                    "{}: duplicate API key (already given at {})",
                    entry.origin, origins[i]
                ));
            }
            keys.push((entry.key.into_bytes(), Tenant(entry.tenant)));
            origins.push(entry.origin);
        }
        Ok(Self {
            keys,
            metrics: None,
        })
    }
}

/// The key of an `Authorization: Bearer <key>` value (the scheme is
/// case-insensitive).
fn bearer(value: &str) -> Result<&str, AuthError> {
    let (scheme, key) = value.trim().split_once(' ').ok_or(AuthError::Malformed)?;
    if scheme.eq_ignore_ascii_case("bearer") {
        Ok(key.trim())
    } else {
        Err(AuthError::Malformed)
    }
}

fn default_tenant() -> Tenant {
    Tenant(DEFAULT_TENANT.to_string())
}

/// Whether `name` is a valid tenant name: `[A-Za-z0-9_-]{1,64}`.
pub(crate) fn valid_tenant(name: &str) -> bool {
    (1..=MAX_TENANT_LEN).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

/// Equality of two byte strings whose running time depends on their lengths
/// only, not on where they first differ.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let len = a.len().max(b.len());
    let mut diff = u8::from(a.len() != b.len());
    for i in 0..len {
        let x = a.get(i).copied().unwrap_or(0);
        let y = b.get(i).copied().unwrap_or(0);
        diff |= std::hint::black_box(x ^ y);
    }
    std::hint::black_box(diff) == 0
}

/// One `key=tenant` pair with where it came from (`--api-keys entry 2`).
struct Entry {
    key: String,
    tenant: String,
    origin: String,
}

/// `--api-keys`: comma-separated `key=tenant`; empty entries are skipped.
fn parse_list(list: &str) -> Result<Vec<Entry>, String> {
    list.split(',')
        .enumerate()
        .filter(|(_, item)| !item.trim().is_empty())
        .map(|(i, item)| parse_entry(item.trim(), format!("--api-keys entry {}", i + 1)))
        .collect()
}

/// `--api-keys-file`: one `key=tenant` per line; blank lines and lines
/// starting with `#` are skipped.
fn parse_file(text: &str) -> Result<Vec<Entry>, String> {
    text.lines()
        .enumerate()
        .map(|(i, line)| (i, line.trim()))
        .filter(|(_, line)| !line.is_empty() && !line.starts_with('#'))
        .map(|(i, line)| parse_entry(line, format!("--api-keys-file line {}", i + 1)))
        .collect()
}

/// A key is at least [`MIN_KEY_LEN`] printable ASCII characters without
/// spaces; the error names `origin`, never the key.
fn check_key(key: &str, origin: &str) -> Result<(), String> {
    if key.len() < MIN_KEY_LEN {
        return Err(format!(
            "{origin}: the key must be at least {MIN_KEY_LEN} characters"
        ));
    }
    if !key.bytes().all(|b| b.is_ascii_graphic()) {
        return Err(format!(
            "{origin}: the key must be printable ASCII without spaces"
        ));
    }
    Ok(())
}

fn parse_entry(item: &str, origin: String) -> Result<Entry, String> {
    let Some((key, tenant)) = item.split_once('=') else {
        return Err(format!("{origin}: expected `key=tenant`"));
    };
    let (key, tenant) = (key.trim(), tenant.trim());
    check_key(key, &origin)?;
    if !valid_tenant(tenant) {
        return Err(format!(
            "{origin}: the tenant must match [A-Za-z0-9_-]{{1,{MAX_TENANT_LEN}}}"
        ));
    }
    Ok(Entry {
        key: key.to_string(),
        tenant: tenant.to_string(),
        origin,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(list: &str) -> ApiKeys {
        ApiKeys::from_entries(parse_list(list).unwrap()).unwrap()
    }

    fn list_error(list: &str) -> String {
        match parse_list(list).and_then(ApiKeys::from_entries) {
            Ok(_) => panic!("{list:?} should be rejected"),
            Err(e) => e,
        }
    }

    #[test]
    fn constant_time_eq_is_equality() {
        for (a, b, eq) in [
            (&b""[..], &b""[..], true),
            (b"abc", b"abc", true),
            (b"abc", b"abd", false),
            (b"abc", b"xbc", false),
            (b"abc", b"ab", false),
            (b"ab", b"abc", false),
            (b"", b"a", false),
            // Padding with zeros must not make a prefix equal.
            (b"ab\0", b"ab", false),
        ] {
            assert_eq!(constant_time_eq(a, b), eq, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn list_maps_keys_to_tenants() {
        let k = keys(" k1secret=acme , k2secret=globex,,k3secret=acme,");
        assert!(!k.is_open());
        assert_eq!(k.tenant_count(), 2);
        assert_eq!(
            k.authenticate(Some("Bearer k1secret")),
            Ok(Tenant("acme".into()))
        );
        assert_eq!(
            k.authenticate(Some("bearer k2secret")),
            Ok(Tenant("globex".into()))
        );
        assert_eq!(
            k.authenticate_key(Some("k3secret")),
            Ok(Tenant("acme".into()))
        );
    }

    #[test]
    fn bad_credentials_are_told_apart() {
        let k = keys("k1secret=acme");
        assert_eq!(k.authenticate(None), Err(AuthError::Missing));
        assert_eq!(k.authenticate(Some("k1secret")), Err(AuthError::Malformed));
        assert_eq!(
            k.authenticate(Some("Basic k1secret")),
            Err(AuthError::Malformed)
        );
        assert_eq!(k.authenticate(Some("Bearer ")), Err(AuthError::Malformed));
        assert_eq!(k.authenticate(Some("")), Err(AuthError::Malformed));
        assert_eq!(k.authenticate_key(Some("")), Err(AuthError::Malformed));
        assert_eq!(
            k.authenticate(Some("Bearer k1secreT")),
            Err(AuthError::UnknownKey)
        );
        assert_eq!(
            k.authenticate(Some("Bearer k1secret2")),
            Err(AuthError::UnknownKey)
        );
        assert_eq!(k.authenticate_key(None), Err(AuthError::Missing));
    }

    #[test]
    fn a_certificate_tenant_stands_for_a_key_and_must_agree_with_one() {
        let k = keys("k1secret=acme,k2secret=globex");
        let acme = CertTenant(Tenant("acme".into()));
        let auth = |cert, authorization, key| k.authenticate_request(cert, authorization, key);
        // The certificate alone.
        assert_eq!(auth(Some(&acme), None, None), Ok(Tenant("acme".into())));
        // With its own tenant's key, by either header.
        assert_eq!(
            auth(Some(&acme), Some("Bearer k1secret"), None),
            Ok(Tenant("acme".into()))
        );
        assert_eq!(
            auth(Some(&acme), None, Some("k1secret")),
            Ok(Tenant("acme".into()))
        );
        // Another tenant's key: refused, whichever header carries it.
        assert_eq!(
            auth(Some(&acme), Some("Bearer k2secret"), None),
            Err(AuthError::TenantMismatch)
        );
        assert_eq!(
            auth(Some(&acme), None, Some("k2secret")),
            Err(AuthError::TenantMismatch)
        );
        // A bad key is a bad key, certificate or not.
        assert_eq!(
            auth(Some(&acme), Some("Bearer nope-nope"), None),
            Err(AuthError::UnknownKey)
        );
        assert_eq!(
            auth(Some(&acme), Some("k1secret"), None),
            Err(AuthError::Malformed)
        );
        // Without a certificate tenant: the key rules as before.
        assert_eq!(
            auth(None, Some("Bearer k2secret"), None),
            Ok(Tenant("globex".into()))
        );
        assert_eq!(
            auth(None, None, Some("k2secret")),
            Ok(Tenant("globex".into()))
        );
        assert_eq!(auth(None, None, None), Err(AuthError::Missing));
        // Open mode: the certificate's tenant, any key ignored; no
        // certificate: `default`.
        let open = ApiKeys::default();
        assert_eq!(
            open.authenticate_request(Some(&acme), Some("Bearer x"), None),
            Ok(Tenant("acme".into()))
        );
        assert_eq!(
            open.authenticate_request(None, None, None),
            Ok(Tenant("default".into()))
        );
    }

    #[test]
    fn open_mode_is_the_default_tenant() {
        let k = ApiKeys::default();
        assert!(k.is_open());
        for header in [None, Some("Bearer anything"), Some("garbage")] {
            assert_eq!(k.authenticate(header), Ok(Tenant("default".into())));
        }
    }

    #[test]
    fn list_errors_name_the_flag_and_entry_but_not_the_key() {
        for (list, expected) in [
            ("k1secret", "--api-keys entry 1: expected `key=tenant`"),
            (
                "k1secret=acme,short=acme",
                "--api-keys entry 2: the key must be at least 8",
            ),
            (
                "k1 secret=acme",
                "--api-keys entry 1: the key must be printable",
            ),
            ("k1secret=", "--api-keys entry 1: the tenant must match"),
            (
                "k1secret=ac me",
                "--api-keys entry 1: the tenant must match",
            ),
            ("k1secret=acmé", "--api-keys entry 1: the tenant must match"),
            (
                &format!("k1secret={}", "a".repeat(65)),
                "--api-keys entry 1: the tenant must match",
            ),
            (
                "k1secret=acme,k2secret=b,k1secret=globex",
                "--api-keys entry 3: duplicate API key (already given at --api-keys entry 1)",
            ),
        ] {
            let e = list_error(list);
            assert!(e.starts_with(expected), "{list:?}: {e}");
            assert!(!e.contains("k1secret"), "{e} names the key");
        }
        // The longest tenant is accepted.
        keys(&format!("k1secret={}", "a".repeat(64)));
    }

    #[test]
    fn file_skips_comments_and_names_its_lines() {
        let text = "# keys of the staging tenants\n\nk1secret=acme\n  # indented comment\nk2secret = globex\n";
        let entries = parse_file(text).unwrap();
        let origins: Vec<_> = entries.iter().map(|e| e.origin.as_str()).collect();
        assert_eq!(
            origins,
            ["--api-keys-file line 3", "--api-keys-file line 5"]
        );
        let k = ApiKeys::from_entries(entries).unwrap();
        assert_eq!(
            k.authenticate(Some("Bearer k2secret")),
            Ok(Tenant("globex".into()))
        );
        let e = parse_file("k1secret=acme\nnope\n").err().unwrap();
        assert_eq!(e, "--api-keys-file line 2: expected `key=tenant`");
    }

    #[test]
    fn settings_combine_list_and_file() {
        let dir = std::env::temp_dir().join(format!("radar-fusion-keys-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("keys");
        std::fs::write(&path, "k2secret=globex\n").unwrap();
        let mut settings = Settings::for_tests();
        assert!(ApiKeys::from_settings(&settings).unwrap().is_open());
        settings.api_keys = Some("k1secret=acme".into());
        settings.api_keys_file = Some(path.clone());
        let k = ApiKeys::from_settings(&settings).unwrap();
        assert_eq!(k.tenant_count(), 2);
        assert_eq!(
            k.authenticate(Some("Bearer k2secret")),
            Ok(Tenant("globex".into()))
        );
        // A key in both sources is a duplicate, reported at the second.
        std::fs::write(&path, "k1secret=globex\n").unwrap();
        let e = ApiKeys::from_settings(&settings).unwrap_err();
        assert_eq!(
            e,
            "--api-keys-file line 1: duplicate API key (already given at --api-keys entry 1)"
        );
        settings.api_keys_file = Some(dir.join("missing"));
        let e = ApiKeys::from_settings(&settings).unwrap_err();
        assert!(e.starts_with("--api-keys-file: cannot read"), "{e}");
        // Keys configured but none found: refused, never open.
        std::fs::write(&path, "# no keys yet\n\n").unwrap();
        for (list, file) in [
            (None, Some(path.clone())),
            (Some(""), None),
            (Some(","), None),
            (Some(" , "), Some(path.clone())),
        ] {
            settings.api_keys = list.map(Into::into);
            settings.api_keys_file = file;
            let e = ApiKeys::from_settings(&settings).unwrap_err();
            assert!(e.contains("no API key found"), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
