//! The few fields of an X.509 certificate (RFC 5280) the service reads: the
//! subject's common names, the DNS and URI subject alternative names (the
//! identities `FUSION_TLS_CLIENT_TENANTS` maps to tenants) and the end of
//! validity (`tls_certificate_not_after_seconds`).
//!
//! A small DER reader rather than an X.509 crate: rustls (webpki) has
//! verified the client certificates this reads and parsed the server's,
//! and the fields needed are four. Every read is bounds-checked; bytes that
//! are not the expected structure give `None` or an empty list, never a
//! panic (property test below).

/// The names of a certificate's subject.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Names {
    /// The subject's common names (OID 2.5.4.3), in order.
    pub common_names: Vec<String>,
    /// `dNSName` entries of the subject alternative name extension.
    pub dns: Vec<String>,
    /// `uniformResourceIdentifier` entries of that extension.
    pub uris: Vec<String>,
}

/// The subject names of a DER certificate; `None` when the bytes are not a
/// certificate.
pub fn names(der: &[u8]) -> Option<Names> {
    let tbs = Tbs::read(der)?;
    let mut names = Names {
        common_names: common_names(tbs.subject),
        ..Names::default()
    };
    if let Some(san) = tbs.extension(OID_SUBJECT_ALT_NAME) {
        // GeneralNames ::= SEQUENCE OF GeneralName (implicit tags).
        let mut seq = Reader::new(san);
        let (tag, general_names) = seq.next()?;
        if tag != SEQUENCE {
            return None;
        }
        let mut items = Reader::new(general_names);
        while let Some((tag, value)) = items.next() {
            let Ok(text) = std::str::from_utf8(value) else {
                continue;
            };
            match tag {
                DNS_NAME => names.dns.push(text.to_string()),
                URI => names.uris.push(text.to_string()),
                _ => {}
            }
        }
    }
    Some(names)
}

/// The end of a certificate's validity (`notAfter`) in seconds since the
/// Unix epoch; `None` when the bytes are not a certificate.
pub fn not_after_unix(der: &[u8]) -> Option<i64> {
    let tbs = Tbs::read(der)?;
    let mut validity = Reader::new(tbs.validity);
    let _not_before = validity.next()?;
    let (tag, time) = validity.next()?;
    parse_time(tag, time)
}

const SEQUENCE: u8 = 0x30;
const SET: u8 = 0x31;
const OID: u8 = 0x06;
const UTC_TIME: u8 = 0x17;
const GENERALIZED_TIME: u8 = 0x18;
/// `[0]` EXPLICIT version, `[3]` EXPLICIT extensions of a TBSCertificate.
const VERSION: u8 = 0xA0;
const EXTENSIONS: u8 = 0xA3;
/// GeneralName's `[2] dNSName` and `[6] uniformResourceIdentifier`.
const DNS_NAME: u8 = 0x82;
const URI: u8 = 0x86;
/// 2.5.4.3 (id-at-commonName) and 2.5.29.17 (id-ce-subjectAltName), DER.
const OID_COMMON_NAME: &[u8] = &[0x55, 0x04, 0x03];
const OID_SUBJECT_ALT_NAME: &[u8] = &[0x55, 0x1D, 0x11];

/// The parts of a TBSCertificate read here.
struct Tbs<'a> {
    validity: &'a [u8],
    subject: &'a [u8],
    extensions: Option<&'a [u8]>,
}

impl<'a> Tbs<'a> {
    fn read(der: &'a [u8]) -> Option<Self> {
        // Certificate ::= SEQUENCE { tbsCertificate, signatureAlgorithm, signature }
        let (tag, certificate) = Reader::new(der).next()?;
        if tag != SEQUENCE {
            return None;
        }
        let (tag, tbs) = Reader::new(certificate).next()?;
        if tag != SEQUENCE {
            return None;
        }
        // TBSCertificate ::= SEQUENCE { [0] version OPTIONAL, serialNumber,
        //   signature, issuer, validity, subject, subjectPublicKeyInfo,
        //   [1] issuerUniqueID OPTIONAL, [2] subjectUniqueID OPTIONAL,
        //   [3] extensions OPTIONAL }
        let mut fields = Reader::new(tbs);
        let (mut tag, _) = fields.next()?;
        if tag == VERSION {
            (tag, _) = fields.next()?;
        }
        let _serial = tag;
        let _signature = fields.next()?;
        let _issuer = fields.next()?;
        let (tag, validity) = fields.next()?;
        if tag != SEQUENCE {
            return None;
        }
        let (tag, subject) = fields.next()?;
        if tag != SEQUENCE {
            return None;
        }
        let _spki = fields.next()?;
        let mut extensions = None;
        while let Some((tag, value)) = fields.next() {
            if tag == EXTENSIONS {
                extensions = Some(value);
            }
        }
        Some(Self {
            validity,
            subject,
            extensions,
        })
    }

    /// The value (the OCTET STRING's contents) of the extension `oid`.
    fn extension(&self, oid: &[u8]) -> Option<&'a [u8]> {
        // Extensions ::= SEQUENCE OF Extension; Extension ::= SEQUENCE {
        //   extnID OID, critical BOOLEAN DEFAULT FALSE, extnValue OCTET STRING }
        let (tag, list) = Reader::new(self.extensions?).next()?;
        if tag != SEQUENCE {
            return None;
        }
        let mut list = Reader::new(list);
        while let Some((tag, extension)) = list.next() {
            if tag != SEQUENCE {
                continue;
            }
            let mut parts = Reader::new(extension);
            let Some((OID, id)) = parts.next() else {
                continue;
            };
            if id != oid {
                continue;
            }
            // The last part is the OCTET STRING, after an optional BOOLEAN.
            let mut value = None;
            while let Some((tag, v)) = parts.next() {
                if tag == 0x04 {
                    value = Some(v);
                }
            }
            return value;
        }
        None
    }
}

/// Name ::= SEQUENCE OF RelativeDistinguishedName (SET OF
/// AttributeTypeAndValue { type OID, value DirectoryString }): the values of
/// every common name that is a string.
fn common_names(subject: &[u8]) -> Vec<String> {
    let mut out = Vec::new();
    let mut rdns = Reader::new(subject);
    while let Some((tag, rdn)) = rdns.next() {
        if tag != SET {
            continue;
        }
        let mut attributes = Reader::new(rdn);
        while let Some((tag, attribute)) = attributes.next() {
            if tag != SEQUENCE {
                continue;
            }
            let mut parts = Reader::new(attribute);
            let (Some((OID, oid)), Some((kind, value))) = (parts.next(), parts.next()) else {
                continue;
            };
            if oid != OID_COMMON_NAME {
                continue;
            }
            // UTF8String, PrintableString, IA5String (ASCII subsets of UTF-8).
            if matches!(kind, 0x0C | 0x13 | 0x16) {
                if let Ok(text) = std::str::from_utf8(value) {
                    out.push(text.to_string());
                }
            }
        }
    }
    out
}

/// UTCTime `YYMMDDHHMMSSZ` (years 1950–2049, RFC 5280 §4.1.2.5.1) or
/// GeneralizedTime `YYYYMMDDHHMMSSZ`, to Unix seconds.
fn parse_time(tag: u8, text: &[u8]) -> Option<i64> {
    let digits = |range: std::ops::Range<usize>| -> Option<i64> {
        let part = text.get(range)?;
        part.iter().try_fold(0i64, |n, &b| {
            b.is_ascii_digit().then(|| n * 10 + i64::from(b - b'0'))
        })
    };
    let (year, rest) = match (tag, text.len()) {
        (UTC_TIME, 13) => {
            let yy = digits(0..2)?;
            (if yy >= 50 { 1900 + yy } else { 2000 + yy }, 2)
        }
        (GENERALIZED_TIME, 15) => (digits(0..4)?, 4),
        _ => return None,
    };
    if text.last() != Some(&b'Z') {
        return None;
    }
    let month = digits(rest..rest + 2)?;
    let day = digits(rest + 2..rest + 4)?;
    let hour = digits(rest + 4..rest + 6)?;
    let minute = digits(rest + 6..rest + 8)?;
    let second = digits(rest + 8..rest + 10)?;
    if !(1..=12).contains(&month)
        || !(1..=31).contains(&day)
        || hour > 23
        || minute > 59
        || second > 60
    {
        return None;
    }
    Some(days_from_civil(year, month, day) * 86_400 + hour * 3600 + minute * 60 + second)
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's
/// `days_from_civil`).
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12;
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Reads DER TLVs one after the other (low tag numbers, definite lengths
/// of at most four bytes: all that certificates use).
struct Reader<'a> {
    rest: &'a [u8],
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Self { rest: bytes }
    }

    /// The next element's tag and contents; `None` at the end or when the
    /// rest is not well-formed (then every later call is `None` too).
    fn next(&mut self) -> Option<(u8, &'a [u8])> {
        let parsed = (|| {
            let (&tag, rest) = self.rest.split_first()?;
            if tag & 0x1F == 0x1F {
                return None; // high tag number form
            }
            let (&first, mut rest) = rest.split_first()?;
            let len = if first < 0x80 {
                usize::from(first)
            } else {
                let n = usize::from(first & 0x7F);
                if n == 0 || n > 4 {
                    return None;
                }
                let (bytes, after) = rest.split_at_checked(n)?;
                rest = after;
                bytes
                    .iter()
                    .fold(0usize, |len, &b| (len << 8) | usize::from(b))
            };
            let (value, after) = rest.split_at_checked(len)?;
            Some((tag, value, after))
        })();
        match parsed {
            Some((tag, value, after)) => {
                self.rest = after;
                Some((tag, value))
            }
            None => {
                self.rest = &[];
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rcgen::{CertificateParams, DnType, KeyPair, SanType};

    /// A certificate made by rcgen (an independent encoder) with the names
    /// and end of validity given.
    fn certificate(
        cn: Option<&str>,
        dns: &[&str],
        uris: &[&str],
        not_after: (i32, u8, u8),
    ) -> Vec<u8> {
        let mut params =
            CertificateParams::new(dns.iter().map(|s| s.to_string()).collect::<Vec<_>>()).unwrap();
        params.distinguished_name = rcgen::DistinguishedName::new();
        params
            .distinguished_name
            .push(DnType::OrganizationName, "Radar Fusion tests");
        if let Some(cn) = cn {
            params.distinguished_name.push(DnType::CommonName, cn);
        }
        for uri in uris {
            params.subject_alt_names.push(SanType::URI(
                rcgen::string::Ia5String::try_from(*uri).unwrap(),
            ));
        }
        params.not_after = rcgen::date_time_ymd(not_after.0, not_after.1, not_after.2);
        let key = KeyPair::generate().unwrap();
        params.self_signed(&key).unwrap().der().to_vec()
    }

    #[test]
    fn reads_common_name_and_subject_alternative_names() {
        let der = certificate(
            Some("ingest-acme"),
            &["client.acme.example", "b.acme.example"],
            &["spiffe://radar.example/acme"],
            (2031, 3, 1),
        );
        let names = names(&der).unwrap();
        assert_eq!(names.common_names, ["ingest-acme"]);
        assert_eq!(names.dns, ["client.acme.example", "b.acme.example"]);
        assert_eq!(names.uris, ["spiffe://radar.example/acme"]);
        let bare = names_of_bare();
        assert!(bare.common_names.is_empty() && bare.dns.is_empty() && bare.uris.is_empty());
    }

    fn names_of_bare() -> Names {
        names(&certificate(None, &[], &[], (2030, 1, 1))).unwrap()
    }

    #[test]
    fn reads_the_end_of_validity() {
        // 2031-03-01T00:00:00Z = 1_930_089_600 (date -u -d 2031-03-01 +%s).
        let der = certificate(None, &["a.example"], &[], (2031, 3, 1));
        assert_eq!(not_after_unix(&der), Some(1_930_089_600));
        // After 2049 the time is a GeneralizedTime: 2051-01-01 = 2_556_144_000.
        let der = certificate(None, &["a.example"], &[], (2051, 1, 1));
        assert_eq!(not_after_unix(&der), Some(2_556_144_000));
    }

    #[test]
    fn times_in_both_encodings() {
        assert_eq!(parse_time(UTC_TIME, b"700101000000Z"), Some(0));
        assert_eq!(parse_time(UTC_TIME, b"491231235959Z"), Some(2_524_607_999));
        assert_eq!(parse_time(UTC_TIME, b"500101000000Z"), Some(-631_152_000));
        assert_eq!(
            parse_time(GENERALIZED_TIME, b"20000229120000Z"),
            Some(951_825_600)
        );
        for bad in [
            &b"7001010000Z"[..],
            b"701301000000Z",
            b"70010100000aZ",
            b"700101000000+",
        ] {
            assert_eq!(parse_time(UTC_TIME, bad), None, "{bad:?}");
        }
    }

    #[test]
    fn not_a_certificate_is_none() {
        assert_eq!(names(b""), None);
        assert_eq!(names(&[0x30, 0x03, 0x02, 0x01, 0x01]), None);
        assert_eq!(not_after_unix(&[0x30, 0x84, 0xFF, 0xFF, 0xFF, 0xFF]), None);
    }

    proptest! {
        #[test]
        fn arbitrary_and_truncated_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512), cut in 0usize..2000) {
            let _ = names(&bytes);
            let _ = not_after_unix(&bytes);
            let der = certificate(Some("x"), &["a.example"], &["urn:x"], (2030, 1, 1));
            let cut = cut.min(der.len());
            let _ = names(&der[..cut]);
            let mut flipped = der.clone();
            if let Some(b) = flipped.get_mut(cut) {
                *b ^= 0xFF;
            }
            let _ = names(&flipped);
            let _ = not_after_unix(&flipped);
        }
    }
}
