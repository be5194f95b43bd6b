//! The servers a fleet drives: this crate's router on a port of 127.0.0.1 in the caller's
//! process, or `ferret serve` processes of their own.

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;

use super::LoadError;
use crate::{HttpOptions, ServeOptions, Service, router, serve};

/// Serves `service` on a free port of 127.0.0.1 on `runtime`, with the guards and connection
/// loop `ferret serve` runs; returns its URL and the task serving it (abort it to stop).
///
/// # Errors
/// No port can be had, or the router cannot be built.
pub fn serve_in_process(
    runtime: &tokio::runtime::Runtime,
    service: Service,
) -> Result<(String, tokio::task::JoinHandle<std::io::Result<()>>), LoadError> {
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .map_err(LoadError::io("listening on 127.0.0.1"))?;
    let addr = listener
        .local_addr()
        .map_err(LoadError::io("the listener's address"))?;
    let options = HttpOptions {
        listen: Some(addr),
        ..HttpOptions::default()
    };
    let app = router(Arc::new(service), &options).map_err(|e| LoadError::Setup(e.message))?;
    let task = runtime.spawn(serve(
        listener,
        app,
        ServeOptions::default(),
        std::future::pending(),
    ));
    Ok((format!("http://{addr}"), task))
}

/// A `ferret serve` process, stopped when dropped.
pub struct Replica {
    child: Child,
    url: String,
}

impl Replica {
    /// Runs `command` (a `ferret serve` listening on `127.0.0.1:0`, its standard error to
    /// `log`) and waits until it prints the URL it listens on.
    ///
    /// # Errors
    /// It cannot be started, or it exits before listening (its log says why).
    pub fn spawn(mut command: Command, log: &Path) -> Result<Replica, LoadError> {
        let err = std::fs::File::create(log)
            .map_err(LoadError::io(format!("creating {}", log.display())))?;
        command.stdout(Stdio::piped()).stderr(err);
        let mut child = command
            .spawn()
            .map_err(LoadError::io("spawning ferret serve"))?;
        let Some(stdout) = child.stdout.take() else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(LoadError::Setup("the replica's output is not piped".into()));
        };
        let mut lines = std::io::BufReader::new(stdout).lines();
        for line in lines.by_ref() {
            let Ok(line) = line else { break };
            if let Some(rest) = line.split("listening on ").nth(1)
                && let Some(url) = rest.split_whitespace().next()
            {
                // Keep reading its output in the background so it never blocks on a full pipe.
                std::thread::spawn(move || lines.for_each(drop));
                return Ok(Replica {
                    child,
                    url: url.to_string(),
                });
            }
        }
        let _ = child.kill();
        let _ = child.wait();
        Err(LoadError::ReplicaExited {
            log: std::fs::read_to_string(log)
                .unwrap_or_default()
                .trim()
                .to_string(),
        })
    }

    /// The URL it listens on.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Kills it (SIGKILL on Unix: no shutdown, no flush) and waits for it.
    ///
    /// # Errors
    /// It cannot be signalled.
    pub fn kill(&mut self) -> std::io::Result<()> {
        self.child.kill()?;
        self.child.wait().map(drop)
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        // Replicas stop on SIGTERM; kill is enough for a benchmark's throwaway processes.
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Resident memory of process `pid`, bytes (Linux's `/proc`; `None` elsewhere or once it ended).
pub(super) fn resident_bytes(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib * 1024)
}
