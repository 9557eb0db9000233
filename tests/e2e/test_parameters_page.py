"""Numbers typed into the Parameters tab in headless Chromium, key by key as a person types
them: a value within the bounds reaches the estimator as typed, whatever the control's step
(the box used to keep only the step's decimals: 12.33 in a 0.5-step box became 12.3), and
typing through a value below the minimum (0 on the way to 0.0125) is not broken into."""

from __future__ import annotations

import re

import pytest
from _browser import served, session_page, wait_until

from estimator.params import get_param
from tests.inspector.fake_runs import MONACO_LOG, MONACO_ROUTE

pytestmark = pytest.mark.e2e

VIEWPORT = {"width": 1400, "height": 1000}


def _box(page, label: str):
    """The number box on the row of the control labelled ``label`` (a slider's companion box,
    or a number input)."""
    return (
        page.locator("label", has_text=re.compile(f"^{re.escape(label)}$"))
        .first.locator("xpath=ancestor::div[contains(@class, 'mantine-Flex-root')][1]//input")
        .last
    )


def _type(page, label: str, text: str) -> None:
    box = _box(page, label)
    box.scroll_into_view_if_needed()
    box.click()
    box.press("Control+A")
    box.press_sequentially(text, delay=150)
    box.press("Tab")


@pytest.mark.parametrize(
    ("folder", "name", "typed", "expected"),
    [
        ("gates", "gates.max_correction_m", "12.33", 12.33),  # a slider, step 0.5
        ("noise", "noise.gyro_bias_tau_s", "1234.5", 1234.5),  # a number box, step 10
        # through 0, below the minimum 0.001: refused only if the typing rests there
        ("noise", "noise.gyro_arw_deg_sqrt_h", "0.0125", 0.0125),
    ],
)
def test_a_typed_number_within_bounds_is_kept_as_typed(
    browser, folder: str, name: str, typed: str, expected: float
) -> None:
    with served(MONACO_LOG, MONACO_ROUTE) as (server, controller, app):
        page, _ = session_page(browser, server, app, VIEWPORT)
        page.get_by_text("Legend").first.click()  # folded: the panel in view
        page.get_by_role("tab", name="Parameters").click()
        label = name.rsplit(".", 1)[-1]
        if not _box(page, label).is_visible():
            page.get_by_text(folder, exact=True).first.click()
        _type(page, label, typed)
        wait_until(
            lambda: get_param(controller.params, name) == expected,
            15,
            lambda: f"{name} = {expected} (have {get_param(controller.params, name)})",
        )
        assert _box(page, label).input_value() == typed
        page.wait_for_timeout(1500)  # past the typing rest: nothing reported
        assert "Error" not in page.inner_text("body")
        page.close()
