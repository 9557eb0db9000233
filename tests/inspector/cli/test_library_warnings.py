"""A library's Python warning inside a command is one routefuse line on stderr, once, without
the library's source line."""

from __future__ import annotations

import warnings

import pytest

from inspector.library_warnings import library_warnings_as_lines


def _library_call() -> None:
    warnings.warn(
        "Attempting to set identical low and high xlims makes transformation singular;\n"
        "automatically expanding.",
        UserWarning,
        stacklevel=1,
    )


def test_a_library_warning_is_one_line_once(capsys: pytest.CaptureFixture[str]) -> None:
    shown_before = warnings.showwarning
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        with library_warnings_as_lines("export"):
            _library_call()
            _library_call()
    assert warnings.showwarning is shown_before
    assert capsys.readouterr().err == (
        "routefuse export: warning: UserWarning: Attempting to set identical low and high "
        "xlims makes transformation singular;\n"
    )


def test_an_ignored_warning_stays_ignored(capsys: pytest.CaptureFixture[str]) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with library_warnings_as_lines("export"):
            _library_call()
    assert capsys.readouterr().err == ""
