//! The prior: presence-conditioned counts on hand-made houses, the back-off for types it never
//! saw, hold-out folds that must not leak, its calibration, and the fusion fit with a control.

use ferret_plan::{
    FusionSample, FusionWeights, HoldOut, LikelihoodSource, Noise, Prior, Probability, RawPrior,
};
use ferret_world::{
    Container, Footprint, GroundTruth, House, ObjectType, Point, Polygon, Pose, Room, RoomType,
    Scene, SmallObject,
};
use proptest::prelude::*;
use std::sync::Arc;

/// A house of one room of `room` type whose containers have `kinds` and hold `contents`.
fn scene(index: usize, room: &str, containers: &[(&str, &[&str])]) -> Scene {
    let rooms = vec![Room {
        id: "room|1".into(),
        room_type: RoomType::new(room),
        floor: Polygon::new(vec![
            Point::new(0.0, 0.0),
            Point::new(10.0, 0.0),
            Point::new(10.0, 10.0),
            Point::new(0.0, 10.0),
        ]),
    }];
    let boxes: Vec<Container> = containers
        .iter()
        .enumerate()
        .map(|(i, (kind, _))| {
            let at = Point::new(1.0 + i as f64, 1.0);
            Container {
                id: format!("1|{i}"),
                object_type: ObjectType::new(*kind),
                room: Some(0),
                position: at,
                footprint: Footprint {
                    center: at,
                    size_x: 0.5,
                    size_z: 0.5,
                    yaw_deg: 0.0,
                },
                access: None,
            }
        })
        .collect();
    let truth = GroundTruth::new(
        containers
            .iter()
            .map(|(_, held)| {
                held.iter()
                    .enumerate()
                    .map(|(j, t)| SmallObject {
                        id: format!("small|{j}"),
                        object_type: ObjectType::new(*t),
                    })
                    .collect()
            })
            .collect(),
    );
    Scene {
        house: House {
            name: format!("hand-made#{index}"),
            index,
            rooms,
            walls: vec![],
            doors: vec![],
            containers: boxes,
            obstacles: vec![],
            start: Pose {
                position: Point::new(5.0, 5.0),
                yaw_deg: 0.0,
            },
            map: None,
        },
        truth,
    }
}

/// Four kitchens with a fridge and a counter: eggs in the fridge of houses 0 and 1 (no egg at
/// all in 2 and 3), a book on the counter of houses 0, 2 and 3.
fn kitchens() -> Vec<Scene> {
    vec![
        scene(
            0,
            "Kitchen",
            &[("Fridge", &["Egg"]), ("CounterTop", &["Book"])],
        ),
        scene(1, "Kitchen", &[("Fridge", &["Egg"]), ("CounterTop", &[])]),
        scene(2, "Kitchen", &[("Fridge", &[]), ("CounterTop", &["Book"])]),
        scene(3, "Kitchen", &[("Fridge", &[]), ("CounterTop", &["Book"])]),
    ]
}

fn t(name: &str) -> ObjectType {
    ObjectType::new(name)
}

fn p(prior: &Prior, target: &str, container: &str, room: &str) -> f64 {
    prior
        .probability(&t(target), &t(container), Some(room))
        .get()
}

fn raw(prior: &Prior, target: &str, container: &str, room: &str) -> f64 {
    prior
        .raw_probability(&t(target), &t(container), Some(room))
        .get()
}

#[test]
fn presence_conditioning_counts_only_houses_that_held_the_target() {
    // Without smoothing the estimates are the plain ratios of the counts.
    let prior = Prior::count(&kitchens(), 0.0);
    // Eggs were in 2 of 4 fridges, but in both fridges of the 2 houses that had eggs.
    assert!((raw(&prior, "Egg", "Fridge", "Kitchen") - 0.5).abs() < 1e-12);
    assert!((p(&prior, "Egg", "Fridge", "Kitchen") - 1.0).abs() < 1e-12);
    assert!(p(&prior, "Egg", "CounterTop", "Kitchen").abs() < 1e-12);
    // Books: on 3 of 4 counters, and on every counter of the 3 houses that had one.
    assert!((raw(&prior, "Book", "CounterTop", "Kitchen") - 0.75).abs() < 1e-12);
    assert!((p(&prior, "Book", "CounterTop", "Kitchen") - 1.0).abs() < 1e-12);
    assert!(p(&prior, "Book", "Fridge", "Kitchen").abs() < 1e-12);
}

#[test]
fn smoothing_keeps_the_conditioned_estimate_above_the_raw_one_where_the_type_was_held() {
    let prior = Prior::count(&kitchens(), 2.0);
    for (target, container) in [("Egg", "Fridge"), ("Book", "CounterTop")] {
        let (c, r) = (
            p(&prior, target, container, "Kitchen"),
            raw(&prior, target, container, "Kitchen"),
        );
        assert!(c > r, "{target} in {container}: {c} ≤ {r}");
        assert!(c < 1.0, "smoothing keeps {c} below 1");
    }
}

#[test]
fn a_type_never_seen_gets_the_rate_of_any_object_in_that_kind_of_container() {
    let prior = Prior::count(&kitchens(), 0.0);
    // Containers in houses holding a type, over both types: fridges 2 of 5 held it, counters 3
    // of 5. A mug (never seen) is likelier on a counter than in a fridge, by exactly that.
    assert!((p(&prior, "Mug", "Fridge", "Kitchen") - 0.4).abs() < 1e-12);
    assert!((p(&prior, "Mug", "CounterTop", "Kitchen") - 0.6).abs() < 1e-12);
    // A container type never seen: the rate of any object in any container (5 of 10).
    assert!((p(&prior, "Mug", "Bathtub", "Bathroom") - 0.5).abs() < 1e-12);
    assert!(!prior.has_seen(&t("Mug")) && prior.has_seen(&t("Egg")));
    // No evidence at all: the gap is 1; two containers seen with eggs: s / (2 + s).
    assert_eq!(prior.evidence_gap(&t("Mug"), &t("Fridge")), 1.0);
    assert_eq!(prior.evidence_gap(&t("Egg"), &t("Bathtub")), 1.0);
    assert!((prior.evidence_gap(&t("Egg"), &t("Fridge")) - 1.0 / 3.0).abs() < 1e-12);
}

#[test]
fn an_empty_prior_says_what_the_uniform_source_says() {
    let prior = Prior::count(std::iter::empty::<&Scene>(), 2.0);
    let u = ferret_plan::Uniform::default().p.get();
    assert!((p(&prior, "Egg", "Fridge", "Kitchen") - u).abs() < 1e-12);
}

/// The scenes without any object of a type `hidden` accepts.
fn without(scenes: &[Scene], hidden: &dyn Fn(&ObjectType) -> bool) -> Vec<Scene> {
    scenes
        .iter()
        .map(|s| Scene {
            house: s.house.clone(),
            truth: GroundTruth::new(
                (0..s.house.containers.len())
                    .map(|c| {
                        s.truth
                            .contents(c)
                            .iter()
                            .filter(|o| !hidden(&o.object_type))
                            .cloned()
                            .collect()
                    })
                    .collect(),
            ),
        })
        .collect()
}

#[test]
fn a_held_out_fold_is_exactly_a_prior_trained_without_its_types() {
    let scenes = ferret_world::generate::default_scenes(40, 17).unwrap();
    let prior = Prior::count(&scenes, 2.0);
    let folds = 3;
    let every = prior.holding_out(HoldOut::every_fold(folds).unwrap());
    let types: Vec<ObjectType> = prior.seen_types().cloned().collect();
    assert!(
        types.len() > 10,
        "the generated houses hold {} types",
        types.len()
    );
    for k in 0..folds {
        let in_fold = |o: &ObjectType| HoldOut::fold_of(o, folds) == k;
        let retrained = Prior::count(&without(&scenes, &in_fold), 2.0);
        let forgot = prior.without_types(&in_fold);
        assert_eq!(forgot, retrained, "fold {k}: forgetting ≠ training without");
        // The file of the fold's prior names none of its types: nothing leaks.
        let json = serde_json::to_string(&forgot).unwrap();
        let one = prior.holding_out(HoldOut::one_fold(k, folds).unwrap());
        for ty in types.iter().filter(|o| in_fold(o)) {
            assert!(
                !json.contains(&format!("\"{}\"", ty.as_str())),
                "{ty:?} is still in fold {k}'s prior"
            );
            assert!(!one.has_seen(ty) && !every.has_seen(ty), "{ty:?} leaked");
            for scene in &scenes {
                let expected = retrained.likelihoods(&scene.house, ty).unwrap();
                assert_eq!(one.likelihoods(&scene.house, ty).unwrap(), expected);
                assert_eq!(every.likelihoods(&scene.house, ty).unwrap(), expected);
                assert_eq!(
                    every.evidence_gaps(&scene.house, ty),
                    retrained.evidence_gaps(&scene.house, ty)
                );
            }
        }
    }
    // Types of other folds keep their counts under one fold's hold-out.
    let one = prior.holding_out(HoldOut::one_fold(0, folds).unwrap());
    let kept = types
        .iter()
        .find(|o| HoldOut::fold_of(o, folds) != 0)
        .unwrap();
    assert!(one.has_seen(kept));
}

/// Training held every training house whole (920 MB for 20 000 houses) and one row per
/// calibration question: the same prior comes from houses kept with their types only, and the
/// calibration fitted on grouped questions is the one fitted question by question.
#[test]
fn a_prior_trained_on_houses_kept_with_their_types_only_is_the_same_prior() {
    let scenes = ferret_world::generate::default_scenes(40, 9).unwrap();
    let slim: Vec<Scene> = scenes.iter().cloned().map(Scene::into_types_only).collect();
    assert!(
        slim.iter()
            .all(|s| s.house.walls.is_empty() && s.house.obstacles.is_empty())
    );
    let full = Prior::train(&scenes, 2.0);
    assert_eq!(Prior::train(&slim, 2.0), full);
    // The calibration question by question, as it was fitted before.
    let folds = ferret_plan::CALIBRATION_FOLDS;
    let mut rows = Vec::new();
    for f in 0..folds {
        let counted = Prior::count(
            scenes
                .iter()
                .enumerate()
                .filter(|(i, _)| i % folds != f)
                .map(|(_, s)| s),
            2.0,
        );
        for scene in scenes.iter().skip(f).step_by(folds) {
            for target in scene.truth.target_types() {
                let ps = counted.likelihoods(&scene.house, &target).unwrap();
                for (c, p) in ps.iter().enumerate() {
                    rows.push((
                        [ferret_plan::logistic::logit(p.get()), 1.0],
                        scene.truth.holds(c, &target),
                    ));
                }
            }
        }
    }
    let w = ferret_plan::logistic::fit(&rows, [1.0, 0.0], [true, false]).unwrap();
    let c = full.calibration.expect("40 houses are enough");
    assert_eq!(c.pairs, rows.len() as u64);
    assert!(
        (c.a - w[0]).abs() < 1e-9 && (c.c - w[1]).abs() < 1e-9,
        "{c:?} against {w:?}"
    );
}

#[test]
fn a_trained_prior_is_calibrated_on_its_own_houses_and_round_trips() {
    let scenes = ferret_world::generate::default_scenes(60, 5).unwrap();
    let prior = Prior::train(&scenes, 2.0);
    let c = prior
        .calibration
        .clone()
        .expect("60 houses are enough to fit");
    assert_eq!(c.folds, ferret_plan::CALIBRATION_FOLDS);
    assert!(c.a.is_finite() && c.c.is_finite() && c.a > 0.0, "{c:?}");
    assert!(c.positives > 0 && c.positives < c.pairs);
    // The calibration keeps the order of the counted estimates.
    let counted = Prior::count(&scenes, 2.0);
    let house = &scenes[0].house;
    for target in scenes[0].truth.target_types() {
        let a = counted.likelihoods(house, &target).unwrap();
        let b = prior.likelihoods(house, &target).unwrap();
        for i in 0..a.len() {
            for j in 0..a.len() {
                if a[i].get() < a[j].get() {
                    assert!(b[i].get() <= b[j].get());
                }
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("prior.json");
    prior.save(&path).unwrap();
    assert_eq!(Prior::load(&path).unwrap(), prior);
    // Too few houses to fit on: counted only.
    assert!(Prior::train(&scenes[..5], 2.0).calibration.is_none());
    assert!(Prior::train_with(&scenes, 2.0, 0).calibration.is_none());
}

#[test]
fn a_saved_prior_reads_back_as_the_very_same_numbers() {
    // The default prior's calibration slope is one whose decimal form a fast float parser reads
    // one unit in the last place off; the fingerprint that ties fusion weights to a prior would
    // then differ between a prior in memory and its file.
    let scenes = ferret_world::generate::default_scenes(500, 1_000_003).unwrap();
    let prior = Prior::train(&scenes, 2.0);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("prior.json");
    prior.save(&path).unwrap();
    let read = Prior::load(&path).unwrap();
    assert_eq!(read.calibration, prior.calibration);
    assert!(read == prior, "the counts read back differ");
    assert_eq!(
        ferret_plan::prior_fingerprint(&read),
        ferret_plan::prior_fingerprint(&prior)
    );
}

#[test]
fn a_prior_file_without_presence_counts_is_refused_with_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.json");
    std::fs::write(
        &path,
        r#"{"smoothing": 2.0, "houses": 1, "by_pair": {}, "by_container": {},
            "overall": {"containers": 1, "holding": {"Egg": 1}}}"#,
    )
    .unwrap();
    let e = Prior::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("old.json") && e.contains("ferret prior train"),
        "{e}"
    );
}

#[test]
fn the_raw_source_is_the_uncalibrated_estimate() {
    let scenes = ferret_world::generate::default_scenes(30, 3).unwrap();
    let prior = Arc::new(Prior::train(&scenes, 2.0));
    let raw = RawPrior(prior.clone());
    assert_eq!(raw.name(), "prior-raw");
    let house = &scenes[1].house;
    let target = scenes[1].truth.target_types().into_iter().next().unwrap();
    let got = raw.likelihoods(house, &target).unwrap();
    for (c, container) in house.containers.iter().enumerate() {
        let room = house.container_room(c).map(|r| r.room_type.as_str());
        assert_eq!(
            got[c],
            prior.raw_probability(&target, &container.object_type, room)
        );
    }
}

/// The fusion samples of `source` against `prior` on every target of `scenes`.
fn samples(prior: &Prior, source: &dyn LikelihoodSource, scenes: &[Scene]) -> Vec<FusionSample> {
    let mut out = Vec::new();
    for s in scenes {
        for target in s.truth.target_types() {
            let pp = prior.likelihoods(&s.house, &target).unwrap();
            let po = source.likelihoods(&s.house, &target).unwrap();
            let gaps = prior.evidence_gaps(&s.house, &target);
            for c in 0..pp.len() {
                out.push(FusionSample {
                    prior: pp[c].get(),
                    other: po[c].get(),
                    gap: gaps[c],
                    holds: s.truth.holds(c, &target),
                });
            }
        }
    }
    out
}

#[test]
fn a_fit_with_the_noise_control_gives_the_noise_almost_no_weight() {
    let training = ferret_world::generate::default_scenes(150, 1).unwrap();
    let fit_on = ferret_world::generate::default_scenes(60, 2).unwrap();
    let prior = Prior::train(&training, 2.0);
    // Seen and unseen questions both, as `calibrate --fit-fusion` fits them.
    let unseen = prior.holding_out(HoldOut::every_fold(5).unwrap());
    let mut all = samples(&prior, &Noise::default(), &fit_on);
    all.extend(samples(&unseen, &Noise::default(), &fit_on));
    let w = FusionWeights::fit(&all).unwrap();
    assert!(w.b.abs() < 0.1, "noise got weight b = {}", w.b);
    assert!(
        (w.b + w.d).abs() < 0.2,
        "noise got weight where unseen: {w:?}"
    );
    // A source that knows the truth gets it, most of all where the prior has no evidence.
    struct Truthful<'a>(&'a [Scene]);
    impl LikelihoodSource for Truthful<'_> {
        fn name(&self) -> &str {
            "truthful"
        }
        fn likelihoods(
            &self,
            house: &House,
            target: &ObjectType,
        ) -> Result<Vec<Probability>, ferret_plan::PlanError> {
            let s = self.0.iter().find(|s| s.house.name == house.name).unwrap();
            Ok((0..house.containers.len())
                .map(|c| {
                    Probability::clamped(if s.truth.holds(c, target) { 0.7 } else { 0.2 }, 0.0, 1.0)
                })
                .collect())
        }
    }
    let mut all = samples(&prior, &Truthful(&fit_on), &fit_on);
    all.extend(samples(&unseen, &Truthful(&fit_on), &fit_on));
    let w = FusionWeights::fit(&all).unwrap();
    assert!(w.b > 0.5, "{w:?}");
}

#[test]
fn the_noise_control_answers_each_question_the_same_way() {
    let n = Noise::default();
    let a = n.probability(&t("Egg"), &t("Fridge"), "Kitchen");
    assert_eq!(a, n.probability(&t("Egg"), &t("Fridge"), "Kitchen"));
    assert_ne!(a, n.probability(&t("Egg"), &t("Fridge"), "Bedroom"));
    assert_ne!(
        a,
        Noise { seed: 1 }.probability(&t("Egg"), &t("Fridge"), "Kitchen")
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// On random houses: every probability is in [0, 1], every evidence gap in (0, 1], the gap
    /// is 1 exactly where the type was never in a house beside that kind of container, and
    /// without smoothing the conditioned estimate of a seen pair is never below the raw one.
    #[test]
    fn estimates_and_gaps_keep_their_bounds(
        houses in prop::collection::vec(
            prop::collection::vec((0usize..3, prop::collection::vec(0usize..4, 0..3)), 1..4),
            1..8,
        ),
        smoothing in 0.0f64..4.0,
    ) {
        const KINDS: [&str; 3] = ["Fridge", "Bed", "Desk"];
        const OBJECTS: [&str; 4] = ["Egg", "Book", "Pen", "Mug"];
        let scenes: Vec<Scene> = houses
            .iter()
            .enumerate()
            .map(|(i, cs)| {
                let held: Vec<Vec<&str>> = cs
                    .iter()
                    .map(|(_, objs)| objs.iter().map(|&o| OBJECTS[o]).collect())
                    .collect();
                let spec: Vec<(&str, &[&str])> = cs
                    .iter()
                    .zip(&held)
                    .map(|((k, _), h)| (KINDS[*k], h.as_slice()))
                    .collect();
                scene(i, "Kitchen", &spec)
            })
            .collect();
        let prior = Prior::count(&scenes, smoothing);
        let flat = Prior::count(&scenes, 0.0);
        for target in OBJECTS {
            for kind in KINDS {
                let v = p(&prior, target, kind, "Kitchen");
                prop_assert!((0.0..=1.0).contains(&v));
                let g = prior.evidence_gap(&t(target), &t(kind));
                prop_assert!(g > 0.0 && g <= 1.0);
                let together = scenes.iter().any(|s| {
                    s.truth.target_types().contains(&t(target))
                        && s.house.containers.iter().any(|c| c.object_type.as_str() == kind)
                });
                prop_assert_eq!(g == 1.0, !together);
                if together {
                    prop_assert!(p(&flat, target, kind, "Kitchen") >= raw(&flat, target, kind, "Kitchen") - 1e-12);
                }
            }
        }
    }
}
