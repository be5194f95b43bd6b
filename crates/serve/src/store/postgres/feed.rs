//! Notifications between replicas: what one replica publishes goes out as `NOTIFY` on a
//! channel, and a session of every replica that `LISTEN`s on it hears it (the sender too), so
//! each replica tells its own watchers. PostgreSQL delivers a notification only once the
//! transaction that sent it commits, and to sessions listening then: a replica whose listening
//! session dropped is told so (`None`) when it listens again, since it may have missed some.
//!
//! A replica killed between a write's commit and its notification takes that event with it.
//! Each listening session therefore names its replica (`application_name`), and a replica with
//! watchers looks every [`PRESENCE`] at who is listening: one that left without a word is
//! reported as `None` too, so its last events are never silently missing from a page.

use std::collections::BTreeSet;
use std::time::Duration;

use deadpool_postgres::Pool;
use tokio::sync::mpsc;
use tokio_postgres::{AsyncMessage, NoTls};

use super::Postgres;
use crate::store::error::StoreError;
use crate::store::{Deliver, FeedOptions};

/// Texts sent in one statement at most.
const BATCH: usize = 256;

/// How long the first text of a batch waits for others: well under what a page would notice.
const GATHER: Duration = Duration::from_millis(25);

/// How often a replica with watchers looks for replicas that left the database.
const PRESENCE: Duration = Duration::from_secs(1);

/// How a replica's listening session names itself: this, then the replica's name.
const APPLICATION: &str = "ferret-replica:";

impl Postgres {
    /// Starts listening on `channel` (calling `deliver` for each notification) and returns
    /// where to put texts to notify; both run on the store's runtime until the store is
    /// dropped. `queue` texts may wait to be sent; more are refused by the sender.
    pub(in crate::store) fn feed(
        &self,
        channel: &'static str,
        queue: usize,
        deliver: Deliver,
        options: FeedOptions,
    ) -> Result<mpsc::Sender<String>, StoreError> {
        let Some(rt) = &self.runtime else {
            return Err(StoreError::Unreachable {
                db: self.db.clone(),
                what: "the client's runtime is gone".into(),
            });
        };
        let (outbox, inbox) = mpsc::channel(queue.max(1));
        rt.spawn(listen(
            self.config.clone(),
            self.db.clone(),
            channel,
            options.sender.clone(),
            deliver.clone(),
        ));
        rt.spawn(notify(
            self.pool.clone(),
            self.db.clone(),
            channel,
            inbox,
            options,
            deliver,
        ));
        Ok(outbox)
    }
}

/// Listens on `channel` for good, on a session of its own named after `replica`, opening a new
/// one after a loss.
async fn listen(
    mut config: tokio_postgres::Config,
    db: String,
    channel: &str,
    replica: String,
    deliver: Deliver,
) {
    config.application_name(format!("{APPLICATION}{replica}"));
    let mut first = true;
    loop {
        match config.connect(NoTls).await {
            Ok((client, mut connection)) => {
                let hear = deliver.clone();
                // The connection's messages: the LISTEN's own reply goes to `client`, the
                // notifications come out here.
                let driver = async move {
                    loop {
                        match futures_util::future::poll_fn(|cx| connection.poll_message(cx)).await
                        {
                            Some(Ok(AsyncMessage::Notification(n))) => {
                                hear(Some(n.payload().to_string()));
                            }
                            Some(Ok(_)) => {}
                            Some(Err(e)) => return e.to_string(),
                            None => return "closed".to_string(),
                        }
                    }
                };
                tokio::pin!(driver);
                let sql = format!("LISTEN {channel}");
                let listening = tokio::select! {
                    r = client.batch_execute(&sql) => r.map_err(|e| e.to_string()),
                    why = &mut driver => Err(why),
                };
                match listening {
                    Ok(()) => {
                        if !first {
                            deliver(None);
                        }
                        first = false;
                        let why = driver.await;
                        tracing::warn!("{db}: the session listening for events ended ({why})");
                    }
                    Err(why) => tracing::warn!("{db}: cannot listen for events: {why}"),
                }
                drop(client);
            }
            Err(e) => tracing::warn!(
                "{db}: cannot open a session to listen for events: {}",
                super::with_causes(&e)
            ),
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// Sends what is put in `inbox` as notifications on `channel`, as many at once as are waiting,
/// and what `options.beat` gives when it is due. While this replica has watchers (`beat` gives
/// something), it also looks for replicas that left and tells `deliver` (`None`).
async fn notify(
    pool: Pool,
    db: String,
    channel: &str,
    mut inbox: mpsc::Receiver<String>,
    options: FeedOptions,
    deliver: Deliver,
) {
    let mut batch = Vec::with_capacity(BATCH);
    let mut beat = tokio::time::interval(options.every);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut presence = tokio::time::interval(PRESENCE);
    presence.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    // The replicas listening when last looked, while this one had watchers.
    let mut present: Option<BTreeSet<String>> = None;
    // A batch the database refused: the others are told to read everything again next time.
    let mut failed = false;
    loop {
        tokio::select! {
            n = inbox.recv_many(&mut batch, BATCH) => {
                if n == 0 {
                    return;
                }
                // A notification costs the database and every listening replica far more than
                // its bytes: what comes within a moment goes in the same ones.
                tokio::time::sleep(GATHER).await;
                while batch.len() < BATCH {
                    match inbox.try_recv() {
                        Ok(t) => batch.push(t),
                        Err(_) => break,
                    }
                }
            }
            _ = beat.tick() => {
                match (options.beat)() {
                    Some(text) => batch.push(text),
                    None => continue,
                }
            }
            _ = presence.tick() => {
                if (options.beat)().is_none() {
                    present = None;
                    continue;
                }
                match listening(&pool).await {
                    Ok(now) => {
                        if let Some(gone) = present.as_ref().and_then(|before| before.difference(&now).next()) {
                            tracing::info!("{db}: replica {gone} left; its last events may be lost");
                            deliver(None);
                        }
                        present = Some(now);
                    }
                    Err(e) => tracing::debug!("{db}: cannot look for replicas: {e}"),
                }
                continue;
            }
        }
        if std::mem::take(&mut failed) {
            batch.insert(0, options.lost.clone());
        }
        let payloads = pack(&options.sender, &batch, options.max_bytes, &options.lost);
        let sent = async {
            let client = pool.get().await.map_err(|e| e.to_string())?;
            client
                .execute(
                    "SELECT pg_notify($1, t) FROM unnest($2::text[]) AS t",
                    &[&channel, &payloads],
                )
                .await
                .map_err(|e| e.to_string())
        }
        .await;
        if let Err(e) = sent {
            tracing::warn!(
                "{db}: {} events not sent to other replicas: {e}",
                batch.len()
            );
            failed = true;
        }
        batch.clear();
    }
}

/// The replicas whose listening sessions are open on the database now.
async fn listening(pool: &Pool) -> Result<BTreeSet<String>, String> {
    let client = pool.get().await.map_err(|e| e.to_string())?;
    let rows = client
        .query(
            "SELECT application_name FROM pg_stat_activity \
             WHERE datname = current_database() AND starts_with(application_name, $1)",
            &[&APPLICATION],
        )
        .await
        .map_err(|e| e.to_string())?;
    Ok(rows
        .iter()
        .filter_map(|r| r.get::<_, Option<String>>(0))
        .filter_map(|name| name.strip_prefix(APPLICATION).map(str::to_string))
        .collect())
}

/// `texts` in as few notifications as fit `max` bytes each: `sender`, a newline, then the texts
/// separated by blank lines. A text that does not fit alone goes as `lost` instead.
fn pack(sender: &str, texts: &[String], max: usize, lost: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for t in texts {
        let t = if sender.len() + 1 + t.len() > max {
            tracing::warn!(
                "an event of {} bytes is too long to notify; the other replicas are told to read everything again",
                t.len()
            );
            lost
        } else {
            t.as_str()
        };
        if !current.is_empty() && current.len() + 2 + t.len() > max {
            out.push(std::mem::take(&mut current));
        }
        if current.is_empty() {
            current.push_str(sender);
            current.push('\n');
        } else {
            current.push_str("\n\n");
        }
        current.push_str(t);
    }
    if !current.is_empty() {
        out.push(current);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::pack;

    #[test]
    fn texts_are_packed_into_notifications_that_fit() {
        let texts: Vec<String> = (0..10)
            .map(|i| format!("t{i}-{}", "x".repeat(20)))
            .collect();
        let packed = pack("r1", &texts, 80, "lost");
        assert!(packed.len() > 1);
        assert!(
            packed
                .iter()
                .all(|p| p.len() <= 80 && p.starts_with("r1\n"))
        );
        let back: Vec<String> = packed
            .iter()
            .flat_map(|p| {
                p["r1\n".len()..]
                    .split("\n\n")
                    .map(str::to_string)
                    .collect::<Vec<_>>()
            })
            .collect();
        assert_eq!(back, texts, "every text once, in order");
        assert_eq!(
            pack("r1", &["a".into(), "y".repeat(100), "b".into()], 80, "lost"),
            ["r1\na\n\nlost\n\nb"],
            "a text too long alone goes as the word that something was lost"
        );
    }
}
