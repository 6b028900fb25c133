//! Two standard pieces of diffusion training that cost little: a learning-rate
//! schedule (linear warm-up, cosine decay) and an exponential moving average
//! (EMA) of the weights, which sampling uses instead of the last weights.

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
