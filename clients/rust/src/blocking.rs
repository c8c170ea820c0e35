//! The same client without async: each call runs the async one to completion
//! on the client's own single-threaded runtime (so it must not be called from
//! inside another tokio runtime, as `reqwest::blocking` must not).

use crate::{
    ActRequest, ActResponse, Binary, ClientError, EvaluateRequest, EvaluateResponse, ModelDetail,
    ModelList, PlanRequest, PlanResponse, RolloutRequest, RolloutResponse, ScoreRequest,
    ScoreResponse, StepRequest, StepResponse,
};

/// A blocking client of one server.
pub struct Client {
    inner: crate::Client,
    runtime: tokio::runtime::Runtime,
}

impl Client {
    pub fn new(base: &str) -> Result<Self, ClientError> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| ClientError::Decode(format!("cannot start the client's runtime: {e}")))?;
        Ok(Self {
            inner: crate::Client::new(base),
            runtime,
        })
    }

    pub fn with_token(mut self, token: &str) -> Self {
        self.inner = self.inner.with_token(token);
        self
    }

    pub fn with_binary(mut self, binary: Binary) -> Self {
        self.inner = self.inner.with_binary(binary);
        self
    }

    pub fn models(&self) -> Result<ModelList, ClientError> {
        self.runtime.block_on(self.inner.models())
    }

    pub fn model(&self, id: &str) -> Result<ModelDetail, ClientError> {
        self.runtime.block_on(self.inner.model(id))
    }

    pub fn step(&self, id: &str, request: &StepRequest) -> Result<StepResponse, ClientError> {
        self.runtime.block_on(self.inner.step(id, request))
    }

    pub fn rollout(
        &self,
        id: &str,
        request: &RolloutRequest,
    ) -> Result<RolloutResponse, ClientError> {
        self.runtime.block_on(self.inner.rollout(id, request))
    }

    pub fn score(&self, id: &str, request: &ScoreRequest) -> Result<ScoreResponse, ClientError> {
        self.runtime.block_on(self.inner.score(id, request))
    }

    pub fn plan(&self, id: &str, request: &PlanRequest) -> Result<PlanResponse, ClientError> {
        self.runtime.block_on(self.inner.plan(id, request))
    }

    pub fn act(&self, id: &str, request: &ActRequest) -> Result<ActResponse, ClientError> {
        self.runtime.block_on(self.inner.act(id, request))
    }

    pub fn evaluate(
        &self,
        id: &str,
        request: &EvaluateRequest,
    ) -> Result<EvaluateResponse, ClientError> {
        self.runtime.block_on(self.inner.evaluate(id, request))
    }
}
