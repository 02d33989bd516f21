# SPDX-License-Identifier: Apache-2.0
"""Every plot of `review.plots` in the matplotlib convention: it returns the Figure it drew,
draws into the axes (`ax=`) or figure (`fig=`) it is given and returns that figure, and makes a
pyplot-free Figure when given none (the CLI's PNGs: test_figures, test_cli, test_replay,
test_fleet, test_transient)."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure

from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.model.nonlinear import analyse, simulate
from leadscrew_ros.model.nonlinear.transient import TransientSettings
from leadscrew_ros.model.studies.stability_map import stability_map
from leadscrew_ros.model.studies.sweep import sweep
from leadscrew_ros.review import plots
from leadscrew_ros.review.fleet import FleetRun
from leadscrew_ros.review.replay import ReplaySettings, replay
from leadscrew_ros.review.timeline import InputSettings


@pytest.fixture(scope="module")
def speed_sweep():
    return sweep(SqueakModel(), "speed_rad_s", np.geomspace(0.5, 120.0, 25))


@pytest.fixture(scope="module")
def speed_map():
    return stability_map(
        SqueakModel(),
        "load_n",
        np.linspace(0.0, 600.0, 4),
        "speed_rad_s",
        np.geomspace(1.0, 100.0, 5),
        probability=True,
    )


@pytest.fixture(scope="module")
def transient():
    run = simulate(ScrewParameters(), 20.0, 200.0, TransientSettings(duration_s=0.02, modes=6))
    return run, analyse(run)


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    cycle = DutyCycle(duration_s=6.0, rate_hz=20.0, rest_s=1.0)
    tmp = tmp_path_factory.mktemp("replay")
    return replay(
        write_log(cycle, tmp / "bag"),
        SqueakModel(),
        tmp / "out",
        ReplaySettings(InputSettings(joint_name=cycle.joint_name), workers=0, progress=False),
    )


FLEET = FleetRun(
    rows=[
        {"status": "ok", "episodes": 2, "time_in_squeak_s": 1.5, "unit_id": "a"},
        {"status": "ok", "episodes": 0, "time_in_squeak_s": 0.0, "unit_id": "b"},
        {"status": "error"},
    ],
    points=[[20.0, 200.0, 1500.0], [25.0, 210.0, 1520.0]],
    reviewed=3,
    skipped=0,
)

# (plot, the fixture of its data or None, other arguments): one axes
SINGLE = {
    "map": (plots.plot_map, "speed_map", {}),
    "map with P": (plots.plot_map, "speed_map", {"overlay": "probability"}),
    "frequencies": (plots.plot_frequencies, "speed_sweep", {}),
    "sweep": (plots.plot_sweep, "speed_sweep", {"probability": True}),
    "friction": (plots.plot_friction, None, {}),
}


def _single_args(request, fixture, options):
    if fixture is None:  # the friction law: parameters and sliding speeds
        return (ScrewParameters(), np.linspace(0.0, 1.0, 50)), {}
    data = request.getfixturevalue(fixture)
    if options.get("overlay") == "probability":
        options = {"overlay": plots.probability_overlay(data)}
    return (data,), options


@pytest.mark.parametrize("name", SINGLE)
def test_a_plot_makes_its_figure(name, request):
    plot, fixture, options = SINGLE[name]
    args, kwargs = _single_args(request, fixture, options)
    fig = plot(*args, **kwargs)
    assert isinstance(fig, Figure) and fig.axes and fig.canvas.manager is None  # no pyplot


@pytest.mark.parametrize("name", SINGLE)
def test_a_plot_draws_into_the_axes_it_is_given(name, request):
    plot, fixture, options = SINGLE[name]
    args, kwargs = _single_args(request, fixture, options)
    given = Figure()
    left, right = given.subplots(1, 2)
    assert plot(*args, **kwargs, ax=right) is given
    assert right.has_data() and not left.has_data()


def test_the_panels_go_into_the_figure_given(transient, replayed):
    run, analysis = transient
    for draw, panels in (
        (lambda fig: plots.plot_transient(run, analysis, fig=fig), 3),
        (lambda fig: plots.plot_timeline(replayed, fig=fig), 4),
        (lambda fig: replayed.plot(fig=fig), 4),
        (lambda fig: plots.plot_fleet(FLEET, fig=fig), 4),
    ):
        new = draw(None)
        assert isinstance(new, Figure) and len(new.axes) >= panels
        given = Figure()
        assert draw(given) is given and len(given.axes) == len(new.axes)


def test_nothing_is_written(tmp_path, monkeypatch, speed_sweep):
    monkeypatch.chdir(tmp_path)
    plots.plot_sweep(speed_sweep).canvas.draw()
    assert not list(tmp_path.iterdir())


def test_the_fleet_panels_count_logs_as_their_titles_say():
    """5 logs, 1 error: '1 error' (not '1 errors'); the squeak panel's title and its bars'
    shares both of all 5 logs; whole-number log ticks; the error log named in the
    time-in-squeak panel."""
    rows = [
        {"status": "ok", "episodes": 2, "time_in_squeak_s": t, "unit_id": f"u{k}"}
        for k, t in enumerate([2.5, 2.6, 1.9, 3.1])
    ]
    rows.append({"status": "error", "unit_id": "broken", "error": "not a log"})
    run = FleetRun(rows=rows, points=FLEET.points, reviewed=5, skipped=0)
    fig = plots.plot_fleet(run)
    fig.canvas.draw()
    a, _, c, _ = fig.axes[:4]
    assert fig.get_suptitle() == "fleet review: 5 logs, 1 error"
    assert a.get_title() == "4 of 5 logs squeak"
    assert [t.get_text() for t in a.texts] == ["4 (80 %)", "0 (0 %)", "1 (20 %)"]
    ticks = [t for t in a.get_yticks() if a.get_ylim()[0] <= t <= a.get_ylim()[1]]
    assert ticks and all(float(t).is_integer() for t in ticks)
    labels = [t.get_text() for t in c.get_yticklabels()]
    assert labels[0] == "broken" and "error" in [t.get_text().strip() for t in c.texts]


def test_a_maps_colourbar_ticks_are_round_and_its_contour_labels_upright(speed_map):
    """Issue 32: the colourbar was ticked at its contour levels (454.2, 363.4, ...) and a
    '90 %' label read top to bottom once the layout had changed the axes' aspect."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = plots.plot_map(speed_map, overlay=plots.probability_overlay(speed_map))
    FigureCanvasAgg(fig).draw()
    bar = fig.axes[1]
    lo, hi = bar.get_ylim()
    ticks = [t for t in bar.get_yticks() if lo <= t <= hi]
    assert 0.0 in ticks and len(ticks) >= 4
    assert all(float(f"{t:.1g}") == t or float(f"{t:.2g}") == t and t % 5 == 0 for t in ticks)
    # read left to right, or bottom to top: none steeper than 60 degrees top to bottom (the
    # labels of this map were at -69, -65 and -88 degrees)
    angles = [(t.get_rotation() + 180.0) % 360.0 - 180.0 for t in fig.axes[0].texts]
    assert angles and all(-60.0 <= a <= 90.0 for a in angles), angles
