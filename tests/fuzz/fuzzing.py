"""What the fuzz suite (issue 22) shares: the checks a step's outputs must pass, what an error message must name,
a collector of defects that reports every kind found (not only the first), and the figures the run prints.

A *defect* is anything the standards forbid: an exception other than the documented one, a ``ValueError`` that
does not name the field (or file) and the value, NaN anywhere in an observation, reward or info, inf outside
the keys documented to be inf, an observation outside its space, different bits for the same seeds.

The tests record their figures (cases, outcomes, steps, defects) in :data:`FIGURES`; ``conftest.py`` prints them
at the end of the run (and writes them as JSON to ``$TIMEGAP_FUZZ_FIGURES`` if set).
"""

from __future__ import annotations

import collections
import hashlib
import math
import re
import traceback
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import hypothesis
import numpy as np
from hypothesis import HealthCheck

from timegap_env.config import shown
from timegap_env.leaders import default_ngsim_path, default_openacc_dir
from timegap_env.leaders.scenarios import SCENARIOS

RECORDED_SCENARIOS = ("ngsim", "ngsim_in_band", "openacc")  # read from ../shared/data (or $TIMEGAP_*_PATH)
DATA_PRESENT = default_ngsim_path().is_file() and default_openacc_dir().is_dir()
NO_DATA = (f"the NGSIM or OpenACC data are absent ({default_ngsim_path()}, {default_openacc_dir()}; set "
           "TIMEGAP_NGSIM_PATH and TIMEGAP_OPENACC_PATH): recorded leaders left out")
# the scenarios a reset can run here: every one but highway-env's IDM (fuzzed apart), recorded ones with their data
PLAYABLE = [name for name in sorted(SCENARIOS) if name != "idm" and (DATA_PRESENT or name not in RECORDED_SCENARIOS)]


def skip_without_data(config: Mapping[str, Any]) -> None:
    """Skip the test when ``config`` (an env config) draws a recorded leader and its data are absent."""
    weights = config.get("scenario_weights") or {}
    if not DATA_PRESENT and any(name in RECORDED_SCENARIOS and weight for name, weight in weights.items()):
        import pytest

        pytest.skip(NO_DATA)

ENV_ID = "TimeGapMonitor-v0"
QUALIFIED_ENV_ID = "timegap_env:TimeGapMonitor-v0"

# The info keys documented to be +inf (never -inf, never NaN): README "The environment", timegap_env/envs/task.py
# monitor_info, timegap_env/envs/totals.py (min_ttc) and DegradationTable.truth (onset/end of a follower not hit or a
# degradation that never ends, no string-stable setting found).
ALLOWED_INF = frozenset({
    "actual_time_gap",  # undefined below 1 m/s: inf
    "ttc",  # never closing in: inf
    "episode_min_ttc",  # the episode's smallest ttc
    "truth_onset", "truth_end",  # not hit / never
    "truth_smallest_stable_setting",  # none in the searched range
})

# Hypothesis settings: deterministic (derandomize, no example database), no deadline (numba's first compile and
# shared CPUs make timings meaningless), the slow-but-fine health checks off.
SUPPRESSED = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much,
              HealthCheck.function_scoped_fixture, HealthCheck.large_base_example]


def fuzz_settings(max_examples: int) -> hypothesis.settings:
    """Deterministic hypothesis settings with ``max_examples`` examples, no shrinking phase needed: the fuzz tests
    collect every defect in a :class:`Defects` and fail once at the end, listing them."""
    return hypothesis.settings(max_examples=max_examples, derandomize=True, database=None, deadline=None,
                               suppress_health_check=SUPPRESSED, print_blob=False,
                               phases=[hypothesis.Phase.explicit, hypothesis.Phase.generate])


# ----------------------------------------------------------------------------------------------- figures

FIGURES: dict[str, dict[str, Any]] = {}  # area -> its figures, printed by conftest.py at the end of the run


def figures(area: str) -> dict[str, Any]:
    """The figures of ``area`` (a dict the test fills: counts of cases, outcomes, steps, defects)."""
    return FIGURES.setdefault(area, {})


def accumulate(into: dict[str, Any], figures_: Mapping[str, Any]) -> None:
    """Add ``figures_`` into ``into``: numbers add, dicts add key by key, anything else is replaced."""
    for key, value in figures_.items():
        if isinstance(value, Mapping):
            accumulate(into.setdefault(key, {}), value)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            into[key] = into.get(key, 0) + value
        else:
            into[key] = value


# ----------------------------------------------------------------------------------------------- defects

def _signature(message: str) -> str:
    """A message with its numbers, quoted strings and paths blanked, so that defects of one kind group together."""
    text = re.sub(r"(/[\w.+-]+)+", "<path>", message)
    text = re.sub(r"'[^']*'|\"[^\"]*\"", "<str>", text)
    text = re.sub(r"[-+]?\d[\d.e+-]*", "#", text)
    return text[:160]


def short(value: Any, limit: int = 300) -> str:
    """``repr(value)`` cut to ``limit`` characters (huge integers by their size)."""
    try:
        return shown(value, limit)
    except Exception:  # noqa: BLE001 - a repr that raises is itself worth seeing
        return f"<{type(value).__name__} whose repr raises>"


class Defects:
    """Every defect a fuzz test finds, grouped by (what, the message's shape), with a count and the shortest input
    of each group; :meth:`check` fails once, listing them all."""

    def __init__(self, area: str) -> None:
        self.area = area
        self.groups: dict[tuple[str, str], dict[str, Any]] = {}
        self.outcomes: collections.Counter[str] = collections.Counter()
        self.cases = 0
        self.total = 0
        self.notes: collections.Counter[str] = collections.Counter()  # allowed outcomes worth a look (refusals)

    def note(self, text: str) -> None:
        """Count an allowed outcome worth a look, e.g. the shape of a refusal's message."""
        self.notes[_signature(text)[:120]] += 1

    def case(self, outcome: str) -> None:
        """Count one case and its outcome (e.g. "works", "ValueError")."""
        self.cases += 1
        self.outcomes[outcome] += 1

    def add(self, what: str, message: str, case: Any) -> None:
        """A defect: ``what`` (e.g. "TypeError at reset"), the error's message, the input that made it."""
        self.total += 1
        key = (what, _signature(message))
        text = case if isinstance(case, str) else short(case, 600)
        group = self.groups.setdefault(key, {"count": 0, "message": message, "case": text})
        group["count"] += 1
        if len(text) < len(group["case"]):
            group["message"], group["case"] = message, text

    def exception(self, stage: str, error: BaseException, case: Any) -> None:
        """A defect made of an exception raised at ``stage``, with where it was raised."""
        frames = traceback.extract_tb(error.__traceback__)
        where = f" [{frames[-1].filename.split('/work/main/')[-1]}:{frames[-1].lineno}]" if frames else ""
        self.add(f"{type(error).__name__} at {stage}{where}", str(error)[:500], case)

    def report(self) -> str:
        lines = [f"{self.area}: {self.total} defect(s) in {self.cases} case(s), {len(self.groups)} kind(s); "
                 f"outcomes {dict(self.outcomes)}"]
        for (what, _), group in sorted(self.groups.items(), key=lambda item: -item[1]["count"]):
            lines.append(f"- {what} (x{group['count']}): {group['message'][:400]}\n    input: {group['case'][:600]}")
        return "\n".join(lines)

    def record(self, extra: Mapping[str, Any] | None = None) -> None:
        """Add this test's figures to its area's in :data:`FIGURES` (parametrized tests add up)."""
        accumulate(figures(self.area), {"tests": 1, "cases": self.cases, "outcomes": dict(self.outcomes),
                                        "defects": self.total, "defect_kinds": len(self.groups), **(extra or {}),
                                        **({"notes": dict(self.notes)} if self.notes else {})})

    def check(self, extra: Mapping[str, Any] | None = None) -> None:
        """Record the figures, then fail listing every defect if there was one."""
        self.record(extra)
        assert not self.groups, self.report()


# ----------------------------------------------------------------------------------------------- messages

def representations(value: Any) -> list[str]:
    """Ways an error message may show ``value``: its repr (shortened as the config shortens it), its str, a float's
    forms; for a container, those of any of its items. Empty strings never count."""
    forms: list[str] = []
    if isinstance(value, (bool, np.bool_)) or value is None:
        forms += [repr(value), str(value)]
    elif isinstance(value, (int, np.integer)) and abs(int(value)) >= 10**200:
        forms += ["bits", "integer"]  # config.shown: "<an integer of N bits>"
    elif isinstance(value, (int, float, np.integer, np.floating)):
        number = float(value) if abs(int(value) if isinstance(value, (int, np.integer)) else 0) < 10**300 else None
        forms += [repr(value), str(value)]
        if number is not None:
            forms += [repr(number), str(number), f"{number:g}"]
            if math.isfinite(number) and number == int(number):
                forms.append(str(int(number)))
    elif isinstance(value, str):
        forms += [repr(value)[:60], value[:60] if len(value) >= 2 else repr(value)]
    elif isinstance(value, Mapping):
        forms += [short(value)[:40]] + [repr(key)[:60] for key in value] + [str(key)[:60] for key in value]
        for item in list(value.values())[:20]:
            forms += representations(item)
    elif isinstance(value, (list, tuple, np.ndarray)):
        forms += [short(value)[:40], str(value)[:40]]
        if not isinstance(value, np.ndarray) or value.size < 10**4:  # a config may show a list as a tuple and back
            forms += [short(tuple(np.asarray(value, dtype=object).ravel().tolist()))[:40],
                      short(list(np.asarray(value, dtype=object).ravel().tolist()))[:40]]
        for item in list(np.asarray(value, dtype=object).ravel())[:20] if not isinstance(value, np.ndarray) or \
                value.size < 10**6 else []:
            forms += representations(item)
    else:
        forms += [short(value)[:40], str(value)[:40]]
    return [form for form in forms if form and form.strip()]


def names_value(message: str, value: Any) -> bool:
    """Whether ``message`` shows ``value`` in one of its :func:`representations`."""
    return any(form in message for form in representations(value))


# ----------------------------------------------------------------------------------------------- step outputs

def bad_values(info: Mapping[str, Any], prefix: str = "") -> list[str]:
    """What in a (single or batched) info breaks "nothing NaN, inf only where documented": a list of
    ``key: what`` (empty when clean). ``final_obs`` rows and ``final_info`` are checked too."""
    problems = []
    for key, value in info.items():
        if key.startswith("_"):
            continue
        if isinstance(value, Mapping):
            problems += bad_values(value, f"{prefix}{key}/")
            continue
        array = np.asarray(value)
        if array.dtype == object:
            for i, row in enumerate(array.ravel()):
                if row is not None:
                    row = np.asarray(row)
                    if row.dtype.kind not in "fiub" or not np.isfinite(row.astype(float)).all():
                        problems.append(f"{prefix}{key}[{i}]: {row.dtype} row {short(row, 200)}")
            continue
        if array.dtype.kind not in "fiub":
            problems.append(f"{prefix}{key}: not numeric ({array.dtype})")
            continue
        if array.dtype.kind == "f":
            if np.isnan(array).any():
                problems.append(f"{prefix}{key}: NaN")
            elif np.isinf(array).any():
                name = key
                if name not in ALLOWED_INF:
                    problems.append(f"{prefix}{key}: inf ({short(array, 200)})")
                elif (array == -np.inf).any():
                    problems.append(f"{prefix}{key}: -inf")
    return problems


def bad_step(space: Any, obs: np.ndarray, reward: Any = 0.0) -> list[str]:
    """What breaks "a float32 observation within its space, finite; a finite reward" (a single env's or batched)."""
    problems = []
    obs = np.asarray(obs)
    if obs.dtype != np.float32:
        problems.append(f"observation dtype {obs.dtype}, not float32")
    if not np.isfinite(obs).all():
        problems.append(f"observation not finite: {short(obs, 200)}")
    elif not space.contains(obs):
        problems.append(f"observation outside {space}: min {obs.min()}, max {obs.max()}, shape {obs.shape}")
    reward = np.asarray(reward, dtype=float)
    if not np.isfinite(reward).all():
        problems.append(f"reward not finite: {short(reward, 200)}")
    return problems


class Digest:
    """A running SHA-256 of everything a run returned (observations, rewards, flags, infos), to compare runs bit for
    bit."""

    def __init__(self) -> None:
        self._hash = hashlib.sha256()

    def add(self, *values: Any) -> None:
        for value in values:
            if isinstance(value, Mapping):
                for key in sorted(value):
                    self._hash.update(key.encode())
                    self.add(value[key])
            elif isinstance(value, np.ndarray) and value.dtype == object:
                for row in value.ravel():
                    self.add(np.asarray(-1.0) if row is None else row)
            else:
                array = np.ascontiguousarray(np.asarray(value))
                self._hash.update(str(array.dtype).encode() + str(array.shape).encode() + array.tobytes())

    def hexdigest(self) -> str:
        return self._hash.hexdigest()


def same_infos(got: Mapping[str, Any], want: Mapping[str, Any], where: str = "") -> list[str]:
    """Differences between two infos (keys, dtypes, shapes, values; nested dicts and object arrays of rows)."""
    problems = []
    if sorted(got) != sorted(want):
        return [f"{where}: keys differ: {sorted(set(got) ^ set(want))}"]
    for key, value in want.items():
        mine = got[key]
        if isinstance(value, Mapping):
            problems += same_infos(mine, value, f"{where}/{key}")
        elif np.asarray(value).dtype == object:
            rows = [None if v is None else np.asarray(v).tolist() for v in value]
            if [None if v is None else np.asarray(v).tolist() for v in mine] != rows:
                problems.append(f"{where}/{key}: rows differ")
            if not all(v is None or np.asarray(v).dtype == np.float32 for v in mine):
                problems.append(f"{where}/{key}: rows not float32")
        else:
            mine, value = np.asarray(mine), np.asarray(value)
            if mine.dtype != value.dtype or mine.shape != value.shape:
                problems.append(f"{where}/{key}: {mine.dtype}{mine.shape} vs {value.dtype}{value.shape}")
            elif not np.array_equal(mine, value, equal_nan=True):
                problems.append(f"{where}/{key}: values differ")
    return problems


def first(items: Iterable[str], n: int = 3) -> str:
    return "; ".join(list(items)[:n])


def call(function: Callable[[], Any]) -> tuple[Any, BaseException | None]:
    """``(function(), None)`` or ``(None, the exception)``; KeyboardInterrupt still stops the run."""
    try:
        return function(), None
    except Exception as error:  # noqa: BLE001 - the fuzz judges every exception
        return None, error
