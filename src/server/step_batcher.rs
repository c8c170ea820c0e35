//! Dynamic batching of `step` requests (Triton's `dynamic_batching` with
//! `max_queue_delay_microseconds`): concurrent requests for the same model
//! run as one computation. Their networks' part runs as one call, then each
//! request's own rest (its particles' noise from its own seed, rewards,
//! terminations, its answer) on its rows, so an answer is the same batched or
//! alone: the networks' rows do not depend on one another.
//!
//! A batch forms once a compute slot is free (requests queue while every
//! slot computes, so load makes batches larger), then waits for the requests
//! already in a `step` handler (a lone request never waits), at most
//! `--batch-delay-us`. It runs on that one slot; a request whose client left
//! before its batch ran is skipped, and a batch of such requests runs nothing.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use axum::response::Response;
use tokio::sync::{Notify, Semaphore, mpsc, oneshot};

use super::{ApiError, ComputeHook, LoadedModel, Metrics};
use crate::agent::particle_terms;
use crate::shared::ModelStep;

/// What a request does with its rows of the networks' terms: `(observations,
/// actions, terms)` to its answer.
pub type Finish = Box<dyn FnOnce(&[f32], &[f32], &ModelStep) -> Result<Response, ApiError> + Send>;

/// Where `step` requests queue for their batch.
pub struct StepBatcher {
    delay: Duration,
    max_rows: usize,
    compute: Arc<Semaphore>,
    metrics: Arc<Metrics>,
    hook: Option<ComputeHook>,
    /// Requests in a `step` handler that have not queued yet.
    arriving: Arc<Arriving>,
    /// Started with the first request, on its runtime.
    queue: OnceLock<mpsc::UnboundedSender<Job>>,
}

#[derive(Default)]
struct Arriving {
    count: AtomicUsize,
    changed: Notify,
}

/// Held by a `step` handler from its start until its job is queued (or it
/// gave up), so a batch knows whom to wait for.
pub struct Arrival(Arc<Arriving>);

impl Drop for Arrival {
    fn drop(&mut self) {
        self.0.count.fetch_sub(1, Ordering::SeqCst);
        self.0.changed.notify_one();
    }
}

/// One request's items and the rest of its work.
struct Job {
    model: Arc<LoadedModel>,
    observations: Vec<f32>,
    actions: Vec<f32>,
    finish: Finish,
    reply: oneshot::Sender<Result<Response, ApiError>>,
}

impl StepBatcher {
    /// Batches within `delay` (zero: every request alone), at most `max_rows`
    /// items a call, each batch on one of `compute`'s slots, after `hook`
    /// (as every computation: [`ServerConfig::before_compute`](super::ServerConfig)).
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

    /// The networks' terms of `observations` under `actions` in `model`
    /// ([`particle_terms`]), computed with the rest of its batch, then
    /// `finish` on them: the request's answer.
    pub async fn run(
        &self,
        arrival: Arrival,
        model: Arc<LoadedModel>,
        (observations, actions): (Vec<f32>, Vec<f32>),
        finish: Finish,
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
        let (reply, answer) = oneshot::channel();
        let job = Job {
            model,
            observations,
            actions,
            finish,
            reply,
        };
        let stopped = || ApiError::Internal("the step batcher stopped".into());
        queue.send(job).map_err(|_| stopped())?;
        self.metrics.step_queue(1);
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
            self.metrics.step_queue(-(waiting.len() as i64));
            let mut batches = self.batches(waiting).into_iter();
            if let Some(batch) = batches.next() {
                self.spawn(batch, slot);
            }
            // Other models' requests: each batch on a slot of its own.
            for batch in batches {
                let Ok(slot) = self.compute.clone().acquire_owned().await else {
                    return;
                };
                self.spawn(batch, slot);
            }
        }
    }

    /// `first`, what is queued behind it, and the requests still arriving,
    /// until `max_rows` items, nobody else arriving, or the delay.
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
            let requests = run_batch(batch);
            if requests > 0 {
                metrics.step_batch(requests);
            }
        });
    }

    /// The jobs grouped by model (the same loaded copy), in arrival order,
    /// each group cut at `max_rows` items.
    fn batches(&self, jobs: Vec<Job>) -> Vec<Vec<Job>> {
        let mut batches: Vec<(Vec<Job>, usize)> = Vec::new();
        for job in jobs {
            let rows = job.rows();
            let open = batches.iter_mut().find(|(batch, taken)| {
                Arc::ptr_eq(&batch[0].model, &job.model) && taken + rows <= self.max_rows
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
    fn rows(&self) -> usize {
        self.observations.len() / self.model.obs_dim()
    }
}

/// One network call for the batch's live requests, then each one's own rest
/// on its rows. Returns how many requests it served.
fn run_batch(batch: Vec<Job>) -> usize {
    let live: Vec<Job> = batch.into_iter().filter(|j| !j.reply.is_closed()).collect();
    let Some(first) = live.first() else {
        return 0;
    };
    let served = live.len();
    let model = first.model.clone();
    let dynamics = model.batch_dynamics();
    let observations: Vec<f32> = live.iter().flat_map(|j| j.observations.clone()).collect();
    let actions: Vec<f32> = live.iter().flat_map(|j| j.actions.clone()).collect();
    let terms = particle_terms(dynamics, &observations, &actions);
    let mut start = 0;
    for job in live {
        let rows = job.rows();
        let own = terms.rows(start..start + rows, dynamics.state_dim());
        let answer = (job.finish)(&job.observations, &job.actions, &own);
        let _ = job.reply.send(answer);
        start += rows;
    }
    served
}
