//! CAT034 monoradar service messages (north markers, sector crossings),
//! UAP of edition 1.29 (EUROCONTROL ASTERIX Part 2b), as libasterix's
//! generated definitions give it.
//!
//! Items decoded: I034/010 SAC/SIC, /000 message type, /030 time of day
//! (1/128 s), /020 sector (360/2⁸ °), /041 antenna rotation period
//! (1/128 s). Every other item of the UAP is skipped by its rule.

use super::fields::{time_of_day, u16_at};
use super::uap::{Item, Len, item};
use super::{CAT_SERVICE_MESSAGES, Category, Decoded};

/// A CAT034 record: a service message of a radar's scan.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ServiceMessage {
    pub offset: usize,
    /// I034/010 (SAC, SIC).
    pub source: Option<(u8, u8)>,
    /// I034/000: 1 north marker, 2 sector crossing, 3 geographical
    /// filtering, 4 jamming strobe, …
    pub message_type: Option<u8>,
    /// I034/030, seconds since midnight UTC.
    pub time_of_day_s: Option<f64>,
    /// I034/020 (degrees).
    pub sector_deg: Option<f64>,
    /// I034/041 antenna rotation period (s).
    pub rotation_period_s: Option<f64>,
}

/// CAT034 UAP, FRN 1..=14.
const UAP_034: [Option<Item>; 14] = {
    use Len::{Compound, Explicit, Fixed, Repetitive};
    [
        item("I034/010", Fixed(2)),
        item("I034/000", Fixed(1)),
        item("I034/030", Fixed(3)),
        item("I034/020", Fixed(1)),
        item("I034/041", Fixed(2)),
        // COM, spare, spare, PSR, SSR, MDS (2 bytes), spare.
        item(
            "I034/050",
            Compound(&[
                Some(Fixed(1)),
                None,
                None,
                Some(Fixed(1)),
                Some(Fixed(1)),
                Some(Fixed(2)),
                None,
            ]),
        ),
        // COM, spare, spare, PSR, SSR, MDS (1 byte each), spare.
        item(
            "I034/060",
            Compound(&[
                Some(Fixed(1)),
                None,
                None,
                Some(Fixed(1)),
                Some(Fixed(1)),
                Some(Fixed(1)),
                None,
            ]),
        ),
        item("I034/070", Repetitive(2)),
        item("I034/100", Fixed(8)),
        item("I034/110", Fixed(1)),
        item("I034/120", Fixed(8)),
        item("I034/090", Fixed(2)),
        item("I034/RE", Explicit),
        item("I034/SP", Explicit),
    ]
};

impl Category for ServiceMessage {
    const CAT: u8 = CAT_SERVICE_MESSAGES;
    const UAP: &'static [Option<Item>] = &UAP_034;

    fn read(&mut self, frn: usize, v: &[u8]) {
        let s = self;
        match frn {
            1 => s.source = Some((v[0], v[1])),
            2 => s.message_type = Some(v[0]),
            3 => s.time_of_day_s = Some(time_of_day(v, 0)),
            4 => s.sector_deg = Some(v[0] as f64 * (360.0 / 256.0)),
            5 => s.rotation_period_s = Some(u16_at(v, 0) as f64 / 128.0),
            _ => {}
        }
    }

    fn store(mut self, offset: usize, out: &mut Decoded) {
        self.offset = offset;
        out.service_messages.push(self);
    }
}
