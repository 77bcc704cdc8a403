"""What `pip install .` installs is what the tests tested: the wheel built from the tracked files,
installed into a fresh venv outside the checkout (tests/conftest.py: installed_wheel), ships every
package and runs `analyze` on a log of every vehicle model and `train` on the Jackal samples.

The checkout's own tests run an editable install, which finds any module in the tree: a package the
wheel leaves out (logscan.recovery once was) shows only here."""

from __future__ import annotations

import json
import re
import subprocess
import zipfile
from pathlib import PurePosixPath

import pytest
from conftest import REPO, SAMPLES

from logscan import __version__

pytestmark = pytest.mark.slow

# one sample log per vehicle model of sample_logs/README.md's table (its "model" column), chosen
# with a fault so that analyze exits 1 and writes alarms into the report
MODEL_SAMPLES = {
    "quadcopter": "quad_imu_bias.mcap",
    "steer_by_wire": "sbw_yaw_rate_bitflip.mcap",
    "dc_motor": "jackal_gps_bias.mcap",
    "ins": "ins_imu_bias.mcap",
    "hover_uav": "hover_rotor_offset.mcap",
    "ground_robot": "ground_robot_attack.mcap",  # hierarchical loops and the recovery engine
}
# the other readers on models already compiled: a ROS 2 (CDR) bag with the built-in ros2 profile,
# and a wide CSV with its sidecar profile and truth
READER_SAMPLES = ["ros2_ins.mcap", "quad_healthy.csv"]
JACKAL_TRAINING = ["jackal_train_1.mcap", "jackal_train_2.mcap"]


def sample_models() -> dict[str, str]:
    """log name -> model, from the table of sample_logs/README.md."""
    text = (SAMPLES / "README.md").read_text(encoding="utf-8")
    return dict(re.findall(r"^\| `([^`]+)` \| (\w+) \|", text, re.M))


def tracked(*patterns: str) -> list[str]:
    """The paths git tracks that match these patterns (what a clean clone holds)."""
    listed = subprocess.run(["git", "ls-files", *patterns], cwd=REPO, capture_output=True, text=True, check=True)
    return listed.stdout.split()


def test_every_model_of_the_samples_is_analysed_here():
    models = sample_models()
    assert models, "sample_logs/README.md has no table of logs and models"
    assert set(models.values()) == set(MODEL_SAMPLES), "a sample model has no log in MODEL_SAMPLES"
    for model, log in MODEL_SAMPLES.items():
        assert models[log] == model, (log, models[log], model)


def test_the_wheel_ships_every_package_and_nothing_else(installed_wheel):
    names = zipfile.ZipFile(installed_wheel.wheel).namelist()
    shipped = {name.rsplit("/", 1)[0] for name in names if name.endswith(".py")}
    # every tracked folder of Python modules, under the name it installs as
    expected = {  # every tracked folder of Python modules, under the name it installs as
        str(PurePosixPath("logscan", *PurePosixPath(path).parts[path.startswith("logscan/") :]).parent)
        for path in tracked("logscan/*.py", "detectors/*.py", "templates/*.py")
    }
    assert "logscan/recovery" in shipped
    assert shipped == expected, (sorted(expected - shipped), sorted(shipped - expected))
    assert installed_wheel.wheel.name.startswith(f"logscan-{__version__}-")
    templates = {name.rsplit("/", 1)[1] for name in names if name.startswith("logscan/templates/")}
    for path in tracked(*(f"templates/*.{ext}" for ext in ("j2", "html", "css", "js"))):
        assert path.rsplit("/", 1)[1] in templates, f"{path} is not shipped"
    tops = {name.split("/", 1)[0] for name in names}
    assert tops == {"logscan", f"logscan-{__version__}.dist-info"}, tops
    assert not [name for name in names if "__pycache__" in name or name.endswith((".pyc", ".nbi", ".nbc"))]


def test_version_and_import_come_from_the_venv_not_the_checkout(installed_wheel):
    version = installed_wheel.run("--version")
    assert version.returncode == 0, version.stderr[-2000:]
    assert version.stdout.startswith(f"logscan {__version__}"), version.stdout
    where = installed_wheel.python("import logscan, logscan.recovery, logscan.detectors; print(logscan.__file__)")
    assert where.returncode == 0, where.stderr[-2000:]
    assert where.stdout.strip().startswith(str(installed_wheel.venv)), where.stdout


@pytest.mark.timeout(1800)  # the first run compiles every model's kernels (about 90 s on an idle machine)
def test_analyze_a_log_of_every_model_and_reader(installed_wheel):
    logs = [SAMPLES / name for name in (*MODEL_SAMPLES.values(), *READER_SAMPLES)]
    out = installed_wheel.workdir / "reports"
    result = installed_wheel.run("analyze", *logs, "-o", f"{out}/", "--json", "summary.json")
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    assert result.returncode == 1, (result.returncode, result.stderr[-3000:])  # faults: alarms, never 3
    summary = json.loads((installed_wheel.workdir / "summary.json").read_text(encoding="utf-8"))
    assert summary["errors"] == [] and summary["logscan_version"] == __version__
    by_name = {entry["file"].rsplit("/", 1)[1]: entry for entry in summary["logs"]}
    assert sorted(by_name) == sorted(log.name for log in logs)
    for name, entry in by_name.items():
        expected = 0 if name in READER_SAMPLES else 1  # the readers' samples are healthy
        assert entry["exit_code"] == expected and entry["failed_detectors"] == [], (name, entry["verdict"])
        report = out / f"{name.rsplit('.', 1)[0]}.report.html"
        assert entry["report"] == str(report) and report.stat().st_size > 100_000, name
    assert "recovery" in by_name["ground_robot_attack.mcap"]  # the roll-forward recovery ran
    assert (out / "index.html").is_file()


def test_train_on_the_jackal_samples_and_analyze_with_the_tables(installed_wheel):
    tables = installed_wheel.workdir / "jackal.tables.json"
    trained = installed_wheel.run("train", *(SAMPLES / name for name in JACKAL_TRAINING), "-o", tables)
    assert trained.returncode == 0, trained.stderr[-3000:]
    assert json.loads(tables.read_text(encoding="utf-8"))["training_logs"]
    assert tables.with_suffix(".html").stat().st_size > 100_000  # the training report
    faulty = SAMPLES / MODEL_SAMPLES["dc_motor"]
    analysed = installed_wheel.run("analyze", faulty, "--tables", tables, "-d", "atfm", "--no-report")
    assert analysed.returncode == 1, analysed.stderr[-3000:]
    assert "atfm.gps_speed.gps" in analysed.stdout
