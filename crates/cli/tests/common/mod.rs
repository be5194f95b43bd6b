//! Helpers shared by the end-to-end tests: run the built `ferret` binary and read what it said.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

/// Runs the `ferret` binary built for these tests with `args`.
pub fn ferret(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ferret"))
        .args(args)
        .output()
        .expect("the ferret binary runs")
}

/// Standard error as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Standard output then standard error, as text.
pub fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(o))
}

/// A temporary path as the `&str` an argument list wants.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("temp paths are UTF-8")
}

/// The rows of a CSV file, each a map from column to value.
pub fn read_csv(path: &Path) -> Vec<HashMap<String, String>> {
    let mut r = csv::Reader::from_path(path).expect("csv exists");
    let headers = r.headers().expect("headers").clone();
    r.records()
        .map(|rec| {
            let rec = rec.expect("row");
            headers
                .iter()
                .map(String::from)
                .zip(rec.iter().map(String::from))
                .collect()
        })
        .collect()
}

/// POSTs `body` as JSON to `url`: the status and the reply's JSON.
pub fn post(url: &str, body: serde_json::Value) -> (u16, serde_json::Value) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let r = reqwest::Client::new()
            .post(url)
            .json(&body)
            .send()
            .await
            .unwrap();
        (r.status().as_u16(), r.json().await.unwrap())
    })
}

/// A JSON file, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("file exists")).expect("JSON")
}

/// The ProcTHOR folder the tests that need real houses read (`FERRET_PROCTHOR_DIR`); `None`, with
/// a message saying how to run them, when it is not set.
pub fn data_dir() -> Option<PathBuf> {
    match std::env::var_os("FERRET_PROCTHOR_DIR") {
        Some(d) => Some(PathBuf::from(d)),
        None => {
            eprintln!(
                "skipped: set FERRET_PROCTHOR_DIR to the directory of ProcTHOR house files to run"
            );
            None
        }
    }
}

/// A word table of a few kitchen, bedroom and bathroom words with meaning, and every other word
/// of the generator's names and the example scenes' (a name with no known word is refused) on
/// a fifth axis of its own, one fixed small vector per word from its letters.
pub fn word_table(dir: &Path) -> PathBuf {
    let folder = dir.join("table");
    std::fs::create_dir_all(&folder).unwrap();
    let words = [
        ("kitchen", [1.0, 0.0, 0.0, 0.1]),
        ("fridge", [0.9, 0.1, 0.0, 0.0]),
        ("counter", [0.8, 0.0, 0.1, 0.2]),
        ("cabinet", [0.6, 0.3, 0.2, 0.0]),
        ("bedroom", [0.0, 1.0, 0.0, 0.1]),
        ("bed", [0.1, 0.9, 0.0, 0.0]),
        ("dresser", [0.0, 0.8, 0.1, 0.2]),
        ("bathroom", [0.0, 0.0, 1.0, 0.1]),
        ("toilet", [0.1, 0.0, 0.9, 0.0]),
        ("sink", [0.4, 0.0, 0.7, 0.0]),
        ("living", [0.2, 0.2, 0.0, 1.0]),
        ("sofa", [0.0, 0.3, 0.0, 0.9]),
        ("table", [0.5, 0.1, 0.0, 0.6]),
    ];
    let mut lines: Vec<String> = words
        .iter()
        .map(|(w, v)| format!("{w} {} {} {} {} 0", v[0], v[1], v[2], v[3]))
        .collect();
    let mut others = std::collections::BTreeSet::new();
    for scene in ferret_world::generate::default_scenes(200, 0).unwrap() {
        for name in ferret_plan::learned::scene_names(&scene) {
            others.extend(ferret_embed::split_name(&name));
        }
    }
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    for scene in ["apartment", "workshop"] {
        let text = std::fs::read_to_string(examples.join(scene).join("scene.yaml")).unwrap();
        for line in text.lines() {
            if let Some((_, name)) = line.split_once("type: ") {
                let name = name.split([',', '}', ' ']).next().unwrap_or("");
                others.extend(ferret_embed::split_name(name));
            }
        }
    }
    others.extend(
        [
            "blanket", "cell", "phone", "remote", "control", "pillow", "wallet",
        ]
        .map(String::from),
    );
    for w in others {
        if words.iter().any(|(known, _)| *known == w) {
            continue;
        }
        let h = w
            .bytes()
            .fold(7u32, |h, b| h.wrapping_mul(31).wrapping_add(u32::from(b)));
        let small = |k: u32| f64::from((h >> k) % 100) / 1000.0;
        lines.push(format!(
            "{w} {} {} {} {} 1",
            small(0),
            small(8),
            small(16),
            small(24)
        ));
    }
    std::fs::write(
        folder.join("vectors.txt"),
        format!("# id: tiny\n{}\n", lines.join("\n")),
    )
    .unwrap();
    folder
}

/// A `ferret serve` started by a test: its process and the address it printed; killed when
/// dropped.
pub struct Server {
    pub child: Child,
    pub url: String,
}

impl Server {
    /// `ferret serve` with `args` (after `serve`; give `--listen 127.0.0.1:0`) and `env` set,
    /// without a token from the environment; returns once it printed its address.
    pub fn spawn(args: &[&str], env: &[(&str, &Path)]) -> Server {
        use std::io::BufRead;
        let mut child = Command::new(env!("CARGO_BIN_EXE_ferret"))
            .arg("serve")
            .args(args)
            .envs(env.iter().map(|(k, v)| (*k, *v)))
            .env_remove("FERRET_SERVE_TOKEN")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("ferret serve starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let mut line = String::new();
        std::io::BufReader::new(stdout)
            .read_line(&mut line)
            .expect("the server prints its address");
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://"))
            .unwrap_or_else(|| panic!("no address in {line:?}"))
            .to_string();
        Server { child, url }
    }

    /// Stops the server now.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
