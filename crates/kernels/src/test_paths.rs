//! One test body run on every path of the dispatch, as candle's `test_device!` runs one on
//! every device.

/// Defines a module of tests named `$name` with one test per path (`host`, `gpu_formulation`,
/// `stock`, or the paths listed in brackets), each running `$body` with its path pinned
/// ([`crate::dispatch::with_path`]) and the path as `$path`, so the body can compare what that
/// path computes with a reference (burn's operation under a pinned [`crate::Path::Stock`], or a
/// direct computation).
///
/// ```ignore
/// dgstereo_kernels::test_paths!(fn resize_matches_the_matrices(path) {
///     let got = resize_bilinear(x.clone(), [7, 9], false);
///     let want = with_path(Path::Stock, || resize_bilinear(x, [7, 9], false));
///     assert!(max_abs_diff(got, want) < 1e-5, "{path:?}");
/// });
/// ```
#[macro_export]
macro_rules! test_paths {
    ($(#[$meta:meta])* fn $name:ident($path:ident) $body:block) => {
        $crate::test_paths!([Host, Gpu, Stock] $(#[$meta])* fn $name($path) $body);
    };
    ([$($which:ident),+] $(#[$meta:meta])* fn $name:ident($path:ident) $body:block) => {
        $(#[$meta])*
        #[allow(non_snake_case)]
        mod $name {
            #[allow(unused_imports)]
            use super::*;

            fn body($path: $crate::Path) $body

            $(
                #[test]
                fn $which() {
                    $crate::dispatch::with_path($crate::Path::$which, || body($crate::Path::$which));
                }
            )+
        }
    };
}

#[cfg(test)]
mod tests {
    use crate::dispatch::{Op, path};

    crate::test_paths!(
        /// Each generated test sees its own path pinned.
        fn every_path_is_pinned(pinned) {
            let device = burn::tensor::Device::flex();
            assert_eq!(path(&device, Op::Conv), pinned);
        }
    );
}
