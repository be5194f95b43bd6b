//! The live view's server side on a real socket: the embedded page and its guards, the event
//! stream a page reads (in order, within a second of each write, capped), the trial picture
//! (`/trials/{id}/view`), the list of deployments, and a view-only server.

mod support;

use std::time::Duration;

use ferret_serve::{ServeOptions, ServiceOptions};
use serde_json::{Value, json};
use support::events::Stream;
use support::server::{Server, start, start_http};

const SECOND: Duration = Duration::from_secs(1);

async fn send(s: &Server, token: &str, path: &str, body: Value) -> (u16, Value) {
    let r = s
        .client
        .post(format!("{}{path}", s.url))
        .bearer_auth(token)
        .json(&body)
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json().await.unwrap())
}

async fn read(s: &Server, token: &str, path: &str) -> (u16, Value) {
    let r = s
        .client
        .get(format!("{}{path}", s.url))
        .bearer_auth(token)
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json().await.unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_is_served_without_the_token_under_a_policy_that_allows_only_its_own_files() {
    let s = start(None, Some("s3cret")).await;
    let page = s.client.get(format!("{}/", s.url)).send().await.unwrap();
    assert_eq!(page.status(), 200);
    let csp = page.headers()["content-security-policy"]
        .to_str()
        .unwrap()
        .to_string();
    for rule in [
        "default-src 'none'",
        "script-src 'self'",
        "style-src 'self'",
        "connect-src 'self'",
        "frame-ancestors 'none'",
    ] {
        assert!(csp.contains(rule), "{rule} missing from {csp}");
    }
    assert!(!csp.contains("unsafe-inline") && !csp.contains("unsafe-eval"));
    let html = page.text().await.unwrap();
    // Every script is a file of its own (the policy would block an inline one), and nothing
    // comes from elsewhere.
    let scripts: Vec<&str> = html.split("<script").skip(1).collect();
    assert!(!scripts.is_empty(), "the page has its script");
    for s in &scripts {
        let tag = &s[..s.find('>').unwrap()];
        assert!(
            tag.contains("src=\"/ui/"),
            "an inline script: <script{tag}>"
        );
        let body = &s[s.find('>').unwrap() + 1..];
        assert!(
            body.trim_start().starts_with("</script>"),
            "a script with a body"
        );
    }
    assert!(
        !html.contains("style=") && !html.contains("<style"),
        "inline style"
    );
    // Whatever the page loads is one of its own files (an XML namespace is a name, not a load).
    for attr in ["src=\"", "href=\""] {
        for rest in html.split(attr).skip(1) {
            let url = &rest[..rest.find('"').unwrap()];
            assert!(
                url.starts_with("/ui/") || url.starts_with('#'),
                "loads {url}"
            );
        }
    }
    for (path, kind) in [
        ("/ui/app.js", "text/javascript"),
        ("/ui/app.css", "text/css"),
    ] {
        let r = s
            .client
            .get(format!("{}{path}", s.url))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200, "{path}");
        assert!(
            r.headers()["content-type"]
                .to_str()
                .unwrap()
                .starts_with(kind),
            "{path}"
        );
        assert_eq!(r.headers()["x-content-type-options"], "nosniff");
        assert!(
            !r.text().await.unwrap().trim().is_empty(),
            "{path} is empty"
        );
    }
    let js = s
        .client
        .get(format!("{}/ui/app.js", s.url))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(!js.contains("eval(") && !js.contains("new Function"));
    // The data is not: every API route and the event stream want the token.
    for path in ["/events", "/deployments", "/scenes", "/trials/1/view"] {
        let r = s
            .client
            .get(format!("{}{path}", s.url))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 401, "{path} without the token");
        let r = s
            .client
            .get(format!("{}{path}", s.url))
            .bearer_auth("wrong")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 401, "{path} with a wrong token");
    }
    // The page's own origin may call (a browser sends it on a page's POST); another may not.
    let own = s.url.clone();
    let r = s
        .client
        .get(format!("{}/scenes", s.url))
        .bearer_auth("s3cret")
        .header("origin", own)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "the page's own origin");
    let r = s
        .client
        .get(format!("{}/scenes", s.url))
        .bearer_auth("s3cret")
        .header("origin", "http://evil.example")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 403, "another origin");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_sees_every_step_of_a_trial_within_a_second_and_in_order() {
    let token = "t0ken";
    let s = start(None, Some(token)).await;
    let (status, _) = Stream::open(&s, None).await;
    assert_eq!(status, 401, "no stream without the token");
    let mut events = Stream::open(&s, Some(token)).await.1.unwrap();
    let (name, hello) = events.next(SECOND).await;
    assert_eq!(name, "hello");
    assert_eq!(hello["shared"], support::on_postgres());

    let (_, deployment) = send(&s, token, "/deployments", json!({})).await;
    let id = deployment["id"].as_i64().unwrap();
    assert_eq!(
        events.next(SECOND).await,
        ("deployment".into(), json!({ "deployment": id }))
    );
    let scene = read(&s, token, "/scenes/flat").await.1;
    let (status, mut trial) = send(
        &s,
        token,
        &format!("/deployments/{id}/trials"),
        json!({"scene": "flat", "target": "Wallet"}),
    )
    .await;
    assert_eq!(status, 201);
    let tid = trial["trial"].as_i64().unwrap();
    let first = read(&s, token, &format!("/trials/{tid}/view")).await.1;
    // What a page showing the trial draws from its first picture and the events after it.
    let mut route: Vec<Value> = first["route"].as_array().unwrap().clone();
    let mut likelihoods = first["likelihoods"].clone();
    let mut searched = 0;
    let mut observed = Value::Null;
    let mut leg = Value::Null;
    loop {
        let (name, e) = events.next(SECOND).await;
        assert_eq!(name, "trial");
        assert_eq!(e["trial"], tid);
        assert_eq!(e["deployment"], id);
        assert_eq!(e["status"], trial["status"]);
        assert_eq!(e["searched"], searched);
        assert_eq!(e["next"], trial["next"]["container"]);
        assert_eq!(e["next_path"], trial["next"]["path"]);
        assert_eq!(e["strategy"], trial["strategy"]);
        assert_eq!(e["cost_m"], trial["cost_m"]);
        assert_eq!(e["observed"], observed, "the observation it reports");
        if let Some(o) = e["observed"].as_object() {
            let c = o["container"].as_str().unwrap();
            route.extend(leg.as_array().unwrap().iter().skip(1).cloned());
            likelihoods[c] = json!(if o["found"] == true { 1.0 } else { 0.0 });
        }
        leg = e["next_path"].clone();
        if trial["status"] != "searching" {
            break;
        }
        let c = trial["next"]["container"].as_str().unwrap().to_string();
        let held = scene["containers"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["id"] == c.as_str())
            .unwrap()["contents"]
            .clone();
        let found = held.as_array().unwrap().iter().any(|t| t == "Wallet");
        observed = json!({"container": c, "found": found, "objects": held});
        let (status, next) = send(
            &s,
            token,
            &format!("/trials/{tid}/observations"),
            observed.clone(),
        )
        .await;
        assert_eq!(status, 200, "{next}");
        trial = next;
        searched += 1;
    }
    assert_eq!(trial["status"], "done");
    // The events were enough: the picture drawn from them is the server's.
    let last = read(&s, token, &format!("/trials/{tid}/view")).await.1;
    assert_eq!(Value::Array(route), last["route"]);
    assert_eq!(likelihoods, last["likelihoods"]);
    // The list of deployments says it too.
    let (status, list) = read(&s, token, "/deployments").await;
    assert_eq!(status, 200);
    assert_eq!(
        list,
        json!([{"id": id, "selector": "replay", "sequential": false,
        "strategies": ["optimistic+greedy", "model/uniform", "model/uniform/k2"],
        "trials": 1, "open_trials": []}])
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trial_view_shows_its_way_what_it_saw_and_the_likelihoods_now() {
    let s = start(None, None).await;
    let scene = s.get("/scenes/flat").await.1;
    let access = |id: &str| -> [f64; 2] {
        let c = scene["containers"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["id"] == id)
            .unwrap();
        [
            c["access"][0].as_f64().unwrap(),
            c["access"][1].as_f64().unwrap(),
        ]
    };
    // A strategy with a likelihood (uniform: 0.1 everywhere before any search).
    let d = s
        .post("/deployments", json!({"strategies": ["model/uniform"]}))
        .await
        .1;
    let id = d["id"].as_i64().unwrap();
    let (_, trial) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet", "pose": [5.0, 2.0, 0.0]}),
        )
        .await;
    let tid = trial["trial"].as_i64().unwrap();
    let (status, view) = s.get(&format!("/trials/{tid}/view")).await;
    assert_eq!(status, 200);
    assert_eq!(view["trial"], s.get(&format!("/trials/{tid}")).await.1);
    assert_eq!(view["start"], json!([5.0, 2.0, 0.0]));
    assert_eq!(view["route"], json!([[5.0, 2.0]]), "nothing travelled yet");
    let ps = view["likelihoods"].as_object().unwrap();
    assert_eq!(ps.len(), 7, "every container");
    assert!(ps.values().all(|p| p.as_f64() == Some(0.1)), "{ps:?}");

    // Two searches without the wallet, then where it is.
    let mut searched = Vec::new();
    let mut trial = trial;
    while trial["status"] == "searching" {
        let c = trial["next"]["container"].as_str().unwrap().to_string();
        let found = c == "dresser";
        let objects = if c == "fridge" {
            json!(["Egg"])
        } else {
            json!([])
        };
        trial = s
            .post(
                &format!("/trials/{tid}/observations"),
                json!({"container": c, "found": found, "objects": objects}),
            )
            .await
            .1;
        searched.push((c.clone(), found));
        let view = s.get(&format!("/trials/{tid}/view")).await.1;
        // The state the write answered, as planning it again from the rows gives it.
        assert_eq!(view["trial"], trial);
        assert_eq!(view["trial"], s.get(&format!("/trials/{tid}")).await.1);
        let ps = view["likelihoods"].as_object().unwrap();
        for (id, p) in ps {
            let expected = match searched.iter().find(|(s, _)| s == id) {
                Some((_, true)) => 1.0,
                Some((_, false)) => 0.0,
                None => 0.1,
            };
            assert_eq!(p.as_f64(), Some(expected), "{id} after {searched:?}");
        }
        // The way so far runs from the start to the last container searched, through each.
        let route: Vec<[f64; 2]> = serde_json::from_value(view["route"].clone()).unwrap();
        assert_eq!(route[0], [5.0, 2.0]);
        assert_eq!(*route.last().unwrap(), access(&c), "ends at {c}");
        for (s, _) in &searched {
            assert!(route.contains(&access(s)), "passes {s}");
        }
        let length: f64 = route
            .windows(2)
            .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
            .sum();
        let cost = view["trial"]["cost_m"].as_f64().unwrap();
        // The map distance is the grid's; the drawn way's first step goes from the pose to its
        // cell's centre (at most half a cell's diagonal).
        assert!(
            (length - cost).abs() < 0.1,
            "drawn {length} m, cost {cost} m"
        );
        let seen: Vec<String> = view["observations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| o["container"].as_str().unwrap().to_string())
            .collect();
        assert_eq!(
            seen,
            searched.iter().map(|(c, _)| c.clone()).collect::<Vec<_>>()
        );
        if c == "fridge" {
            assert_eq!(
                view["observations"].as_array().unwrap().last().unwrap()["objects"],
                json!(["Egg"])
            );
        }
    }
    assert_eq!(trial["status"], "done");
    assert!(searched.len() >= 2, "the wallet was not the first guess");

    // A strategy without a likelihood has none to show.
    let d = s
        .post("/deployments", json!({"strategies": ["optimistic+greedy"]}))
        .await
        .1;
    let (_, t) = s
        .post(
            &format!("/deployments/{}/trials", d["id"]),
            json!({"scene": "flat", "target": "Wallet"}),
        )
        .await;
    let view = s.get(&format!("/trials/{}/view", t["trial"])).await.1;
    assert_eq!(view["likelihoods"], Value::Null);
    // Abandoned after its start: the picture says so, not the state its start answered.
    let (status, abandoned) = s
        .post(&format!("/trials/{}/abandon", t["trial"]), json!({}))
        .await;
    assert_eq!(status, 200);
    let view = s.get(&format!("/trials/{}/view", t["trial"])).await.1;
    assert_eq!(view["trial"], abandoned);
    assert_eq!(view["trial"]["status"], "abandoned");
    assert_eq!(s.get("/trials/999/view").await.0, 404);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_view_only_server_serves_the_page_and_reads_and_refuses_every_write() {
    let s = start_http(
        None,
        ServiceOptions::default(),
        ServeOptions::default(),
        |o| o.view_only = true,
    )
    .await;
    let page = s.client.get(format!("{}/", s.url)).send().await.unwrap();
    assert_eq!(page.status(), 200);
    assert_eq!(s.get("/deployments").await, (200, json!([])));
    assert_eq!(s.get("/scenes").await.0, 200);
    for path in [
        "/deployments",
        "/scenes",
        "/deployments/1/trials",
        "/trials/1/observations",
        "/trials/1/abandon",
    ] {
        let (status, body) = s.post(path, json!({})).await;
        assert_eq!(status, 403, "{path}");
        assert!(
            body["error"]["message"]
                .as_str()
                .unwrap()
                .contains("view-only"),
            "{body}"
        );
    }
    assert_eq!(
        s.get("/deployments").await,
        (200, json!([])),
        "nothing was written"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn event_streams_past_their_cap_are_refused_and_the_api_still_answers() {
    const CAP: usize = 8;
    let s = start_http(
        None,
        ServiceOptions {
            max_event_streams: CAP,
            ..ServiceOptions::default()
        },
        ServeOptions {
            max_connections: 64,
            ..ServeOptions::default()
        },
        |_| {},
    )
    .await;
    // 200 clients, each on a connection of its own, ask for a stream at once.
    let clients: Vec<reqwest::Client> = (0..200).map(|_| reqwest::Client::new()).collect();
    let opened = futures_util::future::join_all(clients.iter().map(|c| {
        let url = format!("{}/events", s.url);
        async move { c.get(url).send().await }
    }))
    .await;
    let mut held = Vec::new();
    let (mut refused, mut dropped) = (0, 0);
    for r in opened {
        match r {
            Ok(r) if r.status() == 200 => held.push(r),
            Ok(r) => {
                assert_eq!(r.status(), 503);
                assert_eq!(r.headers()["retry-after"], "1");
                refused += 1;
            }
            // Past --max-connections with every connection busy, the server closes new ones.
            Err(_) => dropped += 1,
        }
    }
    assert_eq!(held.len(), CAP, "{refused} refused, {dropped} dropped");
    assert_eq!(s.service.events().open_streams(), CAP);
    // The streams hold their connections; the API still has room.
    assert_eq!(s.get("/health").await.0, 200);
    assert_eq!(s.get("/deployments").await.0, 200);
    // A closed stream gives its place back.
    held.pop();
    let mut freed = false;
    for _ in 0..100 {
        if s.service.events().open_streams() < CAP {
            freed = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(freed, "a closed stream keeps its slot");
    let again = s
        .client
        .get(format!("{}/events", s.url))
        .send()
        .await
        .unwrap();
    assert_eq!(again.status(), 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_of_one_deployment_carries_its_trials_and_new_deployments_only() {
    let s = start(None, None).await;
    let a = s.post("/deployments", json!({})).await.1["id"]
        .as_i64()
        .unwrap();
    let b = s.post("/deployments", json!({})).await.1["id"]
        .as_i64()
        .unwrap();
    for bad in [
        "deployment=x",
        "deployment=0",
        "deployment=+1",
        "deployment=",
        "trial=1",
    ] {
        let r = s
            .client
            .get(format!("{}/events?{bad}", s.url))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 400, "{bad}");
    }
    let (status, stream) = Stream::open(&s, None).await;
    assert_eq!(status, 200);
    let mut all = stream.unwrap();
    let r = s
        .client
        .get(format!("{}/events?deployment={b}", s.url))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let mut only_b = Stream::from_response(r);
    for stream in [&mut all, &mut only_b] {
        assert_eq!(stream.next(SECOND).await.0, "hello");
    }
    for d in [a, b, a] {
        let (status, _) = s
            .post(
                &format!("/deployments/{d}/trials"),
                json!({"scene": "flat", "target": "Wallet"}),
            )
            .await;
        assert_eq!(status, 201);
    }
    let c = s.post("/deployments", json!({})).await.1["id"]
        .as_i64()
        .unwrap();
    let mut seen = Vec::new();
    while seen.len() < 4 {
        let (name, e) = all.next(SECOND).await;
        let d = e["deployment"].as_i64().unwrap();
        // Between replicas, what happened a moment before a page came reaches it too.
        if name == "deployment" && (d == a || d == b) {
            continue;
        }
        seen.push((name, d));
    }
    assert_eq!(
        seen,
        [
            ("trial".into(), a),
            ("trial".into(), b),
            ("trial".into(), a),
            ("deployment".into(), c)
        ]
    );
    let mut first = only_b.next(SECOND).await;
    while first.0 == "deployment" && [a, b].contains(&first.1["deployment"].as_i64().unwrap()) {
        first = only_b.next(SECOND).await;
    }
    assert_eq!(
        (first.0.as_str(), &first.1["deployment"]),
        ("trial", &json!(b))
    );
    assert_eq!(
        only_b.next(SECOND).await,
        ("deployment".into(), json!({ "deployment": c }))
    );
}

/// An event stream counted as idle once its headers were sent: it was closed at the idle timeout
/// plus the header timeout however many events it carried, and it was the first connection
/// closed when plain connects reached the cap.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_event_stream_outlives_the_idle_timeout_and_is_never_the_one_evicted_at_the_cap() {
    const CAP: usize = 8;
    let s = start_http(
        None,
        ServiceOptions::default(),
        ServeOptions {
            header_timeout: Duration::from_millis(300),
            idle_timeout: Duration::from_millis(400),
            max_connections: CAP,
            ..ServeOptions::default()
        },
        |_| {},
    )
    .await;
    let (status, stream) = Stream::open(&s, None).await;
    assert_eq!(status, 200);
    let mut stream = stream.unwrap();
    assert_eq!(stream.next(SECOND).await.0, "hello");
    // A fresh connection per write, so that no pooled connection is the one evicted mid-request.
    let writer = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .build()
        .unwrap();
    let create = || async {
        let r = writer
            .post(format!("{}/deployments", s.url))
            .json(&json!({}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 201);
        r.json::<Value>().await.unwrap()["id"].as_i64().unwrap()
    };
    // Ten times the idle timeout and the header timeout together: events, then quiet, then
    // events again.
    let mut expected = Vec::new();
    let started = std::time::Instant::now();
    while started.elapsed() < Duration::from_secs(7) {
        if started.elapsed() < Duration::from_secs(3) || started.elapsed() > Duration::from_secs(5)
        {
            expected.push(create().await);
        }
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
    // Three times the cap in plain connects that never send a request.
    let flood: Vec<_> = (0..3 * CAP)
        .map(|_| std::net::TcpStream::connect(s.url.trim_start_matches("http://")).unwrap())
        .collect();
    tokio::time::sleep(Duration::from_millis(100)).await;
    expected.push(create().await);
    let mut got = Vec::new();
    while got.len() < expected.len() {
        let (name, data) = stream.next(SECOND).await;
        if name == "deployment" {
            got.push(data["deployment"].as_i64().unwrap());
        } else {
            assert_eq!(name, "keep-alive", "{name}: {data}");
        }
    }
    assert_eq!(got, expected, "every event, on one stream");
    drop(flood);
}

/// A second server on the robots' SQLite file (`--view-only`, say) showed "live" and never
/// heard of the first one's writes: its pages are now told to read again within a second of
/// another process's commit, and never for their own server's writes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_hears_within_a_second_of_another_process_writing_the_sqlite_file() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("robots.sqlite");
    let viewer = start(Some(&db), None).await;
    let (status, stream) = Stream::open(&viewer, None).await;
    assert_eq!(status, 200);
    let mut page = stream.unwrap();
    assert_eq!(page.next(SECOND).await.0, "hello");
    // The server's own write is an event, not a resync.
    for _ in 0..2 {
        let (st, _) = viewer.post("/deployments", json!({})).await;
        assert_eq!(st, 201);
        assert_eq!(
            page.next(SECOND).await.0,
            "deployment",
            "no resync before it"
        );
        tokio::time::sleep(Duration::from_millis(600)).await;
    }
    // Another process's write: here another store on the same file, as a second server has.
    let other = db.clone();
    tokio::task::spawn_blocking(move || {
        let service = ferret_serve::Service::new(
            ferret_serve::Store::open(&other).unwrap(),
            ferret_world::GridParams::default(),
            support::strategies(),
        )
        .unwrap();
        service
            .create_deployment(serde_json::from_str("{}").unwrap(), b"{}")
            .unwrap();
    })
    .await
    .unwrap();
    let written = std::time::Instant::now();
    let (name, data) = page.next(SECOND).await;
    assert_eq!(
        (name.as_str(), &data),
        ("resync", &json!({"missed": null})),
        "the first event after the other's write"
    );
    assert!(written.elapsed() < SECOND);
    let (_, list) = viewer.get("/deployments").await;
    assert_eq!(list.as_array().unwrap().len(), 3, "{list}");
}
