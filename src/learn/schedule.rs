//! The diffusion process of docs/method.md sections 4-5: the continuous cosine
//! log-SNR schedule, the forward (noising) process, the time embedding, and
//! the reverse steps: [`Schedule`] and [`Sampler`] (DDPM or DDIM).
//!
//! Time is continuous, t in [0, 1]; t = 0 is clean data. The model predicts
//! the clean grid x0 directly; samplers turn that prediction into the next
//! (less noisy) state.

use tch::Tensor;

/// How every network is taught: the schedule, the prediction target, where
/// the training noise comes from and the times each level sees. Recorded in
/// every level's training state (`level_K_state.json`) and part of the
/// training stage's digest, so weights trained under another
/// parameterisation are never silently reused: sampling refuses them.
pub const TRAINING_PARAMETERISATION: &str = "schedule=cosine-log-snr(s=0.008,clamp=1e-5); target=x0; \
     noise=per-step-splitmix64-box-muller; t=[0,1] at level 0, [0,upper_t_max] above";

/// How sampling turns a prediction into a step: the clean estimate clamped
/// per channel to the features' ranges
/// ([`crate::learn::sparse::clamp_to_feature_ranges`]), and the final step's
/// rule ([`FinalStep`], a setting), and what `sample.attempts` keeps. Part of
/// the sampling stage's digest: a change resamples.
pub const SAMPLING_PARAMETERISATION: &str =
    "x0=clamped-per-channel(offset 0.5, normal 1, colour [0,1], mask 1); attempts-keep=first-whole-at-64";

/// The continuous cosine schedule (Nichol & Dhariwal) in log-SNR form, as the
/// released code uses it: log SNR(t) = -log(cos((t+s)/(1+s) * pi/2)^-2 - 1).
/// Only the clean end is clamped (log-SNR at most -ln(clamp) = 11.5, which
/// the offset already keeps t = 0 below: 8.77); the noisy end is finite
/// because cos(pi/2) is 6.1e-17 in f64, not 0: log-SNR(1) = -74.7, alpha(1)
/// = 6.1e-17 (pure noise). Training noises with it and both samplers step with it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// The offset s (0.008).
    pub offset: f64,
    /// Lower clamp of cos^-2 - 1 (1e-5: log-SNR at most ~11.5; the offset keeps
    /// t = 0 below it: log-SNR(0) = 8.77, alpha(0) = 0.99992, sigma(0) = 0.0125).
    pub clamp: f64,
}

impl Default for Schedule {
    fn default() -> Self {
        Schedule { offset: 0.008, clamp: 1e-5 }
    }
}

impl Schedule {
    /// log SNR(t), decreasing in t.
    pub fn log_snr(&self, t: f64) -> f64 {
        let c = ((t + self.offset) / (1.0 + self.offset) * std::f64::consts::FRAC_PI_2).cos();
        let inv = 1.0 / (c * c) - 1.0;
        -(inv.max(self.clamp)).ln()
    }

    /// (alpha, sigma) at time t: alpha^2 = sigmoid(log_snr), sigma^2 = sigmoid(-log_snr).
    pub fn alpha_sigma(&self, t: f64) -> (f64, f64) {
        let l = self.log_snr(t);
        let sig = |x: f64| 1.0 / (1.0 + (-x).exp());
        (sig(l).sqrt(), sig(-l).sqrt())
    }

    /// Forward process: x_t = alpha(t) x0 + sigma(t) eps.
    pub fn add_noise(&self, x0: &Tensor, t: f64, eps: &Tensor) -> Tensor {
        let (a, s) = self.alpha_sigma(t);
        x0 * a + eps * s
    }

    /// Forward process with a time per row (`t`: [rows] of t values), the
    /// same formula as [`Schedule::log_snr`] in tensor form (a batch of crops,
    /// each at its own time).
    pub fn add_noise_rows(&self, x0: &Tensor, t: &Tensor, eps: &Tensor) -> Tensor {
        let arg = (t + self.offset) / (1.0 + self.offset) * std::f64::consts::FRAC_PI_2;
        let c = arg.cos();
        let inv = (c.square().reciprocal() - 1.0).clamp_min(self.clamp);
        let l = -inv.log();
        let alpha = l.sigmoid().sqrt().unsqueeze(1);
        let sigma = (-l).sigmoid().sqrt().unsqueeze(1);
        x0 * alpha + eps * sigma
    }
}

/// The 6-number time embedding of each row: sin and cos of 2^k * pi * t
/// for k = 0, 1, 2, for a batch of times `t` ([rows] f32) -> [rows, 6]
/// (concatenated to each voxel's features by the model).
pub fn time_embedding_rows(t: &Tensor) -> Tensor {
    let mut parts = Vec::with_capacity(6);
    for k in 0..3 {
        let a = t * ((1u32 << k) as f64 * std::f64::consts::PI);
        parts.push(a.sin());
        parts.push(a.cos());
    }
    Tensor::stack(&parts, 1)
}

/// The reverse step from time `t` to an earlier time `s` (< t), given the
/// model's clean-data prediction `x0_hat` (`sample.sampler` in a profile).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Sampler {
    /// Ancestral DDPM in continuous time, as the code: c = -expm1(l_t - l_s);
    /// mean = alpha_s (x_t (1 - c) / alpha_t + c x0_hat); var = sigma_s^2 c.
    Ddpm,
    /// Deterministic DDIM: eps_hat = (x_t - alpha_t x0_hat) / sigma_t;
    /// x_s = alpha_s x0_hat + sigma_s eps_hat.
    Ddim,
}

impl std::fmt::Display for Sampler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Sampler::Ddpm => "ddpm",
            Sampler::Ddim => "ddim",
        })
    }
}

/// The rule of the last reverse step (to t = 0): `sample.final_step`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum FinalStep {
    /// The (clamped) clean prediction itself, as the released code ends: no
    /// noise is added at the end, and nothing is scaled by alpha(0).
    #[default]
    Prediction,
    /// The sampler's own update to t = 0, like every other step: the clamped
    /// schedule has alpha(0) = 0.99992 and sigma(0) = 0.0125, so DDPM adds a
    /// last bit of noise and both scale the features by alpha(0).
    Update,
}

impl FinalStep {
    pub fn is_default(&self) -> bool {
        *self == FinalStep::default()
    }
}

/// One reverse step from `t` to `s`, the last one (s = 0) by `final_step`.
#[allow(clippy::too_many_arguments)]
pub fn reverse_step(
    sampler: Sampler,
    final_step: FinalStep,
    schedule: &Schedule,
    x_t: &Tensor,
    x0_hat: &Tensor,
    t: f64,
    s: f64,
    noise: &Tensor,
) -> Tensor {
    if s <= 0.0 && final_step == FinalStep::Prediction {
        return x0_hat.shallow_clone();
    }
    sampler.step(schedule, x_t, x0_hat, t, s, noise)
}

impl Sampler {
    /// One reverse step by the sampler's update (at every s, 0 included: see
    /// [`reverse_step`] for the last one). `noise` is a fresh N(0,1) tensor
    /// like `x_t`; DDIM ignores it (it is still drawn, so a seed gives the
    /// same stream).
    pub fn step(&self, schedule: &Schedule, x_t: &Tensor, x0_hat: &Tensor, t: f64, s: f64, noise: &Tensor) -> Tensor {
        match self {
            Sampler::Ddpm => {
                let (lt, ls) = (schedule.log_snr(t), schedule.log_snr(s));
                let c = -(lt - ls).exp_m1();
                let (at, _) = schedule.alpha_sigma(t);
                let (as_, ss) = schedule.alpha_sigma(s);
                let mean = (x_t * ((1.0 - c) / at) + x0_hat * c) * as_;
                mean + noise * (ss * ss * c).sqrt()
            }
            Sampler::Ddim => {
                let (at, st) = schedule.alpha_sigma(t);
                let (as_, ss) = schedule.alpha_sigma(s);
                let eps_hat = (x_t - x0_hat * at) / st.max(1e-8);
                x0_hat * as_ + eps_hat * ss
            }
        }
    }
}

/// Times of a reverse run from `t_max` down to 0 in `steps` equal steps:
/// `steps + 1` values, decreasing, ending at 0.
pub fn reverse_times(t_max: f64, steps: usize) -> Vec<f64> {
    let steps = steps.max(1);
    (0..=steps).map(|i| t_max * (1.0 - i as f64 / steps as f64)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Kind;

    #[test]
    fn schedule_goes_from_clean_to_noise() {
        let sch = Schedule::default();
        let (a0, s0) = sch.alpha_sigma(0.0);
        let (a1, s1) = sch.alpha_sigma(1.0);
        assert!(a0 > 0.99 && s0 < 0.1, "t=0: {a0} {s0}");
        assert!(a1 < 0.01 && s1 > 0.99, "t=1: {a1} {s1}");
        for i in 0..100 {
            let t = i as f64 / 100.0;
            let (a, s) = sch.alpha_sigma(t);
            assert!((a * a + s * s - 1.0).abs() < 1e-9);
            assert!(sch.log_snr(t) > sch.log_snr(t + 0.01), "log-SNR decreases");
        }
    }

    #[test]
    fn row_noising_matches_scalar() {
        let x0 = Tensor::ones([3, 10], (Kind::Float, tch::Device::Cpu));
        let eps = Tensor::ones([3, 10], (Kind::Float, tch::Device::Cpu)) * 0.5;
        let t = Tensor::from_slice(&[0.1f32, 0.3, 0.7]);
        let sch = Schedule::default();
        let rows = sch.add_noise_rows(&x0, &t, &eps);
        for (i, tv) in [0.1, 0.3, 0.7].iter().enumerate() {
            let one = sch.add_noise(&x0.get(i as i64), *tv, &eps.get(i as i64));
            let d = (rows.get(i as i64) - one).abs().max().double_value(&[]);
            assert!(d < 1e-5, "row {i}: {d}");
        }
    }

    #[test]
    fn perfect_prediction_denoises_exactly() {
        // With x0_hat = x0, both samplers land on x0 at s = 0.
        let x0 = Tensor::from_slice(&[0.3f32, -0.7, 1.5, 0.0]);
        let eps = Tensor::from_slice(&[1.0f32, -0.5, 0.2, 2.0]);
        let sch = Schedule::default();
        for sampler in [Sampler::Ddpm, Sampler::Ddim] {
            let times = reverse_times(1.0, 20);
            let mut x = sch.add_noise(&x0, times[0], &eps);
            for w in times.windows(2) {
                let noise = Tensor::zeros_like(&x);
                x = reverse_step(sampler, FinalStep::Prediction, &sch, &x, &x0, w[0], w[1], &noise);
            }
            let d = (&x - &x0).abs().max().double_value(&[]);
            assert!(d < 1e-4, "{sampler}: {d}");
        }
    }

    #[test]
    fn the_final_update_scales_by_alpha_zero() {
        // The sampler's own last update lands within sigma(0) of x0, scaled by
        // alpha(0) < 1; the prediction rule lands on x0 itself.
        let sch = Schedule::default();
        let x0 = Tensor::from_slice(&[1.0f32, -1.0]);
        let x_t = sch.add_noise(&x0, 0.05, &Tensor::from_slice(&[0.3f32, 0.3]));
        let zero = Tensor::zeros_like(&x0);
        let upd = reverse_step(Sampler::Ddim, FinalStep::Update, &sch, &x_t, &x0, 0.05, 0.0, &zero);
        let pred = reverse_step(Sampler::Ddim, FinalStep::Prediction, &sch, &x_t, &x0, 0.05, 0.0, &zero);
        assert_eq!(Vec::<f32>::try_from(&pred).unwrap(), vec![1.0, -1.0]);
        let d = (&upd - &x0).abs().max().double_value(&[]);
        let (a0, s0) = sch.alpha_sigma(0.0);
        assert!(d > 1e-6 && d < (1.0 - a0) + 2.0 * s0, "{d}");
    }

    #[test]
    fn ddim_keeps_the_noise_direction() {
        // DDIM from t to s with the true x0: x_s = alpha_s x0 + sigma_s eps.
        let x0 = Tensor::from_slice(&[0.5f32, -0.5]);
        let eps = Tensor::from_slice(&[1.0f32, 2.0]);
        let sch = Schedule::default();
        let x_t = sch.add_noise(&x0, 0.6, &eps);
        let x_s = Sampler::Ddim.step(&sch, &x_t, &x0, 0.6, 0.3, &Tensor::zeros_like(&x0));
        let want = sch.add_noise(&x0, 0.3, &eps);
        assert!((x_s - want).abs().max().double_value(&[]) < 1e-5);
    }

    #[test]
    fn embedding_is_six_sin_cos_per_row() {
        let e = time_embedding_rows(&Tensor::from_slice(&[0.0f32, 0.25, 0.5]));
        assert_eq!(e.size(), vec![3, 6]);
        let pi = std::f32::consts::PI;
        for (row, t) in [0.0f32, 0.25, 0.5].into_iter().enumerate() {
            let v: Vec<f32> = Vec::try_from(e.get(row as i64)).unwrap();
            let want: Vec<f32> = (0..3).flat_map(|k| {
                let a = (1 << k) as f32 * pi * t;
                [a.sin(), a.cos()]
            }).collect();
            for (a, b) in v.iter().zip(&want) {
                assert!((a - b).abs() < 1e-6, "row {row}: {v:?} vs {want:?}");
            }
        }
    }
}
