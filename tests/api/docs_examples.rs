//! The request examples of the README and of `docs/` are posted to the real
//! server: every `curl … localhost:8080/<path> … -d '<json>'` whose body is
//! complete JSON must answer 2xx (a session's batch goes to the session the
//! page's create example made). A body that elides part of itself (`…`)
//! is shown for its shape and is not runnable; anything else that is not
//! JSON is a broken example and fails the test.

use super::helpers::spawn_app;

/// The documents with request examples, by path from the repository root.
const DOCS: [(&str, &str); 9] = [
    ("README.md", include_str!("../../README.md")),
    (
        "docs/correlation.md",
        include_str!("../../docs/correlation.md"),
    ),
    ("docs/jpda.md", include_str!("../../docs/jpda.md")),
    (
        "docs/plot-fusion.md",
        include_str!("../../docs/plot-fusion.md"),
    ),
    ("docs/dimension.md", include_str!("../../docs/dimension.md")),
    ("docs/ais-radar.md", include_str!("../../docs/ais-radar.md")),
    ("docs/sessions.md", include_str!("../../docs/sessions.md")),
    (
        "docs/operations.md",
        include_str!("../../docs/operations.md"),
    ),
    (
        "docs/development.md",
        include_str!("../../docs/development.md"),
    ),
];

/// (path, body) of every curl call with an inline body, in page order.
fn curl_examples(doc: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut rest = doc;
    while let Some(at) = rest.find("curl -s") {
        rest = &rest[at + 7..];
        let Some(host) = rest.find("localhost:8080") else {
            break;
        };
        let after = &rest[host + "localhost:8080".len()..];
        let path: String = after
            .chars()
            .take_while(|c| !c.is_whitespace() && *c != '\\')
            .collect();
        // The body belongs to this call only if no other curl starts first.
        let next_curl = after.find("curl -s").unwrap_or(after.len());
        let Some(d) = after[..next_curl].find("-d '") else {
            continue;
        };
        // The body is single-quoted; `'"$(base64 -w0 FILE)"'` inside it
        // splices in the base64 of a repository file, as a shell would.
        let mut body = String::new();
        let mut tail = &after[d + 4..];
        loop {
            let Some(end) = tail.find('\'') else {
                return out;
            };
            body.push_str(&tail[..end]);
            tail = &tail[end + 1..];
            const SPLICE: &str = "\"$(base64 -w0 ";
            let Some(spliced) = tail.strip_prefix(SPLICE) else {
                break;
            };
            let close = spliced.find(")\"'").expect("closed splice");
            let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(&spliced[..close]);
            let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            use base64::Engine as _;
            body.push_str(&base64::engine::general_purpose::STANDARD.encode(bytes));
            tail = &spliced[close + 3..];
        }
        out.push((path, body));
        rest = tail;
    }
    out
}

#[tokio::test]
async fn every_complete_example_in_the_docs_runs() {
    let app = spawn_app().await;
    let mut ran = 0;
    for (name, doc) in DOCS {
        // The session of the last create example; `None` after an elided
        // create, whose batches cannot run either.
        let mut session: Option<Option<String>> = None;
        for (path, body) in curl_examples(doc) {
            if serde_json::from_str::<serde_json::Value>(&body).is_err() {
                assert!(
                    body.contains('…'),
                    "{name}: the example for {path} is neither JSON nor marked elided (…): {body}"
                );
                if path == "/v1/sessions" {
                    session = Some(None);
                }
                continue;
            }
            let path = match (&session, path.contains("<id>")) {
                (Some(Some(id)), true) => path.replace("<id>", id),
                (Some(None), true) => continue,
                (None, true) => panic!("{name}: {path} comes before a session was created"),
                (_, false) => path,
            };
            let response = app.post_raw(&path, &body).await;
            let status = response.status();
            let text = response.text().await.unwrap();
            assert!(
                status.is_success(),
                "{name}: POST {path} gave {status}: {text}"
            );
            if path == "/v1/sessions" {
                let v: serde_json::Value = serde_json::from_str(&text).unwrap();
                let id = v["id"].as_str().map(str::to_string);
                assert!(id.is_some(), "{name}: no id in {text}");
                session = Some(id);
            }
            ran += 1;
        }
    }
    // The pages hold 10 runnable examples today (README 1, correlation 3,
    // jpda 1, plot fusion 1 (ASTERIX), ais-radar 1, sessions 2, operations 1); fewer means the
    // extraction broke or an example lost its body, not better docs.
    assert!(ran >= 10, "only {ran} examples ran");
}
