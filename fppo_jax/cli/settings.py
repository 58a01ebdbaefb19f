"""Settings from a file (``--config FILE``): a run's own ``config.json``, or JSON or YAML
written by hand, as defaults of a command's flags."""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

from fppo_jax.core.config import PRESETS
from fppo_jax.core.resolution import resolve
from fppo_jax.core.surrogates import SurrogateIdentity
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.store.record import REQUIRED, RunRecord

# What a run's config.json records beside its settings (metric_log.environment_record).
RECORD_ONLY = ("versions", "platform")
# What every run's record holds: a file that holds them all is read as one, a file written by
# hand (flag names, as many as it sets) as it is.


def settings_file(path: Path) -> dict[str, Any]:
    """The settings in `path` (JSON or YAML) as defaults of a command's flags: a run's own
    ``config.json`` (train) or a sweep's (sweep, its grid as the grid's flags), or a file of
    flag names written by hand. A surrogate of one's own that the record names is given by
    where an import finds it (``module:attribute``); one made in a script or a notebook cannot
    be found, and is refused with what to pass instead."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise MissingFile(f"settings file {path} not found") from None
    except (IsADirectoryError, UnicodeDecodeError) as error:  # not a settings file at all
        raise InvalidInput(f"{path} cannot be read as settings: {error}") from None
    try:
        if Path(path).suffix in (".yaml", ".yml"):
            settings = _yaml_without_repeated_keys(text)
        else:
            settings = json.loads(text, object_pairs_hook=_without_repeated_keys)
    except ImportError:
        raise InvalidInput(f"{path}: reading YAML needs PyYAML (pip install pyyaml)") from None
    except Exception as error:
        raise InvalidInput(f"{path} cannot be read as settings: {error}") from None
    if not isinstance(settings, dict):
        raise InvalidInput(f"{path} must hold a mapping of settings, got {type(settings).__name__}")
    settings = {k: v for k, v in settings.items() if k not in RECORD_ONLY}
    if isinstance(settings.get("devices"), list):  # the record's device kinds, not a count
        del settings["devices"]
    if all(key in settings for key in REQUIRED):
        return _rerun(path, RunRecord.from_json(settings, str(path)))
    return settings


def _rerun(path: Path, record: RunRecord) -> dict[str, object]:
    """The flags that rerun the run (or the sweep) `record` records, read from `path`: its
    setting and seed, or a sweep's grid (as the grid's flags), seeds, share and group size."""
    flags: dict[str, object] = {"env": record.env, "preset": record.preset, **record.setting}
    flags |= dataclasses.asdict(record.config) | (record.grid or {})
    seeds = None if record.seeds is None else list(record.seeds)
    found = {
        "backend": record.backend,
        "seed": record.seed,
        "seeds": seeds,
        "part": record.part,
        "chunk": record.runs_per_call,
    }
    flags |= {name: value for name, value in found.items() if value is not None}
    if record.surrogates and "variant" in flags:
        flags["variant"] = _importable(path, flags["variant"], record.surrogates)
    return flags


def _importable(path: Path, variant: Any, own: dict[str, SurrogateIdentity]) -> Any:
    """`variant` (a name or a list of them) with each surrogate of one's own replaced by
    where its record says an import finds it."""
    if isinstance(variant, list):
        return ",".join(_importable(path, v, own) for v in variant)
    if variant not in own:
        return variant
    recorded = own[variant]
    found = recorded.get("import")
    if not found:
        raise InvalidInput(
            f"{path}: the surrogate {variant!r} was made in a script or a notebook, where no "
            "import finds it; put it in a module and pass --variant module:attribute"
        )
    # As a resumed run's: the function found now must be the one the run trained.
    now = resolve(found).identity()
    differing = [
        f"{key} {recorded.get(key)!r}, now {now.get(key)!r}"
        for key in sorted(set(recorded) | set(now))
        if recorded.get(key) != now.get(key)
    ]
    if differing:
        raise InvalidInput(
            f"{path} records another surrogate {variant!r} than {found} is now (recorded "
            f"{'; '.join(differing)}): restore the one it trained to rerun the run, or train "
            "this one without --config"
        )
    return found


def check_settings(
    path: Path, settings: Mapping[str, object], command: argparse.ArgumentParser
) -> None:
    """Raise InvalidInput naming any key of `settings` (from `path`) that `command` has no flag
    for."""
    valid = set(vars(command.parse_args([]))) - {
        "commands",
        "command",
        "config",
        "hyperparameter_flags",
    }
    unknown = sorted(set(settings) - valid)
    if unknown:
        raise InvalidInput(
            f"{path}: unknown setting{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
            f"valid: {', '.join(sorted(valid))}"
        )
    # A flag's default is not parsed as the flag is unless it is text, so a switch given "no"
    # would be on: a switch's setting must be a boolean (or the flag's own null default).
    for action in command._actions:
        if action.nargs == 0 and action.dest in settings:
            value = settings[action.dest]
            if not isinstance(value, bool) and (value is not None or action.default is not None):
                raise InvalidInput(f"{path}: {action.dest} must be true or false, got {value!r}")


def check_preset(path: Path, settings: Mapping[str, object], preset: str | None) -> None:
    """Refuse `preset`, given on the command line, beside a file that records a run of another
    preset with that preset's run shape: the file's shape would win and the run would be
    labelled `preset` without having its shape."""
    recorded: Any = settings.get("preset")  # whatever the file holds
    shape = [name for name in PRESETS.get(recorded, {}) if name in settings]
    if preset is None or recorded in (None, preset) or not shape:
        return
    fields = ", ".join(f"{name}={settings[name]}" for name in shape)
    raise InvalidInput(
        f"{path} records a run of the {recorded} preset, with its run shape ({fields}), which "
        f"would override --preset {preset} and leave the run labelled {preset} without its "
        f"shape; drop --preset to rerun it as recorded, or, for the {preset} preset, write "
        "the settings to keep in a file without the run shape"
    )


def _without_repeated_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object, refused if it names a key twice (JSON keeps the last, silently)."""
    keys = [key for key, _ in pairs]
    repeated = sorted({str(key) for key in keys if keys.count(key) > 1})
    if repeated:
        raise InvalidInput(f"{', '.join(repeated)} given more than once")
    return dict(pairs)


def _yaml_without_repeated_keys(text: str) -> Any:
    """YAML's settings, refused if a mapping names a key twice (PyYAML keeps the last)."""
    import yaml

    class Loader(yaml.SafeLoader):  # type: ignore[misc]  # PyYAML has no type information here
        def construct_mapping(self, node: Any, deep: bool = False) -> dict[Any, Any]:
            keys = [self.construct_object(key, deep=deep) for key, _ in node.value]
            _without_repeated_keys([(key, None) for key in keys])
            return cast(dict[Any, Any], super().construct_mapping(node, deep=deep))

    return yaml.load(text, Loader=Loader)
