// SPDX-License-Identifier: MIT
//! Per-stage wall-clock statistics for benchmarks and progress reports.

use std::time::Instant;

/// Measures elapsed milliseconds.
pub(crate) struct Stopwatch(Instant);

impl Stopwatch {
    pub(crate) fn start() -> Self {
        Self(Instant::now())
    }

    pub(crate) fn ms(&self) -> f64 {
        self.0.elapsed().as_secs_f64() * 1e3
    }
}

/// Samples per stage, in first-seen order.
#[derive(Default)]
pub(crate) struct StageTimes {
    stages: Vec<(String, Vec<f64>)>,
}

/// Median, 95th percentile, min and max of a set of samples.
pub(crate) struct Summary {
    pub(crate) median_ms: f64,
    pub(crate) p95_ms: f64,
    pub(crate) min_ms: f64,
    pub(crate) max_ms: f64,
}

pub(crate) fn summarize(samples: &[f64]) -> Summary {
    let mut s = samples.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |q: f64| s[((s.len() - 1) as f64 * q).round() as usize];
    Summary { median_ms: at(0.5), p95_ms: at(0.95), min_ms: s[0], max_ms: s[s.len() - 1] }
}

impl StageTimes {
    pub(crate) fn record(&mut self, stage: &str, ms: f64) {
        match self.stages.iter_mut().find(|(name, _)| name == stage) {
            Some((_, v)) => v.push(ms),
            None => self.stages.push((stage.to_owned(), vec![ms])),
        }
    }

    /// Whether nothing was recorded.
    pub(crate) fn is_empty(&self) -> bool {
        self.stages.is_empty()
    }

    pub(crate) fn print(&self) {
        println!("{:<40} {:>10} {:>10} {:>10} {:>10} {:>6}", "stage", "median ms", "p95 ms", "min ms", "max ms", "n");
        for (name, samples) in &self.stages {
            let s = summarize(samples);
            println!("{name:<40} {:>10.3} {:>10.3} {:>10.3} {:>10.3} {:>6}", s.median_ms, s.p95_ms, s.min_ms, s.max_ms, samples.len());
        }
    }

    pub(crate) fn to_json(&self) -> serde_json::Value {
        self.stages
            .iter()
            .map(|(name, samples)| {
                let s = summarize(samples);
                (name.clone(), serde_json::json!({ "median": s.median_ms, "p95": s.p95_ms, "min": s.min_ms, "max": s.max_ms, "n": samples.len() }))
            })
            .collect::<serde_json::Map<_, _>>()
            .into()
    }
}
