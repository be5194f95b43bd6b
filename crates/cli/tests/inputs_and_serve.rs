//! The command line's last input holes and `ferret serve`'s start-up and limits, end to end:
//! inputs that are not regular files, options refused before files are touched, temporary files
//! of killed runs, outputs of two runs mixed, keys and escape sequences kept off the terminal,
//! and the server's memory, start-up and connections. Servers listen on 127.0.0.1 only.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{ferret, s, stderr, text};
use serde_json::{Value, json};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn apartment() -> PathBuf {
    repo().join("examples/apartment/scene.yaml")
}

/// Runs `ferret` with `args`, giving up (and failing the test) after `limit`.
fn ferret_within(args: &[&str], limit: Duration) -> (std::process::Output, Duration) {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ferret"))
        .args(args)
        .env_remove("FERRET_SERVE_TOKEN")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    loop {
        if child.try_wait().unwrap().is_some() {
            return (child.wait_with_output().unwrap(), started.elapsed());
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let o = child.wait_with_output().unwrap();
            panic!(
                "ferret {args:?} still running after {limit:?}: {}",
                text(&o)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// `ln -s /dev/zero z.json; ferret houses check --houses z.json` grew to 23.6 GB; a FIFO named
/// `.json` hung. Every command refuses both at once, naming the file.
#[cfg(unix)]
#[test]
fn devices_and_fifos_are_refused_by_every_command_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let zero_json = dir.path().join("z.json");
    let zero_yaml = dir.path().join("z.yaml");
    std::os::unix::fs::symlink("/dev/zero", &zero_json).unwrap();
    std::os::unix::fs::symlink("/dev/zero", &zero_yaml).unwrap();
    let fifo = dir.path().join("f.json");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let db = dir.path().join("db.sqlite");
    let cases: Vec<(Vec<&str>, &Path)> = vec![
        (
            vec!["houses", "check", "--houses", s(&zero_json)],
            &zero_json,
        ),
        (vec!["houses", "check", "--houses", s(&fifo)], &fifo),
        (vec!["scene", "check", s(&zero_yaml)], &zero_yaml),
        (
            vec![
                "serve",
                "--scene",
                s(&zero_yaml),
                "--listen",
                "127.0.0.1:0",
                "--db",
                s(&db),
            ],
            &zero_yaml,
        ),
        (
            vec![
                "eval",
                "--generate",
                "2",
                "--prior",
                s(&zero_json),
                "--out",
                s(dir.path()),
            ],
            &zero_json,
        ),
    ];
    for (args, file) in cases {
        let (o, took) = ferret_within(&args, Duration::from_secs(20));
        assert!(!o.status.success(), "{args:?}");
        let e = stderr(&o);
        assert!(e.contains(s(file)), "{args:?}: {e}");
        assert!(e.contains("not a regular file"), "{args:?}: {e}");
        assert!(took < Duration::from_secs(10), "{args:?} took {took:?}");
    }
    assert!(!db.exists(), "serve created its database before failing");
}

/// serve created `--db` before it rejected a bad option or an empty token.
#[test]
fn serve_refuses_bad_options_and_an_empty_token_before_creating_its_database() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("never.sqlite");
    let scene = apartment();
    let base = [
        "serve",
        "--scene",
        s(&scene),
        "--listen",
        "127.0.0.1:0",
        "--db",
        s(&db),
    ];
    for extra in [
        &["--resolution", "-1"][..],
        &["--max-scenes", "0"],
        &["--max-scene-cells", "99999999999"],
        &["--header-timeout", "0"],
        &["--cors-origin", "http://a\u{7f}b"],
        &["--allow-host", "a b"],
        &["--strategies", "model/nothing"],
    ] {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        let (o, _) = ferret_within(&args, Duration::from_secs(60));
        assert!(!o.status.success(), "{extra:?} was accepted");
        assert!(
            !db.exists(),
            "{extra:?}: the database was created: {}",
            text(&o)
        );
    }
    let o = Command::new(env!("CARGO_BIN_EXE_ferret"))
        .args(base)
        .env("FERRET_SERVE_TOKEN", "")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("FERRET_SERVE_TOKEN is set but empty"),
        "{}",
        text(&o)
    );
    assert!(!db.exists());
}

/// A loopback port that accepts connections and never answers, until dropped.
struct Silent {
    url: String,
    _stop: std::sync::mpsc::Sender<()>,
}

fn silent() -> Silent {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}/v1", listener.local_addr().unwrap());
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    listener.set_nonblocking(true).unwrap();
    std::thread::spawn(move || {
        let mut held = Vec::new();
        while rx.try_recv() == Err(std::sync::mpsc::TryRecvError::Empty) {
            if let Ok((s, _)) = listener.accept() {
                held.push(s);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    });
    Silent { url, _stop: tx }
}

/// An endpoint that accepts connections and never answers held `llm ping` for 120 s × 5
/// attempts; ping makes one attempt.
#[test]
fn llm_ping_gives_up_on_a_silent_endpoint_after_one_timeout() {
    let server = silent();
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        format!(
            "[llm.hang]\nbase_url = \"{}\"\nmodel = \"m\"\ntimeout_secs = 2\n",
            server.url
        ),
    )
    .unwrap();
    let (o, took) = ferret_within(
        &["llm", "ping", "hang", "--config", s(&config)],
        Duration::from_secs(30),
    );
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("did not answer within 2 s, 1 attempt"),
        "{}",
        text(&o)
    );
    assert!(took < Duration::from_secs(8), "{took:?}");
}

/// A key pasted into `api_key_env` was listed by `ferret llm list` as a variable name.
#[test]
fn a_key_pasted_into_api_key_env_is_never_printed() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    let key = "sk-proj-Zq81ExampleKeyNotReal0042";
    std::fs::write(
        &config,
        format!("[llm.x]\nbase_url = \"http://127.0.0.1:9/v1\"\nmodel = \"m\"\napi_key_env = \"{key}\"\n"),
    )
    .unwrap();
    for args in [
        vec!["llm", "list", "--config", s(&config)],
        vec!["llm", "ping", "x", "--config", s(&config)],
    ] {
        let o = ferret(&args);
        assert!(!o.status.success(), "{args:?}");
        let out = text(&o);
        assert!(!out.contains(key) && !out.contains("Zq81Example"), "{out}");
        assert!(out.contains("api_key_env"), "{out}");
    }
}

/// `reply began: ^[[2J…`: what a server sent reached the terminal raw.
#[test]
fn llm_ping_escapes_control_characters_of_the_reply() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let server = rt.block_on(wiremock::MockServer::start());
    rt.block_on(
        wiremock::Mock::given(wiremock::matchers::method("POST"))
            .respond_with(wiremock::ResponseTemplate::new(200).set_body_json(json!({
                "id": "x", "object": "chat.completion", "created": 1, "model": "m",
                "choices": [{"index": 0, "message": {"role": "assistant", "content": "\u{1b}[2J\u{1b}]0;owned\u{7}pong"}, "finish_reason": "stop"}],
                "usage": {"prompt_tokens": 1, "completion_tokens": 1, "total_tokens": 2}
            })))
            .mount(&server),
    );
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        format!(
            "[llm.m]\nbase_url = \"{}/v1\"\nmodel = \"m\"\n",
            server.uri()
        ),
    )
    .unwrap();
    let o = ferret(&["llm", "ping", "m", "--config", s(&config)]);
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(!out.contains('\u{1b}') && !out.contains('\u{7}'), "{out:?}");
    assert!(out.contains("\\u{1b}[2J"), "{out}");
}

const STRATEGIES: &str = "optimistic+greedy,model/uniform,oracle";

fn eval(out: &Path, seed: &str) -> std::process::Output {
    ferret(&[
        "eval",
        "--generate",
        "6",
        "--strategies",
        STRATEGIES,
        "--seed",
        seed,
        "--out",
        s(out),
    ])
}

/// A process id no process has (above the kernel's limit).
fn dead_pid() -> u64 {
    std::fs::read_to_string("/proc/sys/kernel/pid_max")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok())
        .unwrap_or(4_194_304)
        + 1
}

/// A killed eval left `.summary.md.XXXX.md` files for good, and could leave a new trials.csv
/// beside the old run.json, which select then refused with a confusing message.
#[test]
fn a_killed_evals_leftovers_are_cleaned_and_mixed_runs_named() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    assert!(eval(&out, "0").status.success());
    let stale = [
        out.join(format!(".summary.md.{}.Xa1b2c.md", dead_pid())),
        out.join(format!(".trials.csv.{}.Yd3e4f.csv", dead_pid())),
    ];
    for p in &stale {
        std::fs::write(p, "half a file").unwrap();
    }
    assert!(eval(&out, "1").status.success());
    for p in &stale {
        assert!(!p.exists(), "{} is left", p.display());
    }
    // As a kill between the two files would leave them: another run's trials.csv.
    let other = dir.path().join("other");
    assert!(eval(&other, "2").status.success());
    std::fs::copy(other.join("trials.csv"), out.join("trials.csv")).unwrap();
    let o = ferret(&[
        "select",
        "--trials",
        s(&out),
        "--deployments",
        "5",
        "--trials-per-deployment",
        "3",
        "--out",
        s(&dir.path().join("sel")),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("trials.csv and run.json are from different runs"),
        "{}",
        text(&o)
    );
}

/// A running `ferret serve`; killed when dropped.
struct Server {
    child: Child,
    url: String,
    addr: std::net::SocketAddr,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `ferret serve` on the apartment, started through `sh` so that `ulimit` applies.
fn serve(db: &Path, extra: &str, ulimit: Option<u32>) -> Server {
    let exe = env!("CARGO_BIN_EXE_ferret");
    let limit = ulimit.map_or(String::new(), |n| format!("ulimit -n {n}; "));
    let script = format!(
        "{limit}exec '{exe}' serve --scene '{}' --strategies optimistic+greedy,model/uniform --listen 127.0.0.1:0 --db '{}' {extra}",
        apartment().display(),
        db.display()
    );
    let mut child = Command::new("sh")
        .args(["-c", &script])
        .env_remove("FERRET_SERVE_TOKEN")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("http://"))
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();
    let addr = url.trim_start_matches("http://").parse().unwrap();
    Server { child, url, addr }
}

fn http(
    addr: std::net::SocketAddr,
    method: &str,
    path: &str,
    body: Option<&Value>,
) -> (u16, Value) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let body = body.map(Value::to_string).unwrap_or_default();
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let text = String::from_utf8_lossy(&out);
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let json = text
        .split_once("\r\n\r\n")
        .and_then(|(_, b)| serde_json::from_str(b).ok())
        .unwrap_or(Value::Null);
    (status, json)
}

fn rss_mib(pid: u32) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse::<f64>().ok())
        .unwrap()
        / 1024.0
}

fn square(name: &str, side: f64) -> Value {
    json!({
        "ferret_scene": 1, "name": name,
        "rooms": [{"name": "hall", "type": "LivingRoom", "polygon": [[0,0],[side,0],[side,side],[0,side]]}],
        "containers": [
            {"id": "a", "type": "Dresser", "pose": [side / 2.0, side / 2.0, 0]},
            {"id": "b", "type": "Bed", "pose": [1.0, 1.0, 0]}
        ],
        "start": [side / 3.0, side / 3.0, 0]
    })
}

/// Every uploaded scene's grid stayed in memory (10 uploads: 1.0 → 1.3 GB), and start-up
/// rebuilt them all.
#[cfg(target_os = "linux")]
#[test]
fn serve_memory_is_bounded_by_its_grid_cache_and_start_up_loads_no_scene() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("s.sqlite");
    let server = serve(&db, "--grid-cache-mib 16", None);
    let before = rss_mib(server.child.id());
    // 60 m × 60 m: 1.45 M cells, about 3 MB of grid each; 24 of them, 70 MB if all were kept.
    for i in 0..24 {
        let (st, reply) = http(
            server.addr,
            "POST",
            "/scenes",
            Some(&json!({"scene": square(&format!("sq{i}"), 60.0)})),
        );
        assert_eq!(st, 201, "{reply}");
    }
    let grown = rss_mib(server.child.id()) - before;
    assert!(grown < 48.0, "resident memory grew by {grown:.0} MiB");
    drop(server);
    let started = Instant::now();
    let server = serve(&db, "--grid-cache-mib 16", None);
    assert!(started.elapsed() < Duration::from_secs(10));
    let (st, list) = http(server.addr, "GET", "/scenes", None);
    assert_eq!(st, 200);
    assert_eq!(list.as_array().unwrap().len(), 25, "{list}");
    assert!(
        rss_mib(server.child.id()) < before + 16.0,
        "no uploaded scene is loaded at start"
    );
    let (st, _) = http(server.addr, "GET", "/scenes/sq3", None);
    assert_eq!(st, 200);
    assert!(server.url.starts_with("http://127.0.0.1:"));
}

/// 1 100 idle connections under `ulimit -n 1024` made a normal `GET /scenes` time out: the
/// server could not accept and never closed idle connections.
#[cfg(unix)]
#[test]
fn idle_connections_past_the_open_file_limit_cannot_lock_a_client_out() {
    let dir = tempfile::tempdir().unwrap();
    let server = serve(&dir.path().join("s.sqlite"), "", Some(128));
    let idle: Vec<_> = (0..300)
        .map(|_| std::net::TcpStream::connect(server.addr).unwrap())
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let mut times = Vec::new();
    for _ in 0..20 {
        let started = Instant::now();
        let (st, _) = http(server.addr, "GET", "/scenes", None);
        assert_eq!(st, 200);
        times.push(started.elapsed());
    }
    times.sort();
    assert!(times[19] < Duration::from_secs(1), "{times:?}");
    drop(idle);
}
