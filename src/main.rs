//! The `radar-fusion` binary: parse the configuration, build the application,
//! serve until SIGTERM. Everything else lives in the library.

use clap::Parser;
use radar_fusion::{
    app::{Application, shutdown_signal},
    config::{Cli, Command, CopySessions, HealthcheckTls},
    http, telemetry,
};

/// mimalloc instead of glibc's malloc: a profile of the JPDA 500-target
/// request put a third of the server's time in glibc's malloc, free and
/// consolidation (many small vectors per request, freed across threads);
/// docs/RESULTS.md ("Request path") has the figures before and after.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's `mi_option_purge_delay` (`mi_option_t` in mimalloc.h; the
/// enum keeps its order across versions, retired options stay as
/// `deprecated_` entries).
const MI_OPTION_PURGE_DELAY: std::ffi::c_int = 15;

unsafe extern "C" {
    /// mimalloc's option setter and getter (mimalloc.h), linked with the
    /// allocator by `libmimalloc-sys`.
    fn mi_option_set(option: std::ffi::c_int, value: std::ffi::c_long);
    #[cfg(test)]
    fn mi_option_get(option: std::ffi::c_int) -> std::ffi::c_long;
}

/// Keeps memory the service frees for its later requests instead of giving
/// it back to the kernel a second after (mimalloc's default purge delay):
/// every page given back is zeroed by the kernel again when a later request
/// touches it (a dimension fusion of issue 15's traffic after a pause of
/// 1.5 s: 700–1,200 page faults, against none kept), and the start-up
/// warm-up's pages would be gone before the first request. The process keeps its high-water mark,
/// which the request limits bound. `MIMALLOC_PURGE_DELAY` (milliseconds)
/// still decides when it is set.
fn keep_freed_memory() {
    if std::env::var_os("MIMALLOC_PURGE_DELAY").is_none() {
        // SAFETY: mimalloc's public API, callable at any time.
        unsafe { mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
    }
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    keep_freed_memory();
    let cli = Cli::parse();
    match cli
        .command
        .unwrap_or_else(|| Command::Serve(Box::new(cli.settings)))
    {
        Command::Openapi => print_ignoring_closed_pipe(&http::openapi_json()),
        Command::Healthcheck { addr, tls } => healthcheck(addr, &tls).await,
        Command::Eval { .. } => eval_moved(),
        Command::CopySessions(copy) => copy_sessions(*copy).await,
        Command::Serve(settings) => {
            telemetry::init_logging(&settings.log, settings.log_format);
            let app = Application::build(*settings).await?;
            app.run_until(shutdown_signal()).await
        }
    }
}

/// `radar-fusion copy-sessions --from URL`: every session of `--from` into
/// the settings' store (docs/operations.md, "Moving sessions to a Cluster").
async fn copy_sessions(copy: CopySessions) -> anyhow::Result<()> {
    use anyhow::Context;
    let to = copy.settings.store_settings();
    let from = store::StoreSettings {
        url: copy.from,
        ..to.clone()
    };
    let from = store::SessionStore::connect(&from)
        .await
        .context("the store to copy from (--from)")?;
    let to = store::SessionStore::connect(&to)
        .await
        .context("the store to copy into (FUSION_SESSION_STORE)")?;
    let copied = from.copy_sessions_to(&to).await?;
    println!(
        "copied {} sessions; {} were in the target already",
        copied.sessions, copied.skipped
    );
    Ok(())
}

/// `radar-fusion eval` moved to its own binary: say where, exit 2.
fn eval_moved() -> anyhow::Result<()> {
    eprintln!(
        "`radar-fusion eval` moved to its own binary: run `radar-fusion-eval --list` \
         (from a checkout: `cargo run -p eval --release -- --list`)"
    );
    std::process::exit(2)
}

/// Writes `text` to standard output; a reader that stops early (`| head`)
/// ends the output quietly instead of a broken-pipe panic.
fn print_ignoring_closed_pipe(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

/// GET /healthz over an HTTP/1.0 connection (TLS with `--tls-ca`); fails
/// unless the status is 200. Every error names the address probed.
async fn healthcheck(addr: std::net::SocketAddr, tls: &HealthcheckTls) -> anyhow::Result<()> {
    use anyhow::Context;
    let scheme = if tls.ca.is_some() { "https" } else { "http" };
    healthcheck_once(addr, tls)
        .await
        .with_context(|| format!("healthcheck of {scheme}://{addr}/healthz"))
}

async fn healthcheck_once(addr: std::net::SocketAddr, tls: &HealthcheckTls) -> anyhow::Result<()> {
    use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
    async fn probe<S: AsyncRead + AsyncWrite + Unpin>(mut stream: S) -> anyhow::Result<String> {
        stream
            .write_all(b"GET /healthz HTTP/1.0\r\nHost: localhost\r\n\r\n")
            .await?;
        let mut head = vec![0u8; 64];
        let n = stream.read(&mut head).await?;
        Ok(String::from_utf8_lossy(&head[..n]).into_owned())
    }
    // The TLS files are read before the clock starts.
    let connector = match &tls.ca {
        None => None,
        Some(ca) => {
            let client = tls.client_cert.as_deref().zip(tls.client_key.as_deref());
            let config = radar_fusion::tls::client_config(ca, client, &[b"http/1.1"])
                .map_err(anyhow::Error::msg)?;
            let name =
                radar_fusion::tls::server_name(&tls.server_name).map_err(anyhow::Error::msg)?;
            Some((
                tokio_rustls::TlsConnector::from(std::sync::Arc::new(config)),
                name,
            ))
        }
    };
    let exchange = async {
        let tcp = tokio::net::TcpStream::connect(addr).await?;
        match connector {
            None => probe(tcp).await,
            Some((connector, name)) => probe(connector.connect(name, tcp).await?).await,
        }
    };
    let head = tokio::time::timeout(std::time::Duration::from_secs(3), exchange)
        .await
        .map_err(|_| anyhow::anyhow!("no answer within 3 s"))??;
    anyhow::ensure!(
        head.starts_with("HTTP/1.0 200") || head.starts_with("HTTP/1.1 200"),
        "unhealthy: {}",
        head.lines().next().unwrap_or("")
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_purge_delay_option_is_mimallocs_and_is_switched_off() {
        // mimalloc 3's default purge delay is 1000 ms (options.c), a value
        // no neighbouring option has: the index names that option.
        if std::env::var_os("MIMALLOC_PURGE_DELAY").is_some() {
            return;
        }
        // SAFETY: mimalloc's public API.
        assert_eq!(unsafe { mi_option_get(MI_OPTION_PURGE_DELAY) }, 1000);
        keep_freed_memory();
        // SAFETY: as above.
        assert_eq!(unsafe { mi_option_get(MI_OPTION_PURGE_DELAY) }, -1);
    }
}
