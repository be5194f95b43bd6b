#!/usr/bin/env python3
"""Markdown tables from the runs of scripts/learned-benchmarks.sh (standard library only).

    scripts/learned-tables.py OUT_DIR
    scripts/learned-tables.py --lane LANE_OUT

Reads each run's summary.csv, paired.csv and calibration.csv under OUT_DIR and prints the tables
of docs/learned.md: mean cost per strategy with the paired difference against the reference
(strategy - reference, metres; negative is cheaper) and its 95 % bootstrap interval. With
--lane, the tables of `scripts/real-llm.sh learned` (the learned likelihood with P-YESNO) from its
output folder: each strategy against the prior, the learned likelihood and the fused controls.
"""

import csv
import json
import sys
from pathlib import Path


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def planning(out, title, runs, reference="model/prior"):
    """One table: a row per (run label, strategy)."""
    print(f"### {title}\n")
    print(f"| run | strategy | trials | mean (m) | vs {reference} (m, 95 % CI; w/t/l) |")
    print("|---|---|---:|---:|---|")
    for label, name in runs:
        run = out / name
        if not (run / "summary.csv").exists():
            print(f"| {label} | (no run: {name}) | | | |")
            continue
        paired = {r["strategy"]: r for r in rows(run / "paired.csv") if r["reference"] == reference}
        for s in rows(run / "summary.csv"):
            p = paired.get(s["strategy"])
            diff = (
                f"{float(p['mean_diff_m']):+.2f} [{float(p['ci95_low_m']):+.2f}, "
                f"{float(p['ci95_high_m']):+.2f}] ({p['wins']}/{p['ties']}/{p['losses']})"
                if p
                else ""
            )
            print(
                f"| {label} | {s['strategy']} | {s['trials']} | {float(s['mean_m']):.2f} | {diff} |"
            )
    print()


def calibration(out, title, runs):
    print(f"### {title}\n")
    print(
        "| run | source | pairs | Brier | log loss | AUROC | mean p (holders) | mean p (others) |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for label, name in runs:
        path = out / name / "calibration.csv"
        if not path.exists():
            print(f"| {label} | (no run: {name}) | | | | | | |")
            continue
        for r in rows(path):
            print(
                f"| {label} | {r['source']} | {r['pairs']} | {float(r['brier']):.4f} | "
                f"{float(r['log_loss']):.4f} | {float(r['auroc']):.3f} | "
                f"{float(r['mean_p_pos']):.3f} | {float(r['mean_p_neg']):.3f} |"
            )
    print()


def costs(out):
    path = out / "costs.json"
    if not path.exists():
        return
    print("### Costs\n")
    print("| what | figure |")
    print("|---|---|")
    for k, v in json.loads(path.read_text()).items():
        print(f"| {k} | {v} |")
    print()


def diff(p):
    return (
        f"{float(p['mean_diff_m']):+.2f} [{float(p['ci95_low_m']):+.2f}, "
        f"{float(p['ci95_high_m']):+.2f}]"
        if p
        else ""
    )


def against(out, title, runs, references):
    """One table: a row per (run label, strategy), a column per reference."""
    print(f"### {title}\n")
    print(
        "| run | strategy | trials | mean (m) | "
        + " | ".join(f"vs {r} (m, 95 % CI)" for r in references)
        + " |"
    )
    print("|---|---|---:|---:|" + "---|" * len(references))
    for label, name in runs:
        run = out / name
        if not (run / "summary.csv").exists():
            print(f"| {label} | (no run: {name}) | | |" + " |" * len(references))
            continue
        paired = {(r["reference"], r["strategy"]): r for r in rows(run / "paired.csv")}
        for s in rows(run / "summary.csv"):
            cells = [diff(paired.get((r, s["strategy"]))) for r in references]
            print(
                f"| {label} | {s['strategy']} | {s['trials']} | "
                f"{float(s['mean_m']):.2f} | " + " | ".join(cells) + " |"
            )
    print()


def fusions(out, title, files):
    print(f"### {title}\n")
    print("| prior | strategy | a | b | c | d | e | AUROC base / LLM / fused (training houses) |")
    print("|---|---|---:|---:|---:|---:|---:|---|")
    for label, name in files:
        path = out / name
        if not path.exists():
            print(f"| {label} | (no file: {name}) | | | | | | |")
            continue
        for f in json.loads(path.read_text())["fits"]:
            kind = "fused-learned" if f.get("base") == "learned" else "fused"
            w = f["weights"]
            a = [f[k]["auroc"] for k in ("prior_score", "source_score", "fused_score")]
            print(
                f"| {label} | {kind}/{f['source']} | {w['a']:.3f} | {w['b']:.3f} | {w['c']:.3f} "
                f"| {w['d']:.3f} | {w['e']:.3f} | {a[0]:.3f} / {a[1]:.3f} / {a[2]:.3f} |"
            )
    print()


def lane(out):
    calibration(
        out,
        "With the LLM: calibration (a target per house; the workshop every target)",
        [
            ("val150, unseen types (5 folds), GloVe", "learned-cal-unseen-glove"),
            ("val150, seen types, GloVe", "learned-cal-seen-glove"),
            ("workshop, GloVe", "learned-cal-workshop-glove"),
            ("workshop, MiniLM", "learned-cal-workshop-minilm"),
        ],
    )
    fusions(
        out,
        "P-YESNO fused with the prior and with the learned likelihood (fitted on training houses)",
        [("GloVe", "fusion-glove.json"), ("MiniLM", "fusion-minilm.json")],
    )
    refs = ["model/prior", "model/learned", "fused/noise", "fused-learned/noise"]
    against(
        out,
        "With the LLM: unseen target types (`--holdout-types 5`), val150",
        [("GloVe", "learned-unseen-glove")],
        refs,
    )
    against(
        out,
        "With the LLM: seen target types, val150",
        [("GloVe", "learned-seen-glove")],
        refs,
    )
    against(
        out,
        "With the LLM: furniture and rooms ProcTHOR never had (examples/workshop, every target)",
        [("GloVe", "learned-workshop-glove"), ("MiniLM", "learned-workshop-minilm")],
        refs,
    )


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--lane":
        lane(Path(sys.argv[2]))
        return
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = Path(sys.argv[1])
    costs(out)
    calibration(
        out,
        "Calibration on val150 and the workshop scene (every target present, every container)",
        [
            ("seen types, GloVe", "cal-seen-glove"),
            ("unseen types (5 folds), GloVe", "cal-unseen-glove"),
            ("seen types, MiniLM", "cal-seen-minilm"),
            ("unseen types (5 folds), MiniLM", "cal-unseen-minilm"),
            ("workshop, GloVe", "cal-workshop-glove"),
            ("workshop, MiniLM", "cal-workshop-minilm"),
            ("unseen types (5 folds), GloVe + WordNet", "cal-unseen-wordnet"),
            ("unseen types (5 folds), GloVe + shuffled WordNet", "cal-unseen-wordnet-shuffled"),
            ("workshop, GloVe + WordNet", "cal-workshop-wordnet"),
            ("workshop, GloVe + shuffled WordNet", "cal-workshop-wordnet-shuffled"),
        ],
    )
    planning(
        out,
        "Unseen target types (`--holdout-types 5`), val150",
        [
            ("one target, GloVe", "unseen-glove-1"),
            ("every target, GloVe", "unseen-glove-all"),
            ("one target, MiniLM", "unseen-minilm-1"),
            ("one target, GloVe, head seed 100", "unseen-glove-seed100"),
            ("one target, GloVe, head seed 200", "unseen-glove-seed200"),
            ("one target, GloVe + WordNet", "unseen-wordnet-1"),
            ("one target, GloVe + shuffled WordNet", "unseen-wordnet-shuffled-1"),
        ],
    )
    planning(
        out,
        "Seen target types, val150",
        [
            ("one target, GloVe", "seen-glove-1"),
            ("every target, GloVe", "seen-glove-all"),
            ("one target, MiniLM", "seen-minilm-1"),
        ],
    )
    planning(
        out,
        "Furniture and rooms ProcTHOR never had (examples/workshop, every target)",
        [
            ("GloVe", "workshop-glove"),
            ("MiniLM", "workshop-minilm"),
            ("GloVe + WordNet", "workshop-wordnet"),
            ("GloVe + shuffled WordNet", "workshop-wordnet-shuffled"),
        ],
    )
    planning(
        out,
        "Few training houses (val150, one target)",
        [
            ("5 houses", "few-5"),
            ("20 houses", "few-20"),
            ("100 houses", "few-100"),
            ("1 500 houses", "seen-glove-1"),
        ],
    )
    planning(
        out,
        "Other house sets and protocols",
        [
            ("`--protocol paper`, val150", "paper-val150"),
            ("generated houses (100)", "generated-1"),
            ("generated houses, every target", "generated-all"),
        ],
    )


if __name__ == "__main__":
    main()
