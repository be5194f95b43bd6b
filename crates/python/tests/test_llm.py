"""LLM strategies through the command line's endpoint configuration and response cache, against
a stand-in OpenAI-compatible endpoint on 127.0.0.1 (started and stopped by the test)."""

import hashlib
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

import ferret
from conftest import HOUSE_SEED, HOUSES, read_trials, run_cli


class Endpoint(BaseHTTPRequestHandler):
    """Answers every chat completion Yes or No, by a hash of the question (so that containers
    get different probabilities), and counts the requests."""

    requests = 0

    def do_POST(self):
        body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
        type(self).requests += 1
        question = json.dumps(body["messages"], sort_keys=True).encode()
        answer = "Yes" if hashlib.sha256(question).digest()[0] % 3 == 0 else "No"
        reply = json.dumps(
            {
                "id": "stand-in",
                "object": "chat.completion",
                "created": 1_752_000_000,
                "model": body.get("model", "stand-in"),
                "choices": [
                    {
                        "index": 0,
                        "finish_reason": "stop",
                        "message": {"role": "assistant", "content": answer},
                    }
                ],
                "usage": {"prompt_tokens": 10, "completion_tokens": 1, "total_tokens": 11},
            }
        ).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(reply)))
        self.end_headers()
        self.wfile.write(reply)

    def log_message(self, *args):
        pass


@pytest.fixture()
def endpoint(tmp_path):
    server = ThreadingHTTPServer(("127.0.0.1", 0), Endpoint)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    Endpoint.requests = 0
    config = tmp_path / "ferret.toml"
    config.write_text(
        f'[llm.stand-in]\nbase_url = "http://127.0.0.1:{server.server_port}/v1"\nmodel = "m"\n'
    )
    yield config
    server.shutdown()
    server.server_close()
    thread.join()


def test_llm_strategy_matches_ferret_eval_through_the_shared_cache(
    endpoint, tmp_path, houses, ferret_bin
):
    cache = tmp_path / "answers.sqlite"
    specs = ["llm+model/p-yesno/stand-in", "model/uniform"]
    ev = ferret.evaluate(houses[:4], specs, config=endpoint, llm_cache=cache, seed=1)
    asked = Endpoint.requests
    assert asked > 0 and cache.is_file()
    llm_rows = [r for r in ev.rows if r["strategy"] == specs[0]]
    assert len(llm_rows) == 4
    # The command line answers from the same cache, offline: nothing is asked again.
    run_cli(
        ferret_bin,
        "eval",
        "--generate",
        str(HOUSES),
        "--house-seed",
        str(HOUSE_SEED),
        "--range",
        "0..4",
        "--strategies",
        ",".join(specs),
        "--seed",
        "1",
        "--config",
        str(endpoint),
        "--llm-cache",
        str(cache),
        "--offline",
        "--out",
        str(tmp_path / "out"),
        cwd=tmp_path,
    )
    assert Endpoint.requests == asked
    cli = read_trials(tmp_path / "out" / "trials.csv")
    assert [(c["strategy"], float(c["cost_m"]), c["searched"]) for c in cli] == [
        (r["strategy"], r["cost_m"], r["searched"]) for r in ev.rows
    ]
    # The LLM's probabilities are really used: some trial plans differently from uniform.
    uniform = [r["searched"] for r in ev.rows if r["strategy"] == "model/uniform"]
    assert [r["searched"] for r in llm_rows] != uniform
    # A Search over the cache, offline, makes the same decisions.
    row = llm_rows[2]
    house = houses[row["house_index"]]
    s = ferret.Search(
        house, row["target"], specs[0], config=endpoint, llm_cache=cache, offline=True
    )
    while (c := s.next_container()) is not None:
        s.record(c, row["target"] in house.contents(c), house.contents(c))
    assert s.cost == row["cost_m"] and " ".join(s.searched) == row["searched"]
    assert Endpoint.requests == asked


def test_a_search_asks_the_endpoint_without_holding_the_gil(endpoint, tmp_path, houses):
    # The stand-in endpoint is a Python thread of this process: were the GIL held while the
    # strategy asks, the search would wait for it forever.
    house = houses[1]
    target = house.target_types()[0]
    spec = "llm+model/p-yesno/stand-in"
    s = ferret.Search(house, target, spec, config=endpoint, llm_cache=tmp_path / "live.sqlite")
    while (c := s.next_container()) is not None:
        s.record(c, target in house.contents(c), house.contents(c))
    assert Endpoint.requests > 0
    ev = ferret.evaluate(
        [house], [spec], config=endpoint, llm_cache=tmp_path / "live.sqlite", trials_per_house="all"
    )
    [row] = [r for r in ev.rows if r["target"] == target]
    assert s.cost == row["cost_m"] and " ".join(s.searched) == row["searched"]
