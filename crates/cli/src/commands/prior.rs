//! `ferret prior train`: learn P(target | container type, room type) from training houses.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use ferret_plan::{LearnedSettings, Prior};

use crate::common::HouseArgs;

/// Train and inspect likelihood priors.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Learn a prior from training houses. Several files may be given as `--houses A --also B`.
    Train(TrainArgs),
}

/// Arguments of `prior train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    #[command(flatten)]
    houses: HouseArgs,
    /// More training files (whole files), e.g. smallhouse-train1000 plus oneroom-train500.
    #[arg(long, value_name = "PATH")]
    also: Vec<PathBuf>,
    /// Which top-level objects of the training houses are containers: train with the set the
    /// evaluation will use (`furniture` for `--protocol paper`), so that every container type
    /// it meets has been seen.
    #[arg(long, value_name = "receptacles|furniture", default_value_t)]
    containers: ferret_world::ContainerSet,
    /// Smoothing weight toward the back-off estimate (pseudo-containers).
    #[arg(long, default_value_t = 2.0)]
    smoothing: f64,
    /// Folds of the cross-fitting that calibrates the prior's probabilities on its own training
    /// houses (Platt scaling, recorded in the file); 0 leaves them as counted. Given, it must
    /// be 0 or between 2 and half the training houses; by default 5, or none (and said so) when
    /// there are fewer than ten houses.
    #[arg(long, value_name = "N")]
    calibration_folds: Option<usize>,
    /// Also train the learned likelihood (`model/learned`) over these word embeddings (a
    /// folder; `scripts/embeddings.sh install` prints one). The file keeps the vector of every
    /// name it embedded, so runs need the folder only for names their training houses never
    /// had.
    #[arg(long, value_name = "DIR", env = "FERRET_EMBEDDINGS")]
    embeddings: Option<PathBuf>,
    /// A WordNet dictionary folder (Debian's wordnet-base; `scripts/embeddings.sh install
    /// wordnet`), read for words of a name the embeddings lack: their base forms, then the
    /// nearest hypernym the embeddings know (`vise` → `holding device`). Each such word is
    /// reported on stderr; a name with no known word is refused. Default: FERRET_WORDNET, else
    /// /usr/share/wordnet when installed.
    #[arg(long, value_name = "DIR")]
    wordnet: Option<PathBuf>,
    /// A second knowledge source beside the word vectors (with --embeddings): `wordnet` puts
    /// what WordNet says of each name (its synonyms, the nouns above it, its gloss), embedded
    /// with the same vectors, beside the name's own vector; `wordnet-shuffled` is its control,
    /// the same of another noun picked by hashing the name. Needs WordNet.
    #[arg(long, value_enum, value_name = "SOURCE")]
    knowledge: Option<KnowledgeArg>,
    /// Folds of held-out types and houses while training the learned likelihood: at least 2,
    /// and at most half the training houses. `--holdout-types N` runs need N here.
    #[arg(long, value_name = "N", default_value_t = LearnedSettings::default().folds)]
    learned_folds: usize,
    /// Heads per fold of the learned likelihood, each from its own seed (their logits are
    /// averaged: a single head depends on its seed).
    #[arg(long, value_name = "N", default_value_t = LearnedSettings::default().seeds)]
    learned_seeds: usize,
    /// Passes over the training questions per head.
    #[arg(long, value_name = "N", default_value_t = LearnedSettings::default().head.epochs)]
    learned_epochs: usize,
    /// Widths of the heads' hidden layers, comma separated.
    #[arg(long, value_name = "N,N", value_delimiter = ',', default_values_t = LearnedSettings::default().head.hidden)]
    learned_hidden: Vec<usize>,
    /// Weight decay of the heads' training (AdamW).
    #[arg(long, value_name = "X", default_value_t = LearnedSettings::default().head.weight_decay)]
    learned_weight_decay: f64,
    /// Seed of the learned likelihood's heads.
    #[arg(long, value_name = "N", default_value_t = 0)]
    learned_seed: u64,
    /// Also measure counts built into the head (one head over the names' vectors, the counted
    /// prior's logit and its evidence gaps) against the fusion model/learned uses, both scored
    /// where they were not fitted, and print both; the file gets the figures, the answers stay
    /// the fusion's. Trains one more set of heads.
    #[arg(long)]
    learned_compare_counts_in_head: bool,
    /// Output JSON file.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Runs a `prior` subcommand.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::Train(args) => train(args),
    }
}

fn train(args: TrainArgs) -> Result<ExitCode> {
    let mut loaded = args.houses.load_types_only(args.containers)?;
    for path in &args.also {
        let more = HouseArgs {
            houses: Some(path.clone()),
            range: None,
            ..args.houses.clone()
        }
        .load_types_only(args.containers)?;
        loaded.scenes.extend(more.scenes);
        loaded.skipped.extend(more.skipped);
    }
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    if !(args.smoothing.is_finite() && args.smoothing >= 0.0) {
        anyhow::bail!(
            "--smoothing {}: must be a finite number ≥ 0",
            args.smoothing
        );
    }
    if args.learned_seeds == 0 || args.learned_epochs == 0 {
        anyhow::bail!("--learned-seeds and --learned-epochs must be at least 1");
    }
    if args.embeddings.is_some() && !(2..=loaded.scenes.len() / 2).contains(&args.learned_folds) {
        anyhow::bail!(
            "--learned-folds {}: between 2 and half the training houses ({} houses here{})",
            args.learned_folds,
            loaded.scenes.len(),
            if loaded.scenes.len() >= 4 {
                ", try --learned-folds 2"
            } else {
                ": too few to learn from"
            }
        );
    }
    if args.learned_hidden.contains(&0) || args.learned_hidden.iter().sum::<usize>() > 4096 {
        anyhow::bail!("--learned-hidden: every width at least 1, 4096 in all at most");
    }
    if !(args.learned_weight_decay.is_finite() && (0.0..1.0).contains(&args.learned_weight_decay)) {
        anyhow::bail!("--learned-weight-decay: a number in [0, 1)");
    }
    let houses = loaded.scenes.len();
    let calibration_folds = match args.calibration_folds {
        None => ferret_plan::CALIBRATION_FOLDS,
        Some(0) => 0,
        Some(k) if (2..=houses / 2).contains(&k) => k,
        Some(k) => anyhow::bail!(
            "--calibration-folds {k}: 0 (no calibration) or between 2 and half the training houses ({houses} here{})",
            if houses >= 4 {
                ""
            } else {
                ": too few to calibrate, give 0"
            }
        ),
    };
    let started = std::time::Instant::now();
    let mut prior = Prior::train_with(&loaded.scenes, args.smoothing, calibration_folds);
    let mut learned_line = String::new();
    if let Some(dir) = &args.embeddings {
        let embeddings = ferret_lab::language::open_embeddings(dir)?;
        let wordnet = ferret_lab::language::LazyWordNet::new(args.wordnet.as_deref());
        let settings = LearnedSettings {
            folds: args.learned_folds,
            seeds: args.learned_seeds,
            seed: args.learned_seed,
            head: ferret_plan::learned::HeadSettings {
                epochs: args.learned_epochs,
                hidden: args.learned_hidden.clone(),
                weight_decay: args.learned_weight_decay,
                ..Default::default()
            },
            compare_counts_in_head: args.learned_compare_counts_in_head,
        };
        let source = ferret_lab::language::NameSource {
            embeddings: &embeddings,
            wordnet: &wordnet,
            knowledge: args.knowledge.map(Into::into),
        };
        if source.knowledge.is_some() && source.wordnet.get().map_err(anyhow::Error::msg)?.is_none()
        {
            anyhow::bail!(
                "--knowledge {}: WordNet is not installed (`{}`, or give --wordnet DIR)",
                source.knowledge.map_or("", |k| k.name()),
                ferret_lab::language::WORDNET_INSTALL_HINT
            );
        }
        let (trained, report) =
            ferret_lab::language::train_learned(&loaded.scenes, &prior, &source, &settings)?;
        prior = trained;
        for note in &report.notes {
            eprintln!("warning: {note}");
        }
        if let Some(l) = prior.learned() {
            let s = &l.language.unseen_score;
            let c = &l.control.unseen_score;
            learned_line = format!(
                "\nlearned likelihood over {} ({} names, {} folds × {} heads): on held-out target types AUROC prior {:.3}, head {:.3}, fused {:.3} (random-vector control: head {:.3}, fused {:.3})",
                l.embedding,
                report.names,
                l.settings.folds,
                l.settings.seeds,
                s.prior_auroc,
                s.head_auroc,
                s.fused_auroc,
                c.head_auroc,
                c.fused_auroc
            );
            if let Some(j) = &l.language.counts_in_head {
                learned_line.push_str(&format!(
                    "
counts and language, each fitted on all folds but one and scored on that one: the fusion AUROC {:.3} / log loss {:.4} (unseen target types {:.3} / {:.4}); counts built into the head {:.3} / {:.4} ({:.3} / {:.4})",
                    j.fusion_auroc,
                    j.fusion_log_loss,
                    j.fusion_auroc_unseen,
                    j.fusion_log_loss_unseen,
                    j.head_auroc,
                    j.head_log_loss,
                    j.head_auroc_unseen,
                    j.head_log_loss_unseen
                ));
            }
        }
    }
    crate::output::write_with_path(&args.out, |p| Ok(prior.save(p)?))?;
    let calibration = match &prior.calibration {
        Some(c) => format!(
            "calibrated by {}-fold cross-fitting on {} questions: logit P = {:.3}·logit P_counts {:+.3}",
            c.folds, c.pairs, c.a, c.c
        ),
        None => "not calibrated (too few houses, or --calibration-folds 0)".to_string(),
    };
    println!(
        "trained a prior on {} houses ({} containers) in {:.1} s, {calibration}, and wrote {}{learned_line}",
        prior.houses,
        prior.container_count(),
        started.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// `--knowledge`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum KnowledgeArg {
    /// WordNet's synonyms, hypernyms and gloss of each name.
    Wordnet,
    /// The control: the same of a noun picked by hashing the name.
    WordnetShuffled,
}

impl From<KnowledgeArg> for ferret_lab::language::Knowledge {
    fn from(k: KnowledgeArg) -> Self {
        match k {
            KnowledgeArg::Wordnet => ferret_lab::language::Knowledge::WordNet,
            KnowledgeArg::WordnetShuffled => ferret_lab::language::Knowledge::WordNetShuffled,
        }
    }
}
