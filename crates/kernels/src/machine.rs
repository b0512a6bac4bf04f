//! The machine line every timing prints, so that timings from different machines are not
//! compared by mistake: the processor, the vector instructions the matrix products use and the
//! unit of bf16 products. It lives here because the last two are what this crate's products take
//! on this machine (the `gemm` crate's kernels, [`crate::bf16_unit`]).

/// The processor's name from the first `model name` line of a `/proc/cpuinfo` text.
fn cpu_model_name(cpuinfo: &str) -> Option<&str> {
    let line = cpuinfo.lines().find(|l| l.starts_with("model name"))?;
    Some(line.split_once(':')?.1.trim()).filter(|name| !name.is_empty())
}

/// The widest vector instructions the matrix products use on this CPU: the `gemm` crate picks
/// its AVX-512 kernels where the CPU has them (its `x86-v4` feature), else its AVX2/FMA ones,
/// else scalar code; on other architectures, the architecture's name.
fn vector_level() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            "AVX-512"
        } else if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
            "AVX2+FMA"
        } else {
            "x86-64 without AVX2"
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::env::consts::ARCH
    }
}

/// One line naming the machine (`machine: PROCESSOR, VECTOR LEVEL, bf16 on UNIT`): the processor
/// (Linux), the vector level of the products and the unit of bf16 products (AMX tiles or
/// AVX512-BF16).
pub fn machine_line() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let bf16 = crate::dispatch::bf16_unit().map_or("no bf16 unit".into(), |unit| format!("bf16 on {unit}"));
    format!("machine: {}, {}, {bf16}", cpu_model_name(&cpuinfo).unwrap_or("processor not reported"), vector_level())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_processor_is_named_from_cpuinfo() {
        let cpuinfo = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R) Processor @ 2.50GHz\n\nprocessor\t: 1\nmodel name\t: other\n";
        assert_eq!(cpu_model_name(cpuinfo), Some("Intel(R) Xeon(R) Processor @ 2.50GHz"));
        assert_eq!(cpu_model_name("processor\t: 0\n"), None);
        assert_eq!(cpu_model_name("model name\t:   \n"), None);
        assert!(machine_line().starts_with("machine: "));
    }
}
