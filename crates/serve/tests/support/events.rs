//! A page's event stream (`GET /events`) read as the page reads it.

use std::time::Duration;

use serde_json::Value;

use super::server::Server;

/// An open `GET /events` read as a page reads it.
pub struct Stream {
    response: reqwest::Response,
    buffer: String,
}

impl Stream {
    /// Opens the stream of `s`'s server with `token`: the status, and the stream when 200.
    pub async fn open(s: &Server, token: Option<&str>) -> (u16, Option<Stream>) {
        Self::open_at(&s.client, &s.url, token).await
    }

    /// Opens the stream of the server at `url`.
    pub async fn open_at(
        client: &reqwest::Client,
        url: &str,
        token: Option<&str>,
    ) -> (u16, Option<Stream>) {
        let mut request = client.get(format!("{url}/events"));
        if let Some(t) = token {
            request = request.bearer_auth(t);
        }
        let response = request.send().await.unwrap();
        let status = response.status().as_u16();
        if status != 200 {
            return (status, None);
        }
        assert_eq!(
            response.headers()["content-type"],
            "text/event-stream",
            "an event stream"
        );
        (status, Some(Stream::from_response(response)))
    }

    /// The stream of a `GET /events` answered 200.
    pub fn from_response(response: reqwest::Response) -> Stream {
        Stream {
            response,
            buffer: String::new(),
        }
    }

    /// The next event (name, data), skipping keep-alive comments; panics after `within`.
    pub async fn next(&mut self, within: Duration) -> (String, Value) {
        let deadline = tokio::time::Instant::now() + within;
        loop {
            if let Some(end) = self.buffer.find("\n\n") {
                let block: String = self.buffer.drain(..end + 2).collect();
                let (mut name, mut data) = (String::new(), String::new());
                for line in block.lines() {
                    if let Some(v) = line.strip_prefix("event:") {
                        name = v.trim().to_string();
                    } else if let Some(v) = line.strip_prefix("data:") {
                        data.push_str(v.trim());
                    }
                }
                if name.is_empty() {
                    continue; // a comment
                }
                return (name, serde_json::from_str(&data).unwrap());
            }
            let chunk = tokio::time::timeout_at(deadline, self.response.chunk())
                .await
                .unwrap_or_else(|_| panic!("no event within {within:?}"))
                .unwrap()
                .expect("the stream ended");
            self.buffer.push_str(std::str::from_utf8(&chunk).unwrap());
        }
    }
}
