//! The client against a real server on loopback (the shipped hopper-random
//! model and its policy): typed answers equal to the server's raw JSON, the
//! binary step equal to the JSON one, refusals carrying the server's status,
//! code and message, and the blocking client.

use std::path::Path;

use nuno::infer::Kernel;
use nuno::server::{AppState, Limits, ServerConfig, serve};
use nuno_client::{
    ActRequest, Binary, Client, ClientError, PlanRequest, Planner, RolloutRequest, Rows,
    ScoreRequest, StepRequest, blocking,
};

const MODEL: &str = "hopper-random";
const TOKEN: &str = "client-test";

/// A server on 127.0.0.1:0 serving a copy of the shipped model; its base URL.
async fn server() -> (String, tempfile::TempDir) {
    let models = tempfile::tempdir().unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../models")
        .join(MODEL);
    let dir = models.path().join(MODEL);
    std::fs::create_dir_all(&dir).unwrap();
    for file in [
        "model.json",
        "dynamics.safetensors",
        "policy.json",
        "policy.safetensors",
    ] {
        std::fs::copy(shipped.join(file), dir.join(file)).unwrap();
    }
    let config = ServerConfig {
        models_dir: models.path().to_path_buf(),
        limits: Limits::default(),
        token: Some(TOKEN.to_string()),
        kernel: Kernel::default(),
        before_compute: None,
    };
    let (state, report) = AppState::new(config);
    assert_eq!(report.loaded, vec![MODEL.to_string()]);
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    tokio::spawn(serve(state, listener));
    (base, models)
}

/// `n` upright hopper states, a little apart, and actions for them.
fn batch(n: usize) -> (Rows, Rows) {
    let mut states = vec![0.0f32; n * 11];
    for (i, row) in states.chunks_mut(11).enumerate() {
        row[0] = 1.25;
        row[5] = 0.01 * i as f32;
    }
    let actions: Vec<f32> = (0..n * 3)
        .map(|i| ((i as f32) * 0.37).sin() * 0.5)
        .collect();
    (Rows::new(states, 11), Rows::new(actions, 3))
}

/// `typed` equals the server's raw JSON answer read as the same type (JSON's
/// f32 digits read into f32 again, so the values compare exactly).
fn assert_same<T: serde::Serialize + serde::de::DeserializeOwned>(
    what: &str,
    typed: &T,
    raw: serde_json::Value,
) {
    let raw: T = serde_json::from_value(raw).unwrap();
    assert_eq!(
        serde_json::to_value(typed).unwrap(),
        serde_json::to_value(&raw).unwrap(),
        "{what}"
    );
}

/// The server's own JSON answer to `body` at `path`, untyped.
async fn raw(base: &str, path: &str, body: &impl serde::Serialize) -> serde_json::Value {
    let answer = reqwest::Client::new()
        .post(format!("{base}{path}"))
        .bearer_auth(TOKEN)
        .json(body)
        .send()
        .await
        .unwrap();
    assert!(
        answer.status().is_success(),
        "{}",
        answer.text().await.unwrap()
    );
    answer.json().await.unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn typed_answers_are_the_servers_and_binary_steps_equal_json_ones() {
    let (base, _models) = server().await;
    let client = Client::new(&base).with_token(TOKEN);
    let detail = client.model(MODEL).await.unwrap();
    assert_eq!((detail.summary.obs_dim, detail.summary.act_dim), (11, 3));
    assert_eq!(client.models().await.unwrap().models.len(), 1);

    let (states, actions) = batch(5);
    let mut request = StepRequest::new(states.clone(), actions.clone());
    (request.particles, request.seed, request.penalty) = (3, 7, 0.5);
    let json = client
        .clone()
        .with_binary(Binary::Never)
        .step(MODEL, &request)
        .await
        .unwrap();
    let binary = client
        .clone()
        .with_binary(Binary::Always)
        .step(MODEL, &request)
        .await
        .unwrap();
    let path = format!("/v1/models/{MODEL}/step");
    let server = raw(&base, &path, &request).await;
    assert_same("typed JSON step", &json, server.clone());
    assert_same("binary step", &binary, server);
    assert_eq!(json.next_states.len(), 5);
    assert_eq!(json.next_states[0].len(), 3);

    let mut rollout = RolloutRequest::new(states.clone(), 4);
    rollout.particles = 2;
    let path = format!("/v1/models/{MODEL}/rollout");
    let answer = client.rollout(MODEL, &rollout).await.unwrap();
    assert_same("rollout", &answer, raw(&base, &path, &rollout).await);

    let candidates = (0..5)
        .map(|b| {
            (0..2)
                .map(|c| Rows::new(vec![0.1 * (b + c) as f32; 4 * 3], 3))
                .collect()
        })
        .collect();
    let score = ScoreRequest::new(states.clone(), candidates, 4);
    let path = format!("/v1/models/{MODEL}/score");
    let answer = client.score(MODEL, &score).await.unwrap();
    assert_same("score", &answer, raw(&base, &path, &score).await);
    assert_eq!((answer.scores.len(), answer.scores[0].len()), (5, 2));

    let state = states.values()[..11].to_vec();
    let plan = PlanRequest::new(state, Planner::Cem, 3, 8, 1);
    let planned = client.plan(MODEL, &plan).await.unwrap();
    assert_eq!((planned.actions.len(), planned.first_action.len()), (3, 3));
    assert_eq!(planned.first_action, planned.actions[0]);

    let act = ActRequest::new(states);
    let path = format!("/v1/models/{MODEL}/act");
    let answer = client.act(MODEL, &act).await.unwrap();
    assert_same("act", &answer, raw(&base, &path, &act).await);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refusals_carry_the_servers_status_code_and_message() {
    let (base, _models) = server().await;
    let client = Client::new(&base).with_token(TOKEN);
    let (states, actions) = batch(2);
    let request = StepRequest::new(states.clone(), actions.clone());
    let api = |e: ClientError| match e {
        ClientError::Api {
            status,
            code,
            message,
        } => (status, code, message),
        other => panic!("an API error expected, got {other}"),
    };

    let (status, code, message) = api(client.step("no-such-model", &request).await.unwrap_err());
    assert_eq!((status, code.as_str()), (404, "model_not_found"));
    assert!(message.contains("no-such-model"), "{message}");

    let narrow = StepRequest::new(Rows::new(vec![0.0; 10], 5), actions);
    for binary in [Binary::Never, Binary::Always] {
        let err = client
            .clone()
            .with_binary(binary)
            .step(MODEL, &narrow)
            .await
            .unwrap_err();
        let (status, code, message) = api(err);
        assert_eq!(
            (status, code.as_str()),
            (422, "invalid_request"),
            "{binary:?}"
        );
        assert!(
            message.contains("states") && message.contains("11"),
            "{message}"
        );
    }

    let anonymous = Client::new(&base);
    let (status, code, _) = api(anonymous.step(MODEL, &request).await.unwrap_err());
    assert_eq!((status, code.as_str()), (401, "unauthorized"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_blocking_client_answers_as_the_async_one() {
    let (base, _models) = server().await;
    let (states, actions) = batch(3);
    let mut request = StepRequest::new(states, actions);
    request.seed = 11;
    let expected = Client::new(&base)
        .with_token(TOKEN)
        .step(MODEL, &request)
        .await
        .unwrap();
    // A thread of its own: a blocking client must not run inside a runtime.
    let answer = std::thread::spawn(move || {
        let client = blocking::Client::new(&base).unwrap().with_token(TOKEN);
        assert_eq!(client.models().unwrap().models.len(), 1);
        client.step(MODEL, &request).unwrap()
    })
    .join()
    .unwrap();
    assert_eq!(
        serde_json::to_value(&answer).unwrap(),
        serde_json::to_value(&expected).unwrap()
    );
}
