//! Parsing a request into the typed input of its endpoint: the one place
//! where a kind of violation gets its wording.
//!
//! Every endpoint parses its all-`Option` input (what a client sent) into a
//! fully typed input with these combinators. Each returns the parsed value,
//! or `None` after recording a violation of its field, so that a client
//! learns of every bad field at once and compute code never unwraps: the
//! typed input is assembled from the `Option`s and handed over by
//! [`Violations::finish_with`].
//!
//! The wording, one per kind of violation:
//!
//! | kind | message |
//! |---|---|
//! | missing | `is required` (with its choices: `is required: one of a, b`) |
//! | empty id | `must not be empty` |
//! | long id | `must be at most 64 bytes, got 200000` |
//! | duplicate id | `duplicates radars[0].id 'a'` |
//! | unknown id | `no radar 'x' in the network (radars: a, b)`; later ones `(radars: as listed at plots[0].radar_id)` |
//! | not finite | `must be finite, got NaN` |
//! | out of range | `must lie in [0, 90], got 91` (`(0, 1]`, `2..=1000`) |
//! | half-line | `must be finite and > 0, got -1` (`≥ 0`) |
//! | not a choice | `must be one of a, b, got 'c'` |
//! | empty list | `must hold at least one track` |
//! | too many | `at most 64 nodes per request, got 65` |
//! | time order | `must be later than the previous time 3, got 2` |
//! | vector | `must have 4 components, got 3` / `contains a non-finite value` |
//! | matrix | `must be a 4 × 4 matrix` / `contains a non-finite value` |
//! | covariance | `is not symmetric (…)` / `is not positive definite` |
//! | more | `and 12 more violations not listed` (after [`MAX_LISTED_VIOLATIONS`]) |
//!
//! A problem body stays small whatever the request: ids are at most
//! [`MAX_ID_BYTES`] long, a string the client sent is quoted at most
//! [`MAX_ID_BYTES`] long ([`quoted`]), a list of ids is given once
//! ([`Listed`]), and at most [`MAX_LISTED_VIOLATIONS`] violations are
//! listed.

use std::borrow::Cow;
use std::collections::{HashMap, hash_map::Entry};
use std::fmt;

use algo::AlgoError;
use algo::geo::{Ellipsoid, LocalFrame};
use algo::small;

use super::{FieldViolation, Rows, ServiceError, covariance_message, param_violation};

/// A field path, built only when a violation needs it: `&str` and `String`
/// are paths as they are; [`at`] wraps a closure for loops over many
/// elements, where formatting every element's path would cost more than
/// checking it.
pub trait Field {
    fn path(self) -> String;
}

impl Field for &str {
    fn path(self) -> String {
        self.to_owned()
    }
}

impl Field for &String {
    fn path(self) -> String {
        self.clone()
    }
}

impl Field for String {
    fn path(self) -> String {
        self
    }
}

/// A lazily built field path (see [`at`]).
pub struct At<F>(F);

impl<F: FnOnce() -> String> Field for At<F> {
    fn path(self) -> String {
        (self.0)()
    }
}

/// The field path `f()`, built only if a violation is recorded.
pub fn at<F: FnOnce() -> String>(f: F) -> At<F> {
    At(f)
}

/// One end of an [`Interval`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bound {
    Closed(f64),
    Open(f64),
    Unbounded,
}

/// The admissible values of a number; every value outside it, and every
/// non-finite value, is a violation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    pub lo: Bound,
    pub hi: Bound,
}

impl Interval {
    /// Any finite number.
    pub const FINITE: Self = Self {
        lo: Bound::Unbounded,
        hi: Bound::Unbounded,
    };
    /// (0, ∞).
    pub const POSITIVE: Self = Self {
        lo: Bound::Open(0.0),
        hi: Bound::Unbounded,
    };
    /// [0, ∞).
    pub const NON_NEGATIVE: Self = Self {
        lo: Bound::Closed(0.0),
        hi: Bound::Unbounded,
    };
    /// (0, 1): a probability that may be neither 0 nor 1.
    pub const OPEN_UNIT: Self = Self::open(0.0, 1.0);

    /// [lo, hi].
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Self {
            lo: Bound::Closed(lo),
            hi: Bound::Closed(hi),
        }
    }

    /// (lo, hi).
    pub const fn open(lo: f64, hi: f64) -> Self {
        Self {
            lo: Bound::Open(lo),
            hi: Bound::Open(hi),
        }
    }

    /// (lo, hi].
    pub const fn open_closed(lo: f64, hi: f64) -> Self {
        Self {
            lo: Bound::Open(lo),
            hi: Bound::Closed(hi),
        }
    }

    /// [lo, hi).
    pub const fn closed_open(lo: f64, hi: f64) -> Self {
        Self {
            lo: Bound::Closed(lo),
            hi: Bound::Open(hi),
        }
    }

    /// Whether `x` is finite and inside.
    pub fn contains(&self, x: f64) -> bool {
        let lo = match self.lo {
            Bound::Closed(a) => x >= a,
            Bound::Open(a) => x > a,
            Bound::Unbounded => true,
        };
        let hi = match self.hi {
            Bound::Closed(b) => x <= b,
            Bound::Open(b) => x < b,
            Bound::Unbounded => true,
        };
        x.is_finite() && lo && hi
    }

    /// The message for `x` outside.
    fn message(&self, x: f64) -> String {
        match (self.lo, self.hi) {
            (Bound::Unbounded, Bound::Unbounded) => format!("must be finite, got {x}"),
            (Bound::Open(a), Bound::Unbounded) => format!("must be finite and > {a}, got {x}"),
            (Bound::Closed(a), Bound::Unbounded) => format!("must be finite and ≥ {a}, got {x}"),
            (Bound::Unbounded, Bound::Open(b)) => format!("must be finite and < {b}, got {x}"),
            (Bound::Unbounded, Bound::Closed(b)) => format!("must be finite and ≤ {b}, got {x}"),
            _ => format!("must lie in {self}, got {x}"),
        }
    }
}

impl fmt::Display for Interval {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.lo {
            Bound::Closed(a) => write!(f, "[{a}, ")?,
            Bound::Open(a) => write!(f, "({a}, ")?,
            Bound::Unbounded => write!(f, "(-∞, ")?,
        }
        match self.hi {
            Bound::Closed(b) => write!(f, "{b}]"),
            Bound::Open(b) => write!(f, "{b})"),
            Bound::Unbounded => write!(f, "∞)"),
        }
    }
}

/// The latitudes of a radar site, in degrees: within 0.1° of a pole north
/// is no usable azimuth reference.
pub const LATITUDE: Interval = Interval::closed(-89.9, 89.9);
/// Longitudes, in degrees.
pub const LONGITUDE: Interval = Interval::closed(-180.0, 180.0);
/// Heights of a site above the ellipsoid, in m: the deepest ocean trench to
/// the edge of space.
pub const SITE_HEIGHT: Interval = Interval::closed(-11_000.0, 100_000.0);

/// The longest id a client may choose (radars, nodes, tracks), in bytes.
pub const MAX_ID_BYTES: usize = 64;

/// The most violations one error lists; the rest are counted in a last
/// entry, so that a large bad request does not get a larger answer.
pub const MAX_LISTED_VIOLATIONS: usize = 100;

/// `s` as a message quotes it: whole up to [`MAX_ID_BYTES`] bytes, else its
/// first bytes (on a character boundary) and `…`.
pub fn quoted(s: &str) -> Cow<'_, str> {
    if s.len() <= MAX_ID_BYTES {
        return Cow::Borrowed(s);
    }
    let mut end = MAX_ID_BYTES;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    Cow::Owned(format!("{}…", &s[..end]))
}

/// What is wrong with a client-chosen id, if anything: empty, or longer
/// than [`MAX_ID_BYTES`].
pub fn id_problem(id: &str) -> Option<String> {
    if id.is_empty() {
        Some("must not be empty".to_string())
    } else if id.len() > MAX_ID_BYTES {
        Some(format!(
            "must be at most {MAX_ID_BYTES} bytes, got {}",
            id.len()
        ))
    } else {
        None
    }
}

/// Collects field violations while a request is parsed, so that a client
/// learns of every bad field at once (the first
/// [`MAX_LISTED_VIOLATIONS`] of them, and how many more there are).
#[derive(Debug, Default)]
pub struct Violations {
    listed: Vec<FieldViolation>,
    /// The first violation not listed, and how many were not.
    more: Option<(String, usize)>,
}

impl Violations {
    pub fn new() -> Self {
        Self::default()
    }

    /// The invalid-input error of one violation of `field`.
    pub fn single(field: impl Field, message: impl Into<String>) -> ServiceError {
        ServiceError::InvalidInput(vec![FieldViolation {
            field: field.path(),
            message: message.into(),
        }])
    }

    /// Records a violation of `field`.
    pub fn add(&mut self, field: impl Field, message: impl Into<String>) {
        self.push(FieldViolation {
            field: field.path(),
            message: message.into(),
        });
    }

    fn push(&mut self, violation: FieldViolation) {
        if self.listed.len() < MAX_LISTED_VIOLATIONS {
            self.listed.push(violation);
        } else {
            self.more.get_or_insert((violation.field, 0)).1 += 1;
        }
    }

    /// A required client-chosen id (not empty, at most [`MAX_ID_BYTES`]),
    /// or a recorded violation.
    pub fn id<'a>(&mut self, field: impl Field, id: Option<&'a str>) -> Option<&'a str> {
        match id.map(|id| (id, id_problem(id))) {
            None => {
                self.add(field, "is required");
                None
            }
            Some((_, Some(problem))) => {
                self.add(field, problem);
                None
            }
            Some((id, None)) => Some(id),
        }
    }

    /// Returns the value of a required field, or records that it is missing.
    pub fn required<T>(&mut self, field: impl Field, value: Option<T>) -> Option<T> {
        if value.is_none() {
            self.add(field, "is required");
        }
        value
    }

    /// As [`required`](Self::required), with the field path built only when
    /// the value is missing (for loops over many elements).
    pub fn required_at<T>(
        &mut self,
        value: Option<T>,
        field: impl FnOnce() -> String,
    ) -> Option<T> {
        self.required(at(field), value)
    }

    /// A required number inside `range`, or a recorded violation.
    pub fn number(&mut self, field: impl Field, x: Option<f64>, range: Interval) -> Option<f64> {
        match x {
            None => {
                self.add(field, "is required");
                None
            }
            Some(x) => self.within(field, x, range),
        }
    }

    /// An optional number inside `range`: `default` when absent (the
    /// default itself is checked like a given value).
    pub fn number_or(
        &mut self,
        field: impl Field,
        x: Option<f64>,
        default: f64,
        range: Interval,
    ) -> Option<f64> {
        self.within(field, x.unwrap_or(default), range)
    }

    /// `x` if it lies inside `range`, or a recorded violation.
    pub fn within(&mut self, field: impl Field, x: f64, range: Interval) -> Option<f64> {
        if range.contains(x) {
            Some(x)
        } else {
            self.add(field, range.message(x));
            None
        }
    }

    /// A required number in [lo, hi], or a recorded violation.
    pub fn number_in(
        &mut self,
        field: impl Field,
        x: Option<f64>,
        lo: f64,
        hi: f64,
    ) -> Option<f64> {
        self.number(field, x, Interval::closed(lo, hi))
    }

    /// A required finite number > 0, or a recorded violation.
    pub fn positive(&mut self, field: impl Field, x: Option<f64>) -> Option<f64> {
        self.number(field, x, Interval::POSITIVE)
    }

    /// An integer in lo..=hi: `default` when absent.
    pub fn count_or<T>(
        &mut self,
        field: impl Field,
        n: Option<T>,
        default: T,
        lo: T,
        hi: T,
    ) -> Option<T>
    where
        T: PartialOrd + Copy + fmt::Display,
    {
        let n = n.unwrap_or(default);
        if n >= lo && n <= hi {
            Some(n)
        } else {
            self.add(field, format!("must lie in {lo}..={hi}, got {n}"));
            None
        }
    }

    /// One of the named `choices`: `default` when absent, else a
    /// violation that lists them.
    pub fn one_of<T: Copy>(
        &mut self,
        field: impl Field,
        given: Option<&str>,
        default: Option<T>,
        choices: &[(&str, T)],
    ) -> Option<T> {
        let names = || {
            choices
                .iter()
                .map(|(name, _)| *name)
                .collect::<Vec<_>>()
                .join(", ")
        };
        match given {
            None if default.is_some() => default,
            None => {
                self.add(field, format!("is required: one of {}", names()));
                None
            }
            Some(name) => match choices.iter().find(|(n, _)| *n == name) {
                Some((_, value)) => Some(*value),
                None => {
                    self.add(
                        field,
                        format!("must be one of {}, got '{}'", names(), quoted(name)),
                    );
                    None
                }
            },
        }
    }

    /// A list that must hold at least one `item` and at most `max`; records
    /// a violation and answers false otherwise.
    pub fn count_within(&mut self, field: &str, len: usize, max: usize, item: &str) -> bool {
        if len == 0 {
            self.add(field, format!("must hold at least one {item}"));
            false
        } else {
            self.at_most(field, len, max, &format!("{item}s"))
        }
    }

    /// At most `max` `items` per request; records a violation and answers
    /// false beyond it.
    pub fn at_most(&mut self, field: &str, n: usize, max: usize, items: &str) -> bool {
        if n > max {
            self.add(field, format!("at most {max} {items} per request, got {n}"));
            false
        } else {
            true
        }
    }

    /// A vector of `n` finite numbers; records a violation and answers
    /// false otherwise.
    pub fn vector(&mut self, field: impl Field, values: &[f64], n: usize) -> bool {
        if values.len() != n {
            self.add(
                field,
                format!("must have {n} components, got {}", values.len()),
            );
            false
        } else if values.iter().any(|x| !x.is_finite()) {
            self.add(field, "contains a non-finite value");
            false
        } else {
            true
        }
    }

    /// A `nrows` × `ncols` matrix of finite numbers, row-major, or a
    /// recorded violation.
    pub fn matrix(
        &mut self,
        field: impl Field,
        rows: &(impl RowMajor + ?Sized),
        nrows: usize,
        ncols: usize,
    ) -> Option<Vec<f64>> {
        self.matrix_values(field, rows, nrows, ncols)
            .map(Cow::into_owned)
    }

    /// [`Violations::matrix`], its values borrowed from flat [`Rows`].
    pub fn matrix_values<'r>(
        &mut self,
        field: impl Field,
        rows: &'r (impl RowMajor + ?Sized),
        nrows: usize,
        ncols: usize,
    ) -> Option<Cow<'r, [f64]>> {
        if !has_shape(rows, nrows, ncols) {
            self.add(field, format!("must be a {nrows} × {ncols} matrix"));
            return None;
        }
        let flat = rows.flat();
        if flat.iter().any(|x| !x.is_finite()) {
            self.add(field, "contains a non-finite value");
            return None;
        }
        Some(flat)
    }

    /// An n × n covariance (finite, symmetric, positive definite),
    /// n ≤ [`small::MAX_DIM`], checked on the stack; records a violation
    /// and answers false otherwise.
    pub fn covariance(
        &mut self,
        field: impl Field,
        rows: &(impl RowMajor + ?Sized),
        n: usize,
    ) -> bool {
        if n > small::MAX_DIM || !has_shape(rows, n, n) {
            self.add(field, format!("must be a {n} × {n} matrix"));
            return false;
        }
        // Symmetry and definiteness do not depend on the order of the
        // components: the request's order is checked as it is.
        let mut flat = small::ZERO;
        rows.write_flat(&mut flat[..n * n]);
        match small::check_covariance("covariance", &flat[..n * n], n) {
            Ok(()) => true,
            Err(e) => {
                self.add(field, covariance_message(&e));
                false
            }
        }
    }

    /// A WGS84 site (`{prefix}.lat_deg`, `.lon_deg`, `.height_m`, all
    /// required) as the local east-north-up frame at it. Within 0.1° of a
    /// pole north is no usable azimuth reference, so |lat| ≤ 89.9°.
    pub fn site(
        &mut self,
        prefix: &str,
        lat_deg: Option<f64>,
        lon_deg: Option<f64>,
        height_m: Option<f64>,
    ) -> Option<LocalFrame> {
        let lat = self.number(format!("{prefix}.lat_deg"), lat_deg, LATITUDE);
        let lon = self.number(format!("{prefix}.lon_deg"), lon_deg, LONGITUDE);
        let h = self.number(format!("{prefix}.height_m"), height_m, SITE_HEIGHT);
        let (lat, lon, h) = (lat?, lon?, h?);
        self.check(
            prefix,
            LocalFrame::new(Ellipsoid::WGS84, lat.to_radians(), lon.to_radians(), h),
        )
    }

    /// Records `result`'s error, if any, against `field`, and passes the value on.
    pub fn check<T, E: fmt::Display>(
        &mut self,
        field: impl Field,
        result: Result<T, E>,
    ) -> Option<T> {
        result.map_err(|e| self.add(field, e.to_string())).ok()
    }

    /// Records a parameter error of the numerical core against the field
    /// `prefix` + the parameter's name (`rules[2].` + `l`), and passes the value on.
    pub fn param<T>(&mut self, prefix: &str, result: Result<T, AlgoError>) -> Option<T> {
        match result {
            Ok(value) => Some(value),
            Err(e) => {
                self.push(param_violation(prefix, e));
                None
            }
        }
    }

    /// The invalid-input error for one parameter error of the numerical core.
    pub fn from_param(prefix: &str, e: AlgoError) -> ServiceError {
        ServiceError::InvalidInput(vec![param_violation(prefix, e)])
    }

    pub fn is_empty(&self) -> bool {
        self.listed.is_empty()
    }

    /// `Ok(())` when nothing was recorded, otherwise the invalid-input
    /// error: the listed violations, and a last one at the first field not
    /// listed that says how many more there are.
    pub fn finish(self) -> Result<(), ServiceError> {
        let mut listed = self.listed;
        if listed.is_empty() {
            return Ok(());
        }
        if let Some((field, more)) = self.more {
            listed.push(FieldViolation {
                field,
                message: format!("and {more} more violations not listed"),
            });
        }
        Err(ServiceError::InvalidInput(listed))
    }

    /// The typed input, when nothing was recorded; otherwise the
    /// invalid-input error. A `None` without a violation is a bug of the
    /// parser: it is an internal error, not a panic.
    pub fn finish_with<T>(self, parsed: Option<T>) -> Result<T, ServiceError> {
        self.finish()?;
        parsed.ok_or_else(|| {
            ServiceError::Internal("the request parsed without a violation but to no value".into())
        })
    }
}

/// A matrix as a request gives it: nested rows or flat [`Rows`].
pub trait RowMajor {
    /// `(rows, cols)` when every row has the same length (`(0, 0)` for no
    /// rows), `None` for ragged rows.
    fn shape(&self) -> Option<(usize, usize)>;
    /// The values row after row.
    fn flat(&self) -> Cow<'_, [f64]>;
    /// The values row after row into `out` (as long as they are), without
    /// an allocation.
    fn write_flat(&self, out: &mut [f64]) {
        out.copy_from_slice(&self.flat());
    }
}

/// Whether `rows` is `nrows × ncols` (no rows at all is `0 × anything`).
fn has_shape(rows: &(impl RowMajor + ?Sized), nrows: usize, ncols: usize) -> bool {
    match rows.shape() {
        Some((0, _)) => nrows == 0,
        shape => shape == Some((nrows, ncols)),
    }
}

impl RowMajor for [Vec<f64>] {
    fn shape(&self) -> Option<(usize, usize)> {
        let cols = self.first().map_or(0, Vec::len);
        self.iter()
            .all(|r| r.len() == cols)
            .then_some((self.len(), cols))
    }

    fn flat(&self) -> Cow<'_, [f64]> {
        Cow::Owned(self.concat())
    }

    fn write_flat(&self, out: &mut [f64]) {
        let mut at = 0;
        for row in self {
            out[at..at + row.len()].copy_from_slice(row);
            at += row.len();
        }
    }
}

/// Nested rows held in a `Vec` or an array.
impl<T: AsRef<[Vec<f64>]>> RowMajor for T {
    fn shape(&self) -> Option<(usize, usize)> {
        self.as_ref().shape()
    }

    fn flat(&self) -> Cow<'_, [f64]> {
        self.as_ref().flat()
    }

    fn write_flat(&self, out: &mut [f64]) {
        self.as_ref().write_flat(out);
    }
}

impl RowMajor for Rows {
    fn shape(&self) -> Option<(usize, usize)> {
        Rows::shape(self)
    }

    fn flat(&self) -> Cow<'_, [f64]> {
        Cow::Borrowed(self.values())
    }
}

/// Ids that must be present, non-empty, at most [`MAX_ID_BYTES`] long and
/// unique within their list.
#[derive(Debug, Default)]
pub struct Ids<'a> {
    seen: HashMap<&'a str, usize>,
}

impl<'a> Ids<'a> {
    pub fn new() -> Self {
        Self::default()
    }

    /// For a list of `n` elements (the map is not grown on the way).
    pub fn with_capacity(n: usize) -> Self {
        Self {
            seen: HashMap::with_capacity(n),
        }
    }

    /// The id of element `index` of the list; `field(i)` is the path of
    /// element i's id. A missing, empty, too long or repeated id is a
    /// violation (and `None`).
    pub fn check(
        &mut self,
        v: &mut Violations,
        id: Option<&'a str>,
        index: usize,
        field: impl Fn(usize) -> String,
    ) -> Option<&'a str> {
        match id {
            None => {
                v.add(field(index), "is required");
                None
            }
            Some(id) if id_problem(id).is_some() => {
                v.id(field(index), Some(id));
                None
            }
            // The first holder keeps the id.
            Some(id) => match self.seen.entry(id) {
                Entry::Occupied(first) => {
                    v.add(
                        field(index),
                        format!("duplicates {} '{id}'", field(*first.get())),
                    );
                    None
                }
                Entry::Vacant(slot) => {
                    slot.insert(index);
                    Some(id)
                }
            },
        }
    }
}

/// A list of ids that violations refer to (a network's radars, a
/// session's nodes): the first violation that needs it gives it whole and
/// later ones point to that violation's field, so that many bad references
/// do not repeat the list.
#[derive(Debug, Default)]
pub struct Listed {
    at: Option<String>,
}

impl Listed {
    pub fn new() -> Self {
        Self::default()
    }

    /// `ids` joined by `, ` for the violation of `field`, the first time;
    /// `as listed at {that field}` afterwards.
    pub fn ids<S: AsRef<str>>(&mut self, ids: &[S], field: impl Field) -> String {
        match &self.at {
            Some(at) => format!("as listed at {at}"),
            None => {
                self.at = Some(field.path());
                ids.iter().map(AsRef::as_ref).collect::<Vec<_>>().join(", ")
            }
        }
    }
}

/// Times that must increase strictly along a list (a track's samples).
#[derive(Debug, Clone, Copy)]
pub struct Increasing {
    last: f64,
}

impl Default for Increasing {
    fn default() -> Self {
        Self {
            last: f64::NEG_INFINITY,
        }
    }
}

impl Increasing {
    pub fn new() -> Self {
        Self::default()
    }

    /// A required time inside `range` and later than the previous one
    /// accepted, or a recorded violation (the previous time stays the
    /// reference).
    pub fn next(
        &mut self,
        v: &mut Violations,
        field: impl Field,
        t: Option<f64>,
        range: Interval,
    ) -> Option<f64> {
        let Some(t) = t else {
            v.add(field, "is required");
            return None;
        };
        if !range.contains(t) {
            v.add(field, range.message(t));
            return None;
        }
        if t <= self.last {
            v.add(
                field,
                format!(
                    "must be later than the previous time {}, got {t}",
                    self.last
                ),
            );
            return None;
        }
        self.last = t;
        Some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn messages(v: Violations) -> Vec<(String, String)> {
        match v.finish() {
            Ok(()) => Vec::new(),
            Err(ServiceError::InvalidInput(list)) => {
                list.into_iter().map(|f| (f.field, f.message)).collect()
            }
            Err(other) => panic!("{other}"),
        }
    }

    #[test]
    fn intervals_admit_exactly_their_values_and_say_so() {
        let mut v = Violations::new();
        assert_eq!(v.number("a", Some(1.0), Interval::OPEN_UNIT), None);
        assert_eq!(v.number("b", Some(0.5), Interval::OPEN_UNIT), Some(0.5));
        assert_eq!(
            v.number("c", Some(1.0), Interval::open_closed(0.0, 1.0)),
            Some(1.0)
        );
        assert_eq!(v.number("d", Some(0.0), Interval::POSITIVE), None);
        assert_eq!(v.number("e", Some(0.0), Interval::NON_NEGATIVE), Some(0.0));
        assert_eq!(v.number("f", Some(f64::INFINITY), Interval::FINITE), None);
        assert_eq!(v.number("g", None, Interval::FINITE), None);
        assert_eq!(
            v.number_or("h", None, 2.0, Interval::closed(0.0, 1.0)),
            None
        );
        assert_eq!(
            v.number("i", Some(-0.5), Interval::closed_open(0.0, 1.0)),
            None
        );
        assert_eq!(
            messages(v),
            [
                ("a", "must lie in (0, 1), got 1"),
                ("d", "must be finite and > 0, got 0"),
                ("f", "must be finite, got inf"),
                ("g", "is required"),
                ("h", "must lie in [0, 1], got 2"),
                ("i", "must lie in [0, 1), got -0.5"),
            ]
            .map(|(f, m)| (f.to_string(), m.to_string()))
        );
    }

    #[test]
    fn choices_default_require_and_list() {
        let choices = [("grid", 1), ("none", 2)];
        let mut v = Violations::new();
        assert_eq!(v.one_of("a", None, Some(1), &choices), Some(1));
        assert_eq!(v.one_of("b", Some("none"), Some(1), &choices), Some(2));
        assert_eq!(v.one_of("c", Some("all"), Some(1), &choices), None);
        assert_eq!(v.one_of("d", None, None, &choices), None);
        assert_eq!(
            messages(v),
            [
                ("c", "must be one of grid, none, got 'all'"),
                ("d", "is required: one of grid, none"),
            ]
            .map(|(f, m)| (f.to_string(), m.to_string()))
        );
    }

    #[test]
    fn ids_name_the_first_holder_of_a_duplicate() {
        let mut v = Violations::new();
        let mut ids = Ids::new();
        let path = |i: usize| format!("nodes[{i}].id");
        assert_eq!(ids.check(&mut v, Some("a"), 0, path), Some("a"));
        assert_eq!(ids.check(&mut v, Some("b"), 1, path), Some("b"));
        assert_eq!(ids.check(&mut v, Some("a"), 2, path), None);
        assert_eq!(ids.check(&mut v, Some("a"), 3, path), None);
        assert_eq!(ids.check(&mut v, Some(""), 4, path), None);
        assert_eq!(ids.check(&mut v, None, 5, path), None);
        let long = "x".repeat(MAX_ID_BYTES + 1);
        assert_eq!(ids.check(&mut v, Some(&long), 6, path), None);
        let longest = "y".repeat(MAX_ID_BYTES);
        assert_eq!(ids.check(&mut v, Some(&longest), 7, path), Some(&*longest));
        assert_eq!(
            messages(v),
            [
                ("nodes[2].id", "duplicates nodes[0].id 'a'"),
                ("nodes[3].id", "duplicates nodes[0].id 'a'"),
                ("nodes[4].id", "must not be empty"),
                ("nodes[5].id", "is required"),
                ("nodes[6].id", "must be at most 64 bytes, got 65"),
            ]
            .map(|(f, m)| (f.to_string(), m.to_string()))
        );
    }

    #[test]
    fn a_long_bad_request_lists_the_first_violations_and_counts_the_rest() {
        let mut v = Violations::new();
        for i in 0..MAX_LISTED_VIOLATIONS + 250 {
            v.add(format!("plots[{i}].t"), "is required");
        }
        let list = messages(v);
        assert_eq!(list.len(), MAX_LISTED_VIOLATIONS + 1);
        assert_eq!(list[99], ("plots[99].t".into(), "is required".into()));
        assert_eq!(
            list[100],
            (
                "plots[100].t".into(),
                "and 250 more violations not listed".into()
            )
        );
    }

    #[test]
    fn quoted_strings_and_listed_ids_stay_short() {
        assert_eq!(quoted("abc"), "abc");
        // 'é' is two bytes: a cut inside it moves back to its start.
        let long = format!("{}é{}", "a".repeat(63), "b".repeat(1000));
        assert_eq!(quoted(&long), format!("{}…", "a".repeat(63)));
        let mut listed = Listed::new();
        let ids = ["north", "south"];
        assert_eq!(listed.ids(&ids, "plots[3].radar_id"), "north, south");
        assert_eq!(
            listed.ids(&ids, "plots[9].radar_id"),
            "as listed at plots[3].radar_id"
        );
        let mut v = Violations::new();
        assert_eq!(v.id("a", Some("ok")), Some("ok"));
        assert_eq!(v.id("b", Some("")), None);
        assert_eq!(v.id("c", None), None);
        assert_eq!(v.id("d", Some(&"z".repeat(200_000))), None);
        assert_eq!(
            messages(v),
            [
                ("b", "must not be empty"),
                ("c", "is required"),
                ("d", "must be at most 64 bytes, got 200000"),
            ]
            .map(|(f, m)| (f.to_string(), m.to_string()))
        );
    }

    #[test]
    fn times_must_increase_strictly() {
        let mut v = Violations::new();
        let mut times = Increasing::new();
        assert_eq!(
            times.next(&mut v, "t0", Some(1.0), Interval::FINITE),
            Some(1.0)
        );
        assert_eq!(times.next(&mut v, "t1", Some(1.0), Interval::FINITE), None);
        assert_eq!(
            times.next(&mut v, "t2", Some(f64::NAN), Interval::FINITE),
            None
        );
        assert_eq!(
            times.next(&mut v, "t3", Some(2.0), Interval::FINITE),
            Some(2.0)
        );
        assert_eq!(
            messages(v),
            [
                ("t1", "must be later than the previous time 1, got 1"),
                ("t2", "must be finite, got NaN"),
            ]
            .map(|(f, m)| (f.to_string(), m.to_string()))
        );
    }

    #[test]
    fn matrices_and_covariances() {
        let mut v = Violations::new();
        let good = vec![vec![2.0, 0.5], vec![0.5, 1.0]];
        assert!(v.covariance("p", &good, 2));
        assert_eq!(v.matrix("m", &good, 2, 2), Some(vec![2.0, 0.5, 0.5, 1.0]));
        assert!(!v.covariance("p1", &[vec![1.0, 0.0]], 2));
        // Eigenvalues 3 and −1: symmetric, not positive definite.
        assert!(!v.covariance("p2", &[vec![1.0, 2.0], vec![2.0, 1.0]], 2));
        assert_eq!(v.matrix("m1", &[vec![f64::NAN]], 1, 1), None);
        assert!(!v.vector("x", &[1.0], 2));
        assert!(v.vector("x0", &[1.0, 2.0], 2));
        // Flat rows: the same checks, the same words.
        let flat = Rows::from_nested(&good);
        assert!(v.covariance("q", &flat, 2));
        assert_eq!(v.matrix("n", &flat, 2, 2), Some(vec![2.0, 0.5, 0.5, 1.0]));
        let ragged = Rows::from_nested(&[vec![2.0, 0.5], vec![0.5]]);
        assert!(!v.covariance("q1", &ragged, 2));
        assert_eq!(v.matrix("n1", &ragged, 2, 2), None);
        // No rows at all is 0 × anything.
        assert_eq!(v.matrix("n0", &Rows::default(), 0, 3), Some(vec![]));
        assert_eq!(v.matrix("n2", &Rows::default(), 1, 1), None);
        assert_eq!(
            messages(v),
            [
                ("p1", "must be a 2 × 2 matrix"),
                ("p2", "is not positive definite"),
                ("m1", "contains a non-finite value"),
                ("x", "must have 2 components, got 1"),
                ("q1", "must be a 2 × 2 matrix"),
                ("n1", "must be a 2 × 2 matrix"),
                ("n2", "must be a 1 × 1 matrix"),
            ]
            .map(|(f, m)| (f.to_string(), m.to_string()))
        );
    }

    #[test]
    fn a_parser_without_a_value_or_a_violation_is_an_internal_error() {
        let v = Violations::new();
        assert!(matches!(
            v.finish_with::<u8>(None),
            Err(ServiceError::Internal(_))
        ));
        let mut v = Violations::new();
        v.add("x", "is required");
        assert!(matches!(
            v.finish_with(Some(1)),
            Err(ServiceError::InvalidInput(_))
        ));
        assert_eq!(Violations::new().finish_with(Some(1)).unwrap(), 1);
    }
}
