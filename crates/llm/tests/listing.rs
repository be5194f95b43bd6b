//! P-YESNO, P-CHOICE and P-BATCH against a loopback server: what is asked, how answers (with and
//! without log-probabilities, with letters missing, in JSON with keys extra or missing) become
//! probabilities, what is counted; more places than letters; and the fused source.

mod common;

use std::sync::Arc;

use common::{JsonServer, completion, logprob, small_scene};
use ferret_llm::{
    AnswerFormat, LlmLikelihood, LlmOptions, LlmService, register_fused, register_strategies,
};
use ferret_plan::{
    FusionBase, FusionFile, FusionFit, FusionWeights, LikelihoodSource, PlannerConfig, Prior,
    StrategyRegistry, TrainingScore, prior_fingerprint,
};
use ferret_world::{House, ObjectType, Scene};
use serde_json::{Value, json};
use wiremock::ResponseTemplate;

/// The user message (where listings and questions are).
fn user(body: &Value) -> String {
    body["messages"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|m| m["role"] == "user")
        .filter_map(|m| m["content"].as_str())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The letter a listing in `prompt` gives the place whose line contains `words`.
fn letter_of(prompt: &str, words: &str) -> Option<String> {
    prompt
        .lines()
        .find(|l| l.contains(words) && l.as_bytes().get(1) == Some(&b'.'))
        .map(|l| l[..1].to_string())
}

/// A text reply whose single token has these alternatives.
fn one_token(text: &str, alts: &[(&str, f64)]) -> ResponseTemplate {
    let mut c = completion(text, 200, 1);
    let p = alts
        .iter()
        .find(|(t, _)| *t == text)
        .map_or(1.0, |(_, p)| *p);
    c["choices"][0]["logprobs"] = json!({"content": [logprob(text, p, alts)]});
    ResponseTemplate::new(200).set_body_json(c)
}

fn text(t: &str) -> ResponseTemplate {
    ResponseTemplate::new(200).set_body_json(completion(t, 200, 4))
}

fn p(v: &[ferret_plan::Probability]) -> Vec<f64> {
    v.iter().map(|p| p.get()).collect()
}

fn close(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
}

fn remote() -> ObjectType {
    ObjectType::new("RemoteControl")
}

// The small scene's places, in house order: A fridge (kitchen), B counter top (kitchen, two
// containers), C bed (bedroom 1), D bed (bedroom 2), E dresser (bedroom 2).

#[test]
fn p_choice_reads_the_letter_distribution_in_both_orders() {
    let server = JsonServer::start(|body| {
        let u = user(body);
        let dresser = letter_of(&u, "dresser").unwrap_or_default();
        let fridge = letter_of(&u, "fridge").unwrap_or_default();
        // 0.6 dresser, 0.2 fridge, 0.1 a word; 0.1 listed for nothing.
        one_token(&dresser, &[(&dresser, 0.6), (&fridge, 0.2), ("The", 0.1)])
    });
    let service = server.service(|c| c.top_logprobs = Some(5));
    let source = LlmLikelihood::new(service.clone(), "p-choice", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    // Labels: dresser 0.6, fridge 0.2, the 0.1 unlisted spread over the 3 others; normalised by
    // 0.9. Containers: fridge, counter top ×2, bed, bed, dresser.
    let other = 0.1 / 3.0 / 0.9;
    assert!(
        close(&got, &[0.2 / 0.9, other, other, other, other, 0.6 / 0.9]),
        "{got:?}"
    );
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 2, "one request per order");
    // The two orders may reach the server in either order.
    let (mut first, mut second) = (user(&bodies[0]), user(&bodies[1]));
    if first.contains("A. dresser") {
        std::mem::swap(&mut first, &mut second);
    }
    assert!(
        first.contains("A. fridge in the kitchen\nB. counter top in the kitchen\n"),
        "{first}"
    );
    assert!(
        second.contains("A. dresser in the bedroom 2\n"),
        "reversed: {second}"
    );
    assert!(
        first.ends_with("Answer with the letter of one place only."),
        "{first}"
    );
    assert!(bodies.iter().all(|b| b["top_logprobs"] == 5));
    let report = service.report();
    let row = report.row("mock", "s").unwrap();
    assert_eq!(
        (
            row.answers.probability_answers,
            row.answers.class_word,
            row.answers.logprob_used,
            row.answers.probability_fallbacks,
            row.distinct.requests
        ),
        (2, 2, 2, 0, 2)
    );
}

#[test]
fn p_choice_without_logprobs_gives_the_word_its_mass_and_counts_it() {
    let server =
        JsonServer::start(|body| text(&letter_of(&user(body), "dresser").unwrap_or_default()));
    let service = server.service(|_| {});
    let source = LlmLikelihood::new(service.clone(), "p-choice", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    // word_answer_mass 0.8 on the dresser, 0.05 each for the four other places.
    assert!(close(&got, &[0.05, 0.05, 0.05, 0.05, 0.05, 0.8]), "{got:?}");
    let report = service.report();
    let a = report.row("mock", "s").unwrap().answers;
    assert_eq!(
        (a.logprob_missing, a.logprob_used, a.probability_fallbacks),
        (2, 0, 0)
    );
}

#[test]
fn unreadable_choices_are_asked_again_then_spread_evenly() {
    let server = JsonServer::start(|_| text("I am not sure which one."));
    let service = server.service(|_| {});
    let source = LlmLikelihood::new(service.clone(), "p-choice", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    assert!(close(&got, &[0.2; 6]), "{got:?}");
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 4, "two orders, each asked again once");
    assert!(user(&bodies[1]).contains("Answer with the letter of one place"));
    let report = service.report();
    let a = report.row("mock", "s").unwrap().answers;
    assert_eq!(
        (a.class_no_word, a.reasked, a.probability_fallbacks),
        (2, 2, 2)
    );
}

/// A house with `n` places: one room, containers of `n` distinct types.
fn wide_house(n: usize) -> House {
    let (mut house, _) = small_scene("wide#0");
    let template = house.containers[0].clone();
    house.containers = (0..n)
        .map(|i| ferret_world::Container {
            id: format!("c|{i}"),
            object_type: ObjectType::new(format!("Shelf{}", i + 1)),
            ..template.clone()
        })
        .collect();
    house
}

#[test]
fn more_places_than_letters_are_asked_in_parts() {
    // Always all mass on `A`: the first place of each part and order.
    let server = JsonServer::start(|_| one_token("A", &[("A", 1.0)]));
    let service = server.service(|c| c.top_logprobs = Some(5));
    let source = LlmLikelihood::new(service, "p-choice", "mock", "s").unwrap();
    let house = wide_house(30);
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 4, "two parts of 15, each in two orders");
    for b in &bodies {
        let u = user(b);
        assert!(
            u.contains("\nO. ") && !u.contains("\nP. "),
            "15 letters: {u}"
        );
    }
    // Per part: the first place (forward) and the last (reversed) get half the part's mass each;
    // the part holds half of all places, so 0.25; the others are floored at 0.01.
    for (i, v) in got.iter().enumerate() {
        let want = if [0, 14, 15, 29].contains(&i) {
            0.25
        } else {
            0.01
        };
        assert!((v - want).abs() < 1e-9, "place {i}: {v} (all: {got:?})");
    }
}

#[test]
fn p_batch_json_with_extra_and_missing_keys_is_asked_again_for_what_is_missing() {
    let server = JsonServer::start(|body| {
        let last = user(body);
        if last.contains("for each of these places too") {
            text("C: 30%\nE: 50%")
        } else {
            text(r#"{"A": "10%", "B": "20%", "Z": "99%", "D": "40%"}"#)
        }
    });
    let service = server.service(|c| {
        c.answer_format = AnswerFormat::JsonSchema;
        c.max_output_tokens = Some(8);
    });
    let source = LlmLikelihood::new(service.clone(), "p-batch", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    assert!(close(&got, &[0.1, 0.2, 0.2, 0.3, 0.4, 0.5]), "{got:?}");
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 2);
    let schema = &bodies[0]["response_format"]["json_schema"]["schema"];
    assert_eq!(schema["required"], json!(["A", "B", "C", "D", "E"]));
    // An output limit too small for five percentages is raised for this question.
    assert_eq!(bodies[0]["max_completion_tokens"], 16 + 5 * 12);
    let reask = user(&bodies[1]);
    assert!(
        reask.contains("for each of these places too, one line each, for example \"C: 40%\": C, E"),
        "{reask}"
    );
    let report = service.report();
    let a = report.row("mock", "s").unwrap().answers;
    assert_eq!(
        (
            a.probability_answers,
            a.class_json,
            a.class_missing,
            a.reasked,
            a.probability_fallbacks
        ),
        (5, 3, 2, 2, 0)
    );
}

#[test]
fn p_batch_places_still_missing_fall_back_and_are_counted() {
    let server = JsonServer::start(|_| text("A: 70%"));
    let service = server.service(|_| {});
    let source = LlmLikelihood::new(service.clone(), "p-batch", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    assert!(close(&got, &[0.7, 0.01, 0.01, 0.01, 0.01, 0.01]), "{got:?}");
    assert_eq!(server.bodies().len(), 2);
    let report = service.report();
    let a = report.row("mock", "s").unwrap().answers;
    assert_eq!(
        (
            a.class_number_only,
            a.class_missing,
            a.probability_fallbacks
        ),
        (1, 4, 4)
    );
}

fn yes_no_server() -> JsonServer {
    JsonServer::start(|body| {
        let u = user(body);
        if u.contains("dresser") {
            one_token("Yes", &[("Yes", 0.6), ("No", 0.3), ("Maybe", 0.1)])
        } else {
            one_token("No", &[("No", 0.9), ("Yes", 0.1)])
        }
    })
}

#[test]
fn p_yesno_asks_per_room_type_and_one_answer_serves_every_house() {
    let server = yes_no_server();
    let dir = tempfile::tempdir().unwrap();
    let service = server.service_with(
        |c| c.top_logprobs = Some(5),
        LlmOptions {
            cache_path: Some(dir.path().join("c.sqlite")),
            offline: false,
            ..LlmOptions::default()
        },
    );
    let source = LlmLikelihood::new(service.clone(), "p-yesno", "mock", "s").unwrap();
    for name in ["h#0", "other#7"] {
        let (house, _) = small_scene(name);
        let got = p(&source.likelihoods(&house, &remote()).unwrap());
        assert!(
            close(&got, &[0.1, 0.1, 0.1, 0.1, 0.1, 0.6 / 0.9]),
            "{name}: {got:?}"
        );
    }
    let bodies = server.bodies();
    // fridge, counter top, bed and dresser: the two bedrooms' beds are one question, and the
    // second house asks nothing.
    assert_eq!(bodies.len(), 4, "{bodies:#?}");
    assert!(
        bodies
            .iter()
            .any(|b| user(b).contains("in or on the bed in the bedroom? Answer Yes or No.")),
        "{bodies:#?}"
    );
}

#[test]
fn p_yesno_without_logprobs_reads_the_word() {
    let server = JsonServer::start(|body| {
        text(if user(body).contains("dresser") {
            "Yes."
        } else {
            "No"
        })
    });
    let service = server.service(|_| {});
    let source = LlmLikelihood::new(service.clone(), "p-yesno", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    let no = 1.0 - 0.8;
    assert!(close(&got, &[no, no, no, no, no, 0.8]), "{got:?}");
    let report = service.report();
    let a = report.row("mock", "s").unwrap().answers;
    assert_eq!((a.class_word, a.logprob_missing), (4, 4));
}

fn prior() -> Arc<Prior> {
    let scenes: Vec<Scene> = ["a#0", "b#1"]
        .iter()
        .map(|n| {
            let (house, truth) = small_scene(n);
            Scene { house, truth }
        })
        .collect();
    Arc::new(Prior::train(&scenes, 2.0))
}

fn fusion_for(prior: &Prior, source: &str, weights: FusionWeights) -> FusionFile {
    let score = TrainingScore {
        brier: 0.1,
        auroc: Some(0.7),
    };
    FusionFile::new(vec![FusionFit {
        source: source.into(),
        base: FusionBase::Prior,
        weights,
        prior: prior_fingerprint(prior),
        trained_on: "test houses".into(),
        pairs: 6,
        positives: 1,
        prior_score: score,
        source_score: score,
        fused_score: score,
    }])
}

fn registry(
    service: &Arc<LlmService>,
    prior: Arc<Prior>,
    fusion: Option<FusionFile>,
) -> StrategyRegistry {
    let mut r = StrategyRegistry::builtin(Some(prior.clone()), PlannerConfig::default(), 12);
    register_strategies(&mut r, service.clone(), PlannerConfig::default(), 12);
    register_fused(
        &mut r,
        service.clone(),
        Some(prior),
        fusion.map(|f| ("fusion.json".to_string(), Arc::new(f))),
        PlannerConfig::default(),
        12,
    );
    r
}

#[test]
fn fused_sources_combine_the_prior_and_the_llm_by_the_fitted_weights() {
    let server = yes_no_server();
    let service = server.service(|c| c.top_logprobs = Some(5));
    let prior = prior();
    let weights = FusionWeights {
        a: 0.7,
        b: 1.3,
        c: -0.4,
        d: 0.9,
        e: 0.5,
    };
    let r = registry(
        &service,
        prior.clone(),
        Some(fusion_for(&prior, "p-yesno/mock", weights)),
    );
    let fused = r.build("fused/p-yesno/mock/exact").unwrap();
    let llm = r.build("llm+model/p-yesno/mock").unwrap();
    let (house, _) = small_scene("h#0");
    let f = p(&fused
        .likelihood_source()
        .unwrap()
        .likelihoods(&house, &remote())
        .unwrap());
    let l = p(&llm
        .likelihood_source()
        .unwrap()
        .likelihoods(&house, &remote())
        .unwrap());
    let pr = p(&prior.likelihoods(&house, &remote()).unwrap());
    let gaps = prior.evidence_gaps(&house, &remote());
    let want: Vec<f64> = pr
        .iter()
        .zip(&l)
        .zip(&gaps)
        .map(|((a, b), g)| weights.fuse(*a, *b, *g))
        .collect();
    assert!(close(&f, &want), "{f:?} vs {want:?}");
    assert!(
        f[5] > f[0],
        "the dresser, which the LLM favours, rises: {f:?}"
    );

    // Refusals say why: no file, no fit for the source, a fit made with another prior.
    let no_file = registry(&service, prior.clone(), None);
    let e = no_file
        .build("fused/p-yesno/mock")
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("--fit-fusion"), "{e}");
    let e = r
        .build("fused/p-choice/mock")
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("no fit for fused/p-choice/mock") && e.contains("fused/p-yesno/mock"),
        "{e}"
    );
    let other = Arc::new(Prior::train(
        &[{
            let (house, truth) = small_scene("z#0");
            Scene { house, truth }
        }],
        5.0,
    ));
    let stale = registry(
        &service,
        other,
        Some(fusion_for(&prior, "p-yesno/mock", weights)),
    );
    let e = stale
        .build("fused/p-yesno/mock")
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("another prior"), "{e}");
}

#[test]
fn the_noise_control_is_fused_like_an_llm_without_asking_one() {
    let server = yes_no_server();
    let service = server.service(|c| c.top_logprobs = Some(5));
    let prior = prior();
    let weights = FusionWeights {
        a: 1.1,
        b: 0.4,
        c: 0.2,
        d: 0.0,
        e: 0.0,
    };
    let r = registry(
        &service,
        prior.clone(),
        Some(fusion_for(&prior, "noise", weights)),
    );
    let fused = r.build("fused/noise/exact").unwrap();
    let (house, _) = small_scene("h#0");
    let f = p(&fused
        .likelihood_source()
        .unwrap()
        .likelihoods(&house, &remote())
        .unwrap());
    let noise = p(&ferret_plan::Noise::default()
        .likelihoods(&house, &remote())
        .unwrap());
    let pr = p(&prior.likelihoods(&house, &remote()).unwrap());
    let gaps = prior.evidence_gaps(&house, &remote());
    let want: Vec<f64> = (0..pr.len())
        .map(|i| weights.fuse(pr[i], noise[i], gaps[i]))
        .collect();
    assert!(close(&f, &want), "{f:?} vs {want:?}");
    assert!(server.bodies().is_empty(), "the control asks no LLM");
    // Without a fit for it, the control is refused like an LLM source.
    let e = registry(
        &service,
        prior.clone(),
        Some(fusion_for(&prior, "p-yesno/mock", weights)),
    )
    .build("fused/noise")
    .err()
    .map(|e| e.to_string())
    .unwrap_or_default();
    assert!(e.contains("no fit for fused/noise"), "{e}");
}

#[test]
fn batch_prompts_may_name_places_and_ask_yes_or_no() {
    let dir = tempfile::tempdir().unwrap();
    let template = dir.path().join("yes-no-batch.j2");
    std::fs::write(
        &template,
        "{# ferret:kind batch names yesno #}\nPlaces:\n{% for o in options %}\n- {{ o.label }}\n{% endfor %}\nWould {{ target | article }} be there? One line per place: \"<place>: Yes\" or \"<place>: No\".\n",
    )
    .unwrap();
    // The dresser line answered Yes (0.7 of the token's mass against No 0.2), every other No
    // without log-probabilities for its word... except that one line's token is given too.
    let server = JsonServer::start(|body| {
        let u = user(body);
        let places: Vec<&str> = u.lines().filter_map(|l| l.strip_prefix("- ")).collect();
        let mut text = String::new();
        let mut tokens = Vec::new();
        for p in places {
            let prefix = format!("{p}: ");
            tokens.push(logprob(&prefix, 1.0, &[(&prefix, 1.0)]));
            let (word, alts): (&str, Vec<(&str, f64)>) = if p.starts_with("dresser") {
                ("Yes", vec![("Yes", 0.7), ("No", 0.2)])
            } else {
                ("No", vec![("No", 0.6), ("Yes", 0.4)])
            };
            let p_word = alts[0].1;
            tokens.push(logprob(word, p_word, &alts));
            tokens.push(logprob("\n", 1.0, &[("\n", 1.0)]));
            text.push_str(&format!("{prefix}{word}\n"));
        }
        let mut c = completion(&text, 100, 30);
        c["choices"][0]["logprobs"] = json!({ "content": tokens });
        ResponseTemplate::new(200).set_body_json(c)
    });
    let service = server.service(|c| c.top_logprobs = Some(5));
    let source =
        LlmLikelihood::new(service.clone(), template.to_str().unwrap(), "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let got = p(&source.likelihoods(&house, &remote()).unwrap());
    assert!(
        close(&got, &[0.4, 0.4, 0.4, 0.4, 0.4, 0.7 / 0.9]),
        "{got:?}"
    );
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 1, "one request for the house");
    assert!(
        user(&bodies[0]).contains("- bed in the bedroom 2\n"),
        "places named"
    );
    let report = service.report();
    let a = report.row("mock", "s").unwrap().answers;
    assert_eq!(
        (a.probability_answers, a.class_word, a.logprob_used),
        (5, 5, 5)
    );
}
