//! Experiment files: the resolved configuration of a run (model, prior, loss, training, data).
#![deny(missing_docs)]
