//! Calibration and selection on small generated houses, as the faces call them.

use std::sync::Arc;

use ferret_lab::calibrate::{CalibrationSettings, TargetCount, calibrate, targets_for};
use ferret_lab::selection::select;
use ferret_lab::{
    EvalRun, HouseSource, LlmSettings, PlanningSettings, RunInfo, Silent, Strategies, TrialDraw,
    build_maps, evaluate,
};
use ferret_plan::{Protocol, Strategy, TrialsPerHouse};
use ferret_select::{ExperimentOptions, Method};
use ferret_world::GridParams;

fn generated(count: usize, seed: u64) -> HouseSource {
    HouseSource {
        generate: count,
        house_seed: seed,
        ..HouseSource::default()
    }
}

/// No LLM endpoint (no `ferret.toml` where the tests run), the cache in `dir`.
fn offline_llm(dir: &std::path::Path) -> LlmSettings {
    LlmSettings {
        llm_cache: dir.join("cache.sqlite"),
        ..LlmSettings::default()
    }
}

#[test]
fn calibration_scores_every_container_of_every_target_and_the_prior_beats_uniform() {
    let dir = tempfile::tempdir().unwrap();
    let loaded = generated(8, 21)
        .load_for(ferret_world::ContainerSet::Receptacles)
        .unwrap();
    let settings = CalibrationSettings {
        targets_per_house: TargetCount::N(2),
        ..CalibrationSettings::default()
    };
    let llm = offline_llm(dir.path());
    let specs = settings.specs_to_build().unwrap();
    let setup = Strategies::builder(&PlanningSettings::default(), &llm)
        .for_specs(&specs)
        .build()
        .unwrap();
    let done = calibrate(&loaded, &setup, &llm, &settings, &Silent).unwrap();
    assert!(done.errors.is_empty(), "{:?}", done.errors);
    // Every (house, target, container) is one pair; holders are the containers holding it.
    let (mut pairs, mut holders, mut trials) = (0u64, 0u64, 0usize);
    for scene in &loaded.scenes {
        for t in targets_for(scene, TargetCount::N(2), 0) {
            trials += 1;
            pairs += scene.house.containers.len() as u64;
            holders += scene.truth.goal_containers(&t).len() as u64;
        }
    }
    assert_eq!(done.trials, trials);
    let names: Vec<&str> = done.scored.iter().map(|(s, _)| s.as_str()).collect();
    assert_eq!(names, ["model/uniform", "model/prior"]);
    for (source, c) in &done.scored {
        assert_eq!((c.pairs, c.positives), (pairs, holders), "{source}");
    }
    let (uniform, prior) = (&done.scored[0].1, &done.scored[1].1);
    assert!(
        prior.brier < uniform.brier,
        "prior {} vs uniform {}",
        prior.brier,
        uniform.brier
    );
    assert!(prior.auroc.unwrap() > 0.6);
    // The CSV rows are the scores, flat, in the same order.
    let rows = ferret_lab::calibrate::calibration_rows(&done.scored);
    let json = serde_json::to_value(&rows).unwrap();
    assert_eq!(json[1]["source"], "model/prior");
    assert_eq!(json[1]["brier"], prior.brier);
    assert!(json[1].get("bins").is_none());
    assert!(done.markdown.contains("| model/prior |"));
    assert!(done.fusion.is_none());
}

#[test]
fn calibration_refuses_a_strategy_without_probabilities_and_a_fit_without_an_llm() {
    let dir = tempfile::tempdir().unwrap();
    let loaded = generated(2, 4)
        .load_for(ferret_world::ContainerSet::Receptacles)
        .unwrap();
    let run = |sources: &[&str], fit_fusion| {
        let settings = CalibrationSettings {
            sources: sources.iter().map(|s| s.to_string()).collect(),
            fit_fusion,
            ..CalibrationSettings::default()
        };
        let llm = offline_llm(dir.path());
        let specs = match settings.specs_to_build() {
            Ok(specs) => specs,
            Err(e) => return e.to_string(),
        };
        let setup = Strategies::builder(&PlanningSettings::default(), &llm)
            .for_specs(&specs)
            .build()
            .unwrap();
        calibrate(&loaded, &setup, &llm, &settings, &Silent)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    assert!(
        run(&["optimistic+greedy"], false).contains("plans over no likelihood source"),
        "{}",
        run(&["optimistic+greedy"], false)
    );
    assert!(run(&["model/prior"], true).contains("--fit-fusion"));
    assert!(run(&[], false).contains("--sources names no source"));
}

/// An evaluation of three strategies on `count` generated houses, as `ferret eval` writes it.
fn eval_run(dir: &std::path::Path, count: usize) -> EvalRun {
    let source = generated(count, 8);
    let loaded = source
        .load_for(ferret_world::ContainerSet::Receptacles)
        .unwrap();
    let grid = GridParams::default();
    let maps = build_maps(&loaded.scenes, &grid, &Silent);
    let specs = ["optimistic+greedy", "model/uniform", "model/prior"];
    let planning = PlanningSettings::default();
    let names: Vec<String> = specs.iter().map(|s| s.to_string()).collect();
    let setup = Strategies::builder(&planning, &LlmSettings::default())
        .for_specs(&names)
        .build()
        .unwrap();
    let strategies: Vec<Arc<dyn Strategy>> = specs
        .iter()
        .map(|s| setup.registry.build(s).unwrap())
        .collect();
    let draw = TrialDraw {
        seed: 0,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::One,
        protocol: &Protocol::FERRET,
        holdout: None,
        tasks: None,
        team: None,
    };
    let ev = evaluate(&loaded.scenes, &maps, &strategies, &draw, &Silent);
    assert!(ev.errors.is_empty(), "{:?}", ev.errors);
    let info = RunInfo {
        houses: None,
        range: None,
        asset_db: None,
        generate: count,
        house_seed: 8,
        grid: [grid.resolution, grid.robot_radius, grid.wall_thickness],
        planning,
        seed: 0,
        reveal_fraction: 0.0,
        trials_per_house: TrialsPerHouse::One,
        protocol: Protocol::FERRET,
        tasks: None,
        team: None,
        strategies: names,
        trials_sha256: None,
        shard: None,
        merged_from: Vec::new(),
    };
    let run = EvalRun::new(info, ev.rows).unwrap();
    run.write(dir).unwrap();
    run
}

#[test]
fn a_written_run_reads_back_and_selection_over_it_replays_and_deploys() {
    let dir = tempfile::tempdir().unwrap();
    let run = eval_run(dir.path(), 6);
    let back = EvalRun::read(dir.path()).unwrap();
    assert_eq!(back.trials_csv, run.trials_csv);
    assert_eq!(back.run_json, run.run_json);
    assert_eq!(back.rows.len(), 18);
    let settings = ExperimentOptions {
        deployments: 12,
        trials_per_deployment: 5,
        ..ExperimentOptions::default()
    };
    let llm = offline_llm(dir.path());
    let done = select(
        &run,
        dir.path(),
        &Protocol::FERRET,
        &llm,
        &settings,
        &Silent,
    )
    .unwrap();
    assert_eq!(done.replay.candidates.len(), 3);
    assert_eq!(done.result.deployments.len(), 12);
    for method in Method::ALL {
        let s = done.result.summary(method).unwrap();
        assert_eq!(s.avg_cost.len(), 5);
        // Each deployment's choices sum to one at every k.
        for shares in &s.choice_fraction {
            assert!((shares.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        }
    }
    assert!(dir.path().join("replay.csv").exists());
    assert!(
        done.markdown
            .starts_with("# Strategy selection\n\n12 deployments × 5 trials")
    );
    // The second selection reads every replay from the cache: same result.
    let again = select(
        &run,
        dir.path(),
        &Protocol::FERRET,
        &llm,
        &settings,
        &Silent,
    )
    .unwrap();
    assert_eq!(again.result, done.result);
}

#[test]
fn selection_names_the_option_it_cannot_use() {
    let dir = tempfile::tempdir().unwrap();
    let run = eval_run(dir.path(), 3);
    let llm = offline_llm(dir.path());
    let err = |settings: ExperimentOptions| {
        select(
            &run,
            dir.path(),
            &Protocol::FERRET,
            &llm,
            &settings,
            &Silent,
        )
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
    };
    let base = ExperimentOptions {
        deployments: 2,
        trials_per_deployment: 2,
        ..ExperimentOptions::default()
    };
    assert!(
        err(ExperimentOptions {
            trials_per_deployment: 4,
            ..base
        })
        .starts_with("--trials-per-deployment 4: only 3 houses of")
    );
    assert!(err(ExperimentOptions { c: -1.0, ..base }).starts_with("--c -1"));
    assert!(
        err(ExperimentOptions {
            deployments: 0,
            ..base
        })
        .starts_with("--deployments 0")
    );
    assert!(err(base).is_empty());
}
