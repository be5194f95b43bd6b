//! Every Markdown report of the experiment layer, rendered in one place from the figures other
//! modules compute: an evaluation's `summary.md` (table I, the paper's unit, paired comparisons,
//! the reference code's means, and the LLM sections added after a run), a selection's
//! `selection.md`, and a calibration's `calibration.md` with its fitted fusions. Nothing here
//! computes a figure, so a change of wording never changes a number.

use ferret_llm::TokenReport;
use ferret_plan::{Calibration, FusionFile, TrialsPerHouse};
use ferret_select::{
    ExperimentResult, PAPER_KS, selection_table_markdown, strategy_table_markdown,
};

use crate::rows::CELL_M;
use crate::summary::{PAIRED_RESAMPLES, PairedRow, SummaryRow};

/// A p-value as people read it: three decimals, two significant digits below 0.001, and
/// `< 1e-6` below that.
fn format_p(p: Option<f64>) -> String {
    match p {
        None => "–".into(),
        Some(p) if p < 1e-6 => "< 1e-6".into(),
        Some(p) if p < 0.001 => format!("{p:.1e}"),
        Some(p) => format!("{p:.3}"),
    }
}

/// The paired comparisons as Markdown, one table per reference; empty without comparisons.
pub fn paired_markdown(paired: &[PairedRow]) -> String {
    if paired.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "\n## Paired comparisons\n\nPairs are the trials (house and target) both strategies finished. Difference = strategy − reference, metres (negative: the strategy is cheaper); 95 % CI of its mean by bootstrap ({PAIRED_RESAMPLES} resamples); p from the two-sided Wilcoxon signed-rank test; wins / ties / losses count the trials where the strategy is cheaper / equal / dearer.\n"
    );
    let mut current: Option<(&str, &str)> = None;
    for r in paired {
        if current != Some((r.reference.as_str(), r.role)) {
            current = Some((r.reference.as_str(), r.role));
            let why = match r.role {
                "first" => "the first strategy",
                "best" => "the lowest mean, oracle excepted",
                _ => "named with --paired-against",
            };
            md.push_str(&format!(
                "\nAgainst {} ({why}):\n\n| strategy | pairs | mean difference (m) | 95 % CI (m) | Wilcoxon p | wins / ties / losses |\n|---|---:|---:|---:|---:|---:|\n",
                r.reference
            ));
        }
        md.push_str(&format!(
            "| {} | {} | {:+.2} | [{:+.2}, {:+.2}] | {} | {} / {} / {} |\n",
            r.strategy,
            r.pairs,
            r.mean_diff_m,
            r.ci95_low_m,
            r.ci95_high_m,
            format_p(r.wilcoxon_p),
            r.wins,
            r.ties,
            r.losses
        ));
    }
    md
}

/// A run of teams: each strategy's makespan beside what the whole team drove (nothing for a
/// run of one robot).
pub fn team_markdown(summary: &[SummaryRow]) -> String {
    if summary.iter().all(|r| r.mean_total_travel_m.is_none()) {
        return String::new();
    }
    let mut md = String::from(
        "
## Teams

The cost above is the makespan: metres until the goal held (robots drive at equal speed). What the whole team drove, beside it:

| strategy | mean makespan (m) | mean total travel (m) | total / makespan |
|---|---:|---:|---:|
",
    );
    for r in summary {
        if let Some(t) = r.mean_total_travel_m {
            let ratio = if r.mean_m > 0.0 {
                t / r.mean_m
            } else {
                f64::NAN
            };
            md += &format!(
                "| {} | {:.2} | {:.2} | {:.2} |
",
                r.strategy, r.mean_m, t, ratio
            );
        }
    }
    md
}

/// What a run's `summary.md` shows.
#[derive(Clone, Copy, Debug)]
pub struct RunFigures<'a> {
    /// The paper's table I, one row per strategy.
    pub summary: &'a [SummaryRow],
    /// Where the houses came from.
    pub source: &'a str,
    /// Houses with at least one finished trial.
    pub houses_run: usize,
    /// How trials were drawn per house.
    pub trials_per_house: TrialsPerHouse,
    /// Trials drawn on those houses.
    pub trials_run: usize,
    /// The household tasks of the run, described ([`Tasks::describe`](crate::Tasks::describe)),
    /// when its trials are tasks.
    pub tasks: Option<&'a str>,
    /// Costs in grid cells too.
    pub cells: bool,
    /// The reference code's weighted means, when its draws apply.
    pub reference_means: Option<&'a [(String, f64)]>,
    /// The shard (index, count) a shard's run is; its comparisons are the merge's.
    pub shard: Option<(usize, usize)>,
    /// The paired comparisons (none for a shard).
    pub paired: &'a [PairedRow],
}

/// A run's `summary.md`: table I, then in cells, the reference code's means and the paired
/// comparisons as the run has them.
pub fn run_markdown(f: &RunFigures<'_>) -> String {
    let mut md = summary_markdown(
        f.summary,
        f.source,
        f.houses_run,
        (f.trials_per_house, f.tasks),
        f.trials_run,
    );
    if f.cells {
        md += &cells_markdown(f.summary);
    }
    md += &team_markdown(f.summary);
    if let Some(means) = f.reference_means {
        md += &reference_means_markdown(means);
    }
    match f.shard {
        Some((index, count)) => {
            md += &format!(
                "\nShard {index}/{count}: the paired comparisons (and the pictures) are made by `ferret merge` over every shard.\n"
            );
        }
        None => md += &paired_markdown(f.paired),
    }
    md
}

/// The paper's table I as Markdown; `trials` trials were drawn on `houses` houses, as `drawn`
/// says (trials per house, and the household tasks described, when they are tasks).
pub fn summary_markdown(
    summary: &[SummaryRow],
    source: &str,
    houses: usize,
    drawn: (TrialsPerHouse, Option<&str>),
    trials: usize,
) -> String {
    let (per_house, tasks) = drawn;
    let drawn = match (per_house, tasks) {
        (_, Some(tasks)) => format!("{trials} household tasks ({tasks})"),
        (TrialsPerHouse::One, None) => "one trial per house".to_string(),
        (TrialsPerHouse::Count(n), None) => {
            format!("{trials} trials, up to {n} distinct targets per house")
        }
        (TrialsPerHouse::All, None) => {
            format!("{trials} trials, every target type of each house")
        }
    };
    let mut md = format!(
        "# Navigation cost per strategy\n\n{houses} houses from {source}; {drawn}, the same for every strategy.\n\n"
    );
    md.push_str(
        "| strategy | trials | mean cost (m) | 95 % CI | median (m) | cost vs optimistic+greedy |\n",
    );
    md.push_str("|---|---:|---:|---:|---:|---:|\n");
    for r in summary {
        let imp = r
            .improvement_pct
            // Shown as a change of cost, so that lower reads as better (−52.8 % = 52.8 % cheaper);
            // `0.0 - p` keeps the reference's own row at +0.0 rather than −0.0.
            .map_or_else(|| "–".to_string(), |p| format!("{:+.1} %", 0.0 - p));
        md.push_str(&format!(
            "| {} | {} | {:.2} | ±{:.2} | {:.2} | {} |\n",
            r.strategy, r.trials, r.mean_m, r.ci95_m, r.median_m, imp
        ));
    }
    let short: Vec<String> = summary
        .iter()
        .filter(|r| r.trials < trials)
        .map(|r| format!("{} finished {} of {trials}", r.strategy, r.trials))
        .collect();
    if !short.is_empty() {
        md.push_str(&format!(
            "\n**Failed trials:** {}. Means and medians cover each strategy's own trials; \"cost vs optimistic+greedy\" compares only the {} paired trials (houses where every strategy finished).\n",
            short.join("; "),
            summary.first().map_or(0, |r| r.paired_trials)
        ));
    }
    md
}

/// [`reference_means`](crate::summary::reference_means) as Markdown, in metres and cells.
pub fn reference_means_markdown(means: &[(String, f64)]) -> String {
    let mut md = String::from(
        "\n## As the reference code averages\n\nEach mean weighted by how often 500 seeded runs of 100 draws with replacement (numpy's legacy generator, as the reference's results script) pick each house.\n\n| strategy | mean cost (m) | mean cost (cells) |\n|---|---:|---:|\n",
    );
    for (s, m) in means {
        md.push_str(&format!("| {s} | {m:.2} | {:.1} |\n", m / CELL_M));
    }
    md
}

/// The summary in 0.05 m cells as Markdown: the paper's unit, for comparison with its table I.
pub fn cells_markdown(summary: &[SummaryRow]) -> String {
    let mut md = String::from(
        "\n## In the paper's unit\n\nThe same costs in grid cells of 0.05 m (metres / 0.05), the unit of the paper's table I.\n\n| strategy | trials | mean cost (cells) | 95 % CI | median (cells) |\n|---|---:|---:|---:|---:|\n",
    );
    for r in summary {
        md.push_str(&format!(
            "| {} | {} | {:.1} | ±{:.1} | {:.1} |\n",
            r.strategy,
            r.trials,
            r.mean_m / CELL_M,
            r.ci95_m / CELL_M,
            r.median_m / CELL_M
        ));
    }
    md
}

/// `summary.md` with what an LLM service used in the run after it: every `| strategy |` row with
/// a warning marked, the token report (the paper's table V), the answer classes and the
/// warnings.
pub fn with_llm_sections(md: &str, report: &TokenReport, warnings: &[(String, String)]) -> String {
    let mut md = mark_rows(md, warnings);
    md.push_str(&format!("\n## LLM tokens and cost\n\n```\n{report}```\n"));
    md.push_str(&answers_markdown(report));
    if !warnings.is_empty() {
        md.push_str("\n## Warnings\n\n");
        for (strategy, w) in warnings {
            md.push_str(&format!("- ⚠ `{strategy}`: {w}\n"));
        }
    }
    md
}

/// `| strategy |` table rows of strategies with a warning get a ⚠ after the name.
fn mark_rows(md: &str, warnings: &[(String, String)]) -> String {
    md.lines()
        .map(|line| {
            match warnings
                .iter()
                .find(|(s, _)| line.starts_with(&format!("| {s} |")))
            {
                Some((s, _)) => line.replacen(&format!("| {s} |"), &format!("| {s} ⚠ |"), 1),
                None => line.to_string(),
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + if md.ends_with('\n') { "\n" } else { "" }
}
/// How each LLM strategy's answers were read: the class of every first answer, re-asks,
/// fallbacks, log-probabilities, and the most common probability.
pub fn answers_markdown(report: &TokenReport) -> String {
    use ferret_llm::AnswerClass;
    let rows: Vec<_> = report
        .rows
        .iter()
        .filter(|r| r.answers.answers() > 0)
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut md = String::from(
        "\n## LLM answers\n\nClass of each distinct question's first answer (P-BATCH: of each place's percentage); unusable ones (several numbers, none, the worked example echoed, no allowed word, a place left out) are asked again, then fall back to 0.01. \"logprobs missing\": read from the text although log-probabilities were wanted (P-YESNO and P-CHOICE: the word with the endpoint's `word_answer_mass`).\n\n| strategy | answers |",
    );
    for c in AnswerClass::ALL {
        md.push_str(&format!(" {} |", c.label()));
    }
    md.push_str(
        " re-asked | fell back | from logprobs | logprobs missing | most common p |\n|---|---:|",
    );
    for _ in AnswerClass::ALL {
        md.push_str("---:|");
    }
    md.push_str("---:|---:|---:|---:|---:|\n");
    for r in rows {
        let a = &r.answers;
        let mut line = format!("| {} | {} |", r.strategy, a.answers());
        for c in AnswerClass::ALL {
            line.push_str(&format!(" {} |", a.class(c)));
        }
        let common = r.most_common_probability().map_or_else(
            || "–".into(),
            |(v, share)| format!("{:.1} % ({:.0} %)", 100.0 * v, 100.0 * share),
        );
        let direct = if a.direct_answers > 0 {
            format!(" ({} P-DIRECT unmatched)", a.direct_fallbacks)
        } else {
            String::new()
        };
        line.push_str(&format!(
            " {} | {}{} | {} | {} | {} |\n",
            a.reasked,
            a.fallbacks(),
            direct,
            a.logprob_used,
            a.logprob_missing,
            common
        ));
        md.push_str(&line);
    }
    md
}

/// `selection.md` of a selection over `houses` houses: what ran, table II at the paper's k and
/// the strategies. `trials` is the replay table's trial count when houses have several trials.
pub fn selection_markdown(
    result: &ExperimentResult,
    houses: usize,
    trials: Option<usize>,
) -> String {
    let opts = &result.options;
    let ks: Vec<usize> = PAPER_KS
        .iter()
        .copied()
        .filter(|&k| k <= result.trials())
        .collect();
    format!(
        "# Strategy selection\n\n{} deployments × {} trials over {} houses{}, c = {} m, seed {}.\n\n{}\n{}",
        opts.deployments,
        opts.trials_per_deployment,
        houses,
        trials.map_or_else(String::new, |n| format!(
            " ({n} trials; one per house in each deployment)"
        )),
        opts.c,
        opts.seed,
        selection_table_markdown(result, &ks),
        strategy_table_markdown(result)
    )
}

/// The fitted fusions as Markdown.
pub fn fusion_markdown(file: &FusionFile) -> String {
    let mut md = String::from(
        "## Fusion with the prior or the learned likelihood (logit P = a·logit P_base + b·logit P_llm + c + g·(d·logit P_llm + e), g the prior's evidence gap)\n\n| strategy | a | b | c | d | e | pairs | Brier base / LLM / fused | AUROC base / LLM / fused |\n|---|---:|---:|---:|---:|---:|---:|---|---|\n",
    );
    let auroc = |a: Option<f64>| a.map_or_else(|| "–".into(), |a| format!("{a:.3}"));
    for f in &file.fits {
        md.push_str(&format!(
            "| {}/{} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {:.4} / {:.4} / {:.4} | {} / {} / {} |\n",
            f.base.kind(),
            f.source,
            f.weights.a,
            f.weights.b,
            f.weights.c,
            f.weights.d,
            f.weights.e,
            f.pairs,
            f.prior_score.brier,
            f.source_score.brier,
            f.fused_score.brier,
            auroc(f.prior_score.auroc),
            auroc(f.source_score.auroc),
            auroc(f.fused_score.auroc),
        ));
    }
    md
}

/// The table of scores as Markdown; `per_house` says which targets each house had.
pub fn calibration_markdown(
    scored: &[(String, Calibration)],
    source: &str,
    houses: usize,
    trials: usize,
    per_house: &str,
) -> String {
    let mut md = format!(
        "# Calibration of likelihood sources\n\n{houses} houses from {source}, {per_house} per house ({trials} house–target pairs), every container: P_S(target, container) against whether it holds the target. Brier and log loss: lower is better; AUROC: 0.5 is chance.\n\n"
    );
    md.push_str("| source | pairs | holders | Brier | log loss | AUROC | mean p (holders) | mean p (others) |\n");
    md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    let opt =
        |v: Option<f64>, digits: usize| v.map_or_else(|| "–".into(), |v| format!("{v:.digits$}"));
    for (name, c) in scored {
        md.push_str(&format!(
            "| {name} | {} | {} | {:.4} | {:.4} | {} | {} | {} |\n",
            c.pairs,
            c.positives,
            c.brier,
            c.log_loss,
            opt(c.auroc, 3),
            opt(c.mean_p_pos, 3),
            opt(c.mean_p_neg, 3),
        ));
    }
    md
}
