"""A run's identity, typed: :class:`RunRecord`, what checkpoints, ``config.json``,
``sweep.json``, saved policies and a study's or a tune's plan record of a run (or a sweep, or
the protocol a study's runs share), and the one comparison of two, naming what differs.

Its JSON is the object these files have always held, key for key and in the same order, so
every recorded run reads back as it was written."""

from __future__ import annotations

import dataclasses
import json
from typing import Any, cast

from fppo_jax.core.config import Setting, TrainConfig, Value
from fppo_jax.core.surrogates import SurrogateIdentity
from fppo_jax.store.files import IncompatibleFormat, check_format, json_value

_SHAPE = [field.name for field in dataclasses.fields(TrainConfig)]
# Shape fields added after records were first written, with the value every earlier run had:
# a record leaves one out at that value, so that those records and these read alike.
_LATER: dict[str, Any] = {"initial_log_std": 0.0}
# The keys every record holds, whichever version wrote it.
REQUIRED = ("env", "preset", *(name for name in _SHAPE if name not in _LATER))
# The keys a record's JSON holds beside TrainConfig's fields; any other is a train's setting.
_OWN = ("env", "backend", "grid", "seed", "seeds", "part", "surrogates", "preset", "runs_per_call")


@dataclasses.dataclass(frozen=True)
class RunRecord:
    """What was trained: the environment (`env`, as records name it) on `backend` (None in
    sweeps recorded before backends were), the `preset` and run shape (`config`), and, beyond
    the protocol those make: a single run's `setting` (its variant and every hyperparameter's
    value) and `seed`; a sweep's `grid` (each axis's values), `seeds`, its `part` of a split
    and the `runs_per_call` it trained in (a result's, not a plan's); the `surrogates` of one's
    own it ran, by name (:meth:`~fppo_jax.core.surrogates.Surrogate.identity`, whose digest
    tells two functions under one name apart)."""

    # The JSON layout. The records written so far name none (check_format reads them as the
    # first); a later layout names its own, which this code refuses rather than misreads.
    FORMAT = 1

    env: str
    backend: str | None
    preset: str
    config: TrainConfig
    setting: Setting = dataclasses.field(default_factory=dict)
    seed: int | None = None
    grid: dict[str, list[Value]] | None = None
    seeds: tuple[int, ...] | None = None
    part: tuple[int, int] | None = None
    surrogates: dict[str, SurrogateIdentity] = dataclasses.field(default_factory=dict)
    runs_per_call: int | None = None

    def protocol(self) -> RunRecord:
        """What runs must share to be compared or joined: the environment, the backend, the
        preset and the run shape (not the settings, seeds, surrogates or share)."""
        return RunRecord(self.env, self.backend, self.preset, self.config)

    @property
    def num_updates(self) -> int:
        """The update a run of this record ends at."""
        return self.config.num_updates

    def to_json(self) -> dict[str, Any]:
        """The record as its files hold it (absent fields left out, as they always were): a
        new value, plain JSON, that shares nothing with the record."""
        own = {
            "env": self.env,
            "backend": self.backend,
            "grid": self.grid,
            "seed": self.seed,
            "seeds": self.seeds,
            "part": self.part,
            "surrogates": self.surrogates or None,
            "preset": self.preset,
        }
        shape = {
            name: value
            for name, value in dataclasses.asdict(self.config).items()
            if name not in _LATER or value != _LATER[name]
        }
        last = {} if self.runs_per_call is None else {"runs_per_call": self.runs_per_call}
        present = {name: value for name, value in own.items() if value is not None}
        return cast(dict[str, Any], json_value({**self.setting, **present, **shape, **last}))

    @classmethod
    def from_json(cls, value: Any, what: str = "the run's record") -> RunRecord:
        """The record in `value` (as :meth:`to_json` wrote it; `what` names where it is, in
        words); one of another layout, or lacking a field, raises :class:`IncompatibleFormat`."""
        if not isinstance(value, dict):
            raise IncompatibleFormat(f"{what} is not a run's record: {value!r}")
        check_format(value, what, cls.FORMAT)
        missing = [key for key in REQUIRED if key not in value]
        if missing:
            raise IncompatibleFormat(
                f"{what} lacks {', '.join(missing)}: it was written by another version of "
                "fppo-jax, or is not a run's record"
            )
        known = {*_OWN, *_SHAPE, "format"}
        part, seeds = value.get("part"), value.get("seeds")
        pair = isinstance(part, list) and len(part) == 2
        if not isinstance(seeds, list | None) or not (part is None or pair):
            raise IncompatibleFormat(
                f"{what} is not a run's record: its seeds ({seeds!r}) are not a list, or its "
                f"part ({part!r}) is not a pair"
            )
        return cls(
            env=value["env"],
            backend=value.get("backend"),
            preset=value["preset"],
            config=TrainConfig(
                **{name: value[name] if name in value else _LATER[name] for name in _SHAPE}
            ),
            setting={k: v for k, v in value.items() if k not in known},
            seed=value.get("seed"),
            grid=value.get("grid"),
            seeds=None if seeds is None else tuple(seeds),
            part=None if part is None else (part[0], part[1]),
            surrogates=value.get("surrogates") or {},
            runs_per_call=value.get("runs_per_call"),
        )

    def differences(self, other: RunRecord, here: str = "here", there: str = "there") -> list[str]:
        """Each field on which this record and `other` differ, in the record's order, as
        ``"seed: 3 here, 4 there"`` (`here` and `there` say whose each value is); a grid's or
        the surrogates' entry is named within them (``grid.alpha``). Empty for equal records."""
        mine, theirs = self.to_json(), other.to_json()
        found = []
        for name in dict.fromkeys([*mine, *theirs]):
            a, b = mine.get(name), theirs.get(name)
            if a == b:
                continue
            if isinstance(a, dict) and isinstance(b, dict):
                found += [
                    f"{name}.{key}: {_shown(a.get(key))} {here}, {_shown(b.get(key))} {there}"
                    for key in dict.fromkeys([*a, *b])
                    if a.get(key) != b.get(key)
                ]
            else:
                found.append(f"{name}: {_shown(a)} {here}, {_shown(b)} {there}")
        return found


def _shown(value: Any) -> str:
    return "none" if value is None else json.dumps(value)
