//! Loading and reloading the TLS files, with certificates made by rcgen.
//! The handshakes themselves are tested through the real servers
//! (`tests/api/tls.rs`).

use std::path::PathBuf;

use rcgen::{CertificateParams, KeyPair};

use super::*;

/// A scratch directory removed when dropped.
struct Dir(PathBuf);

impl Dir {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("radar-fusion-tls-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }

    fn write(&self, name: &str, contents: impl AsRef<[u8]>) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, contents).unwrap();
        path
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A self-signed server certificate for `localhost` and its key, as PEM.
fn self_signed() -> (String, String) {
    let key = KeyPair::generate().unwrap();
    let cert = CertificateParams::new(vec!["localhost".to_string()])
        .unwrap()
        .self_signed(&key)
        .unwrap();
    (cert.pem(), key.serialize_pem())
}

fn settings(dir: &Dir, cert: &str, key: &str) -> Settings {
    let mut s = Settings::for_tests();
    s.tls_cert = Some(dir.write("cert.pem", cert));
    s.tls_key = Some(dir.write("key.pem", key));
    s
}

fn load_error(settings: &Settings) -> String {
    match Tls::from_settings(settings) {
        Ok(_) => panic!("the settings should not load"),
        Err(e) => e,
    }
}

#[test]
fn no_certificate_is_plaintext() {
    assert!(
        Tls::from_settings(&Settings::for_tests())
            .unwrap()
            .is_none()
    );
}

#[test]
fn bad_files_refuse_to_load_naming_option_and_file() {
    let dir = Dir::new("bad");
    let (cert, key) = self_signed();
    let mut s = settings(&dir, &cert, &key);
    assert!(Tls::from_settings(&s).unwrap().is_some());

    s.tls_cert = Some(dir.0.join("missing.pem"));
    let e = load_error(&s);
    assert!(
        e.starts_with("--tls-cert (FUSION_TLS_CERT): cannot read"),
        "{e}"
    );
    assert!(e.contains("missing.pem"), "{e}");

    s.tls_cert = Some(dir.write("garbage.pem", "not a certificate\n"));
    let e = load_error(&s);
    assert!(
        e.contains("--tls-cert")
            && e.contains("garbage.pem")
            && e.contains("no `BEGIN CERTIFICATE`"),
        "{e}"
    );

    // PEM around bytes that are no certificate.
    s.tls_cert = Some(dir.write(
        "bogus.pem",
        "-----BEGIN CERTIFICATE-----\nbroken\n-----END CERTIFICATE-----\n",
    ));
    let e = load_error(&s);
    assert!(
        e.starts_with("--tls-cert (FUSION_TLS_CERT)")
            && e.contains("bogus.pem")
            && e.contains("not an X.509 certificate"),
        "{e}"
    );

    // The key file holds a certificate, not a key; the message quotes nothing of it.
    s.tls_cert = Some(dir.write("cert.pem", &cert));
    s.tls_key = Some(dir.write("notakey.pem", &cert));
    let e = load_error(&s);
    assert!(
        e.starts_with("--tls-key (FUSION_TLS_KEY)")
            && e.contains("notakey.pem")
            && e.contains("no PEM private key"),
        "{e}"
    );

    // Another certificate's key.
    let (_, other_key) = self_signed();
    s.tls_key = Some(dir.write("other-key.pem", &other_key));
    let e = load_error(&s);
    assert!(
        e.contains("other-key.pem") && e.contains("does not match the certificate in"),
        "{e}"
    );
    assert!(!e.contains("PRIVATE KEY-----"), "{e}");

    s.tls_key = Some(dir.write("key.pem", &key));
    s.tls_client_ca = Some(dir.write(
        "ca.pem",
        "-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n",
    ));
    let e = load_error(&s);
    assert!(
        e.starts_with("--tls-client-ca (FUSION_TLS_CLIENT_CA)") && e.contains("ca.pem"),
        "{e}"
    );

    s.tls_client_ca = Some(dir.write("ca.pem", &cert));
    s.tls_client_tenants = Some(dir.write("tenants", "cn:x=bad tenant\n"));
    let e = load_error(&s);
    assert!(
        e.starts_with("--tls-client-tenants (FUSION_TLS_CLIENT_TENANTS)")
            && e.contains("tenants line 1"),
        "{e}"
    );
    s.tls_client_tenants = Some(dir.write("tenants", "cn:x=acme\n"));
    assert!(Tls::from_settings(&s).unwrap().is_some());
}

#[test]
fn a_reload_loads_changes_and_keeps_the_old_configuration_on_errors() {
    let dir = Dir::new("reload");
    let (cert, key) = self_signed();
    let s = settings(&dir, &cert, &key);
    let tls = Tls::from_settings(&s).unwrap().unwrap();
    let in_use = |tls: &Tls| tls.loaded().fingerprint;
    let first = in_use(&tls);
    assert_eq!(tls.reload(false), Reload::Unchanged);
    assert_eq!(tls.reload(true), Reload::Unchanged);

    // A new certificate whose key is not written yet: refused, the old one kept.
    let (cert2, key2) = self_signed();
    dir.write("cert.pem", &cert2);
    let Reload::Failed(e) = tls.reload(false) else {
        panic!("a mismatched key loads")
    };
    assert!(e.contains("does not match"), "{e}");
    assert_eq!(in_use(&tls), first);
    // The same bad version is not retried by a poll, only when forced.
    assert_eq!(tls.reload(false), Reload::Unchanged);
    assert!(matches!(tls.reload(true), Reload::Failed(_)));

    // The key arrives: loaded.
    dir.write("key.pem", &key2);
    assert_eq!(tls.reload(false), Reload::Loaded);
    let second = in_use(&tls);
    assert_ne!(second, first);

    // A file that disappears is a failure, said once; the new one stays.
    std::fs::remove_file(dir.0.join("key.pem")).unwrap();
    let Reload::Failed(e) = tls.reload(false) else {
        panic!("a missing key loads")
    };
    assert!(
        e.starts_with("--tls-key (FUSION_TLS_KEY): cannot read"),
        "{e}"
    );
    assert_eq!(tls.reload(false), Reload::Unchanged);
    assert_eq!(in_use(&tls), second);
    // Back as it was: nothing to load.
    dir.write("key.pem", &key2);
    assert_eq!(tls.reload(false), Reload::Unchanged);
    assert_eq!(in_use(&tls), second);
}

#[test]
fn handshake_failures_have_a_reason_from_the_fixed_set() {
    let wrap = |e: rustls::Error| io::Error::new(io::ErrorKind::InvalidData, e);
    for (error, reason) in [
        (
            wrap(rustls::Error::NoCertificatesPresented),
            "no_client_cert",
        ),
        (
            wrap(rustls::Error::InvalidCertificate(
                rustls::CertificateError::UnknownIssuer,
            )),
            "bad_client_cert",
        ),
        (
            wrap(rustls::Error::AlertReceived(
                rustls::AlertDescription::UnknownCA,
            )),
            "alert",
        ),
        (wrap(rustls::Error::NoApplicationProtocol), "protocol"),
        (wrap(rustls::Error::General("x".into())), "other"),
        (io::Error::from(io::ErrorKind::UnexpectedEof), "closed"),
        (io::Error::from(io::ErrorKind::ConnectionReset), "closed"),
        (io::Error::other("x"), "other"),
    ] {
        let got = failure_reason(&error);
        assert_eq!(got, reason, "{error}");
        assert!(FAILURE_REASONS.contains(&got));
    }
}
