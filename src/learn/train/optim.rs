//! The optimiser and two standard pieces of diffusion training that cost
//! little: Adam with moments that are checkpointed, a learning-rate schedule
//! (linear warm-up, cosine decay) and an exponential moving average (EMA) of
//! the weights, which sampling uses instead of the last weights.

use std::path::Path;

use tch::{nn::VarStore, Tensor};

use crate::error::{Error, Result};

/// Learning rate at `step` (0-based) of a phase of `total` steps: linear
/// warm-up from `base / warmup` over the first `warmup` steps, then cosine
/// decay from `base` to `base * final_ratio` at the last step. `warmup` 0 and
/// `final_ratio` 1 give the constant `base`.
pub fn lr_at(step: usize, total: usize, base: f64, warmup: usize, final_ratio: f64) -> f64 {
    if step < warmup {
        return base * (step + 1) as f64 / warmup as f64;
    }
    let span = total.saturating_sub(warmup).saturating_sub(1);
    if span == 0 {
        return base;
    }
    let progress = ((step - warmup) as f64 / span as f64).min(1.0);
    let cosine = 0.5 * (1.0 + (std::f64::consts::PI * progress).cos());
    base * (final_ratio + (1.0 - final_ratio) * cosine)
}

/// Adam (Kingma and Ba 2015), with decoupled weight decay when `decoupled`
/// (AdamW, Loshchilov and Hutter 2019): libtorch's update, step for step,
/// written out because tch does not expose libtorch's optimiser state, and
/// a training stopped by a signal or a scheduler must resume with its
/// moments to end exactly where an uninterrupted one ends.
pub struct Adam {
    /// (name, weight, first moment, second moment), sorted by name.
    params: Vec<(String, Tensor, Tensor, Tensor)>,
    steps: i64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    weight_decay: f64,
    decoupled: bool,
}

/// Scales `grads` in place so that their joint L2 norm is at most `max`.
fn clip_norm(grads: &[Tensor], max: f64) {
    tch::no_grad(|| {
        let grads: Vec<&Tensor> = grads.iter().filter(|g| g.defined()).collect();
        if grads.is_empty() {
            return;
        }
        // (Training calls this inside its step's one-thread guard: a
        // whole-tensor norm's parts are added in a thread-count order.)
        let norms: Vec<Tensor> = grads.iter().map(|g| g.norm()).collect();
        let total = Tensor::stack(&norms, 0).norm().double_value(&[]);
        let coef = max / (total + 1e-6);
        if coef < 1.0 {
            for g in grads {
                let _ = g.shallow_clone().g_mul_scalar_(coef);
            }
        }
    });
}

impl Adam {
    /// Over the trainable weights of `vs`; `tch`'s defaults: betas (0.9,
    /// 0.999), eps 1e-8; weight decay 0 for Adam, 0.01 for AdamW.
    pub fn new(vs: &VarStore, decoupled: bool) -> Adam {
        let mut vars: Vec<(String, Tensor)> = vs.variables().into_iter().filter(|(_, t)| t.requires_grad()).collect();
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        let params = vars
            .into_iter()
            .map(|(n, t)| {
                let (m, v) = tch::no_grad(|| (t.zeros_like(), t.zeros_like()));
                (n, t, m, v)
            })
            .collect();
        Adam { params, steps: 0, beta1: 0.9, beta2: 0.999, eps: 1e-8, weight_decay: if decoupled { 0.01 } else { 0.0 }, decoupled }
    }

    pub fn zero_grad(&mut self) {
        for (_, p, _, _) in self.params.iter_mut() {
            p.zero_grad();
        }
    }

    /// Scales the gradients so that their joint L2 norm is at most `max`.
    pub fn clip_grad_norm(&self, max: f64) {
        let grads: Vec<Tensor> = self.params.iter().map(|(_, p, _, _)| p.grad()).filter(|g| g.defined()).collect();
        clip_norm(&grads, max);
    }

    /// The trainable weights, in the order [`Adam::step_with`] takes their gradients.
    pub fn weights(&self) -> Vec<Tensor> {
        self.params.iter().map(|(_, p, _, _)| p.shallow_clone()).collect()
    }

    /// Clips `grads` (one per weight, in [`Adam::weights`]' order) to a
    /// joint L2 norm of at most `clip`, then one update at learning rate
    /// `lr` with them: [`Adam::clip_grad_norm`] and [`Adam::step`] on
    /// gradients computed apart from the weights' own (a training step's
    /// parts, `train::diffusion_step`).
    pub fn step_with(&mut self, grads: &[Tensor], clip: f64, lr: f64) {
        assert_eq!(grads.len(), self.params.len(), "one gradient per weight");
        clip_norm(grads, clip);
        self.update(grads.iter().map(|g| Some(g.shallow_clone())).collect(), lr);
    }

    /// One update at learning rate `lr`.
    pub fn step(&mut self, lr: f64) {
        let grads = self.params.iter().map(|(_, p, _, _)| Some(p.grad()).filter(|g| g.defined())).collect();
        self.update(grads, lr);
    }

    /// One update with `grads` (None: the weight is left as it is).
    fn update(&mut self, grads: Vec<Option<Tensor>>, lr: f64) {
        self.steps += 1;
        let bias1 = 1.0 - self.beta1.powi(self.steps as i32);
        let bias2 = 1.0 - self.beta2.powi(self.steps as i32);
        let (b1, b2, eps, wd, decoupled) = (self.beta1, self.beta2, self.eps, self.weight_decay, self.decoupled);
        tch::no_grad(|| {
            for ((_, p, m, v), g) in self.params.iter_mut().zip(grads) {
                let Some(g) = g else { continue };
                let g = if !decoupled && wd != 0.0 { &g + &*p * wd } else { g };
                if decoupled && wd != 0.0 {
                    let _ = p.g_mul_scalar_(1.0 - lr * wd);
                }
                let _ = m.g_mul_scalar_(b1);
                let _ = m.g_add_(&(&g * (1.0 - b1)));
                let _ = v.g_mul_scalar_(b2);
                let _ = v.addcmul_(&g, &(&g * (1.0 - b2)));
                let denom = (v.sqrt() / bias2.sqrt()) + eps;
                let _ = p.addcdiv_(&(&*m * (-lr / bias1)), &denom);
            }
        });
    }

    /// Writes the moments and the step count (`path`, safetensors).
    pub fn save(&self, path: &Path) -> Result<()> {
        let steps = Tensor::from_slice(&[self.steps]);
        let mut named: Vec<(String, &Tensor)> = vec![("steps".into(), &steps)];
        for (n, _, m, v) in &self.params {
            named.push((format!("exp_avg.{n}"), m));
            named.push((format!("exp_avg_sq.{n}"), v));
        }
        let refs: Vec<(&str, &Tensor)> = named.iter().map(|(n, t)| (n.as_str(), *t)).collect();
        crate::util::fs::write_atomically(path, |tmp| {
            Tensor::write_safetensors(&refs, tmp).map_err(|e| Error::file(path, format!("cannot save the optimiser state: {e}")))
        })
    }

    /// Continues from moments [`Adam::save`] wrote for the same network.
    pub fn load(&mut self, path: &Path) -> Result<()> {
        let stored = Tensor::read_safetensors(path).map_err(|e| Error::file(path, format!("cannot load the optimiser state: {e}")))?;
        let get = |name: &str| stored.iter().find(|(n, _)| n == name).map(|(_, t)| t);
        let steps = get("steps").ok_or_else(|| Error::file(path, "has no step count"))?;
        self.steps = steps.int64_value(&[0]);
        for (n, _, m, v) in self.params.iter_mut() {
            for (key, dst) in [(format!("exp_avg.{n}"), &mut *m), (format!("exp_avg_sq.{n}"), &mut *v)] {
                let t = get(&key).ok_or_else(|| Error::file(path, format!("has no '{key}'")))?;
                if t.size() != dst.size() {
                    return Err(Error::file(path, format!("'{key}' has shape {:?}, not {:?}", t.size(), dst.size())));
                }
                tch::no_grad(|| dst.copy_(&t.to_device(dst.device()).to_kind(dst.kind())));
            }
        }
        Ok(())
    }
}

/// The moving average of a network's weights, kept beside the live ones.
pub struct Ema {
    decay: f64,
    /// (name, live weight, average), sorted by name.
    pairs: Vec<(String, Tensor, Tensor)>,
}

impl Ema {
    /// Starts from the live weights of `vs`, or from `saved` (a checkpoint of
    /// an earlier session of the same training) where there is one.
    pub fn new(vs: &VarStore, decay: f64, saved: Option<&Path>) -> Result<Ema> {
        let mut vars: Vec<(String, Tensor)> = vs.variables().into_iter().collect();
        vars.sort_by(|a, b| a.0.cmp(&b.0));
        let mut pairs: Vec<(String, Tensor, Tensor)> =
            vars.into_iter().map(|(n, t)| { let avg = t.detach().copy(); (n, t, avg) }).collect();
        if let Some(path) = saved {
            let stored = Tensor::read_safetensors(path).map_err(|e| Error::file(path, format!("cannot load EMA weights: {e}")))?;
            for (name, _, avg) in pairs.iter_mut() {
                let (_, t) = stored
                    .iter()
                    .find(|(n, _)| n == name)
                    .ok_or_else(|| Error::file(path, format!("has no EMA weight '{name}'")))?;
                if t.size() != avg.size() {
                    return Err(Error::file(path, format!("EMA weight '{name}' has shape {:?}, not {:?}", t.size(), avg.size())));
                }
                tch::no_grad(|| avg.copy_(&t.to_device(avg.device())));
            }
        }
        Ok(Ema { decay, pairs })
    }

    /// One step: average = decay * average + (1 - decay) * live.
    pub fn update(&mut self) {
        tch::no_grad(|| {
            for (_, live, avg) in self.pairs.iter_mut() {
                let _ = avg.g_mul_scalar_(self.decay);
                let _ = avg.g_add_(&(live.detach() * (1.0 - self.decay)));
            }
        });
    }

    /// Writes the averages under the live weights' names, so the file loads
    /// into a fresh network like any checkpoint.
    pub fn save(&self, path: &Path) -> Result<()> {
        let named: Vec<(&str, &Tensor)> = self.pairs.iter().map(|(n, _, a)| (n.as_str(), a)).collect();
        crate::util::fs::write_atomically(path, |tmp| {
            Tensor::write_safetensors(&named, tmp).map_err(|e| Error::file(path, format!("cannot save EMA weights: {e}")))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_warms_up_then_decays_to_the_final_ratio() {
        let lr = |s| lr_at(s, 1000, 1e-3, 100, 0.1);
        assert!((lr(0) - 1e-5).abs() < 1e-12);
        assert!((lr(99) - 1e-3).abs() < 1e-12);
        assert!((lr(100) - 1e-3).abs() < 1e-12);
        assert!((lr(999) - 1e-4).abs() < 1e-12);
        assert!(lr(500) < lr(300) && lr(500) > lr(800));
        assert_eq!(lr_at(7, 50, 2e-3, 0, 1.0), 2e-3, "constant without warm-up and decay");
    }

    #[test]
    fn adam_matches_libtorch_and_resumes_exactly() {
        // The same weights and gradients through tch's Adam and ours.
        let run = |ours: bool, stop_at: Option<usize>, dir: &Path| -> Vec<f32> {
            let mut vs = VarStore::new(tch::Device::Cpu);
            let w = vs.root().var_copy("w", &Tensor::from_slice(&[0.5f32, -1.0, 2.0, 0.1]));
            let target = Tensor::from_slice(&[1.0f32, 0.0, -1.0, 0.3]);
            let mut theirs = tch::nn::OptimizerConfig::build(tch::nn::Adam::default(), &vs, 1e-2).unwrap();
            let mut adam = Adam::new(&vs, false);
            let state = dir.join("adam.safetensors");
            let start = if stop_at.is_none() && state.exists() { adam.load(&state).unwrap(); adam.steps as usize } else { 0 };
            if start > 0 {
                vs.load(dir.join("w.safetensors")).unwrap();
            }
            for step in start..20 {
                if Some(step) == stop_at {
                    adam.save(&state).unwrap();
                    vs.save(dir.join("w.safetensors")).unwrap();
                    break;
                }
                let loss = (&w - &target).square().sum(tch::Kind::Float);
                if ours {
                    adam.zero_grad();
                    loss.backward();
                    adam.clip_grad_norm(1.0);
                    adam.step(1e-2);
                } else {
                    theirs.zero_grad();
                    loss.backward();
                    theirs.clip_grad_norm(1.0);
                    theirs.step();
                }
            }
            Vec::try_from(&w).unwrap()
        };
        let dir = tempfile::tempdir().unwrap();
        let reference = run(false, None, dir.path());
        let ours = run(true, None, dir.path());
        for (a, b) in reference.iter().zip(&ours) {
            assert!((a - b).abs() < 1e-5, "libtorch {reference:?} vs ours {ours:?}");
        }
        // Stopped at step 7 and resumed from the saved moments: identical.
        let _ = run(true, Some(7), dir.path());
        let resumed = run(true, None, dir.path());
        assert_eq!(resumed, ours, "a resumed Adam ends where an uninterrupted one does");
    }

    #[test]
    fn ema_follows_the_weights_and_round_trips() {
        let vs = VarStore::new(tch::Device::Cpu);
        let w = vs.root().zeros("w", &[3]);
        let mut ema = Ema::new(&vs, 0.5, None).unwrap();
        tch::no_grad(|| {
            let _ = w.shallow_clone().fill_(4.0);
        });
        ema.update(); // 0.5 * 0 + 0.5 * 4
        ema.update(); // 0.5 * 2 + 0.5 * 4
        let avg: Vec<f32> = Vec::try_from(&ema.pairs[0].2).unwrap();
        assert_eq!(avg, [3.0, 3.0, 3.0]);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ema.safetensors");
        ema.save(&p).unwrap();
        let mut vs2 = VarStore::new(tch::Device::Cpu);
        let w2 = vs2.root().zeros("w", &[3]);
        vs2.load(&p).unwrap();
        assert_eq!(Vec::<f32>::try_from(&w2).unwrap(), [3.0, 3.0, 3.0], "loads into a fresh network");
        let resumed = Ema::new(&vs, 0.5, Some(&p)).unwrap();
        assert_eq!(Vec::<f32>::try_from(&resumed.pairs[0].2).unwrap(), [3.0, 3.0, 3.0]);
    }
}
