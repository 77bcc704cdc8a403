"""The analysed span in the terminal header of `logscan analyze`: the log's length when the grid
covers the whole log (to within its end steps), "start-end s of whole s" for a window or a grid
that leaves a part of the log out."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from logscan.cli.render import _analysed_span


def analysis(start: float, end: float, dt: float, whole: float, window=None) -> SimpleNamespace:
    run = SimpleNamespace(t=np.arange(start, end + dt / 2, dt), dt=dt, window=window)
    return SimpleNamespace(run=run, log=SimpleNamespace(duration_s=whole), prepared=SimpleNamespace(lead_in=None))


def test_a_grid_starting_a_fraction_of_its_step_after_time_zero_is_the_whole_log():
    # a ROS bag analysed without its IMU: a 10 Hz grid from the odometry, 3 ms after the IMU's first sample
    assert _analysed_span(analysis(0.003232792, 395.303232792, 0.1, 395.30711614)) == "395.3 s"


def test_a_grid_from_time_zero_to_the_end_is_the_whole_log():
    assert _analysed_span(analysis(0.0, 60.0, 0.01, 60.0)) == "60.0 s"


def test_a_window_is_shown_even_when_it_covers_the_log():
    assert _analysed_span(analysis(0.0, 60.0, 0.01, 60.0, window=(0.0, None))) == "0.0-60.0 s of 60.0 s"


def test_a_grid_that_leaves_more_than_its_end_steps_out_shows_its_span():
    assert _analysed_span(analysis(5.0, 395.3, 0.1, 395.3)) == "5.0-395.3 s of 395.3 s"  # inputs start late
    assert _analysed_span(analysis(0.0, 50.0, 0.01, 60.0)) == "0.0-50.0 s of 60.0 s"  # outlying times dropped
