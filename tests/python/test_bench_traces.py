"""`juno bench` reads bench_fmu's traces by column position (python_harness/juno/bench.py): its
list of trace columns must be the C program's, or the accuracy figures compare other signals."""

from __future__ import annotations

import re
from pathlib import Path

from juno.bench import ACCURACY_SIGNALS, TRACE_COLUMNS

ROOT = Path(__file__).resolve().parents[2]


def _c_trace_names() -> list[str]:
    """The trace_names initializer of bench/bench_fmu.c (the C side, checked there against the
    size of the model's Outputs struct)."""
    source = (ROOT / "bench" / "bench_fmu.c").read_text()
    body = re.search(r"trace_names\[\]\s*=\s*\{(.*?)\};", source, re.S)
    assert body, "bench_fmu.c has no trace_names initializer"
    return re.findall(r'"([^"]+)"', body.group(1))


def test_the_harness_reads_the_trace_columns_bench_fmu_writes():
    assert list(TRACE_COLUMNS) == _c_trace_names()


def test_every_accuracy_signal_is_a_trace_column():
    assert set(ACCURACY_SIGNALS) <= set(TRACE_COLUMNS)
