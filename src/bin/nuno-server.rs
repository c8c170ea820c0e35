//! `nuno-server`: serves the models in a directory over HTTP (see `nuno::server`).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use clap::builder::RangedU64ValueParser;
use nuno::infer::Kernel;
use nuno::server::{AppState, Limits, ServerConfig, openapi_json, serve, serve_grpc};

#[derive(Debug, Parser)]
#[command(name = "nuno-server", version, about)]
struct Args {
    /// Directory whose subdirectories are model artifacts (model.json, dynamics.safetensors, policy.*).
    #[arg(long, default_value = "models")]
    models: PathBuf,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8080", env = "NUNO_ADDR")]
    addr: SocketAddr,
    /// Also serve the Open Inference Protocol over gRPC here (`inference.GRPCInferenceService`).
    #[arg(long, env = "NUNO_GRPC_ADDR")]
    grpc_addr: Option<SocketAddr>,
    /// Bearer token required on every route except health (gRPC: `authorization` metadata).
    #[arg(long, env = "NUNO_TOKEN", hide_env_values = true)]
    token: Option<String>,
    #[arg(long, default_value_t = Limits::default().max_batch, value_parser = at_least_one())]
    max_batch: usize,
    #[arg(long, default_value_t = Limits::default().max_particles, value_parser = at_least_one())]
    max_particles: usize,
    #[arg(long, default_value_t = Limits::default().max_horizon, value_parser = at_least_one())]
    max_horizon: usize,
    #[arg(long, default_value_t = Limits::default().max_rollout_steps, value_parser = at_least_one())]
    max_rollout_steps: usize,
    #[arg(long, default_value_t = Limits::default().max_episodes, value_parser = at_least_one())]
    max_episodes: usize,
    #[arg(long, default_value_t = Limits::default().max_body_bytes, value_parser = at_least_one())]
    max_body_bytes: usize,
    /// Largest answer in bytes (4 a number in binary, 16 as JSON), checked before any work.
    #[arg(long, default_value_t = Limits::default().max_answer_bytes, value_parser = at_least_one())]
    max_answer_bytes: usize,
    /// Seconds before a request is answered with a timeout error.
    #[arg(long, default_value_t = Limits::default().request_timeout_s, value_parser = clap::value_parser!(u64).range(1..))]
    request_timeout: u64,
    /// Requests handled at once.
    #[arg(long, default_value_t = Limits::default().concurrency, value_parser = at_least_one())]
    concurrency: usize,
    /// Model computations at once (default: the number of cores).
    #[arg(long, default_value_t = Limits::default().compute_slots, value_parser = at_least_one())]
    compute_slots: usize,
    /// Iterations of one `plan` call.
    #[arg(long, default_value_t = Limits::default().max_plan_iterations, value_parser = at_least_one())]
    max_plan_iterations: usize,
    /// `plan` sessions kept at once (the least recently used goes first).
    #[arg(long, default_value_t = Limits::default().plan_sessions, value_parser = at_least_one())]
    plan_sessions: usize,
    /// Seconds a `plan` session is kept after its last use.
    #[arg(long, default_value_t = Limits::default().plan_session_ttl_s, value_parser = clap::value_parser!(u64).range(1..))]
    plan_session_ttl: u64,
    /// Microseconds a `step` request waits for others to the same model, so
    /// their networks run as one call (dynamic batching); 0 runs each alone.
    #[arg(long, default_value_t = Limits::default().batch_delay_us)]
    batch_delay_us: u64,
    /// What evaluates the models: the fused CPU path, or burn (the training code path): `fused` or `burn`.
    #[arg(long, default_value_t = Kernel::Fused, env = "NUNO_KERNEL")]
    kernel: Kernel,
    /// Print the OpenAPI document and exit.
    #[arg(long)]
    print_openapi: bool,
}

/// A limit of 0 would refuse every request (or keep nothing), so it is refused
/// at the start, by flag, instead.
fn at_least_one() -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::new().range(1..)
}

impl Args {
    /// The server's configuration as the flags give it.
    fn config(&self) -> ServerConfig {
        ServerConfig {
            models_dir: self.models.clone(),
            limits: Limits {
                max_batch: self.max_batch,
                max_particles: self.max_particles,
                max_horizon: self.max_horizon,
                max_rollout_steps: self.max_rollout_steps,
                max_episodes: self.max_episodes,
                max_body_bytes: self.max_body_bytes,
                max_answer_bytes: self.max_answer_bytes,
                request_timeout_s: self.request_timeout,
                concurrency: self.concurrency,
                compute_slots: self.compute_slots,
                max_plan_iterations: self.max_plan_iterations,
                batch_delay_us: self.batch_delay_us,
                plan_sessions: self.plan_sessions,
                plan_session_ttl_s: self.plan_session_ttl,
            },
            token: self.token.clone().filter(|t| !t.is_empty()),
            kernel: self.kernel,
            before_compute: None,
        }
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    if args.print_openapi {
        print!("{}", openapi_json());
        return ExitCode::SUCCESS;
    }
    init_logging();
    let (state, report) = AppState::new(args.config());
    for failure in &report.failed {
        tracing::warn!("not serving `{}`: {}", failure.id, failure.error);
    }
    if report.loaded.is_empty() {
        tracing::warn!(
            "no model loaded from {} (each model is a subdirectory with model.json)",
            args.models.display()
        );
    }
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(runtime) => runtime,
        Err(e) => {
            tracing::error!("cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(args.addr).await?;
        tracing::info!(
            "serving {:?} on http://{} (docs at /docs)",
            report.loaded,
            listener.local_addr()?
        );
        let Some(grpc_addr) = args.grpc_addr else {
            return serve(state, listener).await;
        };
        let grpc = tokio::net::TcpListener::bind(grpc_addr).await?;
        tracing::info!("gRPC (Open Inference Protocol) on {}", grpc.local_addr()?);
        tokio::try_join!(serve(state.clone(), listener), serve_grpc(state, grpc)).map(|_| ())
    });
    match result {
        Ok(()) => {
            tracing::info!("stopped");
            ExitCode::SUCCESS
        }
        Err(e) => {
            tracing::error!("{e}");
            ExitCode::FAILURE
        }
    }
}

/// Log lines on stderr, filtered by `RUST_LOG` (`info` when unset; e.g.
/// `RUST_LOG=nuno=debug,tower=warn`), coloured only on a terminal.
fn init_logging() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        // A closed stderr must not take requests down: by default a failed
        // write is reported with `eprintln!`, which panics on that same stderr.
        .log_internal_errors(false)
        .init();
}
