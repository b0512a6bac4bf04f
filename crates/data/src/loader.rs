//! A prefetching loader: produces items on rayon's pool ahead of the consumer, in order.
//!
//! A feeder thread takes the indices in chunks of `ahead` items, builds each chunk in parallel
//! on rayon's global pool and sends the items, in index order, through a channel holding at most
//! `ahead` items. So while the consumer works on item `k`, up to `ahead` following items are
//! being loaded or wait ready. Dropping the loader stops the feeder after its current chunk.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, sync_channel};
use std::thread::JoinHandle;

use rayon::prelude::*;

use dgstereo_core::Result;

use crate::datasets::{Dataset, Sample};

/// An iterator over `f(index)` for the given indices, computed ahead in parallel.
pub struct PrefetchLoader<T: Send + 'static> {
    rx: Option<Receiver<T>>,
    feeder: Option<JoinHandle<()>>,
    remaining: usize,
}

impl<T: Send + 'static> PrefetchLoader<T> {
    /// Starts producing `f(i)` for each of `indices`, keeping up to `ahead` (at least 1) items
    /// ahead of the consumer.
    pub fn new<F>(indices: Vec<usize>, ahead: usize, f: F) -> Self
    where
        F: Fn(usize) -> T + Send + Sync + 'static,
    {
        let ahead = ahead.max(1);
        let remaining = indices.len();
        let (tx, rx) = sync_channel::<T>(ahead);
        let feeder = std::thread::spawn(move || {
            for chunk in indices.chunks(ahead) {
                let items: Vec<T> = chunk.par_iter().map(|&i| f(i)).collect();
                for item in items {
                    if tx.send(item).is_err() {
                        return; // the consumer is gone
                    }
                }
            }
        });
        Self { rx: Some(rx), feeder: Some(feeder), remaining }
    }
}

impl PrefetchLoader<Result<Sample>> {
    /// Loads the samples `indices` of `dataset` ahead of the consumer.
    pub fn for_dataset(dataset: Arc<dyn Dataset>, indices: Vec<usize>, ahead: usize) -> Self {
        Self::new(indices, ahead, move |i| dataset.get(i))
    }
}

impl<T: Send + 'static> Iterator for PrefetchLoader<T> {
    type Item = T;

    fn next(&mut self) -> Option<T> {
        let item = self.rx.as_ref()?.recv().ok();
        if item.is_some() {
            self.remaining -= 1;
        }
        item
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.remaining, Some(self.remaining))
    }
}

impl<T: Send + 'static> Drop for PrefetchLoader<T> {
    fn drop(&mut self) {
        // Closing the receiver makes the feeder's next send fail, ending it.
        self.rx.take();
        if let Some(h) = self.feeder.take() {
            let _ = h.join();
        }
    }
}
