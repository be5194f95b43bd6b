//! Training a learned source: the questions of the training houses, heads held out by fold,
//! and the fits over their cross-fitted answers beside a prior counted without each fold.

use std::collections::{BTreeMap, BTreeSet};

use ferret_world::{ObjectType, Scene};
use rayon::prelude::*;

use super::head::{Example, Head};
use super::{
    CountsInHead, FUSION_WEIGHTS, HeldOutScore, LEARNED_FORMAT, Learned, LearnedModel,
    LearnedSettings, fold_of, fusion_features, head_input, learned_error, mean_logit,
    random_vector, scene_names,
};
use crate::error::PlanError;
use crate::logistic::{fit_counts, logit};
use crate::prior::Prior;

/// The names one question is about, as indices into a name table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Question {
    target: usize,
    container: usize,
    room: usize,
}

/// Holders and containers asked, per question.
type Tally = BTreeMap<Question, (f64, f64)>;

/// The questions of one house, with how many containers held the target and how many there were.
fn house_questions(scene: &Scene, index: &BTreeMap<&str, usize>) -> Tally {
    let mut tally = Tally::new();
    let targets = scene.truth.target_types();
    for (c, container) in scene.house.containers.iter().enumerate() {
        let room = scene
            .house
            .container_room(c)
            .map(|r| r.room_type.as_str())
            .unwrap_or("");
        for t in &targets {
            // The table holds every name of these houses (`scene_names`); a name it lacked
            // would only drop that question.
            let (Some(&target), Some(&kind), Some(&in_room)) = (
                index.get(t.as_str()),
                index.get(container.object_type.as_str()),
                index.get(room),
            ) else {
                continue;
            };
            let q = Question {
                target,
                container: kind,
                room: in_room,
            };
            let e = tally.entry(q).or_insert((0.0, 0.0));
            e.0 += f64::from(u8::from(scene.truth.holds(c, t)));
            e.1 += 1.0;
        }
    }
    tally
}

/// The folds of the container types and of the room types of `scenes`: dealt round the folds in
/// name order.
pub(super) fn kind_folds(
    scenes: &[&Scene],
    folds: usize,
) -> (BTreeMap<String, usize>, BTreeMap<String, usize>) {
    let (containers, rooms) = kinds_of_names(scenes);
    let deal = |kind: BTreeSet<String>| -> BTreeMap<String, usize> {
        kind.into_iter()
            .enumerate()
            .map(|(i, n)| (n, i % folds))
            .collect()
    };
    (deal(containers), deal(rooms))
}

/// The container type names and the room type names of `scenes` (no `""`).
fn kinds_of_names(scenes: &[&Scene]) -> (BTreeSet<String>, BTreeSet<String>) {
    let (mut containers, mut rooms) = (BTreeSet::new(), BTreeSet::new());
    for s in scenes {
        for (c, container) in s.house.containers.iter().enumerate() {
            containers.insert(container.object_type.as_str().to_string());
            if let Some(r) = s.house.container_room(c) {
                rooms.insert(r.room_type.as_str().to_string());
            }
        }
    }
    (containers, rooms)
}

/// Trains a learned source on `scenes` (the training houses `prior` was counted on), over
/// `vectors` (every name [`scene_names`] gives, but `""`), from `embedding`. Deterministic: the
/// same inputs and settings give the same model, whatever the number of threads.
pub fn train(
    scenes: &[&Scene],
    prior: &Prior,
    embedding: &str,
    vectors: BTreeMap<String, Vec<f32>>,
    settings: &LearnedSettings,
) -> Result<Learned, PlanError> {
    let folds = settings.folds;
    if folds < 2 {
        return Err(learned_error(format!(
            "{folds} folds: training holds types out in at least 2 folds"
        )));
    }
    if scenes.len() < 2 * folds {
        return Err(learned_error(format!(
            "{} training houses for {folds} folds: at least {} are needed",
            scenes.len(),
            2 * folds
        )));
    }
    let dim = vectors.values().next().map_or(0, Vec::len);
    if dim == 0 {
        return Err(learned_error("no word vectors given"));
    }
    if let Some((name, v)) = vectors.iter().find(|(_, v)| v.len() != dim) {
        return Err(learned_error(format!(
            "the vector of `{name}` has {} numbers, others {dim}",
            v.len()
        )));
    }
    let mut names: BTreeSet<String> = BTreeSet::new();
    for s in scenes {
        names.extend(scene_names(s));
    }
    let names: Vec<String> = names.into_iter().collect();
    let missing: Vec<&str> = names
        .iter()
        .filter(|n| !n.is_empty() && !vectors.contains_key(n.as_str()))
        .map(String::as_str)
        .collect();
    if !missing.is_empty() {
        return Err(learned_error(format!(
            "no vector for {} name(s) of the training houses: {}",
            missing.len(),
            missing.join(", ")
        )));
    }
    let index: BTreeMap<&str, usize> = names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    // Target types fall into folds by HoldOut's hash, so a run holding out target types finds
    // the heads that never saw them. Container and room types are dealt round the folds in name
    // order instead: ProcTHOR has four room types, and a hash put two of them in one fold,
    // whose heads then never saw a kitchen or a bedroom.
    let (container_fold, room_fold) = kind_folds(scenes, folds);
    let target_fold: Vec<usize> = names.iter().map(|n| fold_of(n, folds)).collect();
    let fold_in =
        |map: &BTreeMap<String, usize>, name: &str| map.get(name).copied().unwrap_or(usize::MAX);
    let c_fold: Vec<usize> = names.iter().map(|n| fold_in(&container_fold, n)).collect();
    let r_fold: Vec<usize> = names.iter().map(|n| fold_in(&room_fold, n)).collect();
    let language_vectors: Vec<Vec<f32>> = names
        .iter()
        .map(|n| vectors.get(n).cloned().unwrap_or_else(|| vec![0.0; dim]))
        .collect();
    let control_vectors: Vec<Vec<f32>> = names
        .iter()
        .map(|n| {
            if n.is_empty() {
                vec![0.0; dim]
            } else {
                random_vector(n, dim)
            }
        })
        .collect();

    let per_house: Vec<Tally> = scenes.iter().map(|s| house_questions(s, &index)).collect();
    let held_out = |q: &Question, k: usize| {
        target_fold[q.target] == k || c_fold[q.container] == k || r_fold[q.room] == k
    };
    // Per fold: the questions its heads learn from (other houses, no held-out type) and the
    // questions they answer blind (its own houses).
    let mut learn: Vec<Tally> = vec![Tally::new(); folds];
    let mut blind: Vec<Tally> = vec![Tally::new(); folds];
    for (i, tally) in per_house.iter().enumerate() {
        for k in 0..folds {
            let blind_house = i % folds == k;
            let into = if blind_house {
                &mut blind[k]
            } else {
                &mut learn[k]
            };
            for (q, &(pos, n)) in tally {
                if !blind_house && held_out(q, k) {
                    continue;
                }
                let e = into.entry(*q).or_insert((0.0, 0.0));
                e.0 += pos;
                e.1 += n;
            }
        }
    }

    if let Some(k) = (0..folds).find(|&k| learn[k].is_empty() || blind[k].is_empty()) {
        return Err(learned_error(format!(
            "fold {} of {folds} has no question to learn from or none to be scored on: too few training houses or types for {folds} folds",
            k + 1
        )));
    }
    let examples = |tally: &Tally, table: &[Vec<f32>]| -> Vec<Example> {
        tally
            .iter()
            .map(|(q, &(positives, total))| Example {
                x: head_input(&table[q.target], &table[q.container], &table[q.room]),
                positives,
                total,
            })
            .collect()
    };
    // Every head is its own job: two cores train two at a time, and the results come back in
    // job order whatever finished first.
    let jobs: Vec<(bool, usize, usize)> = [false, true]
        .into_iter()
        .flat_map(|control| {
            (0..folds).flat_map(move |k| (0..settings.seeds.max(1)).map(move |s| (control, k, s)))
        })
        .collect();
    let heads: Vec<Head> = jobs
        .par_iter()
        .map(|&(control, k, s)| {
            let table = if control {
                &control_vectors
            } else {
                &language_vectors
            };
            let seed = settings
                .seed
                .wrapping_add((k * settings.seeds.max(1) + s) as u64)
                .wrapping_add(if control { 1 << 32 } else { 0 });
            Head::train(&examples(&learn[k], table), &settings.head, seed)
        })
        .collect();
    let mut by_model: [Vec<Vec<Head>>; 2] = [vec![Vec::new(); folds], vec![Vec::new(); folds]];
    for (&(control, k, _), head) in jobs.iter().zip(heads) {
        by_model[usize::from(control)][k].push(head);
    }
    let [language_heads, control_heads] = by_model;

    // The prior of each fold: counted on the other houses, without the fold's container and
    // room types, forgetting its target types; calibrated as the full prior is.
    let fold_priors: Vec<Prior> = (0..folds)
        .map(|k| {
            let keep = |c: &ObjectType, room: &str| {
                fold_in(&container_fold, c.as_str()) != k && fold_in(&room_fold, room) != k
            };
            let counted = Prior::count_where(
                scenes
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| i % folds != k)
                    .map(|(_, s)| *s),
                prior.smoothing,
                &keep,
            )
            .without_types(&|t: &ObjectType| fold_of(t.as_str(), folds) == k);
            counted.with_calibration(prior.calibration.clone())
        })
        .collect();

    let fit_model = |heads: Vec<Vec<Head>>,
                     table: &[Vec<f32>],
                     compare: bool|
     -> Result<LearnedModel, PlanError> {
        // (prior logit, head logit, evidence, holders, asked, target unseen) per blind question,
        // and its fold and question.
        let mut rows = Vec::new();
        let mut asked = Vec::new();
        for (k, tally) in blind.iter().enumerate() {
            for (q, &(pos, n)) in tally {
                let x = head_input(&table[q.target], &table[q.container], &table[q.room]);
                let lh = mean_logit(&heads[k], &x);
                let target = ObjectType::new(names[q.target].as_str());
                let container = ObjectType::new(names[q.container].as_str());
                let room = names[q.room].as_str();
                let p = fold_priors[k].probability(&target, &container, Some(room));
                let e = fold_priors[k].evidence(&target, &container, room);
                rows.push((logit(p.get()), lh, e, pos, n, target_fold[q.target] == k));
                asked.push((k, *q));
            }
        }
        let head_rows: Vec<([f64; 2], f64, f64)> =
            rows.iter().map(|r| ([r.1, 1.0], r.3, r.4)).collect();
        let head_fit = fit_counts(&head_rows, [1.0, 0.0], [false, false]).ok_or_else(|| {
            learned_error("the head's scaling could not be fitted (one class only)")
        })?;
        let fusion_rows: Vec<([f64; FUSION_WEIGHTS], f64, f64)> = rows
            .iter()
            .map(|r| (fusion_features(r.0, r.1, &r.2), r.3, r.4))
            .collect();
        let mut start = [0.0; FUSION_WEIGHTS];
        start[0] = 1.0;
        let mut penalised = [true; FUSION_WEIGHTS];
        penalised[2] = false;
        let fusion = fit_counts(&fusion_rows, start, penalised)
            .ok_or_else(|| learned_error("the fusion could not be fitted (one class only)"))?;
        let scored = |only_unseen: bool| {
            let pick: Vec<_> = rows
                .iter()
                .zip(&fusion_rows)
                .filter(|(r, _)| !only_unseen || r.5)
                .collect();
            let score = |f: &dyn Fn(usize) -> f64| {
                weighted_auroc(
                    &pick
                        .iter()
                        .enumerate()
                        .map(|(i, (r, _))| (f(i), r.3, r.4))
                        .collect::<Vec<_>>(),
                )
            };
            HeldOutScore {
                questions: pick.iter().map(|(r, _)| r.4).sum(),
                positives: pick.iter().map(|(r, _)| r.3).sum(),
                prior_auroc: score(&|i| pick[i].0.0),
                head_auroc: score(&|i| pick[i].0.1),
                fused_auroc: score(&|i| pick[i].1.0.iter().zip(&fusion).map(|(x, w)| x * w).sum()),
            }
        };
        let counts_in_head = compare.then(|| {
            let joint: Vec<JointRow> = rows
                .iter()
                .zip(&fusion_rows)
                .zip(&asked)
                .map(|((r, f), &(k, q))| {
                    let mut x = head_input(&table[q.target], &table[q.container], &table[q.room]);
                    x.extend(
                        [r.0, r.2.target, r.2.container, r.2.room, r.2.pair].map(|v| v as f32),
                    );
                    JointRow {
                        fold: k,
                        features: f.0,
                        x,
                        positives: r.3,
                        total: r.4,
                        unseen: r.5,
                    }
                })
                .collect();
            let held = |i: usize, k: usize| held_out(&asked[i].1, k);
            compare_counts_in_head(&joint, folds, &held, settings)
        });
        Ok(LearnedModel {
            heads,
            head_fit,
            fusion: fusion.to_vec(),
            score: scored(false),
            unseen_score: scored(true),
            counts_in_head,
        })
    };
    let language = fit_model(
        language_heads,
        &language_vectors,
        settings.compare_counts_in_head,
    )?;
    let control = fit_model(control_heads, &control_vectors, false)?;
    Ok(Learned {
        ferret_learned: LEARNED_FORMAT,
        embedding: embedding.to_string(),
        dim,
        settings: settings.clone(),
        vectors: vectors.into_iter().filter(|(n, _)| !n.is_empty()).collect(),
        language,
        control,
    })
}

/// One cross-fitted question for [`compare_counts_in_head`].
struct JointRow {
    /// The fold whose heads and prior answered it blind.
    fold: usize,
    /// The fusion's inputs ([`fusion_features`]).
    features: [f64; FUSION_WEIGHTS],
    /// The joint head's inputs: [`head_input`], then the prior's logit and the four gaps.
    x: Vec<f32>,
    positives: f64,
    total: f64,
    /// Whether the target type was never seen by that fold.
    unseen: bool,
}

/// [`CountsInHead`] over cross-fitted rows: for each fold j, the fusion and a joint head are
/// fitted on the other folds' rows that hold none of fold j's types (`held(i, j)`), and score
/// fold j's rows.
fn compare_counts_in_head(
    rows: &[JointRow],
    folds: usize,
    held: &(dyn Fn(usize, usize) -> bool + Sync),
    settings: &LearnedSettings,
) -> CountsInHead {
    let scores: Vec<Vec<(usize, f64, f64)>> = (0..folds)
        .into_par_iter()
        .map(|j| {
            let train: Vec<usize> = (0..rows.len())
                .filter(|&i| rows[i].fold != j && !held(i, j))
                .collect();
            let fusion_rows: Vec<([f64; FUSION_WEIGHTS], f64, f64)> = train
                .iter()
                .map(|&i| (rows[i].features, rows[i].positives, rows[i].total))
                .collect();
            let mut start = [0.0; FUSION_WEIGHTS];
            start[0] = 1.0;
            let mut penalised = [true; FUSION_WEIGHTS];
            penalised[2] = false;
            let w = fit_counts(&fusion_rows, start, penalised).unwrap_or(start);
            let examples: Vec<Example> = train
                .iter()
                .map(|&i| Example {
                    x: rows[i].x.clone(),
                    positives: rows[i].positives,
                    total: rows[i].total,
                })
                .collect();
            let heads: Vec<Head> = (0..settings.seeds.max(1))
                .map(|s| {
                    let seed = settings
                        .seed
                        .wrapping_add((j * settings.seeds.max(1) + s) as u64)
                        .wrapping_add(2 << 32);
                    Head::train(&examples, &settings.head, seed)
                })
                .collect();
            (0..rows.len())
                .filter(|&i| rows[i].fold == j)
                .map(|i| {
                    let fused: f64 = rows[i].features.iter().zip(&w).map(|(x, w)| x * w).sum();
                    (i, fused, mean_logit(&heads, &rows[i].x))
                })
                .collect()
        })
        .collect();
    let scored: Vec<(usize, f64, f64)> = scores.into_iter().flatten().collect();
    let measure = |only_unseen: bool, pick: &dyn Fn(&(usize, f64, f64)) -> f64| {
        let chosen: Vec<(f64, f64, f64)> = scored
            .iter()
            .filter(|s| !only_unseen || rows[s.0].unseen)
            .map(|s| (pick(s), rows[s.0].positives, rows[s.0].total))
            .collect();
        (weighted_auroc(&chosen), grouped_log_loss(&chosen))
    };
    let (fusion_auroc, fusion_log_loss) = measure(false, &|s| s.1);
    let (head_auroc, head_log_loss) = measure(false, &|s| s.2);
    let (fusion_auroc_unseen, fusion_log_loss_unseen) = measure(true, &|s| s.1);
    let (head_auroc_unseen, head_log_loss_unseen) = measure(true, &|s| s.2);
    CountsInHead {
        fusion_auroc,
        head_auroc,
        fusion_log_loss,
        head_log_loss,
        fusion_auroc_unseen,
        head_auroc_unseen,
        fusion_log_loss_unseen,
        head_log_loss_unseen,
    }
}

/// Mean cross-entropy (nats per container) of logits over grouped rows (logit, positives,
/// total).
fn grouped_log_loss(rows: &[(f64, f64, f64)]) -> f64 {
    let (loss, n) = rows.iter().fold((0.0, 0.0), |(loss, n), &(z, pos, total)| {
        // −log σ(z) = softplus(−z) and −log(1 − σ(z)) = softplus(z), without overflow.
        (
            loss + pos * softplus(-z) + (total - pos) * softplus(z),
            n + total,
        )
    });
    if n > 0.0 { loss / n } else { 0.0 }
}

/// ln(1 + e^x), exact for large |x|.
fn softplus(x: f64) -> f64 {
    if x > 30.0 { x } else { x.exp().ln_1p() }
}

/// AUROC of scores over grouped rows (score, positives, total): the chance that a random holder
/// scores above a random other container, ties counting half.
pub(super) fn weighted_auroc(rows: &[(f64, f64, f64)]) -> f64 {
    let mut sorted: Vec<&(f64, f64, f64)> = rows.iter().collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut neg_below, mut area) = (0.0, 0.0);
    let (pos_all, neg_all): (f64, f64) = rows
        .iter()
        .fold((0.0, 0.0), |(p, n), r| (p + r.1, n + r.2 - r.1));
    let mut i = 0;
    while i < sorted.len() {
        let mut j = i;
        let (mut pos, mut neg) = (0.0, 0.0);
        while j < sorted.len() && sorted[j].0 == sorted[i].0 {
            pos += sorted[j].1;
            neg += sorted[j].2 - sorted[j].1;
            j += 1;
        }
        area += pos * (neg_below + 0.5 * neg);
        neg_below += neg;
        i = j;
    }
    if pos_all > 0.0 && neg_all > 0.0 {
        area / (pos_all * neg_all)
    } else {
        0.5
    }
}
