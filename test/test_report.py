"""The diagnosis report: every picture is written, referenced and rendered by a headless browser."""

import re
import shutil
import subprocess

import pytest

from ship_ident.diagnosis.diagnose import diagnose
from ship_ident.diagnosis.report import write_report
from ship_ident.model.simulator import simulate

pytestmark = pytest.mark.slow  # fits, diagnoses and renders a full report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHECK = """<script>window.addEventListener('load', () => {
  const imgs = [...document.images];
  const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;
  document.body.setAttribute('data-images', ok + '/' + imgs.length);
});</script></body>"""


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    sim = simulate("random", "seed001", effects=("rudder_delay",), duration=300, seed=4)
    result = diagnose(sim.dataset, "nomoto2", ("rudder_offset",), workers=2)
    return write_report(result, tmp_path_factory.mktemp("report"), source="simulated")


def test_report_writes_and_references_every_png(report):
    html = report.read_text()
    images = re.findall(r'<img src="([^"]+)"', html)
    assert len(images) == 6
    for name in images:
        path = report.parent / name
        assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Verdict" in html and "free run" in html
    assert re.search(r"Verdict: (adequate|missing_effect|unexplained)</b>: \w", html)  # and its sentence
    # the worst segments name their recording, held-out ones included
    assert "simulate:random (training)" in html and "simulate:random (held out)" in html


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install -y chromium)")
def test_report_renders_in_headless_chromium(report, tmp_path):
    check = report.parent / "check.html"
    check.write_text(report.read_text().replace("</body>", CHECK))
    out = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--virtual-time-budget=10000",
            "--dump-dom",
            check.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert 'data-images="6/6"' in out.stdout, out.stderr[-2000:]
