//! Instrumentation of a forward pass: an optional trace of named tensors and an optional stage
//! clock, handed down as one argument.
//!
//! Design decision: the production code records and times its stages through a [`Probe`]; an
//! empty probe ([`Probe::none`]) runs each stage and nothing else, so the instrumented path is
//! the only path. A recorded name is formatted only when a trace is present.

use std::collections::BTreeMap;
use std::fmt::Display;

use burn::tensor::Tensor;

use crate::timing::StageClock;

/// Named intermediate tensors of one forward pass, for conformance checks.
pub type Trace = BTreeMap<String, Tensor<4>>;

/// Where a forward pass reports its intermediate tensors and stage times; both optional.
#[derive(Debug, Default)]
pub struct Probe<'a> {
    trace: Option<&'a mut Trace>,
    clock: Option<&'a mut StageClock>,
}

impl<'a> Probe<'a> {
    /// A probe recording into `trace` and timing on `clock`, where given.
    pub fn new(trace: Option<&'a mut Trace>, clock: Option<&'a mut StageClock>) -> Self {
        Self { trace, clock }
    }

    /// A probe that records and times nothing.
    pub fn none() -> Self {
        Self::default()
    }

    /// Whether tensors are recorded (a caller may compute a tensor for the trace only).
    pub fn tracing(&self) -> bool {
        self.trace.is_some()
    }

    /// Records `tensor` under `name` if tracing.
    pub fn record(&mut self, name: impl Display, tensor: &Tensor<4>) {
        if let Some(trace) = self.trace.as_deref_mut() {
            trace.insert(name.to_string(), tensor.clone());
        }
    }

    /// Runs `f`, timed as stage `stage` if there is a clock.
    pub fn time<T>(&mut self, stage: &'static str, f: impl FnOnce() -> T) -> T {
        match self.clock.as_deref_mut() {
            Some(clock) => clock.time(stage, f),
            None => f(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_probe_records_and_times_only_what_it_has() {
        let device = burn::tensor::Device::flex();
        let t = Tensor::<4>::ones([1, 1, 2, 2], &device);
        let mut none = Probe::none();
        assert!(!none.tracing());
        none.record("x", &t);
        assert_eq!(none.time("stage", || 3), 3);

        let (mut trace, mut clock) = (Trace::new(), StageClock::new());
        let mut probe = Probe::new(Some(&mut trace), Some(&mut clock));
        assert!(probe.tracing());
        probe.record(format_args!("iter.{}.x", 2), &t);
        assert_eq!(probe.time("stage", || 4), 4);
        assert_eq!(trace.keys().collect::<Vec<_>>(), ["iter.2.x"]);
        assert_eq!(clock.stages()[0].name, "stage");
    }
}
