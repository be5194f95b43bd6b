//! The head: a small fully connected network from the vectors of a question's names to the logit
//! of "this container holds the target", trained by Adam on grouped binary cross-entropy.
//!
//! Written out rather than taken from a crate: the network has a few thousand weights, and the
//! file it goes into must be the same byte for byte for the same inputs and seed. A hand-written
//! loop fixes the order of every addition; the tensor crates' CPU kernels split sums over threads
//! and SIMD lanes by the machine they run on, and bring minutes of build for this.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Slope of the leaky ReLU on negative inputs (the authors' head uses the same).
const LEAK: f32 = 0.1;

/// One fully connected layer: `out = w · in + b`, `w` row-major (`outputs` rows of `inputs`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    /// Inputs.
    pub inputs: usize,
    /// Outputs.
    pub outputs: usize,
    /// Weights, `outputs × inputs`, row-major.
    #[serde(with = "f32_base64")]
    pub w: Vec<f32>,
    /// Biases, one per output.
    #[serde(with = "f32_base64")]
    pub b: Vec<f32>,
}

/// Numbers written as the base64 of their little-endian bytes: exact, and a fifth of the size
/// of JSON numbers (a prior file holds tens of thousands of weights).
mod f32_base64 {
    use base64::Engine;
    use base64::engine::general_purpose::STANDARD;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[f32], s: S) -> Result<S::Ok, S::Error> {
        let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
        s.serialize_str(&STANDARD.encode(bytes))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f32>, D::Error> {
        let text = String::deserialize(d)?;
        let bytes = STANDARD
            .decode(text.as_bytes())
            .map_err(|e| serde::de::Error::custom(format!("weights: not base64 ({e})")))?;
        if bytes.len() % 4 != 0 {
            return Err(serde::de::Error::custom(format!(
                "weights: {} bytes, not a whole number of 4-byte floats",
                bytes.len()
            )));
        }
        Ok(bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
}

/// A trained head: hidden layers with leaky ReLU, then one output (a logit).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Head {
    /// The layers, input first; the last has one output.
    pub layers: Vec<Layer>,
}

/// How heads are trained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeadSettings {
    /// Widths of the hidden layers.
    pub hidden: Vec<usize>,
    /// Passes over the training questions.
    pub epochs: usize,
    /// Question groups per Adam step.
    pub batch: usize,
    /// Adam's step size.
    pub learning_rate: f64,
    /// Decoupled weight decay per step (AdamW), on weights, not biases.
    pub weight_decay: f64,
}

impl Default for HeadSettings {
    fn default() -> Self {
        Self {
            hidden: vec![64, 32],
            epochs: 40,
            batch: 32,
            learning_rate: 2e-3,
            weight_decay: 1e-4,
        }
    }
}

/// One training example: a question's input vector, how many of its cases were positive and how
/// many there were (every house asking the same question adds to one group).
#[derive(Clone, Debug)]
pub struct Example {
    /// The input vector.
    pub x: Vec<f32>,
    /// Containers that held the target.
    pub positives: f64,
    /// Containers asked about.
    pub total: f64,
}

/// `a · b`, with eight running sums so that the compiler may keep them in vector lanes (their
/// order is fixed by the code, so the result does not depend on the machine).
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

fn leaky(z: f32) -> f32 {
    if z > 0.0 { z } else { LEAK * z }
}

impl Layer {
    fn new(inputs: usize, outputs: usize, rng: &mut ChaCha8Rng) -> Self {
        // Glorot's uniform range keeps the first forward passes in a sensible range.
        let r = (6.0 / (inputs + outputs) as f64).sqrt();
        let w = (0..inputs * outputs)
            .map(|_| rng.random_range(-r..r) as f32)
            .collect();
        Self {
            inputs,
            outputs,
            w,
            b: vec![0.0; outputs],
        }
    }

    fn forward(&self, x: &[f32], out: &mut Vec<f32>) {
        out.clear();
        if self.inputs == 0 {
            // `chunks_exact(0)` would panic; a layer without inputs gives its biases.
            out.extend_from_slice(&self.b);
            return;
        }
        out.extend(
            self.w
                .chunks_exact(self.inputs)
                .zip(&self.b)
                .map(|(row, b)| dot(row, x) + b),
        );
    }
}

impl Head {
    /// Input width.
    pub fn inputs(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inputs)
    }

    /// Whether the layers chain (each layer's inputs are the previous one's outputs) and end in
    /// one output, with weight and bias counts to match: what a file read back must show.
    pub fn is_well_formed(&self) -> bool {
        !self.layers.is_empty()
            && self.layers.last().is_some_and(|l| l.outputs == 1)
            && self.layers.windows(2).all(|w| w[0].outputs == w[1].inputs)
            && self.layers.iter().all(|l| {
                l.w.len() == l.inputs * l.outputs
                    && l.b.len() == l.outputs
                    && l.w.iter().chain(&l.b).all(|v| v.is_finite())
            })
    }

    /// The logit for input `x` (of [`inputs`](Self::inputs) numbers).
    pub fn logit(&self, x: &[f32]) -> f32 {
        let mut a = x.to_vec();
        let mut z = Vec::new();
        let last = self.layers.len().saturating_sub(1);
        for (i, layer) in self.layers.iter().enumerate() {
            layer.forward(&a, &mut z);
            if i < last {
                z.iter_mut().for_each(|v| *v = leaky(*v));
            }
            std::mem::swap(&mut a, &mut z);
        }
        a.first().copied().unwrap_or(0.0)
    }

    /// Trains a head on `examples` (all of one input width) with `seed`.
    pub fn train(examples: &[Example], settings: &HeadSettings, seed: u64) -> Head {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let inputs = examples.first().map_or(0, |e| e.x.len());
        let mut widths = vec![inputs];
        widths.extend(settings.hidden.iter().copied().filter(|&w| w > 0));
        widths.push(1);
        let mut head = Head {
            layers: widths
                .windows(2)
                .map(|w| Layer::new(w[0], w[1], &mut rng))
                .collect(),
        };
        if examples.is_empty() {
            return head;
        }
        // The loss is the groups' summed cross-entropy over the mean group size, so that a step's
        // size does not depend on how many houses were counted.
        let mean_total = examples.iter().map(|e| e.total).sum::<f64>() / examples.len() as f64;
        let scale = 1.0 / mean_total.max(1e-9);
        let mut adam = Adam::new(&head);
        let mut grads = Grads::zeros(&head);
        let mut order: Vec<usize> = (0..examples.len()).collect();
        let mut tape = Tape::default();
        for _ in 0..settings.epochs {
            order.shuffle(&mut rng);
            for batch in order.chunks(settings.batch.max(1)) {
                grads.clear();
                for &i in batch {
                    let e = &examples[i];
                    head.backward(e, scale, &mut tape, &mut grads);
                }
                adam.step(&mut head, &grads, batch.len(), settings);
            }
        }
        head
    }

    /// Adds the gradient of one group's loss to `grads`.
    fn backward(&self, e: &Example, scale: f64, tape: &mut Tape, grads: &mut Grads) {
        let n = self.layers.len();
        tape.acts.resize(n + 1, Vec::new());
        tape.pre.resize(n, Vec::new());
        tape.acts[0].clear();
        tape.acts[0].extend_from_slice(&e.x);
        for (i, layer) in self.layers.iter().enumerate() {
            let (before, after) = tape.acts.split_at_mut(i + 1);
            layer.forward(&before[i], &mut tape.pre[i]);
            let out = &mut after[0];
            out.clear();
            if i + 1 < n {
                out.extend(tape.pre[i].iter().map(|&v| leaky(v)));
            } else {
                out.extend_from_slice(&tape.pre[i]);
            }
        }
        let z = f64::from(tape.acts[n][0]);
        let p = crate::logistic::sigmoid(z);
        // d/dz of k·softplus(−z) + (n − k)·softplus(z).
        let mut delta = vec![((e.total * p - e.positives) * scale) as f32];
        for i in (0..n).rev() {
            let layer = &self.layers[i];
            let input = &tape.acts[i];
            let g = &mut grads.layers[i];
            for (o, &d) in delta.iter().enumerate() {
                g.b[o] += d;
                let row = &mut g.w[o * layer.inputs..(o + 1) * layer.inputs];
                for (gw, &x) in row.iter_mut().zip(input) {
                    *gw += d * x;
                }
            }
            if i == 0 {
                break;
            }
            let mut back = vec![0.0f32; layer.inputs];
            for (o, &d) in delta.iter().enumerate() {
                let row = &layer.w[o * layer.inputs..(o + 1) * layer.inputs];
                for (b, &w) in back.iter_mut().zip(row) {
                    *b += d * w;
                }
            }
            for (b, &pre) in back.iter_mut().zip(&tape.pre[i - 1]) {
                if pre <= 0.0 {
                    *b *= LEAK;
                }
            }
            delta = back;
        }
    }
}

/// Activations of one forward pass, kept for the backward pass.
#[derive(Default)]
struct Tape {
    acts: Vec<Vec<f32>>,
    pre: Vec<Vec<f32>>,
}

/// Gradients, shaped as the head.
struct Grads {
    layers: Vec<Layer>,
}

impl Grads {
    fn zeros(head: &Head) -> Self {
        Self {
            layers: head
                .layers
                .iter()
                .map(|l| Layer {
                    inputs: l.inputs,
                    outputs: l.outputs,
                    w: vec![0.0; l.w.len()],
                    b: vec![0.0; l.b.len()],
                })
                .collect(),
        }
    }

    fn clear(&mut self) {
        for l in &mut self.layers {
            l.w.iter_mut().for_each(|v| *v = 0.0);
            l.b.iter_mut().for_each(|v| *v = 0.0);
        }
    }
}

/// Adam's moment estimates (Kingma & Ba), with decoupled weight decay (AdamW).
struct Adam {
    m: Grads,
    v: Grads,
    t: i32,
}

impl Adam {
    fn new(head: &Head) -> Self {
        Self {
            m: Grads::zeros(head),
            v: Grads::zeros(head),
            t: 0,
        }
    }

    fn step(&mut self, head: &mut Head, grads: &Grads, batch: usize, s: &HeadSettings) {
        const B1: f64 = 0.9;
        const B2: f64 = 0.999;
        const EPS: f64 = 1e-8;
        self.t += 1;
        let c1 = 1.0 - B1.powi(self.t);
        let c2 = 1.0 - B2.powi(self.t);
        let lr = s.learning_rate;
        let decay = (s.learning_rate * s.weight_decay) as f32;
        let inv = 1.0 / batch.max(1) as f64;
        for (((layer, g), m), v) in head
            .layers
            .iter_mut()
            .zip(&grads.layers)
            .zip(&mut self.m.layers)
            .zip(&mut self.v.layers)
        {
            let update = |w: &mut f32, g: f32, m: &mut f32, v: &mut f32, decayed: bool| {
                let g = f64::from(g) * inv;
                let mf = B1 * f64::from(*m) + (1.0 - B1) * g;
                let vf = B2 * f64::from(*v) + (1.0 - B2) * g * g;
                *m = mf as f32;
                *v = vf as f32;
                let step = lr * (mf / c1) / ((vf / c2).sqrt() + EPS);
                if decayed {
                    *w -= decay * *w;
                }
                *w -= step as f32;
            };
            for (((w, &g), m), v) in layer.w.iter_mut().zip(&g.w).zip(&mut m.w).zip(&mut v.w) {
                update(w, g, m, v, true);
            }
            for (((b, &g), m), v) in layer.b.iter_mut().zip(&g.b).zip(&mut m.b).zip(&mut v.b) {
                update(b, g, m, v, false);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example(x: Vec<f32>, positives: f64, total: f64) -> Example {
        Example {
            x,
            positives,
            total,
        }
    }

    #[test]
    fn the_dot_product_is_the_plain_sum() {
        let a: Vec<f32> = (0..19).map(|i| i as f32 * 0.5 - 3.0).collect();
        let b: Vec<f32> = (0..19).map(|i| (i as f32).sin()).collect();
        let plain: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - plain).abs() < 1e-4);
    }

    #[test]
    fn gradients_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let head = Head {
            layers: vec![
                Layer::new(4, 5, &mut rng),
                Layer::new(5, 3, &mut rng),
                Layer::new(3, 1, &mut rng),
            ],
        };
        let e = example(vec![0.3, -0.7, 0.2, 0.9], 2.0, 5.0);
        let loss = |h: &Head| {
            let z = f64::from(h.logit(&e.x));
            let sp = |v: f64| (1.0 + v.exp()).ln();
            e.positives * sp(-z) + (e.total - e.positives) * sp(z)
        };
        let mut grads = Grads::zeros(&head);
        head.backward(&e, 1.0, &mut Tape::default(), &mut grads);
        for (l, layer) in head.layers.iter().enumerate() {
            for i in 0..layer.w.len() {
                let mut up = head.clone();
                up.layers[l].w[i] += 1e-2;
                let mut down = head.clone();
                down.layers[l].w[i] -= 1e-2;
                let numeric = (loss(&up) - loss(&down)) / 2e-2;
                let analytic = f64::from(grads.layers[l].w[i]);
                assert!(
                    (numeric - analytic).abs() < 2e-2 * (1.0 + numeric.abs()),
                    "layer {l} weight {i}: {numeric} vs {analytic}"
                );
            }
        }
    }

    #[test]
    fn a_head_learns_which_inputs_mean_holding() {
        // Holding depends on the sign of the product of the first two inputs: no linear model
        // gets it, a hidden layer does.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let examples: Vec<Example> = (0..400)
            .map(|_| {
                let x: Vec<f32> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
                let holds = x[0] * x[1] > 0.0;
                example(x, if holds { 9.0 } else { 1.0 }, 10.0)
            })
            .collect();
        let settings = HeadSettings {
            epochs: 200,
            ..HeadSettings::default()
        };
        let head = Head::train(&examples, &settings, 1);
        let right = examples
            .iter()
            .filter(|e| (head.logit(&e.x) > 0.0) == (e.positives > 5.0))
            .count();
        assert!(right >= 360, "{right} of 400 right");
        assert!(head.is_well_formed());
    }

    #[test]
    fn the_same_seed_gives_the_same_head_and_another_seed_another() {
        let examples: Vec<Example> = (0..50)
            .map(|i| {
                example(
                    vec![i as f32 / 50.0, 1.0 - i as f32 / 50.0],
                    (i % 3) as f64,
                    3.0,
                )
            })
            .collect();
        let s = HeadSettings {
            epochs: 5,
            ..HeadSettings::default()
        };
        assert_eq!(Head::train(&examples, &s, 7), Head::train(&examples, &s, 7));
        assert_ne!(Head::train(&examples, &s, 7), Head::train(&examples, &s, 8));
    }
}
