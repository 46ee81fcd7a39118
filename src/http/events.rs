//! `GET /v1/sessions/{id}/events`: a session's updates as Server-Sent Events.
//!
//! Events (`event:` names; `id:` is the session's version after it):
//! - `snapshot`: the whole session, as `GET /v1/sessions/{id}` answers. The
//!   first event, unless `Last-Event-ID` resumed the stream; again whenever a
//!   gap in the versions had to be filled from the store.
//! - `update`: one batch update, as the push answered it (plot-fusion updates
//!   also carry `plots`, where the batch's plots are), in version order.
//! - `end`: the last event, `{"reason", "message", "version"}`: `deleted`,
//!   `expired`, `slow` (the watcher fell behind) or `shutdown`.
//!
//! A comment line (`: heartbeat`) is sent after each quiet interval.

use std::convert::Infallible;

use axum::{
    Extension,
    extract::{Path, State},
    http::{HeaderMap, HeaderValue},
    response::{
        IntoResponse, Response,
        sse::{Event, Sse},
    },
};
use serde::Serialize;
use tokio::sync::mpsc;
use tokio_stream::wrappers::ReceiverStream;
use utoipa::ToSchema;

use super::{
    problem::Problem,
    sessions::{BatchUpdate, plot_update_out, update_out, view_out},
};
use crate::{auth::Tenant, state::AppState};
use service::{
    Violations,
    session::{
        events::{SessionEvent, WatchItem},
        registry::EventBody,
    },
};

/// The data of an `end` event.
#[derive(Debug, Serialize, ToSchema)]
pub struct WatchEnd {
    /// `deleted`, `expired`, `slow` or `shutdown`.
    #[schema(example = "deleted")]
    pub reason: &'static str,
    pub message: String,
    /// The version of the last event before it.
    pub version: u64,
}

/// One event of the stream, as the OpenAPI document describes it (the
/// `itemSchema` of `text/event-stream`, OpenAPI 3.2's form for a sequence of
/// items): `event` names it, `id` is the session's version after it and
/// `data` is JSON whose shape the event name fixes. Only the schema is
/// used; the events themselves are written by [`json_event`].
pub struct SessionStreamEvent;

impl SessionStreamEvent {
    /// The events: their names, their `data`'s schema, and what each is.
    const EVENTS: [(&'static str, &'static str, &'static str); 3] = [
        (
            "snapshot",
            "SessionState",
            "The whole session, as `GET /v1/sessions/{id}` answers: first (unless \
             `Last-Event-ID` resumed the stream), and again whenever a gap in the versions \
             had to be filled from the store",
        ),
        (
            "update",
            "BatchUpdate",
            "One batch update, as the push answered it (plot-fusion updates also carry \
             `plots`), in version order",
        ),
        (
            "end",
            "WatchEnd",
            "The last event: the session was deleted or expired, the watcher fell behind \
             (`slow`) or the server shuts down",
        ),
    ];
}

impl utoipa::PartialSchema for SessionStreamEvent {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::{ObjectBuilder, OneOfBuilder, Ref, Type};
        let mut one_of = OneOfBuilder::new();
        for (name, data, description) in Self::EVENTS {
            one_of = one_of.item(
                ObjectBuilder::new()
                    .title(Some(name))
                    .description(Some(description))
                    .property(
                        "event",
                        ObjectBuilder::new()
                            .schema_type(Type::String)
                            .enum_values(Some([name])),
                    )
                    .required("event")
                    .property(
                        "id",
                        ObjectBuilder::new()
                            .schema_type(Type::String)
                            .pattern(Some("^[0-9]+$"))
                            .description(Some(
                                "The session's version after the event (resume with \
                                 `Last-Event-ID`)",
                            )),
                    )
                    .required("id")
                    .property(
                        "data",
                        ObjectBuilder::new()
                            .schema_type(Type::String)
                            .content_media_type("application/json")
                            .content_schema(Some(Ref::from_schema_name(data))),
                    )
                    .required("data"),
            );
        }
        utoipa::openapi::RefOr::T(utoipa::openapi::schema::Schema::OneOf(one_of.build()))
    }
}

impl ToSchema for SessionStreamEvent {
    fn schemas(
        schemas: &mut Vec<(
            String,
            utoipa::openapi::RefOr<utoipa::openapi::schema::Schema>,
        )>,
    ) {
        use utoipa::PartialSchema;
        schemas.push((WatchEnd::name().into(), WatchEnd::schema()));
        schemas.push((BatchUpdate::name().into(), BatchUpdate::schema()));
        <BatchUpdate as ToSchema>::schemas(schemas);
        schemas.push((
            super::sessions::SessionState::name().into(),
            super::sessions::SessionState::schema(),
        ));
        <super::sessions::SessionState as ToSchema>::schemas(schemas);
    }
}

/// The REST form of an update event.
pub fn update_dto(e: &SessionEvent) -> Option<BatchUpdate> {
    match &e.body {
        EventBody::Correlation(u) => Some(update_out(u.clone())),
        EventBody::PlotFusion { update, plots } => {
            let mut out = plot_update_out(update.clone());
            if let Some(pf) = out.plot_fusion.as_mut() {
                pf.plots = Some(
                    plots
                        .iter()
                        .map(|p| super::sessions::PlotPosition {
                            radar: p.radar,
                            t: p.t,
                            position_m: p.position,
                        })
                        .collect(),
                );
            }
            Some(out)
        }
        EventBody::Deleted => None,
    }
}

fn json_event(name: &str, id: u64, data: &impl Serialize) -> Event {
    match Event::default()
        .event(name)
        .id(id.to_string())
        .json_data(data)
    {
        Ok(e) => e,
        // Serialising our own DTOs does not fail; say so if it ever does.
        Err(e) => Event::default().comment(format!("event not serialised: {e}")),
    }
}

/// The version `Last-Event-ID` names; a value that is not one is a 422
/// naming the header.
fn last_event_id(headers: &HeaderMap) -> Result<Option<u64>, Problem> {
    let Some(value) = headers.get("last-event-id") else {
        return Ok(None);
    };
    let text = value.to_str().unwrap_or("").trim();
    if text.is_empty() {
        return Ok(None);
    }
    text.parse::<u64>().map(Some).map_err(|_| {
        Violations::single(
            "Last-Event-ID",
            format!("must be a session version (an event's id), got {text:?}"),
        )
        .into()
    })
}

/// Follows a session: its updates as Server-Sent Events.
#[utoipa::path(get, path = "/v1/sessions/{id}/events", tag = "sessions",
    params(
        ("id" = String, Path, description = "Session id"),
        ("Last-Event-ID" = Option<u64>, Header, description = "Resume after this version: the events after it when this replica still holds them, else a fresh snapshot"),
    ),
    responses(
        (status = 200, description = "`text/event-stream`: `snapshot` (a SessionState), `update` (a BatchUpdate, version order) and a last `end` (a WatchEnd) events, `id` the session's version; `: heartbeat` comments on a quiet session", content_type = "text/event-stream", item_schema = SessionStreamEvent),
        (status = 404, description = "No such session for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Last-Event-ID is not a version", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many watchers of the session or of the tenant on this replica", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Session store unreachable", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn events(
    State(state): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, Problem> {
    let after = last_event_id(&headers)?;
    let watch = state.sessions().watch(&tenant.0, &id, after).await?;
    let heartbeat = watch.heartbeat();
    let (tx, rx) = mpsc::channel::<Result<Event, Infallible>>(1);
    tokio::spawn(watch.forward(tx, move |item, _| {
        Some(Ok(match item {
            WatchItem::Snapshot(view) => {
                let dto = view_out(*view);
                json_event("snapshot", dto.version, &dto)
            }
            WatchItem::Update(e) => {
                let dto = update_dto(&e)?;
                json_event("update", e.version, &dto)
            }
            WatchItem::Heartbeat => Event::default().comment("heartbeat"),
            WatchItem::End { reason, version } => json_event(
                "end",
                version,
                &WatchEnd {
                    reason: reason.name(),
                    message: reason.message(heartbeat),
                    version,
                },
            ),
        }))
    }));
    let mut response = Sse::new(ReceiverStream::new(rx)).into_response();
    // Proxies (nginx) must not buffer the stream.
    response
        .headers_mut()
        .insert("x-accel-buffering", HeaderValue::from_static("no"));
    Ok(response)
}
