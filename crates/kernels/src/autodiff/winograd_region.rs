//! The training forward's Winograd regions: which convolutions of a training forward may take
//! Winograd's rounding.
//!
//! Design decision: Winograd's sums differ from plain products in rounding, and an instance or
//! group norm after a layer divides by that layer's own statistics, which magnifies the
//! difference (the official training step's check fails on the feature encoder's gradients when
//! its layers take Winograd). The convolution cannot see what follows it, so the caller that
//! knows says so: a guard per thread, held by the update loop and by the context encoder with
//! fixed norms.

thread_local! {
    /// [`WinogradForward`] guards alive on this thread.
    static WINOGRAD_FORWARDS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// A region of the training forward whose convolutions feed no norm that divides by the
/// activations' own statistics (instance or group norm, which magnify a change of rounding in the
/// layer before them): while a guard is alive on this thread, `autodiff::conv2d` takes Winograd for
/// every layer that suits it, not only from `autodiff::conv::WINOGRAD_MIN_CHANNELS` input channels.
/// The update loop holds one (`UpdateLoop`), and so does the context encoder where its norms are
/// frozen batch norms or none (around its whole forward, or around the heads alone where its
/// trunk is shared with the feature head). Per thread, so a region open on another thread (a
/// test, a second model) never changes this one's path; not `Send`. Inference takes Winograd
/// everywhere regardless.
#[must_use = "the training forward takes Winograd only while the guard is alive"]
pub struct WinogradForward(std::marker::PhantomData<*const ()>);

impl WinogradForward {
    /// Opens the region on the calling thread.
    pub fn new() -> Self {
        WINOGRAD_FORWARDS.set(WINOGRAD_FORWARDS.get() + 1);
        Self(std::marker::PhantomData)
    }

    /// Whether the calling thread is inside a region.
    pub fn active() -> bool {
        WINOGRAD_FORWARDS.get() > 0
    }
}

impl Default for WinogradForward {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for WinogradForward {
    fn drop(&mut self) {
        WINOGRAD_FORWARDS.set(WINOGRAD_FORWARDS.get() - 1);
    }
}
