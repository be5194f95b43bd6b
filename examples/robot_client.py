#!/usr/bin/env python3
"""A robot client for `ferret serve`: drives a *simulated* robot through a deployment over HTTP.

    ferret serve --scene examples/apartment/scene.yaml --strategies model/uniform,model/prior \\
        --prior prior.json --db ferret-serve.sqlite &
    python3 examples/robot_client.py --scene apartment \\
        --targets Blanket,CellPhone,RemoteControl,Pillow,Wallet

For each target it opens a trial, then repeats: ask where to search next, "drive" there, look
inside, report what was seen; until the target is found (`done`) or every container was searched
(`exhausted`). Stopped with Ctrl-C in the middle of a search, it tells the server it gave the
trial up (`abandoned`), so the trial is not left open. The simulated robot's eyes are the
`contents` of each container in the scene listing (GET /scenes/{name}). With `--pace 1` it waits
a second before each search, so that a person can follow it on the server's live view (open the
server's address in a browser).

With `--robot ID` the robot names itself in every trial it starts: the server's list then says
whose each trial is, the live view shows the robot and how long since it was last heard from, and
with `--deployment` the client finishes (or `--abandon-open` gives up) only an open trial of its
own, leaving other robots' trials alone. Give each robot sharing a deployment its own `--robot`;
a client without one takes up only an open trial no robot named.

With `--robot ID --team ID1,ID2,...` (and a shared `--deployment`) the client is one robot of a
team that searches each trial together: the team's first robot starts each trial naming the
team, the others join it; every robot asks for its own next container (`POST
/trials/{id}/claims`), which the server gives to no teammate, and reports with its id. Run one
client per robot, each with its own `--robot`.

On a real robot (a ROS node, say) only `search_container()` changes: send a navigation goal to the
proposal's `path` end / access point, run the detector, and report the object types it saw and the
odometry of the leg. Everything else (the request ids, the retries, the loop) stays as it is.

Standard library only (Python 3.8+). A bearer token is read from FERRET_SERVE_TOKEN when set.
"""

import argparse
import http.client
import json
import os
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid

DEFAULT_URL = "http://127.0.0.1:8080"
TIMEOUT_S = 30  # per request; the planner answers in milliseconds, LLM strategies can take longer
RETRY_DELAYS_S = (0.5, 1.0, 2.0, 4.0)  # between attempts on connection errors and 5xx


class ApiError(Exception):
    """The server refused a request (4xx, or 5xx after every retry)."""

    def __init__(self, method, path, status, field, message):
        super().__init__(message)
        self.method, self.path = method, path
        self.status, self.field, self.message = status, field, message

    def __str__(self):
        field = f" (field {self.field!r})" if self.field else ""
        return f"{self.method} {self.path} -> {self.status}{field}: {self.message}"


class Unreachable(Exception):
    """No answer from the server after every retry."""


class Client:
    """A tiny `ferret serve` client: JSON in and out, bearer token, retries with the same
    request id (the server stores the reply of each `request_id`, so a repeated POST returns the
    first reply and changes nothing: a dropped connection or a server restart is harmless)."""

    def __init__(self, url, token=None, delays=RETRY_DELAYS_S, timeout=TIMEOUT_S, log=None):
        self.url = url.rstrip("/")
        self.token = token
        self.delays = tuple(delays)
        self.timeout = timeout
        self.log = log or (lambda msg: None)

    def get(self, path):
        return self._send("GET", path, None)

    def post(self, path, body):
        """POSTs `body` plus a fresh `request_id`; every retry sends the same bytes."""
        body = dict(body, request_id=str(uuid.uuid4()))
        return self._send("POST", path, body)

    def _send(self, method, path, body):
        data = None if body is None else json.dumps(body).encode("utf-8")
        headers = {"Accept": "application/json"}
        if data is not None:
            headers["Content-Type"] = "application/json"
        if self.token:
            headers["Authorization"] = "Bearer " + self.token
        last = None
        for attempt in range(len(self.delays) + 1):
            if attempt:
                delay = self.delays[attempt - 1]
                self.log(f"retrying {method} {path} in {delay:g} s ({last})")
                time.sleep(delay)
            req = urllib.request.Request(self.url + path, data=data, headers=headers, method=method)
            try:
                with urllib.request.urlopen(req, timeout=self.timeout) as resp:
                    raw = resp.read()
                return json.loads(raw) if raw else None
            except urllib.error.HTTPError as e:
                err = self._api_error(method, path, e)
                if e.code >= 500:  # the server's fault: it may be restarting; try again
                    last = err
                    continue
                raise err
            except (OSError, http.client.HTTPException) as e:
                # Refused, reset, timed out, the server closed the connection mid-reply...
                last = getattr(e, "reason", e)
                continue
        if isinstance(last, ApiError):
            raise last
        raise Unreachable(
            f"no answer from {self.url} ({method} {path}) after "
            f"{len(self.delays) + 1} attempts: {last}"
        )

    @staticmethod
    def _api_error(method, path, e):
        """The server's JSON error {"error": {"status", "field", "message"}}, or the raw body."""
        try:
            raw = e.read().decode("utf-8", "replace")
        except Exception:  # noqa: BLE001 - a broken body must not hide the status
            raw = ""
        try:
            err = json.loads(raw)["error"]
            return ApiError(
                method, path, err.get("status", e.code), err.get("field"), err.get("message", raw)
            )
        except (ValueError, KeyError, TypeError, AttributeError):
            return ApiError(method, path, e.code, None, raw.strip()[:500] or e.reason)


def quote(segment):
    """A path segment: scene names may hold '#', '/', spaces (`multiroom-val150.jsonl.gz#3`)."""
    return urllib.parse.quote(str(segment), safe="")


def search_container(proposal, scene_containers, target):
    """The simulated robot: drives to the proposed container and looks inside.

    Returns (container id actually searched, object types seen, metres travelled). A real robot
    navigates to the proposal's access point (the last point of `proposal["path"]`), runs its
    detector and reports its own odometry; it may also search another container than proposed.
    """
    cid = proposal["container"]
    if cid not in scene_containers:
        raise SystemExit(
            f"error: the server proposed container {cid!r}, which the scene listing does not have"
        )
    seen = list(scene_containers[cid].get("contents") or [])
    return cid, seen, proposal.get("distance_m")


def open_trial_id(state, robot=None):
    """The first of the deployment's open trials that is this robot's: one it started naming
    itself `robot`, or with no robot one that no robot named. Another robot's trial is never
    taken over."""
    for t in state.get("trials") or []:
        if t.get("status") == "searching" and t.get("robot") == robot:
            return t.get("trial")
    return None


def run_trial(api, trial_id, target, strategy, reply, containers, log, pace=0.0):
    """Searches until the trial ends. `reply` is the reply that opened (or resumed) the trial;
    returns the trial's summary for the output. `pace` seconds pass before each search, as a
    real robot's drive would take."""
    searched = []
    status = reply.get("status", "searching")
    # The server ends a trial itself after at most one search per container; the bound only
    # guards this loop against a misbehaving server.
    for _ in range(len(containers) + 1):
        if status in ("done", "exhausted", "abandoned"):
            break
        proposal = reply.get("next")
        if not proposal:
            raise SystemExit(
                f"error: trial {trial_id} is {status!r} but the server proposed no container"
            )
        time.sleep(pace)
        cid, seen, travelled = search_container(proposal, containers, target)
        found = target in seen
        log(
            f"  trial {trial_id}: {cid} ({proposal.get('type')}, {proposal.get('room')}) "
            f"{fmt_m(proposal.get('distance_m'))} m: {'FOUND' if found else 'not there'}"
        )
        obs = {"container": cid, "found": found, "objects": seen}
        if travelled is not None:
            obs["travelled_m"] = travelled
        reply = api.post(f"/trials/{quote(trial_id)}/observations", obs)
        searched.append(cid)
        status = reply.get("status")
    else:
        raise SystemExit(f"error: trial {trial_id} did not end after searching every container")
    return {
        "trial": trial_id,
        "target": target,
        "strategy": strategy,
        "cost_m": reply.get("cost_m"),
        "searched": searched,
        "status": status,
    }


def join_team_trial(api, dep, target, me, after_k, log, wait_s=60.0):
    """The trial of deployment `dep` that the team's first robot started for `target` naming
    robot `me`, started after trial number `after_k`: waits for it up to `wait_s` seconds."""
    deadline = time.monotonic() + wait_s
    while True:
        state = api.get(f"/deployments/{quote(dep)}")
        for t in state.get("trials") or []:
            if t.get("k", 0) <= after_k or t.get("target") != target:
                continue
            trial = api.get(f"/trials/{quote(t['trial'])}")
            if any(r.get("id") == me for r in trial.get("robots") or []):
                return trial
        if time.monotonic() > deadline:
            raise SystemExit(
                f"error: robot {me}: no trial for {target} naming it in deployment {dep} after "
                f"{wait_s:g} s (is the team's first robot running with the same --team?)"
            )
        log(f"robot {me}: waiting for the team's trial for {target}")
        time.sleep(0.05)


def run_team_trial(api, trial, me, containers, log, pace=0.0):
    """Robot `me`'s part of team trial `trial` (its state): claims a container, searches it,
    reports it with its id, until the trial ends. Returns the trial's summary with the
    containers this robot searched."""
    trial_id, target = trial["trial"], trial["target"]
    claim_path = f"/trials/{quote(trial_id)}/claims"
    reply = api.post(claim_path, {"robot": me})
    searched = []
    # The server ends a trial once its goal holds or every container was searched; waits for
    # teammates are bounded by the server's claim time, searches by the containers.
    for _ in range(100 * (len(containers) + 1)):
        if reply.get("status") != "searching":
            break
        proposal = reply.get("next")
        if not proposal:
            # Everything left is a teammate's: ask again in a moment.
            time.sleep(0.1)
            reply = api.post(claim_path, {"robot": me})
            continue
        time.sleep(pace)
        cid, seen, travelled = search_container(proposal, containers, target)
        found = target in seen
        log(f"  trial {trial_id} robot {me}: {cid}: {'FOUND' if found else 'not there'}")
        obs = {"robot": me, "container": cid, "found": found, "objects": seen}
        if travelled is not None:
            obs["travelled_m"] = travelled
        try:
            reply = api.post(f"/trials/{quote(trial_id)}/observations", obs)
            searched.append(cid)
        except ApiError as e:
            if e.status != 409:
                raise
            # The trial ended meanwhile (a teammate found it), or a teammate got there first
            # (this robot's claim had lapsed): read where it stands.
            log(f"  trial {trial_id} robot {me}: {e.message}")
            reply = api.post(claim_path, {"robot": me})
    mine = next((r for r in reply.get("robots") or [] if r.get("id") == me), {})
    return {
        "trial": trial_id,
        "target": target,
        "strategy": reply.get("strategy"),
        "cost_m": mine.get("cost_m"),
        "searched": searched,
        "status": reply.get("status"),
        "team_cost_m": reply.get("cost_m"),
        "k": reply.get("k"),
    }


def resume_open_trial(api, trial_id, containers, log, pace=0.0):
    """Finishes a trial left open (the client stopped mid-trial). GET /trials/{id} gives the trial
    so far; its `next` is the container still to search."""
    trial = api.get(f"/trials/{quote(trial_id)}")
    target, strategy = trial.get("target"), trial.get("strategy")
    if not target or not trial.get("next"):
        raise SystemExit(
            f"error: deployment has an open trial {trial_id} that this client cannot "
            f"resume (GET /trials/{trial_id} gave no target or no next container)"
        )
    log(f"resuming open trial {trial_id} ({target}, {strategy})")
    summary = run_trial(api, trial_id, target, strategy, trial, containers, log, pace)
    # The searches made before the client stopped count too.
    before = [s.get("container") if isinstance(s, dict) else s for s in trial.get("searched") or []]
    summary["searched"] = [c for c in before if c] + summary["searched"]
    return summary


def fmt_m(v):
    if v is None:
        return "-"
    return f"{v:.2f}" if isinstance(v, (int, float)) else str(v)


TRIAL_HEADER = f"{'k':>3}  {'trial':>5}  {'target':<14} {'strategy':<28} {'cost_m':>7}  searched"


def print_trial(k, t):
    """One line per trial, printed as it ends."""
    if k == 1:
        print(TRIAL_HEADER)
    note = "" if t["status"] == "done" else f"  ({t['status']})"
    print(
        f"{k:>3}  {t['trial']!s:>5}  {t['target']:<14} {t['strategy'] or '-':<28} "
        f"{fmt_m(t['cost_m']):>7}  {', '.join(t['searched']) or '-'}{note}",
        flush=True,
    )


def print_state(state):
    """The deployment's per-strategy table (GET /deployments/{id})."""
    print()
    print(
        f"deployment {state.get('id')}: selector {state.get('selector')}, c {state.get('c')}, "
        f"seed {state.get('seed')}, {len(state.get('trials') or [])} trials"
    )
    print(
        f"{'strategy':<28} {'deployed':>8} {'mean_cost_m':>11} {'replay_mean_m':>13} {'score':>8}"
    )
    for s in state.get("per_strategy") or []:
        print(
            f"{s.get('strategy', '?'):<28} {s.get('deployed', 0):>8} "
            f"{fmt_m(s.get('mean_cost_m')):>11} {fmt_m(s.get('replay_mean_m')):>13} "
            f"{fmt_m(s.get('score')):>8}"
        )
    nxt = state.get("next")
    if nxt:
        print(f"next: {nxt.get('strategy')} ({nxt.get('why')})")


def parse_args(argv):
    ap = argparse.ArgumentParser(
        description="Drive a simulated robot through a ferret serve deployment."
    )
    ap.add_argument("--url", default=DEFAULT_URL, help=f"server (default {DEFAULT_URL})")
    ap.add_argument("--scene", required=True, help="scene name, as GET /scenes lists it")
    ap.add_argument(
        "--targets",
        required=True,
        help="comma-separated object types, one trial each, in order "
        "(e.g. Blanket,CellPhone,RemoteControl,Pillow,Wallet)",
    )
    ap.add_argument(
        "--strategies", help="comma-separated candidate strategies (default: all of the server's)"
    )
    ap.add_argument("--selector", choices=("replay", "ucb"), default="replay")
    ap.add_argument("--c", type=float, default=5.0, help="UCB exploration constant (default 5.0)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--deployment",
        help="continue this deployment instead of creating one (--strategies, "
        "--selector, --c and --seed are then the deployment's own); a trial it "
        "has open is finished first and counts for its target if that is in "
        "--targets",
    )
    ap.add_argument(
        "--abandon-open",
        action="store_true",
        help="with --deployment: give up the trial it has open (POST "
        "/trials/{id}/abandon) instead of finishing it",
    )
    ap.add_argument(
        "--robot",
        help="this robot's id (1 to 64 letters, digits, _ - . /): it names the robot in the "
        "trials it starts, and with --deployment only its own open trial is taken up; with "
        "--team, its id in the team",
    )
    ap.add_argument(
        "--team",
        help="comma-separated ids of the team that searches each trial together, this "
        "robot's among them; the first starts the trials. Needs --deployment",
    )
    ap.add_argument(
        "--pace",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="wait this long before each search and after each trial, so that a person can "
        "follow the search on the live view (http://<server>/); default 0",
    )
    ap.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object with the results instead of the table",
    )
    ap.add_argument(
        "-v", "--verbose", action="store_true", help="log each search and retry to stderr"
    )
    args = ap.parse_args(argv)
    if not 0 <= args.pace <= 3600:
        ap.error("--pace is 0 to 3600 seconds")
    args.targets = [t.strip() for t in args.targets.split(",") if t.strip()]
    if not args.targets:
        ap.error("--targets names no object type")
    if args.strategies is not None:
        args.strategies = [s.strip() for s in args.strategies.split(",") if s.strip()]
        if not args.strategies:
            ap.error("--strategies names no strategy")
    if args.team is not None and args.robot is None:
        ap.error("--team needs --robot: this robot's id in the team")
    if args.team is not None:
        args.team = [r.strip() for r in args.team.split(",") if r.strip()]
        if args.robot not in args.team:
            ap.error(f"--robot {args.robot!r} is not in --team {','.join(args.team)}")
        if len(set(args.team)) != len(args.team):
            ap.error("--team names a robot twice")
        if not args.deployment:
            ap.error("--team needs --deployment: the team's robots share one")
    return args


def run(args, log):
    api = Client(args.url, token=os.environ.get("FERRET_SERVE_TOKEN") or None, log=log)

    scene = api.get(f"/scenes/{quote(args.scene)}")
    containers = {c["id"]: c for c in scene.get("containers") or []}
    if not containers:
        raise SystemExit(f"error: scene {args.scene!r} lists no containers")
    log(f"scene {args.scene}: {len(containers)} containers")

    if args.deployment:
        state = api.get(f"/deployments/{quote(args.deployment)}")
        log(f"continuing deployment {state.get('id', args.deployment)}")
    else:
        body = {"selector": args.selector, "c": args.c, "seed": args.seed}
        if args.strategies is not None:
            body["strategies"] = args.strategies
        state = api.post("/deployments", body)
        log(f"created deployment {state.get('id')}: {', '.join(state.get('strategies') or [])}")
    dep = state["id"]

    trials = []
    targets = list(args.targets)
    # A team's robots find their trials by the team's names (join_team_trial), not as the
    # deployment's open trial.
    open_id = open_trial_id(state, args.robot) if args.team is None else None
    if open_id is not None and args.abandon_open:
        t = api.post(f"/trials/{quote(open_id)}/abandon", {})
        log(f"gave up open trial {open_id} ({t.get('target')}, {t.get('strategy')})")
        trials.append(
            {
                "trial": open_id,
                "target": t.get("target"),
                "strategy": t.get("strategy"),
                "cost_m": t.get("cost_m"),
                "searched": list(t.get("searched") or []),
                "status": t.get("status"),
            }
        )
        if not args.json:
            print_trial(len(trials), trials[-1])
    elif open_id is not None:
        summary = resume_open_trial(api, open_id, containers, log, args.pace)
        trials.append(summary)
        if summary["target"] in targets:
            targets.remove(summary["target"])
        if not args.json:
            print_trial(len(trials), summary)

    if args.team is not None:
        after_k = 0
        for target in targets:
            if args.robot == args.team[0]:
                trial = api.post(
                    f"/deployments/{quote(dep)}/trials",
                    {
                        "scene": args.scene,
                        "target": target,
                        "robots": [{"id": r} for r in args.team],
                    },
                )
                log(f"trial {trial['trial']}: {target}, team {','.join(args.team)}")
            else:
                trial = join_team_trial(api, dep, target, args.robot, after_k, log)
            summary = run_team_trial(api, trial, args.robot, containers, log, args.pace)
            after_k = summary.get("k") or after_k
            trials.append(summary)
            if not args.json:
                print_trial(len(trials), summary)
        return dep, trials, api.get(f"/deployments/{quote(dep)}")

    for target in targets:
        # No pose: the robot starts from the scene's start pose. A real robot sends its
        # localisation as "pose": [x, y, yaw_deg].
        body = {"scene": args.scene, "target": target}
        if args.robot is not None:
            body["robot"] = args.robot
        reply = api.post(f"/deployments/{quote(dep)}/trials", body)
        trial_id = reply["trial"]
        log(f"trial {trial_id}: {target} with {reply.get('strategy')}")
        try:
            summary = run_trial(
                api, trial_id, target, reply.get("strategy"), reply, containers, log, args.pace
            )
        except KeyboardInterrupt:
            # Stopped mid-search: the trial is given up rather than left open. Best effort:
            # without the server, the next run with --deployment resumes it instead.
            try:
                api.post(f"/trials/{quote(trial_id)}/abandon", {})
                print(f"stopped: trial {trial_id} abandoned", file=sys.stderr)
            except (ApiError, Unreachable) as e:
                print(f"stopped: trial {trial_id} left open ({e})", file=sys.stderr)
            raise
        trials.append(summary)
        if not args.json:
            print_trial(len(trials), summary)
        time.sleep(args.pace)

    state = api.get(f"/deployments/{quote(dep)}")
    return dep, trials, state


def main(argv=None):
    args = parse_args(argv)
    log = (
        (lambda msg: print(msg, file=sys.stderr, flush=True))
        if args.verbose
        else (lambda msg: None)
    )
    try:
        dep, trials, state = run(args, log)
    except ApiError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    except Unreachable as e:
        print(f"error: {e}; is `ferret serve` running there?", file=sys.stderr)
        return 2
    except (KeyError, TypeError, ValueError) as e:
        print(f"error: unexpected reply from {args.url}: {e!r}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    if args.json:
        json.dump({"deployment": dep, "trials": trials, "state": state}, sys.stdout, indent=2)
        print()
    else:
        print_state(state)
    return 0


if __name__ == "__main__":
    sys.exit(main())
