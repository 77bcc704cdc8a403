"""PX4 parameters in the report: those set away from their defaults, those changed in flight, and
a log without defaults saying so."""

from __future__ import annotations

import re

from test_report import HOSTILE, make_report
from test_run_context import sample_context
from test_ulog_reader import ulog

from logscan.readers.ulog_reader import read_ulog
from logscan.report import render_html
from logscan.report.parameters import parameter_facts

START_NS = 2_000_000_000
METADATA = {
    "ulog.parameters": {"BAT1_N_CELLS": "4", "MPC_XY_VEL_MAX": "12.0", "SYS_AUTOSTART": "4001", HOSTILE: "1"},
    "ulog.parameters_default": {"BAT1_N_CELLS": "0", "MPC_XY_VEL_MAX": "12", HOSTILE: "0"},
    "ulog.parameters_changed": {"00000": "5.500000 s MPC_XY_VEL_MAX = 8.0", "00001": "garbled"},
}


def test_only_parameters_away_from_their_default_are_listed():
    facts = parameter_facts(METADATA, START_NS)
    assert facts.has_defaults and facts.n_parameters == 4
    # 12.0 equals the default 12: not listed
    assert facts.differ == [(HOSTILE, "1", "0"), ("BAT1_N_CELLS", "4", "0")]  # by name
    assert facts.changed == [(3.5, "MPC_XY_VEL_MAX", "8.0")]  # s since the log's time zero


def test_float_values_are_shown_in_seven_digits():
    from logscan.report.parameters import value_text

    assert value_text("0.15150000154972076") == "0.1515" and value_text("-1") == "-1"
    assert value_text("1e-05") == "1e-05" and value_text("abc.def") == "abc.def"


def test_a_log_without_defaults_lists_the_changes_only_and_a_non_ulog_nothing():
    facts = parameter_facts({k: v for k, v in METADATA.items() if k != "ulog.parameters_default"}, START_NS)
    assert not facts.has_defaults and facts.differ == [] and len(facts.changed) == 1
    assert parameter_facts({"mcap.metadata": {}}, 0) is None


def _page(metadata: dict) -> str:
    report = make_report(6_000, truth=False)
    report.context = sample_context(6_000)
    report.context.parameters = parameter_facts(metadata, START_NS)
    return render_html(report)


def test_the_report_folds_the_parameter_tables_escaped():
    page = _page(METADATA)
    block = re.search(r'<details id="px4-parameters"><summary>(.*?)</summary>(.*?)</details>', page, re.S)
    assert block and block.group(1) == "parameters: 2 of 4 set away from PX4's defaults; 1 changed during the log"
    differ = re.findall(r"<tr><td>([^<]*)</td><td class=\"num\">([^<]*)</td><td class=\"num\">([^<]*)</td></tr>",
                        block.group(2))  # fmt: skip
    assert differ == [("&lt;script&gt;alert(1)&lt;/script&gt;", "1", "0"), ("BAT1_N_CELLS", "4", "0")]
    assert re.search(r'<tr data-start="3.5" data-end="3.5"><td class="num">[^<]*</td><td>MPC_XY_VEL_MAX</td>'
                     r'<td class="num">8</td>', block.group(2))  # fmt: skip
    assert HOSTILE not in page


def test_the_report_says_when_the_log_carries_no_defaults():
    page = _page({k: v for k, v in METADATA.items() if k != "ulog.parameters_default"})
    summary = re.search(r'<details id="px4-parameters"><summary>(.*?)</summary>', page).group(1)
    assert "the log carries no defaults" in summary and "1 of 4 changed during the log" in summary
    assert 'id="parameters-differ"' not in page


def test_the_ulog_reader_keeps_the_logs_parameter_defaults():
    log = read_ulog(ulog("sample_logging_tagged_and_default_params.ulg"), {"vehicle_status"})
    defaults = log.source.metadata["ulog.parameters_default"]
    assert len(defaults) == 44 and defaults["BAT1_N_CELLS"] == "0"
    assert log.source.metadata["ulog.parameters"]["BAT1_N_CELLS"] == "4"
    old = read_ulog(ulog("sample_log_small.ulg"), {"vehicle_status"})
    assert "ulog.parameters_default" not in old.source.metadata
