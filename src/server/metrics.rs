//! Prometheus metrics: requests by route and status, latency and batch-size
//! histograms by route, items served per model. Kept in one mutex-guarded
//! table; rendered in the text exposition format at `GET /metrics`.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::sync::Mutex;

const LATENCY_BUCKETS: [f64; 12] = [
    0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 5.0,
];
const BATCH_BUCKETS: [f64; 8] = [1.0, 16.0, 64.0, 256.0, 1024.0, 4096.0, 16384.0, 65536.0];

#[derive(Debug, Clone, Default)]
struct Histogram {
    counts: Vec<u64>,
    sum: f64,
    count: u64,
}

impl Histogram {
    fn observe(&mut self, buckets: &[f64], value: f64) {
        if self.counts.is_empty() {
            self.counts = vec![0; buckets.len()];
        }
        for (count, bound) in self.counts.iter_mut().zip(buckets) {
            if value <= *bound {
                *count += 1;
            }
        }
        self.sum += value;
        self.count += 1;
    }

    fn render(&self, out: &mut String, name: &str, labels: &str, buckets: &[f64]) {
        for (count, bound) in self.counts.iter().zip(buckets) {
            let _ = writeln!(out, "{name}_bucket{{{labels},le=\"{bound}\"}} {count}");
        }
        let _ = writeln!(out, "{name}_bucket{{{labels},le=\"+Inf\"}} {}", self.count);
        let _ = writeln!(out, "{name}_sum{{{labels}}} {}", self.sum);
        let _ = writeln!(out, "{name}_count{{{labels}}} {}", self.count);
    }
}

#[derive(Debug, Default)]
struct Table {
    requests: BTreeMap<(String, u16), u64>,
    latency: BTreeMap<String, Histogram>,
    batch: BTreeMap<String, Histogram>,
    items: BTreeMap<String, u64>,
    cancelled: u64,
    /// Per batched route: batches run, requests they served, requests queued.
    batches: BTreeMap<&'static str, (u64, u64, i64)>,
}

/// The server's metrics.
#[derive(Debug, Default)]
pub struct Metrics {
    table: Mutex<Table>,
}

impl Metrics {
    fn with<T>(&self, f: impl FnOnce(&mut Table) -> T) -> T {
        match self.table.lock() {
            Ok(mut table) => f(&mut table),
            Err(poisoned) => f(&mut poisoned.into_inner()),
        }
    }

    /// One finished request.
    pub fn request(&self, route: &str, status: u16, seconds: f64) {
        self.with(|t| {
            *t.requests.entry((route.to_string(), status)).or_default() += 1;
            t.latency
                .entry(route.to_string())
                .or_default()
                .observe(&LATENCY_BUCKETS, seconds);
        });
    }

    /// A batch of `items` (state-action rows × particles, or rollout steps) served by `model`.
    pub fn batch(&self, route: &str, model: &str, items: usize) {
        self.with(|t| {
            t.batch
                .entry(route.to_string())
                .or_default()
                .observe(&BATCH_BUCKETS, items as f64);
            *t.items.entry(model.to_string()).or_default() += items as u64;
        });
    }

    /// A computation that stopped early because its request was gone.
    pub fn cancelled(&self) {
        self.with(|t| t.cancelled += 1);
    }

    /// One batch of `route` requests run by the batcher, for `requests` requests.
    pub fn batched(&self, route: &'static str, requests: usize) {
        self.with(|t| {
            let entry = t.batches.entry(route).or_default();
            entry.0 += 1;
            entry.1 += requests as u64;
        });
    }

    /// `change` more (or fewer) `route` requests waiting in the batcher's queue.
    pub fn batch_queue(&self, route: &'static str, change: i64) {
        self.with(|t| t.batches.entry(route).or_default().2 += change);
    }

    /// The text exposition format.
    pub fn render(&self) -> String {
        self.with(|t| {
            let mut out = String::new();
            out.push_str("# HELP nuno_requests_total HTTP requests by route and status.\n");
            out.push_str("# TYPE nuno_requests_total counter\n");
            for ((route, status), n) in &t.requests {
                let _ = writeln!(
                    out,
                    "nuno_requests_total{{route=\"{route}\",status=\"{status}\"}} {n}"
                );
            }
            out.push_str("# HELP nuno_request_duration_seconds Request latency by route.\n");
            out.push_str("# TYPE nuno_request_duration_seconds histogram\n");
            for (route, h) in &t.latency {
                let labels = format!("route=\"{route}\"");
                h.render(
                    &mut out,
                    "nuno_request_duration_seconds",
                    &labels,
                    &LATENCY_BUCKETS,
                );
            }
            out.push_str("# HELP nuno_batch_items Items per request by route.\n");
            out.push_str("# TYPE nuno_batch_items histogram\n");
            for (route, h) in &t.batch {
                let labels = format!("route=\"{route}\"");
                h.render(&mut out, "nuno_batch_items", &labels, &BATCH_BUCKETS);
            }
            out.push_str(
                "# HELP nuno_items_total Items served per model (rate() gives items/s).\n",
            );
            out.push_str("# TYPE nuno_items_total counter\n");
            for (model, n) in &t.items {
                let _ = writeln!(out, "nuno_items_total{{model=\"{model}\"}} {n}");
            }
            out.push_str(
                "# HELP nuno_computations_cancelled_total Computations stopped early because their request timed out or its client hung up.\n",
            );
            out.push_str("# TYPE nuno_computations_cancelled_total counter\n");
            let _ = writeln!(out, "nuno_computations_cancelled_total {}", t.cancelled);
            out.push_str("# HELP nuno_batches_total Computations of the batcher (--batch-delay-us) by route; nuno_batched_requests_total / this is the mean requests a computation.\n");
            out.push_str("# TYPE nuno_batches_total counter\n");
            for (route, (batches, _, _)) in &t.batches {
                let _ = writeln!(out, "nuno_batches_total{{route=\"{route}\"}} {batches}");
            }
            out.push_str("# HELP nuno_batched_requests_total Requests served by the batcher's computations, by route.\n");
            out.push_str("# TYPE nuno_batched_requests_total counter\n");
            for (route, (_, requests, _)) in &t.batches {
                let _ = writeln!(out, "nuno_batched_requests_total{{route=\"{route}\"}} {requests}");
            }
            out.push_str("# HELP nuno_batch_queue_requests Requests waiting for the batcher's next batch, by route.\n");
            out.push_str("# TYPE nuno_batch_queue_requests gauge\n");
            for (route, (_, _, queued)) in &t.batches {
                let _ = writeln!(out, "nuno_batch_queue_requests{{route=\"{route}\"}} {queued}");
            }
            out
        })
    }
}
