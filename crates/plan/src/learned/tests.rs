use super::train::{kind_folds, weighted_auroc};
use super::*;
use crate::HoldOut;
use crate::likelihood::LikelihoodSource;
use crate::logistic::fit_counts;
use crate::prior::Prior;
use ferret_world::generate;
use proptest::prelude::*;

const DIM: usize = 6;

fn scenes(n: usize) -> Vec<Scene> {
    generate::default_scenes(n, 41).unwrap()
}

fn every_name(scenes: &[Scene]) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for s in scenes {
        names.extend(scene_names(s));
    }
    names.remove("");
    names
}

/// Vectors for every name: pseudo-random, with `salt` changing the names `changed` accepts.
fn vectors(
    names: &BTreeSet<String>,
    salt: &str,
    changed: &dyn Fn(&str) -> bool,
) -> BTreeMap<String, Vec<f32>> {
    names
        .iter()
        .map(|n| {
            let key = if changed(n) {
                format!("{salt}{n}")
            } else {
                n.clone()
            };
            (n.clone(), random_vector(&key, DIM))
        })
        .collect()
}

fn settings() -> LearnedSettings {
    LearnedSettings {
        folds: 3,
        seeds: 1,
        seed: 5,
        head: HeadSettings {
            hidden: vec![5],
            epochs: 3,
            ..HeadSettings::default()
        },
        compare_counts_in_head: false,
    }
}

fn trained(scenes: &[Scene], v: BTreeMap<String, Vec<f32>>, s: &LearnedSettings) -> Learned {
    let refs: Vec<&Scene> = scenes.iter().collect();
    let prior = Prior::train(scenes, 2.0);
    train(&refs, &prior, "test", v, s).unwrap()
}

#[test]
fn a_folds_heads_never_see_its_target_container_or_room_types_nor_its_houses() {
    let scenes = scenes(12);
    let refs: Vec<&Scene> = scenes.iter().collect();
    let s = settings();
    let names = every_name(&scenes);
    let base = trained(&scenes, vectors(&names, "", &|_| false), &s);
    let (container_fold, room_fold) = kind_folds(&refs, s.folds);
    let targets: BTreeSet<String> = scenes
        .iter()
        .flat_map(|s| s.truth.target_types())
        .map(|t| t.as_str().to_string())
        .collect();
    for k in 0..s.folds {
        // Whatever the held-out names mean to fold k's heads, they never read them: other
        // vectors for them leave those heads exactly as they were, and change the others.
        // A name is held out when every part it plays (target, container, room) is held out.
        let held = |n: &str| {
            (!targets.contains(n) || fold_of(n, s.folds) == k)
                && container_fold.get(n).is_none_or(|&f| f == k)
                && room_fold.get(n).is_none_or(|&f| f == k)
        };
        assert!(names.iter().any(|n| held(n)), "fold {k} holds nothing out");
        let moved = trained(&scenes, vectors(&names, "moved ", &held), &s);
        assert_eq!(
            moved.language.heads[k], base.language.heads[k],
            "fold {k} leaked"
        );
        assert!(
            (0..s.folds)
                .filter(|&j| j != k)
                .any(|j| moved.language.heads[j] != base.language.heads[j]),
            "fold {k}: no other head read the held-out names either"
        );
    }
    // A house of fold k changed (its contents emptied) leaves fold k's heads as they were.
    let mut emptied = scenes.clone();
    emptied[1].truth =
        ferret_world::GroundTruth::new(vec![Vec::new(); emptied[1].house.containers.len()]);
    let names_left = every_name(&emptied);
    let v: BTreeMap<String, Vec<f32>> = vectors(&names, "", &|_| false)
        .into_iter()
        .filter(|(n, _)| names_left.contains(n))
        .collect();
    let base = trained(&scenes, vectors(&names, "", &|_| false), &s);
    let changed = trained(&emptied, v, &s);
    assert_eq!(changed.language.heads[1], base.language.heads[1]);
    assert_ne!(changed.language.heads[0], base.language.heads[0]);
}

#[test]
fn the_same_inputs_give_the_same_file_and_another_seed_another() {
    let scenes = scenes(9);
    let names = every_name(&scenes);
    let s = settings();
    let a = trained(&scenes, vectors(&names, "", &|_| false), &s);
    let b = trained(&scenes, vectors(&names, "", &|_| false), &s);
    let json = |l: &Learned| serde_json::to_string(l).unwrap();
    assert_eq!(json(&a), json(&b));
    let other = trained(
        &scenes,
        vectors(&names, "", &|_| false),
        &LearnedSettings { seed: 6, ..s },
    );
    assert_ne!(json(&a), json(&other));
}

/// Measuring counts built into the head changes no answer and nothing of a file trained
/// without it; both ways are scored out of fold, where the counts and the names carry signal.
#[test]
fn comparing_counts_in_the_head_measures_both_ways_and_changes_no_answer() {
    let scenes = scenes(15);
    let names = every_name(&scenes);
    let s = LearnedSettings {
        head: HeadSettings {
            hidden: vec![8],
            epochs: 40,
            ..HeadSettings::default()
        },
        ..settings()
    };
    let plain = trained(&scenes, vectors(&names, "", &|_| false), &s);
    let json = serde_json::to_string(&plain).unwrap();
    assert!(
        !json.contains("counts_in_head"),
        "a file without the comparison is as before"
    );
    let compared = trained(
        &scenes,
        vectors(&names, "", &|_| false),
        &LearnedSettings {
            compare_counts_in_head: true,
            ..s.clone()
        },
    );
    assert_eq!(compared.language.heads, plain.language.heads);
    assert_eq!(compared.language.fusion, plain.language.fusion);
    assert_eq!(compared.control, plain.control);
    assert!(plain.language.counts_in_head.is_none());
    let j = compared.language.counts_in_head.clone().unwrap();
    // Out of fold, the fusion ranks about as the in-sample fit does, and far above chance: the
    // counted prior is in it. The joint head has the same inputs and must beat chance too.
    assert!(
        (j.fusion_auroc - compared.language.score.fused_auroc).abs() < 0.05,
        "{j:?}"
    );
    assert!(j.fusion_auroc > 0.7 && j.head_auroc > 0.6, "{j:?}");
    for loss in [j.fusion_log_loss, j.head_log_loss] {
        assert!(
            loss.is_finite() && loss > 0.0 && loss < std::f64::consts::LN_2,
            "{j:?}"
        );
    }
}

#[test]
fn a_prior_file_with_a_learned_part_reads_back_as_written_and_a_damaged_one_is_refused() {
    let scenes = scenes(9);
    let names = every_name(&scenes);
    let learned = trained(&scenes, vectors(&names, "", &|_| false), &settings());
    let prior = Prior::train(&scenes, 2.0).with_learned(learned);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("prior.json");
    prior.save(&path).unwrap();
    let back = Prior::load(&path).unwrap();
    assert_eq!(back, prior);
    assert_eq!(back.learned(), prior.learned());

    // One vector a number short: the file names what is wrong.
    let mut value: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let first = names.iter().next().unwrap().clone();
    value["learned"]["vectors"][&first]
        .as_array_mut()
        .unwrap()
        .pop();
    std::fs::write(&path, value.to_string()).unwrap();
    let err = Prior::load(&path).unwrap_err().to_string();
    assert!(err.contains("prior.json") && err.contains(&first), "{err}");

    // Weights that are not base64.
    let mut value: serde_json::Value =
        serde_json::from_str(&serde_json::to_string(&prior).unwrap()).unwrap();
    value["learned"]["language"]["heads"][0][0]["layers"][0]["w"] = "not base64!".into();
    std::fs::write(&path, value.to_string()).unwrap();
    let err = Prior::load(&path).unwrap_err().to_string();
    assert!(err.contains("base64"), "{err}");

    // Fits no training gives were taken (`[1e308, 1e308]` moved every answer), and a NaN
    // weight was reported as a head of the wrong width: each now names its field.
    let damaged = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut value: serde_json::Value =
            serde_json::from_str(&serde_json::to_string(&prior).unwrap()).unwrap();
        edit(&mut value);
        std::fs::write(&path, value.to_string()).unwrap();
        Prior::load(&path).unwrap_err().to_string()
    };
    let err =
        damaged(&|v| v["learned"]["language"]["head_fit"] = serde_json::json!([1e308, 1e308]));
    assert!(
        err.contains("language.head_fit[0]") && err.contains("±1000"),
        "{err}"
    );
    let err = damaged(&|v| v["learned"]["control"]["fusion"][3] = serde_json::json!(-5000.0));
    assert!(err.contains("control.fusion[3]"), "{err}");
    let err = damaged(&|v| {
        use base64::Engine;
        let engine = base64::engine::general_purpose::STANDARD;
        let w = &mut v["learned"]["language"]["heads"][1][0]["layers"][0]["w"];
        let mut bytes = engine.decode(w.as_str().unwrap()).unwrap();
        bytes[..4].copy_from_slice(&f32::NAN.to_le_bytes());
        *w = engine.encode(bytes).into();
    });
    assert!(
        err.contains("language.heads[1][0]") && err.contains("finite"),
        "{err}"
    );
}

fn source(prior: Prior, kind: LearnedKind) -> Result<LearnedSource, String> {
    LearnedSource::new(Arc::new(prior), kind)
}

#[test]
fn learned_sources_say_what_they_need() {
    let scenes = scenes(9);
    let plain = Prior::train(&scenes, 2.0);
    let err = source(plain, LearnedKind::Fused).unwrap_err();
    assert!(err.contains("--embeddings"), "{err}");

    let names = every_name(&scenes);
    let learned = trained(&scenes, vectors(&names, "", &|_| false), &settings());
    let prior = Prior::train(&scenes, 2.0).with_learned(learned);
    let wrong_folds = prior.holding_out(HoldOut::every_fold(5).unwrap());
    let err = source(wrong_folds, LearnedKind::Head).unwrap_err();
    assert!(err.contains("3 folds"), "{err}");

    // A house with furniture the file has no vector for: the error names it and the way out;
    // the random-vector control needs no vector.
    let mut house = scenes[0].house.clone();
    house.containers[0].object_type = ObjectType::new("ToolChest");
    let target = scenes[0].truth.target_types().into_iter().next().unwrap();
    let fused = source(prior.clone(), LearnedKind::Fused).unwrap();
    let err = fused.likelihoods(&house, &target).unwrap_err().to_string();
    assert!(
        err.contains("ToolChest") && err.contains("FERRET_EMBEDDINGS"),
        "{err}"
    );
    let control = source(prior.clone(), LearnedKind::FusedControl).unwrap();
    assert_eq!(
        control.likelihoods(&house, &target).unwrap().len(),
        house.containers.len()
    );

    // With vectors from elsewhere, it answers, and the vector counts.
    struct Fixed(Vec<f32>);
    impl NameVectors for Fixed {
        fn vector(&self, _: &str) -> Result<Vec<f32>, String> {
            Ok(self.0.clone())
        }
    }
    let answer = |v: Vec<f32>| {
        source(
            prior.with_embedder(Embedder(Arc::new(Fixed(v)))),
            LearnedKind::Head,
        )
        .unwrap()
        .likelihoods(&house, &target)
        .unwrap()[0]
    };
    let (a, b) = (
        answer(random_vector("a", DIM)),
        answer(random_vector("b", DIM)),
    );
    assert_ne!(a, b);
    let short = source(
        prior.with_embedder(Embedder(Arc::new(Fixed(vec![0.5; 2])))),
        LearnedKind::Head,
    )
    .unwrap();
    let err = short.likelihoods(&house, &target).unwrap_err().to_string();
    assert!(err.contains("2 numbers"), "{err}");
}

#[test]
fn under_a_hold_out_only_the_heads_that_never_saw_the_target_answer() {
    let scenes = scenes(9);
    let names = every_name(&scenes);
    let s = settings();
    let learned = trained(&scenes, vectors(&names, "", &|_| false), &s);
    let prior = Prior::train(&scenes, 2.0);
    let holdout = HoldOut::every_fold(s.folds).unwrap();
    let target = scenes[0].truth.target_types().into_iter().next().unwrap();
    let fold = HoldOut::fold_of(&target, s.folds);
    let answers = |learned: Learned| {
        source(
            prior.with_learned(learned).holding_out(holdout),
            LearnedKind::Fused,
        )
        .unwrap()
        .likelihoods(&scenes[0].house, &target)
        .unwrap()
    };
    let before = answers(learned.clone());
    // Other folds' heads swapped for untrained ones: nothing changes.
    let mut others = learned.clone();
    let mut blank = learned.language.heads[0][0].clone();
    blank
        .layers
        .iter_mut()
        .for_each(|l| l.w.iter_mut().for_each(|w| *w = 0.0));
    for (k, heads) in others.language.heads.iter_mut().enumerate() {
        if k != fold {
            heads.iter_mut().for_each(|h| *h = blank.clone());
        }
    }
    assert_eq!(answers(others), before);
    // The target's own fold swapped: the answers change.
    let mut own = learned;
    own.language.heads[fold]
        .iter_mut()
        .for_each(|h| *h = blank.clone());
    assert_ne!(answers(own), before);
}

/// A fusion whose base is the learned likelihood fuses the learned answers with the other
/// source, by the prior's evidence gaps; it is the prior's fusion only where the two agree.
#[test]
fn a_fusion_over_the_learned_base_fuses_the_learned_answers() {
    use crate::fusion::{Fused, FusionWeights};
    use crate::likelihood::Noise;
    let scenes = scenes(9);
    let names = every_name(&scenes);
    let s = settings();
    let learned = trained(&scenes, vectors(&names, "", &|_| false), &s);
    // Under a hold-out the learned answers differ from the prior's wherever the target's fold
    // has gaps.
    let prior = Arc::new(
        Prior::train(&scenes, 2.0)
            .with_learned(learned)
            .holding_out(HoldOut::every_fold(s.folds).unwrap()),
    );
    let base: Arc<dyn LikelihoodSource> =
        Arc::new(LearnedSource::new(prior.clone(), LearnedKind::Fused).unwrap());
    let other: Arc<dyn LikelihoodSource> = Arc::new(Noise::default());
    let w = FusionWeights {
        a: 0.9,
        b: 0.4,
        c: -0.2,
        d: 0.7,
        e: 0.3,
    };
    let over_learned = Fused::over("l", base.clone(), prior.clone(), other.clone(), w);
    let over_prior = Fused::new("p", prior.clone(), other.clone(), w);
    let mut differ = 0;
    for scene in &scenes {
        for target in scene.truth.target_types() {
            let house = &scene.house;
            let l = base.likelihoods(house, &target).unwrap();
            let o = other.likelihoods(house, &target).unwrap();
            let g = prior.evidence_gaps(house, &target);
            let got = over_learned.likelihoods(house, &target).unwrap();
            for c in 0..got.len() {
                let want = w.fuse(l[c].get(), o[c].get(), g[c]);
                assert!(
                    (got[c].get() - want).abs() < 1e-12,
                    "{} vs {want}",
                    got[c].get()
                );
            }
            if got != over_prior.likelihoods(house, &target).unwrap() {
                differ += 1;
            }
        }
    }
    assert!(differ > 0, "the learned base changed no answer");
}

#[test]
fn the_auroc_of_grouped_rows_is_that_of_the_rows_spelled_out() {
    // Scores 0.1 (1 holder of 3), 0.5 (1 of 2), 0.9 (2 of 2): holders above others in
    // 1·(0 + 0.5·2) + 1·(2 + 0.5·1) + 2·3 = 9.5 of 4·3 = 12 pairs.
    let rows = [(0.1, 1.0, 3.0), (0.5, 1.0, 2.0), (0.9, 2.0, 2.0)];
    assert!((weighted_auroc(&rows) - 9.5 / 12.0).abs() < 1e-12);
    assert_eq!(weighted_auroc(&[(0.3, 0.0, 4.0)]), 0.5);
}

proptest! {
    #[test]
    fn random_vectors_are_unit_length_fixed_per_name_and_differ_between_names(
        a in "[A-Za-z]{1,12}", b in "[A-Za-z]{1,12}", dim in 2usize..64,
    ) {
        let v = random_vector(&a, dim);
        prop_assert_eq!(v.len(), dim);
        let norm: f32 = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        prop_assert!((norm - 1.0).abs() < 1e-4);
        prop_assert_eq!(&v, &random_vector(&a, dim));
        if a != b {
            prop_assert_ne!(v, random_vector(&b, dim));
        }
    }

    #[test]
    fn a_grouped_fit_is_the_fit_of_the_rows_spelled_out(
        groups in prop::collection::vec((-3.0f64..3.0, 0u8..5, 1u8..6), 3..12),
    ) {
        let grouped: Vec<([f64; 2], f64, f64)> = groups
            .iter()
            .map(|&(x, k, n)| ([x, 1.0], f64::from(k.min(n)), f64::from(n)))
            .collect();
        let spelled: Vec<([f64; 2], bool)> = groups
            .iter()
            .flat_map(|&(x, k, n)| {
                (0..n).map(move |i| ([x, 1.0], i < k.min(n)))
            })
            .collect();
        let g = fit_counts(&grouped, [1.0, 0.0], [true, false]);
        let s = crate::logistic::fit(&spelled, [1.0, 0.0], [true, false]);
        prop_assert_eq!(g.is_some(), s.is_some());
        if let (Some(g), Some(s)) = (g, s) {
            prop_assert!((g[0] - s[0]).abs() < 1e-6 && (g[1] - s[1]).abs() < 1e-6, "{:?} {:?}", g, s);
        }
    }
}
