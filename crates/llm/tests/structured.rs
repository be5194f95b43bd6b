//! Structured answers, probabilities from log-probabilities, the system-role merge and the fast
//! failure of a dead endpoint, against a loopback server; and the log-probability reading of a
//! reply recorded from a real model.

mod common;

use common::{JsonServer as Server, completion, logprob, small_scene, straight_distances};
use ferret_llm::{
    AnswerClass, AnswerFormat, LlmError, LlmLikelihood, ProbabilityFrom, SystemRole, TokenLogprob,
    expected_percentage, prefetch_probabilities, read_probability, register_strategies,
};
use ferret_plan::{
    LikelihoodSource, PlannerConfig, SearchProblem, StrategyRegistry, TrialSpec, run_trial,
};
use ferret_world::ObjectType;
use serde_json::{Value, json};
use wiremock::ResponseTemplate;

/// `{"percent": 40}` written as Qwen tokenises it, with the first digit 4 (p 0.5) or 1 (p 0.5 →
/// read as 10): expected percentage 0.5·40 + 0.5·10 = 25.
fn json_answer_with_logprobs() -> Value {
    let mut c = completion("{\"percent\": 40}", 50, 6);
    c["choices"][0]["logprobs"] = json!({"content": [
        logprob("{\"", 1.0, &[("{\"", 1.0)]),
        logprob("percent", 1.0, &[("percent", 1.0)]),
        logprob("\":", 1.0, &[("\":", 1.0)]),
        logprob(" ", 1.0, &[(" ", 1.0)]),
        logprob("4", 0.5, &[("4", 0.5), ("1", 0.5)]),
        logprob("0", 1.0, &[("0", 1.0)]),
        logprob("}", 1.0, &[("}", 1.0)]),
    ]});
    c
}

#[test]
fn json_schema_and_logprobs_requests_carry_the_right_fields() {
    let server =
        Server::start(|_| ResponseTemplate::new(200).set_body_json(json_answer_with_logprobs()));
    let service = server.service(|c| {
        c.answer_format = AnswerFormat::JsonSchema;
        c.probability_from = ProbabilityFrom::Logprobs;
        c.system_role = SystemRole::Merge;
    });
    let source = LlmLikelihood::new(service.clone(), "p-context-a", "mock", "s").unwrap();
    let (house, _) = small_scene("h#0");
    let p = source
        .likelihoods(&house, &ObjectType::new("RemoteControl"))
        .unwrap();
    // Every container gets the expectation from the tokens (25 %), not the text's 40 %.
    assert!(p.iter().all(|p| (p.get() - 0.25).abs() < 1e-9), "{p:?}");
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 5);
    for b in &bodies {
        assert_eq!(b["response_format"]["type"], "json_schema");
        let schema = &b["response_format"]["json_schema"]["schema"];
        assert_eq!(schema["required"], json!(["percent"]));
        let values = schema["properties"]["percent"]["enum"].as_array().unwrap();
        assert_eq!(values.len(), 100);
        assert_eq!(
            (values[0].clone(), values[99].clone()),
            (json!("1%"), json!("100%"))
        );
        assert_eq!(b["logprobs"], true);
        assert_eq!(b["top_logprobs"], 20);
        // The role text is merged into the first user message: no system message is sent.
        let messages = b["messages"].as_array().unwrap();
        assert!(messages.iter().all(|m| m["role"] != "system"), "{b}");
        assert!(
            messages[0]["content"]
                .as_str()
                .unwrap()
                .starts_with("You are helping a household robot"),
            "{b}"
        );
    }
    let report = service.report();
    let row = report.row("mock", "s").unwrap();
    assert_eq!((row.answers.class_json, row.answers.logprob_used), (5, 5));
}

#[test]
fn json_object_dialect_and_location_enums_for_p_direct() {
    let server = Server::start(|body| {
        let labels = body["response_format"]["schema"]["properties"]["location"]["enum"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        // Always the last location offered.
        let last = labels.last().and_then(Value::as_str).unwrap_or("nothing");
        ResponseTemplate::new(200).set_body_json(completion(
            &json!({"location": last}).to_string(),
            50,
            8,
        ))
    });
    let service = server.service(|c| c.answer_format = AnswerFormat::JsonObject);
    let mut registry = StrategyRegistry::new();
    register_strategies(&mut registry, service.clone(), PlannerConfig::default(), 12);
    let strategy = registry.build("llm-direct/p-direct/mock").unwrap();
    let (house, truth) = small_scene("h#0");
    let trial = TrialSpec::single(ObjectType::new("Apple"));
    let out = run_trial(
        strategy.as_ref(),
        &SearchProblem::new(&house, &straight_distances(&house), &trial),
        &truth,
    )
    .unwrap();
    // The last location listed each time: the dresser (5), then bed 2 (4), ..., the fridge.
    assert_eq!(out.searched, [5, 4, 3, 2, 1, 0]);
    let bodies = server.bodies();
    assert_eq!(bodies.len(), 5);
    let first = &bodies[0]["response_format"];
    assert_eq!(first["type"], "json_object");
    assert_eq!(
        first["schema"]["properties"]["location"]["enum"],
        json!([
            "fridge in the kitchen",
            "counter top 1 in the kitchen",
            "counter top 2 in the kitchen",
            "bed in the bedroom 1",
            "bed in the bedroom 2",
            "dresser in the bedroom 2"
        ])
    );
    // P-DIRECT answers are not numbers: no log-probabilities asked for.
    assert!(bodies.iter().all(|b| b.get("logprobs").is_none()));
    let report = service.report();
    let row = report.row("mock", "llm-direct/p-direct/mock").unwrap();
    assert_eq!(
        (row.answers.direct_exact, row.answers.direct_fallbacks),
        (5, 0)
    );
}

#[test]
fn a_dead_endpoint_is_given_up_on_after_one_question() {
    let server = Server::start(|_| ResponseTemplate::new(503).set_body_string("overloaded"));
    let service = server.service(|c| {
        c.max_attempts = 3;
        c.concurrency = 2;
    });
    let scenes: Vec<_> = (0..4).map(|i| small_scene(&format!("h#{i}"))).collect();
    let target = ObjectType::new("RemoteControl");
    let trials: Vec<_> = scenes.iter().map(|(h, _)| (h, &target)).collect();
    let specs = vec!["llm+model/p-context-a/mock".to_string()];
    let summary = prefetch_probabilities(&service, &specs, &trials, &|_, _| {}).unwrap();
    // At most `concurrency` questions were in flight when the first one gave up; each took
    // max_attempts requests. Nothing else was sent.
    let sent = server.bodies().len();
    assert!((3..=6).contains(&sent), "{sent} requests");
    assert!(
        summary.failures.iter().any(|f| f.contains("503")),
        "{summary:?}"
    );
    assert!(summary.skipped >= summary.distinct - 2, "{summary:?}");
    let down = service.failed_llms();
    assert_eq!(down.len(), 1);
    assert!(down[0].1.contains("503"), "{down:?}");
    // Trials asking afterwards fail at once, naming the endpoint, without a request.
    let source = LlmLikelihood::new(service.clone(), "p-minimal", "mock", "t").unwrap();
    let e = service
        .block_on(source.likelihoods_async(&scenes[0].0, &target))
        .unwrap_err();
    assert!(matches!(e, LlmError::EndpointDown { .. }), "{e}");
    assert!(e.to_string().contains("`mock`"), "{e}");
    assert_eq!(server.bodies().len(), sent);
}

/// A reply recorded from Qwen2.5-Coder-1.5B-Instruct (Q4_K_M) served by llama-cpp-python 0.3.36
/// to a P-MINIMAL question: text "10%", tokens "1", "0", "%" with their top-20 alternatives.
#[test]
fn recorded_qwen_reply_reads_to_its_expected_percentage() {
    let fixture: Value =
        serde_json::from_str(include_str!("fixtures/qwen-p-minimal-10-percent.json")).unwrap();
    let reply = fixture["reply"].as_str().unwrap();
    let tokens: Vec<TokenLogprob> = serde_json::from_value(fixture["logprobs"].clone()).unwrap();
    let r = read_probability(reply, None);
    assert_eq!(r.class, AnswerClass::NumberOnly);
    assert_eq!(r.probability, Some(0.10));
    let e = expected_percentage(&tokens, reply, r.number.unwrap()).unwrap();
    // 30.1608 was computed from the same file by an independent Python implementation of the
    // method documented in ferret_llm::logprobs: the model's "1" competes with "5", "2", "3" as
    // first digits, which the text answer hides.
    assert!((e - 30.1608).abs() < 1e-3, "{e}");
}
