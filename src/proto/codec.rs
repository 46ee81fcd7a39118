//! The protobuf codec of our gRPC services: prost's, except that a request
//! whose bytes do not decode is the client's fault (INVALID_ARGUMENT), not the
//! server's (tonic-prost reports INTERNAL), and that a message is decoded
//! from one slice. build.rs points the generated code here with `codec_path`.

use prost::bytes::Buf;
use tonic::{
    Status,
    codec::{Codec, DecodeBuf, Decoder},
};
use tonic_prost::ProstEncoder;

/// tonic-prost's codec, except that a message that does not decode is
/// INVALID_ARGUMENT, and that messages are decoded from one contiguous
/// slice.
#[derive(Debug, Clone)]
pub struct ProtoCodec<T, U>(std::marker::PhantomData<fn(T) -> U>);

impl<T, U> Default for ProtoCodec<T, U> {
    fn default() -> Self {
        Self(std::marker::PhantomData)
    }
}

impl<T, U> Codec for ProtoCodec<T, U>
where
    T: prost::Message + Send + 'static,
    U: prost::Message + Default + Send + 'static,
{
    type Encode = T;
    type Decode = U;
    type Encoder = ProstEncoder<T>;
    type Decoder = ProtoDecoder<U>;

    fn encoder(&mut self) -> Self::Encoder {
        ProstEncoder::default()
    }

    fn decoder(&mut self) -> Self::Decoder {
        ProtoDecoder(std::marker::PhantomData)
    }
}

/// Decodes a `U`, naming a message that does not decode as malformed.
///
/// tonic hands over the message in one buffer; decoded from its slice,
/// prost reads varints and packed numbers without asking a generic buffer
/// for its next chunk at every field: the JPDA 500-target request decodes
/// in 30 % less time (docs/RESULTS.md, "gRPC calls on the lanes").
#[derive(Debug)]
pub struct ProtoDecoder<U>(std::marker::PhantomData<fn() -> U>);

impl<U: prost::Message + Default> Decoder for ProtoDecoder<U> {
    type Item = U;
    type Error = Status;

    fn decode(&mut self, src: &mut DecodeBuf<'_>) -> Result<Option<U>, Status> {
        let len = src.remaining();
        let decoded = if src.chunk().len() == len {
            let decoded = U::decode(src.chunk());
            src.advance(len);
            decoded
        } else {
            U::decode(src)
        };
        decoded.map(Some).map_err(|e| {
            Status::invalid_argument(format!(
                "the message is not valid protobuf for this method: {e}"
            ))
        })
    }
}
