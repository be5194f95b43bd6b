"""The live view of `ferret serve` in a real browser: a robot drives deployments and trials through
the API, and everything is read back from the page's DOM, each change within a second of the
request that made it."""

import time
import urllib.request

from conftest import BUDGET_MS, TOKEN, Robot, seg

# Opening a page reads several routes one after another; the budget of a second is for changes.
LOAD_MS = 5000

# The page shows this trial as the server knows it: the trial, its status, the next container
# (marked on the plan and named beside it), the searched containers in order, each container's
# likelihood, and the deployment's open trials.
STATE_SHOWN = """(e) => {
  const card = document.querySelector("#plan-card");
  if (card.dataset.trial !== String(e.trial) || card.dataset.status !== e.status) return false;
  const next = document.querySelector("#next-container");
  if (e.next === null) {
    if (!next.hidden) return false;
  } else {
    if (next.hidden || next.dataset.container !== e.next) return false;
    const sel = `#plan g.container[data-container="${CSS.escape(e.next)}"][data-next="true"]`;
    if (!document.querySelector(sel) || !document.querySelector("#next-path")) return false;
  }
  const marks = [...document.querySelectorAll("#plan g.container")];
  if (marks.length !== e.containers) return false;
  for (const g of marks) {
    const c = g.dataset.container;
    const order = e.searched.indexOf(c) + 1;
    if (g.dataset.searched !== String(order > 0)) return false;
    if (order > 0 && g.dataset.order !== String(order)) return false;
    const p = e.likelihoods === null ? undefined : e.likelihoods[c];
    if (p === undefined || p === null) {
      if (g.dataset.likelihood !== "none") return false;
    } else if (Math.abs(Number(g.dataset.likelihood) - p) > 1e-9) return false;
  }
  const route = document.querySelector("#route");
  if ((route ? Number(route.dataset.points) : 0) !== (e.route > 1 ? e.route : 0)) return false;
  const path = document.querySelector("#next-path");
  if ((path ? Number(path.dataset.points) : 0) !== e.path) return false;
  if (document.querySelector("#fact-cost").textContent !== e.cost) return false;
  const listed = [...document.querySelectorAll("#searched-list li[data-container]")];
  if (listed.map((li) => li.dataset.container).join() !== e.searched.join()) return false;
  const open = [...document.querySelectorAll("#open-trials button[data-trial]")];
  return open.map((b) => Number(b.dataset.trial)).join() === e.open.join();
}"""

# The selection curve holds this trial's mark, and the strategy table the server's counts.
SELECTION_SHOWN = """(e) => {
  const sel = `#selection-curve [data-k="${e.k}"][data-trial="${e.trial}"]`;
  const mark = document.querySelector(sel);
  if (!mark || mark.dataset.strategy !== e.strategy || mark.dataset.status !== e.status) {
    return false;
  }
  if (e.cost !== null && Math.abs(Number(mark.dataset.cost) - e.cost) > 1e-9) return false;
  for (const [strategy, deployed, mean] of e.rows) {
    const row = document.querySelector(`#strategy-table tr[data-strategy="${strategy}"]`);
    if (!row || row.cells[1].textContent !== String(deployed)) return false;
    if (row.cells[2].textContent !== mean) return false;
  }
  return true;
}"""

COLOURS = """() => [...document.querySelectorAll("#plan g.container")].map((g) => [
  g.dataset.likelihood, g.querySelector("circle.marker").getAttribute("fill")])"""

EMPTY = {
    "containers on the plan": "[data-container]",
    "deployments to pick": "#deployment-select option",
    "strategy rows": "#strategy-table tbody tr",
    "trials on the selection curve": "#selection-curve [data-k]",
    "open trials": "#open-trials li",
    "searched containers": "#searched-list li",
    "replays": "#replays tbody tr",
}

TARGETS = ["Wallet", "Book", "RemoteControl", "KeyChain", "Mug", "Pillow", "Laptop"]


def fmt(v):
    return "–" if v is None else f"{v:.2f}"


def expect_trial(v, api, trial, deployment_open=None, budget_ms=BUDGET_MS):
    """The page shows `trial` (a reply of the server) within the budget."""
    view = api.get(f"/trials/{seg(trial['trial'])}/view")
    assert view["trial"]["searched"] == trial["searched"]
    expected = {
        "trial": trial["trial"],
        "status": trial["status"],
        "next": trial["next"]["container"] if trial["next"] else None,
        "searched": trial["searched"],
        "likelihoods": view["likelihoods"],
        "containers": 9,
        "route": len(view["route"]),
        "path": len(trial["next"]["path"]) if trial["next"] else 0,
        "cost": f"{trial['cost_m']:.2f} m",
        "open": deployment_open
        if deployment_open is not None
        else ([trial["trial"]] if trial["status"] == "searching" else []),
    }
    what = f"trial {trial['trial']} after {trial['searched']}"
    v.within(STATE_SHOWN, expected, what=what, budget_ms=budget_ms)
    check_colours(v, view["likelihoods"])
    # What the robot saw in each container it searched is listed beside the plan.
    for o in view["observations"]:
        item = v.page.inner_text(f'#searched-list li[data-container="{o["container"]}"]')
        assert all(obj in item for obj in o["objects"]), (o, item)
        assert ("found" in item) == o["found"], (o, item)
    return view


def check_colours(v, likelihoods):
    """Each container's colour is its likelihood's: equal likelihoods alike, different ones
    told apart, grey for a strategy without likelihoods."""
    pairs = v.page.evaluate(COLOURS)
    if likelihoods is None:
        assert all(p == "none" and fill == "#c4c8cf" for p, fill in pairs), pairs
        return
    by_p = {}
    for p, fill in pairs:
        by_p.setdefault(float(p), set()).add(fill)
    assert all(len(fills) == 1 for fills in by_p.values()), by_p
    ps = sorted(by_p)
    for a, b in zip(ps, ps[1:]):
        if b - a > 0.01:
            assert by_p[a] != by_p[b], f"likelihoods {a} and {b} share a colour"


def expect_selection(v, api, trial):
    """After a trial ends: its mark on the selection curve and the strategy table updated."""
    dep = api.get(f"/deployments/{seg(trial['deployment'])}")
    rows = [[r["strategy"], r["deployed"], fmt(r["mean_cost_m"])] for r in dep["per_strategy"]]
    expected = {
        "k": trial["k"],
        "trial": trial["trial"],
        "strategy": trial["strategy"],
        "status": trial["status"],
        "cost": trial["cost_m"],
        "rows": rows,
    }
    v.within(SELECTION_SHOWN, expected, what=f"selection after trial {trial['trial']}")


def test_a_robots_search_shows_live(serve, view):
    server = serve()
    v = view(server).open()
    # Asked without a token first; the server wants one, so the page asks for it.
    v.page.wait_for_selector("#auth-error", state="visible", timeout=5000)
    assert "needs a token" in v.page.inner_text("#auth-error")
    assert v.count("[data-container]") == 0
    v.enter_token(TOKEN)
    v.wait_live()
    # No deployment yet: the scene's plan with grey containers.
    v.within(
        "() => document.querySelectorAll('#plan g.container').length === 9",
        what="plan",
        budget_ms=LOAD_MS,
    )
    assert "No deployment yet" in v.page.inner_text("#deployment-summary")

    robot = Robot(server.api)
    # UCB tries every strategy early, so the selection curve has a mark in each row.
    dep = robot.deploy(
        strategies=["model/prior", "model/uniform", "optimistic+greedy"], selector="ucb"
    )
    v.within(
        """(id) => document.querySelector("#deployment-card").dataset.deployment === String(id)
            && !!document.querySelector(`#deployment-select option[value="${id}"]`)
            && document.querySelectorAll("#strategy-table tbody tr").length === 3""",
        dep["id"],
        what="the new deployment",
    )

    shots = set()
    ended = []
    for target in TARGETS[:6]:
        trial = robot.start(dep["id"], target)
        assert trial["status"] == "searching"
        expect_trial(v, server.api, trial)
        while trial["status"] == "searching":
            trial = robot.search_next(trial)
            view_ = expect_trial(v, server.api, trial)
            if (
                "trial" not in shots
                and trial["status"] == "searching"
                and len(trial["searched"]) >= 2
                and len(set((view_["likelihoods"] or {}).values())) > 2
            ):
                v.shot("serve-view-trial.png")
                shots.add("trial")
        assert trial["status"] == "done"
        expect_selection(v, server.api, trial)
        # The finished trial stays in view, with what every other strategy would have cost.
        replays = set(trial["replays_m"]) | {trial["strategy"]}
        v.within(
            """(names) => {
                const rows = [...document.querySelectorAll("#replays tbody tr")];
                return !document.querySelector("#replays-box").hidden
                    && rows.map((r) => r.dataset.strategy).sort().join() === names.join();
            }""",
            sorted(replays),
            what=f"replays of trial {trial['trial']}",
        )
        # Every column says what it holds (the third, the difference to the deployed
        # strategy's cost, had no header).
        headers = v.page.eval_on_selector_all(
            "#replays thead th", "(ths) => ths.map((t) => t.textContent)"
        )
        assert len(headers) == 3 and all(h.strip() for h in headers), headers
        ended.append(trial)

    # A trial in progress, and an earlier one picked on the selection curve.
    trial = robot.start(dep["id"], TARGETS[6])
    trial = robot.search_next(trial)
    expect_trial(v, server.api, trial)
    pick = ended[2]
    v.page.click(f'#selection-curve [data-k="{pick["k"]}"]')
    v.within(
        """(id) => document.querySelector("#plan-card").dataset.trial === String(id)
            && !document.querySelector("#replays-box").hidden
            && !document.querySelector("#follow-box").hidden""",
        pick["trial"],
        what="the trial clicked on the curve",
    )
    # Watching a trial picked by hand: the robot's next search does not take the view away.
    trial = robot.search_next(trial) if trial["status"] == "searching" else trial
    v.page.wait_for_timeout(300)
    assert v.attr("#plan-card", "data-trial") == str(pick["trial"])
    v.shot("serve-view-deployment.png")
    v.page.click("#follow")
    expect_trial(v, server.api, trial)
    assert {"trial"} <= shots


# The page names every target of a task, found or not, and marks the destination on the plan;
# once the goal holds, the route ends there.
TASK_SHOWN = """(e) => {
  const card = document.querySelector("#plan-card");
  if (card.dataset.trial !== String(e.trial) || card.dataset.status !== e.status) return false;
  if (!document.querySelector("#trial-title").textContent.includes(e.title)) return false;
  const named = [...document.querySelectorAll("#fact-target [data-target]")];
  if (named.map((n) => n.dataset.target).join() !== e.targets.join()) return false;
  for (const n of named) {
    if (n.dataset.foundIn !== (e.found_in[n.dataset.target] || "")) return false;
  }
  const dest = document.querySelector("#destination");
  if (!dest || dest.dataset.kind !== e.kind) return false;
  if (!document.querySelector("#fact-destination")) return false;
  const route = document.querySelector("#route");
  return (route ? Number(route.dataset.points) : 0) === (e.route > 1 ? e.route : 0);
}"""


def test_a_task_shows_every_target_and_the_destination(serve, view):
    server = serve()
    v = view(server).open(token=TOKEN)
    v.wait_live()
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["model/prior", "optimistic+greedy"])
    trial = robot.start_task(
        dep["id"], ["Wallet", "Tomato", "Vase"], destination={"kind": "room", "name": "bedroom"}
    )
    while True:
        shown = server.api.get(f"/trials/{seg(trial['trial'])}/view")
        expected = {
            "trial": trial["trial"],
            "status": trial["status"],
            "title": "all of Wallet, Tomato, Vase, then to the bedroom",
            "targets": trial["targets"],
            "found_in": trial["found_in"],
            "kind": "room",
            "route": len(shown["route"]),
        }
        v.within(TASK_SHOWN, expected, what=f"task trial after {trial['searched']}")
        if len(trial["found_in"]) == 1:
            v.shot("serve-view-task.png")
        if trial["status"] != "searching":
            break
        trial = robot.search_next(trial)
    assert trial["status"] == "done" and len(trial["found_in"]) == 3
    # The route ends where the destination is, and the trial's cost counts the way there.
    assert shown["route"][-1] == trial["destination"]["path"][-1]
    assert trial["destination"]["distance_m"] > 0
    v.check_clean()


TEAM_SHOWN = """(e) => {
  const card = document.querySelector("#plan-card");
  if (card.dataset.trial !== String(e.trial) || card.dataset.status !== e.status) return false;
  // Every robot named on the plan, where the server says it is, with its way so far.
  const marks = [...document.querySelectorAll("#plan .team-robot")];
  if (marks.map((m) => m.dataset.robot).join() !== e.robots.join()) return false;
  for (const r of e.robots) {
    const way = document.querySelector(`#plan .robot-route[data-robot="${r}"]`);
    if ((way ? Number(way.dataset.points) : 0) !== e.points[r]) return false;
    const claim = document.querySelector(`#plan .claim-path[data-robot="${r}"]`);
    if ((claim ? claim.dataset.container : "") !== e.claims[r]) return false;
    const badge = document.querySelector(`#fact-robots [data-robot="${r}"]`);
    if (!badge || badge.dataset.claim !== e.claims[r]) return false;
  }
  // One robot's single route and proposal are not drawn for a team.
  return !document.querySelector("#route") && !document.querySelector("#next-path");
}"""


def test_a_team_shows_every_robot_its_way_and_its_claim(serve, view):
    server = serve()
    v = view(server).open(token=TOKEN)
    v.wait_live()
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["model/prior"])
    team = ["kitchen-bot", "hall-bot", "upstairs-bot"]
    trial = server.api.post(
        f"/deployments/{seg(dep['id'])}/trials",
        {"scene": "apartment", "target": "Wallet", "robots": [{"id": r} for r in team]},
    )
    tid = seg(trial["trial"])
    heading = {}
    for r in team:
        reply = server.api.post(f"/trials/{tid}/claims", {"robot": r})
        heading[r] = reply["next"]["container"] if reply["next"] else None
    turn = 0
    while True:
        shown = server.api.get(f"/trials/{tid}/view")
        state = shown["trial"]
        expected = {
            "trial": state["trial"],
            "status": state["status"],
            "robots": team,
            "points": {
                r["id"]: (len(r["route"]) if len(r["route"]) > 1 else 0)
                for r in shown["robot_routes"]
            },
            "claims": {
                r["id"]: (r["claim"] if r["claim"] and rr["claim_path"] else "")
                for r, rr in zip(state["robots"], shown["robot_routes"])
            },
        }
        v.within(TEAM_SHOWN, expected, what=f"team trial after {state['searched']}")
        if len(state["searched"]) == 2:
            v.shot("serve-view-team.png")
        if state["status"] != "searching":
            break
        movers = [r for r in team if heading.get(r)]
        assert movers, state
        r = movers[turn % len(movers)]
        turn += 1
        c = heading[r]
        seen = robot.contents[c]
        reply = server.api.post(
            f"/trials/{tid}/observations",
            {"robot": r, "container": c, "found": "Wallet" in seen, "objects": seen},
        )
        heading[r] = reply["next"]["container"] if reply["next"] else None
    assert state["status"] == "done"
    assert sum(1 for r in state["robots"] if r["searched"]) >= 2, state
    v.check_clean()


def test_the_page_asks_only_for_what_changed(serve, view):
    server = serve()
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["model/prior", "model/uniform"])
    v = view(server).open(TOKEN)
    v.wait_live()
    v.page.wait_for_selector(f'#deployment-card[data-deployment="{dep["id"]}"]', timeout=2000)
    # Once it shows a deployment, the page's stream carries only that deployment's events.
    v.page.wait_for_selector(f'#connection[data-stream="{dep["id"]}"]', timeout=2000)
    v.page.wait_for_timeout(300)
    trial = robot.start(dep["id"], "Wallet")
    expect_trial(v, server.api, trial)
    v.page.wait_for_timeout(300)

    def gets_since(t):
        return [
            u.split("/", 3)[3]
            for ts, m, u in v.requests
            if ts >= t and m == "GET" and "/ui/" not in u
        ]

    loaded = gets_since(0)
    # The first try without a token (refused: 401), then with it.
    assert sorted(loaded) == sorted(
        [
            "",
            "events",
            "events",
            "scenes",
            "deployments",
            f"deployments/{dep['id']}",
            f"events?deployment={dep['id']}",
            "scenes/apartment",
            f"trials/{trial['trial']}/view",
        ]
    ), loaded
    # Each observation comes with its event, which is enough to draw it: nothing is asked. The
    # end brings the trial's replays and the deployment's new scores.
    while trial["status"] == "searching":
        t = time.monotonic()
        trial = robot.search_next(trial)
        expect_trial(v, server.api, trial)
        v.page.wait_for_timeout(600)
        asked = gets_since(t)
        if trial["status"] == "searching":
            assert asked == [], asked
        else:
            assert sorted(asked) == sorted(
                [f"trials/{trial['trial']}/view", f"deployments/{dep['id']}"]
            ), asked
    # Nothing happens: nothing is asked.
    t = time.monotonic()
    v.page.wait_for_timeout(2000)
    assert gets_since(t) == [], "the page polls"
    assert not [r for r in v.requests if r[1] != "GET"], "the page wrote"


def test_a_robot_off_the_proposal_and_a_search_given_up_show_too(serve, view):
    server = serve()
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["model/prior"])
    v = view(server).open(TOKEN)
    v.page.wait_for_selector(f'#connection[data-stream="{dep["id"]}"]', timeout=5000)
    trial = robot.start(dep["id"], "Wallet")
    expect_trial(v, server.api, trial)
    # The robot searches another container than the one proposed: the event's way does not
    # lead there, so the page reads the trial again.
    other = next(c for c in robot.contents if c != trial["next"]["container"])
    seen = robot.contents[other]
    trial = server.api.post(
        f"/trials/{trial['trial']}/observations",
        {"container": other, "found": "Wallet" in seen, "objects": seen},
    )
    expect_trial(v, server.api, trial)
    if trial["status"] == "searching":
        trial = robot.search_next(trial)
        expect_trial(v, server.api, trial)
    if trial["status"] == "searching":
        trial = server.api.post(f"/trials/{trial['trial']}/abandon", {})
        assert trial["status"] == "abandoned"
        expect_trial(v, server.api, trial)
        v.within(
            """(id) => document.querySelector("#trial-status").textContent === "abandoned"
                && !!document.querySelector(`#selection-curve [data-trial="${id}"]`
                    + `[data-status="abandoned"]`)""",
            trial["trial"],
            what="the trial given up",
        )


def test_a_wrong_token_shows_the_refusal_and_no_data(serve, view):
    server = serve()
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["model/prior", "model/uniform"])
    trial = robot.finish(robot.start(dep["id"], "Book"))
    robot.search_next(robot.start(dep["id"], "Wallet"))
    v = view(server).open(TOKEN)
    v.wait_live()
    v.within(
        "() => document.querySelectorAll('#plan g.container').length === 9",
        what="plan",
        budget_ms=LOAD_MS,
    )
    v.within(
        "() => document.querySelectorAll('#selection-curve [data-k]').length === 2",
        budget_ms=LOAD_MS,
    )
    # The token lives in this tab's sessionStorage only, never in the URL or localStorage.
    stored = v.page.evaluate("() => [sessionStorage.length, localStorage.length, location.href]")
    assert stored[:2] == [1, 0] and TOKEN not in stored[2], stored

    v.page.click("#token-button")
    v.enter_token("not-the-token")
    v.page.wait_for_selector("#auth-error", state="visible", timeout=1000)
    assert "the server refused this token" in v.page.inner_text("#auth-error").lower()
    assert v.attr("#connection", "data-state") == "refused"

    def nothing_shown():
        for what, sel in EMPTY.items():
            assert v.count(sel) == 0, f"{what} still shown after a refusal"
        assert v.page.is_hidden("#view")
        body = v.page.inner_text("body")
        assert "Wallet" not in body and "model/prior" not in body, body

    nothing_shown()
    # The robot goes on; the refused page shows none of it, even after a reload.
    robot.finish(robot.api.get(f"/trials/{trial['trial'] + 1}"))
    v.page.wait_for_timeout(500)
    nothing_shown()
    v.page.reload()
    v.page.wait_for_selector("#auth-error", state="visible", timeout=5000)
    nothing_shown()
    # The right token brings it all back.
    v.enter_token(TOKEN)
    v.wait_live()
    v.within(
        "() => document.querySelectorAll('#selection-curve [data-k]').length === 2",
        budget_ms=LOAD_MS,
    )


def test_without_a_server_token_no_token_is_asked(serve, view):
    server = serve(token=None)
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["optimistic+greedy"])
    v = view(server).open()
    v.wait_live()
    assert v.page.is_hidden("#token-panel")
    trial = robot.start(dep["id"], "Mug")
    # optimistic+greedy plans without likelihoods: every container grey, the legend says why.
    view_ = expect_trial(v, server.api, trial)
    assert view_["likelihoods"] is None
    assert "without likelihoods" in v.page.inner_text("#legend")


def test_the_csp_is_served_and_a_violation_would_be_caught(serve, view):
    server = serve()
    for path in ("/", "/ui/app.js", "/ui/app.css"):
        # The page's files need no token: the data does.
        with urllib.request.urlopen(server.url + path) as resp:
            csp = resp.headers["Content-Security-Policy"]
        assert "script-src 'self'" in csp and "default-src 'none'" in csp, (path, csp)
    v = view(server).open(TOKEN)
    v.wait_live()
    assert not [m for m in v.console if "Content Security Policy" in m]
    # The check of every test sees a violation: an inline style, as a careless page would set.
    v.page.evaluate(
        "() => { document.body.insertAdjacentHTML('beforeend', '<b style=\"color:red\">x</b>'); }"
    )
    v.page.wait_for_timeout(200)
    assert [m for m in v.console if "Content Security Policy" in m], v.console
    v.console.clear()


def test_view_only_shows_the_page_and_refuses_writes(serve, view, tmp_path):
    db = str(tmp_path / "site.sqlite")
    writer = serve(db=db)
    robot = Robot(writer.api)
    dep = robot.deploy(strategies=["model/prior", "model/uniform"])
    robot.finish(robot.start(dep["id"], "Pillow"))
    open_trial = robot.search_next(robot.start(dep["id"], "Wallet"))
    writer.stop()

    wall = serve("--view-only", db=db)
    v = view(wall).open(TOKEN)
    v.wait_live()
    expect_trial(v, wall.api, open_trial, budget_ms=LOAD_MS)
    v.within(
        "() => document.querySelectorAll('#selection-curve [data-k]').length === 2",
        budget_ms=LOAD_MS,
    )
    status, body = wall.api.request(
        "POST", "/deployments", {"strategies": ["model/prior"], "selector": "replay"}
    )
    assert status == 403, (status, body)
    status, body = wall.api.request(
        "POST",
        f"/trials/{open_trial['trial']}/observations",
        {"container": open_trial["next"]["container"], "found": False, "objects": []},
    )
    assert status == 403, (status, body)


def test_a_trial_driven_through_another_replica_shows_live(serve, view, postgres_url):
    a = serve(db=postgres_url)
    b = serve(db=postgres_url)
    v = view(a).open(TOKEN)
    v.wait_live()
    v.page.wait_for_selector('#connection:text("every replica")', timeout=2000)
    robot = Robot(b.api)
    dep = robot.deploy(strategies=["model/prior", "model/uniform"])
    v.within(
        """(id) => document.querySelector("#deployment-card").dataset.deployment === String(id)""",
        dep["id"],
        what="a deployment made on the other replica",
    )
    trial = robot.start(dep["id"], "RemoteControl")
    expect_trial(v, a.api, trial)
    while trial["status"] == "searching":
        trial = robot.search_next(trial)
        expect_trial(v, b.api, trial)
    expect_selection(v, a.api, trial)

    # A fleet: two robots share the deployment, one on each replica; both open trials listed.
    other = Robot(a.api)
    t1 = robot.start(dep["id"], "Wallet")
    t2 = other.start(dep["id"], "Mug")
    v.within(
        """(ids) => [...document.querySelectorAll("#open-trials button[data-trial]")]
            .map((b) => Number(b.dataset.trial)).join() === ids.join()""",
        sorted([t1["trial"], t2["trial"]]),
        what="both robots' open trials",
    )
    v.page.click(f'#open-trials button[data-trial="{t2["trial"]}"]')
    expect_trial(v, a.api, t2, deployment_open=sorted([t1["trial"], t2["trial"]]))


def test_the_stream_reconnects_and_catches_up(serve, view, tmp_path):
    db = str(tmp_path / "site.sqlite")
    first = serve(db=db)
    port = first.url.rsplit(":", 1)[1]
    robot = Robot(first.api)
    dep = robot.deploy(strategies=["model/prior", "model/uniform"])
    v = view(first).open(TOKEN)
    v.wait_live()
    first.stop()
    v.page.wait_for_selector('#connection[data-state="reconnecting"]', timeout=2000)
    # While the page is cut off, a trial is run through another server on the same database.
    other = serve(db=db)
    done = Robot(other.api).finish(Robot(other.api).start(dep["id"], "Book"))
    other.stop()
    again = serve(db=db, listen=f"127.0.0.1:{port}")
    v.wait_live(timeout=20000)
    # Back: what happened meanwhile is fetched again.
    v.page.wait_for_selector(
        f'#selection-curve [data-trial="{done["trial"]}"][data-status="done"]', timeout=2000
    )
    trial = Robot(again.api).start(dep["id"], "Wallet")
    expect_trial(v, again.api, trial)


def test_past_the_cap_of_event_streams_a_page_still_shows_and_retries(serve, view):
    server = serve("--max-event-streams", "1")
    robot = Robot(server.api)
    dep = robot.deploy(strategies=["model/prior", "model/uniform"])
    robot.search_next(robot.start(dep["id"], "Wallet"))
    first = view(server).open(TOKEN)
    first.page.wait_for_selector(
        f'#connection[data-state="live"][data-stream="{dep["id"]}"]', timeout=5000
    )
    second = view(server).open(TOKEN)
    second.page.wait_for_selector('#connection[data-state="reconnecting"]', timeout=3000)
    second.within(
        "() => document.querySelectorAll('#plan g.container').length === 9", budget_ms=3000
    )
    # It retries with a growing backoff, not in a tight loop.
    second.page.wait_for_timeout(3000)
    tries = [u for _, _, u in second.requests if u.endswith("/events")]
    assert 1 < len(tries) <= 6, tries
    first.page.close()
    second.wait_live(timeout=20000)


def test_the_page_follows_a_fast_robot_to_its_last_trial(serve, view):
    """A deployment read that crossed a robot's last trials replaced what the events had shown:
    the page went back to an earlier trial and stayed there, still "live". After each of five
    runs of 20 trials without a pause, the page shows the last trial within a second."""
    server = serve()
    v = view(server).open(TOKEN)
    v.wait_live()
    robot = Robot(server.api)
    for run in range(5):
        dep = robot.deploy(strategies=["model/prior", "model/uniform"], selector="ucb")
        last = None
        for i in range(20):
            last = robot.finish(robot.start(dep["id"], TARGETS[i % len(TARGETS)]))
        v.within(
            """(e) => {
                const card = document.querySelector("#plan-card");
                return card.dataset.trial === String(e.trial) && card.dataset.status === e.status
                    && document.querySelector("#deployment-card").dataset.deployment
                        === String(e.deployment);
            }""",
            {"trial": last["trial"], "status": last["status"], "deployment": dep["id"]},
            what=f"run {run}: the last trial, {last['trial']} (k = {last['k']})",
            budget_ms=1000,
        )
    v.check_clean()
