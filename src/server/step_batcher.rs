//! Dynamic batching of `step` requests (Triton's `dynamic_batching` with
//! `max_queue_delay_microseconds`): the networks' part of concurrent requests
//! for the same model that arrive within `--batch-delay-us` of the first runs
//! as one call, and each request gets its rows back. The rest of a step
//! (its particles' noise from its own seed, rewards, terminations, the
//! answer) stays the request's own, so an answer is the same batched or
//! alone: the networks' rows do not depend on one another.
//!
//! The batched call takes one compute slot; a request whose client left
//! before its batch ran is skipped, and a batch of such requests runs nothing.

use std::sync::{Arc, OnceLock};
use std::time::Duration;

use tokio::sync::{Semaphore, mpsc, oneshot};

use super::{ApiError, LoadedModel, Metrics};
use crate::agent::particle_terms;
use crate::shared::ModelStep;

/// Where `step` requests queue for their batch.
pub struct StepBatcher {
    delay: Duration,
    max_rows: usize,
    compute: Arc<Semaphore>,
    metrics: Arc<Metrics>,
    /// Started with the first request, on its runtime.
    queue: OnceLock<mpsc::UnboundedSender<Job>>,
}

/// One request's items, and where its rows go.
struct Job {
    model: Arc<LoadedModel>,
    observations: Vec<f32>,
    actions: Vec<f32>,
    reply: oneshot::Sender<ModelStep>,
}

impl StepBatcher {
    /// Batches within `delay` (zero: every request alone), at most `max_rows`
    /// items a call (a batch that has them runs at once), each call on one of
    /// `compute`'s slots.
    pub fn new(
        delay: Duration,
        max_rows: usize,
        compute: Arc<Semaphore>,
        metrics: Arc<Metrics>,
    ) -> Self {
        Self {
            delay,
            max_rows: max_rows.max(1),
            compute,
            metrics,
            queue: OnceLock::new(),
        }
    }

    pub fn enabled(&self) -> bool {
        !self.delay.is_zero()
    }

    /// The networks' terms of `observations` under `actions` in `model`
    /// ([`particle_terms`]), computed with the other requests of its batch.
    pub async fn terms(
        &self,
        model: Arc<LoadedModel>,
        observations: Vec<f32>,
        actions: Vec<f32>,
    ) -> Result<ModelStep, ApiError> {
        let queue = self.queue.get_or_init(|| {
            let (sender, receiver) = mpsc::unbounded_channel();
            let batches = Batches {
                delay: self.delay,
                max_rows: self.max_rows,
                compute: self.compute.clone(),
                metrics: self.metrics.clone(),
            };
            tokio::spawn(batches.run(receiver));
            sender
        });
        let (reply, answer) = oneshot::channel();
        let job = Job {
            model,
            observations,
            actions,
            reply,
        };
        let stopped = || ApiError::Internal("the step batcher stopped".into());
        queue.send(job).map_err(|_| stopped())?;
        answer.await.map_err(|_| stopped())
    }
}

/// The batcher's task.
struct Batches {
    delay: Duration,
    max_rows: usize,
    compute: Arc<Semaphore>,
    metrics: Arc<Metrics>,
}

impl Batches {
    async fn run(self, mut queue: mpsc::UnboundedReceiver<Job>) {
        while let Some(first) = queue.recv().await {
            let deadline = tokio::time::Instant::now() + self.delay;
            let mut rows = first.rows();
            let mut waiting = vec![first];
            while rows < self.max_rows
                && let Ok(Some(job)) = tokio::time::timeout_at(deadline, queue.recv()).await
            {
                rows += job.rows();
                waiting.push(job);
            }
            for batch in self.batches(waiting) {
                let compute = self.compute.clone();
                let metrics = self.metrics.clone();
                tokio::spawn(async move {
                    let Ok(slot) = compute.acquire_owned().await else {
                        return;
                    };
                    let _ = tokio::task::spawn_blocking(move || {
                        let _slot = slot;
                        let requests = run_batch(batch);
                        if requests > 0 {
                            metrics.step_batch(requests);
                        }
                    })
                    .await;
                });
            }
        }
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

/// One network call for the batch's live requests; each gets its rows.
/// Returns how many requests it served.
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
        let _ = (job.reply).send(terms.rows(start..start + rows, dynamics.state_dim()));
        start += rows;
    }
    served
}
