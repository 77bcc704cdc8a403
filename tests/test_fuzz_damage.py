"""Damage the readers must count, through `python -m logscan analyze`: never "no alarms" (exit 0) or
a verdict (exit 1) on damaged input, never exit 3, and a valid oddity reads as its seed does.

The classes and mutators are `bench/fuzz_damage.py`'s (its campaign runs hundreds of cases per
class; bench/README.md): edits inside MCAP chunks with their CRCs recomputed (a message's channel id
undefined, a Channel record taking another channel's id, a log_time beyond int64 ns), lz4 chunks
declaring another size than they hold (1 GiB, 500 MiB, off by one...), one 1-16 MiB all-zero
message added to an MCAP (valid: it must read), ULog 'A' records and type bytes damaged, a CSV cut
inside its last row. Seeds are healthy windows of the shipped jackal MCAP (lz4 and zstd), the quad
CSV and two PX4 ULogs of ../shared/testdata (skipped when absent, unless LOGSCAN_REQUIRE_TESTDATA).

One batch per run: CASES cases per class (ten times as many with ``--campaign=full``), analysed by
one process per group of arguments, like `tests/test_fuzz.py`.
"""

from __future__ import annotations

import importlib.util
import random
import sys
from pathlib import Path

import pytest
from conftest import REPO, need_testdata

import logscan

CASES = 4  # per class


def _damage_module():
    spec = importlib.util.spec_from_file_location("fuzz_damage", REPO / "bench" / "fuzz_damage.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_damage"] = module
    spec.loader.exec_module(module)
    return module


fd = _damage_module()
fc = fd.fc


@pytest.fixture(scope="module")
def damage(tmp_path_factory, request):
    root = tmp_path_factory.mktemp("fuzz-damage")
    seeds = fd.damage_seeds(fc.build_seeds(root / "seeds"))
    runner = fc.Runner(root / "work", fc.child_env(logscan.cache_dir()), keep=root / "failures")
    runner.workdir.mkdir()
    seed_problems = fc.warm_up(runner, seeds)
    per_class = CASES * (10 if request.config.getoption("campaign") == "full" else 1)
    rng = random.Random(31)
    cases = []
    for damage_class in fd.CLASSES:
        if fd.CLASS_FORMAT[damage_class] == "ulog" and not any(s.fmt == "ulog" for s in seeds.values()):
            continue
        cases += fd.draw(seeds, damage_class, per_class, rng)
    outcomes = fd.judge(seeds, runner.analyze(cases))
    return seeds, seed_problems, outcomes, runner.keep


def _of(outcomes: list, damage_class: str) -> list:
    return [o for o in outcomes if o.case.kind == damage_class]


def _failures(outcomes: list, keep: Path) -> str:
    lines = [f"  {o.case.label[:160]}\n    exit {o.exit_code}: {'; '.join(o.problems)[:300]}" for o in outcomes]
    return "\n".join(lines[:10]) + f"\n(cases kept in {keep})"


def test_the_seeds_are_healthy_fully_checked_logs(damage):
    seeds, seed_problems, _outcomes, _keep = damage
    assert not seed_problems, seed_problems
    # "no alarms" on a healthy seed: a damaged copy that still said so would be visible
    assert {s.exit_code for s in seeds.values()} == {0}, {s.name: s.exit_code for s in seeds.values()}


@pytest.mark.parametrize("damage_class", ["mcap_inner", "mcap_lz4_lie", "csv_short_row"])
def test_damaged_input_is_never_passed_off_as_checked(damage, damage_class):
    _seeds, _problems, outcomes, keep = damage
    mine = _of(outcomes, damage_class)
    assert len(mine) >= CASES
    failed = [o for o in mine if o.problems]
    assert not failed, _failures(failed, keep)
    assert {o.exit_code for o in mine} == {2}, [(o.case.detail, o.exit_code) for o in mine]


def test_damaged_ulog_subscriptions_and_type_bytes_are_never_passed_off_as_checked(damage):
    need_testdata("px4-ulog")
    _seeds, _problems, outcomes, keep = damage
    mine = _of(outcomes, "ulog_subscription")
    assert len(mine) >= CASES
    failed = [o for o in mine if o.problems]
    assert not failed, _failures(failed, keep)
    assert {o.exit_code for o in mine} == {2}, [(o.case.detail, o.exit_code) for o in mine]


def test_an_all_zero_chunk_reads_as_its_seed(damage):
    seeds, _problems, outcomes, keep = damage
    mine = _of(outcomes, "mcap_zero_chunk")
    assert len(mine) >= CASES
    failed = [o for o in mine if o.problems]  # fd.judge: the seed's own exit code, nothing else
    assert not failed, _failures(failed, keep)
    assert all(o.exit_code == seeds[o.case.seed].exit_code == 0 and not o.partial for o in mine)


def test_no_case_exits_3_or_runs_out_of_memory(damage):
    _seeds, _problems, outcomes, _keep = damage
    assert all(o.exit_code in (0, 1, 2) for o in outcomes)
    assert max(o.max_rss_mb for o in outcomes) < 2048
