//! The model server end to end: the real router, called in process with
//! tower's `oneshot`, or on 127.0.0.1:0 with reqwest where a test needs a
//! socket (other processes' clients, shared clients, closed connections). Happy paths with value checks against the library, every bad-input
//! case, auth, concurrency, metrics, KServe v2, reload, and the committed spec.
#![cfg(feature = "server")]

mod common;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use burn::tensor::Device;
use nuno::agent::FusedActor;
use nuno::agent::{ActionMode, ActorConfig, ActorPolicy};
use nuno::artifact::{BEST_POLICY, PolicyProvenance, load_dynamics, save_policy};
use nuno::envs::{Rules, System, TaskConfig, TaskName, TaskRules};
use nuno::infer::Kernel;
use nuno::sde::FusedSde;
use nuno::server::{
    ActResponse, AppState, BINARY, ComputeHook, EvaluateResponse, Limits, ModelDetail, ModelList,
    RolloutResponse, Rows, ServerConfig, StepResponse, ValidateResponse, app, openapi_json, serve,
    serve_grpc,
};
use nuno::shared::{BatchDynamics, BatchPolicy};
use reqwest::StatusCode;
use serde_json::{Value, json};
use tower::ServiceExt;

const MODEL: &str = "hopper-random";

fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("models")
        .join(MODEL)
}

fn copy_model(to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for file in ["model.json", "dynamics.safetensors"] {
        std::fs::copy(shipped().join(file), to.join(file)).unwrap();
    }
}

/// A models directory with `hopper-random` (plus a seeded random policy) and
/// `no-policy` (dynamics only).
fn models_dir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    copy_model(&dir.path().join(MODEL));
    copy_model(&dir.path().join("no-policy"));
    let device = Device::flex();
    let actor = nuno::nn::seeded_init(&device, 1, || {
        ActorConfig::new(11, 3, vec![-1.0; 3], vec![1.0; 3]).init(&device)
    });
    let task = TaskConfig::d4rl(TaskName::Hopper);
    save_policy(
        &dir.path().join(MODEL),
        BEST_POLICY,
        &actor,
        &System::Task(task),
        PolicyProvenance::default(),
    )
    .unwrap();
    dir
}

/// How a test reaches the server.
enum Transport {
    /// The router called in process with tower's `oneshot`: no socket.
    InProcess(axum::Router),
    /// `serve` on 127.0.0.1:0, for what needs a socket: peers in other
    /// processes, a client shared between tasks, connections that close;
    /// `serve_grpc` beside it on another port (`grpc`, host:port).
    Socket {
        base: String,
        client: reqwest::Client,
        grpc: String,
    },
}

/// An answer as the test reads it, whichever the transport.
struct Answer {
    status: StatusCode,
    headers: reqwest::header::HeaderMap,
    body: Vec<u8>,
}

impl Answer {
    fn json(&self) -> Value {
        serde_json::from_slice(&self.body).unwrap_or(Value::Null)
    }
}

struct Server {
    transport: Transport,
    _models: tempfile::TempDir,
    models_path: PathBuf,
}

impl Server {
    /// The server in process (see [`Transport`]).
    async fn start(limits: Limits, token: Option<&str>) -> Self {
        Self::start_with_config(limits, |config| config.token = token.map(String::from)).await
    }

    /// The server on a socket (see [`Transport`]).
    async fn listening(limits: Limits, token: Option<&str>) -> Self {
        let adjust = |config: &mut ServerConfig| config.token = token.map(String::from);
        let (server, loaded) = Self::start_on(models_dir(), limits, adjust, true).await;
        assert_eq!(loaded, vec![MODEL.to_string(), "no-policy".to_string()]);
        server
    }

    /// In process, on `limits`, with whatever else `adjust` sets.
    async fn start_with_config(limits: Limits, adjust: impl FnOnce(&mut ServerConfig)) -> Self {
        let (server, loaded) = Self::start_on(models_dir(), limits, adjust, false).await;
        assert_eq!(loaded, vec![MODEL.to_string(), "no-policy".to_string()]);
        server
    }

    /// A server on the models in `models`, on a socket when `listen`, and
    /// the ids it loaded.
    async fn start_on(
        models: tempfile::TempDir,
        limits: Limits,
        adjust: impl FnOnce(&mut ServerConfig),
        listen: bool,
    ) -> (Self, Vec<String>) {
        let mut config = ServerConfig {
            models_dir: models.path().to_path_buf(),
            limits,
            token: None,
            kernel: Kernel::default(),
            before_compute: None,
        };
        adjust(&mut config);
        let (state, report) = AppState::new(config);
        let transport = if listen {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            let base = format!("http://{}", listener.local_addr().unwrap());
            let grpc_listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            let grpc = grpc_listener.local_addr().unwrap().to_string();
            tokio::spawn(serve_grpc(state.clone(), grpc_listener));
            tokio::spawn(serve(state, listener));
            Transport::Socket {
                base,
                grpc,
                // A fresh connection per request: the server may close one after an
                // error answer (a refused body it never read), and a pooled connection
                // reused in that instant fails with hyper's IncompleteMessage.
                client: reqwest::Client::builder()
                    .pool_max_idle_per_host(0)
                    .timeout(common::bounded::HANG_BOUND)
                    .build()
                    .unwrap(),
            }
        } else {
            Transport::InProcess(app(state))
        };
        let server = Self {
            transport,
            models_path: models.path().to_path_buf(),
            _models: models,
        };
        (server, report.loaded)
    }

    /// The socket's base URL and client: the test must have started the
    /// server [`listening`](Self::listening).
    fn socket(&self) -> (&str, &reqwest::Client) {
        match &self.transport {
            Transport::Socket { base, client, .. } => (base, client),
            Transport::InProcess(_) => panic!("this test needs Server::listening"),
        }
    }

    /// The gRPC service's host:port: the test must have started the server
    /// [`listening`](Self::listening).
    fn grpc(&self) -> &str {
        match &self.transport {
            Transport::Socket { grpc, .. } => grpc,
            Transport::InProcess(_) => panic!("this test needs Server::listening"),
        }
    }

    /// `method path` with `headers` and `body`, through either transport.
    async fn request(
        &self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: Vec<u8>,
    ) -> Answer {
        match &self.transport {
            Transport::InProcess(router) => {
                let mut request = axum::http::Request::builder().method(method).uri(path);
                for (name, value) in headers {
                    request = request.header(*name, *value);
                }
                let request = request.body(axum::body::Body::from(body)).unwrap();
                let response = router.clone().oneshot(request).await.unwrap();
                let (parts, body) = response.into_parts();
                let body = axum::body::to_bytes(body, usize::MAX).await.unwrap();
                Answer {
                    status: parts.status,
                    headers: parts.headers,
                    body: body.to_vec(),
                }
            }
            Transport::Socket { base, client, .. } => {
                let method = reqwest::Method::from_bytes(method.as_bytes()).unwrap();
                let mut request = client.request(method, format!("{base}{path}")).body(body);
                for (name, value) in headers {
                    request = request.header(*name, *value);
                }
                let response = request.send().await.unwrap();
                Answer {
                    status: response.status(),
                    headers: response.headers().clone(),
                    body: response.bytes().await.unwrap().to_vec(),
                }
            }
        }
    }

    async fn post(&self, path: &str, body: &Value) -> (StatusCode, Value) {
        let bytes = serde_json::to_vec(body).unwrap();
        let answer = self
            .request("POST", path, &[("content-type", "application/json")], bytes)
            .await;
        (answer.status, answer.json())
    }

    async fn post_raw(&self, path: &str, content_type: &str, body: impl Into<Vec<u8>>) -> Answer {
        let headers = [("content-type", content_type)];
        self.request("POST", path, &headers, body.into()).await
    }

    /// The Prometheus text of `/metrics`.
    async fn metrics(&self) -> String {
        let answer = self.request("GET", "/metrics", &[], Vec::new()).await;
        String::from_utf8(answer.body).unwrap()
    }

    async fn get(&self, path: &str) -> (StatusCode, Value) {
        let answer = self.request("GET", path, &[], Vec::new()).await;
        (answer.status, answer.json())
    }
}

fn limits() -> Limits {
    Limits {
        max_batch: 5000,
        max_particles: 8,
        max_horizon: 50,
        max_body_bytes: 1 << 20,
        ..Limits::default()
    }
}

fn upright(n: usize) -> Vec<Vec<f32>> {
    (0..n)
        .map(|i| {
            let mut s = vec![0.0f32; 11];
            s[0] = 1.25;
            s[5] = 0.1 * i as f32;
            s[7] = -0.2 * i as f32;
            s
        })
        .collect()
}

fn actions(n: usize) -> Vec<Vec<f32>> {
    (0..n)
        .map(|i| vec![0.3 * (i as f32).sin(), -0.2, 0.5])
        .collect()
}

fn error_code(body: &Value) -> &str {
    body["error"]["code"].as_str().unwrap_or("<no code>")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn models_are_listed_with_their_details() {
    let server = Server::start(limits(), None).await;
    let (status, body) = server.get("/v1/models").await;
    assert_eq!(status, StatusCode::OK);
    let list: ModelList = serde_json::from_value(body).unwrap();
    assert_eq!(list.models.len(), 2);
    let m = &list.models[0];
    assert_eq!(
        (m.id.as_str(), m.task.as_str(), m.obs_dim, m.act_dim),
        (MODEL, "hopper", 11, 3)
    );
    assert!(m.has_policy && !list.models[1].has_policy);
    assert!((m.dt - 0.008).abs() < 1e-12);
    // The shipped model was saved before models recorded their sampling scale:
    // it loads with the meaning it had, samples at the full Σ.
    assert_eq!(m.sample_noise_scale, 1.0);
    let (status, body) = server.get(&format!("/v1/models/{MODEL}")).await;
    assert_eq!(status, StatusCode::OK);
    let detail: ModelDetail = serde_json::from_value(body).unwrap();
    assert_eq!(detail.thresholds["horizons"], json!([5, 10, 15, 20]));
    assert_eq!(detail.state_split["positions"].as_array().unwrap().len(), 5);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn step_matches_the_library_in_json_and_binary() {
    let server = Server::start(limits(), None).await;
    let (states, acts) = (upright(4), actions(4));
    let request =
        json!({"states": states, "actions": acts, "particles": 3, "seed": 7, "penalty": 0.5});
    let (status, body) = server
        .post(&format!("/v1/models/{MODEL}/step"), &request)
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: StepResponse = serde_json::from_value(body).unwrap();
    assert_eq!(
        (
            r.batch,
            r.particles,
            r.next_states.len(),
            r.next_states[0].len()
        ),
        (4, 3, 4, 3)
    );

    // The drift mean, σ, h(η) and η equal the library's step.
    let (model, metadata) = load_dynamics(&shipped(), &Device::flex()).unwrap();
    let flat_states: Vec<f32> = states.concat();
    let flat_actions: Vec<f32> = acts.concat();
    // The server runs the fused kernel by default; tests/infer.rs ties it to burn.
    let direct = FusedSde::new(&model).step(&flat_states, &flat_actions, &[0.0; 44]);
    for (b, action) in acts.iter().enumerate() {
        for i in 0..11 {
            assert!((r.mean[b][i] - direct.means[b * 11 + i]).abs() < 1e-5);
            assert!((r.sigma[b][i] - direct.sigma[b * 11 + i]).abs() < 1e-6);
        }
        assert!((r.eta[b] - direct.eta[b]).abs() < 1e-6);
        let rules = Rules::from(TaskRules::new(
            metadata.provenance.task.as_ref().unwrap(),
            metadata.spec.dt,
        ));
        for p in 0..3 {
            let reward = rules.reward(&states[b], action, &r.next_states[b][p]);
            assert!((r.rewards[b][p] - reward).abs() < 1e-5);
            assert!((r.penalized_rewards[b][p] - (reward - 0.5 * r.eta[b])).abs() < 1e-5);
            assert_eq!(r.terminals[b][p], rules.terminal(&r.next_states[b][p]));
        }
        assert_ne!(r.next_states[b][0], r.next_states[b][1], "particles differ");
    }
    // Same seed, same answer; no noise, the mean.
    let (_, again) = server
        .post(&format!("/v1/models/{MODEL}/step"), &request)
        .await;
    assert_eq!(
        serde_json::from_value::<StepResponse>(again)
            .unwrap()
            .next_states,
        r.next_states
    );
    let calm = json!({"states": states, "actions": acts, "noise_scale": 0.0});
    let (_, calm) = server
        .post(&format!("/v1/models/{MODEL}/step"), &calm)
        .await;
    let calm: StepResponse = serde_json::from_value(calm).unwrap();
    for b in 0..4 {
        assert_eq!(calm.next_states[b][0], calm.mean[b]);
    }

    // The binary body gives the same numbers.
    let tensors = nuno::artifact::NamedTensors::from([
        ("states".to_string(), (vec![4, 11], flat_states.clone())),
        ("actions".to_string(), (vec![4, 3], flat_actions.clone())),
    ]);
    let metadata = std::collections::HashMap::from([
        ("particles".to_string(), "3".to_string()),
        ("seed".to_string(), "7".to_string()),
        ("penalty".to_string(), "0.5".to_string()),
    ]);
    let bytes = nuno::artifact::safetensors_bytes(&tensors, Some(metadata)).unwrap();
    let response = server
        .post_raw(&format!("/v1/models/{MODEL}/step"), BINARY, bytes)
        .await;
    assert_eq!(response.status, StatusCode::OK);
    assert_eq!(response.headers["content-type"], "application/octet-stream");
    let body = response.body;
    let out = nuno::artifact::parse_safetensors(&body, Path::new("response")).unwrap();
    assert_eq!(out["next_states"].0, vec![4, 3, 11]);
    let json_next: Vec<f32> = r.next_states.concat().concat();
    assert_eq!(out["next_states"].1, json_next);
    assert_eq!(out["eta"].1, r.eta);

    // A body over 64 KiB is parsed off the async runtime: same numbers, same errors.
    let (states, acts) = (upright(1200), actions(1200));
    let big = json!({"states": states, "actions": acts, "noise_scale": 0.0});
    let text = big.to_string();
    assert!(text.len() > 64 * 1024, "{} bytes", text.len());
    let (status, body) = server.post(&format!("/v1/models/{MODEL}/step"), &big).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: StepResponse = serde_json::from_value(body).unwrap();
    let direct =
        FusedSde::new(&model).step(&states.concat(), &acts.concat(), &vec![0.0; 1200 * 11]);
    assert_eq!(r.batch, 1200);
    for b in [0, 599, 1199] {
        assert!((r.eta[b] - direct.eta[b]).abs() < 1e-6, "η of row {b}");
        assert!(
            (r.mean[b][5] - direct.means[b * 11 + 5]).abs() < 1e-5,
            "mean of row {b}"
        );
    }
    let cut = text[..text.len() - 10].to_string();
    let response = server
        .post_raw(&format!("/v1/models/{MODEL}/step"), "application/json", cut)
        .await;
    assert_eq!(response.status, StatusCode::BAD_REQUEST);
    let body = response.json();
    assert_eq!(error_code(&body), "malformed_body", "{body}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rollout_without_noise_chains_steps_and_truncates_at_epsilon() {
    let server = Server::start(limits(), None).await;
    let h = 6;
    let starts = upright(2);
    let plan: Vec<Vec<Vec<f32>>> = (0..2).map(|_| actions(h)).collect();
    let request = json!({"states": starts, "actions": plan, "horizon": h, "noise_scale": 0.0, "penalty": 0.0});
    let (status, body) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &request)
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: RolloutResponse = serde_json::from_value(body).unwrap();
    assert_eq!(r.trajectories.len(), 2);
    let t = &r.trajectories[0];
    // Chained steps through the step endpoint reproduce it.
    let mut state = starts[0].clone();
    for (k, action) in plan[0].iter().enumerate().take(t.length) {
        let step =
            json!({"states": [state], "actions": [action], "noise_scale": 0.0, "penalty": 0.0});
        let (_, s) = server
            .post(&format!("/v1/models/{MODEL}/step"), &step)
            .await;
        let s: StepResponse = serde_json::from_value(s).unwrap();
        assert!((s.eta[0] - t.eta[k]).abs() < 1e-6, "η at step {k}");
        state = s.next_states[0][0].clone();
        for (a, b) in state.iter().zip(&t.states[k + 1]) {
            assert!((a - b).abs() < 1e-5, "state at step {k}");
        }
    }

    // Closed loop with the policy and an explicit threshold.
    let epsilon = 0.5f32;
    let request = json!({"states": upright(20), "horizon": 10, "particles": 2, "threshold": epsilon, "seed": 3});
    let (status, body) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &request)
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: RolloutResponse = serde_json::from_value(body).unwrap();
    assert_eq!((r.trajectories.len(), r.threshold), (40, Some(epsilon)));
    let mut truncated = 0;
    for t in &r.trajectories {
        let last = *t.accumulated_eta.last().unwrap();
        assert_eq!(t.truncated, last > epsilon, "flag vs accumulated η");
        assert!(t.accumulated_eta[..t.length].iter().all(|&a| a <= epsilon));
        assert_eq!(t.states.len(), t.length + 1);
        if t.truncated {
            assert_eq!(t.truncation_step, Some(t.length));
            truncated += 1;
        }
    }
    assert!(truncated > 0, "ε = {epsilon} should truncate something");
    // α picks ε(h, α) from the model's table.
    let request = json!({"states": upright(1), "horizon": 10, "alpha": 0.9});
    let (_, body) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &request)
        .await;
    let expected = load_dynamics(&shipped(), &Device::flex())
        .unwrap()
        .1
        .provenance
        .thresholds
        .unwrap()
        .get(10, 0.9);
    assert_eq!(
        serde_json::from_value::<RolloutResponse>(body)
            .unwrap()
            .threshold,
        expected
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn act_evaluate_and_validate() {
    let server = Server::start(limits(), None).await;
    let states = upright(5);
    let (status, body) = server
        .post(
            &format!("/v1/models/{MODEL}/act"),
            &json!({"states": states}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: ActResponse = serde_json::from_value(body).unwrap();
    let device = Device::flex();
    let (actor, _) =
        nuno::artifact::load_policy(&server.models_path.join(MODEL), BEST_POLICY, &device).unwrap();
    let policy = FusedActor::new(&ActorPolicy {
        actor,
        mode: ActionMode::Deterministic,
    });
    let expected = policy.act(&states.concat(), &mut rand::rng());
    assert_eq!(r.actions.concat(), expected);
    assert!(r.actions.iter().flatten().all(|a| (-1.0..=1.0).contains(a)));

    let (status, body) = server
        .post(
            "/v1/evaluate",
            &json!({"model": MODEL, "episodes": 3, "seed": 4}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let e: EvaluateResponse = serde_json::from_value(body).unwrap();
    assert_eq!((e.report.returns.len(), e.report.lengths.len()), (3, 3));
    assert!(e.report.lengths.iter().all(|&l| (1..=1000).contains(&l)));
    let mean = e.report.returns.iter().sum::<f64>() / 3.0;
    assert!((mean - e.report.mean_return).abs() < 1e-9);

    let (status, body) = server
        .post("/v1/evaluate", &json!({"model": "no-policy"}))
        .await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::CONFLICT, "no_policy")
    );

    let (status, body) = server
        .post(
            &format!("/v1/models/{MODEL}/validate"),
            &json!({"actions": actions(8), "seed": 2}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let v: ValidateResponse = serde_json::from_value(body).unwrap();
    assert!(v.steps >= 1 && v.steps <= 8);
    assert_eq!(
        (v.rmse.len(), v.real_states.len(), v.model_states.len()),
        (v.steps, v.steps + 1, v.steps + 1)
    );
    assert_eq!(
        v.real_states[0], v.model_states[0],
        "both start from the reset state"
    );
    assert!(v.rmse.iter().all(|e| e.is_finite() && *e >= 0.0));
    assert!(
        v.rmse[0] < 0.5,
        "one step of a fitted model stays close: {}",
        v.rmse[0]
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_input_gets_a_named_4xx() {
    let server = Server::start(limits(), None).await;
    let step = format!("/v1/models/{MODEL}/step");
    let cases: Vec<(Value, StatusCode, &str, &str)> = vec![
        (
            json!({"states": [[1.0, 2.0]], "actions": [[0, 0, 0]]}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_request",
            "expects 11",
        ),
        (
            json!({"states": upright(1), "actions": [[0, 0]]}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_request",
            "expects 3",
        ),
        (
            json!({"states": [], "actions": []}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_request",
            "empty",
        ),
        (
            json!({"states": upright(2), "actions": actions(1)}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_request",
            "rows",
        ),
        (
            json!({"states": upright(1), "actions": actions(1), "particles": 9}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "over_limit",
            "limit of 8",
        ),
        (
            json!({"states": upright(1), "actions": actions(1), "particles": 0}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_request",
            "at least 1",
        ),
        (
            json!({"states": upright(1), "actions": actions(1), "penalty": -1}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_request",
            "penalty",
        ),
        (
            json!({"states": [[1e39, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]], "actions": actions(1)}),
            StatusCode::BAD_REQUEST,
            "malformed_body",
            "out of range",
        ),
        (
            json!({"states": upright(1), "actions": actions(1), "bogus": 1}),
            StatusCode::BAD_REQUEST,
            "malformed_body",
            "bogus",
        ),
        (
            json!({"actions": actions(1)}),
            StatusCode::BAD_REQUEST,
            "malformed_body",
            "states",
        ),
    ];
    for (body, status, code, needle) in cases {
        let (got, response) = server.post(&step, &body).await;
        assert_eq!(
            (got, error_code(&response)),
            (status, code),
            "{body} -> {response}"
        );
        let message = response["error"]["message"].as_str().unwrap();
        assert!(
            message.contains(needle),
            "{message} should mention {needle}"
        );
    }
    let (status, body) = server
        .post(
            &format!("/v1/models/{MODEL}/rollout"),
            &json!({"states": upright(1), "horizon": 51}),
        )
        .await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::UNPROCESSABLE_ENTITY, "over_limit")
    );
    let (status, body) = server
        .post(
            "/v1/models/no-policy/rollout",
            &json!({"states": upright(1), "horizon": 3}),
        )
        .await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::CONFLICT, "no_policy")
    );
    let (status, body) = server
        .post(
            &format!("/v1/models/{MODEL}/rollout"),
            &json!({"states": upright(1), "horizon": 3, "alpha": 0.5}),
        )
        .await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::UNPROCESSABLE_ENTITY, "invalid_request"),
        "{body}"
    );

    // Unknown models and path tricks never reach the filesystem.
    for id in ["nope", "..%2F..%2Fetc", "%2e%2e", "hopper-random%00"] {
        let (status, body) = server
            .post(&format!("/v1/models/{id}/step"), &json!({}))
            .await;
        assert_eq!(status, StatusCode::NOT_FOUND, "{id}");
        assert!(error_code(&body).ends_with("not_found"), "{id}: {body}");
    }
    // Not JSON, the wrong type, too large, an unknown route.
    let r = server
        .post_raw(&step, "application/json", "{\"states\": [[")
        .await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    let r = server.post_raw(&step, "text/csv", "states=1").await;
    assert_eq!(r.status, StatusCode::UNSUPPORTED_MEDIA_TYPE);
    let r = server.post_raw(&step, BINARY, "not safetensors").await;
    assert_eq!(r.status, StatusCode::BAD_REQUEST);
    let r = server
        .post_raw(&step, "application/json", vec![b' '; 2 << 20])
        .await;
    assert_eq!(r.status, StatusCode::PAYLOAD_TOO_LARGE);
    let body = r.json();
    assert_eq!(error_code(&body), "body_too_large");
    let (status, body) = server.get("/v1/nothing").await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::NOT_FOUND, "route_not_found")
    );
    // NaN inside a binary body.
    let tensors = nuno::artifact::NamedTensors::from([
        ("states".to_string(), (vec![1, 11], vec![f32::NAN; 11])),
        ("actions".to_string(), (vec![1, 3], vec![0.0; 3])),
    ]);
    let bytes = nuno::artifact::safetensors_bytes(&tensors, None).unwrap();
    let r = server.post_raw(&step, BINARY, bytes).await;
    assert_eq!(r.status, StatusCode::UNPROCESSABLE_ENTITY);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn token_guards_everything_but_health() {
    let server = Server::start(limits(), Some("s3cret")).await;
    assert_eq!(server.get("/healthz").await.0, StatusCode::OK);
    assert_eq!(server.get("/readyz").await.0, StatusCode::OK);
    assert_eq!(server.get("/v2/health/live").await.0, StatusCode::OK);
    let (status, body) = server.get("/v1/models").await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::UNAUTHORIZED, "unauthorized")
    );
    let with_token = |path: &str, token: &str| {
        let bearer = format!("Bearer {token}");
        let server = &server;
        let path = path.to_string();
        async move {
            let headers = [("authorization", bearer.as_str())];
            server
                .request("GET", &path, &headers, Vec::new())
                .await
                .status
        }
    };
    assert_eq!(
        with_token("/v1/models", "wrong").await,
        StatusCode::UNAUTHORIZED
    );
    // A prefix or an extension of the token is no token.
    for near in ["s3cre", "s3cretX", "S3cret", ""] {
        let status = with_token("/v1/models", near).await;
        assert_eq!(status, StatusCode::UNAUTHORIZED, "{near:?}");
    }
    assert_eq!(with_token("/v1/models", "s3cret").await, StatusCode::OK);
    // KServe routes refuse in the protocol's error shape, `{"error": "<message>"}`.
    let (status, body) = server.get(&format!("/v2/models/{MODEL}")).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert!(
        body["error"].as_str().unwrap().contains("bearer token"),
        "{body}"
    );
    // The spec and the docs list every route: with a token, they need it too.
    for path in ["/openapi.json", "/docs"] {
        assert_eq!(server.get(path).await.0, StatusCode::UNAUTHORIZED, "{path}");
        assert_eq!(with_token(path, "s3cret").await, StatusCode::OK, "{path}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_requests_metrics_kserve_and_reload() {
    let server = Server::listening(limits(), None).await;
    let (base, client) = server.socket();
    let step = format!("/v1/models/{MODEL}/step");
    let request = |seed: u64| json!({"states": upright(64), "actions": actions(64), "seed": seed});
    let mut tasks = Vec::new();
    for seed in 0..16u64 {
        let (client, url, body) = (client.clone(), format!("{base}{step}"), request(seed % 4));
        tasks.push(tokio::spawn(async move {
            let r = client.post(url).json(&body).send().await.unwrap();
            assert_eq!(r.status(), StatusCode::OK);
            r.json::<StepResponse>().await.unwrap()
        }));
    }
    let mut answers = Vec::new();
    for t in tasks {
        answers.push(t.await.unwrap());
    }
    for (i, a) in answers.iter().enumerate() {
        assert_eq!(
            a.next_states,
            answers[i % 4].next_states,
            "seed {} answers alike",
            i % 4
        );
    }

    // Unknown routes are answered in JSON and counted like the others.
    let (status, body) = server.get("/v1/no-such-route").await;
    assert_eq!(
        (status, error_code(&body)),
        (StatusCode::NOT_FOUND, "route_not_found")
    );
    let text = server.metrics().await;
    assert!(
        text.contains("nuno_requests_total{route=\"/v1/models/{id}/step\",status=\"200\"} 16"),
        "{text}"
    );
    assert!(
        text.contains("nuno_requests_total{route=\"unmatched\",status=\"404\"} 1"),
        "{text}"
    );
    assert!(
        text.contains("nuno_items_total{model=\"hopper-random\"} 1024"),
        "{text}"
    );
    assert!(
        text.contains("nuno_request_duration_seconds_count{route=\"/v1/models/{id}/step\"} 16")
    );

    // KServe v2: metadata and infer agree with step.
    let (status, meta) = server.get(&format!("/v2/models/{MODEL}")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(
        meta["inputs"][0],
        json!({"name": "states", "datatype": "FP32", "shape": [-1, 11]})
    );
    let infer = json!({"id": "q1", "inputs": [
        {"name": "states", "shape": [2, 11], "datatype": "FP32", "data": upright(2).concat()},
        {"name": "actions", "shape": [2, 3], "datatype": "FP32", "data": actions(2).concat()},
    ], "parameters": {"seed": 5}});
    let (status, out) = server
        .post(&format!("/v2/models/{MODEL}/infer"), &infer)
        .await;
    assert_eq!(status, StatusCode::OK, "{out}");
    assert_eq!(out["id"], "q1");
    let (_, s) = server
        .post(
            &step,
            &json!({"states": upright(2), "actions": actions(2), "seed": 5}),
        )
        .await;
    let s: StepResponse = serde_json::from_value(s).unwrap();
    let next: Vec<f64> = s
        .next_states
        .concat()
        .concat()
        .iter()
        .map(|&x| f64::from(x))
        .collect();
    let got: Vec<f64> = serde_json::from_value(out["outputs"][0]["data"].clone()).unwrap();
    assert_eq!(out["outputs"][0]["name"], "next_states");
    assert_eq!(got, next);
    let (status, err) = server
        .post(&format!("/v2/models/{MODEL}/infer"), &json!({"inputs": []}))
        .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(err["error"].as_str().unwrap().contains("states"));
    // Inline data is read as numbers while the body is parsed: anything else is a
    // malformed body; a number past f32's range is refused by name as not finite.
    let with_states = |data: Value| {
        json!({"inputs": [
            {"name": "states", "shape": [1, 11], "datatype": "FP32", "data": data},
            {"name": "actions", "shape": [1, 3], "datatype": "FP32", "data": [0.0, 0.0, 0.0]},
        ]})
    };
    let mut huge = upright(1)
        .concat()
        .iter()
        .map(|&x| json!(x))
        .collect::<Vec<_>>();
    huge[4] = json!(1e39);
    for (data, status, needle) in [
        (
            json!(vec!["x"; 11]),
            StatusCode::BAD_REQUEST,
            "invalid type: string",
        ),
        (
            json!([vec![1.0; 11]]),
            StatusCode::BAD_REQUEST,
            "invalid type: sequence",
        ),
        (
            Value::Array(huge),
            StatusCode::UNPROCESSABLE_ENTITY,
            "`states[0][4]` is not a finite number",
        ),
    ] {
        let (got, err) = server
            .post(&format!("/v2/models/{MODEL}/infer"), &with_states(data))
            .await;
        let message = err["error"].as_str().unwrap();
        assert_eq!(got, status, "{message}");
        assert!(message.contains(needle), "{message}");
    }

    // Reload: a new model appears, a broken one is refused and not served.
    copy_model(&server.models_path.join("second"));
    let broken = server.models_path.join("broken");
    copy_model(&broken);
    let weights = broken.join("dynamics.safetensors");
    let bytes = std::fs::read(&weights).unwrap();
    std::fs::write(&weights, &bytes[..bytes.len() / 2]).unwrap();
    let (status, report) = server.post("/v1/admin/reload", &json!({})).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(
        report["loaded"],
        json!(["hopper-random", "no-policy", "second"])
    );
    assert_eq!(report["failed"][0]["id"], "broken");
    assert_eq!(server.get("/v1/models/second").await.0, StatusCode::OK);
    assert_eq!(
        server.get("/v1/models/broken").await.0,
        StatusCode::NOT_FOUND
    );
}

#[test]
fn committed_openapi_spec_is_current() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("openapi/openapi.json");
    let committed = std::fs::read_to_string(&path).unwrap();
    assert!(
        committed == openapi_json(),
        "openapi/openapi.json is stale: run `make openapi` and commit it"
    );
    let spec: Value = serde_json::from_str(&committed).unwrap();
    assert_eq!(spec["openapi"], "3.1.0");
    // Every route the router serves (the KServe v2 ones included).
    for path in [
        "/v1/models",
        "/v1/models/{id}",
        "/v1/models/{id}/step",
        "/v1/models/{id}/rollout",
        "/v1/models/{id}/act",
        "/v1/models/{id}/validate",
        "/v1/evaluate",
        "/v1/admin/reload",
        "/healthz",
        "/readyz",
        "/metrics",
        "/v2",
        "/v2/health/live",
        "/v2/health/ready",
        "/v2/models/{id}",
        "/v2/models/{id}/ready",
        "/v2/models/{id}/infer",
    ] {
        assert!(
            spec["paths"][path].is_object(),
            "{path} missing from the spec"
        );
    }
    // The token is optional (a server without `--token` needs none); probes never need it.
    assert_eq!(spec["security"], json!([{}, {"bearer": []}]));
    for probe in ["/healthz", "/readyz", "/v2/health/live", "/v2/health/ready"] {
        assert_eq!(
            spec["paths"][probe]["get"]["security"],
            json!([{}]),
            "{probe}"
        );
    }
    // What the layers and the body extractor answer is documented on every route it can reach.
    let responses = |path: &str, method: &str| {
        let mut codes: Vec<String> = spec["paths"][path][method]["responses"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        codes.sort();
        codes
    };
    assert_eq!(
        responses("/v1/models/{id}/step", "post"),
        [
            "200", "400", "401", "404", "413", "415", "422", "500", "503"
        ]
    );
    assert_eq!(responses("/healthz", "get"), ["200", "500", "503"]);
    let infer_422 = &spec["paths"]["/v2/models/{id}/infer"]["post"]["responses"]["422"];
    assert_eq!(
        infer_422["content"]["application/json"]["schema"]["$ref"],
        "#/components/schemas/V2ErrorBody"
    );
    let step = &spec["paths"]["/v1/models/{id}/step"]["post"]["requestBody"]["content"];
    assert!(step["application/json"].is_object() && step["application/octet-stream"].is_object());
}

/// KServe's own Python client (PyPI `kserve`, protocol v2) with the binary
/// tensor extension off and on: the same numbers as `/v1/.../step` with the
/// same seed, and binary answers are binary.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
async fn kserves_python_client_infers_in_json_and_binary() {
    let server = Server::listening(limits(), None).await;
    let (states, acts) = (upright(5), actions(5));
    let body = json!({"states": states, "actions": acts, "seed": 3, "penalty": 0.5});
    let (status, step) = server
        .post(&format!("/v1/models/{MODEL}/step"), &body)
        .await;
    assert_eq!(status, StatusCode::OK, "{step}");
    let step: StepResponse = serde_json::from_value(step).unwrap();

    let work = tempfile::tempdir().unwrap();
    let (base, dir) = (server.socket().0.to_string(), work.path().to_path_buf());
    let args = [
        base,
        MODEL.to_string(),
        json!(states).to_string(),
        json!(acts).to_string(),
    ];
    tokio::task::spawn_blocking(move || common::run_python("kserve_client.py", &args, &dir))
        .await
        .unwrap();
    let result: Value =
        serde_json::from_str(&std::fs::read_to_string(work.path().join("result.json")).unwrap())
            .unwrap();
    assert_eq!(
        (&result["live"], &result["ready"], &result["model_ready"]),
        (&json!(true), &json!(true), &json!(true))
    );
    assert_eq!(result["json"]["content_type"], "application/json");
    assert_eq!(result["binary"]["content_type"], "application/octet-stream");
    let as_f32 = |v: &Value| -> Vec<f32> {
        v.as_array()
            .unwrap()
            .iter()
            .flat_map(|x| match x {
                Value::Array(row) => row.iter().map(|y| y.as_f64().unwrap() as f32).collect(),
                x => vec![x.as_f64().unwrap() as f32],
            })
            .collect()
    };
    for mode in ["json", "binary"] {
        let outputs = &result[mode]["outputs"];
        // Shape [batch, obs_dim]: one particle per row, the same draw as step's first.
        let next: Vec<f32> = step
            .next_states
            .iter()
            .map(|p| p[0].clone())
            .collect::<Vec<_>>()
            .concat();
        assert_eq!(as_f32(&outputs["next_states"]), next, "{mode} next_states");
        assert_eq!(as_f32(&outputs["eta"]), step.eta, "{mode} eta");
        let penalised: Vec<f32> = step.penalized_rewards.iter().map(|p| p[0]).collect();
        assert_eq!(
            as_f32(&outputs["penalized_rewards"]),
            penalised,
            "{mode} penalised rewards"
        );
        let terminals: Vec<f32> = step
            .terminals
            .iter()
            .map(|p| f32::from(u8::from(p[0])))
            .collect();
        assert_eq!(as_f32(&outputs["terminals"]), terminals, "{mode} terminals");
    }
}

/// The Open Inference Protocol over gRPC with Triton's own Python client
/// (`tritonclient[grpc]`): health, metadata, `ModelInfer` with raw and with
/// typed contents answering `/v1/.../step`'s draw for the same seed, the
/// token as metadata, and bad tensors answered with the matching status code
/// and a message naming them (`tests/python/grpc_client.py` asserts each).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
async fn tritons_grpc_client_infers_what_rest_steps() {
    let token = "grpc-secret";
    let server = Server::listening(
        Limits {
            max_batch: 64,
            ..limits()
        },
        Some(token),
    )
    .await;
    let (states, acts) = (upright(5), actions(5));
    let (base, client) = server.socket();
    let typed = nuno_client::Client::new(base).with_token(token);
    let mut request =
        nuno_client::StepRequest::new(Rows::new(states.concat(), 11), Rows::new(acts.concat(), 3));
    (request.seed, request.penalty) = (3, 0.5);
    let step = typed.step(MODEL, &request).await.unwrap();
    // One particle per row: the step's first draw of each.
    let first = |rows: &Vec<Vec<f32>>| -> Vec<f32> { rows.iter().map(|p| p[0]).collect() };
    let expected = json!({
        "states": states,
        "actions": acts,
        "next_states": step.next_states.iter().map(|p| p[0].clone()).collect::<Vec<_>>(),
        "eta": step.eta,
        "penalized_rewards": first(&step.penalized_rewards),
        "terminals": step.terminals.iter().map(|p| p[0]).collect::<Vec<_>>(),
    });
    let work = tempfile::tempdir().unwrap();
    std::fs::write(work.path().join("expected.json"), expected.to_string()).unwrap();
    let args = [
        server.grpc().to_string(),
        MODEL.to_string(),
        token.to_string(),
    ];
    let dir = work.path().to_path_buf();
    tokio::task::spawn_blocking(move || common::run_python("grpc_client.py", &args, &dir))
        .await
        .unwrap();
    let metrics = client
        .get(format!("{base}/metrics"))
        .bearer_auth(token)
        .send()
        .await;
    let metrics = metrics.unwrap().text().await.unwrap();
    assert!(
        metrics.contains("/inference.GRPCInferenceService/ModelInfer"),
        "gRPC calls are counted with the REST routes:\n{metrics}"
    );
}

/// Binary-extension bodies that do not add up are refused, naming what is wrong.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn malformed_binary_infer_bodies_are_refused_by_name() {
    let server = Server::start(limits(), None).await;
    let infer = format!("/v2/models/{MODEL}/infer");
    let header = json!({"inputs": [
        {"name": "states", "shape": [1, 11], "datatype": "FP32", "parameters": {"binary_data_size": 44}},
        {"name": "actions", "shape": [1, 3], "datatype": "FP32", "parameters": {"binary_data_size": 12}},
    ]})
    .to_string();
    let send = |body: Vec<u8>, length: Option<usize>| {
        let (server, infer) = (&server, infer.clone());
        async move {
            let length = length.map(|l| l.to_string());
            let mut headers = vec![("content-type", BINARY)];
            if let Some(length) = &length {
                headers.push(("inference-header-content-length", length.as_str()));
            }
            server.request("POST", &infer, &headers, body).await
        }
    };
    let mut body = header.clone().into_bytes();
    body.extend(std::iter::repeat_n(0u8, 40)); // 4 bytes short of the states
    let cases = [
        (
            body.clone(),
            None,
            StatusCode::UNPROCESSABLE_ENTITY,
            "inference-header-content-length",
        ),
        (
            body.clone(),
            Some(body.len() + 1),
            StatusCode::BAD_REQUEST,
            "the body has",
        ),
        (
            body,
            Some(header.len()),
            StatusCode::BAD_REQUEST,
            "binary_data_size 44, but only 40 bytes",
        ),
    ];
    for (body, length, status, needle) in cases {
        let r = send(body, length).await;
        assert_eq!(r.status, status, "{needle}");
        let answer = r.json();
        let message = answer["error"].as_str().unwrap();
        assert!(message.contains(needle), "{message}");
    }
}

/// schemathesis `--checks all` against the spec the server serves: 0
/// failures (tests/python/contract_hooks.py names the two things set aside:
/// binary bodies, and model-dependent widths and field relations). Small
/// limits keep every generated request cheap, and the spec states them.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
async fn the_server_keeps_the_contract_of_its_own_spec() {
    let limits = Limits {
        max_batch: 16,
        max_particles: 4,
        max_horizon: 20,
        max_episodes: 2,
        ..Limits::default()
    };
    let server = Server::listening(limits, None).await;
    let (_, spec) = server.get("/openapi.json").await;
    let schemas = &spec["components"]["schemas"];
    assert_eq!(
        schemas["StepRequest"]["properties"]["particles"]["maximum"],
        4
    );
    assert_eq!(
        schemas["StepRequest"]["properties"]["states"]["maxItems"],
        16
    );
    assert_eq!(
        schemas["RolloutRequest"]["properties"]["horizon"]["maximum"],
        20
    );
    assert_eq!(
        schemas["EvaluateRequest"]["properties"]["episodes"]["maximum"],
        2
    );
    let work = tempfile::tempdir().unwrap();
    let (base, dir) = (server.socket().0.to_string(), work.path().to_path_buf());
    tokio::task::spawn_blocking(move || {
        common::run_python("contract.py", &[base.as_str(), MODEL, "50"], &dir)
    })
    .await
    .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
async fn a_client_generated_from_the_spec_calls_the_server() {
    let server = Server::listening(limits(), None).await;
    let work = tempfile::tempdir().unwrap();
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("openapi/openapi.json");
    let (base, dir) = (server.socket().0.to_string(), work.path().to_path_buf());
    tokio::task::spawn_blocking(move || {
        common::run_python("openapi_client.py", &[spec.to_str().unwrap(), &base], &dir)
    })
    .await
    .unwrap();
    let result: Value =
        serde_json::from_str(&std::fs::read_to_string(work.path().join("result.json")).unwrap())
            .unwrap();
    assert_eq!(result["models"], json!([MODEL, "no-policy"]));
    let start = {
        let mut s = vec![0.0f32; 11];
        s[0] = 1.25;
        s
    };
    let request = json!({"states": [start, start], "actions": [[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]], "particles": 2, "seed": 3});
    let (_, direct) = server
        .post(&format!("/v1/models/{MODEL}/step"), &request)
        .await;
    let direct: StepResponse = serde_json::from_value(direct).unwrap();
    let eta: Vec<f32> = serde_json::from_value(result["eta"].clone()).unwrap();
    let next: Vec<Vec<Vec<f32>>> = serde_json::from_value(result["next_states"].clone()).unwrap();
    assert_eq!((eta, next), (direct.eta, direct.next_states));
    assert_eq!(result["actions"].as_array().unwrap().len(), 1);
    assert_eq!(
        (
            result["missing_status"].as_u64(),
            result["missing_code"].as_str()
        ),
        (Some(404), Some("model_not_found"))
    );
}

/// The Python package (clients/python, installed into the venv by `make
/// venv`): its generated layer is what the committed spec generates; its
/// `step` answers with the numbers the server's own JSON gives, the same in
/// JSON and in binary; its rollout comes back as `[starts, particles, …]`
/// arrays; `act` as `[batch, act_dim]`; refusals raise `NunoError` with the
/// server's status, code and message.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
async fn the_python_package_calls_the_server_with_numpy_arrays() {
    let server = Server::listening(limits(), None).await;
    let work = tempfile::tempdir().unwrap();
    let (base, dir) = (server.socket().0.to_string(), work.path().to_path_buf());
    tokio::task::spawn_blocking(move || common::run_python("nuno_package.py", &[base], &dir))
        .await
        .unwrap();
    let result: Value =
        serde_json::from_str(&std::fs::read_to_string(work.path().join("result.json")).unwrap())
            .unwrap();
    assert_eq!(
        result["stale"],
        json!([]),
        "regenerate: python clients/python/generate.py"
    );
    assert_eq!(result["models"], json!([MODEL, "no-policy"]));
    assert_eq!(result["kind"], "neural-sde");
    let mut start = vec![0.0f32; 11];
    start[0] = 1.25;
    let request = json!({"states": [start, start], "actions": [[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]],
                         "particles": 2, "seed": 3});
    let (_, direct) = server
        .post(&format!("/v1/models/{MODEL}/step"), &request)
        .await;
    let direct: StepResponse = serde_json::from_value(direct).unwrap();
    let step = &result["step_json"];
    let next: Vec<Vec<Vec<f32>>> = serde_json::from_value(step["next_states"].clone()).unwrap();
    let eta: Vec<f32> = serde_json::from_value(step["eta"].clone()).unwrap();
    let terminals: Vec<Vec<bool>> = serde_json::from_value(step["terminals"].clone()).unwrap();
    assert_eq!(
        (next, eta, terminals),
        (direct.next_states, direct.eta, direct.terminals)
    );
    assert_eq!(result["step_binary_equal"], true);
    assert_eq!(
        result["rollout_shapes"],
        json!([[2, 3, 5, 11], [2, 3, 4, 3], [2, 3, 4]])
    );
    assert_eq!(result["act"].as_array().unwrap().len(), 2);
    assert_eq!(result["act"][0].as_array().unwrap().len(), 3);
    let errors = &result["errors"];
    assert_eq!(
        (&errors["missing"]["status"], &errors["missing"]["code"]),
        (&json!(404), &json!("model_not_found"))
    );
    assert_eq!(errors["narrow"]["status"], 422, "{errors}");
    assert!(
        errors["narrow"]["message"]
            .as_str()
            .unwrap()
            .contains("expects 11"),
        "{errors}"
    );
    // nuno.gym.ModelEnv passed Gymnasium's check_env in the script.
    let gym = &result["gym"];
    assert_eq!(
        gym["action_box"],
        json!([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    );
    assert_eq!(gym["repeats"], true, "a seeded episode repeats");
    assert_eq!(gym["first_step_is_the_servers"], true);
    assert_eq!(gym["truncated_at_limit"], json!([false, false, false]));
    // nuno.gym.ModelVectorEnv: batched spaces, one server step per vector step,
    // every episode ended at the limit, then Gymnasium's NEXT_STEP autoreset.
    let vector = &result["vector"];
    assert_eq!(vector["spaces"], json!([[3, 11], [3, 3]]));
    assert_eq!(vector["first_step_is_the_servers"], true);
    assert_eq!(vector["ended_at_limit"], json!([true, true, true]));
    assert_eq!(vector["autoreset"], true);
    // score: the server's own JSON answer to the same request.
    let candidates: Vec<f32> = (0..72)
        .map(|i| (f64::from(i) / 71.0 - 0.5) as f32)
        .collect();
    let nested: Vec<Vec<Vec<Vec<f32>>>> = candidates
        .chunks(36)
        .map(|b| {
            b.chunks(12)
                .map(|c| c.chunks(3).map(<[f32]>::to_vec).collect())
                .collect()
        })
        .collect();
    let request = json!({"states": [start, start], "actions": nested, "horizon": 4,
                         "particles": 2, "seed": 4, "cvar_alpha": 0.5});
    let (_, direct) = server
        .post(&format!("/v1/models/{MODEL}/score"), &request)
        .await;
    let direct: Vec<Vec<f64>> = (direct["scores"].as_array().unwrap().iter())
        .map(|row| {
            row.as_array()
                .unwrap()
                .iter()
                .map(|c| c["mean_return"].as_f64().unwrap())
                .collect()
        })
        .collect();
    let ours: Vec<Vec<f64>> = serde_json::from_value(result["score_mean_return"].clone()).unwrap();
    for (a, b) in ours.iter().flatten().zip(direct.iter().flatten()) {
        assert!(
            (a - b).abs() <= 1e-6 * b.abs().max(1.0),
            "{ours:?} vs {direct:?}"
        );
    }
    assert_eq!(result["score_shape"], json!([2, 3]));
    assert_eq!(result["plan_actions"], json!([3, 3]));
    assert_eq!(result["plan_first_is_first"], true);
}

/// [`common::bounded::wait_until`] for a condition the test awaits (a server's
/// metrics): panics naming `what` once HANG_BOUND has passed, never earlier.
async fn wait_until_async<F>(what: &str, mut done: impl FnMut() -> F)
where
    F: std::future::Future<Output = bool>,
{
    let deadline = std::time::Instant::now() + common::bounded::HANG_BOUND;
    while !done().await {
        assert!(
            std::time::Instant::now() < deadline,
            "{what}: still waiting after {} min, so it is taken to hang",
            common::bounded::HANG_BOUND.as_secs() / 60
        );
        tokio::time::sleep(common::bounded::POLL).await;
    }
}

/// A compute hook that holds the first computation until `release` is sent or
/// dropped (a failing test drops it; HANG_BOUND past that), and counts every computation.
fn hold_first_computation() -> (ComputeHook, std::sync::mpsc::Sender<()>, Arc<AtomicUsize>) {
    let (release, released) = std::sync::mpsc::channel::<()>();
    let released = Mutex::new(released);
    let started = Arc::new(AtomicUsize::new(0));
    let counter = started.clone();
    let hook = ComputeHook(Arc::new(move || {
        if counter.fetch_add(1, Ordering::SeqCst) == 0 {
            let _ = released
                .lock()
                .unwrap()
                .recv_timeout(common::bounded::HANG_BOUND);
        }
    }));
    (hook, release, started)
}

/// A server with one compute slot, a 1 s timeout, and its first computation
/// held until released (see [`hold_first_computation`]).
async fn one_held_slot() -> (Server, std::sync::mpsc::Sender<()>, Arc<AtomicUsize>) {
    let limits = Limits {
        request_timeout_s: 1,
        compute_slots: 1,
        ..limits()
    };
    let (hook, release, started) = hold_first_computation();
    let server =
        Server::start_with_config(limits, |config| config.before_compute = Some(hook)).await;
    (server, release, started)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_requests_time_out_with_a_json_error_and_keep_their_slot() {
    let (server, release, started) = one_held_slot().await;
    let step = format!("/v1/models/{MODEL}/step");
    let body = json!({"states": upright(2), "actions": actions(2)});
    // The first computation is held until released: whatever the machine's speed,
    // the answer can only come from the timeout.
    let (status, answer) = server.post(&step, &body).await;
    assert_eq!(
        (status, error_code(&answer)),
        (StatusCode::SERVICE_UNAVAILABLE, "timeout")
    );
    // The abandoned work still holds the only slot: the next request waits for it,
    // times out in turn, and its computation never starts.
    let (status, answer) = server.post(&step, &body).await;
    assert_eq!(
        (status, error_code(&answer)),
        (StatusCode::SERVICE_UNAVAILABLE, "timeout")
    );
    assert_eq!(
        started.load(Ordering::SeqCst),
        1,
        "a second computation ran"
    );
    // Once the held work ends, its slot is free again and requests are served.
    // A busy machine may take longer than the 1 s limit to free the slot and
    // compute the next step: such an answer is a timeout again, so the request
    // is repeated until served; a slot never freed hangs it (HANG_BOUND).
    release.send(()).unwrap();
    let deadline = std::time::Instant::now() + common::bounded::HANG_BOUND;
    let (status, answer) = loop {
        let (status, answer) = server.post(&step, &body).await;
        let slow = (status, error_code(&answer)) == (StatusCode::SERVICE_UNAVAILABLE, "timeout");
        if !slow || std::time::Instant::now() > deadline {
            break (status, answer);
        }
    };
    assert_eq!(status, StatusCode::OK, "{answer}");
    assert!(started.load(Ordering::SeqCst) >= 2);
}

/// The answer's size is checked before any work: over the byte budget is a
/// 422 naming the limit; the same request fits in binary (4 bytes a number
/// instead of JSON's 16).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn answers_over_the_byte_budget_are_refused_before_any_work() {
    let limits = Limits {
        max_answer_bytes: 10_000,
        ..limits()
    };
    let server = Server::start(limits, None).await;
    // 20 rows × 4 particles: 20·(3·11 + 1) + 80·(11 + 3) = 1800 numbers.
    let (states, acts) = (upright(20), actions(20));
    let request = json!({"states": states, "actions": acts, "particles": 4});
    let (status, answer) = server
        .post(&format!("/v1/models/{MODEL}/step"), &request)
        .await;
    assert_eq!(
        (status, error_code(&answer)),
        (StatusCode::UNPROCESSABLE_ENTITY, "over_limit")
    );
    let message = answer["error"]["message"].as_str().unwrap();
    assert!(
        message.contains("28800 bytes") && message.contains("max_answer_bytes"),
        "{message}"
    );
    let tensors = nuno::artifact::NamedTensors::from([
        ("states".to_string(), (vec![20, 11], states.concat())),
        ("actions".to_string(), (vec![20, 3], acts.concat())),
    ]);
    let metadata = std::collections::HashMap::from([("particles".to_string(), "4".to_string())]);
    let bytes = nuno::artifact::safetensors_bytes(&tensors, Some(metadata)).unwrap();
    let response = server
        .post_raw(&format!("/v1/models/{MODEL}/step"), BINARY, bytes)
        .await;
    assert_eq!(response.status, StatusCode::OK);
    // A rollout counts (horizon + 1) states and horizon actions, η, Ση and rewards per row.
    let rollout = json!({"states": upright(5), "horizon": 10, "particles": 8});
    let (status, answer) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &rollout)
        .await;
    assert_eq!(
        (status, error_code(&answer)),
        (StatusCode::UNPROCESSABLE_ENTITY, "over_limit"),
        "{answer}"
    );
}

/// `Accept: application/octet-stream` answers a rollout as padded tensors
/// holding the same numbers as its JSON answer.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rollouts_answer_in_binary_with_the_json_numbers() {
    let server = Server::start(limits(), None).await;
    let h = 8;
    let request =
        json!({"states": upright(3), "horizon": h, "particles": 2, "seed": 5, "threshold": 1.5});
    let path = format!("/v1/models/{MODEL}/rollout");
    let (status, body) = server.post(&path, &request).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let json: RolloutResponse = serde_json::from_value(body).unwrap();
    let headers = [("accept", BINARY), ("content-type", "application/json")];
    let r = server
        .request("POST", &path, &headers, request.to_string().into_bytes())
        .await;
    assert_eq!(r.status, StatusCode::OK);
    assert_eq!(r.headers["content-type"], BINARY);
    let bytes = r.body;
    let t = nuno::artifact::parse_safetensors(&bytes, Path::new("answer")).unwrap();
    assert_eq!(t["states"].0, vec![6, h + 1, 11]);
    assert_eq!(t["eta"].0, vec![6, h]);
    for (row, trajectory) in json.trajectories.iter().enumerate() {
        assert_eq!(t["length"].1[row], trajectory.length as f32);
        let outcome = match (
            trajectory.terminal,
            trajectory.truncated,
            trajectory.diverged,
        ) {
            (true, _, _) => 1.0,
            (_, true, _) => 2.0,
            (_, _, true) => 3.0,
            _ => 0.0,
        };
        assert_eq!(t["outcome"].1[row], outcome, "row {row}");
        let states = &t["states"].1[row * (h + 1) * 11..(row + 1) * (h + 1) * 11];
        let kept = trajectory.states.concat();
        assert_eq!(&states[..kept.len()], &kept[..], "row {row} states");
        assert!(
            states[kept.len()..].iter().all(|x| x.is_nan()),
            "row {row} padding"
        );
        let eta = &t["eta"].1[row * h..(row + 1) * h];
        assert_eq!(&eta[..trajectory.eta.len()], &trajectory.eta[..]);
        let penalised = &t["penalized_rewards"].1[row * h..(row + 1) * h];
        assert_eq!(
            &penalised[..trajectory.penalized_rewards.len()],
            &trajectory.penalized_rewards[..]
        );
    }
    assert!(
        json.trajectories.iter().any(|t| t.truncated),
        "the threshold truncates some rollouts, so padding is exercised"
    );
}

/// A request that times out while its computation waits (held by the hook)
/// leaves the work cancelled: it stops instead of rolling out, says so in the
/// metrics, and frees the only slot for the next request.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn abandoned_work_is_cancelled_and_frees_its_slot() {
    let (server, release, started) = one_held_slot().await;
    let rollout = json!({"states": upright(4), "horizon": 50, "particles": 8});
    let (status, answer) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &rollout)
        .await;
    assert_eq!(
        (status, error_code(&answer)),
        (StatusCode::SERVICE_UNAVAILABLE, "timeout")
    );
    release.send(()).unwrap();
    // The cancelled work returns at once; wait for it to be counted (an event,
    // not a duration: the loop ends as soon as the metric says so).
    let cancelled = "nuno_computations_cancelled_total 1";
    wait_until_async(cancelled, || async {
        server.metrics().await.contains(cancelled)
    })
    .await;
    let body = json!({"states": upright(2), "actions": actions(2)});
    let (status, answer) = server
        .post(&format!("/v1/models/{MODEL}/step"), &body)
        .await;
    assert_eq!(status, StatusCode::OK, "{answer}");
    assert_eq!(started.load(Ordering::SeqCst), 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_binary_serves_and_stops_cleanly_on_sigterm() {
    use std::io::{BufRead, BufReader};
    use std::process::{Command, Stdio};
    let models = models_dir();
    let mut child = Command::new(env!("CARGO_BIN_EXE_nuno-server"))
        .args([
            "--models",
            models.path().to_str().unwrap(),
            "--addr",
            "127.0.0.1:0",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The first line names the address it bound (read aside, so a server that
    // never says it fails the wait instead of blocking it).
    let stderr = child.stderr.take().unwrap();
    let (sender, first_line) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stderr).read_line(&mut line);
        let _ = sender.send(line);
    });
    let line = first_line
        .recv_timeout(common::bounded::HANG_BOUND)
        .expect("nuno-server never named its address");
    assert!(
        line.contains("serving [\"hopper-random\", \"no-policy\"]"),
        "{line}"
    );
    let addr = line
        .split("http://")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .to_string();
    let client = reqwest::Client::builder()
        .timeout(common::bounded::HANG_BOUND)
        .build()
        .unwrap();
    let health = client
        .get(format!("http://{addr}/readyz"))
        .send()
        .await
        .unwrap();
    assert_eq!(health.status(), StatusCode::OK);
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let exit = common::bounded::wait_within(&mut child, "nuno-server after SIGTERM");
    assert!(exit.success(), "graceful shutdown exits 0, got {exit:?}");
}

#[test]
fn the_binary_refuses_a_zero_limit_by_flag() {
    // A zero limit would refuse every request, or keep no plan session: the
    // binary names the flag and exits. (--print-openapi exits once the flags
    // parse, so a binary that took the 0 ends at once too, with status 0.)
    for flag in [
        "--max-batch",
        "--compute-slots",
        "--request-timeout",
        "--plan-sessions",
    ] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_nuno-server"))
            .args(["--print-openapi", flag, "0"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag}: {stderr}");
        assert!(
            stderr.contains(&format!("invalid value '0' for '{flag}")),
            "{stderr}"
        );
        assert!(out.stdout.is_empty(), "{flag}: the spec was printed");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_burn_kernel_answers_with_burns_numbers() {
    let server = Server::start_with_config(limits(), |config| config.kernel = Kernel::Burn).await;
    let (states, actions) = (upright(3), vec![vec![0.3f32, -0.2, 0.9]; 3]);
    let request = json!({"states": states, "actions": actions, "noise_scale": 0.0});
    let (status, body) = server
        .post(&format!("/v1/models/{MODEL}/step"), &request)
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: StepResponse = serde_json::from_value(body).unwrap();
    let (model, _) = load_dynamics(&shipped(), &Device::flex()).unwrap();
    let burn = BatchDynamics::step(&model, &states.concat(), &actions.concat(), &[0.0; 33]);
    assert_eq!(r.mean.concat(), burn.means);
    assert_eq!(r.eta, burn.eta);
    let (_, body) = server
        .post(
            &format!("/v1/models/{MODEL}/act"),
            &json!({"states": states}),
        )
        .await;
    let r: ActResponse = serde_json::from_value(body).unwrap();
    let (actor, _) = nuno::artifact::load_policy(
        &server.models_path.join(MODEL),
        BEST_POLICY,
        &Device::flex(),
    )
    .unwrap();
    let burn = ActorPolicy {
        actor,
        mode: ActionMode::Deterministic,
    };
    assert_eq!(
        r.actions.concat(),
        burn.act(&states.concat(), &mut rand::rng())
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gaussian_ensemble_is_served_by_the_same_routes() {
    use nuno::ensemble::{EnsembleConfig, EnsembleDynamics, EnsembleUncertainty, fit_ensemble};
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let policy = nuno::agent::PortableActor::rlkit_random(11, 3, &[32, 32], 0);
    let data = nuno::data::generate(
        &nuno::data::GenerateConfig::new(task.clone(), "random", 1000, 0),
        &policy,
        "test",
        &|_| {},
    )
    .unwrap();
    let config = EnsembleConfig::new()
        .with_members(3)
        .with_elites(2)
        .with_hidden(vec![16, 16])
        .with_weight_decay(vec![2.5e-5, 5e-5, 1e-4])
        .with_max_epochs(Some(2));
    let fit = fit_ensemble(
        &data,
        &config,
        Kernel::Fused,
        &Device::flex(),
        None,
        &mut |_| Ok(()),
    )
    .unwrap();
    let models = tempfile::tempdir().unwrap();
    copy_model(&models.path().join(MODEL));
    nuno::artifact::save_ensemble(
        &models.path().join("mopo"),
        &fit,
        &config,
        &System::Task(task),
        None,
    )
    .unwrap();
    let (server, loaded) = Server::start_on(models, limits(), |_| {}, false).await;
    assert_eq!(loaded, vec![MODEL.to_string(), "mopo".to_string()]);

    let (_, list) = server.get("/v1/models").await;
    let list: ModelList = serde_json::from_value(list).unwrap();
    let kinds: Vec<Value> = list.models.iter().map(|m| json!(m.kind)).collect();
    assert_eq!(kinds, vec![json!("neural-sde"), json!("gaussian-ensemble")]);
    let ensemble = &list.models[1];
    assert!(ensemble.reward_model && !ensemble.has_policy);
    assert_eq!((ensemble.obs_dim, ensemble.act_dim), (11, 3));
    assert!(
        (ensemble.dt - 0.008).abs() < 1e-12,
        "one step is one task step"
    );
    let (status, detail) = server.get("/v1/models/mopo").await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(detail["kind"], "gaussian-ensemble");
    assert_eq!(detail["hyperparameters"]["members"], 3);
    assert_eq!(detail["training"]["elites"].as_array().unwrap().len(), 2);
    assert!(detail["thresholds"].is_null());

    // step: without noise the middle elite's mean; η is MOPO's max ‖σᵢ‖;
    // rewards are the model's, penalised by λ·η.
    let (states, acts) = (upright(3), actions(3));
    let request = json!({"states": states, "actions": acts, "noise_scale": 0.0, "penalty": 2.0});
    let (status, body) = server.post("/v1/models/mopo/step", &request).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: StepResponse = serde_json::from_value(body).unwrap();
    let library = EnsembleDynamics::new(&fit, 11, 3, EnsembleUncertainty::MaxAleatoric);
    let flat: Vec<f32> = states
        .iter()
        .flat_map(|s| s.iter().copied().chain([0.0]))
        .collect();
    let direct = library.step(&flat, &acts.concat(), &[0.0; 3 * 13]);
    for b in 0..3 {
        for i in 0..11 {
            let expected = direct.means[b * 12 + i];
            assert!((r.mean[b][i] - expected).abs() < 1e-4 * expected.abs().max(1.0));
            assert_eq!(r.next_states[b][0], r.mean[b]);
        }
        assert!((r.eta[b] - direct.eta[b]).abs() < 1e-4 * direct.eta[b]);
        let reward = direct.means[b * 12 + 11];
        assert!((r.rewards[b][0] - reward).abs() < 1e-4 * reward.abs().max(1.0));
        assert!((r.penalized_rewards[b][0] - (r.rewards[b][0] - 2.0 * r.eta[b])).abs() < 1e-4);
    }
    // rollout on given actions: h steps, η at each, no ε table to look up.
    let sequences: Vec<Vec<Vec<f32>>> = acts.iter().map(|a| vec![a.clone(); 4]).collect();
    let request = json!({"states": states, "actions": sequences, "horizon": 4, "seed": 1});
    let (status, body) = server.post("/v1/models/mopo/rollout", &request).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    let r: RolloutResponse = serde_json::from_value(body).unwrap();
    assert_eq!(r.trajectories.len(), 3);
    for t in &r.trajectories {
        assert!(!t.eta.is_empty() && t.eta.len() <= 4);
        assert!(
            t.eta.iter().all(|&e| e > 0.0),
            "MOPO's η is a std: {:?}",
            t.eta
        );
    }
    let (status, body) = server
        .post(
            "/v1/models/mopo/rollout",
            &json!({"states": states, "actions": sequences, "horizon": 4, "alpha": 0.9}),
        )
        .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert!(
        body["error"]["message"].as_str().unwrap().contains("no ε"),
        "{body}"
    );
}

/// A model fitted with NUNO's code's convention samples at the scale its
/// model.json records, and `step` and `rollout` say which scale they used.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn step_and_rollout_sample_at_the_models_recorded_scale() {
    let models = tempfile::tempdir().unwrap();
    let dir = models.path().join(MODEL);
    copy_model(&dir);
    let path = dir.join("model.json");
    let mut json: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let scale = 0.008f32.sqrt();
    json["model"]["sample_noise_scale"] = json!(scale);
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let (server, _) = Server::start_on(models, limits(), |_| {}, false).await;
    let (_, detail) = server.get(&format!("/v1/models/{MODEL}")).await;
    assert_eq!(
        detail["sample_noise_scale"].as_f64().map(|v| v as f32),
        Some(scale)
    );

    let states = vec![vec![1.25f32, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0]; 2];
    let actions = vec![vec![0.1f32, -0.2, 0.3]; 2];
    let step = |noise: Option<f32>| {
        let mut body = json!({"states": states, "actions": actions, "particles": 2, "seed": 3});
        if let Some(noise) = noise {
            body["noise_scale"] = json!(noise);
        }
        let server = &server;
        async move {
            let (status, body) = server
                .post(&format!("/v1/models/{MODEL}/step"), &body)
                .await;
            assert_eq!(status, StatusCode::OK, "{body}");
            serde_json::from_value::<StepResponse>(body).unwrap()
        }
    };
    let (default, calibrated) = (step(None).await, step(Some(1.0)).await);
    assert_eq!(default.noise_scale, scale);
    assert_eq!(calibrated.noise_scale, 1.0);
    // Same seed, same ε: each sample's distance from the mean shrinks by the scale.
    for b in 0..2 {
        for p in 0..2 {
            for i in 0..11 {
                let small = default.next_states[b][p][i] - default.mean[b][i];
                let full = calibrated.next_states[b][p][i] - calibrated.mean[b][i];
                assert!(
                    (small - scale * full).abs() < 1e-5 * (1.0 + full.abs()),
                    "{small} vs {full}"
                );
            }
        }
    }
    let rollout = |noise: Option<f32>| {
        let mut body = json!({"states": states, "actions": [[[0.1, -0.2, 0.3]], [[0.1, -0.2, 0.3]]], "horizon": 1});
        if let Some(noise) = noise {
            body["noise_scale"] = json!(noise);
        }
        let server = &server;
        async move {
            let (status, body) = server
                .post(&format!("/v1/models/{MODEL}/rollout"), &body)
                .await;
            assert_eq!(status, StatusCode::OK, "{body}");
            serde_json::from_value::<RolloutResponse>(body).unwrap()
        }
    };
    assert_eq!(rollout(None).await.noise_scale, scale);
    assert_eq!(rollout(Some(0.5)).await.noise_scale, 0.5);
}

/// Candidates `n` per start, each a scaled copy of [`actions`] so they differ.
fn candidates(starts: usize, n: usize, h: usize) -> Vec<Vec<Vec<Vec<f32>>>> {
    (0..starts)
        .map(|b| {
            (0..n)
                .map(|c| {
                    let scale = 1.0 + 0.3 * (b * n + c) as f32;
                    let scaled = |a: Vec<f32>| a.into_iter().map(|x| x * scale).collect();
                    actions(h).into_iter().map(scaled).collect()
                })
                .collect()
        })
        .collect()
}

/// `score` answers each candidate with the reduction of the rollouts the
/// `rollout` route gives for the same starts (each once per candidate),
/// actions and seed: discounted returns, penalised returns and the CVaR of
/// the worst half, summed here from the rollout's own rewards.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn score_reduces_the_rollouts_of_its_candidates_to_one_answer_each() {
    let server = Server::start(limits(), None).await;
    let (h, n, p, gamma) = (5, 3, 4, 0.9f64);
    let starts = upright(2);
    let plans = candidates(2, n, h);
    let request = json!({"states": starts, "actions": plans, "horizon": h, "particles": p,
        "discount": gamma, "penalty": 0.5, "cvar_alpha": 0.5, "seed": 7});
    let (status, body) = server
        .post(&format!("/v1/models/{MODEL}/score"), &request)
        .await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(
        (body["batch"].as_u64(), body["candidates"].as_u64()),
        (Some(2), Some(3))
    );

    let tiled: Vec<Vec<f32>> = (starts.iter())
        .flat_map(|s| std::iter::repeat_n(s.clone(), n))
        .collect();
    let flat: Vec<Vec<Vec<f32>>> = plans.into_iter().flatten().collect();
    let rollout = json!({"states": tiled, "actions": flat, "horizon": h, "particles": p,
        "penalty": 0.5, "seed": 7});
    let (_, rolled) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &rollout)
        .await;
    let rolled: RolloutResponse = serde_json::from_value(rolled).unwrap();
    let discounted = |values: &[f32], length: usize| -> f64 {
        let terms = values[..length].iter().enumerate();
        terms
            .map(|(k, &v)| gamma.powi(k as i32) * f64::from(v))
            .sum()
    };
    for b in 0..2 {
        for c in 0..n {
            let particles = &rolled.trajectories[(b * n + c) * p..][..p];
            let mut returns: Vec<f64> = (particles.iter())
                .map(|t| discounted(&t.rewards, t.length))
                .collect();
            let penalized: f64 = (particles.iter())
                .map(|t| discounted(&t.penalized_rewards, t.length))
                .sum::<f64>()
                / p as f64;
            let mean = returns.iter().sum::<f64>() / p as f64;
            returns.sort_by(f64::total_cmp);
            let worst_half = (returns[0] + returns[1]) / 2.0;
            let fell = particles.iter().filter(|t| t.terminal).count() as f64 / p as f64;
            let s = &body["scores"][b][c];
            let close = |field: &str, expected: f64| {
                let got = s[field].as_f64().unwrap();
                assert!(
                    (got - expected).abs() < 1e-3 * (1.0 + expected.abs()),
                    "{field}: {s}"
                );
            };
            close("mean_return", mean);
            close("penalized_return", penalized);
            close("cvar_return", worst_half);
            close("terminated", fell);
        }
    }
}

/// Cost terms replace or join the reward: the score of each candidate is
/// worked from the rollout route's own trajectories (same seed) by hand.
#[tokio::test]
async fn score_cost_terms_reward_their_targets() {
    let server = Server::start(limits(), None).await;
    let (h, n, p) = (4, 2, 3);
    let starts = upright(1);
    let plans = candidates(1, n, h);
    // Observation 0 is hopper's torso height, 1 its angle.
    let terms = json!([{"observation": 0, "target": 1.2, "weight": 2.0},
                       {"observation": 1, "target": 0.0}]);
    let score = |replace: bool| {
        json!({"states": starts, "actions": plans, "horizon": h, "particles": p,
            "seed": 3, "cost": {"terms": terms, "replace_reward": replace}})
    };
    let path = format!("/v1/models/{MODEL}/score");
    let (status, added) = server.post(&path, &score(false)).await;
    assert_eq!(status, StatusCode::OK, "{added}");
    let (_, replaced) = server.post(&path, &score(true)).await;

    let flat: Vec<Vec<Vec<f32>>> = plans.iter().flatten().cloned().collect();
    let tiled = vec![starts[0].clone(); n];
    let rollout = json!({"states": tiled, "actions": flat, "horizon": h, "particles": p,
        "seed": 3});
    let (_, rolled) = server
        .post(&format!("/v1/models/{MODEL}/rollout"), &rollout)
        .await;
    let rolled: RolloutResponse = serde_json::from_value(rolled).unwrap();
    for c in 0..n {
        let particles = &rolled.trajectories[c * p..][..p];
        let (mut with_reward, mut costs_alone) = (0.0, 0.0);
        for t in particles {
            for k in 0..t.length {
                let next = &t.states[k + 1];
                let cost = 2.0 * f64::from(next[0] - 1.2).powi(2) + f64::from(next[1]).powi(2);
                with_reward += f64::from(t.rewards[k]) - cost;
                costs_alone -= cost;
            }
        }
        for (body, expected) in [(&added, with_reward), (&replaced, costs_alone)] {
            let got = body["scores"][0][c]["mean_return"].as_f64().unwrap();
            let expected = expected / p as f64;
            assert!(
                (got - expected).abs() < 1e-3 * (1.0 + expected.abs()),
                "candidate {c}: {got} against {expected}"
            );
        }
    }
    // Names need a system that names its observations; indices must fit.
    for (term, needle) in [
        (
            json!({"observation": "height", "target": 1.0}),
            "have no names; give the index",
        ),
        (
            json!({"observation": 11, "target": 1.0}),
            "observation 11 is past the model's 11",
        ),
    ] {
        let mut bad = score(false);
        bad["cost"]["terms"] = json!([term]);
        let (status, body) = server.post(&path, &bad).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
        assert!(body.to_string().contains(needle), "{needle}: {body}");
    }
}

/// Shared candidates are each start's own, repeated; the answer's binary
/// form holds the JSON's numbers; a binary request answers the JSON one's
/// bytes and its wrong metadata or shapes are named; both or neither way of giving candidates,
/// or starts with unequal candidate counts, are refused by name.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shared_candidates_binary_answers_and_bad_score_requests() {
    let server = Server::start(limits(), None).await;
    let path = format!("/v1/models/{MODEL}/score");
    let (h, n) = (4, 2);
    let shared = candidates(1, n, h).remove(0);
    let own = vec![shared.clone(), shared.clone()];
    let base = json!({"states": upright(2), "horizon": h, "particles": 2, "seed": 3});
    let with = |field: &str, value: &Value| {
        let mut request = base.clone();
        request[field] = value.clone();
        request
    };
    let (status, by_start) = server.post(&path, &with("actions", &json!(own))).await;
    assert_eq!(status, StatusCode::OK, "{by_start}");
    let (_, by_shared) = server
        .post(&path, &with("shared_actions", &json!(shared)))
        .await;
    assert_eq!(by_start["scores"], by_shared["scores"]);

    let headers = [("accept", BINARY), ("content-type", "application/json")];
    let body = with("actions", &json!(own)).to_string().into_bytes();
    let answer = server.request("POST", &path, &headers, body).await;
    assert_eq!(answer.status, StatusCode::OK);
    let t = nuno::artifact::parse_safetensors(&answer.body, Path::new("answer")).unwrap();
    assert_eq!(t["mean_return"].0, vec![2, n]);
    for (i, value) in t["mean_return"].1.iter().enumerate() {
        let json = by_start["scores"][i / n][i % n]["mean_return"]
            .as_f64()
            .unwrap();
        assert!((f64::from(*value) - json).abs() < 1e-3 * (1.0 + json.abs()));
    }
    assert!(
        t["cvar_return"].1.iter().all(|v| v.is_nan()),
        "no CVaR asked"
    );

    // The same request as safetensors, by start or shared: the same answer's bytes.
    let states: Vec<f32> = upright(2).concat();
    let own_flat: Vec<f32> = own.concat().concat().concat();
    let shared_flat: Vec<f32> = shared.concat().concat();
    let binary = |tensors: Vec<(&str, Vec<usize>, Vec<f32>)>, metadata: &[(&str, &str)]| {
        let tensors: nuno::artifact::NamedTensors = (tensors.into_iter())
            .map(|(name, shape, values)| (name.to_string(), (shape, values)))
            .collect();
        let metadata = (metadata.iter())
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        nuno::artifact::safetensors_bytes(&tensors, Some(metadata)).unwrap()
    };
    let options = [("particles", "2"), ("seed", "3"), ("horizon", "4")];
    let both_binary = [("accept", BINARY), ("content-type", BINARY)];
    for (name, shape, values) in [
        ("actions", vec![2, n, h, 3], own_flat.clone()),
        ("shared_actions", vec![n, h, 3], shared_flat),
    ] {
        let tensors = vec![
            ("states", vec![2, 11], states.clone()),
            (name, shape, values),
        ];
        let by_binary = server
            .request("POST", &path, &both_binary, binary(tensors, &options))
            .await;
        assert_eq!(by_binary.status, StatusCode::OK, "{name}");
        assert_eq!(by_binary.body, answer.body, "{name}: binary ≠ JSON request");
    }
    let own_tensors = || {
        vec![
            ("states", vec![2, 11], states.clone()),
            ("actions", vec![2, n, h, 3], own_flat.clone()),
        ]
    };
    let wrong_width = vec![
        ("states", vec![2, 11], states.clone()),
        ("actions", vec![2, n, h * 3, 1], own_flat.clone()),
    ];
    for (bytes, needle) in [
        (
            binary(own_tensors(), &[("particle", "2")]),
            "metadata `particle`",
        ),
        (
            binary(own_tensors(), &[("horizon", "5")]),
            "`horizon` is 5 but `actions` has 4",
        ),
        (
            binary(wrong_width, &[]),
            "`actions` has shape [2, 2, 12, 1]",
        ),
    ] {
        let answer = server.request("POST", &path, &both_binary, bytes).await;
        assert_eq!(answer.status, StatusCode::UNPROCESSABLE_ENTITY, "{needle}");
        let text = String::from_utf8_lossy(&answer.body).to_string();
        assert!(text.contains(needle), "{needle}: {text}");
    }

    let mut both = with("actions", &json!(own));
    both["shared_actions"] = json!(shared);
    let uneven = with("actions", &json!([shared.clone(), vec![shared[0].clone()]]));
    for (request, needle) in [
        (both, "exactly one"),
        (base.clone(), "exactly one"),
        (uneven, "`actions[1]` has 1 candidates, `actions[0]` has 2"),
    ] {
        let (status, body) = server.post(&path, &request).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
        let message = body["error"]["message"]
            .as_str()
            .unwrap_or_default()
            .to_string()
            + body["error"].as_str().unwrap_or_default();
        assert!(message.contains(needle), "{needle}: {body}");
    }
}

#[tokio::test]
async fn plan_answers_what_the_score_route_scores_and_a_session_warm_starts() {
    // Sessions that never expire: however slow the machine, the second call finds the first's plan.
    let lasting = Limits {
        plan_session_ttl_s: u64::MAX,
        ..limits()
    };
    let server = Server::start(lasting, None).await;
    let path = format!("/v1/models/{MODEL}/plan");
    let state = upright(1).remove(0);
    let request = json!({"state": state, "planner": "mppi", "horizon": 5, "population": 16,
                         "iterations": 2, "noise_scale": 0.0, "seed": 1, "open_session": true});
    let (status, first) = server.post(&path, &request).await;
    assert_eq!(status, StatusCode::OK, "{first}");
    let actions = first["actions"].as_array().unwrap();
    assert_eq!(actions.len(), 5);
    assert_eq!(first["first_action"], actions[0]);
    assert_eq!(first["warm_started"], false);
    let session = first["session"].as_str().unwrap().to_string();

    // Noise off, one particle: the score route rolls the same plan to the same score.
    let scored = json!({"states": [state], "shared_actions": [actions], "horizon": 5,
                        "noise_scale": 0.0});
    let (status, scores) = server
        .post(&format!("/v1/models/{MODEL}/score"), &scored)
        .await;
    assert_eq!(status, StatusCode::OK, "{scores}");
    let by_route = scores["scores"][0][0]["penalized_return"].as_f64().unwrap();
    let by_plan = first["score"]["penalized_return"].as_f64().unwrap();
    assert!(
        (by_route - by_plan).abs() < 1e-6 * (1.0 + by_plan.abs()),
        "{by_route} vs {by_plan}"
    );
    assert_eq!(first["objective"].as_f64().unwrap(), by_plan);

    let mut next = request.clone();
    next.as_object_mut().unwrap().remove("open_session");
    next["session"] = json!(session);
    let (status, second) = server.post(&path, &next).await;
    assert_eq!(status, StatusCode::OK, "{second}");
    assert_eq!(
        (second["warm_started"].clone(), second["session"].clone()),
        (json!(true), json!(session))
    );

    let with = |field: &str, value: Value| {
        let mut r = request.clone();
        r[field] = value;
        r
    };
    let mut cem_with_temperature = with("planner", json!("cem"));
    cem_with_temperature["temperature"] = json!(1.0);
    for (bad, status_wanted, needle) in [
        (
            with("session", json!("nope")),
            StatusCode::UNPROCESSABLE_ENTITY,
            "not both",
        ),
        (
            cem_with_temperature,
            StatusCode::UNPROCESSABLE_ENTITY,
            "settings of mppi",
        ),
        (
            with("state", json!([1.0, 2.0])),
            StatusCode::UNPROCESSABLE_ENTITY,
            "`state` has 2 values",
        ),
    ] {
        let (status, body) = server.post(&path, &bad).await;
        assert_eq!(status, status_wanted, "{body}");
        assert!(body.to_string().contains(needle), "{needle}: {body}");
    }
    let mut unknown = next.clone();
    unknown["session"] = json!("nope");
    let (status, body) = server.post(&path, &unknown).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{body}");
    assert_eq!(body["error"]["code"], "session_not_found", "{body}");
}

#[tokio::test]
async fn an_expired_session_is_a_404_not_a_cold_start() {
    let expiring = Limits {
        plan_session_ttl_s: 0,
        ..limits()
    };
    let server = Server::start(expiring, None).await;
    let path = format!("/v1/models/{MODEL}/plan");
    let request = json!({"state": upright(1)[0], "planner": "cem", "horizon": 3,
                         "population": 8, "iterations": 1, "open_session": true});
    let (status, first) = server.post(&path, &request).await;
    assert_eq!(status, StatusCode::OK, "{first}");
    let continued = json!({"state": upright(1)[0], "planner": "cem", "horizon": 3,
                           "population": 8, "iterations": 1, "session": first["session"]});
    let (status, body) = server.post(&path, &continued).await;
    assert_eq!(status, StatusCode::NOT_FOUND, "{body}");
    assert!(body.to_string().contains("expired"), "{body}");
}

/// Dynamic batching: while the only compute slot is held (the hook holds
/// the first request's batch), seven step requests of different sizes, seeds
/// and particles queue; once it is released they run as one batch (events,
/// not durations: the test waits for the queue gauge, whatever the machine's
/// speed). Each answer has the same bytes as the same request to a server
/// that runs every request alone.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batched_step_requests_answer_what_they_answer_alone() {
    let requests: Vec<Value> = (0..8)
        .map(|i: usize| {
            let mut states = upright(i + 1);
            for (k, row) in states.iter_mut().enumerate() {
                row[5] += 0.01 * (i * 8 + k) as f32;
            }
            json!({"states": states, "actions": actions(i + 1),
                "particles": 1 + i % 3, "seed": 100 + i as u64})
        })
        .collect();
    batched_requests_answer_what_they_answer_alone("step", requests).await;
}

/// The same for `score`: eight requests of different starts, candidates,
/// horizons, particles, seeds, thresholds and cost terms share one rollout
/// and each answers as alone.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batched_score_requests_answer_what_they_answer_alone() {
    let requests: Vec<Value> = (0..8)
        .map(|i: usize| {
            let (starts, n, h) = (1 + i % 2, 1 + i % 3, 2 + i % 4);
            let mut request = json!({"states": upright(starts), "actions": candidates(starts, n, h),
                "horizon": h, "particles": 1 + i % 3, "seed": 200 + i as u64,
                "discount": 0.9, "cvar_alpha": 0.5});
            if i % 2 == 1 {
                request["threshold"] = json!(0.05 * i as f32);
            }
            if i % 4 == 2 {
                request["cost"] = json!({"terms": [{"observation": 0, "target": 1.2}]});
            }
            request
        })
        .collect();
    batched_requests_answer_what_they_answer_alone("score", requests).await;
}

/// Sends `requests` to `route` on a server that batches, all queued behind
/// one held computation, and to one that runs each alone: the same bytes
/// answer each, and the batcher ran them as two batches (the first request's,
/// then the other seven's).
async fn batched_requests_answer_what_they_answer_alone(route: &str, requests: Vec<Value>) {
    let requests: Vec<Vec<u8>> = (requests.iter())
        .map(|r| serde_json::to_vec(r).unwrap())
        .collect();
    let alone = Limits {
        batch_delay_us: 0,
        ..limits()
    };
    let alone = Server::start(alone, None).await;
    let batching = Limits {
        batch_delay_us: 600_000_000,
        compute_slots: 1,
        ..limits()
    };
    let (hook, release, started) = hold_first_computation();
    let together =
        Arc::new(Server::start_with_config(batching, |c| c.before_compute = Some(hook)).await);
    let path = format!("/v1/models/{MODEL}/{route}");
    let mut batched = tokio::task::JoinSet::new();
    let send = |set: &mut tokio::task::JoinSet<_>, i: usize| {
        let (server, body, path) = (together.clone(), requests[i].clone(), path.clone());
        set.spawn(async move { (i, server.post_raw(&path, "application/json", body).await) });
    };
    send(&mut batched, 0);
    wait_until_async("the first computation", || async {
        started.load(Ordering::SeqCst) == 1
    })
    .await;
    for i in 1..requests.len() {
        send(&mut batched, i);
    }
    let queued = requests.len() - 1;
    let waiting = format!("nuno_batch_queue_requests{{route=\"{route}\"}} {queued}\n");
    wait_until_async(&waiting, || async {
        together.metrics().await.contains(&waiting)
    })
    .await;
    release.send(()).unwrap();
    let mut answers = batched.join_all().await;
    answers.sort_by_key(|(i, _)| *i);
    for ((i, answer), body) in answers.iter().zip(&requests) {
        assert_eq!(answer.status, StatusCode::OK, "request {i}");
        let single = alone
            .post_raw(&path, "application/json", body.clone())
            .await;
        assert_eq!(answer.body, single.body, "request {i}: batched ≠ alone");
    }
    let metrics = together.metrics().await;
    let batches = format!("nuno_batches_total{{route=\"{route}\"}} 2\n");
    assert!(metrics.contains(&batches), "{metrics}");
    let served = format!(
        "nuno_batched_requests_total{{route=\"{route}\"}} {}\n",
        requests.len()
    );
    assert!(metrics.contains(&served), "{metrics}");
}
