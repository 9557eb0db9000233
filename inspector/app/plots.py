"""The Plots tab: the ``routefuse run`` metrics table, the deviation plots of both runs and the
distance from the route, each with a marker at the playhead."""

from __future__ import annotations

import viser

from inspector.controller import Session
from inspector.plots import metrics_markdown, pinned_uplot

DEVIATION_KINDS = ("position", "heading", "truth")


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
            h = self.plots.get(which)
            if which not in dev.kinds:
                if h is not None:
                    h.visible = False
                continue
            kw = dev.uplot(which, t)
            if h is None:
                with self.tab:
                    self.plots[which] = self.gui.add_uplot(
                        kw["data"],
                        kw["series"],
                        scales=kw["scales"],
                        title=kw["title"],
                        aspect=1.6,
                        order=self.metrics.order - 1.0 + 0.25 * k,
                    )
            else:
                h.data = kw["data"]
                h.visible = True
        self._show_off_route(session, t)
        self.show_pinned(self.pinned, session, t)
        self._plot_t = None

    def show_pinned(self, a: Session | None, b: Session, t: float) -> None:
        """A's proposed run against B's on each deviation plot both have (hidden without A)."""
        self.pinned = a
        for k, which in enumerate(DEVIATION_KINDS):
            key = f"pinned_{which}"
            h = self.plots.get(key)
            other_drive = a is not None and (a.log_path, a.route_path) != (b.log_path, b.route_path)
            if (
                a is None
                or other_drive
                or which not in a.deviation.kinds
                or which not in b.deviation.kinds
            ):
                if h is not None:
                    h.visible = False
                continue
            kw = pinned_uplot(a.deviation, b.deviation, which, t)
            if h is None:
                with self.tab:
                    self.plots[key] = self.gui.add_uplot(
                        kw["data"],
                        kw["series"],
                        scales=kw["scales"],
                        title=kw["title"],
                        aspect=1.6,
                        order=self.metrics.order - 0.9 + 0.25 * k,
                    )
            else:
                h.data = kw["data"]
                h.visible = True

    def _show_off_route(self, session: Session, t: float) -> None:
        """The vehicle's distance from the route with the off-route spans shaded."""
        h = self.plots.get("off_route")
        if session.off_route is None:
            if h is not None:
                h.visible = False
            return
        kw = session.off_route.uplot(t)
        if h is None:
            with self.tab:
                self.plots["off_route"] = self.gui.add_uplot(
                    kw["data"],
                    kw["series"],
                    scales=kw["scales"],
                    title=kw["title"],
                    aspect=2.2,
                    order=self.metrics.order - 0.25,
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
