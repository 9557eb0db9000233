"""``routefuse export --compare A.toml B.toml`` (issue 19): A, B and B - A, and every attempt
whose verdict changed with both gate tables, headless."""

from __future__ import annotations

import csv
from pathlib import Path

from inspector.cli.main import main

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"


def test_two_sets_on_one_log_are_compared_attempt_by_attempt(tmp_path, capsys):
    a = tmp_path / "defaults.toml"
    a.write_text("")
    b = tmp_path / "tight <residual>.toml"
    b.write_text("[gates]\nmax_residual_m = 0.6\n")
    out = tmp_path / "cmp"
    argv = [
        "export",
        str(SAMPLES / "monaco_tunnel.mcap"),
        "--route",
        str(SAMPLES / "monaco_tunnel.route.geojson"),
        "--out",
        str(out),
        "--compare",
        str(a),
        str(b),
    ]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "attempts changed verdict" in printed and "compare.html" in printed
    with open(out / "changed_verdicts.csv", encoding="utf-8") as f:
        changed = list(csv.DictReader(f))
    assert changed, "a tighter residual gate changed no verdict"
    assert all(r["A_verdict"] != r["B_verdict"] for r in changed)
    assert any(r["B_verdict"] == "rejected: residual" for r in changed)
    with open(out / "compare_metrics.csv", encoding="utf-8") as f:
        rows = {r["quantity"]: r for r in csv.DictReader(f)}
    accepted = rows["accepted"]
    assert int(accepted["B"]) < int(accepted["A"])
    truth = rows["truth horizontal RMSE [m]"]
    assert abs(float(truth["B - A"]) - (float(truth["B"]) - float(truth["A"]))) < 2e-3
    page = (out / "compare.html").read_text(encoding="utf-8")
    assert "tight &lt;residual&gt;.toml" in page and "<residual>" not in page
    assert page.count("<table>") >= 1 + len(changed)  # each changed attempt: its gate tables
    assert "http" not in page
    assert (out / "set_b.toml").read_text().count("max_residual_m = 0.6") == 1
    assert (
        main(
            [
                *argv[:1],
                "--batch",
                str(SAMPLES),
                "--out",
                str(tmp_path / "x"),
                "--compare",
                str(a),
                str(b),
            ]
        )
        == 3
    )


def test_the_difference_of_two_equal_figures_is_written_without_a_sign() -> None:
    from inspector.export.compare import _delta
    from inspector.fleet.report import _signed

    # 0.1 + 0.2 - 0.3 is 5.6e-17 in floats, the other way -5.6e-17
    assert _delta(0.1 + 0.2, 0.3) == "0.000"
    assert _delta(1.0, 1.25) == "+0.250" and _delta(1.25, 1.0) == "-0.250"
    assert _delta(None, 1.0) == "" and _delta(1.0, float("nan")) == "nan"
    assert _signed(0.3 - (0.1 + 0.2)) == "0.000" and _signed(-0.5) == "-0.500"


def test_the_compare_page_names_the_log_route_and_method_escaped(tmp_path):
    """compare.html used to name only the two TOML files: mailed on its own, it did not say
    which drive it compared on."""
    from estimator.params import Params
    from inspector.export.compare import Comparison, write_comparison

    comparison = Comparison(
        metrics=(("truth horizontal RMSE [m]", None, None), ("route deviation RMSE [m]", 1.0, 1.5)),
        attempts=(3, 3),
        accepted=(3, 2),
        changed=(),
    )
    log = tmp_path / "tunnel <b>bold é.mcap"
    route = tmp_path / "tunnel <b>bold é.route.geojson"
    write_comparison(
        tmp_path, comparison, Params(), Params(), ("a.toml", "b.toml"),
        log=log, route=route, method="paper",
    )  # fmt: skip
    page = (tmp_path / "compare.html").read_text(encoding="utf-8")
    assert "<b>bold" not in page
    assert f"log <code>{tmp_path}/tunnel &lt;b&gt;bold é.mcap</code>" in page
    assert "tunnel &lt;b&gt;bold é.route.geojson" in page and "method paper" in page
    assert "<title>routefuse: tunnel &lt;b&gt;bold é.mcap: a.toml vs b.toml</title>" in page
    assert "no ground truth in this log" in page
