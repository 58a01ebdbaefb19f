"""The persistent compilation cache: on by default in a directory per JAX version, moved or
turned off by FPPO_JAX_CACHE_DIR, a cache directory the user gave JAX kept. Each case runs in a
process of its own, as the cache is the process's (and this one's is the test session's)."""

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jaxlib
import pytest
from conftest import TINY

from fppo_jax.cli import build_parser
from fppo_jax.run import compile_cache

ROOT = Path(__file__).resolve().parents[1]
VERSIONS = f"jax-{jax.__version__}-jaxlib-{jaxlib.__version__}"

# Trains a tiny run, counting the programs JAX loaded from the cache and those it wrote there.
TRAIN = textwrap.dedent(f"""
    import json, jax, fppo_jax
    heard = {{"/jax/compilation_cache/cache_hits": 0, "/jax/compilation_cache/cache_misses": 0}}
    def listen(event, **_):
        if event in heard:
            heard[event] += 1
    jax.monitoring.register_event_listener(listen)
    result = fppo_jax.train("cartpole", total_steps=128, **{TINY!r})
    print(json.dumps({{
        "dir": jax.config.jax_compilation_cache_dir,
        "loaded": heard["/jax/compilation_cache/cache_hits"],
        "written": heard["/jax/compilation_cache/cache_misses"],
        "return": result.metrics["average_return"].tolist(),
    }}))
""")


def start(code: str, tmp_path: Path, **environ: str) -> subprocess.Popen:
    """A fresh process running `code`, whose environment has no cache settings but `environ`
    and a cache home in `tmp_path`."""
    unset = ("FPPO_JAX_CACHE_DIR", "JAX_COMPILATION_CACHE_DIR")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    env |= {"XDG_CACHE_HOME": str(tmp_path / "home-cache"), "PYTHONPATH": str(ROOT), **environ}
    return subprocess.Popen(
        [sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


def result(process: subprocess.Popen) -> dict:
    """The process's last line of output, as JSON, once it has ended well."""
    out, err = process.communicate()
    assert process.returncode == 0, err.decode()[-3000:]
    return json.loads(out.decode().splitlines()[-1])


def run(code: str, tmp_path: Path, **environ: str) -> dict:
    return result(start(code, tmp_path, **environ))


def entries(directory: Path) -> list[Path]:
    return sorted(directory.glob("*-cache")) if directory.is_dir() else []


def test_the_directory_is_per_user_and_per_version_unless_moved_or_off(tmp_path):
    home = {"XDG_CACHE_HOME": str(tmp_path)}
    assert compile_cache.directory(home) == tmp_path / "fppo-jax" / VERSIONS
    moved = {**home, "FPPO_JAX_CACHE_DIR": str(tmp_path / "elsewhere")}
    assert compile_cache.directory(moved) == tmp_path / "elsewhere" / VERSIONS
    for off in ("", "off", " OFF "):
        assert compile_cache.directory({**home, "FPPO_JAX_CACHE_DIR": off}) is None
    assert compile_cache.directory({}) == Path.home() / ".cache" / "fppo-jax" / VERSIONS


def test_on_by_default_and_a_second_process_loads_what_the_first_compiled(tmp_path):
    first = run(TRAIN, tmp_path)
    where = tmp_path / "home-cache" / "fppo-jax" / VERSIONS
    assert first["dir"] == str(where)
    assert first["written"] > 0 and first["loaded"] == 0
    assert len(entries(where)) == first["written"]
    again = run(TRAIN, tmp_path)
    assert again["loaded"] == first["written"]
    assert again["return"] == first["return"]  # the programs loaded compute the same


def test_processes_writing_one_cache_at_once_both_succeed_and_a_third_loads(tmp_path):
    # As a job array's tasks share it: FPPO_JAX_CACHE_DIR, under which JAX locks each entry.
    shared = {"FPPO_JAX_CACHE_DIR": str(tmp_path / "shared")}
    both = [result(p) for p in [start(TRAIN, tmp_path, **shared) for _ in range(2)]]
    programs = len(entries(tmp_path / "shared" / VERSIONS))
    assert programs >= 2  # at least the training program's two parts, whoever wrote them
    third = run(TRAIN, tmp_path, **shared)
    assert third["loaded"] == programs  # each one whole
    assert both[0]["return"] == both[1]["return"] == third["return"]


def test_the_command_says_whether_it_compiled_or_loaded_its_program(tmp_path):
    flags = ["train", "--env", "cartpole", "--variant", "ppo", "--steps", "256", "--num-envs"]
    flags += ["4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    said = []
    for _ in range(2):  # the second process finds what the first wrote in the fresh cache
        done = start(f"from fppo_jax.cli import main; main({flags!r})", tmp_path)
        _, err = done.communicate()
        assert done.returncode == 0, err.decode()[-3000:]
        lines = err.decode().splitlines()
        said.append(next(line for line in lines if line.startswith(("compiled", "loaded"))))
    assert re.fullmatch(r"compiled in \d+\.\d s", said[0]), said
    assert re.fullmatch(r"loaded from the compilation cache in \d+\.\d s", said[1]), said


@pytest.mark.slow  # the message alone in tests/test_stop_signals.py, in the default suite
def test_a_tune_says_whether_it_compiled_or_loaded_a_rungs_program(tmp_path):
    flags = ["tune", "--variants", "ppo", "--tasks", "cartpole", "--trials", "2", "--eta", "2"]
    flags += ["--steps", "256", "--num-envs", "4", "--num-steps", "32", "--minibatches", "4"]
    flags += ["--epochs", "2", "--score", "train", "--finalists", "1", "--validation-seeds", "4"]
    flags += ["--race-level", "0.1", "--rungs", "1"]
    said = []
    for output in ("a", "b"):  # the second process finds the first rung's program in the cache
        run = [*flags, "--output", str(tmp_path / output)]
        done = start(f"from fppo_jax.cli import main; main({run!r})", tmp_path)
        _, err = done.communicate()
        assert done.returncode == 0, err.decode()[-3000:]
        lines = err.decode().splitlines()
        said.append(
            next(
                line
                for line in lines
                if line.startswith("cartpole: rung 1 ")
                and ("compiled in" in line or "loaded from" in line)
            )
        )
    assert re.fullmatch(r"cartpole: rung 1 compiled in \d+\.\d s", said[0]), said
    assert re.fullmatch(
        r"cartpole: rung 1 loaded from the compilation cache in \d+\.\d s", said[1]
    ), said


def test_off_by_the_environment_variable(tmp_path):
    ran = run(TRAIN, tmp_path, FPPO_JAX_CACHE_DIR="off")
    assert ran["dir"] is None and ran["written"] == ran["loaded"] == 0
    assert not (tmp_path / "home-cache" / "fppo-jax").exists()


def test_the_command_line_turns_it_on(tmp_path):
    where = tmp_path / "cache"
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    subprocess.run(
        [sys.executable, "-m", "fppo_jax", "list"],
        env=env | {"PYTHONPATH": str(ROOT), "FPPO_JAX_CACHE_DIR": str(where)},
        capture_output=True,
        check=True,
    )
    assert (where / VERSIONS).is_dir()


def test_the_command_lines_help_names_the_switch():
    assert "FPPO_JAX_CACHE_DIR=off" in " ".join(build_parser().format_help().split())


def test_a_cache_directory_given_to_jax_is_kept(tmp_path):
    theirs, ours = tmp_path / "theirs", tmp_path / "ours"
    # What train does first (compile_cache.enable), without a training run to compile.
    check = textwrap.dedent("""
        import json, jax
        from fppo_jax.run import compile_cache
        compile_cache.enable()
        print(json.dumps({"min_seconds": jax.config.jax_persistent_cache_min_compile_time_secs,
                          "dir": jax.config.jax_compilation_cache_dir}))
    """)
    ran = run(check, tmp_path, JAX_COMPILATION_CACHE_DIR=str(theirs), FPPO_JAX_CACHE_DIR=str(ours))
    assert ran == {"min_seconds": 1.0, "dir": str(theirs)}  # JAX's own threshold, too
    assert not ours.exists()


def test_a_change_of_the_variable_moves_or_turns_off_only_the_cache_it_set(tmp_path):
    a, b, c, user = (str(tmp_path / name) for name in ("a", "b", "c", "user"))
    code = textwrap.dedent(f"""
        import json, os, jax
        from fppo_jax.run import compile_cache
        def enabled(value):
            os.environ["FPPO_JAX_CACHE_DIR"] = value
            compile_cache.enable()
            return jax.config.jax_compilation_cache_dir
        seen = [enabled(value) for value in ({a!r}, {b!r}, "off", "")]
        jax.config.update("jax_compilation_cache_dir", {user!r})
        seen += [enabled({c!r}), enabled("off")]
        print(json.dumps(seen))
    """)
    versioned = [str(Path(d) / VERSIONS) for d in (a, b)]
    assert run(code, tmp_path) == [*versioned, None, None, user, user]
