//! Estimates the input tokens each prompt costs per house, with a rough tokenizer (characters / 4),
//! on generated houses and, when FERRET_PROCTHOR_DIR is set to a directory holding
//! `multiroom-val150.jsonl.gz`, on the ProcTHOR evaluation houses.
//!
//! For each house one trial is drawn as `ferret eval` draws it (seed 0). Probability prompts
//! count every distinct question of the house once; P-DIRECT counts one question per decision of
//! the trial, following the optimistic+greedy order until the target is found (llm-direct's
//! trajectory differs, so this is an estimate of its length, not of its choices).
//!
//! `cargo run -p ferret-llm --release --example prompt_tokens -- [N]`

use std::collections::HashSet;

use ferret_llm::{
    ChatMessage, DirectContext, EndpointConfig, HouseContext, P_CONTEXT_A, P_CONTEXT_B, P_DIRECT,
    P_MINIMAL, PromptLibrary, QueryPlan, cache_key,
};
use ferret_plan::strategy::GreedyStrategy;
use ferret_plan::{Belief, SearchProblem, draw_trial, run_trial};
use ferret_world::{GridParams, Scene};

fn tokens(messages: &[ChatMessage]) -> usize {
    messages
        .iter()
        .map(|m| m.content.chars().count())
        .sum::<usize>()
        .div_ceil(4)
}

fn measure(label: &str, scenes: &[Scene]) {
    let lib = PromptLibrary::new();
    let key_config = EndpointConfig::new("http://x/v1", "m");
    let mut rows = Vec::new();
    for prompt in [P_CONTEXT_A, P_CONTEXT_B, P_MINIMAL] {
        let (mut total, mut questions, mut houses) = (0usize, 0usize, 0usize);
        let mut distinct = HashSet::new();
        let mut distinct_tokens = 0usize;
        for s in scenes {
            let Ok(trial) = draw_trial(&s.house, &s.truth, 0, 0.0) else {
                continue;
            };
            houses += 1;
            let ctx = HouseContext::new(&s.house);
            let plan = QueryPlan::new(&s.house, trial.task.first());
            for q in &plan.queries {
                let Ok(m) = lib.probability_messages(prompt, &ctx, q) else {
                    continue;
                };
                let t = tokens(&m);
                total += t;
                questions += 1;
                if distinct.insert(cache_key(
                    &key_config,
                    &ferret_llm::Request::plain(m.clone()),
                )) {
                    distinct_tokens += t;
                }
            }
        }
        rows.push((
            prompt,
            houses,
            questions,
            total,
            distinct.len(),
            distinct_tokens,
        ));
    }
    let (mut total, mut questions, mut houses, mut first) = (0usize, 0usize, 0usize, 0usize);
    for s in scenes {
        let Ok(trial) = draw_trial(&s.house, &s.truth, 0, 0.0) else {
            continue;
        };
        let Ok((_, d)) = ferret_world::distance::build(&s.house, &GridParams::default()) else {
            continue;
        };
        let Ok(out) = run_trial(
            &GreedyStrategy,
            &SearchProblem::new(&s.house, &d, &trial),
            &s.truth,
        ) else {
            continue;
        };
        houses += 1;
        let ctx = HouseContext::new(&s.house);
        let mut belief = Belief::new(&s.house, &d, &trial.task);
        for (step, &c) in out.searched.iter().enumerate() {
            let unsearched: Vec<usize> = belief.unsearched().collect();
            if unsearched.len() > 1 {
                let (dc, _) = DirectContext::new(
                    &s.house,
                    &ctx,
                    &d,
                    trial.task.first(),
                    belief.position(),
                    &unsearched,
                )
                .expect("a consistent house");
                let t = tokens(
                    &lib.direct_messages(P_DIRECT, &dc)
                        .expect("p-direct renders"),
                );
                total += t;
                questions += 1;
                if step == 0 {
                    first += t;
                }
            }
            belief.search(c, vec![]);
        }
    }
    println!("\n{label}: {} houses", scenes.len());
    println!(
        "{:<12} {:>8} {:>14} {:>16} {:>18} {:>16}",
        "prompt",
        "houses",
        "questions/house",
        "tokens/question",
        "input tokens/house",
        "distinct prompts"
    );
    for (prompt, h, q, t, dn, dt) in rows {
        let h = h.max(1) as f64;
        println!(
            "{:<12} {:>8} {:>14.1} {:>16.0} {:>18.0} {:>10} ({:.0} tok/house)",
            prompt,
            h,
            q as f64 / h,
            t as f64 / q.max(1) as f64,
            t as f64 / h,
            dn,
            dt as f64 / h
        );
    }
    let h = houses.max(1) as f64;
    println!(
        "{:<12} {:>8} {:>14.1} {:>16.0} {:>18.0}   (first decision {:.0} tokens)",
        P_DIRECT,
        houses,
        questions as f64 / h,
        total as f64 / questions.max(1) as f64,
        total as f64 / h,
        first as f64 / h
    );
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(50);
    let generated = ferret_world::generate::default_scenes(n, 0).expect("generated houses");
    measure("generated houses (seed 0)", &generated);
    if let Ok(dir) = std::env::var("FERRET_PROCTHOR_DIR") {
        let path = std::path::Path::new(&dir).join("multiroom-val150.jsonl.gz");
        let opts = ferret_world::procthor::LoadOptions {
            shard: None,
            skip_invalid: true,
            ..Default::default()
        };
        match ferret_world::procthor::load_scenes(&path, &opts) {
            Ok(report) => measure("ProcTHOR multiroom-val150", &report.scenes),
            Err(e) => eprintln!("{}: {e}", path.display()),
        }
    } else {
        println!(
            "\nProcTHOR houses skipped: set FERRET_PROCTHOR_DIR to a directory holding multiroom-val150.jsonl.gz to include them"
        );
    }
}
