"""The fuzz suite's figures: printed at the end of the run, and written as JSON to ``$TIMEGAP_FUZZ_FIGURES`` if set."""

from __future__ import annotations

import json
import os

from tests.fuzz.fuzzing import FIGURES


def pytest_terminal_summary(terminalreporter, exitstatus, config):  # noqa: ANN001, ANN201, ARG001
    if not FIGURES:
        return
    terminalreporter.section("fuzz figures (issue 22)")
    for area in sorted(FIGURES):
        terminalreporter.write_line(f"{area}: {json.dumps(FIGURES[area], sort_keys=True, default=str)}")
    path = os.environ.get("TIMEGAP_FUZZ_FIGURES")
    if path:
        with open(path, "w") as file:
            json.dump(FIGURES, file, indent=1, sort_keys=True, default=str)
