"""A tune's Optuna storage in Optuna's own dashboard (docs/dashboard.md): the dashboard's app,
served on the loopback address, lists each task's draws and each arm's trials as studies, and
gives a trial's score at the end of each rung as its intermediate values, as the tune recorded
them. It reads a copy of the classic tasks' recorded tune, so nothing is trained and the record
is left as it is."""

from __future__ import annotations

import json
import shutil
import threading
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from wsgiref.simple_server import WSGIRequestHandler, WSGIServer, make_server

import pytest

import fppo_jax

TUNE = Path(__file__).resolve().parent.parent / "experiments" / "results" / "tuned" / "classic"
TUNE = TUNE / "tune"


class _Quiet(WSGIRequestHandler):
    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture(scope="module")
def dashboard(tmp_path_factory) -> Iterator[str]:
    """The dashboard's app on a copy of the recorded tune's storage, on 127.0.0.1 at a port the
    system picks; its address. Reading the storage there leaves the copy as it was."""
    optuna_dashboard = pytest.importorskip(  # imported here: a test process imports this file
        "optuna_dashboard", reason="optuna-dashboard is not installed: pip install -e '.[tune]'"
    )
    storage = tmp_path_factory.mktemp("tune") / "optuna.db"
    shutil.copyfile(TUNE / "optuna.db", storage)
    app = optuna_dashboard.wsgi(f"sqlite:///{storage}")
    server: WSGIServer = make_server("127.0.0.1", 0, app, handler_class=_Quiet)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_port}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join()
    assert storage.read_bytes() == (TUNE / "optuna.db").read_bytes()


def _get(url: str) -> dict:
    with urllib.request.urlopen(url) as answer:
        return json.load(answer)


def _studies(dashboard: str) -> dict[str, dict]:
    return {s["study_name"]: s for s in _get(f"{dashboard}/api/studies")["study_summaries"]}


def test_the_dashboard_lists_each_task_s_draws_and_each_arm_s_trials(dashboard):
    tune = fppo_jax.load_tune(TUNE)
    studies = _studies(dashboard)
    names = ["draws", *tune.plan["variants"]]
    expected = {f"{task}/{name}" for task in tune.plan["tasks"] for name in names}
    assert set(studies) == expected
    assert studies["cartpole/ppo"]["directions"] == ["maximize"]
    role = {a["key"]: a["value"] for a in studies["cartpole/draws"]["user_attrs"]}
    assert role == {"role": "the points each arm's trials take; scores are in theirs"}


def test_a_trial_s_intermediate_values_are_its_scores_at_the_end_of_each_rung(dashboard):
    tune = fppo_jax.load_tune(TUNE)
    chosen = tune.results["cartpole"]["ppo"]["chosen"]
    assert chosen is not None
    study = _get(f"{dashboard}/api/studies/{_studies(dashboard)['cartpole/ppo']['study_id']}")
    assert study["has_intermediate_values"]
    trials = {t["number"]: t for t in study["trials"]}
    assert len(trials) == tune.plan["trials"]
    trial = trials[chosen["trial"]]
    assert trial["state"] == "Complete"  # the others were pruned at a rung
    shown = {v["step"]: v["value"] for v in trial["intermediate_values"]}
    rungs = tune.plan["budget"]["cartpole"]["rungs"]
    recorded = {
        rung["ends_at_update"]: next(
            t["score"] for t in scores["arms"]["ppo"]["trials"] if t["trial"] == chosen["trial"]
        )
        for rung, scores in zip(rungs, tune.rungs["cartpole"], strict=True)
    }
    assert shown == pytest.approx(recorded)
    assert trial["values"] == pytest.approx([chosen["score"]])
    pruned = [t for n, t in trials.items() if n != chosen["trial"]]
    assert all(t["state"] == "Pruned" for t in pruned)
