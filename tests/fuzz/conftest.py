"""Print the fuzzers' counts at the end of a run that set IMPACT_ENV_FUZZ_REPORT (``make fuzz`` does)."""

from __future__ import annotations

import json
import os
from collections import defaultdict
from pathlib import Path


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    path = os.environ.get("IMPACT_ENV_FUZZ_REPORT")
    if not path or not Path(path).is_file() or hasattr(config, "workerinput"):
        return
    totals: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    for line in Path(path).read_text().splitlines():
        row = json.loads(line)
        for key in ("inputs", "worked", "rejected", "seconds"):
            totals[row["fuzzer"]][key] += row.get(key) or 0
    write = terminalreporter.write_line
    write("")
    write("| fuzzer | inputs | checks that worked | checks rejected with a typed error | seconds |")
    write("|---|---:|---:|---:|---:|")
    for name in sorted(totals):
        t = totals[name]
        write(f"| {name} | {int(t['inputs']):,} | {int(t['worked']):,} | {int(t['rejected']):,} | "
              f"{t['seconds']:.0f} |")
    write(f"| all | {int(sum(t['inputs'] for t in totals.values())):,} | "
          f"{int(sum(t['worked'] for t in totals.values())):,} | "
          f"{int(sum(t['rejected'] for t in totals.values())):,} | |")
