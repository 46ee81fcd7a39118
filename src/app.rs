//! Start-up: loads the TLS files (when configured), binds both listeners,
//! builds the shared state and the routers, serves until a shutdown signal,
//! then drains in-flight requests.

use std::{future::Future, net::SocketAddr, sync::Arc, time::Duration};

use anyhow::Context;
use tokio::{net::TcpListener, sync::watch};
use tonic_health::{ServingStatus, server::HealthReporter};

use crate::{
    auth::ApiKeys,
    config::Settings,
    grpc, http, serve,
    state::{AppState, Readiness, StoreHealth},
    telemetry,
    tls::{Port, Tls, TlsPort},
};
use store::SessionStore;

/// How often the gRPC health status is recomputed from readiness (session store ping).
const HEALTH_CHECK_EVERY: Duration = Duration::from_secs(1);

/// A built application whose listeners are bound (port 0 resolves here, so
/// tests learn the real ports before serving starts).
pub struct Application {
    http_listener: TcpListener,
    grpc_listener: TcpListener,
    state: AppState,
    rest: axum::Router,
    grpc: axum::Router,
    health: HealthReporter,
    tls: Option<Arc<Tls>>,
}

impl Application {
    pub async fn build(settings: Settings) -> anyhow::Result<Self> {
        settings.validate().map_err(anyhow::Error::msg)?;
        let api_keys = ApiKeys::from_settings(&settings).map_err(anyhow::Error::msg)?;
        if api_keys.is_open() {
            tracing::warn!(
                "no API keys configured: the service is open, every request acts as tenant `default`"
            );
        } else {
            tracing::info!(
                tenants = api_keys.tenant_count(),
                "API keys configured: requests must authenticate"
            );
        }
        // Before binding: a bad certificate or key refuses to start, naming the file.
        let tls = Tls::from_settings(&settings).map_err(anyhow::Error::msg)?;
        match &tls {
            Some(tls) => tracing::info!("{}", tls.describe()),
            None => tracing::info!("TLS off: both ports speak plaintext"),
        }
        let http_listener = TcpListener::bind(settings.http_addr)
            .await
            .with_context(|| format!("binding the REST address {}", settings.http_addr))?;
        let grpc_listener = TcpListener::bind(settings.grpc_addr)
            .await
            .with_context(|| format!("binding the gRPC address {}", settings.grpc_addr))?;
        let store = SessionStore::connect(&settings.store_settings())
            .await
            .context("building the session store")?;
        tracing::info!(backend = store.backend(), "session store");
        let state = AppState::new(settings, api_keys, telemetry::metrics_handle(), store);
        let grpc::GrpcServices {
            router: grpc,
            health,
        } = grpc::services(&state).context("building gRPC reflection")?;
        let rest = http::router(state.clone(), grpc.clone());
        Ok(Self {
            http_listener,
            grpc_listener,
            state,
            rest,
            grpc,
            health,
            tls,
        })
    }

    pub fn http_addr(&self) -> SocketAddr {
        self.http_listener
            .local_addr()
            .expect("a bound listener has an address")
    }

    pub fn grpc_addr(&self) -> SocketAddr {
        self.grpc_listener
            .local_addr()
            .expect("a bound listener has an address")
    }

    pub fn state(&self) -> AppState {
        self.state.clone()
    }

    /// The TLS configuration of both ports, when TLS is on.
    pub fn tls(&self) -> Option<Arc<Tls>> {
        self.tls.clone()
    }

    /// Serves both ports until `shutdown` completes, then stops accepting,
    /// reports not ready, and waits (at most the grace period) for the
    /// requests in flight to finish.
    pub async fn run_until<F>(self, shutdown: F) -> anyhow::Result<()>
    where
        F: Future<Output = ()> + Send + 'static,
    {
        let Self {
            http_listener,
            grpc_listener,
            state,
            rest,
            grpc,
            health,
            tls,
        } = self;
        // The first health status is set before readiness is reported, so a
        // probe that sees ready also sees the matching gRPC status.
        let store_ok = match state.store().ping().await {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(
                    error = %e,
                    "session store unavailable at start: sessions degraded, everything else serving"
                );
                false
            }
        };
        // Bound (and its session created) before readiness is reported.
        let asterix_udp =
            crate::asterix_udp::spawn(&state, crate::http::sessions::plot_fusion_spec_from_json)
                .await?;
        // Reloads (and the SIGHUP handler) from before readiness.
        let tls_watcher = tls.as_ref().map(Tls::spawn_watcher);
        // What the first requests would pay once, paid before ready.
        let (lanes, took) = crate::http::warm_up(state.settings().warm_up_mib).await;
        tracing::info!(
            lanes,
            ms = took.as_secs_f64() * 1e3,
            "compute lanes warmed up"
        );
        set_health(&health, true, store_ok).await;
        state.set_ready(true);
        let monitor = tokio::spawn(follow_readiness(state.clone(), health.clone(), store_ok));
        tracing::info!(
            http = %http_listener.local_addr()?,
            grpc = %grpc_listener.local_addr()?,
            "serving REST (and gRPC) on http, gRPC on grpc"
        );

        let (stop_tx, stop_rx) = watch::channel(false);
        let stopped = |mut rx: watch::Receiver<bool>| async move {
            let _ = rx.wait_for(|stop| *stop).await;
        };
        let limits = serve::ConnectionLimits::from_settings(state.settings());
        let access_log = state.settings().access_log;
        let http_server = tokio::spawn(serve::serve(
            http_listener,
            rest,
            limits,
            "http",
            tls.clone().map(|t| TlsPort::new(t, Port::Http)),
            stopped(stop_rx.clone()),
        ));
        let grpc_server = tokio::spawn(serve::serve(
            grpc_listener,
            telemetry::with_request_tracing(grpc, access_log),
            limits,
            "grpc",
            tls.map(|t| TlsPort::new(t, Port::Grpc)),
            stopped(stop_rx),
        ));

        shutdown.await;
        tracing::info!("shutdown requested: draining in-flight requests");
        state.set_ready(false);
        monitor.abort();
        let _ = monitor.await;
        if let Some(listener) = asterix_udp {
            listener.abort();
        }
        if let Some(watcher) = tls_watcher {
            watcher.abort();
        }
        set_health(&health, false, false).await;
        // Watches end with an `end` event of reason `shutdown` instead of
        // holding their connections open through the drain.
        state.sessions().events().close();
        let _ = stop_tx.send(true);

        let grace = state.settings().shutdown_grace();
        let drained = tokio::time::timeout(grace, async {
            let (h, g) = tokio::join!(http_server, grpc_server);
            h.context("REST server task")?;
            g.context("gRPC server task")?;
            anyhow::Ok(())
        })
        .await;
        match drained {
            Ok(result) => result.context("serving")?,
            Err(_) => tracing::warn!(
                grace_s = grace.as_secs_f64(),
                "grace period over: closing remaining connections"
            ),
        }
        tracing::info!("stopped");
        Ok(())
    }
}

/// The gRPC health statuses: the server ("") and the stateless services
/// follow readiness; `SessionService` also needs the session store.
async fn set_health(health: &HealthReporter, ready: bool, store_ok: bool) {
    health.set_service_status("", serving_status(ready)).await;
    for name in grpc::SERVICE_NAMES {
        let serving = ready && (store_ok || *name != grpc::SESSION_SERVICE);
        health
            .set_service_status(*name, serving_status(serving))
            .await;
    }
}

/// Keeps the gRPC health statuses in step with readiness (started, not
/// draining) and the session store's health, checked every
/// [`HEALTH_CHECK_EVERY`]; runs until aborted.
async fn follow_readiness(state: AppState, health: HealthReporter, mut store_reported: bool) {
    let mut ready_reported = true;
    loop {
        tokio::time::sleep(HEALTH_CHECK_EVERY).await;
        let (ready, store_ok) = match state.check_ready().await {
            Readiness::Ready { store } => (true, store == StoreHealth::Ok),
            Readiness::NotReady(_) => (false, store_reported),
        };
        if ready != ready_reported || store_ok != store_reported {
            set_health(&health, ready, store_ok).await;
            if store_ok != store_reported {
                if store_ok {
                    tracing::info!("session store reachable again: sessions serving");
                } else {
                    tracing::warn!(
                        "session store unavailable: sessions degraded, everything else serving"
                    );
                }
            }
            (ready_reported, store_reported) = (ready, store_ok);
        }
    }
}

fn serving_status(serving: bool) -> ServingStatus {
    if serving {
        ServingStatus::Serving
    } else {
        ServingStatus::NotServing
    }
}

/// Completes on Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(e) => {
                tracing::warn!(error = %e, "cannot listen for SIGTERM");
                std::future::pending::<()>().await;
            }
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = terminate => {},
    }
}
