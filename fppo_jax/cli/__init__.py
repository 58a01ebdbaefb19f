"""The ``fppo-jax`` command line: ``train`` one policy, ``sweep`` a grid, ``study`` candidates
against a baseline, ``tune`` every variant with the same budget, ``eval`` (and render) or
``export`` a trained policy, ``table``, ``compare``, ``merge`` and ``plot`` sweeps' results,
``list`` the tasks and variants.

:mod:`.flags` turns text into checked values and makes the flags of the fields that declare
them; :mod:`.parser` assembles the commands; :mod:`.settings` reads ``--config FILE``;
:mod:`.commands` does what each command does. ``main`` reports every expected error in one line.
"""

from __future__ import annotations

# Light imports alone (no JAX): the command catches a cluster's stop signals before it imports
# anything heavy, which takes seconds (fppo_jax.run.stop_signals).
import argparse
import contextlib
import gc
import os
import signal
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, NoReturn

from fppo_jax.errors import FppoError
from fppo_jax.run.stop_signals import STOP_SIGNALS, caught, let_go

if TYPE_CHECKING:
    from sys import UnraisableHookArgs

    from fppo_jax.core.surrogates import Surrogate

__all__ = ["build_parser", "entry_point", "main"]


def build_parser(surrogates: Sequence[Surrogate] = ()) -> argparse.ArgumentParser:
    """The command line (:func:`fppo_jax.cli.parser.build_parser`), imported on first use."""
    from fppo_jax.cli.parser import build_parser as build

    return build(surrogates)


def entry_point() -> NoReturn:
    """``fppo-jax`` in a process of its own: the installed command and ``python -m fppo_jax``."""
    # A cluster's stop signals are held from the first moment, before the seconds that JAX's
    # import takes; a command that does not catch them lets them act once it knows (main).
    with caught(STOP_SIGNALS):
        import fppo_jax.cli.parser  # noqa: F401  # what every command needs, frozen with it

        # What is imported by now lives as long as the process. Frozen, it is left out of
        # the collector's full passes, which tracing a program sets off, and of those at the
        # exit: together a tenth of a short run's wall time.
        gc.freeze()
        sys.unraisablehook = _without_closed_loop_reports(sys.unraisablehook)
        try:
            status = main()
        except KeyboardInterrupt:
            print(INTERRUPTED, file=sys.stderr)
            status = 128 + signal.SIGINT  # what a shell reports for a program Ctrl-C ended
    if status in _STOPPED:
        _exit_now(status)
    sys.exit(status)


# The statuses of a command a stop signal stopped (128 + the signal: 143, 138).
_STOPPED = frozenset(128 + number for number in STOP_SIGNALS)


def _exit_now(status: int) -> NoReturn:
    """Ends the process with `status` once what it printed is out, skipping the interpreter's
    teardown. A run stopped by a signal leaves its next compiled call running on XLA's threads
    (dispatched ahead of the chunk it stopped at, run_chunks); the C library's exit, running the
    shared libraries' destructors meanwhile, crashed that call's compiled code in 3 stops of 27
    here (status 139), which a job script keyed on the status takes for a failure. All the
    command wrote is closed by now: the checkpoint waited for and its manager closed, the logs
    released (fppo_jax.run.driver), a tune's and a study's records written as they went."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


# What a command writes is written as it goes (a run's metrics.csv update by update, each
# checkpoint committed whole by orbax), so an interrupted one keeps it; summaries come at the end.
INTERRUPTED = (
    "fppo-jax: interrupted; what it wrote so far is kept (a checkpointed run goes on from its "
    "newest checkpoint with --resume; a tune or study, run again, from what it recorded)"
)


def _without_closed_loop_reports(
    report: Callable[[UnraisableHookArgs], object],
) -> Callable[[UnraisableHookArgs], None]:
    """`report` for every unraisable exception but a closed event loop's.

    A checkpoint read that fails ends orbax's event loop while TensorStore still completes the
    reads it had started; each completion finds the loop closed, and Python would print a
    traceback for it, dozens in all, interleaved with the one line that says the checkpoint is
    damaged. Only the command, which owns its process, drops them; the library leaves the hook
    as it finds it (docs/checkpoints.md)."""

    def hook(unraisable: UnraisableHookArgs) -> None:
        error = unraisable.exc_value
        if isinstance(error, RuntimeError) and str(error) == "Event loop is closed":
            return
        report(unraisable)

    return hook


def main(argv: Sequence[str] | None = None) -> int:
    from fppo_jax.cli.flags import surrogates_named

    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        surrogates = surrogates_named(argv)  # their hyperparameters become flags
    except FppoError as error:
        print(f"fppo-jax: error: {error}", file=sys.stderr)
        return 2
    parser = build_parser(surrogates)
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # the command's one-line error, pointing at its --help, not the whole usage
        args.commands[args.command].error(f"unrecognized arguments: {' '.join(unknown)}")
    if getattr(args, "config", None) is not None:
        try:
            args = _with_settings_file(parser, argv, args, surrogates)
        except FppoError as error:
            print(f"fppo-jax: error: {error}", file=sys.stderr)
            return 2
    # A checkpointed command, a tune and a study, in one process, catch a cluster's stop
    # signals from its start: one that comes while it imports or compiles stops it once
    # compiled, in a line and with the exit status a signal stopping it in training gives
    # (fppo_jax.run.driver). Joined processes leave SIGTERM to JAX's preemption service; any
    # other command, to the signal's own action.
    checkpointed = getattr(args, "checkpoint_dir", None) is not None
    recorded = args.command in ("tune", "study")  # each goes on from what it recorded
    catch = (checkpointed or recorded) and not getattr(args, "distributed", False)
    if not catch:
        let_go()
    with caught(STOP_SIGNALS if catch else ()):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    """The command `args` names, its expected errors each reported in a line."""
    # What the commands need (the trainer, checkpoints, JAX's devices) only now: --help and a
    # mistyped flag answer without waiting for it.
    from fppo_jax.cli.commands import COMMANDS
    from fppo_jax.run import compile_cache
    from fppo_jax.run.distributed import initialize
    from fppo_jax.run.stop_signals import StoppedBySignal

    with _warnings_as_lines():
        try:
            if getattr(args, "distributed", False):
                initialize()
            compile_cache.enable()
            return COMMANDS[args.command](args)
        except FppoError as error:  # what the user can act on; any other error is a bug
            print(f"fppo-jax: error: {error}", file=sys.stderr)
            return 2
        except OSError as error:
            # A file or directory the command reads or writes (a full disk, a read-only or
            # vanished directory); one with no path named is another failure, left to raise.
            if error.filename is None:
                raise
            print(f"fppo-jax: error: {error.filename}: {error.strerror or error}", file=sys.stderr)
            return 2
        except StoppedBySignal as stopped:
            print(f"fppo-jax: {stopped}", file=sys.stderr)
            # What a shell reports for a program the signal ended: a job script tells a time
            # limit's warning (SIGUSR1, 138) from a preemption or scancel (SIGTERM, 143).
            return 128 + stopped.signal


def _with_settings_file(
    parser: argparse.ArgumentParser,
    argv: list[str],
    args: argparse.Namespace,
    surrogates: Sequence[Surrogate],
) -> argparse.Namespace:
    """`argv` parsed with the settings of ``--config FILE`` as the command's defaults (a flag
    given wins), its own surrogates' flags included, once the file's names are checked."""
    from fppo_jax.cli.flags import own_surrogates
    from fppo_jax.cli.settings import check_preset, check_settings, settings_file

    settings = settings_file(args.config)
    named = own_surrogates(_variants(settings.get("variant")))
    if named:
        parser = build_parser([*surrogates, *named])
    command = parser.parse_args(argv).commands[args.command]
    check_settings(args.config, settings, command)
    check_preset(args.config, settings, _given(parser, argv, command, "preset"))
    command.set_defaults(**settings)
    return parser.parse_args(argv)


def _given(
    parser: argparse.ArgumentParser, argv: list[str], command: argparse.ArgumentParser, dest: str
) -> Any:
    """The value `argv` gives `command`'s flag `dest`, or None where it gives none."""
    default = command.get_default(dest)
    command.set_defaults(**{dest: None})
    try:
        return getattr(parser.parse_args(argv), dest)
    finally:
        command.set_defaults(**{dest: default})


def _variants(variant: object) -> Sequence[object]:
    """A settings file's variant (a name, a comma list, a list, or none) as a list."""
    if isinstance(variant, str):
        return variant.split(",")
    return list(variant) if isinstance(variant, list) else []


@contextlib.contextmanager
def _warnings_as_lines() -> Iterator[None]:
    """A damaged checkpoint reported in a line of the command's own, as its errors are; any
    other warning as before."""
    from fppo_jax.store.checkpoint import DamagedCheckpoint

    with warnings.catch_warnings():
        show = warnings.showwarning

        def shown(message: Warning | str, category: type[Warning], *rest: Any) -> None:
            if issubclass(category, DamagedCheckpoint):
                print(f"fppo-jax: warning: {message}", file=sys.stderr)
            else:
                show(message, category, *rest)

        warnings.showwarning = shown  # type: ignore[assignment]  # warnings calls it with positional arguments
        yield
