"""One runner over many logs: log expansion, output naming, per-log failure isolation, one progress
bar, local processes (`--jobs N`) and a Dask cluster (`--scheduler ADDRESS`).

    logs = expand_logs(["runs/", "extra.mcap"])
    outcomes = run_many(logs, task, jobs=4, progress=True)   # results in input order

``task`` is any picklable callable of one log path, or of one tuple whose first item is the log
path (`logscan analyze` passes (log, report path) pairs); a module-level function or a
functools.partial of one; it returns what the caller wants back. A log whose task raises becomes a
`LogFailure` in its place and never stops the others. Results do not depend on ``jobs``: each log
is processed by the same task, and outcomes come back in the order of ``logs``.

With ``scheduler`` (``tcp://host:8786``, or ``local:N`` for a LocalCluster of N worker processes
started for the run) the same task runs on Dask workers (`run_on_dask`): same outcomes, same order.
Workers must see the logs and the output directories at the same paths (a shared file system).
"""

from logscan.fleet.dask import check_scheduler, run_on_dask
from logscan.fleet.expand import LOG_FILE_SUFFIXES, expand_logs
from logscan.fleet.failures import LogFailure, failure_of
from logscan.fleet.local import run_many
from logscan.fleet.outputs import output_paths, refuse_clobbering, unique_names

__all__ = [
    "LOG_FILE_SUFFIXES",
    "LogFailure",
    "check_scheduler",
    "expand_logs",
    "failure_of",
    "output_paths",
    "refuse_clobbering",
    "run_many",
    "run_on_dask",
    "unique_names",
]
