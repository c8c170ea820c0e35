//! A typed client of `nuno-server`. Requests and answers are the server's own
//! types (`nuno::server`: [`StepRequest`], [`StepResponse`], [`ScoreRequest`],
//! …), so a field the server adds reaches a client build without a copy to
//! keep in step. `step` sends and receives safetensors bodies once a request
//! is large ([`Binary`]), and answers the same [`StepResponse`] either way.
//! Every refusal is a [`ClientError::Api`] with the server's status, code and
//! message. [`blocking::Client`] is the same client without async.
//!
//! ```no_run
//! # async fn run() -> Result<(), nuno_client::ClientError> {
//! use nuno_client::{Client, Rows, StepRequest};
//! let client = Client::new("http://127.0.0.1:8080");
//! let mut states = vec![0.0f32; 11];
//! states[0] = 1.25;
//! let request = StepRequest::new(Rows::new(states, 11), Rows::new(vec![0.0; 3], 3));
//! let step = client.step("hopper-random", &request).await?;
//! println!("η = {:?}, next states {:?}", step.eta, step.next_states);
//! # Ok(()) }
//! ```

pub mod blocking;
mod tensors;

use reqwest::header::{ACCEPT, CONTENT_TYPE};
use serde::Serialize;
use serde::de::DeserializeOwned;

pub use nuno::agent::{ActionMode, ParticleStep};
pub use nuno::planning::{CandidateScore, Planner};
pub use nuno::server::{
    ActRequest, ActResponse, ErrorBody, EvaluateRequest, EvaluateResponse, ModelDetail, ModelList,
    PlanRequest, PlanResponse, RolloutRequest, RolloutResponse, Rows, ScoreRequest, ScoreResponse,
    StepRequest, StepResponse,
};

/// Everything a call can fail with.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The server refused the request: its HTTP status and its error body.
    #[error("{status} {code}: {message}")]
    Api {
        status: u16,
        code: String,
        message: String,
    },
    /// No answer: connection, timeout, or a body that could not be sent.
    #[error("transport: {0}")]
    Transport(#[from] reqwest::Error),
    /// An answer this client could not read.
    #[error("unreadable answer: {0}")]
    Decode(String),
}

/// When `step` sends and receives safetensors bodies instead of JSON.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Binary {
    /// From [`BINARY_FROM_ROWS`] rows × particles on (JSON below: small
    /// requests read better in logs).
    #[default]
    Auto,
    Always,
    Never,
}

/// Rows × particles from which [`Binary::Auto`] goes binary (the Python
/// package's threshold too).
pub const BINARY_FROM_ROWS: usize = 4096;

/// A client of one server (`base`: `http://host:port`).
#[derive(Debug, Clone)]
pub struct Client {
    base: String,
    http: reqwest::Client,
    token: Option<String>,
    binary: Binary,
}

impl Client {
    pub fn new(base: &str) -> Self {
        Self {
            base: base.trim_end_matches('/').to_string(),
            http: reqwest::Client::new(),
            token: None,
            binary: Binary::default(),
        }
    }

    /// Sends `Authorization: Bearer <token>` (a server started with `--token`).
    pub fn with_token(mut self, token: &str) -> Self {
        self.token = Some(token.to_string());
        self
    }

    /// When `step` goes binary.
    pub fn with_binary(mut self, binary: Binary) -> Self {
        self.binary = binary;
        self
    }

    fn request(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        let request = self.http.request(method, format!("{}{path}", self.base));
        match &self.token {
            Some(token) => request.bearer_auth(token),
            None => request,
        }
    }

    /// The answer's bytes, or the server's refusal as [`ClientError::Api`].
    async fn send(&self, request: reqwest::RequestBuilder) -> Result<Vec<u8>, ClientError> {
        let answer = request.send().await?;
        let status = answer.status();
        let bytes = answer.bytes().await?.to_vec();
        if status.is_success() {
            return Ok(bytes);
        }
        Err(match serde_json::from_slice::<ErrorBody>(&bytes) {
            Ok(body) => ClientError::Api {
                status: status.as_u16(),
                code: body.error.code,
                message: body.error.message,
            },
            Err(_) => ClientError::Api {
                status: status.as_u16(),
                code: "http".to_string(),
                message: String::from_utf8_lossy(&bytes).into_owned(),
            },
        })
    }

    async fn get<T: DeserializeOwned>(&self, path: &str) -> Result<T, ClientError> {
        let bytes = self.send(self.request(reqwest::Method::GET, path)).await?;
        decode(&bytes)
    }

    async fn post<B: Serialize, T: DeserializeOwned>(
        &self,
        path: &str,
        body: &B,
    ) -> Result<T, ClientError> {
        let request = self.request(reqwest::Method::POST, path).json(body);
        decode(&self.send(request).await?)
    }

    /// `GET /v1/models`.
    pub async fn models(&self) -> Result<ModelList, ClientError> {
        self.get("/v1/models").await
    }

    /// `GET /v1/models/{id}`: widths, action box, ε table, policy.
    pub async fn model(&self, id: &str) -> Result<ModelDetail, ClientError> {
        self.get(&format!("/v1/models/{id}")).await
    }

    /// `POST /v1/models/{id}/step`, in JSON or safetensors as [`Binary`] says.
    pub async fn step(&self, id: &str, request: &StepRequest) -> Result<StepResponse, ClientError> {
        let rows = request.states.len() * request.particles;
        let binary = match self.binary {
            Binary::Auto => rows >= BINARY_FROM_ROWS,
            Binary::Always => true,
            Binary::Never => false,
        };
        let path = format!("/v1/models/{id}/step");
        if !binary {
            return self.post(&path, request).await;
        }
        let body = tensors::step_body(request)?;
        let http = (self.request(reqwest::Method::POST, &path))
            .header(CONTENT_TYPE, nuno::server::BINARY)
            .header(ACCEPT, nuno::server::BINARY)
            .body(body);
        tensors::step_answer(id, &self.send(http).await?)
    }

    /// `POST /v1/models/{id}/rollout` (JSON).
    pub async fn rollout(
        &self,
        id: &str,
        request: &RolloutRequest,
    ) -> Result<RolloutResponse, ClientError> {
        self.post(&format!("/v1/models/{id}/rollout"), request)
            .await
    }

    /// `POST /v1/models/{id}/score` (JSON).
    pub async fn score(
        &self,
        id: &str,
        request: &ScoreRequest,
    ) -> Result<ScoreResponse, ClientError> {
        self.post(&format!("/v1/models/{id}/score"), request).await
    }

    /// `POST /v1/models/{id}/plan`.
    pub async fn plan(&self, id: &str, request: &PlanRequest) -> Result<PlanResponse, ClientError> {
        self.post(&format!("/v1/models/{id}/plan"), request).await
    }

    /// `POST /v1/models/{id}/act`: the served policy's actions.
    pub async fn act(&self, id: &str, request: &ActRequest) -> Result<ActResponse, ClientError> {
        self.post(&format!("/v1/models/{id}/act"), request).await
    }

    /// `POST /v1/models/{id}/evaluate`: the policy in the real MuJoCo task.
    pub async fn evaluate(
        &self,
        id: &str,
        request: &EvaluateRequest,
    ) -> Result<EvaluateResponse, ClientError> {
        self.post(&format!("/v1/models/{id}/evaluate"), request)
            .await
    }
}

fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ClientError> {
    serde_json::from_slice(bytes).map_err(|e| ClientError::Decode(e.to_string()))
}
