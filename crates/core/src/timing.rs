//! Wall-clock time per named stage, for profiling a forward pass without a second copy of it.
//!
//! Design decision: the production code takes an optional [`StageClock`] and wraps each stage in
//! [`timed`]; with `None` it runs the stage and nothing else. The CPU backend executes every
//! operation eagerly, so the time a closure takes is the time of its stage. A stage that runs
//! several times (the update iterations) accumulates its seconds and counts its calls. A GPU
//! backend queues operations and returns at once, so a clock made with [`StageClock::synced`]
//! waits for the device before and after each stage: slower, but each stage's time is its own.
//! A clock given a meter ([`StageClock::metered`], e.g. the kernels' operation count) also
//! attributes to each stage what the meter advanced over its spans. Beside the clock, what a
//! timing of whole runs reads of its process ([`process_cpu_seconds`], [`peak_memory_bytes`])
//! and how it summarises its runs ([`median`]).

use std::time::Instant;

/// The accumulated time of one named stage.
#[derive(Debug, Clone, PartialEq)]
pub struct StageSeconds {
    /// Stage name.
    pub name: &'static str,
    /// Wall-clock seconds, all calls together.
    pub seconds: f64,
    /// CPU seconds of the whole process (all threads) over the same spans; `NaN` where the
    /// system does not report them ([`process_cpu_seconds`]). Over `seconds`: the cores busy
    /// on average while the stage ran.
    pub cpu_seconds: f64,
    /// How many times it ran.
    pub calls: usize,
    /// How far the clock's meter advanced over the stage's spans (0 without a meter).
    pub work: u64,
}

/// Stages in order of their first call, with their accumulated times.
#[derive(Debug, Clone, Default)]
pub struct StageClock {
    stages: Vec<StageSeconds>,
    sync: Option<burn::tensor::Device>,
    meter: Option<fn() -> u64>,
}

impl StageClock {
    /// An empty clock.
    pub fn new() -> Self {
        Self::default()
    }

    /// A clock that waits for `device` to finish its queued work before and after each stage
    /// (needed on a GPU, harmless on the CPU).
    pub fn synced(device: burn::tensor::Device) -> Self {
        Self { sync: Some(device), ..Self::default() }
    }

    /// This clock, also adding to each stage the advance of `meter` (a monotonic reading, such
    /// as the operations counted so far) over its spans.
    pub fn metered(self, meter: fn() -> u64) -> Self {
        Self { meter: Some(meter), ..self }
    }

    fn wait(&self) {
        if let Some(d) = &self.sync {
            // A failed sync surfaces again at the next read of a result; timing needs no error.
            let _ = d.sync();
        }
    }

    /// Runs `f`, adding its wall-clock and CPU time to stage `name`.
    pub fn time<T>(&mut self, name: &'static str, f: impl FnOnce() -> T) -> T {
        self.wait();
        let (start, cpu_start) = (Instant::now(), process_cpu_seconds());
        let work_start = self.meter.map_or(0, |meter| meter());
        let out = f();
        self.wait();
        let seconds = start.elapsed().as_secs_f64();
        let cpu_seconds = process_cpu_seconds().zip(cpu_start).map_or(f64::NAN, |(end, start)| end - start);
        let work = self.meter.map_or(0, |meter| meter().wrapping_sub(work_start));
        match self.stages.iter_mut().find(|s| s.name == name) {
            Some(s) => {
                s.seconds += seconds;
                s.cpu_seconds += cpu_seconds;
                s.calls += 1;
                s.work += work;
            }
            None => self.stages.push(StageSeconds { name, seconds, cpu_seconds, calls: 1, work }),
        }
        out
    }

    /// The stages timed so far, in order of their first call.
    pub fn stages(&self) -> &[StageSeconds] {
        &self.stages
    }
}

/// CPU seconds (user and system, all threads) this process has used so far, to the
/// nanosecond (`CLOCK_PROCESS_CPUTIME_ID`); `None` other than on Linux with glibc.
pub fn process_cpu_seconds() -> Option<f64> {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `clock_gettime` writes one `timespec` through the valid pointer it is given
        // and reads nothing else.
        #[allow(unsafe_code)]
        let status = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut now) };
        (status == 0).then_some(now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(all(target_os = "linux", target_env = "gnu")))]
    {
        None
    }
}

/// Peak resident memory of this process in bytes (`VmHWM` of `/proc/self/status`), where the
/// system reports it (Linux).
pub fn peak_memory_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The median of `v` (sorted in place; the mean of the middle two for an even count; NaN for
/// none).
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 { v[m] } else { 0.5 * (v[m - 1] + v[m]) }
}

/// Runs `f` under `clock` as stage `name` if there is a clock, else just runs it.
pub fn timed<T>(clock: &mut Option<&mut StageClock>, name: &'static str, f: impl FnOnce() -> T) -> T {
    match clock.as_deref_mut() {
        Some(c) => c.time(name, f),
        None => f(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stages_accumulate_in_order_of_first_call() {
        let mut clock = StageClock::new();
        let mut maybe = Some(&mut clock);
        let a = timed(&mut maybe, "a", || 1);
        timed(&mut maybe, "b", || std::thread::sleep(std::time::Duration::from_millis(2)));
        let a2 = timed(&mut maybe, "a", || 2);
        assert_eq!((a, a2), (1, 2));
        let s = clock.stages();
        assert_eq!(s.iter().map(|s| (s.name, s.calls)).collect::<Vec<_>>(), vec![("a", 2), ("b", 1)]);
        assert!(s[1].seconds >= 0.002);
        // A stage that spins one thread takes CPU time: at least a good part of its wall-clock
        // time (the clock counts the whole process, so other tests' threads may add to it; no
        // upper bound holds).
        if process_cpu_seconds().is_some() {
            let spin = timed(&mut Some(&mut clock), "spin", || {
                let start = Instant::now();
                let mut x = 0u64;
                while start.elapsed().as_secs_f64() < 0.02 {
                    x = std::hint::black_box(x.wrapping_add(1));
                }
                x
            });
            assert!(spin > 0);
            let spun = &clock.stages()[2];
            assert!(spun.cpu_seconds.is_finite() && spun.cpu_seconds >= 0.3 * spun.seconds, "{spun:?}");
        }
        let mut none: Option<&mut StageClock> = None;
        assert_eq!(timed(&mut none, "a", || 3), 3);
    }

    #[test]
    fn a_metered_clock_adds_the_meter_per_stage() {
        use std::sync::atomic::{AtomicU64, Ordering};
        static METER: AtomicU64 = AtomicU64::new(0);
        let mut clock = StageClock::new().metered(|| METER.load(Ordering::Relaxed));
        let mut advance = |name, by| clock.time(name, || METER.fetch_add(by, Ordering::Relaxed));
        advance("a", 5);
        advance("b", 7);
        advance("a", 1);
        METER.fetch_add(100, Ordering::Relaxed); // outside every stage
        let work: Vec<(&str, u64)> = clock.stages().iter().map(|s| (s.name, s.work)).collect();
        assert_eq!(work, [("a", 6), ("b", 7)]);
    }

    #[test]
    fn a_synced_clock_times_device_work() {
        let device = burn::tensor::Device::flex();
        let mut clock = StageClock::synced(device.clone());
        let t = clock.time("ones", || burn::tensor::Tensor::<2>::ones([64, 64], &device).sum());
        assert_eq!(crate::tensor::to_vec(t.reshape([1]))[0], 4096.0);
        assert_eq!(clock.stages()[0].calls, 1);
    }

    #[test]
    fn median_of_even_odd_and_no_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }

    #[test]
    fn peak_memory_and_cpu_time_are_read_on_linux() {
        if cfg!(all(target_os = "linux", target_env = "gnu")) {
            assert!(peak_memory_bytes().unwrap() > 0);
            let before = process_cpu_seconds().unwrap();
            let mut x = 0u64;
            for i in 0..50_000_000u64 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(i);
            }
            std::hint::black_box(x);
            assert!(process_cpu_seconds().unwrap() >= before);
        }
    }
}
