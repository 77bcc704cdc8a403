"""Fuzzing in CI: mutated MCAP, CSV, ULog and profile inputs through `python -m logscan` never crash,
hang, exhaust memory or pass damaged input off as checked.

The mutators, seeds, runner and oracle are `bench/fuzz_campaign.py`'s (its long campaign runs
10,000+ cases; bench/README.md); here hypothesis draws a fixed, derandomised few hundred cases:
byte flips, truncations, record and chunk lengths (MCAP), message sizes (ULog), one timestamp far
off (days late, 2**63-1, negative, zero), NaN / inf / huge / non-numbers in values, control
characters and empty strings in names, broken profiles (values, keys, lines, bytes). Seeds are
5-25 s windows of the shipped sample logs (lz4 and zstd chunks with CRCs, a data-section CRC,
unchunked JSON without CRCs, ROS 2 CDR), the CSV with its sidecars, two PX4 ULogs from
../shared/testdata and the profiles the logs embed.

Each batch of cases is analysed by one `python -m logscan analyze F1 F2 ... --no-report --json -`
process (each log's exit code is in the JSON; failures of one log do not stop the others), with a
60 s timeout per case and a 2 GiB address-space cap; a batch that goes wrong as a whole (hang,
signal, traceback, a log missing from the JSON) is split in halves until the culprits run alone.
A failing case is kept under the session's temporary directory (`.../fuzz*/failures/`) with a .txt
saying what was done and what went wrong; known bugs (`fuzz_campaign.KNOWN_BUGS`, each with an
xfail(strict) reproducer below) are waived symptom by symptom, any other problem fails.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import pickle
import random
import shutil
import stat
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import REPO
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import logscan


def _campaign():
    spec = importlib.util.spec_from_file_location("fuzz_campaign", REPO / "bench" / "fuzz_campaign.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_campaign"] = module  # dataclasses look their module up while it loads
    spec.loader.exec_module(module)
    return module


fc = _campaign()
REGRESSIONS = Path(__file__).resolve().parent / "fuzz_regressions"
BATCH = 40


def fuzz_settings(examples: int):
    """Derandomised (the same cases every run), no shrinking (each failing case is named and kept
    instead: a shrink step costs a subprocess)."""
    return settings(
        max_examples=examples,
        derandomize=True,
        database=None,
        deadline=None,
        phases=(Phase.explicit, Phase.generate),
        suppress_health_check=[HealthCheck.too_slow],
    )


@dataclass
class Fuzz:
    """The session's seeds (warmed up) and runner."""

    seeds: dict
    runner: object
    seed_problems: list[str]


def seed_inputs_digest() -> str:
    """sha256 of what the seeds are made from: the campaign's source, the sample logs and the
    shared ULogs (names and bytes), and this Python (the seeds are pickled)."""
    digest = hashlib.sha256(f"{sys.version_info[:2]} {pickle.HIGHEST_PROTOCOL}".encode())
    inputs = [Path(fc.__file__), *sorted(fc.SAMPLES.iterdir())]
    inputs += sorted(fc.ULOG_DIR.glob("*.ulg")) if fc.ULOG_DIR.is_dir() else []
    for path in inputs:
        if path.is_file():
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:24]


def cached_seeds(cache: Path) -> dict:
    """The seeds, built once per content of their inputs (seed_inputs_digest) and kept under
    ``cache``: the profile files the seeds' --profile arguments name live beside the pickle. A
    directory is built aside and renamed into place, so concurrent sessions (pytest-xdist workers)
    never see half of one."""
    built = cache / seed_inputs_digest()
    if not (built / "seeds.pickle").is_file():
        cache.mkdir(parents=True, exist_ok=True)
        aside = Path(tempfile.mkdtemp(prefix=f"{built.name}.", dir=cache))
        seeds = fc.build_seeds(aside)
        for seed in seeds.values():  # --profile paths point into the final directory
            seed.args = tuple(a.replace(str(aside), str(built)) for a in seed.args)
        (aside / "seeds.pickle").write_bytes(pickle.dumps(seeds))
        try:
            aside.rename(built)
        except OSError:  # another session renamed its copy first: use that one
            shutil.rmtree(aside, ignore_errors=True)
    return pickle.loads((built / "seeds.pickle").read_bytes())


@pytest.fixture(scope="session")
def fuzz(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    work = root / "work"
    work.mkdir()
    seeds = cached_seeds(logscan.cache_dir() / "fuzz-seeds")
    # the children share the compiled kernels of this process and of every other logscan run (the
    # numba cache is keyed on the kernels' sources: logscan/numba_cache.py)
    runner = fc.Runner(work, fc.child_env(logscan.cache_dir()), keep=root / "failures")
    problems = fc.warm_up(runner, seeds)  # a clean run of every seed (compiles what is not cached yet)
    return Fuzz(seeds, runner, problems)


def assert_all_pass(fuzz: Fuzz, outcomes: list) -> None:
    failed = [o for o in outcomes if o.problems]  # known bugs are waived by the runner
    report = "\n".join(
        f"  {o.case.label[:160]}\n    exit {o.exit_code}: {'; '.join(o.problems)[:400]}" for o in failed[:15]
    )
    kept = f"\n(cases kept in {fuzz.runner.keep})" if failed else ""
    assert not failed, f"{len(failed)} of {len(outcomes)} cases failed:\n{report}{kept}"


def assert_ran(outcomes: list, verdicts: bool = True) -> None:
    """The batch really ran: not every case ended the same way (all unreadable, say); ``verdicts``:
    some cases still got one (exit 0 or 1)."""
    seen = {o.exit_code for o in outcomes}
    assert 2 in seen and (not verdicts or seen & {0, 1}), seen


def test_seeds_are_clean_runs(fuzz):
    """Every seed, intact, is a fully checked log (exit 0 or 1): a mutation's exit 2 is its own."""
    assert not fuzz.seed_problems, fuzz.seed_problems
    assert {s.exit_code for s in fuzz.seeds.values()} <= {0, 1}
    assert {s.exit_code for s in fuzz.seeds.values() if s.fmt == "mcap"} == {0, 1}


BATCH_SEEDS = st.integers(0, 2**32 - 1)  # one batch of BATCH cases each (fuzz_campaign.draw_cases)


def run_batch(fuzz: Fuzz, fmt: str, kinds, batch_seed: int) -> list:
    return fuzz.runner.analyze(fc.draw_cases(fuzz.seeds, fmt, kinds, BATCH, random.Random(batch_seed)))


@fuzz_settings(examples=5)
@given(batch_seed=BATCH_SEEDS)
def test_mutated_mcap_gets_a_verdict_or_one_clear_error(fuzz, batch_seed):
    outcomes = run_batch(fuzz, "mcap", ["flip", "truncate", "length", "time", "special", "names"], batch_seed)
    assert_all_pass(fuzz, outcomes)
    assert_ran(outcomes)


@fuzz_settings(examples=5)
@given(batch_seed=BATCH_SEEDS)
def test_mutated_csv_gets_a_verdict_or_one_clear_error(fuzz, batch_seed):
    outcomes = run_batch(fuzz, "csv", ["flip", "truncate", "time", "special", "names", "structure"], batch_seed)
    assert_all_pass(fuzz, outcomes)
    assert_ran(outcomes)


@pytest.mark.testdata("px4-ulog")
@fuzz_settings(examples=4)
@given(batch_seed=BATCH_SEEDS)
def test_mutated_ulog_gets_a_verdict_or_one_clear_error(fuzz, batch_seed):
    outcomes = run_batch(fuzz, "ulog", ["flip", "truncate", "length", "time", "special", "names"], batch_seed)
    assert_all_pass(fuzz, outcomes)
    assert_ran(outcomes)


@fuzz_settings(examples=4)
@given(batch_seed=BATCH_SEEDS)
def test_mutated_embedded_and_sidecar_profiles_are_checked_or_refused(fuzz, batch_seed):
    """The profile an MCAP embeds or a CSV's sidecar: bad values, keys, lines and bytes."""
    rng = random.Random(batch_seed)
    drawn = fc.draw_cases(fuzz.seeds, "mcap", ["profile"], BATCH // 2, rng)
    drawn += fc.draw_cases(fuzz.seeds, "csv", ["profile"], BATCH // 2, rng)
    batch = [c for c in drawn if c.profile_arg is None]  # not the logs given --profile
    assert len(batch) > BATCH // 2
    outcomes = fuzz.runner.analyze(batch)
    assert_all_pass(fuzz, outcomes)
    assert_ran(outcomes, verdicts=False)


ULOG = pytest.mark.testdata("px4-ulog")


@pytest.mark.parametrize("name", ["quad_datacrc", pytest.param("ulog_tagged", marks=ULOG)])
@fuzz_settings(examples=6)
@given(case_seed=st.integers(0, 2**32 - 1))
def test_mutated_profile_option_is_checked_or_refused(fuzz, name, case_seed):
    """`--profile BROKEN.toml`: one log per process (the profile is the whole run's)."""
    case = fc.mutate(fuzz.seeds[name], "profile", random.Random(case_seed))
    assert case.profile_arg is not None
    assert_all_pass(fuzz, fuzz.runner.analyze([case]))


@pytest.mark.parametrize("fmt", ["mcap", "csv", pytest.param("ulog", marks=ULOG)])
@fuzz_settings(examples=4)
@given(case_seed=BATCH_SEEDS)
def test_one_mutated_log_per_process_and_its_inspect(fuzz, fmt, case_seed):
    """The single-log paths: `analyze LOG` (its error is the process's, without a JSON summary)
    and `logscan inspect LOG` (exit 0 or 2, PARTIAL when damaged, names printed escaped)."""
    (case,) = fc.draw_cases(fuzz.seeds, fmt, fc.MUTATORS[fmt], 1, random.Random(case_seed))
    outcomes = fuzz.runner.analyze([case])
    outcomes.append(fuzz.runner.inspect(case))
    assert_all_pass(fuzz, outcomes)


# --- the bugs the fuzzer found (tests/fuzz_regressions/README.md) ------------------------------


@dataclass
class Regression:
    file: str
    bug: str  # the bug's id (fuzz_regressions/README.md)
    open: bool = False  # not fixed yet: listed in fuzz_campaign.KNOWN_BUGS, the test is xfail(strict)
    damaged: bool = False  # the reader must notice (exit 2)
    profile: str | None = None  # passed as --profile (a file in fuzz_regressions/)
    command: str = "analyze"  # or "inspect"
    copies: int = 1  # analysed together in one process (several logs)
    kind: str = "regression"  # the mutation kind that found it (some KNOWN_BUGS symptoms need it)


REPRODUCERS = [
    Regression("mcap_chunk_opcode.mcap", "mcap-chunk-skipped", damaged=True, profile="mcap_chunk_opcode.toml"),
    Regression("json_huge_integer.mcap", "json-huge-integer"),
    Regression("profile_rate_tiny.csv", "profile-rate-tiny", kind="profile"),
    Regression("profile_stale_huge.csv", "profile-stale-overflow", kind="profile"),
    Regression("runtime_warning.mcap", "runtime-warning-leak"),
    Regression("ulog_missing_timestamp.ulg", "ulog-missing-timestamp", command="inspect"),
    Regression("unknown_detector.csv", "unknown-detector-unnamed"),
    Regression("unknown_detector.csv", "error-tuple-name", copies=2),
]


class KnownBugShows(Exception):
    """The reproducer shows its known bug, and nothing else (any other failure is a failure)."""


def _reproducer_param(regression: Regression):
    marks = ()
    if regression.open:
        reason = f"known bug {regression.bug!r} (fuzz_campaign.KNOWN_BUGS): remove the mark when it is fixed"
        marks = (pytest.mark.xfail(strict=True, raises=KnownBugShows, reason=reason),)
    return pytest.param(regression, marks=marks, id=f"{regression.file}-{regression.bug}")


@pytest.mark.parametrize("regression", [_reproducer_param(r) for r in REPRODUCERS])
def test_fuzz_regression(fuzz, regression):
    path = REGRESSIONS / regression.file
    sidecars = {  # a CSV's profile and truth
        suffix: (REGRESSIONS / f"{path.stem}{suffix}").read_bytes()
        for suffix in (".profile.toml", ".truth.json")
        if (REGRESSIONS / f"{path.stem}{suffix}").exists()
    }
    profile = (REGRESSIONS / regression.profile).read_text(encoding="utf-8") if regression.profile else None
    cases = [
        fc.Case(
            "regression",
            path.suffix[1:],
            regression.kind,
            regression.file,
            path.read_bytes(),
            path.suffix,
            damaged=regression.damaged,
            sidecars=sidecars,
            profile_arg=profile,
        )
        for _ in range(regression.copies)
    ]
    if regression.command == "inspect":
        outcomes = [fuzz.runner.inspect(case) for case in cases]
    else:
        outcomes = fuzz.runner.analyze(cases)
    for outcome in outcomes:
        assert not outcome.problems, f"exit {outcome.exit_code}: {outcome.problems}"
        if outcome.known:
            assert regression.bug in outcome.known.split(","), f"{outcome.known} instead of {regression.bug}"
            raise KnownBugShows(f"{outcome.known}: exit {outcome.exit_code}, {outcome.line}")


def test_json_output_to_a_fifo_is_written_into_or_refused_never_replaced(fuzz, tmp_path):
    """Found while building the fuzzer (`--json /dev/null`, as root, left /dev/null a regular file)."""
    fifo = tmp_path / "summary.json"
    os.mkfifo(fifo)
    log = tmp_path / "quad.mcap"
    log.write_bytes(fuzz.seeds["quad_zstd"].data)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()  # writing into the FIFO is as good as refusing it: a reader is there
    proc = fc.run_logscan(
        ["analyze", log.name, "--no-report", "--json", fifo.name, "-q"], cwd=tmp_path, env=fuzz.runner.env, timeout=60
    )
    if reader.is_alive():  # nothing opened the FIFO for writing: let the reader go
        with open(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK), "wb"):
            pass
        reader.join(5)
    assert proc.returncode in (1, 2), proc.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode), "the FIFO was replaced by a regular file"


def test_every_reproducer_is_listed():
    listed = {r.file for r in REPRODUCERS} | {r.profile for r in REPRODUCERS if r.profile}
    readme = (REGRESSIONS / "README.md").read_text(encoding="utf-8")
    for path in REGRESSIONS.iterdir():
        if path.suffix in (".mcap", ".csv", ".ulg", ".toml") and not path.name.endswith(".profile.toml"):
            assert path.name in listed, f"{path.name} has no Regression entry"
        if path.name != "README.md":
            assert f"`{path.name}`" in readme, f"{path.name} is not described in README.md"
    assert {r.bug for r in REPRODUCERS if r.open} <= set(fc.KNOWN_BUGS)
    assert not {r.bug for r in REPRODUCERS if not r.open} & set(fc.KNOWN_BUGS), "a fixed bug is still waived"


# --- the oracle and the runner themselves ------------------------------------------------------


def _case(damaged=False):
    return fc.Case("s", "mcap", "flip", "", b"", ".mcap", damaged=damaged)


def _entry(code, partial=False, unchecked=(), failed=()):
    return {
        "exit_code": code,
        "verdict": "v",
        "unchecked": list(unchecked),
        "failed_detectors": list(failed),
        "log": {"partial": partial},
    }


@pytest.mark.parametrize(
    "case, entry, is_error, flagged",
    [
        (_case(), _entry(0), False, False),
        (_case(), _entry(1), False, False),
        (_case(), _entry(2, partial=True), False, False),
        (_case(damaged=True), _entry(2, partial=True), False, False),
        (_case(), _entry(3, failed=["detector 'nis' failed: ValueError"]), False, True),
        (_case(), _entry(0, partial=True), False, True),
        (_case(), _entry(1, unchecked=["nis: never computed"]), False, True),
        (_case(damaged=True), _entry(0), False, True),
        (_case(), {"exit_code": 2, "error": "x.mcap: corrupt MCAP"}, True, False),
        (_case(), {"exit_code": 3, "error": "internal error: KeyError"}, True, True),
        (_case(), {"exit_code": 2, "error": "x.mcap: MemoryError"}, True, True),
    ],
)
def test_the_oracle_judges_each_log(case, entry, is_error, flagged):
    _code, problems, _line, _partial = fc.judge_entry(case, entry, is_error)
    assert bool(problems) == flagged, problems


@pytest.mark.parametrize(
    "returncode, stderr, flagged",
    [
        (0, "q.mcap: no alarms\n", False),
        (None, "", True),  # timed out
        (-9, "", True),  # killed
        (3, "Traceback (most recent call last):\n  File ...\nKeyError: 1\n", True),
        (2, "logscan: error: x.csv: MemoryError\n", True),
        (0, "/x/nis.py:103: RuntimeWarning: overflow encountered in cast\n  y = a * b\n", True),
        (2, "logscan: error: channel '\x1b[31m' is not in the log\n", True),
        (2, "logscan: error: channel '\\x1b[31m' is not in the log\n", False),
    ],
)
def test_the_oracle_reads_each_process(returncode, stderr, flagged):
    proc = fc.Proc(returncode, "", stderr, 1.0, 100.0)
    assert bool(fc.stream_problems(proc)) == flagged


def test_the_runner_kills_at_the_timeout_and_measures_memory(fuzz):
    hung = fc.run_logscan(["--version"], cwd=fuzz.runner.workdir, env=fuzz.runner.env, timeout=0.05)
    assert hung.returncode is None
    done = fc.run_logscan(["--version"], cwd=fuzz.runner.workdir, env=fuzz.runner.env)
    assert done.returncode == 0 and "logscan" in done.stdout and done.max_rss_mb > 10


def test_the_memory_cap_holds_in_the_child(fuzz):
    """The cap is the child's RLIMIT_AS: a log needs < 1 GiB of address space, so a child capped at
    a quarter of the cap cannot even start numba (and must not be mistaken for a clean run)."""
    seed = fuzz.seeds["quad_zstd"]
    path = fuzz.runner.workdir / "capped.mcap"
    path.write_bytes(seed.data)
    try:
        capped = fc.run_logscan(
            ["analyze", path.name, "--no-report", "--json", "-", "-q"],
            cwd=fuzz.runner.workdir,
            env=fuzz.runner.env,
            memory=fc.MEMORY_CAP_BYTES // 16,
        )
    finally:
        path.unlink()
    assert capped.returncode != seed.exit_code
