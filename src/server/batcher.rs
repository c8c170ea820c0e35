//! Dynamic batching of `step` and `score` requests (Triton's
//! `dynamic_batching` with `max_queue_delay_microseconds`): concurrent
//! requests of one route for the same model run as one computation. A step
//! batch's networks run as one call, then each request's own rest (its
//! particles' noise from its own seed, rewards, terminations, its answer) on
//! its rows; a score batch's candidates share each rollout step's call, each
//! request drawing its noise from its own seed
//! ([`score_groups`](crate::planning::score_groups)). So an answer is the
//! same batched or alone: the networks' rows do not depend on one another.
//!
//! A batch forms once a compute slot is free (requests queue while every
//! slot computes, so load makes batches larger), then waits for the requests
//! already in a `step` or `score` handler (a lone request never waits), at
//! most `--batch-delay-us`. It runs on that one slot; a request whose client
//! left before its batch ran is skipped, a batch of such requests runs
//! nothing, and a score request that times out while its batch runs stops
//! there without stopping the others.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use axum::response::Response;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tokio::sync::{Notify, Semaphore, mpsc, oneshot};

use super::{ApiError, ComputeHook, LoadedModel, Metrics};
use crate::agent::particle_terms;
use crate::planning::{
    CandidateScore, Candidates, PlanningError, ScoreConfig, ScoreGroup, score_groups,
};
use crate::shared::{Cancel, ModelStep};

/// What a step request does with its rows of the networks' terms:
/// `(observations, actions, terms)` to its answer.
pub type StepFinish =
    Box<dyn FnOnce(&[f32], &[f32], &ModelStep) -> Result<Response, ApiError> + Send>;

/// What a score request does with its scores: its answer.
pub type ScoreFinish = Box<
    dyn FnOnce(Result<Vec<CandidateScore>, PlanningError>) -> Result<Response, ApiError> + Send,
>;

/// A request's part of a batch.
pub enum Work {
    Step(StepWork),
    Score(ScoreWork),
}

/// `[rows, obs_dim]` observations under `[rows, act_dim]` actions.
pub struct StepWork {
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    pub finish: StepFinish,
}

/// Candidates to score (as [`Candidates`], owned), with the request's seed
/// and its cancel flag (set when its client leaves or it times out).
pub struct ScoreWork {
    pub starts: Vec<f32>,
    pub sequences: Vec<f32>,
    pub per_start: usize,
    pub config: ScoreConfig,
    pub seed: u64,
    pub cancel: Cancel,
    pub finish: ScoreFinish,
}

impl Work {
    fn route(&self) -> &'static str {
        match self {
            Self::Step(_) => "step",
            Self::Score(_) => "score",
        }
    }
}

/// Where `step` and `score` requests queue for their batch.
pub struct Batcher {
    delay: Duration,
    max_rows: usize,
    compute: Arc<Semaphore>,
    metrics: Arc<Metrics>,
    hook: Option<ComputeHook>,
    /// Requests in a batched handler that have not queued yet.
    arriving: Arc<Arriving>,
    /// Started with the first request, on its runtime.
    queue: OnceLock<mpsc::UnboundedSender<Job>>,
}

#[derive(Default)]
struct Arriving {
    count: AtomicUsize,
    changed: Notify,
}

/// Held by a handler from its start until its job is queued (or it gave
/// up), so a batch knows whom to wait for.
pub struct Arrival(Arc<Arriving>);

impl Drop for Arrival {
    fn drop(&mut self) {
        self.0.count.fetch_sub(1, Ordering::SeqCst);
        self.0.changed.notify_one();
    }
}

/// One request's work and where its answer goes.
struct Job {
    model: Arc<LoadedModel>,
    work: Work,
    reply: oneshot::Sender<Result<Response, ApiError>>,
}

impl Batcher {
    /// Batches within `delay` (zero: every request alone), at most `max_rows`
    /// network rows a call, each batch on one of `compute`'s slots, after
    /// `hook` (as every computation: [`ServerConfig::before_compute`](super::ServerConfig)).
    pub fn new(
        delay: Duration,
        max_rows: usize,
        (compute, hook): (Arc<Semaphore>, Option<ComputeHook>),
        metrics: Arc<Metrics>,
    ) -> Self {
        Self {
            delay,
            max_rows: max_rows.max(1),
            compute,
            metrics,
            hook,
            arriving: Arc::default(),
            queue: OnceLock::new(),
        }
    }

    pub fn enabled(&self) -> bool {
        !self.delay.is_zero()
    }

    /// Says a request is on its way; hold it until [`run`](Self::run).
    pub fn arrival(&self) -> Arrival {
        self.arriving.count.fetch_add(1, Ordering::SeqCst);
        Arrival(self.arriving.clone())
    }

    /// `work` in `model`, computed with the rest of its batch: the request's answer.
    pub async fn run(
        &self,
        arrival: Arrival,
        model: Arc<LoadedModel>,
        work: Work,
    ) -> Result<Response, ApiError> {
        let queue = self.queue.get_or_init(|| {
            let (sender, receiver) = mpsc::unbounded_channel();
            let batches = Batches {
                delay: self.delay,
                max_rows: self.max_rows,
                compute: self.compute.clone(),
                metrics: self.metrics.clone(),
                hook: self.hook.clone(),
                arriving: self.arriving.clone(),
            };
            tokio::spawn(batches.run(receiver));
            sender
        });
        let route = work.route();
        let (reply, answer) = oneshot::channel();
        let job = Job { model, work, reply };
        let stopped = || ApiError::Internal("the batcher stopped".into());
        queue.send(job).map_err(|_| stopped())?;
        self.metrics.batch_queue(route, 1);
        drop(arrival);
        answer.await.map_err(|_| stopped())?
    }
}

/// The batcher's task.
struct Batches {
    delay: Duration,
    max_rows: usize,
    compute: Arc<Semaphore>,
    metrics: Arc<Metrics>,
    hook: Option<ComputeHook>,
    arriving: Arc<Arriving>,
}

impl Batches {
    async fn run(self, mut queue: mpsc::UnboundedReceiver<Job>) {
        while let Some(first) = queue.recv().await {
            let Ok(slot) = self.compute.clone().acquire_owned().await else {
                return;
            };
            let waiting = self.gather(first, &mut queue).await;
            for job in &waiting {
                self.metrics.batch_queue(job.work.route(), -1);
            }
            let mut batches = self.batches(waiting).into_iter();
            if let Some(batch) = batches.next() {
                self.spawn(batch, slot);
            }
            // Other models' or routes' requests: each batch on a slot of its own.
            for batch in batches {
                let Ok(slot) = self.compute.clone().acquire_owned().await else {
                    return;
                };
                self.spawn(batch, slot);
            }
        }
    }

    /// `first`, what is queued behind it, and the requests still arriving,
    /// until `max_rows` rows, nobody else arriving, or the delay.
    async fn gather(&self, first: Job, queue: &mut mpsc::UnboundedReceiver<Job>) -> Vec<Job> {
        let deadline = tokio::time::Instant::now() + self.delay;
        let mut rows = first.rows();
        let mut waiting = vec![first];
        while rows < self.max_rows {
            while let Ok(job) = queue.try_recv() {
                rows += job.rows();
                waiting.push(job);
            }
            if rows >= self.max_rows || self.arriving.count.load(Ordering::SeqCst) == 0 {
                break;
            }
            tokio::select! {
                job = queue.recv() => match job {
                    Some(job) => {
                        rows += job.rows();
                        waiting.push(job);
                    }
                    None => break,
                },
                () = self.arriving.changed.notified() => {}
                () = tokio::time::sleep_until(deadline) => break,
            }
        }
        waiting
    }

    /// Runs `batch` on the blocking pool, on `slot`.
    fn spawn(&self, batch: Vec<Job>, slot: tokio::sync::OwnedSemaphorePermit) {
        let (metrics, hook) = (self.metrics.clone(), self.hook.clone());
        // Requests that gave up while the batch waited for its slot are not
        // computed; a batch of only those never starts.
        let batch: Vec<Job> = batch.into_iter().filter(|j| !j.reply.is_closed()).collect();
        if batch.is_empty() {
            return;
        }
        tokio::task::spawn_blocking(move || {
            let _slot = slot;
            if let Some(ComputeHook(hook)) = hook {
                hook();
            }
            run_batch(batch, &metrics);
        });
    }

    /// The jobs grouped by model (the same loaded copy) and route, in arrival
    /// order, each group cut at `max_rows` rows.
    fn batches(&self, jobs: Vec<Job>) -> Vec<Vec<Job>> {
        let mut batches: Vec<(Vec<Job>, usize)> = Vec::new();
        for job in jobs {
            let rows = job.rows();
            let open = batches.iter_mut().find(|(batch, taken)| {
                Arc::ptr_eq(&batch[0].model, &job.model)
                    && batch[0].work.route() == job.work.route()
                    && taken + rows <= self.max_rows
            });
            match open {
                Some((batch, taken)) => {
                    *taken += rows;
                    batch.push(job);
                }
                None => batches.push((vec![job], rows)),
            }
        }
        batches.into_iter().map(|(batch, _)| batch).collect()
    }
}

impl Job {
    /// The network rows it adds to each call.
    fn rows(&self) -> usize {
        let obs_dim = self.model.obs_dim();
        match &self.work {
            Work::Step(w) => w.observations.len() / obs_dim,
            Work::Score(w) => w.starts.len() / obs_dim * w.per_start * w.config.particles,
        }
    }
}

type Reply = oneshot::Sender<Result<Response, ApiError>>;

/// The batch's live requests (all of one model and route) computed together,
/// each answered.
fn run_batch(batch: Vec<Job>, metrics: &Metrics) {
    let live: Vec<Job> = batch.into_iter().filter(|j| !j.reply.is_closed()).collect();
    let Some(first) = live.first() else {
        return;
    };
    let (model, route, served) = (first.model.clone(), first.work.route(), live.len());
    let mut steps = Vec::new();
    let mut scores = Vec::new();
    for Job { work, reply, .. } in live {
        match work {
            Work::Step(work) => steps.push((work, reply)),
            Work::Score(work) => scores.push((work, reply)),
        }
    }
    run_steps(&model, steps);
    run_scores(&model, scores, metrics);
    metrics.batched(route, served);
}

/// One network call for every step request, then each one's own rest on its rows.
fn run_steps(model: &LoadedModel, jobs: Vec<(StepWork, Reply)>) {
    if jobs.is_empty() {
        return;
    }
    let dynamics = model.batch_dynamics();
    let observations: Vec<f32> = (jobs.iter())
        .flat_map(|(w, _)| w.observations.clone())
        .collect();
    let actions: Vec<f32> = (jobs.iter()).flat_map(|(w, _)| w.actions.clone()).collect();
    let terms = particle_terms(dynamics, &observations, &actions);
    let mut start = 0;
    for (work, reply) in jobs {
        let rows = work.observations.len() / model.obs_dim();
        let own = terms.rows(start..start + rows, dynamics.state_dim());
        let _ = reply.send((work.finish)(&work.observations, &work.actions, &own));
        start += rows;
    }
}

/// Every score request's candidates in one rollout, each answered.
fn run_scores(model: &LoadedModel, jobs: Vec<(ScoreWork, Reply)>, metrics: &Metrics) {
    if jobs.is_empty() {
        return;
    }
    let mut rngs: Vec<ChaCha8Rng> = (jobs.iter())
        .map(|(w, _)| ChaCha8Rng::seed_from_u64(w.seed))
        .collect();
    let groups = (jobs.iter().zip(&mut rngs))
        .map(|((w, _), rng)| ScoreGroup {
            candidates: Candidates {
                starts: &w.starts,
                sequences: &w.sequences,
                per_start: w.per_start,
            },
            config: &w.config,
            rng,
            cancel: &w.cancel,
        })
        .collect();
    let results = score_groups(model.batch_dynamics(), &model.rules, groups);
    for ((work, reply), result) in jobs.into_iter().zip(results) {
        if matches!(result, Err(PlanningError::Cancelled(_))) {
            metrics.cancelled();
        }
        let _ = reply.send((work.finish)(result));
    }
}
