//! `radar.fusion.v1.Matrix`, written by hand instead of generated (build.rs
//! maps it here with `extern_path`): prost decodes a packed `repeated double`
//! one value at a time into a `Vec` that grows as it goes, which made the
//! covariances most of the decoding time of a large JPDA request. This
//! decoder reserves the values once and copies them a chunk at a time. The
//! wire format is the generated one's, checked against it in the tests.

use prost::{
    DecodeError, Message,
    bytes::{Buf, BufMut},
    encoding::{DecodeContext, WireType, decode_varint, double, skip_field, uint32},
};

/// A dense matrix in row-major order.
#[derive(Clone, PartialEq, Default, Debug)]
pub struct Matrix {
    pub rows: u32,
    pub cols: u32,
    pub values: Vec<f64>,
}

impl Message for Matrix {
    fn encode_raw(&self, buf: &mut impl BufMut) {
        if self.rows != 0 {
            uint32::encode(1, &self.rows, buf);
        }
        if self.cols != 0 {
            uint32::encode(2, &self.cols, buf);
        }
        double::encode_packed(3, &self.values, buf);
    }

    fn merge_field(
        &mut self,
        tag: u32,
        wire_type: WireType,
        buf: &mut impl Buf,
        ctx: DecodeContext,
    ) -> Result<(), DecodeError> {
        let named = |field| {
            move |mut e: DecodeError| {
                e.push("Matrix", field);
                e
            }
        };
        match tag {
            1 => uint32::merge(wire_type, &mut self.rows, buf, ctx).map_err(named("rows")),
            2 => uint32::merge(wire_type, &mut self.cols, buf, ctx).map_err(named("cols")),
            3 if wire_type == WireType::LengthDelimited => {
                merge_packed(&mut self.values, buf, ctx).map_err(named("values"))
            }
            // An unpacked encoding (one value per key) is valid protobuf too.
            3 => double::merge_repeated(wire_type, &mut self.values, buf, ctx)
                .map_err(named("values")),
            _ => skip_field(wire_type, tag, buf, ctx),
        }
    }

    fn encoded_len(&self) -> usize {
        let rows = if self.rows != 0 {
            uint32::encoded_len(1, &self.rows)
        } else {
            0
        };
        let cols = if self.cols != 0 {
            uint32::encoded_len(2, &self.cols)
        } else {
            0
        };
        rows + cols + double::encoded_len_packed(3, &self.values)
    }

    fn clear(&mut self) {
        *self = Self::default();
    }
}

/// Appends a packed run of little-endian doubles (after its key). A run
/// whose length does not fit the buffer or is not whole doubles, or whose
/// length prefix is split across buffer chunks, goes to prost's own decoder,
/// which reports the error (or decodes the rare split).
fn merge_packed(
    values: &mut Vec<f64>,
    buf: &mut impl Buf,
    ctx: DecodeContext,
) -> Result<(), DecodeError> {
    let mut peek = buf.chunk();
    let available = peek.len();
    let fast = match decode_varint(&mut peek) {
        Ok(len) => {
            let header = available - peek.len();
            let fits = len <= (buf.remaining() - header) as u64;
            (fits && len % 8 == 0).then_some((header, len as usize))
        }
        Err(_) => None,
    };
    let Some((header, len)) = fast else {
        return double::merge_repeated(WireType::LengthDelimited, values, buf, ctx);
    };
    buf.advance(header);
    values.reserve(len / 8);
    let mut left = len;
    while left > 0 {
        let chunk = buf.chunk();
        let whole = chunk.len().min(left) / 8 * 8;
        if whole == 0 {
            // A value split across two chunks of the buffer.
            values.push(buf.get_f64_le());
            left -= 8;
            continue;
        }
        values.extend(
            chunk[..whole]
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes"))),
        );
        buf.advance(whole);
        left -= whole;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use prost::bytes::Bytes;

    use super::*;

    /// The generated code's Matrix, for comparison of the wire format.
    #[derive(Clone, PartialEq, ::prost::Message)]
    struct Generated {
        #[prost(uint32, tag = "1")]
        rows: u32,
        #[prost(uint32, tag = "2")]
        cols: u32,
        #[prost(double, repeated, tag = "3")]
        values: Vec<f64>,
    }

    fn cases() -> Vec<(u32, u32, Vec<f64>)> {
        vec![
            (0, 0, vec![]),
            (1, 1, vec![1.5]),
            (2, 2, vec![1.0, -0.0, f64::MIN_POSITIVE, 1e300]),
            (3, 5, (0..15).map(|i| f64::from(i) * 0.1 - 0.7).collect()),
            (
                40,
                40,
                (0..1600).map(|i| (f64::from(i) * 1.37).sin()).collect(),
            ),
        ]
    }

    #[test]
    fn encodes_and_decodes_as_the_generated_message() {
        for (rows, cols, values) in cases() {
            let ours = Matrix {
                rows,
                cols,
                values: values.clone(),
            };
            let theirs = Generated { rows, cols, values };
            assert_eq!(ours.encode_to_vec(), theirs.encode_to_vec());
            assert_eq!(ours.encoded_len(), theirs.encoded_len());
            let back = Matrix::decode(theirs.encode_to_vec().as_slice()).unwrap();
            assert_eq!(back, ours);
        }
    }

    #[test]
    fn decodes_values_split_across_buffer_chunks() {
        let m = Matrix {
            rows: 4,
            cols: 4,
            values: (0..16).map(|i| f64::from(i) + 0.25).collect(),
        };
        let bytes = m.encode_to_vec();
        // Every split point, including inside the key, the length and a value.
        for cut in 0..bytes.len() {
            let mut buf =
                Bytes::copy_from_slice(&bytes[..cut]).chain(Bytes::copy_from_slice(&bytes[cut..]));
            assert_eq!(Matrix::decode(&mut buf).unwrap(), m, "cut at {cut}");
        }
    }

    #[test]
    fn unpacked_values_and_unknown_fields_decode_as_prost_does() {
        // values = 3 unpacked: key (3 << 3 | 1) then 8 bytes, twice; an
        // unknown varint field 9 = 7 in between.
        let mut bytes = vec![0x19];
        bytes.extend(2.5f64.to_le_bytes());
        bytes.extend([0x48, 0x07]);
        bytes.push(0x19);
        bytes.extend((-1.0f64).to_le_bytes());
        let ours = Matrix::decode(bytes.as_slice()).unwrap();
        let theirs = Generated::decode(bytes.as_slice()).unwrap();
        assert_eq!(ours.values, theirs.values);
        assert_eq!(ours.values, vec![2.5, -1.0]);
    }

    #[test]
    fn truncated_or_misaligned_packed_values_are_errors() {
        let m = Matrix {
            rows: 1,
            cols: 2,
            values: vec![1.0, 2.0],
        };
        let bytes = m.encode_to_vec();
        // rows (2 bytes), cols (2 bytes), then values' key at offset 4: a cut
        // after its key, inside its length or its doubles, is an error.
        assert_eq!(bytes[4], 0x1a);
        for cut in 5..bytes.len() {
            assert!(Matrix::decode(&bytes[..cut]).is_err(), "cut at {cut}");
            assert!(Generated::decode(&bytes[..cut]).is_err());
        }
        // A packed run of 7 bytes.
        let mut odd = vec![0x1a, 7];
        odd.extend([0u8; 7]);
        assert!(Matrix::decode(odd.as_slice()).is_err());
        assert!(Generated::decode(odd.as_slice()).is_err());
    }
}
