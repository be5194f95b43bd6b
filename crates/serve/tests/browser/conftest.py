"""Fixtures of the browser tests of `ferret serve`'s live view: real servers on 127.0.0.1, Debian's
Chromium driven by Playwright, a robot that drives trials over plain HTTP, and the checks every
page must pass (no Content-Security-Policy violation, no script error, nothing loaded from
anywhere but the server).

Run by scripts/browser-tests.sh, which installs what this needs. FERRET_BIN is the ferret binary,
FERRET_CHROMIUM the browser (default /usr/bin/chromium), FERRET_BROWSER_SHOTS a directory for the
screenshots, FERRET_TEST_POSTGRES a PostgreSQL server to make the replicas' database on (without
it, one is started with scripts/postgres.sh for the session).
"""

import json
import os
import re
import selectors
import statistics
import subprocess
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from pathlib import Path

import pytest
from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parents[4]
SCENE = ROOT / "examples" / "apartment" / "scene.yaml"
TOKEN = "browser-test-token"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
VIEWPORT = {"width": 1400, "height": 900}
# What "live" means for the page: each change shows within this of the request that made it.
BUDGET_MS = 1000

# How long each change took to show, for the summary at the end.
LATENCIES_MS = []


def pytest_terminal_summary(terminalreporter):
    if LATENCIES_MS:
        ms = sorted(LATENCIES_MS)
        slowest = ", ".join(f"{m:.0f}" for m in ms[-5:])
        terminalreporter.write_line(
            f"live view: {len(LATENCIES_MS)} changes shown after a median of "
            f"{statistics.median(LATENCIES_MS):.0f} ms, at most {max(LATENCIES_MS):.0f} ms "
            f"(budget {BUDGET_MS} ms; the slowest {slowest} ms)"
        )


@pytest.fixture(scope="session")
def ferret_bin():
    path = Path(os.environ.get("FERRET_BIN") or ROOT / "target" / "release" / "ferret")
    if not path.is_file():
        pytest.fail(
            f"{path}: no ferret binary (cargo build --release -p ferret-cli, or FERRET_BIN)"
        )
    return str(path)


class Server:
    """One `ferret serve` on 127.0.0.1, stopped by the fixture that made it."""

    def __init__(self, ferret_bin, workdir, args, token, db, listen):
        self.token = token
        self.stderr_path = workdir / f"serve-{uuid.uuid4().hex[:8]}.err"
        env = dict(os.environ)
        env.pop("FERRET_SERVE_TOKEN", None)
        if token:
            env["FERRET_SERVE_TOKEN"] = token
        cmd = [ferret_bin, "serve", "--listen", listen, "--scene", str(SCENE), "--db", db, *args]
        with open(self.stderr_path, "wb") as err:
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, env=env)
        self.url = self._address()
        self.api = Api(self.url, token)

    def _address(self):
        """The address from the line `listening on http://ADDR` the server prints when ready."""
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + 60
        buf = b""
        while time.monotonic() < deadline:
            if not sel.select(timeout=0.2):
                if self.proc.poll() is not None:
                    break
                continue
            chunk = os.read(self.proc.stdout.fileno(), 4096)
            if not chunk:
                break
            buf += chunk
            m = re.search(rb"listening on (http://127\.0\.0\.1:\d+)", buf)
            if m:
                return m.group(1).decode()
        self.stop()
        pytest.fail(f"ferret serve did not start:\n{self.stderr_path.read_text()}")

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stdout.close()


@pytest.fixture
def serve(tmp_path, ferret_bin):
    """serve(*options, token=TOKEN, db=None, listen="127.0.0.1:0") starts a server (its own
    SQLite file unless `db` is given); all are stopped after the test."""
    servers = []

    def start(*args, token=TOKEN, db=None, listen="127.0.0.1:0"):
        db = db or str(tmp_path / f"serve-{len(servers)}.sqlite")
        s = Server(ferret_bin, tmp_path, args, token, db, listen)
        servers.append(s)
        return s

    yield start
    for s in servers:
        s.stop()


class Api:
    """The robot's side: JSON over plain HTTP with the bearer token, as
    examples/robot_client.py talks to the server."""

    def __init__(self, url, token):
        self.url = url
        self.token = token

    def request(self, method, path, body=None):
        """(status, JSON body) without raising on 4xx/5xx."""
        data = None if body is None else json.dumps(body).encode()
        headers = {"Accept": "application/json"}
        if data is not None:
            headers["Content-Type"] = "application/json"
        if self.token:
            headers["Authorization"] = "Bearer " + self.token
        req = urllib.request.Request(self.url + path, data=data, headers=headers, method=method)
        try:
            with urllib.request.urlopen(req, timeout=30) as resp:
                return resp.status, json.loads(resp.read() or b"null")
        except urllib.error.HTTPError as e:
            raw = e.read()
            try:
                return e.code, json.loads(raw)
            except ValueError:
                return e.code, raw.decode(errors="replace")

    def get(self, path):
        status, body = self.request("GET", path)
        assert status == 200, f"GET {path} -> {status}: {body}"
        return body

    def post(self, path, body):
        status, reply = self.request("POST", path, dict(body, request_id=str(uuid.uuid4())))
        assert status in (200, 201), f"POST {path} -> {status}: {reply}"
        return reply


def seg(v):
    return urllib.parse.quote(str(v), safe="")


class Robot:
    """A simulated robot on the apartment: its eyes are the scene's `contents`."""

    def __init__(self, api, scene="apartment"):
        self.api = api
        self.scene = scene
        self.contents = {
            c["id"]: c["contents"] for c in api.get(f"/scenes/{seg(scene)}")["containers"]
        }

    def deploy(self, **body):
        return self.api.post("/deployments", body)

    def start(self, deployment, target, robot=None):
        body = {"scene": self.scene, "target": target}
        if robot is not None:
            body["robot"] = robot
        return self.api.post(f"/deployments/{seg(deployment)}/trials", body)

    def start_task(self, deployment, targets, goal="all", destination=None):
        """Starts a household task: several targets, all or any, brought to `destination`."""
        body = {"scene": self.scene, "targets": targets, "goal": goal}
        if destination is not None:
            body["destination"] = destination
        return self.api.post(f"/deployments/{seg(deployment)}/trials", body)

    def search_next(self, trial):
        """Searches the container the server proposed, naming the trial's targets it sees;
        returns the server's reply."""
        cid = trial["next"]["container"]
        seen = self.contents[cid]
        found = [t for t in trial["targets"] if t in seen]
        body = {"container": cid, "found": bool(found), "found_targets": found, "objects": seen}
        return self.api.post(f"/trials/{seg(trial['trial'])}/observations", body)

    def finish(self, trial):
        while trial["status"] == "searching":
            trial = self.search_next(trial)
        return trial


class View:
    """A browser page on the live view, with what it logged and requested."""

    def __init__(self, page, server):
        self.page = page
        self.server = server
        self.console = []
        self.errors = []
        self.requests = []
        page.on("console", lambda m: self.console.append(f"{m.type}: {m.text}"))
        page.on("pageerror", lambda e: self.errors.append(str(e)))
        page.on("request", lambda r: self.requests.append((time.monotonic(), r.method, r.url)))

    def open(self, token=None):
        self.page.goto(self.server.url + "/")
        if token is not None:
            self.enter_token(token)
        return self

    def enter_token(self, token):
        self.page.wait_for_selector("#token-input", state="visible", timeout=5000)
        self.page.fill("#token-input", token)
        self.page.click("#token-submit")

    def wait_live(self, timeout=5000):
        self.page.wait_for_selector('#connection[data-state="live"]', timeout=timeout)

    def within(self, predicate, arg=None, what="", budget_ms=BUDGET_MS):
        """Waits until the JS `predicate(arg)` holds on the page, at most `budget_ms` from now
        (call it right after the request whose effect it checks), and records how long."""
        t0 = time.monotonic()
        try:
            self.page.wait_for_function(predicate, arg=arg, timeout=budget_ms, polling="raf")
        except Exception as e:  # noqa: BLE001 - a timeout, reported with what was awaited
            raise AssertionError(f"not shown within {budget_ms} ms: {what}") from e
        if budget_ms == BUDGET_MS:
            LATENCIES_MS.append((time.monotonic() - t0) * 1000)

    def attr(self, selector, name):
        return self.page.get_attribute(selector, name)

    def count(self, selector):
        return self.page.locator(selector).count()

    def shot(self, name):
        """A screenshot into FERRET_BROWSER_SHOTS, when set."""
        d = os.environ.get("FERRET_BROWSER_SHOTS")
        if d:
            Path(d).mkdir(parents=True, exist_ok=True)
            self.page.screenshot(path=str(Path(d) / name))

    def check_clean(self):
        csp = [m for m in self.console if "Content Security Policy" in m]
        assert not csp, f"the page broke its Content-Security-Policy: {csp}"
        assert not self.errors, f"script errors on the page: {self.errors}"
        outside = [
            u
            for _, _, u in self.requests
            if urllib.parse.urlsplit(u).hostname != "127.0.0.1" and not u.startswith("data:")
        ]
        assert not outside, f"the page loaded from outside 127.0.0.1: {outside}"


@pytest.fixture(scope="session")
def playwright():
    with sync_playwright() as p:
        yield p


@pytest.fixture
def browser(playwright, tmp_path):
    """Chromium with a fresh profile of its own for each test."""
    ctx = playwright.chromium.launch_persistent_context(
        str(tmp_path / "profile"),
        executable_path=os.environ.get("FERRET_CHROMIUM", "/usr/bin/chromium"),
        headless=True,
        args=CHROMIUM_ARGS,
        viewport=VIEWPORT,
    )
    yield ctx
    ctx.close()


@pytest.fixture
def view(browser):
    """view(server) opens a new page on the server's live view; each page is checked for CSP
    violations, script errors and requests beyond 127.0.0.1 after the test."""
    views = []

    def open_view(server):
        v = View(browser.new_page(), server)
        views.append(v)
        return v

    yield open_view
    for v in views:
        v.check_clean()


@pytest.fixture(scope="session")
def postgres_url(tmp_path_factory):
    """A fresh database on the PostgreSQL of FERRET_TEST_POSTGRES, or on a throwaway cluster
    started here and stopped after the session."""
    script = str(ROOT / "scripts" / "postgres.sh")
    started = None
    env = dict(os.environ)
    if not env.get("FERRET_TEST_POSTGRES"):
        out = subprocess.run([script, "start"], capture_output=True, text=True)
        if out.returncode != 0:
            pytest.fail(f"scripts/postgres.sh start failed:\n{out.stderr}")
        for line in out.stdout.splitlines():
            m = re.match(r"export (\w+)=(.*)", line)
            if m:
                env[m.group(1)] = m.group(2)
        started = env["FERRET_PG_DIR"]
    name = f"browser_{uuid.uuid4().hex[:10]}"
    out = subprocess.run([script, "new-db", name], capture_output=True, text=True, env=env)
    try:
        if out.returncode != 0:
            pytest.fail(f"scripts/postgres.sh new-db failed:\n{out.stderr}")
        yield out.stdout.strip()
    finally:
        if started:
            subprocess.run([script, "stop", started], check=False)
