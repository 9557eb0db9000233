"""The Plots tab's plots in a real (browser-less) viser server."""

from __future__ import annotations

import numpy as np

from inspector.app.plots import PlotsPanel

AXIS_FONT_PX = 12
"""the size of uPlot's axis labels, which it centres on the top tick"""


def test_each_plot_leaves_room_above_its_top_axis_label(viser_server):
    # uPlot draws the top tick's label centred on the plot's top edge: with no padding above
    # it, the title above cut it in half ("60" of the distance plot read as a sliver)
    panel = PlotsPanel(viser_server.gui, viser_server.gui.add_tab_group().add_tab("Plots"))
    t = np.linspace(0.0, 10.0, 11)
    kw = {
        "data": (t, t * 6.0),
        "series": ({"label": "t [s]"}, {"label": "distance [m]"}),
        "scales": {"x": {"time": False}},
        "title": "a plot",
    }
    panel._plot("distance", kw, aspect=1.6, order=1.0)
    top, right, _, _ = panel.plots["distance"].padding or (0, 0, 0, 0)
    assert top >= AXIS_FONT_PX / 2 and right >= AXIS_FONT_PX / 2
