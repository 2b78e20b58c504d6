"""The HTML report: one self-contained file whose figures are inline SVG that parse and
draw, checked in a real headless browser (Debian's chromium) when it is installed."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from hostpc.diagnostics import Diagnosis, diagnose
from hostpc.report import render_html, write_report
from tests.hostpc.diagnose_support import hidden_dataset

SVG = "{http://www.w3.org/2000/svg}"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu",
                  "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--no-first-run"]
IMAGE_CHECK = """<script>
window.addEventListener('load', function () {
  var figures = Array.from(document.querySelectorAll('svg.plot'));
  var drawn = figures.filter(function (f) {
    var box = f.getBoundingClientRect();
    return box.width > 100 && box.height > 100 && f.querySelectorAll('path, rect').length > 2;
  });
  var out = document.createElement('div');
  out.id = 'image-check';
  out.textContent = 'decoded ' + drawn.length + ' of ' + figures.length;
  document.body.appendChild(out);
});
</script>"""


@pytest.fixture(scope="module")
def diagnosis() -> Diagnosis:
    synthetic = hidden_dataset({"joint_compliance.c2": 2.0e-5, "joint_compliance.c3": 2.5e-5},
                               seed=2, n_samples=60)
    return diagnose(synthetic.dataset, ladder=True, source="hidden.json")


@pytest.fixture(scope="module")
def report(diagnosis: Diagnosis, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_report(tmp_path_factory.mktemp("report") / "sub" / "report.html", diagnosis)


def image_sources(text: str) -> list[str]:
    """The inline SVG figures of a report."""
    return re.findall(r'<svg xmlns="http://www.w3.org/2000/svg" class="plot".*?</svg>'
                      r'(?=</figure>)', text, re.S)


def test_report_is_self_contained_with_every_section(report: Path) -> None:
    text = report.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    assert not re.search(r'(src|href)="(https?:|//|file:)', text)
    assert "<script" not in text
    for heading in ("Is the model adequate?", "Model vs measurement", "Where does it fail?",
                    "Which effect is missing?", "Ladder", "Parameters: effect sizes",
                    "Identifiability"):
        assert f"<h2>{heading}</h2>" in text, heading
    assert "joint_compliance" in text and "joint_offsets.q2" in text
    assert "NOT adequate" in text
    assert "<img" not in text and "DATASET" not in text
    sources = image_sources(text)
    assert len(sources) == 8  # measurement, histogram, variables, 2 rankings, ladder, rho, sv
    for source in sources:
        root = ET.fromstring(source)  # well-formed XML, or this raises
        assert root.tag == f"{SVG}svg" and root.get("aria-label")
        marks = root.findall(f".//{SVG}path") + root.findall(f".//{SVG}rect")
        assert len(marks) >= 3 and len(source) > 2000


def test_report_without_ladder_escapes_and_says_how_to_get_one(diagnosis: Diagnosis,
                                                                report: Path) -> None:
    from dataclasses import replace

    text = render_html(replace(diagnosis, ladder=None), title="<b>run & co</b>")
    assert "hostpc diagnose hidden.json --ladder" in text
    anonymous = render_html(replace(diagnosis, ladder=None, source=None))
    assert "DATASET" not in anonymous and "--ladder</code> on this dataset" in anonymous
    from hostpc.diagnostics.advice import command

    assert command(diagnosis.check, "backlash", None, []) == "--effects +backlash"
    assert command(diagnosis.check, "backlash", "d.json", ["p.py"]) == (
        "hostpc diagnose d.json --effects +backlash --plugin p.py")
    assert len(image_sources(text)) == len(image_sources(report.read_text())) - 1
    assert "&lt;b&gt;run &amp; co&lt;/b&gt;" in text and "<b>run" not in text


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.slow
def test_report_renders_in_headless_chromium(report: Path, tmp_path: Path) -> None:
    assert "The model is NOT adequate." in rendered_in_chromium(report, tmp_path)


def rendered_in_chromium(report: Path, tmp_path: Path) -> str:
    """The DOM of ``report`` as headless chromium draws it, after checking that every
    figure drew and a screenshot is no flat page (skips without chromium, except in CI)."""
    if _chromium() is None:
        if os.environ.get("ZEROCAL_REQUIRE_BROWSER"):  # CI installs chromium: never skip there
            pytest.fail("chromium is not installed but ZEROCAL_REQUIRE_BROWSER is set")
        pytest.skip("chromium is not installed (apt-get install -y chromium)")
    checked = tmp_path / "checked.html"
    checked.write_text(report.read_text(encoding="utf-8").replace("</body>",
                                                                  IMAGE_CHECK + "</body>"))
    n_images = len(image_sources(report.read_text(encoding="utf-8")))
    browser = _chromium()
    assert browser is not None
    dom = subprocess.run(
        [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
         "--virtual-time-budget=10000", "--dump-dom", checked.as_uri()],
        capture_output=True, text=True, timeout=120, check=False)
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert f"decoded {n_images} of {n_images}" in dom.stdout, dom.stdout[-500:]

    screenshot = tmp_path / "shot.png"
    shot = subprocess.run(
        [browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile2'}",
         "--window-size=1200,2400", f"--screenshot={screenshot}", report.as_uri()],
        capture_output=True, text=True, timeout=120, check=False)
    assert shot.returncode == 0 and screenshot.is_file(), shot.stderr[-2000:]
    _assert_not_blank(screenshot)
    return dom.stdout


def _assert_not_blank(path: Path) -> None:
    """The screenshot has many colours (plots), not one flat page."""
    from matplotlib.image import imread

    pixels = imread(path)
    assert pixels.ndim == 3 and pixels.shape[0] > 1000
    flat = (pixels[..., :3] * 255).astype(int).reshape(-1, 3)
    colours = {tuple(p) for p in flat[:: max(1, flat.shape[0] // 20000)]}
    assert len(colours) > 50
    assert pixels[..., :3].std() > 0.05


def test_svg_axes_ticks_and_gaps() -> None:
    """Round ticks; NaN breaks a line and drops a point; data outside the limits is clipped
    by the nested viewport, never drawn over the labels."""
    from hostpc.report.svg import Canvas, limits, nice_ticks, tick_label

    assert nice_ticks(0.0, 1.0) == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    assert nice_ticks(-0.013, 0.021, 4) == pytest.approx([-0.01, 0.0, 0.01, 0.02])
    assert [tick_label(v, 0.2) for v in (0.4, 0.0, 1e-5)] == ["0.4", "0", "1e-05"]
    assert limits([1.0, float("nan"), 3.0], pad=0.0) == (1.0, 3.0)
    assert limits([2.0, 2.0])[0] < 2.0 < limits([2.0, 2.0])[1]
    canvas = Canvas(200, 100, "t")
    axes = canvas.axes(30, 10, 160, 70, (0.0, 4.0), (0.0, 1.0))
    axes.line([0, 1, 2, 3, 4], [0.1, 0.2, float("nan"), 0.4, 0.5], "red")
    axes.points([0, 1, 2], [0.5, float("nan"), 0.5], "blue")
    axes.frame("title", "x", "y")
    svg = canvas.render()
    root = ET.fromstring(svg)
    paths = [p.get("d", "") for p in root.iter(f"{SVG}path")]
    line = next(d for d in paths if "L" in d)
    assert line.count("M") == 2  # the NaN splits it
    dots = next(d for d in paths if d.endswith("h0") and d.count("M") == 2)
    assert dots.startswith("M0.0 35.0h0")  # (0, 0.5) in the 160 x 70 viewport
    assert root.find(f"{SVG}svg").get("width") == "160.0"  # type: ignore[union-attr]
