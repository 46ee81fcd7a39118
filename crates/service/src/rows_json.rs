//! JSON for [`Rows`](crate::Rows): nested arrays of numbers (`[[1, 0], [0, 1]]`) read
//! straight into the flat values, one allocation per matrix instead of one
//! per row, and written back as nested arrays.

use std::fmt;

use serde::{
    Deserialize, Deserializer, Serialize, Serializer,
    de::{DeserializeSeed, SeqAccess, Visitor},
    ser::SerializeSeq,
};

use crate::Rows;

impl<'de> Deserialize<'de> for Rows {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(RowsVisitor)
    }
}

struct RowsVisitor;

impl<'de> Visitor<'de> for RowsVisitor {
    type Value = Rows;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a sequence")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Rows, A::Error> {
        // Most matrices of the API are at most 9 × 9.
        let mut rows = Rows::with_capacity(16);
        while seq.next_element_seed(Row(&mut rows))?.is_some() {}
        Ok(rows)
    }
}

/// One row, appended to the matrix being read.
struct Row<'a>(&'a mut Rows);

impl<'de> DeserializeSeed<'de> for Row<'_> {
    type Value = ();

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Row<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a sequence")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut len = 0;
        while let Some(value) = seq.next_element::<f64>()? {
            self.0.push(value);
            len += 1;
        }
        self.0.end_row(len);
        Ok(())
    }
}

impl Serialize for Rows {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.nrows()))?;
        match self.shape() {
            Some((r, 0)) => {
                for _ in 0..r {
                    seq.serialize_element(&[0.0_f64; 0])?;
                }
            }
            Some(_) => {
                for row in self.rows() {
                    seq.serialize_element(row)?;
                }
            }
            // Ragged rows are only ever read, never answered.
            None => {
                return Err(serde::ser::Error::custom(
                    "a ragged matrix cannot be written",
                ));
            }
        }
        seq.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_json_round_trips_through_flat_rows() {
        let m: Rows = serde_json::from_str("[[1, 2.5], [3e2, -4]]").unwrap();
        assert_eq!(m.shape(), Some((2, 2)));
        assert_eq!(m.values(), &[1.0, 2.5, 300.0, -4.0]);
        assert_eq!(
            serde_json::to_string(&m).unwrap(),
            "[[1.0,2.5],[300.0,-4.0]]"
        );
        let ragged: Rows = serde_json::from_str("[[1, 2], [3]]").unwrap();
        assert_eq!(ragged.shape(), None);
        assert!(serde_json::to_string(&ragged).is_err());
        let empty: Rows = serde_json::from_str("[]").unwrap();
        assert_eq!(serde_json::to_string(&empty).unwrap(), "[]");
        let empty_rows: Rows = serde_json::from_str("[[], []]").unwrap();
        assert_eq!(serde_json::to_string(&empty_rows).unwrap(), "[[],[]]");
    }

    #[test]
    fn a_row_that_is_not_an_array_is_a_type_error() {
        for bad in ["[1, 2]", "[[1], 2]", "[[\"a\"]]", "{}"] {
            let err = serde_json::from_str::<Rows>(bad).unwrap_err();
            assert!(err.is_data(), "{bad}: {err}");
        }
    }
}
