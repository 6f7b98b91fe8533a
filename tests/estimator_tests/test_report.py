"""The calibration report renderer: figures from small hand-made frames, and the HTML file."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.container import ErrorbarContainer
from matplotlib.figure import Figure

from estimator.report import (
    Section,
    accuracy_table_html,
    figure_bias_vs_mach,
    figure_crossplot,
    figure_table_updates,
    figure_time_history,
    save_png,
    write_report,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _visible_axes(fig: Figure) -> list:
    return [ax for ax in fig.axes if ax.get_visible()]


def _open_marker_lines(ax) -> list:
    """Lines drawn as markers only with hollow faces: the "truth" markers."""
    return [ln for ln in ax.get_lines()
            if ln.get_linestyle() == "None" and ln.get_markerfacecolor() == "none"]


def _errorbars(ax) -> list[ErrorbarContainer]:
    return [c for c in ax.containers if isinstance(c, ErrorbarContainer)]


@pytest.fixture
def bias() -> pd.DataFrame:
    rows = []
    for aircraft, offset_deg in (("PV1", 0.3), ("PT2", -0.2)):
        for mach in (0.4, 0.5, 0.6):
            rows.append({"mach": mach, "aircraft": aircraft, "mean_bias_deg": offset_deg + 0.1 * mach,
                         "std_deg": 0.02, "true_mean_bias_deg": offset_deg + 0.1 * mach + 0.01})
    return pd.DataFrame(rows)


@pytest.fixture
def updates() -> pd.DataFrame:
    rows = []
    for table, unit in (("f1", "deg"), ("f2", "-")):
        for mach, gear in ((0.4, "up"), (0.6, "up"), (0.4, "down")):
            for bp_deg in (0.0, 5.0, 10.0, 15.0):
                rows.append({"table": table, "breakpoint_deg": bp_deg, "mach": mach, "gear": gear,
                             "value": 0.01 * bp_deg + (0.2 if gear == "down" else 0.0), "std": 0.01,
                             "unit": unit})
    return pd.DataFrame(rows)


@pytest.fixture
def acc() -> pd.DataFrame:
    return pd.DataFrame({
        "sensor": ["vane AOA left", "vane AOA left", "nose-probe AOSS", "nose-probe AOSS", "boom AOA"],
        "channel": ["alpha_zl", "alpha_zl", "beta_znp", "beta_znp", "alpha_zb"],
        "mach": [0.3, 0.6, 0.3, 0.6, 0.6],
        "n": [4000, 5000, 4000, 5000, 5000],
        "three_sigma_deg": [0.38, 0.28, 0.68, 0.26, 0.16],
        "desired_deg": [0.5, 0.5, 0.5, 0.5, 1.0],
        "passed": [True, True, False, True, True],
        "note": ["", "", "AOA < 12 deg & <high>", "", ""],
    })


# --------------------------------------------------------------------------------------------------
# figures


def test_time_history_one_axes_per_channel_measured_and_model():
    t_s = np.arange(0.0, 10.0, 0.025)
    alpha_deg = 3.0 + np.sin(t_s)
    h_m = 6000.0 + t_s
    h_meas = h_m.copy()
    h_meas[np.arange(t_s.size) % 4 != 0] = np.nan  # a 10 Hz channel on the 40 Hz base
    fig = figure_time_history("PV1_M0.6_3211", t_s, {
        "alpha_zl": (alpha_deg + 0.05, alpha_deg, "deg"),
        "tas": (200.0 + 0 * t_s, 200.1 + 0 * t_s, "m/s"),
        "h": (h_meas, h_m, "m"),
    })
    axes = fig.axes
    assert len(axes) == 3
    for ax, unit in zip(axes, ("deg", "m/s", "m"), strict=True):
        assert len(ax.get_lines()) == 2
        assert f"[{unit}]" in ax.get_ylabel()
        assert unit in ax.get_title(loc="right")
    assert "0.05 deg" in axes[0].get_title(loc="right")
    # the slow channel is drawn through its samples, not broken up by the NaNs between them
    measured_h = axes[2].get_lines()[0]
    assert len(measured_h.get_xdata()) == int(np.isfinite(h_meas).sum())
    assert "time [s]" in axes[-1].get_xlabel()
    assert "PV1_M0.6_3211" in fig.get_suptitle()


def test_time_history_rejects_arrays_off_the_time_base():
    t_s = np.arange(10.0)
    with pytest.raises(ValueError, match="alpha_zr"):
        figure_time_history("m1", t_s, {"alpha_zr": (np.zeros(10), np.zeros(9), "deg")})


def test_bias_vs_mach_lines_fleet_mean_and_truth(bias):
    fig = figure_bias_vs_mach(bias, reference_mach=0.5)
    (ax,) = fig.axes
    assert len(_errorbars(ax)) == 2  # one per aircraft
    fleet = [ln for ln in ax.get_lines() if ln.get_label().startswith("fleet mean")]
    assert len(fleet) == 1
    expected = bias.groupby("mach")["mean_bias_deg"].mean()
    np.testing.assert_allclose(fleet[0].get_xdata(), expected.index)
    np.testing.assert_allclose(fleet[0].get_ydata(), expected.to_numpy())
    truth = _open_marker_lines(ax)
    assert len(truth) == 2 and all(len(ln.get_xdata()) == 3 for ln in truth)
    assert "[deg]" in ax.get_ylabel() and "Mach" in ax.get_xlabel()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[:2] == ["PV1", "PT2"] and "truth (open markers)" in labels


def test_bias_vs_mach_names_the_model_sets_biases(bias):
    # the label comes from the caller (the model set's apportioned families), not from this module
    (ax,) = figure_bias_vs_mach(bias, bias_label="$b_{a}$").axes
    assert ax.get_ylabel() == "$b_{a}$ [deg]" and "$b_{a}$" in ax.get_title()
    (ax,) = figure_bias_vs_mach(bias).axes
    assert ax.get_ylabel() == "mean bias [deg]"


def test_bias_vs_mach_without_truth_and_with_missing_columns(bias):
    fig = figure_bias_vs_mach(bias.drop(columns="true_mean_bias_deg"))
    assert _open_marker_lines(fig.axes[0]) == []
    with pytest.raises(ValueError, match="std_deg"):
        figure_bias_vs_mach(bias.drop(columns="std_deg"))


def test_crossplot_subsamples_deterministically_and_draws_limits():
    rng = np.random.default_rng(3)
    n = 60_000
    x_deg = rng.uniform(-2.0, 18.0, n)
    err_deg = rng.normal(0.0, 0.1, n)
    err_deg[:5] = np.nan  # dropped, not plotted
    figs = [figure_crossplot(x_deg, err_deg, "vane AOA left", "alpha_yl [deg]", "alpha_zl - alpha_yl [deg]",
                             limit_deg=0.5, x_limit_deg=12.0) for _ in range(2)]
    (ax,) = figs[0].axes
    (points,) = ax.collections
    assert points.get_rasterized()
    offsets = points.get_offsets()
    assert len(offsets) == 50_000
    np.testing.assert_array_equal(offsets, figs[1].axes[0].collections[0].get_offsets())
    horizontal = sorted(ln.get_ydata()[0] for ln in ax.get_lines() if ln.get_linestyle() == "--")
    assert horizontal == [-0.5, 0.5]
    vertical = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
    assert len(vertical) == 1 and vertical[0].get_xdata()[0] == 12.0
    assert ax.get_xlabel() == "alpha_yl [deg]" and ax.get_ylabel() == "alpha_zl - alpha_yl [deg]"
    # the statistics use every finite point, not the subsample
    text = ax.texts[0].get_text()
    assert f"n = {n - 5:,}" in text
    assert f"{3 * np.nanstd(err_deg):.3f} deg" in text


def test_crossplot_small_sample_draws_every_point_and_needs_finite_data():
    fig = figure_crossplot(np.arange(100.0), np.zeros(100), "t", "x [deg]", "e [deg]")
    assert len(fig.axes[0].collections[0].get_offsets()) == 100
    with pytest.raises(ValueError, match="no finite"):
        figure_crossplot(np.array([np.nan]), np.array([0.0]), "t", "x [deg]", "e [deg]")


def test_table_updates_one_axes_per_table_gear_down_dashed(updates):
    truth = updates.assign(truth=updates["value"] + 0.01)
    fig = figure_table_updates(truth)
    axes = _visible_axes(fig)
    assert [ax.get_title() for ax in axes] == ["f1 update", "f2 update"]
    for ax, unit in zip(axes, ("deg", "-"), strict=True):
        bars = _errorbars(ax)
        assert len(bars) == 3  # (0.4, up), (0.6, up), (0.4, down)
        styles = sorted(c.lines[0].get_linestyle() for c in bars)
        assert styles == ["-", "-", "--"]
        assert all(len(c.lines[0].get_xdata()) == 4 for c in bars)
        assert f"[{unit}]" in ax.get_ylabel() and "[deg]" in ax.get_xlabel()
        assert len(_open_marker_lines(ax)) == 3
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "M 0.40, gear down" in labels and "truth (open markers)" in labels


def test_table_updates_rejects_bad_gear_and_mixed_units(updates):
    with pytest.raises(ValueError, match="gear"):
        figure_table_updates(updates.assign(gear="retracted"))
    mixed = updates.copy()
    mixed.loc[0, "unit"] = "rad"
    with pytest.raises(ValueError, match="f1"):
        figure_table_updates(mixed)


def test_save_png_writes_a_png(tmp_path, bias):
    fig = figure_bias_vs_mach(bias)
    path = save_png(fig, tmp_path / "sub" / "fig4.png")
    assert path.read_bytes()[:8] == PNG_MAGIC
    assert fig.axes  # still open: it can go into the report too


# --------------------------------------------------------------------------------------------------
# tables and the HTML file


def test_accuracy_table_marks_pass_fail_and_missing(acc):
    text = accuracy_table_html(acc, "3 sigma <model - measurement>")
    assert "3 sigma &lt;model - measurement&gt;" in text
    assert re.search(r'<td class="fail"[^>]*>0\.68<sup>1</sup></td>', text)
    assert re.search(r'<td class="pass"[^>]*>0\.38</td>', text)
    assert text.count('class="fail"') == 2  # the failing cell and the legend
    # boom AOA flew only at Mach 0.6: its Mach 0.3 cell is empty
    boom_row = next(r for r in text.split("<tr>") if r.startswith("<th>boom AOA"))
    assert '<td class="na">—</td>' in boom_row and 'class="desired">1</td>' in boom_row
    assert [m for m in re.findall(r"<th>M (\d\.\d\d)</th>", text)] == ["0.30", "0.60"]
    assert "AOA &lt; 12 deg &amp; &lt;high&gt;" in text and "<high>" not in text


def test_accuracy_table_gear_down_bin_is_its_own_column(acc):
    # the default campaign flies gear-down maneuvers at Mach 0.3 beside gear-up ones at Mach 0.3
    down = acc[acc["mach"] == 0.3].assign(gear="down", three_sigma_deg=0.11)
    text = accuracy_table_html(pd.concat([acc.assign(gear="up"), down]), "t")
    assert re.findall(r"<th>(M \d\.\d\d(?:<br>gear down)?)</th>", text) == [
        "M 0.30", "M 0.30<br>gear down", "M 0.60"]
    assert text.count(">0.11<") == int((acc["mach"] == 0.3).sum())


def test_accuracy_table_rejects_duplicate_cells(acc):
    with pytest.raises(ValueError, match="vane AOA left"):
        accuracy_table_html(pd.concat([acc, acc.iloc[[0]]]), "t")


def test_write_report_is_self_contained_escaped_and_writes_csv(tmp_path, bias, updates, acc):
    long = pd.DataFrame({"t_s": np.arange(150) / 40.0, "alpha_deg": np.linspace(0, 5, 150),
                         "maneuver": ["m1"] * 150, "ok": [True, False] * 75})
    figs = [figure_bias_vs_mach(bias), figure_table_updates(updates),
            figure_crossplot(np.arange(50.0), np.zeros(50), "c", "x [deg]", "e [deg]")]
    sections = [
        Section("Vane <biases>", text="First paragraph.\n\n<script>alert(1)</script>\nsecond line",
                tables=[("bias per aircraft", bias)], figures=[("Fig. 4", figs[0])],
                csv=[("vane_bias.csv", bias)]),
        Section("Table updates", figures=[("Fig. 6", figs[1]), ("Fig. 5 & 7", figs[2])],
                tables=[("long table", long)]),
        Section("Accuracy", tables=[("", accuracy_table_html(acc, "Table 2"))], csv=[("accuracy.csv", acc)]),
    ]
    path = write_report(tmp_path / "out", "Calibration <report>", sections, max_table_rows=60)
    assert path == tmp_path / "out" / "report.html"
    page = path.read_text(encoding="utf-8")

    for heading in ("Vane &lt;biases&gt;", "Table updates", "Accuracy"):
        assert heading in page
    assert page.index("Vane &lt;biases&gt;") < page.index("Table updates") < page.index("Accuracy")
    assert "<title>Calibration &lt;report&gt;</title>" in page and "generated " in page
    assert page.count('href="#s') == 3  # the table of contents
    assert "<script>" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "<p>First paragraph.</p>" in page and "<br>second line" in page
    # self-contained: every figure embedded as a PNG, nothing fetched from elsewhere
    images = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(images) == 3
    assert all(base64.b64decode(b)[:8] == PNG_MAGIC for b in images)
    assert not re.search(r'(src|href)="(https?:)?//', page)
    assert all(not fig.axes for fig in figs)  # closed after embedding
    assert re.search(r'<td class="fail"[^>]*>0\.68', page)

    # a long DataFrame shows 60 rows and points at a CSV with all of them
    long_html = page[page.index("long table"):]
    assert long_html[: long_html.index("</table>")].count("<td>m1</td>") == 60
    note = re.search(r'all 150 rows in <a href="([^"]+)">', page)
    assert note
    out = tmp_path / "out"
    pd.testing.assert_frame_equal(pd.read_csv(out / note.group(1)), long)
    pd.testing.assert_frame_equal(pd.read_csv(out / "vane_bias.csv"), bias)
    back = pd.read_csv(out / "accuracy.csv", keep_default_na=False)
    pd.testing.assert_frame_equal(back, acc)
    assert 'href="vane_bias.csv"' in page and 'href="accuracy.csv"' in page


def test_write_report_refuses_a_csv_name_used_twice_or_with_a_directory(tmp_path, bias):
    one, other = bias, bias.assign(std_deg=1.0)
    with pytest.raises(ValueError, match="two different frames"):
        write_report(tmp_path, "r", [Section("a", csv=[("b.csv", one)]),
                                     Section("c", csv=[("b.csv", other)])])
    with pytest.raises(ValueError, match="plain file name"):
        write_report(tmp_path, "r", [Section("a", csv=[("../b.csv", one)])])
    assert not (tmp_path.parent / "b.csv").exists()


def test_report_module_does_not_depend_on_the_testbed():
    repo = Path(__file__).resolve().parents[2]
    source = (repo / "estimator" / "report.py").read_text(encoding="utf-8")
    imports = re.findall(r"^\s*(?:from|import)\s+([\w.]+)", source, flags=re.MULTILINE)
    assert not [m for m in imports if m.split(".")[0] in {"synth", "jsbsim", "campaigns", "estimator"}]
