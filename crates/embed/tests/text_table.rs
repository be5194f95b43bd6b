//! Text tables (`vectors.txt`) and the vectors of names, on small hand-made tables.

use std::path::Path;

use ferret_embed::{EmbedError, Embeddings, INSTALL_HINT, cosine};

const TABLE: &str = "# id: tiny-3d
counter 1 0 0
top 0 1 0
fridge 3 4 0
box 0 0 2
candy 0 2 0
towels 0 0 -1
north 1 0 0
south -1 0 0
";

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write table");
    path
}

fn tiny() -> (tempfile::TempDir, Embeddings) {
    let dir = tempfile::tempdir().expect("tempdir");
    write(dir.path(), "vectors.txt", TABLE);
    let table = Embeddings::open(dir.path()).expect("open");
    (dir, table)
}

fn assert_close(got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-6, "{got:?} vs {want:?}");
    }
}

#[test]
fn loads_words_dimension_and_header_id() {
    let (_dir, t) = tiny();
    assert_eq!(t.id(), "tiny-3d");
    assert_eq!(t.dim(), 3);
    assert_eq!(t.len(), 8);
    assert!(!t.is_empty());
    assert_eq!(t.word("fridge"), Some(&[3.0, 4.0, 0.0][..]));
    assert_eq!(t.word("Fridge"), None, "word() is exact");
    assert_eq!(t.word("sink"), None);
}

#[test]
fn id_falls_back_to_the_file_stem() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write(dir.path(), "kitchen.txt", "pan 1 2\n\npot 3 4\r\n");
    let t = Embeddings::open(&path).expect("open a .txt file directly");
    assert_eq!(t.id(), "kitchen");
    assert_eq!(t.len(), 2);
    assert_eq!(t.word("pot"), Some(&[3.0, 4.0][..]));
}

#[test]
fn embed_name_averages_and_normalises() {
    let (_dir, t) = tiny();
    // One word: its direction.
    assert_close(&t.embed_name("Fridge").expect("known"), &[0.6, 0.8, 0.0]);
    // Two words: the mean (0.5, 0.5, 0) normalised.
    let h = std::f32::consts::FRAC_1_SQRT_2;
    assert_close(&t.embed_name("CounterTop").expect("known"), &[h, h, 0.0]);
    // Averaging happens before normalising: fridge (3, 4, 0) outweighs counter (1, 0, 0).
    let n = (16.0f32 + 16.0).sqrt();
    assert_close(
        &t.embed_name("FridgeCounter").expect("known"),
        &[4.0 / n, 4.0 / n, 0.0],
    );
    let v = t.embed_name("counter_top-fridge").expect("known");
    let norm: f32 = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    assert!((norm - 1.0).abs() < 1e-6, "unit length, got {norm}");
}

#[test]
fn unknown_words_are_skipped_and_all_unknown_is_none() {
    let (_dir, t) = tiny();
    assert_close(
        &t.embed_name("CounterWidget").expect("counter"),
        &[1.0, 0.0, 0.0],
    );
    assert_close(
        &t.embed_name("Widget2Fridge").expect("fridge"),
        &[0.6, 0.8, 0.0],
    );
    assert_eq!(t.embed_name("WidgetGadget"), None);
    assert_eq!(t.embed_name(""), None);
    assert_eq!(t.embed_name("42"), None);
}

#[test]
fn plural_and_singular_fallbacks() {
    let (_dir, t) = tiny();
    assert_close(&t.embed_name("Boxes").expect("box"), &[0.0, 0.0, 1.0]);
    assert_close(&t.embed_name("Candies").expect("candy"), &[0.0, 1.0, 0.0]);
    assert_close(&t.embed_name("Fridges").expect("fridge"), &[0.6, 0.8, 0.0]);
    // Singular to plural: the table only has `towels`.
    assert_close(&t.embed_name("Towel").expect("towels"), &[0.0, 0.0, -1.0]);
    // `ss` is not a plural: `glass` must not become `glas`, and nothing else matches.
    assert_eq!(t.embed_name("Glass"), None);
}

#[test]
fn vectors_that_cancel_have_no_direction() {
    let (_dir, t) = tiny();
    assert_eq!(t.embed_name("NorthSouth"), None);
}

#[test]
fn cosine_of_names() {
    let (_dir, t) = tiny();
    let fridge = t.embed_name("Fridge").expect("known");
    let counter = t.embed_name("Counter").expect("known");
    let top = t.embed_name("Top").expect("known");
    assert!((cosine(&fridge, &counter) - 0.6).abs() < 1e-6);
    assert!((cosine(&fridge, &top) - 0.8).abs() < 1e-6);
    assert_eq!(cosine(&fridge, &[1.0]), 0.0, "lengths differ");
}

fn text_error(text: &str) -> String {
    let dir = tempfile::tempdir().expect("tempdir");
    write(dir.path(), "vectors.txt", text);
    let err = Embeddings::open(dir.path()).expect_err("malformed");
    assert!(matches!(err, EmbedError::Text { .. }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("vectors.txt"), "names the file: {msg}");
    msg
}

#[test]
fn malformed_lines_name_the_line() {
    let msg = text_error("# id: x\na 1 2\nb 1 2 3\n");
    assert!(msg.contains("line 3"), "{msg}");
    assert!(
        msg.contains("has 3 values, but the lines before have 2"),
        "{msg}"
    );

    let msg = text_error("a 1 2\nb 1 x\n");
    assert!(msg.contains("line 2"), "{msg}");
    assert!(msg.contains("\"x\", is not a finite number"), "{msg}");

    let msg = text_error("a 1 nan\n");
    assert!(msg.contains("line 1"), "{msg}");

    let msg = text_error("a\n");
    assert!(msg.contains("line 1") && msg.contains("no values"), "{msg}");

    let msg = text_error("# id: only a header\n");
    assert!(msg.contains("no vectors"), "{msg}");
}

#[test]
fn a_hash_word_after_the_first_line_is_a_word() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(dir.path(), "vectors.txt", "a 1 0\n# 0 1\n");
    let t = Embeddings::open(dir.path()).expect("open");
    assert_eq!(t.word("#"), Some(&[0.0, 1.0][..]));
    assert_eq!(t.id(), "vectors");
}

#[test]
fn a_folder_without_embeddings_says_what_was_looked_for() {
    let dir = tempfile::tempdir().expect("tempdir");
    write(dir.path(), "readme.md", "nothing here");
    let msg = Embeddings::open(dir.path()).expect_err("empty").to_string();
    assert!(msg.contains("vectors.txt"), "{msg}");
    assert!(msg.contains("_emb.npy"), "{msg}");
    assert!(msg.contains(INSTALL_HINT), "{msg}");

    let missing = dir.path().join("nowhere");
    let msg = Embeddings::open(&missing).expect_err("missing").to_string();
    assert!(
        msg.contains("nowhere") && msg.contains("does not exist"),
        "{msg}"
    );
}

#[test]
fn from_words_checks_lengths() {
    let ok = Embeddings::from_words(
        "hand",
        [
            ("a".to_owned(), vec![1.0, 0.0]),
            ("b".to_owned(), vec![0.0, 1.0]),
        ],
    )
    .expect("same lengths");
    assert_eq!((ok.id(), ok.dim(), ok.len()), ("hand", 2, 2));

    let err = Embeddings::from_words(
        "hand",
        [
            ("a".to_owned(), vec![1.0, 0.0]),
            ("b".to_owned(), vec![1.0]),
        ],
    )
    .expect_err("different lengths")
    .to_string();
    assert!(
        err.contains("\"hand\"") && err.contains("\"b\" has 1 values"),
        "{err}"
    );

    let err = Embeddings::from_words("hand", [("a".to_owned(), vec![f32::NAN])])
        .expect_err("not finite")
        .to_string();
    assert!(err.contains("not finite"), "{err}");

    let empty = Embeddings::from_words("none", []).expect("empty is allowed");
    assert!(empty.is_empty());
    assert_eq!(empty.embed_name("Fridge"), None);
}

#[test]
fn a_repeated_word_keeps_its_first_vector() {
    let t = Embeddings::from_words(
        "dup",
        [
            ("a".to_owned(), vec![1.0]),
            ("a".to_owned(), vec![2.0]),
            ("b".to_owned(), vec![3.0]),
        ],
    )
    .expect("duplicates are allowed");
    assert_eq!(t.len(), 2);
    assert_eq!(t.word("a"), Some(&[1.0][..]));
    assert_eq!(t.word("b"), Some(&[3.0][..]));
}
