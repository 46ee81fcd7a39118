//! The body of a streaming call (`SessionService/Stream`) with its
//! incomplete message charged to the budget of buffered body bytes
//! (`FUSION_MAX_BUFFERED_BODY_BYTES`), as a unary call's whole message is
//! (`AppState::read_body`). tonic buffers a message until its last byte has
//! come; the bytes of that message are charged as they arrive and given
//! back when it is complete (its batch then takes an in-flight slot, or is
//! shed). A message the budget cannot take ends the stream with
//! UNAVAILABLE naming the budget.
//!
//! The gRPC framing (gRPC over HTTP/2, "Length-Prefixed-Message"): each
//! message is a compressed flag (1 byte), a big-endian u32 length and that
//! many bytes.

use std::{
    pin::Pin,
    task::{Context, Poll, ready},
};

use axum::body::{Body, Bytes};
use hyper::body::{Body as HttpBody, Frame, SizeHint};
use tonic::Status;

use crate::state::{AppState, BodyCharge};

/// Bytes of the prefix of a message.
const PREFIX: usize = 5;

/// `body` with its incomplete message charged to the budget of `state`.
pub(crate) fn budgeted(state: &AppState, body: Body) -> Body {
    Body::new(Budgeted {
        inner: body,
        state: state.clone(),
        prefix: [0; PREFIX],
        prefix_len: 0,
        remaining: 0,
        charge: BodyCharge::default(),
        failed: false,
    })
}

struct Budgeted {
    inner: Body,
    state: AppState,
    /// The prefix of the message being read, `prefix_len` bytes of it so far.
    prefix: [u8; PREFIX],
    prefix_len: usize,
    /// Bytes of the message after its prefix still to come.
    remaining: usize,
    /// What the message read so far holds of the budget.
    charge: BodyCharge,
    failed: bool,
}

impl Budgeted {
    /// Follows the framing through `data`, charging the bytes of messages;
    /// false when the budget cannot take them.
    fn account(&mut self, data: &[u8]) -> bool {
        let mut at = 0;
        while at < data.len() {
            if self.prefix_len < PREFIX {
                let take = (PREFIX - self.prefix_len).min(data.len() - at);
                self.prefix[self.prefix_len..self.prefix_len + take]
                    .copy_from_slice(&data[at..at + take]);
                self.prefix_len += take;
                at += take;
                if self.prefix_len == PREFIX {
                    let len = u32::from_be_bytes(self.prefix[1..].try_into().expect("4 bytes"));
                    self.remaining = len as usize;
                    if self.remaining == 0 {
                        self.prefix_len = 0;
                    }
                }
                continue;
            }
            let take = self.remaining.min(data.len() - at);
            if !self.state.charge_body_bytes(&mut self.charge, take) {
                return false;
            }
            self.remaining -= take;
            at += take;
            if self.remaining == 0 {
                // Complete: tonic decodes it now; its bytes are given back.
                self.charge = BodyCharge::default();
                self.prefix_len = 0;
            }
        }
        true
    }
}

impl HttpBody for Budgeted {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, axum::Error>>> {
        let this = self.get_mut();
        if this.failed {
            return Poll::Ready(None);
        }
        let frame = ready!(Pin::new(&mut this.inner).poll_frame(cx));
        if let Some(Ok(frame)) = &frame
            && let Some(data) = frame.data_ref()
            && !this.account(data)
        {
            this.failed = true;
            this.charge = BodyCharge::default();
            let status = Status::unavailable(format!(
                "the request bodies being read hold the budget of {} buffered bytes \
                 (FUSION_MAX_BUFFERED_BODY_BYTES); retry shortly",
                this.state.settings().max_buffered_body_bytes
            ));
            return Poll::Ready(Some(Err(axum::Error::new(status))));
        }
        Poll::Ready(frame)
    }

    fn is_end_stream(&self) -> bool {
        self.failed || self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}
