//! A prior file's learned part asked as a likelihood source, its answers kept.

use std::sync::Arc;

use ferret_world::{House, ObjectType};

use super::{Learned, LearnedKind, fusion_features, head_input, mean_logit};
use crate::error::PlanError;
use crate::likelihood::{Evidence, LikelihoodSource};
use crate::logistic::{logit, sigmoid};
use crate::prior::Prior;
use crate::probability::Probability;

/// A likelihood source over a prior file's learned part ([`LearnedKind`]).
#[derive(Clone, Debug)]
pub struct LearnedSource {
    prior: Arc<Prior>,
    kind: LearnedKind,
    /// Answers by (target, container type, room type): a run asks the same few thousand
    /// questions again and again (every strategy's trials, every replay), and twenty heads per
    /// question made planning over the learned source four times as slow as over the prior.
    answers: Arc<std::sync::RwLock<Answers>>,
}

/// P(holds) by (target, container type, room type).
type Answers = std::collections::HashMap<(String, String, String), f64>;

/// Answers a [`LearnedSource`] keeps; past this it computes them again (the names a service
/// meets are few, but it runs for months).
const KEPT_ANSWERS: usize = 1 << 20;

impl LearnedSource {
    /// The source of `kind` over `prior`; an error when the prior has no learned part.
    pub fn new(prior: Arc<Prior>, kind: LearnedKind) -> Result<Self, String> {
        let Some(learned) = prior.learned() else {
            return Err(format!(
                "model/{} needs a prior trained with word vectors (`ferret prior train --embeddings DIR`); this prior has none",
                kind.name()
            ));
        };
        if let Some(h) = prior.holdout()
            && h.folds() != learned.settings.folds
        {
            return Err(format!(
                "--holdout-types with {} folds: the learned heads of this prior were trained with {} folds of held-out types, so only --holdout-types {} (or one fold of it) is answered by heads that never saw the held-out types",
                h.folds(),
                learned.settings.folds,
                learned.settings.folds
            ));
        }
        Ok(Self {
            prior,
            kind,
            answers: Arc::default(),
        })
    }

    /// P(holds) for one question.
    fn probability(
        &self,
        learned: &Learned,
        target: &ObjectType,
        container: &ObjectType,
        room: &str,
    ) -> Result<f64, String> {
        let control = self.kind.control();
        let model = if control {
            &learned.control
        } else {
            &learned.language
        };
        let embedder = self.prior.embedder();
        let x = head_input(
            &learned.vector(target.as_str(), control, "target type", embedder)?,
            &learned.vector(container.as_str(), control, "container type", embedder)?,
            &learned.vector(room, control, "room type", embedder)?,
        );
        // Under a hold-out, only the heads that never saw the target's fold may answer.
        let lh = match self.prior.holdout() {
            Some(h) => mean_logit(
                model
                    .heads
                    .get(h.prior_fold(target))
                    .map_or(&[][..], Vec::as_slice),
                &x,
            ),
            None => {
                model
                    .heads
                    .iter()
                    .map(|fold| mean_logit(fold, &x))
                    .sum::<f64>()
                    / model.heads.len().max(1) as f64
            }
        };
        if self.kind.head_only() {
            return Ok(sigmoid(model.head_fit[0] * lh + model.head_fit[1]));
        }
        let lp = logit(self.prior.probability(target, container, Some(room)).get());
        let e = self.prior.evidence(target, container, room);
        let fused: f64 = fusion_features(lp, lh, &e)
            .iter()
            .zip(&model.fusion)
            .map(|(x, w)| x * w)
            .sum();
        // The counts where they have evidence, the fusion where they have none: its weights
        // were fitted where the counts came from fewer houses and types than the prior's own,
        // so where the prior has seen the target, the furniture and the room, it is the prior
        // that knows best.
        let g = evidence_weight(&e);
        Ok(sigmoid((1.0 - g) * lp + g * fused))
    }
}

/// How much of a learned answer the fusion gives (the rest is the prior's): the largest of the
/// evidence gaps of the target, container and room types, so a question with any part the
/// counts never saw is the fusion's.
pub fn evidence_weight(e: &Evidence) -> f64 {
    e.target.max(e.container).max(e.room).clamp(0.0, 1.0)
}

impl LikelihoodSource for LearnedSource {
    fn name(&self) -> &str {
        self.kind.name()
    }

    fn check_names(&self, house: &House, targets: &[ObjectType]) -> Result<Vec<String>, String> {
        let Some(learned) = self.prior.learned() else {
            return Err("the prior has no learned part".into());
        };
        // The control's vectors are made from the name alone: only the language model's need
        // a word vector.
        if self.kind.control() {
            return Ok(Vec::new());
        }
        let embedder = self.prior.embedder();
        let mut notes = Vec::new();
        let rooms = (0..house.containers.len()).filter_map(|c| house.container_room(c));
        let asked = targets
            .iter()
            .map(|t| (t.as_str(), "target type"))
            .chain(
                house
                    .containers
                    .iter()
                    .map(|c| (c.object_type.as_str(), "container type")),
            )
            .chain(rooms.map(|r| (r.room_type.as_str(), "room type")));
        let mut seen = std::collections::BTreeSet::new();
        let mut missing = Vec::new();
        for (name, kind) in asked {
            if name.is_empty() || !seen.insert(name) || learned.vectors.contains_key(name) {
                continue;
            }
            match embedder {
                Some(e) => {
                    learned.vector(name, false, kind, embedder)?;
                    notes.extend(e.0.notes(name));
                }
                None => missing.push(format!("the {kind} `{name}`")),
            }
        }
        // Every name at once: an operator fixes the command line once, not once per name.
        if !missing.is_empty() {
            return Err(format!(
                "no word vector for {}, which the training houses never had: give the embeddings the prior was trained with ({}) as --embeddings DIR or FERRET_EMBEDDINGS (scripts/embeddings.sh install prints the folder)",
                missing.join(", "),
                learned.embedding
            ));
        }
        Ok(notes)
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        let err = |message: String| PlanError::Likelihood {
            source_name: self.kind.name().to_string(),
            error: message.into(),
        };
        let learned = self
            .prior
            .learned()
            .ok_or_else(|| err("the prior has no learned part".into()))?;
        (0..house.containers.len())
            .map(|c| {
                let room = house
                    .container_room(c)
                    .map(|r| r.room_type.as_str())
                    .unwrap_or("");
                let container = &house.containers[c].object_type;
                let key = (
                    target.as_str().to_string(),
                    container.as_str().to_string(),
                    room.to_string(),
                );
                if let Some(&p) = self.answers.read().ok().as_ref().and_then(|a| a.get(&key)) {
                    return Ok(Probability::clamped(p, 0.0, 1.0));
                }
                let p = self
                    .probability(learned, target, container, room)
                    .map_err(err)?;
                if let Ok(mut answers) = self.answers.write()
                    && answers.len() < KEPT_ANSWERS
                {
                    answers.insert(key, p);
                }
                Ok(Probability::clamped(p, 0.0, 1.0))
            })
            .collect()
    }
}
