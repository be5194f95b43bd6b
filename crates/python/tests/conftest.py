"""Shared fixtures: generated houses, the `ferret` binary the package is compared with, and the
real ProcTHOR data when FERRET_PROCTHOR_DIR points at it."""

import csv
import os
import subprocess
from pathlib import Path

import pytest
from hypothesis import settings

import ferret

# No example database in the checkout or the working directory: every run draws afresh from
# the test's own seed range.
settings.register_profile("ferret", database=None, deadline=None)
settings.load_profile("ferret")

# The houses the comparisons with `ferret eval` run on.
HOUSES, HOUSE_SEED = 12, 3


@pytest.fixture(scope="session")
def houses():
    return ferret.generate_houses(HOUSES, HOUSE_SEED)


@pytest.fixture(scope="session")
def ferret_bin():
    path = os.environ.get("FERRET_BIN")
    if not path:
        pytest.fail("FERRET_BIN is not set: run the tests with scripts/python-tests.sh")
    if not Path(path).is_file():
        pytest.fail(
            f"FERRET_BIN={path}: no such file; build it with cargo build --release -p ferret-cli"
        )
    return path


def run_cli(ferret_bin, *args, cwd=None):
    """Runs the `ferret` binary; fails the test with its stderr when it fails."""
    out = subprocess.run([ferret_bin, *args], capture_output=True, text=True, cwd=cwd)
    assert out.returncode == 0, f"ferret {' '.join(args)} failed:\n{out.stderr}"
    return out


def read_trials(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="session")
def procthor_dir():
    d = os.environ.get("FERRET_PROCTHOR_DIR")
    if not d:
        pytest.skip(
            "real ProcTHOR houses: set FERRET_PROCTHOR_DIR to the directory holding "
            "multiroom-val150.jsonl.gz to run these tests"
        )
    return Path(d)
