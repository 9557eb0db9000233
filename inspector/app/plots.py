"""The Plots tab: the ``routefuse run`` metrics table, the deviation plots of both runs and the
distance from the route, each with a marker at the playhead."""

from __future__ import annotations

from typing import Any

import viser

from inspector.controller import Session
from inspector.plots import metrics_markdown, pinned_uplot

DEVIATION_KINDS = ("position", "heading", "truth")
PLOT_PADDING = (12, 12, 0, 0)
"""uPlot's padding (top, right, bottom, left, px): room above the y axis's top label, which
uPlot centres on the plot's top edge and the title above it cut in half"""


class PlotsPanel:
    """The metrics and the plots; a plot is added with the first session that has it and
    hidden, not removed, when a later one does not."""

    def __init__(self, gui: viser.GuiApi, tab: viser.GuiTabHandle) -> None:
        self.gui = gui
        self.tab = tab
        self.plots: dict[str, viser.GuiUplotHandle] = {}
        self.pinned: Session | None = None
        """run A of the Compare tab, overlaid on the proposed run's plots (None: nothing)"""
        self._plot_t: float | None = None
        with tab:
            self.metrics = gui.add_markdown("")

    def show_session(self, session: Session, t: float) -> None:
        self.metrics.content = metrics_markdown(session.metrics, session.method)
        dev = session.deviation
        for k, which in enumerate(DEVIATION_KINDS):
            kw = dev.uplot(which, t) if which in dev.kinds else None
            self._plot(which, kw, aspect=1.6, order=self.metrics.order - 1.0 + 0.25 * k)
        off = session.off_route
        self._plot(
            "off_route",
            None if off is None else off.uplot(t),
            aspect=2.2,
            order=self.metrics.order - 0.25,
        )
        self.show_pinned(self.pinned, session, t)
        self._plot_t = None

    def show_pinned(self, a: Session | None, b: Session, t: float) -> None:
        """A's proposed run against B's on each deviation plot both have (hidden without A, or
        when A ran over another log or route)."""
        self.pinned = a
        for k, which in enumerate(DEVIATION_KINDS):
            kw = None
            if (
                a is not None
                and (a.log_path, a.route_path) == (b.log_path, b.route_path)
                and which in a.deviation.kinds
                and which in b.deviation.kinds
            ):
                kw = pinned_uplot(a.deviation, b.deviation, which, t)
            order = self.metrics.order - 0.9 + 0.25 * k
            self._plot(f"pinned_{which}", kw, aspect=1.6, order=order)

    def _plot(self, key: str, kw: dict[str, Any] | None, *, aspect: float, order: float) -> None:
        """Show the plot ``key`` with ``kw`` (``add_uplot``'s arguments): added the first time,
        its data replaced afterwards, hidden (not removed) when ``kw`` is None."""
        h = self.plots.get(key)
        if kw is None:
            if h is not None:
                h.visible = False
            return
        if h is None:
            with self.tab:
                self.plots[key] = self.gui.add_uplot(
                    kw["data"],
                    kw["series"],
                    scales=kw["scales"],
                    title=kw["title"],
                    aspect=aspect,
                    padding=PLOT_PADDING,
                    order=order,
                )
        else:
            h.data = kw["data"]
            h.visible = True

    def show_time(self, s: Session, t: float) -> None:
        """Move the plots' time markers (not more often than the plot's resolution needs)."""
        if self._plot_t is not None and abs(self._plot_t - t) <= s.timeline.duration / 800:
            return
        self._plot_t = t
        for which, h in self.plots.items():
            if which.startswith("pinned_"):
                kind = which.removeprefix("pinned_")
                if self.pinned is not None and h.visible:
                    h.data = pinned_uplot(self.pinned.deviation, s.deviation, kind, t)["data"]
            elif which in s.deviation.kinds:
                h.data = s.deviation.uplot(which, t)["data"]
            elif which == "off_route" and s.off_route is not None:
                h.data = s.off_route.uplot(t)["data"]
