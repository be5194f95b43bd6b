//! The real all-MiniLM-L6-v2 model, when installed:
//! `FERRET_MINILM=$(scripts/embeddings.sh install minilm) cargo test -p ferret-embed --release
//! --features minilm --test minilm`. Without the variable the tests print how to enable them and
//! pass. Built without the feature, the installed model must be refused with the error that
//! says to build with `--features minilm`.

use std::path::PathBuf;

/// The environment variable naming the installed model's folder (what `scripts/embeddings.sh
/// install minilm` prints).
const MINILM_ENV: &str = "FERRET_MINILM";

/// The model's folder, or `None` (after saying how to enable the test) when the variable is
/// unset.
fn model_dir() -> Option<PathBuf> {
    match std::env::var_os(MINILM_ENV) {
        Some(dir) if !dir.is_empty() => Some(PathBuf::from(dir)),
        _ => {
            println!(
                "skipped: the all-MiniLM-L6-v2 tests need the model; enable them with \
                 {MINILM_ENV}=$(scripts/embeddings.sh install minilm)"
            );
            None
        }
    }
}

#[cfg(not(feature = "minilm"))]
#[test]
fn without_the_feature_the_installed_model_asks_for_it() {
    use ferret_embed::{EmbedError, Embeddings};
    let Some(dir) = model_dir() else { return };
    let err = Embeddings::open(&dir).expect_err("a build without the minilm feature");
    assert!(matches!(err, EmbedError::NeedsFeature { .. }), "{err:?}");
    assert!(err.to_string().contains("--features minilm"), "{err}");
}

#[cfg(feature = "minilm")]
mod with_model {
    use std::process::Command;
    use std::time::Instant;

    use ferret_embed::{Embeddings, cosine};

    use super::model_dir;

    fn open() -> Option<Embeddings> {
        let dir = model_dir()?;
        Some(Embeddings::open(&dir).expect("the folder in FERRET_MINILM opens"))
    }

    fn name(t: &Embeddings, n: &str) -> Vec<f32> {
        t.embed_name(n)
            .unwrap_or_else(|| panic!("{n} has a vector"))
    }

    const NAMES: [&str; 12] = [
        "CounterTop",
        "TVStand",
        "RemoteControl",
        "LivingRoom",
        "Bathroom",
        "Kitchen",
        "Fridge",
        "Toilet",
        "DiningTable",
        "ShelvingUnit",
        "HousePlant",
        "SoapBottle",
    ];

    #[test]
    fn loads_all_minilm_l6_v2_and_times_it() {
        let Some(dir) = model_dir() else { return };
        let started = Instant::now();
        let t = Embeddings::open(&dir).expect("opens");
        let load = started.elapsed().as_secs_f64();
        assert_eq!(t.id(), "all-minilm-l6-v2");
        assert_eq!(t.dim(), 384);
        assert_eq!(t.len(), 30_522);
        assert!(t.is_model());
        // No stored vector per word.
        assert_eq!(t.word("fridge"), None);
        // No words, no vector.
        assert_eq!(t.embed_name("_2_"), None);

        let started = Instant::now();
        for n in NAMES {
            name(&t, n);
        }
        let first = started.elapsed().as_secs_f64() / NAMES.len() as f64;
        let started = Instant::now();
        for n in NAMES {
            name(&t, n);
        }
        let cached = started.elapsed().as_secs_f64() / NAMES.len() as f64;
        println!(
            "loaded in {load:.3} s; a name takes {:.2} ms to embed, {:.1} µs when cached",
            first * 1e3,
            cached * 1e6
        );
    }

    #[test]
    fn names_are_unit_vectors_and_the_same_every_time() {
        let Some(t) = open() else { return };
        let Some(again) = open() else { return };
        for n in NAMES {
            let v = name(&t, n);
            assert_eq!(v.len(), 384, "{n}");
            let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-5, "{n}: norm {norm}");
            // From the cache, and from a second model with its own cache: the same bits.
            assert_eq!(name(&t, n), v, "{n}");
            assert_eq!(name(&again, n), v, "{n}");
        }
        // The name's words are what is embedded: separators and instance numbers do not count.
        assert_eq!(name(&t, "counter_top_2"), name(&t, "CounterTop"));
    }

    /// The first values of a few vectors, computed by an independent float64 forward pass of the
    /// model in numpy (safetensors read by hand, WordPiece over vocab.txt, BERT with erf GELU,
    /// mean pooling over `[CLS] … [SEP]`, L2 normalisation); not by this crate.
    #[test]
    fn matches_an_independent_reference() {
        let Some(t) = open() else { return };
        let reference: [(&str, [f32; 6]); 4] = [
            (
                "CounterTop",
                [
                    -0.072_819_6,
                    -0.023_524_3,
                    -0.075_653_0,
                    0.014_155_3,
                    -0.067_315_4,
                    0.019_822_5,
                ],
            ),
            (
                "Fridge",
                [
                    -0.098_778_8,
                    0.050_310_2,
                    -0.089_156_0,
                    0.062_885_1,
                    0.068_836_2,
                    0.024_284_4,
                ],
            ),
            (
                "RemoteControl",
                [
                    -0.030_719_2,
                    -0.044_882_6,
                    -0.002_414_4,
                    -0.002_517_1,
                    -0.046_291_7,
                    0.074_623_7,
                ],
            ),
            (
                "LivingRoom",
                [
                    0.038_384_9,
                    -0.015_802_3,
                    -0.032_367_4,
                    0.045_527_2,
                    -0.003_569_0,
                    0.000_038_3,
                ],
            ),
        ];
        for (n, want) in reference {
            let got = name(&t, n);
            for (i, (g, w)) in got.iter().zip(want).enumerate() {
                assert!((g - w).abs() < 2e-5, "{n}[{i}]: {g} vs the reference {w}");
            }
        }
    }

    #[test]
    fn similarities_rank_rooms_and_are_not_all_alike() {
        let Some(t) = open() else { return };
        let sim = |a: &str, b: &str| cosine(&name(&t, a), &name(&t, b));
        // The reference's values (see above): Fridge–Kitchen 0.5262, Fridge–Bathroom 0.3767,
        // Toilet–Bathroom 0.7906, Toilet–Kitchen 0.4435.
        for (a, b, want) in [
            ("Fridge", "Kitchen", 0.526_167),
            ("Fridge", "Bathroom", 0.376_743),
            ("Toilet", "Bathroom", 0.790_573),
            ("Toilet", "Kitchen", 0.443_531),
        ] {
            let got = sim(a, b);
            assert!((got - want).abs() < 1e-4, "{a}–{b}: {got} vs {want}");
        }
        assert!(sim("Fridge", "Kitchen") > sim("Fridge", "Bathroom"));
        assert!(sim("Toilet", "Bathroom") > sim("Toilet", "Kitchen"));
        assert!(sim("RemoteControl", "LivingRoom") > sim("RemoteControl", "Bathroom"));
        // Padding averaged into the mean would make every pair ≈ 0.8; unrelated names are far
        // below (the reference: about 0.18–0.25).
        for (a, b) in [
            ("CounterTop", "RemoteControl"),
            ("TVStand", "Toilet"),
            ("Fridge", "RemoteControl"),
            ("SoapBottle", "DiningTable"),
            ("HousePlant", "TVStand"),
        ] {
            let s = sim(a, b);
            assert!(s < 0.5, "{a}–{b}: {s}");
        }
    }

    /// The bits of a few vectors, as one line, for [`same_bits_whatever_the_thread_count`].
    fn bits(t: &Embeddings) -> String {
        NAMES
            .iter()
            .flat_map(|n| name(t, n))
            .map(|x| format!("{:08x}", x.to_bits()))
            .collect()
    }

    /// Run by [`same_bits_whatever_the_thread_count`] in a child process.
    #[test]
    #[ignore = "run in a child process by same_bits_whatever_the_thread_count"]
    fn print_bits() {
        let Some(t) = open() else { return };
        println!("BITS {}", bits(&t));
    }

    /// candle reads `RAYON_NUM_THREADS` to split its matrix products; the vectors must not depend
    /// on it. Each count runs in a child process of this test binary.
    #[test]
    fn same_bits_whatever_the_thread_count() {
        let Some(t) = open() else { return };
        let want = bits(&t);
        let exe = std::env::current_exe().expect("the test binary");
        for threads in ["1", "2", "8"] {
            let out = Command::new(&exe)
                .args([
                    "--exact",
                    "with_model::print_bits",
                    "--ignored",
                    "--nocapture",
                    "--test-threads=1",
                ])
                .env("RAYON_NUM_THREADS", threads)
                .output()
                .expect("the test binary runs");
            let stdout = String::from_utf8_lossy(&out.stdout);
            assert!(out.status.success(), "{threads} threads: {stdout}");
            // The test harness prints `test … ... ` before the line.
            let got = stdout
                .split_whitespace()
                .skip_while(|w| *w != "BITS")
                .nth(1)
                .unwrap_or_else(|| panic!("{threads} threads printed no vectors: {stdout}"));
            assert_eq!(got.len(), want.len(), "{threads} threads");
            assert!(got == want, "{threads} threads give other vectors");
        }
    }

    /// The sentence model has a vector for any text: the rule only says which words are neither
    /// whole tokens nor WordNet nouns, and refuses a name with none (WordNet at hand).
    #[test]
    fn real_minilm_says_which_words_it_embeds_from_pieces_and_refuses_a_typo() {
        let Some(t) = open() else { return };
        let Some(wn_dir) = ferret_embed::WordNet::default_dir() else {
            println!(
                "skipped: scripts/embeddings.sh install wordnet (or FERRET_WORDNET) to run it"
            );
            return;
        };
        let wn = ferret_embed::WordNet::open(&wn_dir).unwrap();
        // `ladle` and `spatula` are not whole tokens of its vocabulary, but WordNet nouns.
        for n in ["Ladle", "Spatula", "CounterTop", "LaundryHamper"] {
            let r = t.resolve_name(n, Some(&wn)).unwrap();
            assert!(r.notes.is_empty(), "{n}: {:?}", r.notes);
            assert_eq!(Some(r.vector), t.embed_name(n), "{n}");
        }
        let r = t.resolve_name("XyzzyLadle", Some(&wn)).unwrap();
        assert_eq!(r.notes.len(), 1, "{:?}", r.notes);
        assert_eq!(r.notes[0].reading, ferret_embed::WordReading::Pieces);
        let err = t.resolve_name("Xyzzyblorp", Some(&wn)).unwrap_err();
        assert!(err.to_string().contains("`Xyzzyblorp`"), "{err}");
        // Without WordNet only the vocabulary is known: said, not refused.
        assert_eq!(t.resolve_name("Ladle", None).unwrap().notes.len(), 1);
    }
}
