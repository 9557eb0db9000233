"""The Parameters tab: the method, the injected GNSS outages, and one widget per declared
parameter (grouped as :func:`estimator.params.param_specs` declares them)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any

import viser

from estimator.errors import RoutefuseError
from estimator.params import Params, ParamSpec, get_param, param_specs, params_to_toml
from inspector.app.widgets import Event, show_value
from inspector.controller import PROPOSED_METHODS, format_outages, parse_outages

if TYPE_CHECKING:
    from inspector.app.view import ClientView

GROUP_TITLES = {
    "trigger": "trigger",
    "window": "window",
    "gates": "gates",
    "pseudo": "pseudo-observation",
    "offset": "offset compensation",
    "extensions": "extensions",
    "noise": "noise",
    "sensors": "sensors",
    "general": "general",
}
TYPED_DECIMALS = 10
"""decimals a float parameter's box keeps as typed: viser gives a box the decimals of its step
(one for a 0.5 step) and the browser's number box drops every digit typed past them, so 0.33
became 0.3 without a word; the bounds still clamp, the step still drives the slider and the
arrows"""
TYPING_REST_S = 1.0
"""a refused parameter value is reported, and its control shows the value in effect again, only
once the control has rested this long: typing 0.0125 into a box whose minimum is 0.001 passes
through 0, and putting the old value back then broke into what the person was typing; a value
that is accepted within the rest cancels the report"""
OUTAGE_LABEL = "GNSS outages (s)"
OUTAGE_EDIT_QUIET_S = 1.0
"""the outage field applies its text once typing has rested this long: viser sends every
keystroke, and '3', '30', '30:' on the way to '30:60' are not outages the user meant"""


def param_widget(gui: viser.GuiApi, spec: ParamSpec, value: Any) -> viser.GuiInputHandle[Any]:
    """The widget a parameter's declaration calls for: checkbox, dropdown, vector, slider,
    number or text."""
    label = spec.name.rsplit(".", 1)[-1]
    hint = spec.doc + (f" [{spec.unit}]" if spec.unit else "")
    if spec.type is bool:
        return gui.add_checkbox(label, bool(value), hint=hint)
    if spec.choices:
        return gui.add_dropdown(label, spec.choices, initial_value=value, hint=hint)
    if str(spec.type).startswith("tuple"):
        vector = gui.add_vector3(label, tuple(value), step=0.01, hint=hint)
        vector.precision = TYPED_DECIMALS
        return vector
    if spec.type in (int, float) and spec.lo is not None and spec.hi is not None:
        step = spec.step or (1 if spec.type is int else (spec.hi - spec.lo) / 100)
        if spec.type is int:
            if (spec.hi - spec.lo) / step <= 2000:
                return gui.add_slider(
                    label, int(spec.lo), int(spec.hi), int(step), int(value), hint=hint
                )
            return gui.add_number(label, value, min=spec.lo, max=spec.hi, step=step, hint=hint)
        number: viser.GuiSliderHandle[float] | viser.GuiNumberHandle[float]
        if (spec.hi - spec.lo) / step <= 2000:
            number = gui.add_slider(
                label, float(spec.lo), float(spec.hi), float(step), float(value), hint=hint
            )
        else:
            number = gui.add_number(
                label, float(value), min=spec.lo, max=spec.hi, step=step, hint=hint
            )
        number.precision = TYPED_DECIMALS
        return number
    return gui.add_text(label, "" if value is None else str(value), hint=hint)


class ParametersPanel:
    """Edits the controller's shared parameters; shows them again when another tab, or a
    failed run, changed them."""

    def __init__(self, view: ClientView, gui: viser.GuiApi, *, lock: threading.RLock) -> None:
        self.view = view
        self._lock = lock
        self.client = view.client
        self.controller = view.app.controller
        self._widgets: dict[str, viser.GuiInputHandle[Any]] = {}
        self._outage_edits = 0
        self._outage_timer: threading.Timer | None = None
        self._refusals: dict[str, threading.Timer] = {}
        """per parameter, the report of its refused value waiting for the control to rest"""
        self._known: dict[str, Any] = {}
        """per parameter, the controller's value as this panel last knew it: :meth:`sync`
        shows only what changed on the controller's side since, never over a box being typed"""
        self.method = gui.add_dropdown(
            "method", PROPOSED_METHODS, initial_value=self.controller.method
        )
        self.method.on_update(self._on_method)
        self.outage_field = gui.add_text(
            OUTAGE_LABEL,
            format_outages(self.controller.outages),
            hint="remove GNSS between START and END seconds after the log start, as "
            "'routefuse run --outage START:END': e.g. 30:60, 90:120 (empty: none). "
            "Applied when you stop typing; opening another log clears them.",
        )
        self.outage_field.on_update(self._on_outages)
        reset = gui.add_button("reset to defaults")
        reset.on_click(lambda e: view.guard(self.controller.reset_params))
        save = gui.add_button("save parameters")
        save.on_click(self._on_save)
        self._add_widgets(gui)

    def _add_widgets(self, gui: viser.GuiApi) -> None:
        groups: dict[str, list[ParamSpec]] = {}
        for spec in param_specs():
            groups.setdefault(spec.group, []).append(spec)
        params = self.controller.params
        for group, specs in groups.items():
            with gui.add_folder(
                GROUP_TITLES.get(group, group),
                expand_by_default=group in ("trigger", "window", "gates"),
            ):
                for spec in specs:
                    widget = param_widget(gui, spec, get_param(params, spec.name))
                    widget.on_update(self._param_setter(spec.name))
                    self._widgets[spec.name] = widget
                    self._known[spec.name] = _shown(params, spec.name)

    def widget(self, name: str) -> viser.GuiInputHandle[Any]:
        """The control of a parameter by dotted name."""
        return self._widgets[name]

    def _param_setter(self, name: str) -> Callable[[Event], None]:
        def set_value(event: Event) -> None:
            if event.client is None:
                return
            with self._lock:
                pending = self._refusals.pop(name, None)
            if pending is not None:
                pending.cancel()
            try:
                self.controller.set_param(name, self._widgets[name].value)
            except RoutefuseError as exc:
                self._refuse_when_rested(name, exc)
            else:
                with self._lock:
                    self._known[name] = _shown(self.controller.params, name)

        return set_value

    def _refuse_when_rested(self, name: str, exc: RoutefuseError) -> None:
        if TYPING_REST_S <= 0:
            self._refuse(name, exc, None)
            return
        timer = threading.Timer(TYPING_REST_S, lambda: self._refuse(name, exc, timer))
        timer.daemon = True
        with self._lock:
            self._refusals[name] = timer
        timer.start()

    def _refuse(self, name: str, exc: RoutefuseError, timer: threading.Timer | None) -> None:
        with self._lock:
            if timer is not None and self._refusals.get(name) is not timer:
                return  # the control changed since
            self._refusals.pop(name, None)
        self.view.notify_error(exc)
        self.sync(refused=name)

    def _on_method(self, event: Event) -> None:
        if event.client is None:
            return
        self.view.guard(partial(self.controller.set_method, self.method.value))

    def _on_outages(self, event: Event) -> None:
        """Restart the quiet-period timer: the text is applied once the typing rests."""
        if event.client is None:
            return
        with self._lock:
            self._outage_edits += 1
            if self._outage_timer is not None:
                self._outage_timer.cancel()
            timer = threading.Timer(
                OUTAGE_EDIT_QUIET_S, self._commit_outages, args=(self._outage_edits,)
            )
            timer.daemon = True
            self._outage_timer = timer
        timer.start()

    def _commit_outages(self, edit: int) -> None:
        with self._lock:
            if edit != self._outage_edits:
                return  # typed again since
            self._outage_timer = None
            text = str(self.outage_field.value)
        try:
            self.controller.set_outages(parse_outages(text))
        except RoutefuseError as exc:
            kept = format_outages(self.controller.outages) or "none"
            self.client.add_notification(
                "GNSS outages not changed",
                f"{str(exc)[:300]} (kept: {kept})",
                color="red",
                auto_close_seconds=12.0,
            )

    def _on_save(self, event: Event) -> None:
        text = params_to_toml(self.controller.params)
        self.client.send_file_download(
            "routefuse-params.toml", text.encode("utf-8"), save_immediately=True
        )

    def sync(self, *, refused: str | None = None) -> None:
        """Show the controller's parameters where they changed on its side since this panel
        last knew them (another tab changed them, a reset, a failure), and in the control of
        ``refused``. Not over a control whose refused value waits for the typing to rest, nor
        over one whose value the controller still has: a session published while a person
        types 1234.5 (the run of 1234 done) must not put 1234 back into the box."""
        params = self.controller.params
        for name, widget in self._widgets.items():
            value = _shown(params, name)
            with self._lock:
                if name in self._refusals:
                    continue  # being typed: shown when it rests
                if name != refused and self._known.get(name) == value:
                    continue
                self._known[name] = value
            try:
                if widget.value != value:
                    show_value(widget, value)
            except (TypeError, ValueError):
                pass
        if self.method.value != self.controller.method:
            show_value(self.method, self.controller.method)
        self.sync_outages()

    def sync_outages(self) -> None:
        """Show the outages in effect, unless this tab is typing in the field (its text is
        applied, or refused, when the typing rests)."""
        if self._outage_timer is not None:
            return
        wanted = self.controller.outages
        try:
            shown = parse_outages(str(self.outage_field.value))
        except RoutefuseError:
            shown = None
        if shown != wanted:
            show_value(self.outage_field, format_outages(wanted))

    def close(self) -> None:
        with self._lock:
            for timer in self._refusals.values():
                timer.cancel()
            self._refusals.clear()
            if self._outage_timer is not None:
                self._outage_timer.cancel()
                self._outage_timer = None


def _shown(params: Params, name: str) -> Any:
    """A parameter's value as its control holds it (tuples of floats, ``""`` for None)."""
    value = get_param(params, name)
    if isinstance(value, tuple):
        return tuple(float(v) for v in value)
    return "" if value is None else value
