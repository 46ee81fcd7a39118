//! IP allow-lists of the listeners (`--asterix-allow`): parsed with the
//! settings ([`crate::config::Settings::validate`]), used by the ASTERIX
//! listener ([`crate::asterix_udp`]).

use std::net::IpAddr;

/// The sources a listener takes datagrams from: addresses and CIDR
/// prefixes; none listed, every source.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sources(Vec<(IpAddr, u8)>);

impl Sources {
    /// Parses the entries of the flag `flag` (`--asterix-allow`); an error
    /// names the flag and the entry.
    pub fn parse(flag: &str, entries: &[String]) -> Result<Self, String> {
        let bad = |e: &str, why: &str| format!("{flag}: '{e}' {why}");
        entries
            .iter()
            .map(|e| {
                let (ip, prefix) = match e.trim().split_once('/') {
                    Some((ip, p)) => (ip, Some(p)),
                    None => (e.trim(), None),
                };
                let ip: IpAddr = ip
                    .parse()
                    .map_err(|_| bad(e, "is not an IP address or CIDR prefix"))?;
                let max = if ip.is_ipv4() { 32 } else { 128 };
                let prefix = match prefix {
                    None => max,
                    Some(p) => match p.parse::<u8>() {
                        Ok(n) if n <= max => n,
                        _ => return Err(bad(e, &format!("needs a prefix length of 0 to {max}"))),
                    },
                };
                Ok((ip, prefix))
            })
            .collect::<Result<_, _>>()
            .map(Self)
    }

    /// Whether a datagram from `ip` is taken (an IPv4-mapped IPv6 address
    /// counts as its IPv4 address).
    pub fn allows(&self, ip: IpAddr) -> bool {
        let ip = match ip {
            IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
            v4 => v4,
        };
        self.0.is_empty()
            || self.0.iter().any(|&(net, prefix)| match (net, ip) {
                (IpAddr::V4(n), IpAddr::V4(a)) => {
                    let mask = u32::MAX.checked_shl(32 - u32::from(prefix)).unwrap_or(0);
                    u32::from(n) & mask == u32::from(a) & mask
                }
                (IpAddr::V6(n), IpAddr::V6(a)) => {
                    let mask = u128::MAX.checked_shl(128 - u32::from(prefix)).unwrap_or(0);
                    u128::from(n) & mask == u128::from(a) & mask
                }
                _ => false,
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_match_addresses_and_prefixes() {
        let all = Sources::parse("--asterix-allow", &[]).unwrap();
        assert!(all.allows("203.0.113.9".parse().unwrap()));
        let s = Sources::parse(
            "--asterix-allow",
            &[
                "192.0.2.7".into(),
                "10.1.0.0/16".into(),
                "2001:db8::/32".into(),
            ],
        )
        .unwrap();
        for (ip, ok) in [
            ("192.0.2.7", true),
            ("192.0.2.8", false),
            ("10.1.255.3", true),
            ("10.2.0.1", false),
            ("::ffff:10.1.0.9", true),
            ("2001:db8:5::1", true),
            ("2001:db9::1", false),
        ] {
            assert_eq!(s.allows(ip.parse().unwrap()), ok, "{ip}");
        }
        // /0 takes every address of its family.
        let any4 = Sources::parse("--asterix-allow", &["0.0.0.0/0".into()]).unwrap();
        assert!(any4.allows("198.51.100.1".parse().unwrap()));
        assert!(!any4.allows("2001:db8::1".parse().unwrap()));
        for bad in ["10.0.0.0/33", "radar-a", "::/129", "10.0.0.0/x"] {
            let e = Sources::parse("--asterix-allow", &[bad.into()]).unwrap_err();
            assert!(e.starts_with("--asterix-allow") && e.contains(bad), "{e}");
        }
    }
}
