"""Collects the examples of README.md and docs/ as tests (Sybil; the rules are in
``tests/doc_examples.py``). The tests under tests/ have their own conftest.py."""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tests"))
matplotlib.use("Agg")

import doc_examples  # noqa: E402

pytest_collect_file = doc_examples.sybil().pytest()


@pytest.fixture(scope="session")
def doc_env(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> dict:
    """Where the pages run, and the main job's log and output, made once for all test
    processes (``pytest -n 2`` shares it between its workers)."""
    base = tmp_path_factory.getbasetemp()
    shared = base if worker_id == "master" else base.parent
    return {"base": base, "main_job": doc_examples.main_job(shared)}
