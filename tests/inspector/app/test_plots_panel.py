"""The Plots tab's plots in a real (browser-less) viser server."""

from __future__ import annotations

import socket

import numpy as np
import pytest
import viser

from inspector.app.plots import PlotsPanel

AXIS_FONT_PX = 12
"""the size of uPlot's axis labels, which it centres on the top tick"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    yield srv
    srv.stop()


def test_each_plot_leaves_room_above_its_top_axis_label(server):
    # uPlot draws the top tick's label centred on the plot's top edge: with no padding above
    # it, the title above cut it in half ("60" of the distance plot read as a sliver)
    panel = PlotsPanel(server.gui, server.gui.add_tab_group().add_tab("Plots"))
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
