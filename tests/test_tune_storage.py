"""fppo_jax.analysis.tune_storage: tunes sharing one storage keep their own studies (a tune's
plan names them), a resume or a join on another storage is refused by name, a storage that is
none (empty, in memory, not a URL, no driver) is refused before anything is written, and a
storage failing (unreachable, read-only, full) is one line naming it, its password masked.

The shared database is SQLite here; the tests marked slow do the same on a real PostgreSQL
server (where one is installed): a server restarted between two uses, one stopped, two tunes
on one database."""

import multiprocessing
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import types
from pathlib import Path

import pytest
from helpers import TUNE_ARMS as ARMS
from helpers import TUNE_SMALL as SMALL

from fppo_jax.analysis.tune_files import read_plan
from fppo_jax.analysis.tune_storage import (
    StorageFailed,
    open_storage,
    storage_record,
    storage_shown,
    study_name,
    tune_storage,
)
from fppo_jax.analysis.tuning import tune
from fppo_jax.analysis.tuning_draws import import_optuna
from fppo_jax.errors import InvalidInput, MissingPackage

DRAWN = dict(SMALL, rungs=0)  # the trials drawn and recorded, none trained
CLASSIC = Path(__file__).resolve().parent.parent / "experiments/results/tuned/classic/tune"


def _trials(storage: str, plan: dict, arm: str = "ppo") -> list[dict]:
    """The points of `arm`'s trials on cartpole, as the tune of `plan` recorded them."""
    optuna = import_optuna()
    name = f"{plan['storage']['studies']}/cartpole/{arm}"
    return [t.params for t in optuna.load_study(study_name=name, storage=storage).trials]


def _names(storage: str) -> set[str]:
    return {s.study_name for s in import_optuna().get_all_study_summaries(storage)}


def test_tunes_on_one_storage_keep_their_own_studies(tmp_path):
    shared = f"sqlite:///{tmp_path / 'shared.db'}"
    first = tune("cartpole", ["ppo", "spo"], output=tmp_path / "a", storage=shared, **DRAWN)
    # Another tune's arms on the same storage (a KeyError on fppo-lp's α when the draws were
    # shared), another sampler seed, another trial count (which deleted the first's studies).
    same_seed = tune("cartpole", ARMS, output=tmp_path / "b", storage=shared, **DRAWN)
    other_seed = tune(
        "cartpole", ARMS, output=tmp_path / "c", storage=shared, sampler_seed=1, **DRAWN
    )
    more = tune("cartpole", ARMS, output=tmp_path / "d", storage=shared, **{**DRAWN, "trials": 6})
    alone = tune("cartpole", ARMS, output=tmp_path / "e", sampler_seed=1, **DRAWN)
    plans = [first.plan, same_seed.plan, other_seed.plan, more.plan]
    ids = [plan["storage"]["studies"] for plan in plans]
    assert len(set(ids)) == 4 and all(plan["storage"]["url"] == shared for plan in plans)
    assert _names(shared) == {
        f"{tune_id}/cartpole/{name}"
        for tune_id, plan in zip(ids, plans, strict=True)
        for name in ["draws", *plan["variants"]]
    }
    assert len(_trials(shared, first.plan)) == SMALL["trials"]  # not deleted by the 6-trial one
    assert len(_trials(shared, more.plan)) == 6
    # Each seed's own points: seed 1's on the shared storage are those it draws alone.
    private = f"sqlite:///{tmp_path / 'e' / 'optuna.db'}"
    assert _trials(shared, other_seed.plan) == _trials(private, alone.plan)
    assert _trials(shared, other_seed.plan)[1:] != _trials(shared, same_seed.plan)[1:]
    # The same call again goes on with its own studies.
    again = tune("cartpole", ARMS, output=tmp_path / "b", storage=shared, **DRAWN)
    assert again.plan["storage"] == same_seed.plan["storage"] and len(_names(shared)) == 12


def test_a_tunes_studies_are_named_after_its_plan_storage_and_folder(tmp_path):
    plan = {"space": {"ppo": {"learning_rate": {"low": 1e-4, "high": 1e-3}}}, "trials": 4}
    named = storage_record(plan, None, tmp_path / "a")
    assert named == storage_record(plan, None, tmp_path / "a")  # the same tune, the same names
    assert named["url"] == "optuna.db" and len(named["studies"]) == 12
    narrower = {**plan, "space": {"ppo": {"learning_rate": {"low": 2e-3, "high": 1e-2}}}}
    others = [
        storage_record(narrower, None, tmp_path / "a"),  # a space outside the first's
        storage_record({**plan, "trials": 6}, None, tmp_path / "a"),
        storage_record(plan, "sqlite:///shared.db", tmp_path / "a"),
        storage_record(plan, None, tmp_path / "b"),
    ]
    assert len({named["studies"], *(other["studies"] for other in others)}) == 5


def test_a_plan_made_again_in_its_folder_draws_its_own_trials(tmp_path):
    seed_0 = tune("cartpole", ARMS, output=tmp_path, **DRAWN)
    (tmp_path / "tune.json").unlink()
    seed_1 = tune("cartpole", ARMS, output=tmp_path, sampler_seed=1, **DRAWN)
    storage = f"sqlite:///{tmp_path / 'optuna.db'}"
    assert seed_1.plan["sampler"]["seed"] == 1
    assert seed_1.plan["storage"]["studies"] != seed_0.plan["storage"]["studies"]
    assert _trials(storage, seed_1.plan)[1:] != _trials(storage, seed_0.plan)[1:]
    assert _trials(storage, seed_0.plan)  # the earlier plan's studies left as they were


def test_a_call_on_another_storage_than_the_tunes_is_refused_by_name(tmp_path):
    other = f"sqlite:///{tmp_path / 'other.db'}"
    tune("cartpole", ARMS, output=tmp_path / "a", storage=other, **DRAWN)
    with pytest.raises(
        InvalidInput,
        match=rf"trials are in Optuna's storage {other}, not optuna\.db: give --storage {other}",
    ):
        tune("cartpole", ARMS, output=tmp_path / "a", **DRAWN)
    tune("cartpole", ARMS, output=tmp_path / "b", **DRAWN)
    with pytest.raises(InvalidInput, match=r"storage optuna\.db, not .*: give no --storage"):
        tune("cartpole", ARMS, output=tmp_path / "b", storage=other, **DRAWN)
    # A split tune's array tasks and its join check it as well.
    split = dict(DRAWN, chunk=8)
    tune("cartpole", ARMS, output=tmp_path / "c", storage=other, **split)
    for part in [(1, 2), None]:
        with pytest.raises(InvalidInput, match=f"give --storage {other}, as the tune started"):
            tune("cartpole", ARMS, output=tmp_path / "c", part=part, **split)


@pytest.mark.parametrize(
    "storage, said",
    [
        ("", r"storage must name Optuna's storage, .* got '' \(leave it out for optuna\.db"),
        ("sqlite://", r"storage sqlite:// is a database in memory, lost when the tune ends"),
        ("sqlite:///:memory:", r"storage sqlite:///:memory: is a database in memory"),
        ("runs/optuna.db", r"storage must be a database URL .* got 'runs/optuna\.db'"),
        ("nosuch://here", r"cannot open Optuna's storage nosuch://here: SQLAlchemy knows no"),
    ],
)
def test_a_storage_that_is_none_is_refused_before_anything_is_written(tmp_path, storage, said):
    with pytest.raises(InvalidInput, match=said):
        tune("cartpole", ARMS, output=tmp_path / "t", storage=storage, **DRAWN)
    assert not (tmp_path / "t").exists()


def test_a_missing_database_driver_names_the_package_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "psycopg", None)  # as where it is not installed
    url = "postgresql://fppo:s3cret@db.example/optuna"
    with pytest.raises(MissingPackage) as refused:
        tune("cartpole", ARMS, output=tmp_path / "t", storage=url, **DRAWN)
    assert str(refused.value) == (
        "Optuna's storage postgresql://fppo:***@db.example/optuna needs the database driver "
        "psycopg, not installed: pip install 'fppo-jax[postgres]' (from a clone: pip install "
        "-e '.[postgres]')"
    )
    assert not (tmp_path / "t").exists()


def test_the_plan_records_a_storage_without_its_password():
    pytest.importorskip("psycopg", reason="the postgres extra's driver is not installed")
    assert storage_shown("postgresql://fppo:s3cret@db/optuna") == "postgresql://fppo:***@db/optuna"
    assert storage_shown("postgresql://fppo@db/optuna") == "postgresql://fppo@db/optuna"
    assert storage_shown("runs/optuna.log") == "runs/optuna.log"
    assert storage_shown(None) == "optuna.db"


def test_an_unreachable_server_is_one_line_naming_it_without_its_password():
    pytest.importorskip("psycopg", reason="the postgres extra's driver is not installed")
    with socket.socket() as closed:  # a port nothing listens on
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    url = f"postgresql://fppo:s3cret@127.0.0.1:{port}/optuna"
    with pytest.raises(StorageFailed) as failed:
        open_storage(import_optuna(), url)
    said = str(failed.value)
    assert said.startswith(f"cannot open Optuna's storage postgresql://fppo:***@127.0.0.1:{port}")
    assert "refused" in said and "s3cret" not in said and "\n" not in said


def test_a_read_only_storage_is_one_line_naming_it_and_the_cause(tmp_path):
    optuna = import_optuna()
    path = tmp_path / "made.db"
    open_storage(optuna, f"sqlite:///{path}")  # its tables made
    read_only = f"sqlite:///file:{path}?mode=ro&uri=true"
    with pytest.raises(StorageFailed) as failed:
        tune("cartpole", ARMS, output=tmp_path / "t", storage=read_only, **DRAWN)
    assert str(failed.value) == (
        f"Optuna's storage {read_only} failed: attempt to write a readonly database; what the "
        "tune recorded is kept: the same command goes on from it once the storage works again"
    )


def test_a_full_database_is_told_as_such_not_as_invalid_data(tmp_path):
    optuna = import_optuna()
    storage = open_storage(optuna, f"sqlite:///{tmp_path / 'full.db'}")
    engine = storage.inner._backend.engine  # Optuna's cached storage, over its database

    from sqlalchemy import event

    # SQLite's page limit, at the pages the file has: the next page it needs is a full disk.
    @event.listens_for(engine, "connect")
    def full(connection, _):
        pages = connection.execute("PRAGMA page_count").fetchone()[0]
        connection.execute(f"PRAGMA max_page_count = {pages}")

    engine.dispose()
    with pytest.raises(StorageFailed, match=r"failed: database or disk is full; what the tune"):
        for k in range(100):
            optuna.create_study(study_name=f"study {k} " + "x" * 400, storage=storage)


def _pooled_connections_closed(storage):
    """Every connection the storage's pool holds, closed underneath it: what a database
    server's restart does to them."""
    pool = storage.inner._backend.engine.pool
    for record in list(pool._pool.queue):
        record.dbapi_connection.close()


def test_connections_that_died_between_two_uses_are_made_again(tmp_path):
    optuna = import_optuna()
    storage = open_storage(optuna, f"sqlite:///{tmp_path / 'optuna.db'}")
    optuna.create_study(study_name="cartpole/ppo", storage=storage)
    _pooled_connections_closed(storage)
    assert optuna.load_study(study_name="cartpole/ppo", storage=storage).trials == []


class _MadeMeanwhile:
    """Optuna's RDBStorage, whose first tries find another process making the same tables."""

    def __init__(self, optuna, failures):
        self.optuna, self.failures, self.tries = optuna, list(failures), 0

    def __call__(self, url, **kwargs):
        self.tries += 1
        if self.failures:
            raise self.failures.pop(0)
        return self.optuna.storages.RDBStorage(url, **kwargs)


def _with_rdb(optuna, rdb):
    storages = types.SimpleNamespace(
        RDBStorage=rdb,
        get_storage=optuna.storages.get_storage,
        BaseStorage=optuna.storages.BaseStorage,
    )
    return types.SimpleNamespace(storages=storages)


def test_a_new_database_that_another_tune_makes_at_once_is_opened(tmp_path):
    from sqlalchemy import exc

    optuna = import_optuna()
    raced = [
        exc.IntegrityError(
            "INSERT INTO alembic_version", {}, Exception("UNIQUE constraint failed")
        ),
        exc.OperationalError("CREATE TABLE studies", {}, Exception("table studies already exists")),
    ]
    rdb = _MadeMeanwhile(optuna, raced)
    storage = open_storage(_with_rdb(optuna, rdb), f"sqlite:///{tmp_path / 'new.db'}")
    assert rdb.tries == 3 and optuna.get_all_study_summaries(storage) == []
    refused = exc.OperationalError("connect", {}, Exception("unable to open database file"))
    rdb = _MadeMeanwhile(optuna, [refused])
    with pytest.raises(StorageFailed, match=r"new\.db: unable to open database file$"):
        open_storage(_with_rdb(optuna, rdb), f"sqlite:///{tmp_path / 'new.db'}")
    assert rdb.tries == 1  # a failure of its own is not tried again


def test_a_journal_file_holds_several_tunes(tmp_path):
    journal = str(tmp_path / "optuna.log")
    a = tune("cartpole", ARMS, output=tmp_path / "a", storage=journal, **DRAWN)
    b = tune("cartpole", ARMS, output=tmp_path / "b", storage=journal, sampler_seed=1, **DRAWN)
    alone = tune("cartpole", ARMS, output=tmp_path / "c", sampler_seed=1, **DRAWN)
    assert a.plan["storage"]["url"] == journal and (tmp_path / "optuna.log").is_file()
    optuna = import_optuna()
    storage = optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(journal))
    assert _trials(storage, b.plan) == _trials(f"sqlite:///{tmp_path / 'c/optuna.db'}", alone.plan)
    assert len(_trials(storage, a.plan)) == SMALL["trials"]
    tune("cartpole", ARMS, output=tmp_path / "a", storage=journal, **DRAWN)  # goes on
    with pytest.raises(InvalidInput, match=f"storage {journal}, not optuna.db"):
        tune("cartpole", ARMS, output=tmp_path / "a", **DRAWN)


def test_a_tune_recorded_before_its_plan_named_a_storage_keeps_its_studies_names(tmp_path):
    copy = tmp_path / "tune"
    shutil.copytree(CLASSIC, copy, ignore=shutil.ignore_patterns("*.npz", "*.png"))
    plan = read_plan(copy)
    assert "storage" not in plan
    optuna = import_optuna()
    storage = tune_storage(optuna, None, copy, plan)
    assert study_name(storage, "cartpole", "ppo") == "cartpole/ppo"
    study = optuna.load_study(study_name=study_name(storage, "cartpole", "ppo"), storage=storage)
    assert len(study.trials) == plan["trials"]


# A real PostgreSQL server, where one is installed: the stand-ins above, on the real thing.


def _postgres_programs() -> Path | None:
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"))
    if found:
        return found[-1].parent
    on_path = shutil.which("pg_ctl")
    return Path(on_path).parent if on_path else None


class _Server:
    """A PostgreSQL server of its own in `data` (a user fppo, password s3cret), on a port of
    the loopback address; as root, run as the system's postgres user (it refuses root)."""

    def __init__(self, programs: Path, data: Path):
        self.programs, self.data = programs, data
        self.as_user = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
        with socket.socket() as free:
            free.bind(("127.0.0.1", 0))
            self.port = free.getsockname()[1]
        self.url = f"postgresql://fppo:s3cret@127.0.0.1:{self.port}/postgres"

    def run(self, program: str, *args: str) -> None:
        subprocess.run(
            [*self.as_user, str(self.programs / program), *args], check=True, capture_output=True
        )

    def pg_ctl(self, action: str) -> None:
        options = f"-p {self.port} -k {self.data} -c listen_addresses=127.0.0.1"
        log = str(self.data / "server.log")
        self.run("pg_ctl", "-D", str(self.data / "db"), "-o", options, "-l", log, "-w", action)


@pytest.fixture
def postgres():
    programs = _postgres_programs()
    if programs is None:
        pytest.skip("no PostgreSQL server installed (apt-get install postgresql)")
    pytest.importorskip("psycopg", reason="the postgres extra's driver is not installed")
    data = Path(tempfile.mkdtemp(prefix="fppo-postgres-"))
    server = _Server(programs, data)
    (data / "password").write_text("s3cret\n")
    if server.as_user:
        shutil.chown(data, "postgres")
        shutil.chown(data / "password", "postgres")
    server.run(
        "initdb",
        "-D",
        str(data / "db"),
        "-U",
        "fppo",
        "--auth=scram-sha-256",
        f"--pwfile={data / 'password'}",
    )
    server.pg_ctl("start")
    try:
        yield server
    finally:
        server.run("pg_ctl", "-D", str(data / "db"), "-m", "immediate", "stop")
        shutil.rmtree(data)


@pytest.mark.slow
def test_a_restarted_server_is_reconnected_to_and_a_stopped_one_is_one_line(postgres):
    optuna = import_optuna()
    storage = open_storage(optuna, postgres.url)
    optuna.create_study(study_name="cartpole/ppo", storage=storage)
    postgres.pg_ctl("restart")
    assert optuna.load_study(study_name="cartpole/ppo", storage=storage).trials == []
    postgres.pg_ctl("stop")
    with pytest.raises(StorageFailed) as failed:
        optuna.load_study(study_name="cartpole/ppo", storage=storage)
    said = str(failed.value)
    assert said.startswith(f"Optuna's storage postgresql://fppo:***@127.0.0.1:{postgres.port}")
    assert "s3cret" not in said and "\n" not in said
    postgres.pg_ctl("start")


@pytest.mark.slow
def test_tunes_on_one_postgresql_database_keep_their_own_studies(postgres, tmp_path):
    a = tune("cartpole", ARMS, output=tmp_path / "a", storage=postgres.url, **DRAWN)
    b = tune("cartpole", ARMS, output=tmp_path / "b", storage=postgres.url, sampler_seed=1, **DRAWN)
    assert a.plan["storage"]["url"] == f"postgresql://fppo:***@127.0.0.1:{postgres.port}/postgres"
    assert "s3cret" not in (tmp_path / "a" / "tune.json").read_text()
    assert _trials(postgres.url, a.plan)[1:] != _trials(postgres.url, b.plan)[1:]
    assert len(_names(postgres.url)) == 6


def _open_at_once(url: str, start) -> str:
    start.wait()
    try:
        open_storage(import_optuna(), url)
    except StorageFailed as error:
        return str(error)
    return "opened"


@pytest.mark.slow
def test_tunes_that_make_one_new_database_at_once_all_open_it(tmp_path):
    context = multiprocessing.get_context("spawn")
    with context.Manager() as manager, context.Pool(3) as pool:
        for k in range(8):  # each new database made by three processes at once
            url, start = f"sqlite:///{tmp_path / f'new-{k}.db'}", manager.Barrier(3)
            assert pool.starmap(_open_at_once, [(url, start)] * 3) == ["opened"] * 3


def test_the_command_line_says_a_storage_refused_or_unreachable_in_one_line(tmp_path, capsys):
    from fppo_jax.cli import main

    flags = ["tune", "--variants", "ppo,fppo-lp", "--tasks", "cartpole", "--trials", "4"]
    flags += ["--eta", "2", "--steps", "1024", "--num-envs", "4", "--num-steps", "32"]
    flags += ["--minibatches", "4", "--epochs", "2", "--quiet", "--output", str(tmp_path / "t")]
    assert main([*flags, "--storage", ""]) == 2
    said = capsys.readouterr().err
    assert said.startswith("fppo-jax: error: storage must name Optuna's storage, a database URL")
    assert said.count("\n") == 1 and not (tmp_path / "t").exists()
    assert main([*flags, "--storage", "sqlite://"]) == 2
    assert capsys.readouterr().err == (
        "fppo-jax: error: storage sqlite:// is a database in memory, lost when the tune ends: "
        "give a file (sqlite:///path/optuna.db), a server's URL or a journal file "
        "(path/optuna.log)\n"
    )
    pytest.importorskip("psycopg", reason="the postgres extra's driver is not installed")
    with socket.socket() as closed:  # a port nothing listens on
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]
    assert main([*flags, "--storage", f"postgresql://fppo:s3cret@127.0.0.1:{port}/optuna"]) == 2
    said = capsys.readouterr().err
    assert said.startswith(
        f"fppo-jax: error: cannot open Optuna's storage postgresql://fppo:***@127.0.0.1:{port}/"
        "optuna: connection failed: "
    )
    assert said.count("\n") == 1 and "s3cret" not in said
