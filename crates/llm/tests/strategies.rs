//! `llm+model` and `llm-direct` against a loopback server, through the plan crate's registry and
//! trial simulator, as `ferret eval` runs them.

mod common;

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use common::{completion, last_message, small_scene, straight_distances};
use ferret_llm::{
    EndpointConfig, LlmConfig, LlmOptions, LlmService, LlmSpec, prefetch_probabilities,
    register_strategies,
};
use ferret_plan::{
    LikelihoodSource, PlannerConfig, Probability, SearchProblem, StrategyRegistry, StrategySpec,
    TrialSpec, run_trial,
};
use ferret_world::{House, ObjectType};
use serde_json::Value;
use wiremock::matchers::method;
use wiremock::{Mock, MockServer, Request, ResponseTemplate};

/// A loopback server on its own runtime (the tests themselves are synchronous, like rayon
/// threads).
struct Server {
    rt: tokio::runtime::Runtime,
    server: MockServer,
}

impl Server {
    fn start(respond: impl Fn(&str) -> String + Send + Sync + 'static) -> Self {
        let rt = tokio::runtime::Runtime::new().unwrap();
        let server = rt.block_on(MockServer::start());
        rt.block_on(
            Mock::given(method("POST"))
                .respond_with(move |req: &Request| {
                    let body: Value = req.body_json().unwrap_or_default();
                    ResponseTemplate::new(200).set_body_json(completion(
                        &respond(&last_message(&body)),
                        120,
                        3,
                    ))
                })
                .mount(&server),
        );
        Self { rt, server }
    }

    fn requests(&self) -> Vec<String> {
        self.rt
            .block_on(self.server.received_requests())
            .unwrap_or_default()
            .iter()
            .map(|r| last_message(&r.body_json().unwrap_or_default()))
            .collect()
    }

    fn service(&self, cache: Option<PathBuf>, offline: bool) -> Arc<LlmService> {
        let mut c = EndpointConfig::new(format!("{}/v1", self.server.uri()), "test-model");
        c.retry_base_ms = 10;
        c.price_input_per_mtok = 1.0;
        c.price_output_per_mtok = 10.0;
        let config = LlmConfig {
            file: "test.toml".into(),
            endpoints: BTreeMap::from([("mock".to_string(), c)]),
            prompts: BTreeMap::new(),
        };
        Arc::new(
            LlmService::new(
                config,
                LlmOptions {
                    cache_path: cache,
                    offline,
                    ..LlmOptions::default()
                },
            )
            .unwrap(),
        )
    }
}

fn registry(service: &Arc<LlmService>) -> StrategyRegistry {
    let mut r = StrategyRegistry::new();
    register_strategies(&mut r, service.clone(), PlannerConfig::default(), 12);
    r
}

/// Probability answers by container, in the styles the design names, read off the question
/// (the last line of the prompt; the house description above it names every container).
fn probability_answers(prompt: &str) -> String {
    let q = prompt
        .lines()
        .rev()
        .find(|l| l.contains('?'))
        .unwrap_or_default();
    if q.contains("in the fridge") {
        "0.7".into()
    } else if q.contains("in the counter top") {
        "around 70 percent".into()
    } else if q.contains("in the bed ") {
        "I cannot say".into()
    } else if q.contains("in the dresser") {
        "85%".into()
    } else {
        "no idea".into()
    }
}

fn probabilities(p: &[Probability]) -> Vec<f64> {
    p.iter().map(|p| p.get()).collect()
}

#[test]
fn llm_model_reads_answers_as_the_design_says() {
    let server = Server::start(probability_answers);
    let service = server.service(None, false);
    let strategy = "llm+model/p-minimal/mock";
    let source =
        ferret_llm::LlmLikelihood::new(service.clone(), "p-minimal", "mock", strategy).unwrap();
    let (house, _) = small_scene("h#0");
    let p = source
        .likelihoods(&house, &ObjectType::new("RemoteControl"))
        .unwrap();
    // fridge "0.7"; counter tops "around 70 percent"; beds "I cannot say" → 0.01; dresser "85%".
    assert_eq!(probabilities(&p), [0.7, 0.7, 0.7, 0.01, 0.01, 0.85]);
    // One question per (container type, room): fridge, counter top, bed in bedroom 1, bed in
    // bedroom 2, dresser; the two unusable bed answers are asked once more with a reminder.
    let asked = server.requests();
    assert_eq!(asked.len(), 7, "{asked:#?}");
    for room in ["bedroom 1", "bedroom 2"] {
        assert_eq!(
            asked
                .iter()
                .filter(|q| q.contains(&format!("in the bed in the {room}?")))
                .count(),
            1,
            "{asked:#?}"
        );
    }
    assert_eq!(
        asked
            .iter()
            .filter(|q| q.as_str() == ferret_llm::question::PROBABILITY_REMINDER)
            .count(),
        2,
        "{asked:#?}"
    );
    let report = service.report();
    let row = report.row("mock", strategy).unwrap();
    let a = row.answers;
    assert_eq!(
        (
            a.probability_answers,
            a.probability_fallbacks,
            a.reasked,
            a.class_number_only,
            a.class_number_in_prose,
            a.class_no_number
        ),
        (5, 2, 2, 2, 1, 2)
    );
    assert_eq!(
        (
            row.sent.requests,
            row.sent.input_tokens,
            row.sent.output_tokens
        ),
        (7, 840, 21)
    );
    assert!((row.sent.cost_usd - (840.0 + 210.0) / 1e6).abs() < 1e-12);
    // Asking again (another trial on the house) sends nothing and counts nothing twice.
    source
        .likelihoods(&house, &ObjectType::new("RemoteControl"))
        .unwrap();
    assert_eq!(server.requests().len(), 7);
    assert_eq!(
        service
            .report()
            .row("mock", strategy)
            .unwrap()
            .answers
            .probability_answers,
        5
    );
}

#[test]
fn llm_model_strategy_plans_over_llm_probabilities() {
    let server = Server::start(probability_answers);
    let service = server.service(None, false);
    let (house, truth) = small_scene("h#0");
    let d = straight_distances(&house);
    let strategy = registry(&service)
        .build("llm+model/p-context-a/mock/exact")
        .unwrap();
    assert_eq!(strategy.name(), "llm+model/p-context-a/mock/exact");
    let trial = TrialSpec::single(ObjectType::new("RemoteControl"));
    let out = run_trial(
        strategy.as_ref(),
        &SearchProblem::new(&house, &d, &trial),
        &truth,
    )
    .unwrap();
    assert_eq!(out.found, Some(5));
    // p-context-a questions carry the house (re-asks carry only the reminder).
    let asked = server.requests();
    assert!(
        asked
            .iter()
            .filter(|q| q.as_str() != ferret_llm::question::PROBABILITY_REMINDER)
            .all(|q| q.contains("The kitchen contains: fridge, counter top (2).")),
        "{asked:#?}"
    );
}

/// P-DIRECT answers: the dresser when it is on the list, else whatever `otherwise` says.
fn direct_answers(otherwise: &'static str) -> impl Fn(&str) -> String + Send + Sync + 'static {
    move |q: &str| {
        if q.contains("- dresser in the bedroom 2") && !q.contains("The robot is at the dresser") {
            "Dresser in the Bedroom 2.".into()
        } else {
            otherwise.into()
        }
    }
}

#[test]
fn llm_direct_follows_the_answer_and_falls_back_to_the_nearest() {
    let server = Server::start(direct_answers("I would look in the garage"));
    let service = server.service(None, false);
    let (house, truth) = small_scene("h#0");
    let d = straight_distances(&house);
    let strategy = registry(&service)
        .build("llm-direct/p-direct/mock")
        .unwrap();
    // The remote is in the dresser: the LLM names it first (matched ignoring case and the full stop).
    let remote = TrialSpec::single(ObjectType::new("RemoteControl"));
    let out = run_trial(
        strategy.as_ref(),
        &SearchProblem::new(&house, &d, &remote),
        &truth,
    )
    .unwrap();
    assert_eq!(out.searched, [5]);
    // The apple is in the fridge: first the dresser, then nothing matches ("the garage"), so the
    // nearest container to the dresser is taken each time: bed 2 (x=10), ..., the fridge last
    // but one.
    let apple = TrialSpec::single(ObjectType::new("Apple"));
    let out = run_trial(
        strategy.as_ref(),
        &SearchProblem::new(&house, &d, &apple),
        &truth,
    )
    .unwrap();
    assert_eq!(out.searched, [5, 4, 3, 2, 1, 0]);
    let asked = server.requests();
    // 1 question for the remote, 5 for the apple (the last container is taken without asking),
    // and each of the 4 unmatched answers asked once more with a reminder.
    assert_eq!(asked.len(), 10, "{asked:#?}");
    assert_eq!(
        asked
            .iter()
            .filter(|q| q.as_str() == ferret_llm::question::LOCATION_REMINDER)
            .count(),
        4
    );
    assert!(
        asked[1].contains("The robot is in the kitchen.")
            && asked[1].contains("Object to find: apple"),
        "{}",
        asked[1]
    );
    assert!(
        asked[2].contains("The robot is at the dresser in the bedroom 2."),
        "{}",
        asked[2]
    );
    assert!(
        asked[2].contains("- kitchen to bedroom 1: 4.0 m"),
        "{}",
        asked[2]
    );
    assert!(
        !asked[2].contains("- dresser in the bedroom 2\n"),
        "searched containers are not offered"
    );
    let report = service.report();
    let row = report.row("mock", "llm-direct/p-direct/mock").unwrap();
    assert_eq!(row.answers.direct_answers, 6);
    assert_eq!(row.answers.direct_case_insensitive, 2);
    assert_eq!(row.answers.direct_fallbacks, 4);
}

#[test]
fn offline_replay_gives_identical_trials_and_sends_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache.sqlite");
    let server = Server::start(|q| {
        if q.contains("Respond with one search location") {
            direct_answers("bed in the bedroom 1")(q)
        } else {
            probability_answers(q)
        }
    });
    let specs = ["llm+model/p-context-b/mock", "llm-direct/p-direct/mock"];
    let scenes = [small_scene("a#0"), small_scene("b#1")];
    let targets = [ObjectType::new("Apple"), ObjectType::new("RemoteControl")];
    let run = |service: &Arc<LlmService>| {
        let r = registry(service);
        let mut outs = Vec::new();
        for spec in specs {
            let s = r.build(spec).unwrap();
            for ((house, truth), target) in scenes.iter().zip(&targets) {
                let trial = TrialSpec::single(target.clone());
                outs.push(
                    run_trial(
                        s.as_ref(),
                        &SearchProblem::new(house, &straight_distances(house), &trial),
                        truth,
                    )
                    .unwrap(),
                );
            }
        }
        outs
    };
    let live = run(&server.service(Some(cache.clone()), false));
    let sent = server.requests().len();
    assert!(sent > 0);
    let replay_service = server.service(Some(cache.clone()), true);
    let replay = run(&replay_service);
    assert_eq!(live, replay);
    assert_eq!(server.requests().len(), sent, "offline sent requests");
    let report = replay_service.report();
    assert_eq!(report.per_llm()[0].sent.requests, 0);
    assert!(
        report.per_llm()[0].distinct.input_tokens > 0,
        "a warm run still reports the tokens its answers took"
    );
    // A trial needing an answer never asked fails clearly.
    let unknown = TrialSpec::single(ObjectType::new("Book"));
    let s = registry(&replay_service).build(specs[0]).unwrap();
    let (house, truth) = &scenes[0];
    let e = run_trial(
        s.as_ref(),
        &SearchProblem::new(house, &straight_distances(house), &unknown),
        truth,
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("offline") && e.contains("`mock`") && e.contains("book"),
        "{e}"
    );
}

#[test]
fn prefetch_asks_every_question_once_then_trials_send_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(probability_answers);
    let service = server.service(Some(dir.path().join("c.sqlite")), false);
    let scenes: Vec<(House, _)> = (0..3).map(|i| small_scene(&format!("h#{i}"))).collect();
    let target = ObjectType::new("RemoteControl");
    let trials: Vec<(&House, &ObjectType)> = scenes.iter().map(|(h, _)| (h, &target)).collect();
    let specs: Vec<String> = [
        "llm+model/p-minimal/mock",
        "llm+model/p-minimal/mock/exact",
        "llm+model/p-context-a/mock",
        "optimistic+greedy",
    ]
    .map(String::from)
    .to_vec();
    let summary = prefetch_probabilities(&service, &specs, &trials, &|_, _| {}).unwrap();
    // p-minimal has no house in it: 5 questions over all houses (the /exact variant shares them).
    // p-context-a names the house's rooms, which are the same in these copies: 5 more.
    assert_eq!(summary.questions, 30);
    assert_eq!(
        (
            summary.distinct,
            summary.cached,
            summary.asked,
            summary.skipped
        ),
        (10, 0, 10, 0)
    );
    assert!(summary.failures.is_empty());
    // The two unusable bed answers of each prompt are re-asked during the prefetch too.
    assert_eq!(server.requests().len(), 14);
    // Progress is reported up to the number of distinct questions.
    let seen = std::sync::Mutex::new(Vec::new());
    let again = prefetch_probabilities(&service, &specs, &trials, &|done, total| {
        seen.lock().unwrap().push((done, total))
    })
    .unwrap();
    assert_eq!((again.cached, again.asked), (10, 0));
    let seen = seen.into_inner().unwrap();
    assert_eq!(seen.first(), Some(&(0, 10)));
    assert_eq!(seen.iter().map(|s| s.0).max(), Some(10));
    // The trials themselves send nothing.
    let r = registry(&service);
    for spec in &specs[..3] {
        let s = r.build(spec).unwrap();
        for (house, truth) in &scenes {
            let trial = TrialSpec::single(target.clone());
            run_trial(
                s.as_ref(),
                &SearchProblem::new(house, &straight_distances(house), &trial),
                truth,
            )
            .unwrap();
        }
    }
    assert_eq!(server.requests().len(), 14);
}

#[test]
fn sync_callers_on_many_threads_share_the_runtime() {
    let server = Server::start(probability_answers);
    let service = server.service(None, false);
    let source = Arc::new(
        ferret_llm::LlmLikelihood::new(service.clone(), "p-context-a", "mock", "s").unwrap(),
    );
    let results: Vec<Vec<f64>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..6)
            .map(|i| {
                let source = source.clone();
                s.spawn(move || {
                    let (house, _) = small_scene(&format!("h#{}", i % 3));
                    probabilities(
                        &source
                            .likelihoods(&house, &ObjectType::new("RemoteControl"))
                            .unwrap(),
                    )
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(results.iter().all(|r| r == &results[0]));
    assert_eq!(results[0], [0.7, 0.7, 0.7, 0.01, 0.01, 0.85]);
}

#[test]
fn specs_name_prompt_llm_and_limit() {
    let parse = |s: &str| LlmSpec::parse(&StrategySpec::parse(s).unwrap());
    let p = parse("llm+model/p-context-a/gpt-5-mini").unwrap().unwrap();
    assert_eq!(
        (p.prompt.as_str(), p.llm.as_str(), p.limit),
        ("p-context-a", "gpt-5-mini", None)
    );
    let p = parse("llm+model/prompts/mine.j2/gpt-5-mini/k8")
        .unwrap()
        .unwrap();
    assert_eq!(
        (p.prompt.as_str(), p.llm.as_str(), p.limit.as_deref()),
        ("prompts/mine.j2", "gpt-5-mini", Some("k8"))
    );
    let p = parse("llm-direct/p-direct/llama").unwrap().unwrap();
    assert_eq!((p.kind.as_str(), p.llm.as_str()), ("llm-direct", "llama"));
    assert!(parse("llm+model/gpt-5-mini").unwrap().is_err());
    assert!(parse("model/prior").is_none());

    let server = Server::start(probability_answers);
    let service = server.service(None, false);
    let r = registry(&service);
    let e = r
        .build("llm+model/p-context-a/nosuch")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("nosuch") && e.contains("mock"), "{e}");
    let e = r
        .build("llm+model/p-nosuch/mock")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("p-nosuch") && e.contains("p-context-a"), "{e}");
    assert!(r.build("llm+model/p-minimal/mock/exact").is_ok());
    assert!(r.build("llm+model/p-minimal/mock/k8").is_ok());
}

#[test]
fn cache_file_is_opened_only_when_needed_and_offline_needs_one() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("never.sqlite");
    let server = Server::start(probability_answers);
    // Building the service and the registry (as every eval does) touches no file.
    let service = server.service(Some(path.clone()), false);
    let _ = registry(&service);
    let _ = service.report();
    assert!(!path.exists());
    // Offline without the file fails at once, naming it.
    let config = service.config().clone();
    let e = LlmService::new(
        config,
        LlmOptions {
            cache_path: Some(path.clone()),
            offline: true,
            ..LlmOptions::default()
        },
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("offline") && e.contains("never.sqlite"), "{e}");
    // The first LLM used opens (creates) it.
    service.llm("mock").unwrap();
    assert!(path.exists());
}
