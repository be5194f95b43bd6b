//! An eval-shaped run against a loopback OpenAI-compatible server: the three llm+model strategies
//! and llm-direct on N generated houses, first with an empty response cache, then again with the
//! warm cache, then offline. Prints requests, tokens (the server counts characters / 4) and wall
//! times, and checks that the three runs agree.
//!
//! `cargo run -p ferret-lab --release --example mock_eval -- [N]`

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use ferret_lab::{Silent, TrialDraw, TrialRow, build_maps, evaluate};
use ferret_llm::{
    EndpointConfig, LlmConfig, LlmOptions, LlmService, prefetch_probabilities, register_strategies,
};
use ferret_plan::{PlannerConfig, Protocol, Strategy, StrategyRegistry, TrialsPerHouse};
use ferret_world::{GridParams, House, ObjectType};
use serde_json::{Value, json};
use wiremock::matchers::method;
use wiremock::{Mock, MockServer, Request, ResponseTemplate};

const SPECS: [&str; 4] = [
    "llm+model/p-context-a/mock",
    "llm+model/p-context-b/mock",
    "llm+model/p-minimal/mock",
    "llm-direct/p-direct/mock",
];

/// Answers a probability question with a percentage derived from its text, and P-DIRECT with
/// the last location of its list; usage counts characters / 4.
fn respond(req: &Request) -> ResponseTemplate {
    let body: Value = req.body_json().unwrap_or_default();
    let text: String = body["messages"]
        .as_array()
        .map(|m| {
            m.iter()
                .filter_map(|m| m["content"].as_str())
                .collect::<Vec<_>>()
                .join("\n")
        })
        .unwrap_or_default();
    let answer = if text.contains("Unsearched locations:") {
        let list = text
            .rsplit("Unsearched locations:")
            .next()
            .unwrap_or_default();
        list.lines()
            .filter_map(|l| l.strip_prefix("- "))
            .next_back()
            .unwrap_or("?")
            .to_string()
    } else {
        let h = text
            .bytes()
            .fold(7u64, |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b)));
        format!("{}%", 1 + h % 100)
    };
    ResponseTemplate::new(200).set_body_json(json!({
        "id": "m", "object": "chat.completion", "created": 1, "model": "mock",
        "choices": [{"index": 0, "message": {"role": "assistant", "content": answer}, "finish_reason": "stop"}],
        "usage": {"prompt_tokens": text.len().div_ceil(4), "completion_tokens": 3, "total_tokens": 0}
    }))
}

fn service(uri: &str, cache: &std::path::Path, offline: bool) -> Arc<LlmService> {
    let mut c = EndpointConfig::new(format!("{uri}/v1"), "mock");
    c.concurrency = 16;
    c.price_input_per_mtok = 0.25;
    c.price_output_per_mtok = 2.0;
    let config = LlmConfig {
        file: "mock.toml".into(),
        endpoints: BTreeMap::from([("mock".to_string(), c)]),
        prompts: BTreeMap::new(),
    };
    Arc::new(
        LlmService::new(
            config,
            LlmOptions {
                cache_path: Some(cache.to_path_buf()),
                offline,
                ..LlmOptions::default()
            },
        )
        .expect("service"),
    )
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(150);
    let rt = tokio::runtime::Runtime::new().expect("runtime");
    let server = rt.block_on(MockServer::start());
    rt.block_on(
        Mock::given(method("POST"))
            .respond_with(respond)
            .mount(&server),
    );
    let dir = tempfile::tempdir().expect("temp dir");
    let cache = dir.path().join("cache.sqlite");

    let scenes = ferret_world::generate::default_scenes(n, 0).expect("houses");
    let maps = build_maps(&scenes, &GridParams::default(), &Silent);
    let draw = TrialDraw {
        seed: 0,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::One,
        protocol: &Protocol::FERRET,
        holdout: None,
        tasks: None,
        team: None,
    };
    let targets = draw.targets(&scenes, &maps);
    let pairs: Vec<(&House, &ObjectType)> = targets.iter().map(|(h, t)| (*h, t)).collect();
    let specs: Vec<String> = SPECS.map(String::from).to_vec();

    let run = |label: &str, offline: bool| -> Vec<TrialRow> {
        let started = Instant::now();
        let service = service(&server.uri(), &cache, offline);
        let mut registry = StrategyRegistry::new();
        register_strategies(&mut registry, service.clone(), PlannerConfig::default(), 16);
        let prefetch =
            prefetch_probabilities(&service, &specs, &pairs, &|_, _| {}).expect("prefetch");
        let prefetched = started.elapsed();
        let strategies: Vec<Arc<dyn Strategy>> = SPECS
            .iter()
            .map(|s| registry.build(s).expect("strategy"))
            .collect();
        let evaluation = evaluate(&scenes, &maps, &strategies, &draw, &Silent);
        assert!(evaluation.errors.is_empty(), "{:?}", evaluation.errors);
        let outs = evaluation.rows;
        let report = service.report();
        let t = &report.per_llm()[0];
        println!(
            "{label:<6} {:>6.2} s (prefetch {:.2} s: {} distinct, {} asked) | requests {:>5} | cache hits {:>6} | distinct prompts {:>5}, {:>8} input tokens ({:.0}/house), ${:.3}",
            started.elapsed().as_secs_f64(),
            prefetched.as_secs_f64(),
            prefetch.distinct,
            prefetch.asked,
            t.sent.requests,
            t.cache_hits,
            t.distinct.requests,
            t.distinct.input_tokens,
            t.distinct.input_tokens as f64 / pairs.len().max(1) as f64,
            t.distinct.cost_usd,
        );
        outs
    };
    println!(
        "{} generated houses, {} trials per strategy, strategies: {}",
        n,
        pairs.len(),
        SPECS.join(", ")
    );
    let cold = run("cold", false);
    let warm = run("warm", false);
    let offline = run("offline", true);
    println!(
        "identical outcomes: warm {}, offline {}",
        cold == warm,
        cold == offline
    );
}
