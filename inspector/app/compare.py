"""The Compare tab: pin the run on screen as A, change parameters, and see the new run (B)
against it: A's trajectory and verdicts drawn beside B's, a table of A, B and B - A, and the
attempts whose verdict changed, stepped like the refused ones with both gate tables.

A is this tab's own (pinning in one tab does not pin in another); B is the session every tab
shows. The attempts are paired by time as in ``routefuse export --compare``
(:func:`inspector.export.compare.changed_verdicts`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import viser

from estimator.params import params_to_toml
from inspector.app.match import match_markdown
from inspector.app.widgets import markdown_text
from inspector.export.compare import ChangedVerdict, changed_verdicts
from inspector.layers import ACCEPTED, REJECTED
from inspector.numbers import signed
from inspector.scene_data import polyline_segments

if TYPE_CHECKING:
    from inspector.app.view import ClientView
    from inspector.controller import Session

PINNED = (150, 60, 200)
"""A's trajectory"""
ROOT = "/routefuse_pinned_a"
NOT_PINNED = (
    "*Nothing pinned.* **pin as A** keeps the run on screen; change a parameter and the new "
    "run (B) is compared with it here and drawn beside it (A in violet)."
)


GAP = "&ensp;"
"""the space kept between two right-aligned figures of the comparison table"""


def compare_markdown(a: Session, b: Session) -> str:
    """A, B and B - A of the proposed run's figures, and the count of changed verdicts."""
    if a.version == b.version:
        return "**A is pinned** and on screen: change a parameter to compare a new run with it."
    if not same_drive(a, b):
        return (
            f"**A was pinned on {markdown_text(a.log_name)}**; "
            f"{markdown_text(b.log_name)} is on screen: nothing to compare (unpin A)."
        )
    rows = ["| quantity | A | B | B - A |", "|---|---:|---:|---:|"]
    for (label, _, va), (_, _, vb) in zip(a.metrics, b.metrics, strict=False):
        try:
            delta = signed(float(vb) - float(va), _decimals(va, vb))
        except ValueError:
            delta = ""
        # an en space before B and B - A: the table has no cell padding, and right-aligned
        # columns ran together ('5.0550.000', '21+2')
        rows.append(f"| {markdown_text(label)} | {va} | {GAP}{vb} | {GAP}{delta} |")
    changed = changed_verdicts(a.proposed, b.proposed)
    return "\n".join(
        [
            f"**A** (pinned, drawn in violet) against **B** (on screen): {len(changed)} attempts "
            "changed verdict",
            "",
            *rows,
        ]
    )


def _decimals(*shown: str) -> int:
    """The most decimals among figures as shown ('27.2' 1, '43' 0), for their difference: a
    count's is '+2', not '+2.000', and a figure shown to 0.1 is not differenced to 0.001."""
    return max(len(v.partition(".")[2]) for v in shown)


def same_drive(a: Session, b: Session) -> bool:
    """Whether two sessions ran over the same log and route (else no attempt pairs up)."""
    return (a.log_path, a.route_path) == (b.log_path, b.route_path)


def changed_markdown(c: ChangedVerdict | None, n: int, k: int | None) -> str:
    """Both gate tables of the changed attempt at the playhead."""
    if c is None:
        return "*No changed attempt at this time: use* **changed ›**."
    head = f"**Changed attempt {k + 1 if k is not None else '?'} of {n}, t = {c.t:.2f} s**"
    a = "*A made no attempt here.*" if c.a is None else match_markdown(c.a, t_rel=c.t)
    b = "*B made no attempt here.*" if c.b is None else match_markdown(c.b, t_rel=c.t)
    return f"{head}\n\n**A (pinned)**\n\n{a}\n\n---\n\n**B (on screen)**\n\n{b}"


class ComparePanel:
    """Pin, unpin, save A's parameters; the comparison and the changed attempts."""

    def __init__(self, view: ClientView, gui: viser.GuiApi) -> None:
        self.view = view
        self.pinned: Session | None = None
        self._changed: tuple[ChangedVerdict, ...] = ()
        self._against: int | None = None
        pin = gui.add_button("pin as A", hint="keep the run on screen to compare the next with")
        pin.on_click(lambda _: self.pin())
        self.unpin_button = gui.add_button("unpin A", visible=False)
        self.unpin_button.on_click(lambda _: self.unpin())
        self.save_a = gui.add_button("save A's parameters", visible=False)
        self.save_a.on_click(lambda _: self._save_a())
        self.steps = gui.add_button_group("changed", ("‹ changed", "changed ›"), visible=False)
        self.steps.on_click(self._on_step)
        self.summary = gui.add_markdown(NOT_PINNED)
        self.detail = gui.add_markdown("")

    # -- actions -------------------------------------------------------------------------------

    def pin(self) -> None:
        s = self.view.session
        if s is None:
            return
        self.pinned = s
        self._against = None
        self.unpin_button.visible = self.save_a.visible = True
        self._draw_pinned(s)
        self.view.plots.show_pinned(s, s, self.view.playhead.t)
        self.show(s, self.view.playhead.t)

    def unpin(self) -> None:
        self.pinned = None
        self._changed = ()
        self.unpin_button.visible = self.save_a.visible = self.steps.visible = False
        self.view.client.scene.remove_by_name(ROOT)
        if self.view.session is not None:
            self.view.plots.show_pinned(None, self.view.session, self.view.playhead.t)
        self.summary.content = NOT_PINNED
        self.detail.content = ""

    def _save_a(self) -> None:
        if self.pinned is not None:
            text = params_to_toml(self.pinned.params)
            self.view.client.send_file_download(
                "routefuse-params-A.toml", text.encode("utf-8"), save_immediately=True
            )

    def _on_step(self, event: viser.GuiEvent[viser.GuiButtonGroupHandle]) -> None:
        self.step(forward=self.steps.value == "changed ›")

    def step(self, *, forward: bool) -> None:
        """The playhead to the next (previous) attempt whose verdict changed."""
        view = self.view
        with view._lock:
            times = np.array([c.t for c in self._changed])
            t = view.playhead.t
            later = times[times > t + 1e-6] if forward else times[times < t - 1e-6]
            if not len(later):
                view.client.add_notification(
                    "Nothing there", "no changed attempt that way", auto_close_seconds=4.0
                )
                return
            view.playhead.playing = False
            view.playhead.t = float(later[0] if forward else later[-1])
            view.render()

    # -- drawing -------------------------------------------------------------------------------

    def _draw_pinned(self, a: Session) -> None:
        scene = self.view.client.scene
        scene.remove_by_name(ROOT)
        track = a.scene.proposed
        scene.add_line_segments(
            f"{ROOT}/track",
            polyline_segments(track.xy, 0.35),
            PINNED,
            thickness=2.0,
            thickness_units="screen",
        )
        xy = a.scene.match_xy
        ok = np.all(np.isfinite(xy), axis=1) if len(xy) else np.zeros(0, bool)
        if ok.any():
            colors = np.where(a.scene.match_accepted[ok, None], ACCEPTED, REJECTED)
            pts = np.column_stack([xy[ok], np.full(int(ok.sum()), 0.5)]).astype(np.float32)
            scene.add_point_cloud(
                f"{ROOT}/verdicts",
                pts,
                colors.astype(np.uint8),
                point_size=3.0,
                point_shape="diamond",
            )

    def show(self, b: Session, t: float) -> None:
        """The comparison with the session on screen at time ``t`` (called at every render)."""
        a = self.pinned
        if a is None:
            return
        if self._against != b.version:
            self._against = b.version
            comparable = a.version != b.version and same_drive(a, b)
            self._changed = changed_verdicts(a.proposed, b.proposed) if comparable else ()
            self.summary.content = compare_markdown(a, b)
            self.steps.visible = bool(self._changed)
        if not self._changed:
            self.detail.content = ""
            return
        times = np.array([c.t for c in self._changed])
        k = int(np.argmin(np.abs(times - t)))
        here = self._changed[k] if abs(times[k] - t) < 0.05 else None
        self.detail.content = changed_markdown(here, len(self._changed), k if here else None)
