//! The one settings value that steers the dispatch, read once per process.
//!
//! The binaries set it from their flags before the first operation ([`configure`]); otherwise it
//! is read, once, from the environment variable `DGSTEREO_KERNELS` (the same words as
//! `dgstereo bench --kernels`), so criterion benchmarks and scripts can choose paths too. Nothing
//! changes it afterwards: every operation of a process sees the same settings.
//!
//! The words, comma-separated:
//! - `host` (the default): hand-written kernels for CPU inference, GPU formulations on the GPU;
//! - `stock`: burn's operations everywhere on the CPU (what the kernels gain is measured so);
//! - `stock-training`: burn's own backward passes in training (the operations with a host
//!   backward, `crate::autodiff`, record burn's operations instead);
//! - `gpu-routes`: the GPU formulations on the CPU too, where no host kernel runs (with `stock`,
//!   the CPU computes what GPU inference computes);
//! - `no-winograd`, `no-winograd-blocks`: the host convolution without Winograd's algorithm, or
//!   without its cache-resident blocks;
//! - `bf16-winograd=off|f2|f4`: which Winograd tiles take bf16 products under
//!   [`crate::ProductPrecision::Bf16`] (default `f4`: each layer in bands keeps its tile, the
//!   blocks keep f32; `f2`: every Winograd layer takes F(2x2) in bands with bf16 products;
//!   `off`: Winograd's layers keep f32 products);
//! - `no-amx`: bf16 products ([`crate::ProductPrecision::Bf16`]) on AVX512-BF16 even where the
//!   processor has AMX tiles (to compare the two units);
//! - `stock-route=NAME`: one GPU formulation off ([`GpuRoute::name`]; `all` for every one).

use std::str::FromStr;
use std::sync::OnceLock;

use dgstereo_core::{Error, Problem, Result};

/// The environment variable read when no binary configured the settings.
pub const ENV_VAR: &str = "DGSTEREO_KERNELS";

/// A GPU inference formulation that the settings can turn off (`stock-route=NAME`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GpuRoute {
    /// Stride-1 convolutions as one matrix product (`conv`); off: burn's convolution.
    MatmulConv,
    /// The column matrix of that product gathered by one `select` (`im2col`); off: the shifted
    /// windows sliced one by one and concatenated.
    GatheredColumns,
    /// Strided convolutions through that product too (`strided`); off: burn's convolution.
    StridedProducts,
    /// Convolutions with few outputs as the product first and the shifted sum after
    /// (`few-outputs`); off: the gathered columns.
    FewOutputs,
    /// Bilinear resizes as burn's `interpolate` (`resize`); off: the two interpolation-matrix
    /// products (the training path).
    Interpolate,
    /// The pyramid lookup as two gathers over all levels (`lookup`); off: a gather per level.
    GatheredLookup,
    /// Element-wise work after a convolution's product issued on the product's own shape, so
    /// that burn's fusion runs it in the product's kernel (`epilogue`); off: after the reshape.
    FusedEpilogue,
    /// The ConvGRU's inputs gathered into columns once a step for both its products
    /// (`shared-columns`); off: `[h, x]` and `[r·h, x]` each gathered whole.
    SharedColumns,
}

impl GpuRoute {
    /// Every route.
    pub const ALL: [GpuRoute; 8] = [
        Self::MatmulConv,
        Self::GatheredColumns,
        Self::StridedProducts,
        Self::FewOutputs,
        Self::Interpolate,
        Self::GatheredLookup,
        Self::FusedEpilogue,
        Self::SharedColumns,
    ];

    /// The name `stock-route=` knows the route by.
    pub fn name(self) -> &'static str {
        match self {
            Self::MatmulConv => "conv",
            Self::GatheredColumns => "im2col",
            Self::StridedProducts => "strided",
            Self::FewOutputs => "few-outputs",
            Self::Interpolate => "resize",
            Self::GatheredLookup => "lookup",
            Self::FusedEpilogue => "epilogue",
            Self::SharedColumns => "shared-columns",
        }
    }
}

/// Which Winograd tiles take bf16 products (`bf16-winograd=`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Bf16Winograd {
    /// Winograd's layers keep f32 products (`off`).
    Off,
    /// Winograd's layers run F(2x2) in bands with bf16 products, also where F(4x4) is chosen
    /// in f32 (`f2`): F(4x4)'s transforms grow the inputs' rounding about tenfold.
    F2,
    /// Each layer in bands keeps its tile, with bf16 products; F(4x4) in blocks keeps f32
    /// (`f4`, the default).
    F4,
}

/// What the dispatch may choose ([`crate::dispatch::path`]); the default is every fast path on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Settings {
    /// The hand-written host kernels run CPU inference (`host`; off: `stock`).
    pub host_kernels: bool,
    /// Training on the CPU takes the operations whose backward is the host kernels'
    /// (off: `stock-training`).
    pub host_training: bool,
    /// The GPU formulations also run on the CPU where no host kernel does (`gpu-routes`).
    pub gpu_routes_on_cpu: bool,
    /// 3x3 stride-1 host convolutions may take Winograd's algorithm (off: `no-winograd`).
    pub winograd: bool,
    /// Winograd's F(4x4) may run in cache-resident blocks of tiles (off: `no-winograd-blocks`).
    pub winograd_blocks: bool,
    /// bf16 products may run on AMX tiles (off: `no-amx`, AVX512-BF16 only).
    pub amx: bool,
    /// Which Winograd tiles take bf16 products (`bf16-winograd=`).
    pub bf16_winograd: Bf16Winograd,
    /// GPU formulations switched off (`stock-route=NAME`).
    pub stock_routes: Vec<GpuRoute>,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            host_kernels: true,
            host_training: true,
            gpu_routes_on_cpu: false,
            winograd: true,
            winograd_blocks: true,
            amx: true,
            bf16_winograd: Bf16Winograd::F4,
            stock_routes: Vec::new(),
        }
    }
}

impl Settings {
    /// Whether the GPU formulation `route` may run.
    pub fn route_enabled(&self, route: GpuRoute) -> bool {
        !self.stock_routes.contains(&route)
    }

    /// The settings `DGSTEREO_KERNELS` names (the defaults where it is unset or empty); an error
    /// names the variable, its whole value and the word it does not know (a value that is not
    /// Unicode is an error too).
    pub fn from_env() -> Result<Self> {
        match std::env::var(ENV_VAR) {
            Ok(text) => text.parse().map_err(|e: Error| Error::config(ENV_VAR, format!("'{text}': {}", reason(&e)))),
            Err(std::env::VarError::NotPresent) => Ok(Self::default()),
            Err(std::env::VarError::NotUnicode(text)) => {
                Err(Error::config(ENV_VAR, format!("{text:?} is not Unicode text")))
            }
        }
    }
}

impl FromStr for Settings {
    type Err = Error;

    fn from_str(text: &str) -> Result<Self> {
        let mut settings = Self::default();
        for word in text.split(',').map(str::trim).filter(|w| !w.is_empty()) {
            match word.to_ascii_lowercase().as_str() {
                "host" => settings.host_kernels = true,
                "stock" => {
                    settings.host_kernels = false;
                    settings.host_training = false;
                }
                "stock-training" => settings.host_training = false,
                "gpu-routes" => {
                    settings.host_kernels = false;
                    settings.gpu_routes_on_cpu = true;
                }
                "no-winograd" => settings.winograd = false,
                "no-winograd-blocks" => settings.winograd_blocks = false,
                "no-amx" => settings.amx = false,
                "bf16-winograd=off" => settings.bf16_winograd = Bf16Winograd::Off,
                "bf16-winograd=f2" => settings.bf16_winograd = Bf16Winograd::F2,
                "bf16-winograd=f4" => settings.bf16_winograd = Bf16Winograd::F4,
                other => match other.strip_prefix("stock-route=") {
                    Some("all") => settings.stock_routes = GpuRoute::ALL.to_vec(),
                    Some(name) => match GpuRoute::ALL.into_iter().find(|r| r.name() == name) {
                        Some(route) if !settings.stock_routes.contains(&route) => settings.stock_routes.push(route),
                        Some(_) => {}
                        None => {
                            let names: Vec<_> = GpuRoute::ALL.iter().map(|r| r.name()).collect();
                            return Err(Error::config(
                                "kernels",
                                format!("unknown GPU route '{name}' (expected all or one of {})", names.join(", ")),
                            ));
                        }
                    },
                    None => {
                        return Err(Error::config(
                            "kernels",
                            format!(
                                "unknown kernel setting '{word}' (expected host, stock, stock-training, gpu-routes, \
                                 no-winograd, no-winograd-blocks, bf16-winograd=off|f2|f4, no-amx or \
                                 stock-route=NAME)"
                            ),
                        ));
                    }
                },
            }
        }
        Ok(settings)
    }
}

static SETTINGS: OnceLock<Settings> = OnceLock::new();

/// Fixes the process's settings before the first operation reads them. An error when they were
/// already read or configured otherwise (configuring the same value again is not).
pub fn configure(settings: Settings) -> Result<()> {
    let in_use = SETTINGS.get_or_init(|| settings.clone());
    if *in_use == settings {
        Ok(())
    } else {
        Err(Error::config(
            "kernels",
            format!(
                "the settings are already in use ({in_use:?}); they can be configured once, before the first operation"
            ),
        ))
    }
}

/// Why `DGSTEREO_KERNELS` did not parse, where [`settings`] read it and it did not.
static ENV_PROBLEM: OnceLock<Problem> = OnceLock::new();

/// The process's settings: those [`configure`]d, else `DGSTEREO_KERNELS`'s, read once. An
/// operation cannot return an error, so where the variable does not parse the operations run with
/// the defaults and [`check`] returns the error: every entry point (the binary, a library's
/// constructor) calls [`check`] or `configure(Settings::from_env()?)` before its first operation.
pub fn settings() -> &'static Settings {
    SETTINGS.get_or_init(|| {
        Settings::from_env().unwrap_or_else(|e| {
            let problem = match e {
                Error::Config(problem) => problem,
                other => Problem::new(ENV_VAR, other.to_string()),
            };
            let _ = ENV_PROBLEM.set(problem);
            Settings::default()
        })
    })
}

/// The settings in use, or the error naming `DGSTEREO_KERNELS` and its value where they were
/// read from the variable and it does not parse.
pub fn check() -> Result<&'static Settings> {
    let in_use = settings();
    match ENV_PROBLEM.get() {
        Some(problem) => Err(Error::Config(problem.clone())),
        None => Ok(in_use),
    }
}

/// The reason of a configuration error, without a key of its own.
fn reason(e: &Error) -> String {
    match e {
        Error::Config(problem) => problem.reason.clone(),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_parse_and_unknown_ones_are_named() {
        assert_eq!("".parse::<Settings>().unwrap(), Settings::default());
        let s: Settings = " stock , no-winograd,stock-route=lookup,stock-route=conv".parse().unwrap();
        assert!(!s.host_kernels && !s.winograd && s.winograd_blocks && !s.gpu_routes_on_cpu);
        assert!(!s.route_enabled(GpuRoute::GatheredLookup) && !s.route_enabled(GpuRoute::MatmulConv));
        assert!(s.route_enabled(GpuRoute::Interpolate));
        let g: Settings = "gpu-routes,stock-route=all".parse().unwrap();
        assert!(g.gpu_routes_on_cpu && !g.host_kernels);
        assert!(GpuRoute::ALL.iter().all(|&r| !g.route_enabled(r)));
        let b: Settings = "bf16-winograd=f2,no-amx".parse().unwrap();
        assert!(b.bf16_winograd == Bf16Winograd::F2 && !b.amx && b.host_kernels);
        assert_eq!("bf16-winograd=off".parse::<Settings>().unwrap().bf16_winograd, Bf16Winograd::Off);
        assert_eq!(Settings::default().bf16_winograd, Bf16Winograd::F4);
        let e = "bf16-winograd=f8".parse::<Settings>().unwrap_err().to_string();
        assert!(e.contains("'bf16-winograd=f8'") && e.contains("bf16-winograd=off|f2|f4"), "{e}");
        let e = "fast".parse::<Settings>().unwrap_err().to_string();
        assert!(e.contains("'fast'") && e.contains("gpu-routes"), "{e}");
        let e = "stock-route=warp".parse::<Settings>().unwrap_err().to_string();
        assert!(e.contains("'warp'") && e.contains("shared-columns"), "{e}");
    }

    /// A malformed variable is an error naming the variable and its value.
    #[test]
    fn a_malformed_variable_is_named_with_its_value() {
        let e = Error::config(
            ENV_VAR,
            format!("'{}': {}", "host,fast", reason(&"host,fast".parse::<Settings>().unwrap_err())),
        );
        let text = e.to_string();
        assert!(text.contains(ENV_VAR) && text.contains("'host,fast'") && text.contains("'fast'"), "{text}");
    }

    #[test]
    fn route_names_are_distinct() {
        let mut names: Vec<_> = GpuRoute::ALL.iter().map(|r| r.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), GpuRoute::ALL.len());
    }
}
