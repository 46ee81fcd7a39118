//! `GET /view/`: the air-picture page, one self-contained HTML document
//! (its CSS and JavaScript inline, no CDN, no map tiles: it works offline)
//! embedded in the binary. It lists the tenant's sessions and draws the
//! chosen one live from `GET /v1/sessions/{id}/events`, read with `fetch`
//! streaming so that it can send the API key (`EventSource` cannot send
//! headers). The page itself is public, like `/docs`: it holds no data, and
//! every call it makes is authenticated.

use axum::{
    http::{HeaderValue, header},
    response::{IntoResponse, Redirect, Response},
};

/// The page (`src/http/view/index.html`).
pub const PAGE: &str = include_str!("view/index.html");

pub async fn page() -> Response {
    let mut response = ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE).into_response();
    let headers = response.headers_mut();
    // Everything the page needs is in it; it talks only to this origin.
    headers.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; \
             connect-src 'self'; img-src 'self' data:; base-uri 'none'; form-action 'none'",
        ),
    );
    headers.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    headers.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    response
}

pub async fn redirect() -> Redirect {
    Redirect::permanent("/view/")
}
