//! `GET /view/`: the air-picture page, an HTML document with its script
//! and its stylesheet beside it (`GET /view/view.js`, `GET /view/view.css`), all embedded in
//! the binary (no CDN, no map tiles: it works offline). It lists the tenant's sessions and draws the
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
/// Its script (`src/http/view/view.js`), a file of its own so that the
/// page's Content-Security-Policy allows no inline script.
pub const SCRIPT: &str = include_str!("view/view.js");
/// Its stylesheet (`src/http/view/view.css`), a file of its own so that the
/// page's Content-Security-Policy allows no inline style either.
pub const STYLE: &str = include_str!("view/view.css");

/// The page's Content-Security-Policy: scripts and styles only from this
/// origin's files (none inline, so an injected `<script>`, `on…` or `style`
/// attribute does nothing), calls only to this origin, and no framing by
/// any page.
pub const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; \
     connect-src 'self'; img-src 'self' data:; base-uri 'none'; form-action 'none'; \
     frame-ancestors 'none'";

pub async fn page() -> Response {
    served("text/html; charset=utf-8", PAGE)
}

pub async fn script() -> Response {
    served("text/javascript; charset=utf-8", SCRIPT)
}

pub async fn style() -> Response {
    served("text/css; charset=utf-8", STYLE)
}

fn served(content_type: &'static str, body: &'static str) -> Response {
    let mut response = ([(header::CONTENT_TYPE, content_type)], body).into_response();
    let headers = response.headers_mut();
    headers.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    headers.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
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
