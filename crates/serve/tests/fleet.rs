//! A fleet: two replicas of the service on one PostgreSQL database, robots sharing one
//! deployment, each request sent to either replica. Needs a PostgreSQL server
//! (`FERRET_TEST_POSTGRES`; `scripts/postgres.sh start` starts a throwaway one); skipped with a
//! message without it.

mod support;

use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;

use ferret_serve::Service;
use ferret_world::GridParams;
use serde_json::{Value, json};
use support::events::Stream;
use support::{TARGETS, strategies};

const SECOND: std::time::Duration = std::time::Duration::from_secs(1);

/// What contents each container of the scene holds, for answering the robot's searches.
fn contents(container: &str) -> Vec<&'static str> {
    match container {
        "fridge" => vec!["Egg", "Apple"],
        "counter" => vec!["Mug", "CellPhone"],
        "sofa" => vec!["Pillow", "RemoteControl"],
        "table" => vec!["Book", "RemoteControl"],
        "bed" => vec!["Pillow", "CellPhone"],
        "dresser" => vec!["Wallet"],
        _ => vec![],
    }
}

async fn get(client: &reqwest::Client, url: &str) -> Value {
    client.get(url).send().await.unwrap().json().await.unwrap()
}

/// A robot's view of what happened: its trials and the observations acknowledged in each.
type Acked = Vec<(i64, Vec<String>)>;

/// Trial starts answered 409 (a refusal the robot must retry).
static REFUSED_STARTS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// POSTs with a request id to a replica chosen by `pick`, again (same id) until one
/// acknowledges; any refusal but 409 (the same request in flight) fails the test. A 409 to a
/// trial's start is counted in [`REFUSED_STARTS`].
async fn post(
    client: &reqwest::Client,
    urls: &[String],
    pick: &mut impl FnMut() -> usize,
    path: &str,
    body: Value,
) -> Value {
    for _ in 0..200 {
        let url = &urls[pick() % urls.len()];
        let reply = client
            .post(format!("{url}{path}"))
            .json(&body)
            .send()
            .await
            .unwrap();
        let status = reply.status().as_u16();
        let value: Value = reply.json().await.unwrap();
        match status {
            200 | 201 => return value,
            409 => {
                if path.ends_with("/trials") {
                    REFUSED_STARTS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                }
                tokio::time::sleep(std::time::Duration::from_millis(5)).await
            }
            _ => panic!("{path} {body}: {status} {value}"),
        }
    }
    panic!("{path} {body}: never acknowledged")
}

async fn robot(urls: Arc<Vec<String>>, deployment: i64, robot: u64, trials: usize) -> Acked {
    let client = reqwest::Client::new();
    // xorshift: each request to one replica or the other, differently for each robot.
    let mut state = 0x9e37_79b9_7f4a_7c15_u64 ^ robot.wrapping_mul(0x2545_f491_4f6c_dd1d);
    let mut pick = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state as usize
    };
    let mut acked = Vec::new();
    for t in 0..trials {
        let target = TARGETS[(robot as usize + t) % TARGETS.len()];
        let mut reply = post(
            &client,
            &urls,
            &mut pick,
            &format!("/deployments/{deployment}/trials"),
            json!({"request_id": format!("r{robot}-t{t}"), "scene": "flat", "target": target}),
        )
        .await;
        let trial = reply["trial"].as_i64().unwrap();
        let mut searched = Vec::new();
        while reply["status"] == "searching" {
            let next = reply["next"]["container"].as_str().unwrap().to_string();
            let seen = contents(&next);
            let body = json!({
                "request_id": format!("r{robot}-t{t}-o{}", searched.len()),
                "container": next,
                "found": seen.contains(&target),
                "objects": seen,
            });
            reply = post(
                &client,
                &urls,
                &mut pick,
                &format!("/trials/{trial}/observations"),
                body,
            )
            .await;
            searched.push(next);
        }
        acked.push((trial, searched));
    }
    acked
}

/// Twenty robots with trials open at once in one deployment, each request to a random replica:
/// every trial is stored once with its own number, every acknowledged observation once, and
/// the deployment's history replays to the choices the robots were given. Without the
/// deployment's row lock two replicas number two trials alike (or end two as the same) and a
/// robot is refused with 500.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_replicas_share_a_deployment_without_losing_or_doubling_a_trial() {
    let Some(url) = support::postgres_or_skip("two_replicas_share_a_deployment") else {
        return;
    };
    let (a, ha) = support::server::replica(&url).await;
    let (b, hb) = support::server::replica(&url).await;
    let urls = Arc::new(vec![a.clone(), b.clone()]);
    let client = reqwest::Client::new();
    let dep = post(
        &client,
        std::slice::from_ref(&a),
        &mut || 0,
        "/deployments",
        json!({"seed": 3}),
    )
    .await;
    assert_eq!(dep["sequential"], false, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    // Twenty robots of five trials: before a start's choice was made under the deployment's
    // lock, about a third of such starts were refused (409, "changed 8 times").
    let (robots, trials) = (20u64, 5usize);
    let runs: Vec<_> = (0..robots)
        .map(|r| tokio::spawn(robot(urls.clone(), id, r, trials)))
        .collect();
    let mut acked = Vec::new();
    for r in runs {
        acked.extend(r.await.unwrap());
    }
    // Read back through the other replica than the one that created the deployment.
    let state = get(&client, &format!("{b}/deployments/{id}")).await;
    let stored = state["trials"].as_array().unwrap();
    assert_eq!(stored.len(), robots as usize * trials, "{state}");
    let ks: Vec<i64> = stored.iter().map(|t| t["k"].as_i64().unwrap()).collect();
    assert_eq!(ks, (1..=stored.len() as i64).collect::<Vec<_>>());
    let stored_ids: BTreeSet<i64> = stored
        .iter()
        .map(|t| t["trial"].as_i64().unwrap())
        .collect();
    let robot_ids: BTreeSet<i64> = acked.iter().map(|(t, _)| *t).collect();
    assert_eq!(stored_ids, robot_ids, "each started trial stored once");
    assert_eq!(state["open_trials"], json!([]));
    // No start was refused (this is the only test of this binary that starts trials), and the
    // choices replay: the GET above rebuilt the selector from the stored history and checked
    // each stored choice against it.
    assert_eq!(
        REFUSED_STARTS.load(std::sync::atomic::Ordering::SeqCst),
        0,
        "robots sharing a deployment were refused starts"
    );
    let done = stored.iter().filter(|t| t["status"] == "done").count();
    let deployed: u64 = state["per_strategy"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["deployed"].as_u64().unwrap())
        .sum();
    assert_eq!(
        deployed as usize, done,
        "the selector learned each found trial once"
    );
    for (trial, searched) in &acked {
        let t = get(&client, &format!("{a}/trials/{trial}")).await;
        let stored: Vec<String> = t["searched"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap().to_string())
            .collect();
        assert_eq!(&stored, searched, "trial {trial}: {t}");
    }
    ha.abort();
    hb.abort();
}

/// A request id in flight on one replica is a 409 on the other; once it completed, both give
/// its reply byte for byte, and the same id with another body is a 422 on either.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_request_id_is_one_request_across_replicas() {
    let Some(url) = support::postgres_or_skip("a_request_id_is_one_request_across_replicas") else {
        return;
    };
    let (a, ha) = support::server::replica(&url).await;
    let (b, hb) = support::server::replica(&url).await;
    // Hold the id from a third session, as a replica in the middle of the request would.
    let holder = tokio::task::block_in_place(|| support::connect(&url));
    let claim = tokio::task::block_in_place(|| holder.claim("dep-x").unwrap());
    assert!(claim.is_some());
    let client = reqwest::Client::new();
    let body = json!({"request_id": "dep-x", "seed": 1});
    for url in [&a, &b] {
        let r = client
            .post(format!("{url}/deployments"))
            .json(&body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 409, "{}", r.text().await.unwrap());
    }
    tokio::task::block_in_place(|| drop(claim));
    let first = client
        .post(format!("{a}/deployments"))
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(first.status().as_u16(), 201);
    let first = first.bytes().await.unwrap();
    let again = client
        .post(format!("{b}/deployments"))
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(again.status().as_u16(), 201);
    assert_eq!(again.bytes().await.unwrap(), first);
    for url in [&a, &b] {
        let r = client
            .post(format!("{url}/deployments"))
            .json(&json!({"request_id": "dep-x", "seed": 2}))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status().as_u16(), 422);
    }
    tokio::task::block_in_place(|| drop(holder));
    ha.abort();
    hb.abort();
}

/// A page on one replica sees, within a second of each reply, the deployment and every step of
/// a trial that a robot drives through the other replica; when its replica's listening session
/// is lost, the page is told to read everything again, and events flow once it is back.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_page_on_one_replica_sees_a_trial_driven_through_another() {
    let Some(url) =
        support::postgres_or_skip("a_page_on_one_replica_sees_a_trial_driven_through_another")
    else {
        return;
    };
    let (a, ha) = support::server::replica(&url).await;
    let (b, hb) = support::server::replica(&url).await;
    let client = reqwest::Client::new();
    let mut page = Stream::open_at(&client, &a, None).await.1.unwrap();
    assert_eq!(
        page.next(SECOND).await,
        ("hello".into(), json!({"shared": true}))
    );
    let robot = |path: &str, body: Value| {
        let (client, url) = (client.clone(), format!("{b}{path}"));
        async move {
            let r = client.post(url).json(&body).send().await.unwrap();
            assert!(r.status().is_success());
            r.json::<Value>().await.unwrap()
        }
    };
    let d = robot("/deployments", json!({})).await;
    let id = d["id"].as_i64().unwrap();
    assert_eq!(
        page.next(SECOND).await,
        ("deployment".into(), json!({"deployment": id}))
    );
    let mut trial = robot(
        &format!("/deployments/{id}/trials"),
        json!({"scene": "flat", "target": "Wallet"}),
    )
    .await;
    let tid = trial["trial"].as_i64().unwrap();
    let mut steps = 0;
    loop {
        let (name, e) = page.next(SECOND).await;
        assert_eq!(name, "trial");
        assert_eq!(
            (e["trial"].as_i64(), e["searched"].as_i64()),
            (Some(tid), Some(steps))
        );
        assert_eq!(e["next"], trial["next"]["container"]);
        if trial["status"] != "searching" {
            break;
        }
        let c = trial["next"]["container"].as_str().unwrap().to_string();
        trial = robot(
            &format!("/trials/{tid}/observations"),
            json!({"container": c, "found": contents(&c).contains(&"Wallet"), "objects": contents(&c)}),
        )
        .await;
        steps += 1;
    }
    assert_eq!(trial["status"], "done");

    // Both replicas' listening sessions are cut, as a database restart would.
    tokio::task::block_in_place(|| {
        support::psql(
            &url,
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE application_name LIKE 'ferret-replica:%' AND datname = current_database() AND pid <> pg_backend_pid()",
        );
    });
    let (name, _) = page.next(Duration::from_secs(5)).await;
    assert_eq!(name, "resync", "the page is told it may have missed events");
    let d = robot("/deployments", json!({})).await;
    assert_eq!(
        page.next(SECOND).await,
        ("deployment".into(), json!({"deployment": d["id"]}))
    );
    ha.abort();
    hb.abort();
}

/// A fleet that nobody watches sends no notification per write; a page opened on one replica
/// turns them on everywhere, and sees what the other replica did from the moment it connected.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn replicas_notify_each_other_only_while_a_page_watches() {
    let Some(url) =
        support::postgres_or_skip("replicas_notify_each_other_only_while_a_page_watches")
    else {
        return;
    };
    let (a, ha) = support::server::replica(&url).await;
    let (b, hb) = support::server::replica(&url).await;
    let (listener, mut connection) = tokio_postgres::connect(&url, tokio_postgres::NoTls)
        .await
        .unwrap();
    let heard = Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let sink = heard.clone();
    let driver = tokio::spawn(async move {
        while let Some(Ok(m)) =
            futures_util::future::poll_fn(|cx| connection.poll_message(cx)).await
        {
            if let tokio_postgres::AsyncMessage::Notification(n) = m {
                sink.lock().unwrap().push(n.payload().to_string());
            }
        }
    });
    listener
        .batch_execute("LISTEN ferret_events")
        .await
        .unwrap();
    let client = reqwest::Client::new();
    let post = |url: String, body: Value| {
        let client = client.clone();
        async move {
            let r = client.post(url).json(&body).send().await.unwrap();
            assert!(r.status().is_success());
            r.json::<Value>().await.unwrap()
        }
    };
    let d = post(format!("{b}/deployments"), json!({})).await;
    let id = d["id"].as_i64().unwrap();
    let before = post(
        format!("{b}/deployments/{id}/trials"),
        json!({"scene": "flat", "target": "Wallet"}),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(
        heard.lock().unwrap().is_empty(),
        "{:?}",
        heard.lock().unwrap()
    );

    let mut page = Stream::open_at(&client, &a, None).await.1.unwrap();
    assert_eq!(page.next(SECOND).await.0, "hello");
    let after = post(
        format!("{b}/deployments/{id}/trials"),
        json!({"scene": "flat", "target": "Mug"}),
    )
    .await;
    // This start, and those of the moment before the page came (kept for a page on its way).
    let mut trials = Vec::new();
    while trials.last() != Some(&after["trial"]) {
        let (name, e) = page.next(SECOND).await;
        if name == "trial" {
            trials.push(e["trial"].clone());
        }
    }
    assert_eq!(trials, [before["trial"].clone(), after["trial"].clone()]);
    // The page heard B's events through A's listening session; this test's own session may
    // hear the same notification a moment later.
    let deadline = tokio::time::Instant::now() + SECOND;
    while !heard
        .lock()
        .unwrap()
        .iter()
        .any(|n| n.contains("\ntrial\n{"))
        && tokio::time::Instant::now() < deadline
    {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let heard = heard.lock().unwrap().clone();
    // A's word that it watches, then B's events (each notification names its sender).
    assert!(
        heard.first().is_some_and(|n| n.ends_with("\nwatching\n*")),
        "{heard:?}"
    );
    assert!(
        heard[1..].iter().any(|n| n.contains("\ntrial\n{")),
        "{heard:?}"
    );
    driver.abort();
    ha.abort();
    hb.abort();
}

/// Sessions open on database `db` of the server at `admin`, counted from `admin`'s database.
async fn sessions_on(admin: &str, db: &str) -> i64 {
    let (client, connection) = tokio_postgres::connect(admin, tokio_postgres::NoTls)
        .await
        .unwrap();
    tokio::spawn(connection);
    client
        .query_one(
            "SELECT count(*) FROM pg_stat_activity WHERE datname = $1",
            &[&db],
        )
        .await
        .unwrap()
        .get(0)
}

/// A replica opens its pool's connections and its claims session as it starts, so that robots
/// starting at once do not each wait for a connection to be made; a database that admits
/// fewer connections than the pool still lets it start and serve.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replica_opens_its_connections_before_the_first_request() {
    let Some(url) =
        support::postgres_or_skip("a_replica_opens_its_connections_before_the_first_request")
    else {
        return;
    };
    let admin = std::env::var("FERRET_TEST_POSTGRES").unwrap();
    let db = url.rsplit_once('/').unwrap().1.to_string();
    let options = ferret_serve::PostgresOptions {
        pool_size: 4,
        ..Default::default()
    };
    let connect = |url: String| {
        tokio::task::spawn_blocking(move || ferret_serve::Store::connect(&url, options))
    };
    let store = connect(url.clone()).await.unwrap().unwrap();
    // The pool's 4 and the claims session.
    assert_eq!(sessions_on(&admin, &db).await, 5);
    tokio::task::spawn_blocking(move || drop(store))
        .await
        .unwrap();

    // A role that may hold 2 sessions (the limit binds roles that are not superusers), owning
    // a database of its own.
    let role = format!("{db}_limited");
    support::psql(
        &admin,
        &format!("CREATE ROLE {role} LOGIN CONNECTION LIMIT 2"),
    );
    let limited = support::fresh_postgres().unwrap();
    let limited_db = limited.rsplit_once('/').unwrap().1.to_string();
    support::psql(
        &admin,
        &format!("ALTER DATABASE {limited_db} OWNER TO {role}"),
    );
    let mut limited = reqwest::Url::parse(&limited).unwrap();
    limited.set_username(&role).unwrap();
    let store = connect(limited.to_string()).await.unwrap().unwrap();
    assert_eq!(sessions_on(&admin, &limited_db).await, 2);
    let created = tokio::task::spawn_blocking(move || {
        let service = Service::new(store, GridParams::default(), strategies()).unwrap();
        service.create_deployment(serde_json::from_str("{}").unwrap(), b"{}")
    })
    .await
    .unwrap();
    assert!(created.is_ok(), "{:?}", created.err());
}

/// An observation listing 300 object names made a trial event too long for one notification:
/// it was dropped, and a page on the other replica never saw the search nor the trial's end.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_event_too_long_for_a_notification_still_reaches_the_other_replicas_page() {
    let Some(url) = support::postgres_or_skip(
        "an_event_too_long_for_a_notification_still_reaches_the_other_replicas_page",
    ) else {
        return;
    };
    let (a, ha) = support::server::replica(&url).await;
    let (b, hb) = support::server::replica(&url).await;
    let client = reqwest::Client::new();
    let mut page = Stream::open_at(&client, &a, None).await.1.unwrap();
    assert_eq!(page.next(SECOND).await.0, "hello");
    let robot = |path: String, body: Value| {
        let (client, url) = (client.clone(), format!("{b}{path}"));
        async move {
            let r = client.post(url).json(&body).send().await.unwrap();
            assert!(r.status().is_success());
            r.json::<Value>().await.unwrap()
        }
    };
    let id = robot("/deployments".into(), json!({})).await["id"]
        .as_i64()
        .unwrap();
    let trial = robot(
        format!("/deployments/{id}/trials"),
        json!({"scene": "flat", "target": "Wallet"}),
    )
    .await;
    let tid = trial["trial"].as_i64().unwrap();
    // Far more than a notification holds (8000 bytes).
    let objects: Vec<String> = (0..300)
        .map(|i| format!("Thing{i:04}{}", "X".repeat(40)))
        .collect();
    let c = trial["next"]["container"].as_str().unwrap();
    let after = robot(
        format!("/trials/{tid}/observations"),
        json!({"container": c, "found": false, "objects": objects}),
    )
    .await;
    let ended = robot(format!("/trials/{tid}/abandon"), json!({})).await;
    assert_eq!(ended["status"], "abandoned");
    // The page hears the search (without its long list: it reads the trial's picture for
    // that) and the end, or is told to read everything again.
    let mut searched = None;
    loop {
        let (name, e) = page.next(Duration::from_secs(3)).await;
        if name == "resync" {
            break;
        }
        if name != "trial" || e["trial"].as_i64() != Some(tid) {
            continue;
        }
        if e["searched"] == 1 && e["status"] == "searching" {
            assert!(e["observed"].is_null(), "{e}");
            assert_eq!(e["next"], after["next"]["container"]);
            searched = Some(e);
        } else if e["status"] == "abandoned" {
            assert!(searched.is_some(), "the search's event came before the end");
            break;
        }
    }
    ha.abort();
    hb.abort();
}
