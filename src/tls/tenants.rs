//! `FUSION_TLS_CLIENT_TENANTS`: which tenant a verified client certificate
//! stands for. One `kind:name=tenant` per line, `#` comments:
//!
//! ```text
//! uri:spiffe://radar.example/ingest/acme=acme   # a URI subject alternative name
//! dns:client.globex.example=globex              # a DNS subject alternative name
//! cn:acme-batch=acme                            # the subject's common name
//! ```
//!
//! Names are compared exactly (DNS names without regard to ASCII case); no
//! wildcards. A certificate whose names match entries of two different
//! tenants stands for none (and is logged). The precedence between a
//! certificate's tenant and an API key is `auth::ApiKeys::authenticate_request`'s.

use crate::auth::{Tenant, valid_tenant};

use super::x509::Names;

/// The mapping, parsed and checked.
#[derive(Debug, Clone, Default)]
pub struct ClientTenants {
    entries: Vec<Entry>,
}

/// What a certificate's names say about its tenant.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Identified {
    /// Exactly one tenant's entries match.
    Tenant(Tenant),
    /// No entry matches (or there is no mapping).
    Unmapped,
    /// Entries of these tenants match: the certificate stands for none.
    Ambiguous(Vec<Tenant>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Uri,
    Dns,
    CommonName,
}

#[derive(Debug, Clone)]
struct Entry {
    kind: Kind,
    name: String,
    tenant: Tenant,
}

impl ClientTenants {
    /// Parses the file's text; errors name `origin` (the flag and file) and
    /// the line.
    pub fn parse(text: &str, origin: &str) -> Result<Self, String> {
        let mut entries: Vec<Entry> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = strip_comment(line).trim();
            if line.is_empty() {
                continue;
            }
            let at = |what: &str| format!("{origin} line {}: {what}", i + 1);
            // The tenant is after the last `=` (a URI may hold `=`).
            let Some((identity, tenant)) = line.rsplit_once('=') else {
                return Err(at(
                    "expected `uri:NAME=tenant`, `dns:NAME=tenant` or `cn:NAME=tenant`",
                ));
            };
            let (kind, name) = match identity.trim().split_once(':') {
                Some(("uri", name)) => (Kind::Uri, name),
                Some(("dns", name)) => (Kind::Dns, name),
                Some(("cn", name)) => (Kind::CommonName, name),
                _ => {
                    return Err(at("the name must start with `uri:`, `dns:` or `cn:`"));
                }
            };
            let (name, tenant) = (name.trim(), tenant.trim());
            if name.is_empty() {
                return Err(at("the name is empty"));
            }
            if !valid_tenant(tenant) {
                return Err(at(&format!(
                    "the tenant must match [A-Za-z0-9_-]{{1,{}}}",
                    crate::auth::MAX_TENANT_LEN
                )));
            }
            let name = if kind == Kind::Dns {
                name.to_ascii_lowercase()
            } else {
                name.to_string()
            };
            if let Some(other) = entries.iter().find(|e| e.kind == kind && e.name == name) {
                if other.tenant.as_str() != tenant {
                    return Err(at(&format!(
                        "{name:?} is already mapped to tenant {}",
                        other.tenant
                    )));
                }
            }
            entries.push(Entry {
                kind,
                name,
                tenant: Tenant(tenant.to_string()),
            });
        }
        if entries.is_empty() {
            return Err(format!(
                "{origin}: no entry found; give `uri:NAME=tenant`, `dns:NAME=tenant` or \
                 `cn:NAME=tenant` lines, or remove the option"
            ));
        }
        Ok(Self { entries })
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when there is no mapping: every certificate is unmapped.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The tenant a certificate with these names stands for.
    pub fn identify(&self, names: &Names) -> Identified {
        let mut tenants: Vec<Tenant> = Vec::new();
        for entry in &self.entries {
            let matches = match entry.kind {
                Kind::Uri => names.uris.contains(&entry.name),
                Kind::Dns => names
                    .dns
                    .iter()
                    .any(|d| d.eq_ignore_ascii_case(&entry.name)),
                Kind::CommonName => names.common_names.contains(&entry.name),
            };
            if matches && !tenants.contains(&entry.tenant) {
                tenants.push(entry.tenant.clone());
            }
        }
        match tenants.len() {
            0 => Identified::Unmapped,
            1 => Identified::Tenant(tenants.remove(0)),
            _ => Identified::Ambiguous(tenants),
        }
    }
}

/// A line without its comment: `#` at the start or after white space (a
/// URI's fragment `#` follows no space).
fn strip_comment(line: &str) -> &str {
    let bytes = line.as_bytes();
    let at = (0..bytes.len())
        .find(|&i| bytes[i] == b'#' && (i == 0 || bytes[i - 1].is_ascii_whitespace()));
    at.map_or(line, |i| &line[..i])
}

#[cfg(test)]
mod tests {
    use super::*;

    const ORIGIN: &str = "--tls-client-tenants t.map";

    fn names(cn: &[&str], dns: &[&str], uris: &[&str]) -> Names {
        let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect();
        Names {
            common_names: own(cn),
            dns: own(dns),
            uris: own(uris),
        }
    }

    fn tenant(name: &str) -> Identified {
        Identified::Tenant(Tenant(name.into()))
    }

    #[test]
    fn maps_each_kind_of_name() {
        let map = ClientTenants::parse(
            "# client certificates\n\
             uri:spiffe://radar.example/ingest?x=1=acme\n\
             dns:Client.Globex.example = globex   # SAN\n\
             cn:batch-acme=acme\n\
             uri:https://radar.example/c#frag=acme\n",
            ORIGIN,
        )
        .unwrap();
        assert_eq!(map.len(), 4);
        assert_eq!(
            map.identify(&names(&[], &[], &["https://radar.example/c#frag"])),
            tenant("acme")
        );
        assert_eq!(
            map.identify(&names(&[], &[], &["spiffe://radar.example/ingest?x=1"])),
            tenant("acme")
        );
        assert_eq!(
            map.identify(&names(&[], &["client.globex.EXAMPLE"], &[])),
            tenant("globex")
        );
        assert_eq!(
            map.identify(&names(&["batch-acme"], &[], &[])),
            tenant("acme")
        );
        // Exact names only: no prefix, no other kind.
        assert_eq!(
            map.identify(&names(
                &["Client.Globex.example"],
                &["batch-acme"],
                &["spiffe://radar.example/ingest"]
            )),
            Identified::Unmapped
        );
        // Two names of one tenant are one tenant; of two tenants, none.
        assert_eq!(
            map.identify(&names(
                &["batch-acme"],
                &[],
                &["spiffe://radar.example/ingest?x=1"]
            )),
            tenant("acme")
        );
        assert_eq!(
            map.identify(&names(&["batch-acme"], &["client.globex.example"], &[])),
            Identified::Ambiguous(vec![Tenant("globex".into()), Tenant("acme".into())])
        );
        assert_eq!(
            ClientTenants::default().identify(&names(&["batch-acme"], &[], &[])),
            Identified::Unmapped
        );
    }

    #[test]
    fn errors_name_the_file_and_line() {
        for (text, expected) in [
            ("cn:a\n", "line 1: expected `uri:NAME=tenant`"),
            ("\nip:10.0.0.1=acme\n", "line 2: the name must start with"),
            ("cn:=acme", "line 1: the name is empty"),
            ("cn:a=ac me", "line 1: the tenant must match"),
            ("cn:a=", "line 1: the tenant must match"),
            (
                "dns:a.example=acme\ndns:A.example=globex",
                "line 2: \"a.example\" is already mapped to tenant acme",
            ),
        ] {
            let e = ClientTenants::parse(text, ORIGIN).unwrap_err();
            assert!(e.starts_with(ORIGIN), "{e}");
            assert!(e.contains(expected), "{text:?}: {e}");
        }
        let e = ClientTenants::parse("# nothing yet\n", ORIGIN).unwrap_err();
        assert!(e.contains("no entry found"), "{e}");
        // The same mapping twice is harmless.
        ClientTenants::parse("cn:a=acme\ncn:a=acme", ORIGIN).unwrap();
    }
}
