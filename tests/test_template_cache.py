"""The report templates are compiled once per machine: jinja2's bytecode cache in logscan's cache
directory (`logscan.report.page_assets.environment`)."""

from __future__ import annotations

import pytest

from logscan.report import page_assets


@pytest.fixture
def fresh_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("LOGSCAN_CACHE_DIR", str(tmp_path / "cache"))
    page_assets.environment.cache_clear()
    yield tmp_path / "cache" / "templates"
    page_assets.environment.cache_clear()


def test_a_compiled_template_is_kept_and_renders_the_same(fresh_environment):
    first = page_assets.environment().get_template("index.html.j2")
    stored = list(fresh_environment.glob("*.cache"))
    assert len(stored) == 1 and stored[0].stat().st_size > 0
    page_assets.environment.cache_clear()  # a new process: the template comes from the cache
    again = page_assets.environment().get_template("index.html.j2")
    assert again is not first and again.render is not None
    assert list(fresh_environment.glob("*.cache")) == stored


def test_an_unwritable_cache_directory_means_no_cache(fresh_environment, monkeypatch):
    monkeypatch.setattr(page_assets.os, "access", lambda path, mode: False)
    assert page_assets.environment().bytecode_cache is None
    assert page_assets.environment().get_template("index.html.j2") is not None  # compiled in memory
