"""The deviation plots' payloads, as the Plots tab and the export draw them."""

from __future__ import annotations

from fake_runs import FakeInputs, make_route, make_run

from inspector.plots import DeviationPlot


def test_plot_payloads_carry_their_own_titles_units_and_time_marker():
    base, prop = make_run(drift=30, method="baseline"), make_run()
    plot = DeviationPlot.build(FakeInputs(None, make_route(), prop.frame), base, prop)
    assert plot.kinds == ("position", "heading")  # no truth in these runs
    titles = set()
    for which in plot.kinds:
        kw = plot.uplot(which, 50.0)
        titles.add(kw["title"])
        xs, _, _, shade, now = kw["data"]
        assert len({len(a) for a in kw["data"]}) == 1 and len(kw["series"]) == 5
        k = int(abs(xs - 50.0).argmin())
        assert now.max() == 2.0 and xs[now.argmax()] == 50.0  # the marker spans the plot
        assert shade[k] == 1.0 and shade[0] == 0.0  # 50 s is inside the outage
        unit = "deg" if which == "heading" else "m"
        assert kw["series"][1]["label"] == f"baseline [{unit}]"
    assert len(titles) == 2
    assert plot.position[0].max() > 20 > plot.position[1].max()  # baseline drifts 30 m
