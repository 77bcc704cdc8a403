"""The pipeline of one log, in the order it runs (each step a module of this package):

    profile = load_profile_for(path, profile_path)           # preparation: the file, the log's embedded one, a built-in
    detectors = create_detectors(profile)                      # stages: parameters checked, no log read yet
    prepared = prepare(path, profile, needs_of(detectors))    # preparation: read the needed topics, align, filter
    analysis = detect(prepared, detectors)                    # detection: DetectorResults, scores against truth

The modules are named for the step (`preparation`, `detection`), the functions for the act, so a
re-exported function never hides its module. `run.analyze_log` alone composes them for one log;
`loops` runs a hierarchical profile's further loops; `release` frees what no detector still to run
reads. Training and evaluation call `prepare` and then fit or score. No module outside `detectors/`
names a detector: each declares what it needs (`Detector.needs`) and the pipeline runs the union of
those needs.
"""

from logscan.pipeline.detection import consistency_warnings, detect, rescore
from logscan.pipeline.preparation import builtin_profile_for, load_profile_for, prepare
from logscan.pipeline.release import RELEASABLE
from logscan.pipeline.run import analyze_log
from logscan.pipeline.stages import LoadedProfile, Prepared, create_detectors, needs_of
from logscan.verdict.nis_consistency import NIS_BLIND

__all__ = [
    "NIS_BLIND",
    "RELEASABLE",
    "LoadedProfile",
    "Prepared",
    "analyze_log",
    "builtin_profile_for",
    "consistency_warnings",
    "create_detectors",
    "detect",
    "load_profile_for",
    "needs_of",
    "prepare",
    "rescore",
]
