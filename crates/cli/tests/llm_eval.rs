//! End-to-end: `ferret eval` with an llm+model and an llm-direct strategy against a loopback
//! OpenAI-compatible server, then again `--offline` from the cache.

mod common;

use common::{s, text};

use std::path::Path;
use std::process::{Command, Output};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use serde_json::{Value, json};
use wiremock::matchers::{method, path};
use wiremock::{Mock, MockServer, Request, Respond, ResponseTemplate};

const KEY: &str = "sk-e2e-key-must-never-leak-4242";

/// Answers like a cooperative LLM: for P-DIRECT the last listed location, for probability
/// prompts a percentage that depends on the container.
struct FakeLlm {
    requests: Arc<AtomicUsize>,
}

impl Respond for FakeLlm {
    fn respond(&self, req: &Request) -> ResponseTemplate {
        self.requests.fetch_add(1, Ordering::SeqCst);
        let body: Value = serde_json::from_slice(&req.body).unwrap_or_default();
        let prompt: String = body["messages"]
            .as_array()
            .map(|m| {
                m.iter()
                    .filter_map(|x| x["content"].as_str())
                    .collect::<Vec<_>>()
                    .join("\n")
            })
            .unwrap_or_default();
        let answer = if let Some(list) = prompt
            .rsplit("Unsearched locations:")
            .next()
            .filter(|_| prompt.contains("Unsearched locations:"))
        {
            list.lines()
                .filter_map(|l| l.trim().strip_prefix("- "))
                .next_back()
                .unwrap_or("nothing")
                .to_string()
        } else {
            let question = prompt.rsplit("likelihood").next().unwrap_or_default();
            if question.contains("fridge") || question.contains("counter") {
                "around 70 percent".to_string()
            } else if question.contains("bed") {
                "0.3".to_string()
            } else {
                "15%".to_string()
            }
        };
        ResponseTemplate::new(200).set_body_json(json!({
            "id": "x", "object": "chat.completion", "created": 1, "model": "mock-model",
            "choices": [{"index": 0, "message": {"role": "assistant", "content": answer}, "finish_reason": "stop"}],
            "usage": {"prompt_tokens": 100, "completion_tokens": 3, "total_tokens": 103},
            "system_fingerprint": "vllm-extra-field"
        }))
    }
}

fn ferret(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ferret"))
        .args(args)
        .env("FERRET_E2E_KEY", KEY)
        .output()
        .expect("ferret runs")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eval_with_llm_strategies_then_offline_gives_identical_trials() {
    let server = MockServer::start().await;
    let requests = Arc::new(AtomicUsize::new(0));
    Mock::given(method("POST"))
        .and(path("/v1/chat/completions"))
        .respond_with(FakeLlm {
            requests: requests.clone(),
        })
        .mount(&server)
        .await;
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        format!(
            "[llm.mock]\nbase_url = \"{}/v1\"\nmodel = \"mock-model\"\napi_key_env = \"FERRET_E2E_KEY\"\nretry_base_ms = 10\nprice_input_per_mtok = 0.25\nprice_output_per_mtok = 2.0\n",
            server.uri()
        ),
    )
    .unwrap();
    let cache = dir.path().join("cache.sqlite");
    let strategies = "optimistic+greedy,llm+model/p-context-a/mock,llm-direct/p-direct/mock,oracle";
    let first = dir.path().join("first");
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--generate",
            "6",
            "--house-seed",
            "11",
            "--strategies",
            strategies,
            "--config",
            s(&config),
            "--llm-cache",
            s(&cache),
            "--out",
            s(out),
        ];
        args.extend_from_slice(extra);
        ferret(&args)
    };
    let o = tokio::task::block_in_place(|| run(&first, &[]));
    assert!(o.status.success(), "{}", text(&o));
    let sent = requests.load(Ordering::SeqCst);
    assert!(
        sent > 6,
        "the LLM strategies asked the server ({sent} requests)"
    );
    assert!(!text(&o).contains(KEY), "the key leaked into the output");
    let tokens = std::fs::read_to_string(first.join("tokens.csv")).unwrap();
    assert!(
        tokens.contains("llm+model/p-context-a/mock")
            && tokens.contains("llm-direct/p-direct/mock"),
        "{tokens}"
    );
    let md = std::fs::read_to_string(first.join("summary.md")).unwrap();
    let table = md
        .split("## LLM tokens and cost")
        .nth(1)
        .expect("summary.md has the token table");
    assert!(
        table.contains("llm-direct/p-direct/mock") && table.contains("mock "),
        "{table}"
    );

    // A second, offline run answers everything from the cache: no request, identical trials.
    let second = dir.path().join("second");
    let o = tokio::task::block_in_place(|| run(&second, &["--offline"]));
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        requests.load(Ordering::SeqCst),
        sent,
        "the offline run sent requests"
    );
    let a = std::fs::read_to_string(first.join("trials.csv")).unwrap();
    let b = std::fs::read_to_string(second.join("trials.csv")).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.lines().count(), 1 + 6 * 4);

    // The key is nowhere in the cache file.
    let bytes = std::fs::read(&cache).unwrap();
    assert!(!bytes.windows(KEY.len()).any(|w| w == KEY.as_bytes()));

    // Offline with an empty cache fails clearly and names what is missing.
    let empty = dir.path().join("empty.sqlite");
    let o = tokio::task::block_in_place(|| {
        ferret(&[
            "eval",
            "--generate",
            "2",
            "--strategies",
            "llm+model/p-minimal/mock",
            "--config",
            s(&config),
            "--llm-cache",
            s(&empty),
            "--offline",
            "--out",
            s(&dir.path().join("x")),
        ])
    });
    assert!(
        !o.status.success(),
        "an offline run without answers must fail"
    );
    assert!(text(&o).to_lowercase().contains("cache"), "{}", text(&o));
    assert_eq!(requests.load(Ordering::SeqCst), sent);
}
